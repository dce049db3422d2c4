"""The lidar kernel against a straightforward pure-Python reference: bit-identical log-odds and
stamps on random scans, lattice-aligned scans (exact cell corners and edges), beams leaving and
entering fixed maps, unusable readings and values near the clamps."""

from __future__ import annotations

import math

import numpy as np
import pytest

from occmap.grid2d import _kernels as K
from occmap.logodds import logit

L_HIT, L_MISS = logit(0.7), logit(0.4)
L_MIN, L_MAX = logit(0.1192), logit(0.971)


def _quantize(t):
    """A crossing parameter rounded down to a multiple of 2⁻⁵⁰ (so that sums of them are exact)."""
    return math.floor(t * 2.0**50) / 2.0**50 if t < 8.0 else t


def _ref_cells(x0, y0, x1, y1, ox, oy, inv_res):
    """Amanatides–Woo from (x0, y0) to (x1, y1): every cell, start first, end last (steps along x
    first where the crossings of the next x and y boundaries tie; once an axis reaches the end
    index only the other one moves)."""
    u0, v0 = (x0 - ox) * inv_res, (y0 - oy) * inv_res
    u1, v1 = (x1 - ox) * inv_res, (y1 - oy) * inv_res
    ix, iy = math.floor(u0), math.floor(v0)
    ex, ey = math.floor(u1), math.floor(v1)
    du, dv = u1 - u0, v1 - v0
    sx = 1 if ex > ix else -1
    sy = 1 if ey > iy else -1
    tmx = tmy = tdx = tdy = math.inf
    if du != 0.0:
        tmx = _quantize(((ix + (1 if du > 0.0 else 0)) - u0) / du)
        tdx = _quantize(abs(1.0 / du))
    if dv != 0.0:
        tmy = _quantize(((iy + (1 if dv > 0.0 else 0)) - v0) / dv)
        tdy = _quantize(abs(1.0 / dv))
    cells = [(ix, iy)]
    for _ in range(abs(ex - ix) + abs(ey - iy)):
        if iy == ey or (ix != ex and tmx <= tmy):
            ix += sx
            tmx += tdx
        else:
            iy += sy
            tmy += tdy
        cells.append((ix, iy))
    return cells


def reference_lidar(L, stamp, scan0, poses, ranges, angles, max_range, ox, oy, gx0, gy0, inv_res, l_hit, l_miss,
                    l_min, l_max):
    """One scan at a time: the set of hit cells and the set of crossed cells; each hit cell gets
    ``l_hit`` once, each crossed cell that is no hit ``l_miss`` once (clamped, float64 sum stored
    as float32). ``L[r, c]`` is the cell ``(gx0 + c, gy0 + r)``."""
    H, W = L.shape
    used = dropped = maxed = 0
    for k in range(len(poses)):
        s = scan0 + k
        x0, y0, th = (float(v) for v in poses[k])
        hits, free = set(), set()
        for b in range(ranges.shape[1]):
            r = float(ranges[k, b])
            if not r > 0.0:
                dropped += 1
                continue
            used += 1
            hit = r < max_range
            if not hit:
                r = max_range
                maxed += 1
            a = th + float(angles[k, b])
            cells = _ref_cells(x0, y0, x0 + r * math.cos(a), y0 + r * math.sin(a), ox, oy, inv_res)
            if hit:
                hits.add(cells[-1])
            free.update(cells[:-1])
        for cells, delta, value in ((hits, l_hit, 2 * s + 1), (free - hits, l_miss, 2 * s)):
            for ix, iy in cells:
                ix, iy = ix - gx0, iy - gy0
                if 0 <= ix < W and 0 <= iy < H:
                    L[iy, ix] = min(max(float(L[iy, ix]) + delta, l_min), l_max)
                    stamp[iy, ix] = value
    return used, dropped, maxed


