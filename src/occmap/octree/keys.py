"""Octree key arithmetic, all of it (OctoMap's ``OcTreeKey.h`` and the key half of
``OcTreeBaseImpl``).

Conventions (OctoMap's, so maps compare voxel by voxel):

- The tree has depth :data:`DEPTH` = 16; a *key* is a depth-16 voxel index per axis,
  ``key = floor(x / resolution) + 32768`` computed on the float64 value of the coordinate (OctoMap's
  ``coordToKey``); valid keys are 0 .. :data:`MAX_KEY`.
- The node at depth ``d`` holding a key is found by its bits from the top: the child index below a
  node at depth ``d`` is ``x-bit + 2·y-bit + 4·z-bit`` of bit ``15 − d`` (:func:`child_index`).
- The centre of the node at depth ``d`` holding a key is OctoMap's ``keyToCoord(key, d)``
  (:func:`node_center`).
- **The packed key** (:func:`pack`): ``kx | ky << 20 | kz << 40`` in an int64. Each field has four
  spare bits, so a key one step outside the key range (−1 or 65536) is still a distinct integer:
  packing is linear (``pack(a) + pack(b) == pack(a + b)``), a walk can step a packed key by
  adding :func:`pack` of its step, and the difference of two packed keys tells per field how far
  apart they are. Every kernel that keeps keys in one integer uses this layout.
- **Block codes** (:func:`block_code`): the 8×8×8 voxels of one depth-13 node form a *block*; its
  code is the packed key of the block's first voxel, plus one (0 marks an empty hash slot).
- **Morton order** (:func:`morton`): the bits of the three keys interleaved (x lowest), the order
  in which a depth-first walk of the octree visits voxels.

The kernels here are Numba functions of scalars (callable from Python as well);
:func:`coord_to_keys`, :func:`keys_in_range` and :func:`node_centers` are their NumPy forms for
whole arrays.
"""

from __future__ import annotations

import math

import numpy as np

from .._intrinsics import bit_length
from .._jit import kernel

DEPTH = 16
#: OctoMap's ``tree_max_val``: the key of the voxel whose lower corner is the world origin.
CENTER = 32768
MAX_KEY = 65535
#: The ``shift`` of a tree's own keys (none): kernels that take one (:mod:`.marking`) keep keys
#: *local*, OctoMap's key less the shift, so a tiled map can use them anywhere in a 64-bit key space.
NO_SHIFT = np.zeros(3, np.int64)
#: Bits per field of a packed key.
FIELD = 20
_FIELD_MASK = (1 << FIELD) - 1
#: A packed key's bits below the block (the low 3 bits of each field).
_IN_BLOCK = 7 | (7 << FIELD) | (7 << 2 * FIELD)


@kernel
def coord_to_key(c, inv_res):
    """OctoMap's ``coordToKey`` on one axis: ``floor(c / res) + 32768`` on the float64 value of
    ``c`` (``inv_res`` = 1 / resolution). Not range-checked (see :func:`key_in_range`)."""
    return np.int64(math.floor(inv_res * np.float64(c))) + CENTER


@kernel
def key_in_range(k):
    return 0 <= k <= MAX_KEY


@kernel
def key_to_coord(k, res):
    """Centre of the depth-16 voxel ``k`` on one axis (OctoMap's ``keyToCoord(key)``)."""
    return (np.float64(k - CENTER) + 0.5) * res


@kernel
def child_index(kx, ky, kz, depth):
    """Index of the child of a node at ``depth`` (0 = root) that holds key (kx, ky, kz)."""
    shift = DEPTH - 1 - depth
    return ((kx >> shift) & 1) | (((ky >> shift) & 1) << 1) | (((kz >> shift) & 1) << 2)


@kernel
def pack(kx, ky, kz):
    """The packed key ``kx | ky << 20 | kz << 40`` (linear: also packs steps, ±1 per field)."""
    return kx + (ky << FIELD) + (kz << (2 * FIELD))


