"""The grid and the local map update the cells of the one walk (occmap.raster.walk2d): with beams
that end at cell centres (where the local map casts its rays) both give the same log-odds, cell
for cell, and observe exactly the cells the walk crosses, whether they split the work over
threads or not and wherever the local map's ring starts."""

from __future__ import annotations

import math

import numpy as np
import pytest

from occmap import OccupancyGrid2D
from occmap.grid2d import _kernels as grid_kernels
from occmap.local import LocalMap
from occmap.raster.walk2d import traverse_2d

RES = 0.1
N = 80  # cells per side: both maps cover [0, 8) × [0, 8)


def scans_to_cell_centres(rng, n_scans=6, n_beams=240):
    """Scans from poses inside the square whose beams end at cell centres (returns, some of them
    outside the square; a beam cleared up to the maximum range would end elsewhere)."""
    out = []
    for _ in range(n_scans):
        x, y, th = rng.uniform(1.0, 7.0), rng.uniform(1.0, 7.0), rng.uniform(-math.pi, math.pi)
        cells = rng.integers(-15, N + 15, (n_beams, 2))
        ends = (cells + 0.5) * RES
        d = ends - [x, y]
        ranges = np.hypot(d[:, 0], d[:, 1])
        angles = np.arctan2(d[:, 1], d[:, 0]) - th
        max_range = 2.0 * float(ranges.max())
        out.append((np.array([x, y, th]), ranges, angles, max_range, cells))
    return out


def walk_cells(scans):
    """Cells (iy, ix) in the square the walk frees or hits, from the walk alone."""
    seen = set()
    for pose, _, _, _, cells in scans:
        for c in cells:
            iy, ix, _ = traverse_2d(pose[:2], (c + 0.5) * RES, RES)
            seen.update(zip(iy.tolist(), ix.tolist()))
    return {(y, x) for y, x in seen if 0 <= y < N and 0 <= x < N}


@pytest.mark.parametrize("split", [False, True])
def test_grid_and_local_map_update_the_same_cells_of_the_one_walk(split, monkeypatch):
    rng = np.random.default_rng(7)
    scans = scans_to_cell_centres(rng)
    if split:  # the grid in strips of rows, the local map in two halves, on two threads
        monkeypatch.setattr(grid_kernels, "SPLIT_MIN_CELLS", 0)
    grid = OccupancyGrid2D(RES, size=(N * RES, N * RES), origin=(0.0, 0.0))
    lm = LocalMap((N * RES, N * RES), RES, center=(5.37, 4.71))
    lm.move_to(4.0, 4.0)  # the same cells as the grid, with the ring started mid-buffer
    assert lm.origin.tolist() == [0.0, 0.0] and (lm._sr, lm._sc) != (0, 0)
    lm.parallel = split
    for t, (pose, ranges, angles, max_range, _) in enumerate(scans):
        grid.insert_scan(pose, ranges, angles, max_range=max_range)
        lm.insert_scan(pose, ranges, angles, stamp=float(t), max_range=max_range)
    got = lm.log_odds()
    expected = np.zeros((N, N), bool)
    for y, x in walk_cells(scans):
        expected[y, x] = True
    np.testing.assert_array_equal(grid.observed, expected)
    np.testing.assert_array_equal(~np.isnan(got), expected)
    np.testing.assert_array_equal(got[expected], grid.log_odds()[expected])


def test_local_map_scan_codes_roll_over_like_fresh_codes():
    """When the scan codes run out the stamps drop to 'seen' and the codes start again: the cells
    come out as with codes that never ran out, so no ray is skipped as 'already cast this scan'."""
    rng = np.random.default_rng(3)
    scans = scans_to_cell_centres(rng, n_scans=2, n_beams=120) * 2  # scan 2 casts the rays of scan 0
    a = LocalMap((N * RES, N * RES), RES, center=(4.0, 4.0))
    b = LocalMap((N * RES, N * RES), RES, center=(4.0, 4.0))
    for t, (pose, ranges, angles, max_range, _) in enumerate(scans):
        if t == 1:
            b._codes.code = b._codes.last - 1  # scan 1 takes the last code, scan 2 starts again at 1
        for lm in (a, b):
            lm.insert_scan(pose, ranges, angles, stamp=float(t), max_range=max_range)
    np.testing.assert_array_equal(a.log_odds(), b.log_odds())
    assert a.stats == b.stats
