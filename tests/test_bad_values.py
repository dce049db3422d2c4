"""Bad values reaching the maps (issue 15): refused with a clear error, or dropped and counted,
never a silently wrong map or a crash deep inside."""

from __future__ import annotations

import numpy as np
import pytest

from occmap.cli import main
from occmap.errors import InvalidArgumentError, OccmapError
from occmap.grid2d import OccupancyGrid2D

ANGLES = np.linspace(-np.pi / 2, np.pi / 2, 5)


# ---------------------------------------------------------------- 1. a growing grid's extent


def test_growing_grid_refuses_an_outlier_pose_naming_it():
    g = OccupancyGrid2D(0.05)
    g.insert_scan((0.0, 0.0, 0.0), np.full(5, 2.0), ANGLES)
    before = (g.shape, g.origin.copy(), g.log_odds().copy())
    poses = np.array([[0.5, 0.0, 0.0], [1e7, 0.0, 0.0], [1.0, 0.0, 0.0]])
    with pytest.raises(InvalidArgumentError, match=r"poses\[1\] = \[10000000\.0, 0\.0, 0\.0\].*max_extent"):
        g.insert_scans(poses, np.full((3, 5), 2.0), ANGLES)
    assert g.shape == before[0] and np.array_equal(g.origin, before[1])  # nothing changed
    assert np.array_equal(g.log_odds(), before[2], equal_nan=True)


def test_growing_grid_refuses_65_km_and_names_a_long_beam():
    g = OccupancyGrid2D(0.05)
    with pytest.raises(InvalidArgumentError, match=r"poses\[1\] = \[65000\.0"):
        g.insert_scans(np.array([[0.0, 0.0, 0.0], [65e3, 0.0, 0.0]]), np.full((2, 5), 2.0), ANGLES)
    ranges = np.full(5, 2.0)
    ranges[3] = 20e3
    with pytest.raises(InvalidArgumentError, match=r"beam 3 of scan 0 .*ranges\[0, 3\] = 20000\.0"):
        OccupancyGrid2D(0.05).insert_scan((0.0, 0.0, 0.0), ranges, ANGLES)


def test_growing_grid_max_extent_is_an_option_and_the_margin_stays_inside_it():
    g = OccupancyGrid2D(0.05, max_extent=None)
    g.insert_scans(np.array([[0.0, 0.0, 0.0], [12e3, 0.0, 0.0]]), np.full((2, 5), 1.0), ANGLES)
    assert g.shape[1] * 0.05 > 12e3
    small = OccupancyGrid2D(0.1, max_extent=20.0)
    small.insert_scan((0.0, 0.0, 0.0), np.full(5, 5.0), ANGLES)
    small.insert_scan((9.0, 0.0, 0.0), np.full(5, 5.0), ANGLES)  # content 19 m wide: fits
    assert max(small.shape) * 0.1 <= 20.0 + 1e-9
    with pytest.raises(InvalidArgumentError, match="max_extent"):
        small.insert_scan((30.0, 0.0, 0.0), np.full(5, 1.0), ANGLES)
    with pytest.raises(InvalidArgumentError, match="max_extent"):
        OccupancyGrid2D(0.1, max_extent=float("nan"))


def test_growing_grid_sonar_outlier_named():
    g = OccupancyGrid2D(0.05)
    with pytest.raises(InvalidArgumentError, match=r"poses\[1\] = \[10000000\.0"):
        g.insert_sonar(np.array([[0.0, 0.0, 0.0], [1e7, 0.0, 0.0]]), np.full((2, 2), 1.0), np.array([0.0, 1.0]),
                       max_range=3.0)


def _carmen_with_outlier(path, x):
    lines = []
    for i in range(4):
        px = x if i == 2 else 0.1 * i
        ranges = " ".join(["2.0"] * 5)
        lines.append(f"FLASER 5 {ranges} {px} 0.0 0.0 {px} 0.0 0.0 {i}.0 host {i}.0")
    path.write_text("\n".join(lines) + "\n")
    return path


def test_map2d_outlier_pose_one_line_exit_2(tmp_path, capsys):
    log = _carmen_with_outlier(tmp_path / "outlier.log", 1e7)
    code = main(["map2d", str(log), "-o", str(tmp_path / "m.yaml")])
    err = capsys.readouterr().err.strip()
    assert code == 2
    errors = [line for line in err.splitlines() if ": note: " not in line]  # (notes say what was assumed)
    assert len(errors) == 1 and "poses[2]" in errors[0] and "max_extent" in err and "Traceback" not in err
    assert not (tmp_path / "m.yaml").exists()
    # the option lifts the limit
    assert main(["map2d", str(log), "-o", str(tmp_path / "m.yaml"), "--max-extent", "2e7",
                 "--resolution", "1000"]) == 0


# ---------------------------------------------------------------- 2. NaN origin, NaN angles


@pytest.mark.parametrize("origin", [(np.nan, np.nan), (0.0, np.inf), (-np.inf, 0.0)])
@pytest.mark.parametrize("size", [None, (2.0, 2.0)])
def test_grid_refuses_a_non_finite_origin(origin, size):
    with pytest.raises(InvalidArgumentError, match="origin"):
        OccupancyGrid2D(0.1, size=size, origin=origin)


@pytest.mark.parametrize("size", [None, (8.0, 8.0)])
def test_grid_drops_and_counts_non_finite_beam_angles(size):
    angles = ANGLES.copy()
    angles[1], angles[3] = np.nan, np.inf
    g = OccupancyGrid2D(0.1, size=size, origin=None if size is None else (-4.0, -4.0))
    counts = g.insert_scan((0.0, 0.0, 0.0), np.full(5, 2.0), angles, max_range=3.0)
    assert counts["points"] == 3 and counts["dropped"] == 2
    ref = OccupancyGrid2D(0.1, size=size, origin=None if size is None else (-4.0, -4.0))
    ref.insert_scan((0.0, 0.0, 0.0), np.full(3, 2.0), ANGLES[[0, 2, 4]], max_range=3.0)
    assert np.array_equal(g.log_odds(), ref.log_odds(), equal_nan=True)


