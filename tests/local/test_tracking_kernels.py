"""The tracker's shortcut kernels against plain references: the returns beyond clusters' ends
(exact bearings only near the sectors it reads), the promotion of mostly-moving components
(searches stopped at an object's span) and the radix sort of cell keys."""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from occmap.local.tracking import _kernels as K

BINS = 1440


def _beyond_reference(points, point_layers, starts, scene, scene_layers, n_layers, sx, sy, angle, slack):
    """Every finite scene return binned by its exact bearing and its layer; each cluster's angular
    ends as the kernel defines them, and the nearest return beyond each less than ``slack``
    farther, in the end's layer or the next."""
    scale = BINS / (2 * np.pi)
    finite = np.isfinite(scene).all(axis=1)
    sc = scene[finite] - (sx, sy)
    nearest = np.full((BINS, n_layers), np.inf)
    np.minimum.at(nearest, (((np.arctan2(sc[:, 1], sc[:, 0]) + np.pi) * scale).astype(int) % BINS,
                            scene_layers[finite]), np.hypot(sc[:, 0], sc[:, 1]))
    reach = int(np.ceil(angle * scale))
    ends, out = [], []
    for a, b in zip(starts[:-1], starts[1:]):
        d = points[a:b] - (sx, sy)
        mid = np.arctan2(*d.sum(axis=0)[::-1])
        rel = np.arctan2(d[:, 1], d[:, 0]) - mid
        rel -= 2 * np.pi * np.floor((rel + np.pi) / (2 * np.pi))
        lo, hi = np.argmin(rel), np.argmax(rel)
        r = np.hypot(d[:, 0], d[:, 1])
        b_lo, b_hi = int((mid + rel[lo] + np.pi) * scale), int((mid + rel[hi] + np.pi) * scale)
        j = np.arange(1, reach + 1)
        row = []
        for bins, end in (((b_lo - j) % BINS, lo), ((b_hi + j) % BINS, hi)):
            layer = point_layers[a + end]
            near = nearest[bins][:, max(layer - 1, 0):layer + 2].ravel()
            r_end = r[end]
            near = near[near < r_end + slack]
            row.append(near.min() if len(near) else np.inf)
        ends.append((a + lo, a + hi))
        out.append(row)
    return np.array(ends), np.array(out)


def test_returns_beyond_cluster_ends_equal_exact_bearings_of_every_return():
    rng = np.random.default_rng(1)
    hidden = total = 0
    for trial in range(60):
        sx, sy = rng.uniform(-2, 2, 2)
        clusters = [np.column_stack([c[0] + rng.uniform(-1, 1, m), c[1] + rng.uniform(-1, 1, m)])
                    for c, m in zip(rng.uniform(-20, 20, (rng.integers(1, 8), 2)), rng.integers(3, 30, 8))]
        points = np.concatenate(clusters)
        starts = np.concatenate([[0], np.cumsum([len(c) for c in clusters])])
        # returns anywhere, on the clusters, at the sensor, just below bearing 0 (pseudo-bearing 4),
        # not finite, and in every sector
        bearings = -np.pi + (np.arange(BINS) + rng.uniform(0.01, 0.99, BINS)) * 2 * np.pi / BINS
        r = rng.uniform(0.5, 20, BINS)
        ring = np.column_stack([sx + r * np.cos(bearings), sy + r * np.sin(bearings)])
        scene = np.concatenate([rng.uniform(-25, 25, (int(rng.integers(0, 400)), 2)), points,
                                [[sx, sy], [sx + 1, sy - 1e-300], [np.nan, 1.0], [np.inf, 0.0]],
                                ring if trial % 3 == 0 else np.empty((0, 2))])
        angle, slack = np.radians(rng.uniform(0.5, 3)), rng.uniform(0, 1)
        n_layers = int(rng.integers(1, 6))  # a planar scan (1), or a 3D scanner's elevation layers
        point_layers = rng.integers(0, n_layers, len(points))
        scene_layers = rng.integers(0, n_layers, len(scene))
        ends, out = np.empty((len(clusters), 2), np.int64), np.empty((len(clusters), 2))
        K.beyond_ends(points, point_layers, starts, scene, scene_layers, n_layers, sx, sy, BINS, angle, slack, ends,
                      out)
        want_ends, want = _beyond_reference(points, point_layers, starts, scene, scene_layers, n_layers, sx, sy, angle,
                                            slack)
        np.testing.assert_array_equal(ends, want_ends)
        np.testing.assert_array_equal(out, want)
        hidden += np.isfinite(out).sum()
        total += out.size
    assert 0.1 * total < hidden < 0.9 * total  # both outcomes occur


def _promoted_reference(pts, moving, blocked, res, H, W, reach, max_span):
    """Whole components (cells within ``reach`` of each other, found by a k-d tree), then the rule."""
    cells = np.floor(pts / res).astype(int)
    inside = (cells >= 0).all(axis=1) & (cells[:, 0] < W) & (cells[:, 1] < H)
    occupied, index = np.unique(cells[inside], axis=0, return_inverse=True)
    pairs = cKDTree(occupied).query_pairs(reach + 0.5, p=np.inf, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(occupied),) * 2)
    _, comp = connected_components(graph, directed=False)
    comp_of_point = comp[index.reshape(-1)]
    n = comp.max() + 1
    n_all = np.bincount(comp_of_point, minlength=n)
    n_mov = np.bincount(comp_of_point, weights=moving[inside], minlength=n)
    lo = np.full((n, 2), np.iinfo(int).max)
    hi = np.full((n, 2), -1)
    np.minimum.at(lo, comp, occupied)
    np.maximum.at(hi, comp, occupied)
    span = res * np.hypot(*(hi - lo + 1).T)
    good = (n_mov > 0) & (2 * n_mov >= n_all) & (span <= max_span)
    out = np.zeros(len(pts), bool)
    out[inside] = good[comp_of_point]
    return out & ~blocked


def test_promotion_equals_whole_components_and_leaves_the_scratch_clear():
    rng = np.random.default_rng(0)
    H, W, res, reach = 60, 70, 0.1, 3
    grid = np.zeros((3, H, W), np.int32)
    promoted = 0
    for trial in range(60):
        n = int(rng.integers(10, 600))
        pts = rng.uniform(-0.5, 7.5, (n, 2))
        if trial % 2:  # a long wall that movers pass along
            pts[: n // 2] = np.column_stack([rng.uniform(0, 6, n // 2), np.full(n // 2, rng.uniform(0, 6))])
        moving = rng.random(n) < rng.uniform(0.1, 0.9)
        blocked = rng.random(n) < 0.1
        max_span = rng.uniform(0.5, 4)
        out = np.empty(n, bool)
        K.promote_components(pts, moving, blocked, 0.0, 0.0, res, reach, max_span, grid, out)
        np.testing.assert_array_equal(out, _promoted_reference(pts, moving, blocked, res, H, W, reach, max_span))
        assert not grid.any()
        promoted += out.sum()
    assert promoted > 1000


def test_stable_order_is_numpys_stable_argsort():
    rng = np.random.default_rng(7)
    for n, top in ((0, 1), (1, 1), (7, 1), (1_000, 255), (1_000, 256), (20_000, 40_000), (5_000, 2 ** 62)):
        key = rng.integers(0, top, n, dtype=np.int64)  # many equal keys where top is small
        np.testing.assert_array_equal(K.stable_order(key), np.argsort(key, kind="stable"))