def _compare(monkeypatch, L0, S0, scan0, poses, ranges, angles, max_range, ox, oy, res, offset=(0, 0)):
    args = (scan0, np.ascontiguousarray(poses, dtype=np.float64), np.ascontiguousarray(ranges, dtype=np.float64),
            np.ascontiguousarray(np.broadcast_to(angles, ranges.shape), dtype=np.float64), float(max_range),
            float(ox), float(oy), offset[0], offset[1], 1.0 / res, L_HIT, L_MISS, L_MIN, L_MAX)
    Lb, Sb = L0.copy(), S0.copy()
    want = reference_lidar(Lb, Sb, *args)
    # one thread, the grid split in parts (on two threads where Numba has them), the default; the
    # scans' beam ends held for all of them at once or for one scan at a time
    for split_min_cells in (-1, 0, None):
        for block_beams in (K.BLOCK_BEAMS, 1):
            monkeypatch.setattr(K, "BLOCK_BEAMS", block_beams)
            La, Sa = L0.copy(), S0.copy()
            got = K.integrate_lidar(La, Sa, *args, split_min_cells=split_min_cells)
            assert tuple(int(v) for v in got) == want
            np.testing.assert_array_equal(Sa, Sb)
        np.testing.assert_array_equal(La.view(np.int32), Lb.view(np.int32))  # bit-identical


def _initial(rng, H, W, fraction=0.3):
    L = np.zeros((H, W), np.float32)
    S = np.zeros((H, W), np.uint16)  # the grid's stamps
    seen = rng.random((H, W)) < fraction
    L[seen] = rng.uniform(L_MIN, L_MAX, seen.sum()).astype(np.float32)
    L[seen & (rng.random((H, W)) < 0.2)] = np.float32(L_MAX)
    L[seen & (rng.random((H, W)) < 0.2)] = np.float32(L_MIN)
    S[seen] = 1
    return L, S


@pytest.mark.parametrize("seed", range(4))
def test_random_scans_inside_and_across_a_fixed_map(seed, monkeypatch):
    rng = np.random.default_rng(seed)
    H, W, res, ox, oy = 70, 90, 0.05, -2.0, -1.5
    n_scans, n_beams = 6, 300
    # poses inside and outside the map, beams that stay inside, leave, enter and cross it
    poses = np.column_stack([rng.uniform(-3.5, 4.0, n_scans), rng.uniform(-3.0, 3.5, n_scans),
                             rng.uniform(-np.pi, np.pi, n_scans)])
    angles = rng.uniform(-np.pi, np.pi, (n_scans, n_beams))
    ranges = rng.uniform(0.01, 6.0, (n_scans, n_beams))
    u = rng.random((n_scans, n_beams))
    ranges[u < 0.05] = np.nan
    ranges[(u >= 0.05) & (u < 0.08)] = np.inf
    ranges[(u >= 0.08) & (u < 0.1)] = -1.0
    ranges[(u >= 0.1) & (u < 0.12)] = 0.0
    ranges[(u >= 0.12) & (u < 0.2)] = 5.0  # exactly max range: cleared, not marked
    L, S = _initial(rng, H, W)
    _compare(monkeypatch, L, S, 3, poses, ranges, angles, 5.0, ox, oy, res)


@pytest.mark.parametrize("seed", range(3))
def test_many_overlapping_beams_per_scan_and_repeated_scans(seed, monkeypatch):
    """Dense 360° scans from nearby poses: most cells are crossed by several beams of a scan and
    by several scans; values run into both clamps."""
    rng = np.random.default_rng(100 + seed)
    H, W, res = 80, 80, 0.05
    n_scans, n_beams = 25, 720
    poses = np.column_stack([rng.uniform(1.6, 2.4, n_scans), rng.uniform(1.6, 2.4, n_scans),
                             rng.uniform(-np.pi, np.pi, n_scans)])
    angles = np.linspace(-np.pi, np.pi, n_beams, endpoint=False)
    ranges = rng.choice([0.7, 1.1, 1.9, 2.5], (n_scans, n_beams)) + rng.uniform(-0.02, 0.02, (n_scans, n_beams))
    L, S = _initial(rng, H, W, 0.0)
    _compare(monkeypatch, L, S, 1, poses, ranges, angles, 2.2, 0.0, 0.0, res)


