"""The 2D grid of solids: casts through it equal the test of every solid bit for bit (also for rays
along cell borders and through cell corners), point tests likewise, and worlds use it only when
they are large."""

from __future__ import annotations

import numpy as np
import pytest

from occmap.sim import _kernels3d
from occmap.sim.solid_grid import MARGIN, build_grid, footprints
from occmap.sim.world3d import GRID_MIN_SOLIDS, World3D


def many_solids(rng, n_boxes=400, n_cyl=200, span=200.0, far=10_000.0):
    """Boxes and cylinders scattered over ``span`` metres around (far, far), some boxes with
    integer corners (faces on common planes)."""
    lo = far + rng.uniform(-span / 2, span / 2, (n_boxes, 3))
    lo[:, 2] = rng.uniform(-2.0, 5.0, n_boxes)
    boxes = np.hstack([lo, lo + rng.uniform(0.1, 25.0, (n_boxes, 3))])
    boxes[: n_boxes // 4] = np.round(boxes[: n_boxes // 4])
    boxes[: n_boxes // 4, 3:] += 1.0
    c = np.column_stack([far + rng.uniform(-span / 2, span / 2, (n_cyl, 2)), rng.uniform(0.05, 3.0, n_cyl),
                         z0 := rng.uniform(-1.0, 4.0, n_cyl), z0 + rng.uniform(0.1, 10.0, n_cyl)])
    return boxes, c


def rays(rng, n, centre, span, grid):
    """Random rays, and rays that run along cell borders, through cell corners, level, vertical,
    some starting off the grid."""
    o = centre + rng.uniform(-span, span, (n, 3))
    o[:, 2] = rng.uniform(0.1, 30.0, n)
    d = rng.normal(size=(n, 3))
    q = n // 8
    # origins on grid lines, heading along them or diagonally through the corners
    gx = grid.x0 + rng.integers(0, grid.nx, q) * grid.cell
    gy = grid.y0 + rng.integers(0, grid.ny, q) * grid.cell
    o[:q, 0], o[:q, 1] = gx, gy
    d[:q] = [(1, 0, 0), (0, -1, 0), (1, 1, 0), (-1, 1, 0.2), (1, -1, -0.3), (0, 0, -1), (0, 1, 0.5),
             (-1, -1, 0)] * (q // 8) + [(1, 1, 0)] * (q % 8)
    d[q : 2 * q, 2] = 0.0  # level
    d[2 * q : 2 * q + 10] = (0, 0, 1)  # vertical
    return o, d / np.linalg.norm(d, axis=1, keepdims=True)


@pytest.mark.parametrize("seed, cell", [(0, None), (1, 4.0), (2, 1.0), (3, 50.0)])
def test_grid_cast_equals_testing_every_solid(seed, cell):
    rng = np.random.default_rng(seed)
    boxes, cyl = many_solids(rng)
    grid = build_grid(boxes, cyl, cell)
    o, d = rays(rng, 40_000, 10_000.0, 130.0, grid)
    for ground, max_range in ((True, np.inf), (False, 60.0), (True, 25.0)):
        want = np.empty(len(d))
        _kernels3d.cast_rays_parallel(o, d, boxes, cyl, 0.0, ground, max_range, want)
        got = np.empty(len(d))
        _kernels3d.cast_grid_rays(o, d, boxes, cyl, 0.0, ground, max_range, *grid, got)
        np.testing.assert_array_equal(got, want)
        _kernels3d.cast_grid_rays_parallel(o, d, boxes, cyl, 0.0, ground, max_range, *grid, got)
        np.testing.assert_array_equal(got, want)
        assert np.isfinite(want).mean() > 0.3  # the rays do meet solids
    # one origin shared by all rays
    want = np.empty(len(d))
    _kernels3d.cast_rays(o[:1], d, boxes, cyl, 0.0, True, 80.0, want)
    _kernels3d.cast_grid_rays(o[:1], d, boxes, cyl, 0.0, True, 80.0, *grid, got)
    np.testing.assert_array_equal(got, want)


def test_grid_point_test_equals_testing_every_solid(rng):
    boxes, cyl = many_solids(rng)
    grid = build_grid(boxes, cyl, 3.0)
    p = 10_000.0 + rng.uniform(-120.0, 120.0, (100_000, 3))
    p[:, 2] = rng.uniform(-1.0, 20.0, len(p))
    p[:2000] = np.round(p[:2000])  # on the integer boxes' faces and edges
    p[2000:2400] = boxes[:400, 3:]  # on box corners
    want = np.empty(len(p), dtype=bool)
    got = np.empty(len(p), dtype=bool)
    _kernels3d.occupied(p, boxes, cyl, 0.0, True, want)
    _kernels3d.occupied_grid(p, boxes, cyl, 0.0, True, *grid, got)
    np.testing.assert_array_equal(got, want)
    assert 0.05 < want.mean() < 0.95


def test_cells_list_exactly_the_solids_whose_grown_footprint_meets_them(rng):
    boxes, cyl = many_solids(rng, 60, 30, span=40.0)
    grid = build_grid(boxes, cyl, 2.5)
    rects = footprints(boxes, cyl)
    for start, items, rows in ((grid.box_start, grid.box_items, rects[:60]),
                               (grid.cyl_start, grid.cyl_items, rects[60:])):
        assert start[0] == 0 and start[-1] == len(items)
        for c in range(grid.nx * grid.ny):
            cx, cy = c % grid.nx, c // grid.nx
            x0, y0 = grid.x0 + cx * grid.cell, grid.y0 + cy * grid.cell
            def meet(r, eps=0.0):
                return ((r[:, 0] - MARGIN <= x0 + grid.cell + eps) & (r[:, 2] + MARGIN >= x0 - eps)
                        & (r[:, 1] - MARGIN <= y0 + grid.cell + eps) & (r[:, 3] + MARGIN >= y0 - eps))

            listed = items[start[c]:start[c + 1]]
            assert np.all(np.diff(listed) > 0)
            # every solid that meets the cell is listed; a listed one meets it or just touches
            # its border (floor of a coordinate on a cell line)
            assert set(np.flatnonzero(meet(rows))) <= set(listed)
            near = meet(rows[listed], 1e-9)
            assert near.all()


def test_worlds_use_the_grid_only_when_large(rng):
    assert World3D.default()._grid is None
    boxes, cyl = many_solids(rng, GRID_MIN_SOLIDS, 1)
    w = World3D(boxes, cyl)
    assert w._grid is not None
    small = World3D(boxes[: GRID_MIN_SOLIDS - 1], cyl)
    assert small._grid is None
    o, d = rays(rng, 5000, 10_000.0, 120.0, w._grid)
    brute = np.empty(len(d))
    unit = d / np.sqrt(np.einsum("ij,ij->i", d, d))[:, None]  # as World3D.cast normalises
    _kernels3d.cast_rays(o, unit, w.boxes, w.cylinders, 0.0, True, 70.0, brute)
    np.testing.assert_array_equal(w.cast(o, d, 70.0), brute)
    want = np.empty(len(o), dtype=bool)
    _kernels3d.occupied(o, w.boxes, w.cylinders, 0.0, True, want)
    np.testing.assert_array_equal(w.occupied(o), want)
