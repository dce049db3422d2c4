"""Numba kernels of the tiled 2D grid (:mod:`occmap.world.grid_tiles`): plain arrays in, arrays
updated in place.

Cells are those of the world lattice (:mod:`occmap.raster`, origin (0, 0)): cell ``(ix, iy)``
spans ``[ix·res, (ix+1)·res) × [iy·res, (iy+1)·res)``. With ``T = 1 << bits`` cells per tile side,
tile ``(tx, ty) = (ix >> bits, iy >> bits)``. Tiles live in a pool: ``L`` (float32 log-odds) and
``S`` (uint16 stamps, :mod:`occmap.raster.update`), both (slots, T, T); the tile in slot ``p``
holds cell ``(ix, iy)`` at ``[p, iy − ty·T, ix − tx·T]``.

A scan's beams are given to the tiles they cross: :func:`bucket` walks each beam tile by tile
(:func:`occmap.raster.walk2d.dda_span` finds where the walk leaves a tile and enters the next
without walking its cells) and lists, per tile, the beams that update a cell of it, in scan
order. :func:`apply_tiles` then gives each tile its beams scan after scan, hits first, then the
misses of each beam on the tile's cells only (:func:`~occmap.raster.walk2d.miss_walk`, which
starts a walk where it enters a rectangle): the updates :mod:`occmap.grid2d` applies to the same
cells, in the same order, so each tile equals those cells of the one grid bit for bit. Tiles own
disjoint cells: they are updated side by side on threads with no synchronisation.
"""

from __future__ import annotations

import numpy as np
from numba import prange

from .._jit import kernel, kernel_parallel
from ..grid2d._kernels import beam_end
from ..raster.update import clamp_add, hit_stamp
from ..raster.walk2d import cell_of, dda_init, dda_span, miss_walk


@kernel
def beam_ends(poses, ranges, angles, max_range, kinds, ex, ey):
    """Fill ``kinds`` (N, n) int8 and the end points ``ex``, ``ey`` (N, n) of every reading
    (:func:`occmap.grid2d._kernels.beam_end`: 0 unusable, 1 hit, 2 no return)."""
    for k in range(ranges.shape[0]):
        for b in range(ranges.shape[1]):
            kinds[k, b], ex[k, b], ey[k, b] = beam_end(poses[k, 0], poses[k, 1], poses[k, 2], ranges[k, b],
                                                       angles[k, b], max_range)


@kernel
def tile_box(poses, kinds, ex, ey, inv_res, bits):
    """Inclusive box ``(tx0, ty0, tx1, ty1)`` of the tiles holding the scans' sensor cells and
    beam end cells (every cell their walks visit lies in it)."""
    tx0, ty0 = np.iinfo(np.int64).max, np.iinfo(np.int64).max
    tx1, ty1 = np.iinfo(np.int64).min, np.iinfo(np.int64).min
    for k in range(kinds.shape[0]):
        ix, iy = cell_of(poses[k, 0], poses[k, 1], 0.0, 0.0, inv_res)
        tx0, ty0, tx1, ty1 = min(tx0, ix >> bits), min(ty0, iy >> bits), max(tx1, ix >> bits), max(ty1, iy >> bits)
        for b in range(kinds.shape[1]):
            if kinds[k, b] != 0:
                ix, iy = cell_of(ex[k, b], ey[k, b], 0.0, 0.0, inv_res)
                tx0, ty0 = min(tx0, ix >> bits), min(ty0, iy >> bits)
                tx1, ty1 = max(tx1, ix >> bits), max(ty1, iy >> bits)
    return tx0, ty0, tx1, ty1