def test_lattice_aligned_beams_through_cell_corners_and_along_edges(monkeypatch):
    """Sensors on cell corners, edges and centres; beams along the axes and diagonals and at
    rational slopes, with ranges that end on cell boundaries: every tie of the traversal."""
    res = 0.25
    H, W = 40, 40
    poses, rows = [], []
    angles = np.array([k * math.pi / 4 for k in range(8)] + [math.atan2(1, 2), math.atan2(-2, 1), math.atan2(3, -1),
                                                             math.atan2(-1, -3)])
    for x in (5.0, 5.125, 5.25):
        for y in (5.0, 5.125, 5.25):
            for th in (0.0, math.pi / 2, -math.pi):
                poses.append((x, y, th))
                rows.append(np.tile([1.0, 2.0 * math.sqrt(2.0), 1.5, 0.75], 3))
    poses = np.array(poses)
    ranges = np.array(rows)
    L, S = _initial(np.random.default_rng(7), H, W, 0.0)
    _compare(monkeypatch, L, S, 1, poses, ranges, angles, 2.5, 0.0, 0.0, res)
    # the same with the origin off the world lattice and negative cells in play
    _compare(monkeypatch, L, S, 1, poses, ranges, angles, 2.5, 3.0, 3.0, res)


def test_a_window_of_the_world_lattice_far_from_the_origin(monkeypatch):
    """A growing map's storage: a window at an integer cell offset of the world lattice (origin
    (0, 0)), here near x = 10 km, with beams leaving it on every side."""
    rng = np.random.default_rng(9)
    res, H, W, offset = 0.05, 60, 80, (200_030, -41)
    n_scans, n_beams = 5, 400
    cx, cy = (offset[0] + W / 2) * res, (offset[1] + H / 2) * res
    poses = np.column_stack([rng.uniform(cx - 3.0, cx + 3.0, n_scans), rng.uniform(cy - 2.0, cy + 2.0, n_scans),
                             rng.uniform(-np.pi, np.pi, n_scans)])
    ranges = rng.uniform(0.05, 5.0, (n_scans, n_beams))
    L, S = _initial(rng, H, W)
    _compare(monkeypatch, L, S, 4, poses, ranges, rng.uniform(-np.pi, np.pi, (n_scans, n_beams)), 4.0, 0.0, 0.0, res, offset)


def test_beams_along_and_outside_every_border_of_a_fixed_map(monkeypatch):
    res = 0.1
    H, W = 20, 30
    # sensors just inside, on, and outside each border, looking along and across it
    pts = [(-0.5, 1.0), (0.0, 1.0), (0.05, 1.0), (2.95, 1.0), (3.0, 1.0), (3.5, 1.0),
           (1.5, -0.5), (1.5, 0.0), (1.5, 0.05), (1.5, 1.95), (1.5, 2.0), (1.5, 2.5), (-1.0, -1.0), (4.0, 3.0)]
    poses = np.array([(x, y, 0.0) for x, y in pts])
    angles = np.linspace(-np.pi, np.pi, 64, endpoint=False)
    ranges = np.tile(np.linspace(0.3, 5.0, 64), (len(pts), 1))
    L, S = _initial(np.random.default_rng(8), H, W)
    _compare(monkeypatch, L, S, 2, poses, ranges, angles, 4.0, 0.0, 0.0, res)


def test_empty_inputs(monkeypatch):
    L = np.zeros((5, 5), np.float32)
    S = np.zeros((5, 5), np.uint16)
    _compare(monkeypatch, L, S, 1, np.zeros((0, 3)), np.zeros((0, 4)), np.zeros(4), 1.0, 0.0, 0.0, 0.1)
    _compare(monkeypatch, L, S, 1, np.zeros((2, 3)), np.zeros((2, 0)), np.zeros(0), 1.0, 0.0, 0.0, 0.1)
    # a map with no cells at all
    _compare(monkeypatch, np.zeros((0, 0), np.float32), np.zeros((0, 0), np.uint16), 1, np.zeros((1, 3)),
             np.ones((1, 3)), np.zeros(3), 2.0, 0.0, 0.0, 0.1)
