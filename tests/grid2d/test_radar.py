"""RadarModel / insert_radar: the ray and the occupied band of one detection, moving reflectors,
multipath ghosts behind known walls, bad detections, batch = stream, and the simulated street
against its truth (precision and recall of the occupied cells)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.ndimage import binary_dilation

from occmap.errors import InvalidArgumentError, NonFiniteError, ShapeError
from occmap.grid2d import OccupancyGrid2D, RadarModel
from occmap.logodds import logit
from occmap.sim.street import Street

MODEL = RadarModel()


def grid():
    return OccupancyGrid2D(0.1, size=(20.0, 20.0), origin=(-10.0, -10.0))


def lo(g, x, y):
    return float(g.log_odds_at([[x, y]])[0])


def test_one_detection_clears_its_ray_and_marks_its_band_below_the_occupied_threshold():
    g = grid()
    counts = g.insert_radar((0.0, 0.0, 0.0), [5.05], [0.0], max_range=60.0)
    assert counts == {"scans": 1, "points": 1, "dropped": 0, "beyond_max_range": 0, "moving": 0, "ghosts": 0}
    assert lo(g, 2.05, 0.05) == pytest.approx(logit(MODEL.prob_miss) * math.exp(-0.5 * (0.05 / 0.05) ** 2), rel=1e-5)
    # the cell of the point (offset 0.05 across, 0 along): the full hit but for the cross Gaussian
    assert lo(g, 5.05, 0.05) == pytest.approx(logit(MODEL.prob_hit) * math.exp(-0.5), rel=1e-5)
    assert 0 < lo(g, 5.25, 0.05) < lo(g, 5.15, 0.05) < lo(g, 5.05, 0.05)  # the band fades with the range offset
    assert math.isnan(lo(g, 5.45, 0.05))  # beyond 2σ of range: untouched
    assert math.isnan(lo(g, 2.05, 0.25))  # beside the ray
    assert math.isnan(lo(g, -1.0, 0.05))  # behind the sensor
    # one detection is not an obstacle in the saved map (clutter); two at the same place are
    assert lo(g, 5.05, 0.05) < logit(0.65)
    g.insert_radar((0.0, 0.0, 0.0), [5.05], [0.0], max_range=60.0)
    assert lo(g, 5.05, 0.05) >= logit(0.65)


def test_azimuth_and_pose_place_the_detection():
    g = grid()
    g.insert_radar((1.0, -2.0, math.pi / 2), [4.0, 4.0], [0.0, math.pi / 2], max_range=60.0)
    assert lo(g, 1.05, 2.05) > 0 and lo(g, -2.95, -1.95) > 0  # ahead (+y) and to the left (−x)
    assert lo(g, 1.05, 0.05) < 0 and lo(g, -0.95, -1.95) < 0


def test_moving_reflectors_only_clear():
    g = grid()
    # sensor driving +x at 10 m/s; a reflector ahead closing at 10 m/s is static, one closing at
    # 20 m/s moves at 10 m/s towards the sensor
    counts = g.insert_radar((0.0, 0.0, 0.0), [5.0, 5.0], [0.0, math.pi / 2], max_range=60.0,
                            radial_velocity=[-20.0, 0.0], ego_velocity=(10.0, 0.0))
    assert counts["moving"] == 1 and counts["points"] == 2
    assert lo(g, 2.05, 0.05) < 0 and math.isnan(lo(g, 5.05, 0.05))  # cleared, not marked
    assert lo(g, 0.05, 5.05) > 0  # abeam, radial velocity 0 while driving past: static
    g2 = grid()
    g2.insert_radar((0.0, 0.0, 0.0), [5.0], [0.0], max_range=60.0, radial_velocity=[-10.0], ego_velocity=(10.0, 0.0))
    assert lo(g2, 5.05, 0.05) > 0  # closing exactly at the ego speed: static


def test_a_detection_behind_a_known_wall_is_a_ghost():
    g = grid()
    for _ in range(4):
        g.insert_radar((0.0, 0.0, 0.0), [5.05], [0.0], max_range=60.0)
    wall = lo(g, 5.05, 0.05)
    assert wall >= logit(MODEL.obstacle_probability)
    counts = g.insert_radar((0.0, 0.0, 0.0), [8.05], [0.0], max_range=60.0)
    assert counts["ghosts"] == 1 and counts["points"] == 0
    assert lo(g, 5.05, 0.05) == wall and math.isnan(lo(g, 8.05, 0.05)) and math.isnan(lo(g, 6.5, 0.05))
    # within the margin the detection is of the wall: the wall is not cleared, nothing beyond it marked
    g.insert_radar((0.0, 0.0, 0.0), [5.6], [0.0], max_range=60.0)
    assert lo(g, 5.05, 0.05) >= wall and math.isnan(lo(g, 5.55, 0.05))


def test_bad_detections_are_dropped_and_counted():
    g = grid()
    counts = g.insert_radar((0.0, 0.0, 0.0), [np.nan, -1.0, 0.0, np.inf, 3.0, 3.0, 3.0, 70.0],
                            [0.0, 0.0, 0.0, 0.0, np.nan, 0.5, 0.0, 0.0], max_range=60.0,
                            radial_velocity=[0.0, 0.0, 0.0, 0.0, 0.0, np.nan, 0.0, 0.0], ego_velocity=(0.0, 0.0))
    assert counts == {"scans": 1, "points": 1, "dropped": 6, "beyond_max_range": 1, "moving": 0, "ghosts": 0}
    assert g.stats["dropped"] == 6 and g.stats["beyond_max_range"] == 1
    assert np.isfinite(g.log_odds()[g.observed]).all()


def test_bad_calls_raise_naming_the_argument():
    g = grid()
    with pytest.raises(InvalidArgumentError, match=r"sweeps\[1\] = 2"):
        g.insert_radar(np.zeros((2, 3)), [1.0, 1.0], [0.0, 0.0], 60.0, sweeps=[0, 2])
    with pytest.raises(ShapeError, match="need sweeps"):
        g.insert_radar(np.zeros((2, 3)), [1.0], [0.0], 60.0)
    with pytest.raises(InvalidArgumentError, match="ego_velocity"):
        g.insert_radar((0.0, 0.0, 0.0), [1.0], [0.0], 60.0, radial_velocity=[0.0])
    with pytest.raises(NonFiniteError):
        g.insert_radar((np.nan, 0.0, 0.0), [1.0], [0.0], 60.0)
    with pytest.raises(ShapeError):
        g.insert_radar((0.0, 0.0, 0.0), [1.0, 2.0], [0.0], 60.0)
    with pytest.raises(InvalidArgumentError, match="max_range"):
        g.insert_radar((0.0, 0.0, 0.0), [1.0], [0.0], -1.0)
    with pytest.raises(InvalidArgumentError, match="prob_hit"):
        RadarModel(prob_hit=0.4)


def test_one_call_equals_sweep_by_sweep_and_a_growing_map_holds_the_detections():
    street = Street.default()
    rng = np.random.default_rng(5)
    sweeps = [street.radar(t, rng=rng) for t in np.arange(5.0, 7.0, 0.1)]
    a = OccupancyGrid2D(0.2)
    for s in sweeps:
        a.insert_radar(s.pose, s.range, s.azimuth, 60.0, radial_velocity=s.radial_velocity, ego_velocity=s.ego_velocity)
    b = OccupancyGrid2D(0.2)
    index = np.concatenate([np.full(len(s.range), k) for k, s in enumerate(sweeps)])
    # detections in any order within the call: sweeps are applied in order
    shuffle = np.random.default_rng(0).permutation(index.size)
    cat = lambda field: np.concatenate([getattr(s, field) for s in sweeps])[shuffle]  # noqa: E731
    counts = b.insert_radar(np.array([s.pose for s in sweeps]), cat("range"), cat("azimuth"), 60.0,
                            sweeps=index[shuffle], radial_velocity=cat("radial_velocity"),
                            ego_velocity=np.array([s.ego_velocity for s in sweeps]))
    assert counts["scans"] == len(sweeps) and a.stats == b.stats
    assert a.origin.tolist() == b.origin.tolist()
    np.testing.assert_array_equal(a.log_odds(), b.log_odds())


def test_radar_map_of_the_street_matches_its_truth(seed=0):
    """Issue 19's figure: the street's radar alone (10 Hz for 20 s, clutter, ghosts, moving cars
    and people) maps its static structure with precision ≥ 0.9 and recall ≥ 0.8 of the occupied
    cells (:meth:`Street.map_scores`). More seeds: ``benchmarks/bench_radar.py``."""
    street = Street.default()
    res = 0.2
    x0, y0, x1, y1 = street.bounds
    shape = (int(round((y1 - y0) / res)), int(round((x1 - x0) / res)))
    g = OccupancyGrid2D(res, size=(x1 - x0, y1 - y0), origin=(x0, y0))
    rng = np.random.default_rng(seed)
    stamps = np.arange(0.0, street.duration + 1e-9, 0.1)
    ghosts = moving = 0
    for t in stamps:
        s = street.radar(float(t), rng=rng)
        c = g.insert_radar(s.pose, s.range, s.azimuth, 60.0, radial_velocity=s.radial_velocity,
                           ego_velocity=s.ego_velocity)
        ghosts += c["ghosts"]
        moving += c["moving"]
    occupied = (g.probability() >= 0.65)[:shape[0], :shape[1]]
    precision, recall = street.map_scores(occupied, res, (x0, y0), stamps)
    print(f"seed {seed}: precision {precision:.3f}, recall {recall:.3f}, ghosts {ghosts}, moving {moving}")
    assert precision >= 0.9 and recall >= 0.8
    assert ghosts > 0 and moving > 0


def test_map_scores_against_scipy_dilation():
    street = Street.default()
    res, origin, shape = 0.5, (40.0, -10.0), (40, 80)
    stamps = [0.0, 10.0]
    truth = street.occupancy(10.0, res, origin, shape, static_only=True)
    seen = street.visible_static(stamps, res, origin, shape, 30.0)
    assert seen.any() and (seen <= binary_dilation(truth, np.ones((3, 3), bool))).all()
    assert street.map_scores(truth, res, origin, stamps) == (1.0, 1.0)
    rng = np.random.default_rng(1)
    guess = truth ^ (rng.random(shape) < 0.05)
    near = np.ones((3, 3), dtype=bool)
    expect = ((guess & binary_dilation(truth, near)).sum() / guess.sum(),
              (seen & binary_dilation(guess, near)).sum() / seen.sum())
    assert street.map_scores(guess, res, origin, stamps) == pytest.approx(expect, abs=0)
    assert math.isnan(street.map_scores(np.zeros(shape, bool), res, origin, stamps)[0])
