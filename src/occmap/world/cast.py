"""OctoMap's ``castRay`` across tiles: each ray walks with global keys (the walk of
:mod:`occmap.octree.raywalk`, so its voxels are those one tree's cast visits) through one tile at a
time; a ray that leaves its tile is handed back and goes on in the next one. Numba kernels on a
tile's slots (:mod:`occmap.octree.pool`)."""

from __future__ import annotations

import numpy as np

from .._jit import kernel
from ..octree import raywalk
from ..octree.keys import CENTER, DEPTH, child_index, coord_to_key

#: What :func:`walk_tile` says of each ray: still walking (in another tile now), or stopped.
MOVED, HIT, STOPPED, NOT_CAST = 0, 1, 2, 3


@kernel
def start_rays(origins, directions, res):
    """Walk state per ray (float32 origins and directions, one of each or N): global keys (N, 3),
    steps (N, 3), t (N, 3), g (N, 3) float64 (see :mod:`occmap.octree.raywalk`) and whether the ray
    has a direction."""
    n = max(origins.shape[0], directions.shape[0])
    inv_res = 1.0 / res
    keys = np.empty((n, 3), np.int64)
    steps = np.empty((n, 3), np.int64)
    t = np.empty((n, 3))
    g = np.empty((n, 3))
    moving = np.empty(n, np.bool_)
    for r in range(n):
        o = origins[r] if origins.shape[0] == n else origins[0]
        q = directions[r] if directions.shape[0] == n else directions[0]
        kx, ky, kz = coord_to_key(o[0], inv_res), coord_to_key(o[1], inv_res), coord_to_key(o[2], inv_res)
        _, dx, dy, dz = raywalk.direction(q[0], q[1], q[2])
        sx, sy, sz, tx, ty, tz, gx, gy, gz = raywalk.start(o[0], o[1], o[2], dx, dy, dz, kx, ky, kz, res, False)
        keys[r, 0], keys[r, 1], keys[r, 2] = kx, ky, kz
        steps[r, 0], steps[r, 1], steps[r, 2] = sx, sy, sz
        t[r, 0], t[r, 1], t[r, 2] = tx, ty, tz
        g[r, 0], g[r, 1], g[r, 2] = gx, gy, gz
        moving[r] = sx != 0 or sy != 0 or sz != 0
    return keys, steps, t, g, moving


@kernel
def _voxel(slots, kx, ky, kz):
    """Slot of the leaf holding tile keys (kx, ky, kz), −1 where unknown."""
    if slots.shape[0] == 0 or np.isnan(slots[0].value):
        return -1
    node = 0
    d = 0
    while d < DEPTH and slots[node].child >= 0:
        node = slots[node].child + child_index(kx, ky, kz, d)
        if np.isnan(slots[node].value):
            return -1
        d += 1
    return node


@kernel
def walk_tile(slots, base, tile_size, rays, origins, keys, steps, t, g, first, res, max_range,
              ignore_unknown, occ, lo, hi, status):
    """Walk the ``rays`` (indices) through the tile whose first voxel has global key ``base``
    (3,) and whose nodes are ``slots`` (:mod:`occmap.octree.pool`; empty: unknown space), as ``castRay`` does: stop
    at an occupied voxel (HIT), at an unknown one unless ``ignore_unknown``, past ``max_range``
    (> 0) or on leaving the map's key box [``lo``, ``hi``] (STOPPED); a ray that steps out of the
    tile is left MOVED with its state updated for the next."""
    max_range_sq = max_range * max_range
    for j in range(rays.shape[0]):
        r = rays[j]
        o = origins[r] if origins.shape[0] > 1 else origins[0]
        ox, oy, oz = o[0], o[1], o[2]
        kx, ky, kz = keys[r, 0], keys[r, 1], keys[r, 2]
        tx, ty, tz = t[r, 0], t[r, 1], t[r, 2]
        gx, gy, gz = g[r, 0], g[r, 1], g[r, 2]
        sx, sy, sz = steps[r, 0], steps[r, 1], steps[r, 2]
        status[r] = MOVED
        while True:
            node = _voxel(slots, kx - base[0] + CENTER, ky - base[1] + CENTER, kz - base[2] + CENTER)
            if node >= 0 and slots[node].value >= occ:
                status[r] = HIT
                break
            if node < 0 and not ignore_unknown:
                status[r] = STOPPED
                break
            if first[r]:
                first[r] = False
                if sx == 0 and sy == 0 and sz == 0:
                    status[r] = NOT_CAST
                    break
            axis, tx, ty, tz = raywalk.step(tx, ty, tz, gx, gy, gz)
            if axis == 0:
                if kx + sx < lo[0] or kx + sx > hi[0]:
                    status[r] = STOPPED
                    break
                kx += sx
            elif axis == 1:
                if ky + sy < lo[1] or ky + sy > hi[1]:
                    status[r] = STOPPED
                    break
                ky += sy
            else:
                if kz + sz < lo[2] or kz + sz > hi[2]:
                    status[r] = STOPPED
                    break
                kz += sz
            if max_range > 0.0 and raywalk.centre_beyond(kx, ky, kz, ox, oy, oz, res, max_range_sq):
                status[r] = STOPPED
                break
            if not (base[0] <= kx < base[0] + tile_size and base[1] <= ky < base[1] + tile_size
                    and base[2] <= kz < base[2] + tile_size):
                break  # on into the next tile
        keys[r, 0], keys[r, 1], keys[r, 2] = kx, ky, kz
        t[r, 0], t[r, 1], t[r, 2] = tx, ty, tz