# ---------------------------------------------------------------- 3. octree bbx and cast_ray


def _cloud():
    return np.random.default_rng(0).uniform(-3.0, 3.0, (200, 3))


def _leaves(tree):
    lv = tree.leaves()
    order = np.lexsort(lv.centers.T)
    return lv.centers[order], lv.log_odds[order]


def test_octree_bbx_corner_of_1e300_keeps_the_scan():
    from occmap.octree import OcTree

    plain, huge, half, half_ref = OcTree(0.1), OcTree(0.1), OcTree(0.1), OcTree(0.1)
    huge.bbx = ((-1e300, -1e300, -1e300), (1e300, 1e300, 1e300))
    half.bbx = ((-1e300, -1e300, -1e300), (0.0, 1e300, 1e300))
    half_ref.bbx = ((-1e4, -1e4, -1e4), (0.0, 1e4, 1e4))
    for t in (plain, huge, half, half_ref):
        t.insert_point_cloud(_cloud(), (0.0, 0.0, 0.0))
    assert plain.num_leaves() > 0
    for a, b in ((plain, huge), (half_ref, half)):
        ca, va = _leaves(a)
        cb, vb = _leaves(b)
        assert np.array_equal(ca, cb) and np.array_equal(va, vb)
    assert len(plain.leaves(bbx_min=(-1e300,) * 3, bbx_max=(1e300,) * 3).log_odds) == plain.num_leaves()


@pytest.mark.parametrize("direction", [(np.nan, 0.0, 0.0), (1.0, np.nan, 0.0), (np.inf, 0.0, 0.0), (1.0, 0.0, -np.inf)])
@pytest.mark.parametrize("ignore_unknown", [False, True])
def test_octree_cast_ray_with_a_non_finite_direction_has_no_end(direction, ignore_unknown):
    from occmap.octree import OcTree

    t = OcTree(0.1)
    t.insert_point_cloud(np.array([[2.0, 0.05, 0.05]]), (0.05, 0.05, 0.05))
    hit, ends = t.cast_ray((0.05, 0.05, 0.05), [direction, (1.0, 0.0, 0.0)], ignore_unknown=ignore_unknown)
    assert hit.tolist() == [False, True]
    assert np.isnan(ends[0]).all() and np.isfinite(ends[1]).all()


# ---------------------------------------------------------------- 4. LocalMap.move_to far away


@pytest.mark.parametrize("far", [1e18, 1e300, -1e18])
def test_local_map_refuses_a_position_it_cannot_index_and_keeps_working(far):
    from occmap.local import LocalMap

    m = LocalMap(size=(10.0, 10.0), resolution=0.1)
    with pytest.raises(InvalidArgumentError, match="position"):
        m.move_to(far, 0.0)
    with pytest.raises(InvalidArgumentError, match="position"):
        LocalMap(size=(10.0, 10.0), resolution=0.1, center=(0.0, far))
    m.insert_scan((0.0, 0.0, 0.0), np.full(5, 2.0), ANGLES, max_range=4.0, stamp=0.0)
    assert (m.occupancy() > 50).any()
    far_but_fine = LocalMap(size=(10.0, 10.0), resolution=0.1)
    far_but_fine.move_to(1e9, -1e9)
    far_but_fine.insert_scan((1e9, -1e9, 0.0), np.full(5, 2.0), ANGLES, max_range=4.0, stamp=0.0)
    assert (far_but_fine.occupancy() > 50).any()


def test_local_map_drops_and_counts_non_finite_beam_angles():
    from occmap.local import LocalMap

    angles = ANGLES.copy()
    angles[1], angles[3] = np.nan, np.inf
    m, ref = LocalMap(size=(10.0, 10.0), resolution=0.1), LocalMap(size=(10.0, 10.0), resolution=0.1)
    counts = m.insert_scan((0.0, 0.0, 0.0), np.full(5, 2.0), angles, stamp=0.0, max_range=4.0)
    ref.insert_scan((0.0, 0.0, 0.0), np.full(3, 2.0), ANGLES[[0, 2, 4]], stamp=0.0, max_range=4.0)
    assert counts["dropped"] == 2 and counts["rays"] == 3
    assert np.array_equal(m.log_odds(), ref.log_odds(), equal_nan=True)


# ---------------------------------------------------------------- 5. the localizer far away


def test_localizer_far_away_is_a_clear_error():
    from occmap.localize import MonteCarloLocalizer

    angles = np.linspace(-3.0, 3.0, 50)
    g = OccupancyGrid2D(0.1, size=(10.0, 10.0), origin=(-5.0, -5.0))
    for _ in range(5):
        g.insert_scan((0.0, 0.0, 0.0), np.full(50, 3.0), angles)
    m = MonteCarloLocalizer(g, 100, seed=0)
    with pytest.raises(OccmapError, match="pose"):
        m.initialize((1e300, 0.0, 0.0))
    m.initialize((0.0, 0.0, 0.0))
    with pytest.raises(OccmapError, match="odometry_pose"):
        m.update((1e300, 0.0, 0.0), np.full(50, 3.0), angles, max_range=4.0)
    far = OccupancyGrid2D(0.1, size=(10.0, 10.0), origin=(1e300, 0.0))
    far._L[...], far._stamp[...] = g._L, g._stamp
    with pytest.raises(OccmapError, match="map"):
        MonteCarloLocalizer(far, 100, seed=0)
