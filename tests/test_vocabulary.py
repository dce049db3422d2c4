"""The three maps name the same things the same way (docs/architecture.md): insertion counts and
stats keys, log-odds and occupancy read-outs."""

from __future__ import annotations

import numpy as np

from occmap import LocalMap, OccupancyGrid2D, OcTree

COUNTS = {"scans", "points", "dropped", "beyond_max_range"}


def test_insertions_return_and_record_the_same_counts():
    angles = np.array([0.0, 0.5, 1.0])
    ranges = np.array([1.0, np.nan, 9.0])
    grid = OccupancyGrid2D(0.1)
    local = LocalMap((4.0, 4.0), 0.1)
    tree = OcTree(0.1)
    outs = [grid.insert_scan((0.0, 0.0, 0.0), ranges, angles, max_range=5.0),
            local.insert_scan((0.0, 0.0, 0.0), ranges, angles, stamp=0.0, max_range=5.0),
            tree.insert_point_cloud([[1.0, 0.0, 0.0], [np.nan, 0.0, 0.0], [9.0, 0.0, 0.0]], (0.0, 0.0, 0.0), 5.0)]
    for out in outs:
        assert COUNTS <= out.keys()
        assert out["scans"] == 1 and out["dropped"] == 1 and out["beyond_max_range"] == 1
    assert COUNTS <= grid.stats.keys() and COUNTS <= local.stats.keys() and COUNTS - {"beyond_max_range"} <= tree.stats.keys()
    cloud = local.insert_point_cloud(np.array([[1.0, 1.0, 0.5], [np.inf, 0.0, 0.0]]), (0.0, 0.0), 0.1, 0.0, 1.0)
    assert COUNTS <= cloud.keys() and cloud["dropped"] == 1


def test_read_outs_share_names_and_contract():
    """log_odds_at: NaN unknown; occupancy_at: −1 unknown, 0 free, 1 occupied; the same answer
    from each map for one beam along +x."""
    grid = OccupancyGrid2D(0.1, size=(4.0, 2.0), origin=(-2.0, -1.0))
    local = LocalMap((4.0, 2.0), 0.1)
    tree = OcTree(0.1)
    grid.insert_scan((0.05, 0.05, 0.0), [1.0], [0.0], max_range=5.0)
    local.insert_scan((0.05, 0.05, 0.0), [1.0], [0.0], stamp=0.0, max_range=5.0)
    tree.insert_point_cloud([[1.05, 0.05, 0.05]], (0.05, 0.05, 0.05))
    xy = np.array([[0.55, 0.05], [1.05, 0.05], [1.55, 0.05]])  # free, the hit, beyond it
    xyz = np.column_stack([xy, np.full(3, 0.05)])
    for m, p in ((grid, xy), (local, xy), (tree, xyz)):
        assert m.occupancy_at(p).tolist() == [0, 1, -1]
        l = m.log_odds_at(p)
        assert l[0] < 0 < l[1] and np.isnan(l[2])