@kernel
def bucket(poses, kinds, ex, ey, inv_res, bits, tx0, ty0, table, items):
    """The tiles each beam updates, walked tile by tile; ``table`` (th, tw) int64 covers the tiles
    ``(tx0 + c, ty0 + r)``.

    With ``items`` empty: ``table`` is added the number of beams updating each tile. Else
    ``table`` holds, per tile, the position in ``items`` where its next beam goes (−1: leave the
    tile out) and each beam's flat index ``k·n + b`` is written there, in scan and beam order.
    A beam updates the cells of its walk before its end cell, and its end cell when it is a hit."""
    T = 1 << bits
    count = items.shape[0] == 0
    n_beams = kinds.shape[1]
    for k in range(kinds.shape[0]):
        x0, y0 = poses[k, 0], poses[k, 1]
        for b in range(n_beams):
            kind = kinds[k, b]
            if kind == 0:
                continue
            steps, state = dda_init(x0, y0, ex[k, b], ey[k, b], 0.0, 0.0, inv_res)
            last = steps if kind == 1 else steps - 1  # the last step that updates a cell
            if last < 0:
                continue
            sx, sy = state[4], state[5]
            tx, ty = state[0] >> bits, state[1] >> bits
            while True:
                r, c = ty - ty0, tx - tx0
                if count:
                    table[r, c] += 1
                elif table[r, c] >= 0:
                    items[table[r, c]] = k * n_beams + b
                    table[r, c] += 1
                _, s_out, _, _ = dda_span(state, tx * T, tx * T + T, ty * T, ty * T + T)
                if s_out > last:
                    break
                # the walk's next cell (step s_out) is in the next tile along x or along y
                a_in, a_out, _, _ = dda_span(state, (tx + sx) * T, (tx + sx) * T + T, ty * T, ty * T + T)
                if a_in == s_out and a_out > a_in:
                    tx += sx
                else:
                    ty += sy


@kernel
def _apply_tile(Lf, Sf, slot, tx, ty, bits, items, start, end, scan0, poses, kinds, ex, ey, inv_res,
                l_hit, l_miss, l_min, l_max):
    """The updates of one tile by its beams ``items[start:end]`` (flat indices, in scan order):
    scan after scan, first the hits that end in the tile, then each beam's misses on its cells."""
    T = 1 << bits
    x_lo, y_lo = tx * T, ty * T
    base = slot * T * T - y_lo * T - x_lo  # cell (ix, iy) of the tile is at base + iy·T + ix
    n_beams = kinds.shape[1]
    i = start
    while i < end:
        k = items[i] // n_beams
        j = i
        while j < end and items[j] // n_beams == k:
            j += 1
        s = scan0 + k
        for q in range(i, j):
            b = items[q] - k * n_beams
            if kinds[k, b] == 1:
                ix, iy = cell_of(ex[k, b], ey[k, b], 0.0, 0.0, inv_res)
                if x_lo <= ix < x_lo + T and y_lo <= iy < y_lo + T:
                    c = base + iy * T + ix
                    if Sf[c] != hit_stamp(s):
                        Sf[c] = hit_stamp(s)
                        Lf[c] = clamp_add(Lf[c], l_hit, l_min, l_max)
        for q in range(i, j):
            b = items[q] - k * n_beams
            steps, state = dda_init(poses[k, 0], poses[k, 1], ex[k, b], ey[k, b], 0.0, 0.0, inv_res)
            miss_walk(Lf, Sf, base, 1, T, steps, state, x_lo, x_lo + T, y_lo, y_lo + T, s, l_miss, l_min, l_max)
        i = j


@kernel
def apply_tiles(L, S, tiles, bits, items, scan0, poses, kinds, ex, ey, inv_res, l_hit, l_miss, l_min, l_max):
    """:func:`_apply_tile` for each row ``(slot, tx, ty, start, end)`` of ``tiles``, one after the
    other."""
    Lf, Sf = L.reshape(-1), S.reshape(-1)
    for p in range(tiles.shape[0]):
        _apply_tile(Lf, Sf, tiles[p, 0], tiles[p, 1], tiles[p, 2], bits, items, tiles[p, 3], tiles[p, 4], scan0,
                    poses, kinds, ex, ey, inv_res, l_hit, l_miss, l_min, l_max)


@kernel_parallel
def apply_tiles_parallel(L, S, tiles, bits, items, scan0, poses, kinds, ex, ey, inv_res, l_hit, l_miss, l_min,
                         l_max):
    """:func:`apply_tiles` with the tiles on threads (they own disjoint cells)."""
    Lf, Sf = L.reshape(-1), S.reshape(-1)
    for p in prange(tiles.shape[0]):
        _apply_tile(Lf, Sf, tiles[p, 0], tiles[p, 1], tiles[p, 2], bits, items, tiles[p, 3], tiles[p, 4], scan0,
                    poses, kinds, ex, ey, inv_res, l_hit, l_miss, l_min, l_max)