@kernel
def unpack(key):
    """(kx, ky, kz) of a packed key whose fields are non-negative."""
    return key & _FIELD_MASK, (key >> FIELD) & _FIELD_MASK, key >> (2 * FIELD)


@kernel
def field(key, axis):
    """Key of one axis (0, 1, 2) of a packed key whose fields are non-negative."""
    return (key >> (FIELD * axis)) & _FIELD_MASK


@kernel
def shared_depth(a, b):
    """Depth of the deepest node on the paths to the voxels with packed keys ``a`` and ``b`` (16
    when they are the same voxel)."""
    d = a ^ b
    return DEPTH - bit_length((d | (d >> FIELD) | (d >> (2 * FIELD))) & _FIELD_MASK)


@kernel
def block_code(key):
    """Code of the block (8×8×8 voxels, one depth-13 node) holding the voxel with packed key
    ``key``: the packed key of its first voxel, plus one (never 0)."""
    return (key & ~_IN_BLOCK) + 1


@kernel
def block_key(code):
    """Packed key of the first voxel of the block with code ``code`` (:func:`block_code` undone)."""
    return code - 1


@kernel
def in_block(key):
    """Index ``lx + 8·ly + 64·lz`` of the voxel with packed key ``key`` within its block."""
    return (key & 7) | (((key >> FIELD) & 7) << 3) | (((key >> (2 * FIELD)) & 7) << 6)


@kernel
def morton(kx, ky, kz, bits):
    """The low ``bits`` bits of kx, ky, kz interleaved, x lowest (depth-first order of the
    octree's nodes of that many levels)."""
    m = 0
    for bit in range(bits):
        m |= ((((kx >> bit) & 1) << (3 * bit)) | (((ky >> bit) & 1) << (3 * bit + 1))
              | (((kz >> bit) & 1) << (3 * bit + 2)))
    return m


# ---------------------------------------------------------------------------- NumPy forms

def coord_to_keys(points: np.ndarray, resolution: float) -> np.ndarray:
    """:func:`coord_to_key` of float64 ``points`` (..., 3): int64 keys (..., 3), not range-checked
    (NaN and overflowing coordinates give meaningless keys: see :func:`keys_in_range`)."""
    with np.errstate(invalid="ignore"):
        return np.floor(points * (1.0 / resolution)).astype(np.int64) + CENTER


def keys_in_range(keys: np.ndarray) -> np.ndarray:
    """Per key triple (..., 3): whether every axis lies in 0 .. 65535."""
    return np.all((keys >= 0) & (keys <= MAX_KEY), axis=-1)


def packed_in_range(keys: np.ndarray) -> np.ndarray:
    """Per packed key (:func:`pack`, int64): whether it packs three keys of 0 .. 65535."""
    return ((keys >= 0) & ((keys & _FIELD_MASK) <= MAX_KEY) & (((keys >> FIELD) & _FIELD_MASK) <= MAX_KEY)
            & ((keys >> (2 * FIELD)) <= MAX_KEY))


def pack_keys(keys: np.ndarray) -> np.ndarray:
    """:func:`pack` of int64 keys (..., 3)."""
    return keys[..., 0] + (keys[..., 1] << FIELD) + (keys[..., 2] << (2 * FIELD))


def node_cells(depths) -> np.ndarray:
    """Voxels along the edge of a node at ``depths``: 2^(16 − depth) (int64)."""
    return 1 << (DEPTH - np.asarray(depths, np.int64))


def node_centers(keys: np.ndarray, depths, resolution: float) -> np.ndarray:
    """Centres (..., 3) of the nodes at ``depths`` (broadcast over the leading dimensions) that
    hold ``keys`` (..., 3), as OctoMap's ``keyToCoord(key, depth)`` computes them, bit for bit:
    ``(floor((key − 32768) / 2^(16−d)) + 0.5) · resolution · 2^(16−d)``."""
    cells = node_cells(depths)[..., None]
    return (np.floor_divide(keys - CENTER, cells) + 0.5) * (resolution * cells)
