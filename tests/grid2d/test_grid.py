"""OccupancyGrid2D: the log-odds Bayes filter, per-scan update rules, growth and read-outs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from occmap.errors import InvalidArgumentError, NonFiniteError, ShapeError
from occmap.grid2d import LidarModel, OccupancyGrid2D
from occmap.logodds import logit
from occmap.grid2d import _kernels as K

L_HIT, L_MISS, L_MAX, L_MIN = logit(0.7), logit(0.4), logit(0.971), logit(0.1192)


def single_beam(grid, r, max_range=None, pose=(0.05, 0.05, 0.0)):
    return grid.insert_scan(pose, [r], [0.0], max_range=max_range)


def test_one_beam_frees_the_cells_before_its_end_and_hits_the_end_cell():
    g = OccupancyGrid2D(0.1, size=(2.0, 1.0))
    single_beam(g, 1.0)  # from the centre of cell (0, 0) to the centre of cell (0, 10)
    row = g.log_odds()[0]
    np.testing.assert_allclose(row[:10], L_MISS, rtol=1e-6)
    assert row[10] == pytest.approx(L_HIT, rel=1e-6)
    assert (g.occupancy()[0, 11:] == -1).all() and (g.occupancy()[1:] == -1).all()


def test_hit_wins_over_miss_and_each_cell_is_updated_once_per_scan():
    g = OccupancyGrid2D(0.1, size=(3.0, 3.0))
    # beam 0 ends in cell (0, 10); beam 1, on the same line, passes through it to (0, 20);
    # 50 beams all cross the sensor's neighbouring cells
    angles = np.concatenate([[0.0, 0.0], np.linspace(-0.01, 0.01, 50)])
    ranges = np.concatenate([[1.0, 2.0], np.full(50, 1.5)])
    g.insert_scan((0.05, 0.05, 0.0), ranges, angles, max_range=5.0)
    assert g.log_odds()[0, 10] == pytest.approx(L_HIT, rel=1e-6)
    assert g.log_odds()[0, 1] == pytest.approx(L_MISS, rel=1e-6)  # crossed by 52 beams, updated once


def test_max_range_and_infinite_readings_clear_without_marking():
    g = OccupancyGrid2D(0.1, size=(3.0, 1.0))
    counts = g.insert_scan((0.05, 0.05, 0.0), [2.5, np.inf], [0.0, 0.0], max_range=2.0)
    assert counts["beyond_max_range"] == 2 and counts["dropped"] == 0
    row = g.log_odds()[0]
    np.testing.assert_allclose(row[:20], L_MISS, rtol=1e-6)  # free up to 2.0 m, end cell excluded
    assert not g.observed[0, 20:].any() and not (row > 0).any()


def test_invalid_readings_are_dropped_and_counted():
    g = OccupancyGrid2D(0.1, size=(2.0, 2.0))
    counts = g.insert_scan((1.0, 1.0, 0.0), [np.nan, -1.0, 0.0, 0.5], [0.0, 0.5, 1.0, 1.5])
    assert counts == {"scans": 1, "points": 1, "dropped": 3, "beyond_max_range": 0}
    assert g.stats["dropped"] == 3


def test_clamping_bounds():
    g = OccupancyGrid2D(0.1, size=(2.0, 1.0))
    for _ in range(20):
        single_beam(g, 1.0)
    assert g.log_odds()[0, 10] == pytest.approx(L_MAX, rel=1e-6)
    assert g.log_odds()[0, 5] == pytest.approx(L_MIN, rel=1e-6)


def test_a_moving_object_is_free_again_after_ceil_lmax_over_lmiss_scans():
    """Seen for 10 scans the cell saturates at l_max; each later scan through it adds l_miss, so it
    reads free (l ≤ 0) after exactly ceil(l_max / |l_miss|) scans (9 with OctoMap's defaults)."""
    g = OccupancyGrid2D(0.1, size=(3.0, 1.0))
    for _ in range(10):
        single_beam(g, 1.0)  # the object in cell (0, 10)
    expected = math.ceil(L_MAX / -L_MISS)
    assert expected == 9
    for k in range(1, expected + 1):
        single_beam(g, 2.0)  # the object has gone: the beam now passes through its cell
        assert (g.maximum_likelihood()[0, 10] == 0) == (k >= expected)


def test_batched_integration_equals_one_scan_at_a_time(rng):
    poses = np.column_stack([rng.uniform(-2, 2, 20), rng.uniform(-2, 2, 20), rng.uniform(-np.pi, np.pi, 20)])
    angles = np.linspace(-np.pi / 2, np.pi / 2, 91)
    ranges = rng.uniform(0.2, 4.0, (20, 91))
    ranges[rng.random((20, 91)) < 0.05] = 5.0
    a = OccupancyGrid2D(0.05, size=(12.0, 12.0), origin=(-6.0, -6.0))
    b = OccupancyGrid2D(0.05, size=(12.0, 12.0), origin=(-6.0, -6.0))
    a.insert_scans(poses, ranges, angles, max_range=5.0)
    for p, r in zip(poses, ranges):
        b.insert_scan(p, r, angles, max_range=5.0)
    np.testing.assert_array_equal(a.log_odds(), b.log_odds())
    np.testing.assert_array_equal(a.observed, b.observed)


def test_scans_past_the_stamp_codes_equal_wide_stamps(rng):
    """The grid's 16-bit stamps run out of scan codes every 32,767 scans and start again; 70,000
    small scans from nearby poses, in one call and in calls of uneven sizes, give the same cells
    as the kernel with 32-bit stamps and scan ids 1..70,000 (an old stamp mistaken for "already
    updated in this scan" would skip updates)."""
    n = 70_000
    poses = np.column_stack([rng.uniform(-0.3, 0.3, n), rng.uniform(-0.3, 0.3, n), rng.uniform(-np.pi, np.pi, n)])
    angles = np.linspace(-np.pi, np.pi, 6, endpoint=False)
    ranges = rng.uniform(0.3, 1.2, (n, 6))
    one = OccupancyGrid2D(0.05, size=(3.0, 3.0), origin=(-1.5, -1.5))
    one.insert_scans(poses, ranges, angles, max_range=1.0)
    split = OccupancyGrid2D(0.05, size=(3.0, 3.0), origin=(-1.5, -1.5))
    for i, j in ((0, 1), (1, 32_766), (32_766, 32_768), (32_768, 65_535), (65_535, 65_536), (65_536, n)):
        split.insert_scans(poses[i:j], ranges[i:j], angles, max_range=1.0)
    L = np.zeros(one.shape, np.float32)
    S = np.zeros(one.shape, np.int32)
    K.integrate_lidar(L, S, 1, poses, ranges, np.ascontiguousarray(np.broadcast_to(angles, ranges.shape)), 1.0,
                      -1.5, -1.5, 0, 0, 20.0, L_HIT, L_MISS, L_MIN, L_MAX)
    for g in (one, split):
        np.testing.assert_array_equal(g.log_odds().view(np.int32), np.where(S != 0, L, np.float32(np.nan)).view(np.int32))
        np.testing.assert_array_equal(g.observed, S != 0)


def test_growing_map_keeps_content_and_alignment(rng):
    g = OccupancyGrid2D(0.05)
    angles = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    g.insert_scan((0.0, 0.0, 0.0), np.full(360, 1.5), angles)
    probe = rng.uniform(-1.6, 1.6, (500, 2))
    before = g.log_odds_at(probe)
    g.insert_scan((30.0, -20.0, 0.0), np.full(360, 1.5), angles)  # far away: the map must grow
    after = g.log_odds_at(probe)
    np.testing.assert_array_equal(np.isnan(before), np.isnan(after))
    np.testing.assert_array_equal(before[~np.isnan(before)], after[~np.isnan(after)])
    assert np.allclose(g.origin / 0.05, np.round(g.origin / 0.05))  # still on the same cell lattice
    assert g.log_odds_at([[30.0 + 1.5, -20.0]])[0] == pytest.approx(L_HIT, rel=1e-6)


def test_only_calls_into_storage_already_there_are_samples_of_the_kernels_cost(monkeypatch):
    samples = []
    choose = K.THREADS.choose

    def recorded(work, sample=True):
        samples.append(sample)
        return choose(work, sample)

    monkeypatch.setattr(K.THREADS, "choose", recorded)
    g = OccupancyGrid2D(0.05)
    angles = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    for pose in ((0.0, 0.0, 0.0), (0.5, 0.0, 0.0), (60.0, 0.0, 0.0), (60.5, 0.0, 0.0)):
        g.insert_scan(pose, np.full(360, 3.0), angles)
    assert samples == [False, True, False, True]  # the first call, and the one that grew the map, are not


def test_fixed_map_ignores_ray_parts_outside():
    g = OccupancyGrid2D(0.1, size=(1.0, 1.0))
    counts = g.insert_scan((-5.0, 0.55, 0.0), [10.0], [0.0])  # starts outside, crosses, ends outside
    assert counts["points"] == 1
    np.testing.assert_allclose(g.log_odds()[5], L_MISS, rtol=1e-6)


def test_world_cell_conversions_and_occupancy_values():
    g = OccupancyGrid2D(0.1, size=(2.0, 1.0), origin=(-1.0, 0.0))
    assert g.shape == (10, 20)
    np.testing.assert_array_equal(g.world_to_cell([[-0.95, 0.05], [0.95, 0.95]]), [[0, 0], [9, 19]])
    np.testing.assert_allclose(g.cell_to_world([[0, 0], [9, 19]]), [[-0.95, 0.05], [0.95, 0.95]])
    single_beam(g, 1.0, pose=(-0.95, 0.05, 0.0))
    occ = g.occupancy()
    assert occ[0, 0] == round(100 * 0.4) and occ[0, 10] == 70 and occ[5, 5] == -1


def test_bad_input():
    with pytest.raises(InvalidArgumentError):
        OccupancyGrid2D(0.0)
    with pytest.raises(InvalidArgumentError):
        OccupancyGrid2D(0.1, prior=0.99)
    g = OccupancyGrid2D(0.1)
    with pytest.raises(NonFiniteError):
        g.insert_scan((np.nan, 0.0, 0.0), [1.0], [0.0])
    with pytest.raises(ShapeError):
        g.insert_scans(np.zeros((2, 3)), np.ones((3, 5)), np.zeros(5))
    with pytest.raises(ShapeError):
        g.insert_scan((0.0, 0.0, 0.0), [1.0, 2.0], [0.0, 0.1, 0.2])
    with pytest.raises(InvalidArgumentError):
        LidarModel(prob_hit=0.4)


def test_save_load_round_trip_keeps_the_trinary_map(tmp_path, rng):
    g = OccupancyGrid2D(0.05, size=(6.0, 4.0), origin=(-3.0, -1.0))
    poses = np.column_stack([rng.uniform(-2, 2, 10), rng.uniform(0, 2, 10), rng.uniform(-np.pi, np.pi, 10)])
    g.insert_scans(poses, rng.uniform(0.3, 2.5, (10, 90)), np.linspace(-np.pi, np.pi, 90, endpoint=False))
    g.save(tmp_path / "map.yaml")
    h = OccupancyGrid2D.load(tmp_path / "map.yaml")
    assert h.shape == g.shape and np.allclose(h.origin, g.origin) and h.resolution == g.resolution
    # the map_server rules give back exactly the trinary classes that were written
    occ = g.occupancy()
    trinary = np.where(occ < 0, -1, np.where(occ >= 65, 100, np.where(occ <= 19, 0, -1)))
    np.testing.assert_array_equal(h.occupancy() >= 50, trinary == 100)
    np.testing.assert_array_equal(h.observed, trinary >= 0)
    np.testing.assert_array_equal(h.maximum_likelihood()[trinary >= 0], (trinary[trinary >= 0] == 100).astype(np.int8))
    # a loaded map keeps integrating scans
    h.insert_scan((0.0, 1.0, 0.0), [1.0], [0.0])


def test_log_odds_is_a_copy_with_nan_where_unobserved_and_occupancy_at_follows_the_threshold():
    g = OccupancyGrid2D(0.1, size=(2.0, 1.0), occupied_threshold=0.65)
    single_beam(g, 1.0)
    L = g.log_odds()
    assert L.dtype == np.float32 and np.isnan(L[~g.observed]).all() and not np.isnan(L[g.observed]).any()
    L[0, 10] = 0.0
    assert g.log_odds()[0, 10] == pytest.approx(L_HIT, rel=1e-6)  # a copy: the map is untouched
    # cell centres along row 0: free before the end cell, occupied (0.7 ≥ 0.65) at it, unknown after
    at = g.occupancy_at([[0.05 + 0.1 * i, 0.05] for i in range(12)] + [[-1.0, 0.05], [np.nan, 0.05]])
    assert at.dtype == np.int8 and at.tolist() == [0] * 10 + [1, -1, -1, -1]
    assert OccupancyGrid2D(0.1, size=(2.0, 1.0), occupied_threshold=0.75).occupancy_at([[0.05, 0.05]]).tolist() == [-1]
    g75 = OccupancyGrid2D(0.1, size=(2.0, 1.0), occupied_threshold=0.75)
    single_beam(g75, 1.0)
    assert g75.occupancy_at([[1.05, 0.05]]).tolist() == [0]  # 0.7 < 0.75


def _wandering_scans(rng, n, start=(0.0, 0.0)):
    """n scans along a random walk that keeps leaving the map (so it grows many times)."""
    steps = rng.normal(0.0, 1.5, (n, 2))
    xy = np.asarray(start) + np.cumsum(steps, axis=0)
    poses = np.column_stack([xy, rng.uniform(-np.pi, np.pi, n)])
    ranges = rng.uniform(0.3, 6.0, (n, 90))
    ranges[rng.random(ranges.shape) < 0.05] = np.inf
    return poses, ranges, np.linspace(-np.pi, np.pi, 90, endpoint=False)


@pytest.mark.parametrize("start", [(0.0, 0.0), (10_003.3, -7.71)])
def test_a_growing_map_does_not_depend_on_how_its_scans_were_chunked(rng, start):
    poses, ranges, angles = _wandering_scans(rng, 200, start)
    maps = []
    for chunk in (1, 7, 200):
        g = OccupancyGrid2D(0.05)
        for i in range(0, len(poses), chunk):
            g.insert_scans(poses[i:i + chunk], ranges[i:i + chunk], angles, max_range=5.0)
        maps.append(g)
    for g in maps[1:]:
        assert g.shape == maps[0].shape
        np.testing.assert_array_equal(g.origin, maps[0].origin)
        np.testing.assert_array_equal(g.log_odds().view(np.int32), maps[0].log_odds().view(np.int32))


def test_a_growing_map_lies_on_the_world_lattice(rng):
    poses, ranges, angles = _wandering_scans(rng, 30, (3.0, -2.0))
    g = OccupancyGrid2D(0.05)
    g.insert_scans(poses, ranges, angles, max_range=5.0)
    ix, iy = np.round(g.origin / 0.05)
    np.testing.assert_array_equal(g.origin, np.array([ix, iy]) * 0.05)  # an integer cell offset
    # the cell of a point is floor(x / res) of the world, whatever the map's extent
    p = rng.uniform(-2.0, 8.0, (1000, 2)) + poses[0, :2]
    cells = g.world_to_cell(p)
    np.testing.assert_array_equal(cells[:, ::-1] + [ix, iy], np.floor(p * (1.0 / 0.05)))


def test_log_odds_in_reads_a_box_of_a_growing_map_as_the_whole_map_has_it():
    grid = OccupancyGrid2D(0.1)
    grid.insert_scans(np.array([[0.0, 0.0, 0.0], [3.0, 1.0, 1.0]]), np.full((2, 90), 2.5),
                      np.linspace(-np.pi, np.pi, 90, endpoint=False), max_range=4.0)
    whole = grid.log_odds()
    window, corner = grid.log_odds_in((0.0, -1.0), (2.0, 0.5))
    (iy0, ix0) = grid.world_to_cell(np.array([0.0, -1.0]))
    assert corner.tolist() == pytest.approx((grid.origin + 0.1 * np.array([ix0, iy0])).tolist())
    assert window.shape == (16, 21)
    np.testing.assert_array_equal(window, whole[iy0:iy0 + 16, ix0:ix0 + 21])
    clipped, _ = grid.log_odds_in((-100.0, -100.0), (100.0, 100.0))
    np.testing.assert_array_equal(clipped, whole)
    assert grid.log_odds_in((50.0, 50.0), (60.0, 60.0))[0].size == 0
