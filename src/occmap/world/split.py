"""A scan's updates dealt out to tiles: one pass to find each update's tile and its tile key, a
counting sort to group them (each tile's updates keep their Morton order)."""

from __future__ import annotations

import numpy as np

from .._jit import kernel
from ..octree.keys import CENTER, FIELD

_MASK = (1 << FIELD) - 1


@kernel
def split_by_tile(keys, depths, is_hit, shift, bits):
    """Updates (:func:`occmap.octree.insertion.apply`: packed keys local to ``shift``
    (:mod:`occmap.octree.marking`), depths, hit flags; each within one tile) → ``(tiles (m, 3),
    starts (m + 1,), tile_keys, depths, hits)``: the tiles they fall in (tile index
    ``(key − 32768) >> bits`` of the global key), and per tile ``i`` its updates
    ``starts[i]:starts[i + 1]`` as packed tile keys (``((key − 32768) mod 2^bits) + 32768``) with
    their depths and hit flags, in their given order."""
    n = keys.shape[0]
    size = 1 << bits
    lo = np.full(3, np.iinfo(np.int64).max, np.int64)
    hi = np.full(3, np.iinfo(np.int64).min, np.int64)
    tile = np.empty((n, 3), np.int64)
    local = np.empty(n, np.int64)
    for i in range(n):
        k = keys[i]
        packed = 0
        for a in range(3):
            g = ((k >> (FIELD * a)) & _MASK) + shift[a] - CENTER
            t = g >> bits
            tile[i, a] = t
            lo[a] = min(lo[a], t)
            hi[a] = max(hi[a], t)
            packed |= ((g & (size - 1)) + CENTER) << (FIELD * a)
        local[i] = packed
    if n == 0:
        return np.empty((0, 3), np.int64), np.zeros(1, np.int64), local, depths[:0].copy(), is_hit[:0].copy()
    nx, ny = hi[0] - lo[0] + 1, hi[1] - lo[1] + 1
    cells = nx * ny * (hi[2] - lo[2] + 1)
    count = np.zeros(cells + 1, np.int64)
    code = np.empty(n, np.int64)
    for i in range(n):
        c = (tile[i, 0] - lo[0]) + nx * ((tile[i, 1] - lo[1]) + ny * (tile[i, 2] - lo[2]))
        code[i] = c
        count[c + 1] += 1
    m = 0
    for c in range(cells):
        if count[c + 1]:
            m += 1
        count[c + 1] += count[c]
    tiles = np.empty((m, 3), np.int64)
    starts = np.empty(m + 1, np.int64)
    j = 0
    for c in range(cells):
        if count[c + 1] > count[c]:
            starts[j] = count[c]
            tiles[j, 0] = lo[0] + c % nx
            tiles[j, 1] = lo[1] + (c // nx) % ny
            tiles[j, 2] = lo[2] + c // (nx * ny)
            j += 1
    starts[m] = n
    out_keys = np.empty(n, np.int64)
    out_depths = np.empty(n, np.int8)
    out_hit = np.empty(n, np.bool_)
    fill = count[:cells].copy()
    for i in range(n):
        c = code[i]
        out_keys[fill[c]] = local[i]
        out_depths[fill[c]] = depths[i]
        out_hit[fill[c]] = is_hit[i]
        fill[c] += 1
    return tiles, starts, out_keys, out_depths, out_hit
