"""A scan's marked voxels as blocks of bits (Bonxai's ``VoxelGrid`` layout): storage and its hash
(the accessor's lookups), merging, and listing the voxels in Morton order.

A *block* is the 8×8×8 voxels of one depth-13 node, known by its code (:func:`.keys.block_code`);
it holds two 512-bit masks, hits and frees (int64 words; bit ``lx + 8·ly + 64·lz`` = the voxel at
local coordinates (lx, ly, lz), :func:`.keys.in_block`). *Block storage* is the tuple
``(table, slots, codes, hits, frees, count)``: an open-addressing hash from code to block index
(``table`` holds codes, 0 = empty, ``slots`` the indices; at least twice as many entries as
blocks), the blocks' codes and masks in the order they were added, and their number
``count[0]``.

Lookups probe linearly from :func:`home`. The one walk that looks blocks up,
:func:`.marking.mark_scan`, does it through the *block accessor* (Bonxai's
``VoxelGrid::Accessor``): a ray's voxels lie mostly in the block of the voxel before, so it keeps
the last block's code and index and probes only when the code changes; a voxel in the same block
costs an array index, not a hash lookup. The accessor is written inside that walk's loop: as a
Numba function taking the storage's arrays (inlined or not) it made the walk twice as slow.
"""

from __future__ import annotations

import numpy as np

from .._intrinsics import bit_length
from .._jit import kernel
from .keys import block_key, morton, pack, unpack

_FIBONACCI = 0x9E3779B97F4A7C15  # 2^64 / golden ratio


@kernel
def new_blocks(capacity):
    """Empty block storage with room for ``capacity`` blocks."""
    size = 16
    while size < 2 * capacity:
        size *= 2
    return (np.zeros(size, np.int64), np.zeros(size, np.int64), np.zeros(capacity, np.int64),
            np.zeros((capacity, 8), np.int64), np.zeros((capacity, 8), np.int64), np.zeros(1, np.int64))


@kernel
def home(code, mask):
    """Hash slot where a probe for ``code`` starts (Fibonacci hashing: the top bits of the product,
    which depend on every bit of the code)."""
    return np.int64((np.uint64(code) * np.uint64(_FIBONACCI)) >> np.uint64(64 - bit_length(mask)))


@kernel
def grow_blocks(table, slots, codes, hits, frees, count):
    """The block storage at twice the capacity, rehashed."""
    n = count[0]
    t2, s2, c2, h2, f2, n2 = new_blocks(2 * codes.shape[0])
    h2[:n] = hits[:n]
    f2[:n] = frees[:n]
    c2[:n] = codes[:n]
    n2[0] = n
    mask = t2.shape[0] - 1
    for b in range(n):  # (each code once: the first empty entry of its probe sequence)
        h = home(codes[b], mask)
        while t2[h] != 0:
            h = (h + 1) & mask
        t2[h] = codes[b]
        s2[h] = b
    return t2, s2, c2, h2, f2, n2


@kernel
def morton_order(codes):
    """Order of the blocks by the Morton code of their block keys (the octree's DFS order)."""
    n = codes.shape[0]
    order = np.empty(n, np.int64)
    for b in range(n):
        kx, ky, kz = unpack(block_key(codes[b]))
        order[b] = morton(kx >> 3, ky >> 3, kz >> 3, 13)
    return np.argsort(order)


@kernel
def merge_blocks(codes, hits, frees):
    """Blocks of several markings concatenated → each block once, masks OR-ed, Morton-sorted."""
    order = morton_order(codes)
    n = codes.shape[0]
    c2 = np.empty(n, np.int64)
    h2 = np.empty((n, 8), np.int64)
    f2 = np.empty((n, 8), np.int64)
    m = -1
    for j in range(n):
        b = order[j]
        if m < 0 or codes[b] != c2[m]:
            m += 1
            c2[m] = codes[b]
            h2[m] = hits[b]
            f2[m] = frees[b]
        else:
            for w in range(8):
                h2[m, w] |= hits[b, w]
                f2[m, w] |= frees[b, w]
    return c2[:m + 1], h2[:m + 1], f2[:m + 1]


_DEBRUIJN = np.array([
    0, 47, 1, 56, 48, 27, 2, 60, 57, 49, 41, 37, 28, 16, 3, 61, 54, 58, 35, 52, 50, 42, 21, 44,
    38, 32, 29, 23, 17, 11, 4, 62, 46, 55, 26, 59, 40, 36, 15, 53, 34, 51, 20, 43, 31, 22, 10, 45,
    25, 39, 14, 33, 19, 30, 9, 24, 13, 18, 8, 12, 7, 6, 5, 63], np.int64)


@kernel
def _lowest_bit(word):
    """Index of the lowest set bit of a nonzero int64 (de Bruijn multiplication)."""
    return _DEBRUIJN[(((word ^ (word - 1)) * 0x03F79D71B4CB0A89) >> 58) & 63]


@kernel
def _compact(m):
    """Every third bit of m from bit 0, packed: one axis of a 9-bit :func:`.keys.morton` code."""
    return (m & 1) | ((m >> 2) & 2) | ((m >> 4) & 4)


@kernel
def block_voxels(codes, hits, frees, kbox):
    """The marked voxels of Morton-sorted blocks as packed keys (:func:`.keys.pack`) in Morton
    order, with a flag for the hit voxels (a voxel both hit and crossed is a hit); only those
    within the key box ``kbox`` (int64 (2, 3): min, max; (0, 3) for none)."""
    n = 0
    for b in range(codes.shape[0]):
        for w in range(8):
            word = hits[b, w] | frees[b, w]
            while word != 0:
                word &= word - 1
                n += 1
    keys = np.empty(n, np.int64)
    is_hit = np.empty(n, np.bool_)
    order = np.empty(8, np.int64)  # the block's bits re-laid in Morton order
    n = 0
    for b in range(codes.shape[0]):
        order[:] = 0
        for w in range(8):
            word = hits[b, w] | frees[b, w]
            while word != 0:
                bit = _lowest_bit(word)
                word &= word - 1
                m = (w << 6) | bit
                z = morton(m & 7, (m >> 3) & 7, m >> 6, 3)
                order[z >> 6] |= np.int64(1) << (z & 63)
        base = block_key(codes[b])
        bx, by, bz = unpack(base)
        for w in range(8):
            word = order[w]
            while word != 0:
                bit = _lowest_bit(word)
                word &= word - 1
                z = (w << 6) | bit
                lx, ly, lz = _compact(z), _compact(z >> 1), _compact(z >> 2)
                if kbox.shape[0]:
                    if not (kbox[0, 0] <= bx + lx <= kbox[1, 0] and kbox[0, 1] <= by + ly <= kbox[1, 1]
                            and kbox[0, 2] <= bz + lz <= kbox[1, 2]):
                        continue
                keys[n] = base + pack(lx, ly, lz)
                linear = lx | (ly << 3) | (lz << 6)
                is_hit[n] = (hits[b, linear >> 6] >> (linear & 63)) & 1 == 1
                n += 1
    return keys[:n], is_hit[:n]
