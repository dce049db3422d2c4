"""The local map's sensors and objects at their edges: insert_radar (rays with the radar's
evidence, moving reflectors and ghosts, bad input, detections on tracked objects), NaN readings
with tracking, and an object that leaves the window."""

import math

import numpy as np
import pytest

from occmap.errors import InvalidArgumentError, ShapeError
from occmap.grid2d import RadarModel
from occmap.local import LocalMap
from occmap.logodds import logit

MODEL = RadarModel()


def lo(lm, x, y):
    return float(lm.log_odds_at([[x, y]])[0])


def test_a_detection_is_a_ray_with_the_radar_evidence():
    lm = LocalMap((20.0, 20.0), 0.1)
    c = lm.insert_radar((0.0, 0.0, 0.0), [5.05], [0.0], 0.0, max_range=60.0)
    assert c["points"] == 1 and c["moving"] == 0 and c["ghosts"] == 0 and c["dropped"] == 0
    assert lo(lm, 5.05, 0.05) == pytest.approx(logit(MODEL.prob_hit), rel=1e-6)
    assert lo(lm, 2.05, 0.05) == pytest.approx(logit(MODEL.prob_miss), rel=1e-6)
    assert math.isnan(lo(lm, 6.0, 0.05))


def test_moving_reflectors_clear_and_ghosts_behind_known_walls_do_nothing():
    lm = LocalMap((20.0, 20.0), 0.1)
    angles = np.linspace(-0.2, 0.2, 41)
    for k in range(5):  # a wall at x = 5 from a lidar
        lm.insert_scan((0.0, 0.0, 0.0), 5.05 / np.cos(angles), angles, 0.1 * k, max_range=30.0)
    wall = lo(lm, 5.05, 0.05)
    p = 3.0 * np.array([math.cos(0.1), math.sin(0.1)])
    seen = lo(lm, *p)
    c = lm.insert_radar((0.0, 0.0, 0.0), [8.0, 3.0], [0.0, 0.1], 0.5, max_range=60.0,
                        radial_velocity=[0.0, -4.0], ego_velocity=(0.0, 0.0))
    assert c["ghosts"] == 1 and c["moving"] == 1 and c["points"] == 1
    assert lo(lm, 5.05, 0.05) == wall and math.isnan(lo(lm, 8.0, 0.05))  # the ghost: nothing at all
    assert lo(lm, *p) <= seen < 0  # the mover marks nothing


def test_bad_detections_are_dropped_and_bad_calls_raise():
    lm = LocalMap((20.0, 20.0), 0.1)
    c = lm.insert_radar((0.0, 0.0, 0.0), [np.nan, 2.0, -1.0, 90.0], [0.0, np.inf, 0.0, 0.0], 1.0, max_range=60.0)
    assert c["dropped"] == 3 and c["beyond_max_range"] == 1 and c["points"] == 0
    assert lm.stats["dropped"] == 3
    c = lm.insert_radar((np.nan, 0.0, 0.0), [1.0], [0.0], 1.1, max_range=60.0)
    assert c["dropped_pose"] and lm.stats["dropped_poses"] == 1
    with pytest.raises(InvalidArgumentError, match="backwards"):
        lm.insert_radar((0.0, 0.0, 0.0), [1.0], [0.0], 0.5, max_range=60.0)
    with pytest.raises(ShapeError):
        lm.insert_radar((0.0, 0.0), [1.0], [0.0], 2.0, max_range=60.0)
    with pytest.raises(InvalidArgumentError, match="ego_velocity"):
        lm.insert_radar((0.0, 0.0, 0.0), [1.0], [0.0], 2.0, max_range=60.0, radial_velocity=[0.0])


ANGLES = np.radians(np.arange(-180.0, 180.0, 0.5))


def person_scan(c, walls=15.0):
    """Ranges from the origin of a lidar seeing a 0.5 m disc at ``c`` inside a ring of walls."""
    r = np.full(ANGLES.size, walls)
    rel = np.angle(np.exp(1j * (ANGLES - math.atan2(c[1], c[0]))))
    dist = float(np.hypot(*c))
    on = np.abs(rel) < math.asin(0.25 / dist)
    r[on] = dist - 0.25 * np.cos(rel[on] * dist / 0.25)
    return r


def test_detections_on_a_tracked_object_do_not_mark_the_static_layer_and_update_its_speed():
    lm = LocalMap((40.0, 40.0), 0.1, tracking=True)
    person = lambda t: np.array([-6.0 + 1.5 * t, 4.0])  # noqa: E731  walking +x past a sensor at the origin
    for k in range(30):
        t = 0.1 * k
        lm.insert_scan((0.0, 0.0, 0.0), person_scan(person(t)), ANGLES, t, max_range=30.0)
    tracks = lm.tracks()
    assert len(tracks) == 1 and tracks.confirmed[0]
    lm.objects.tracker.state[0, 3] = 3.0  # a wrong speed, uncertain
    lm.objects.tracker.cov[0, 3, 3] = 1.0
    t = 3.0
    c = person(t)
    # a radar behind the walker on its line: the radial speed is its speed, 1.5 m/s away
    n = lm.insert_radar((c[0] - 10.0, c[1], 0.0), [10.0], [0.0], t, max_range=60.0, radial_velocity=[1.5],
                        ego_velocity=(0.0, 0.0))
    assert n["moving"] == 1 and lm.objects.tracker.stats["doppler_updates"] == 1
    assert abs(math.hypot(lm.tracks().vx[0], lm.tracks().vy[0]) - 1.5) < 0.2
    # seen from the side the walker has no radial speed: static by its Doppler, but on the track
    c = person(3.1)
    before = lo(lm, *c)
    n = lm.insert_radar((c[0], c[1] - 8.0, math.pi / 2), [8.0], [0.0], 3.1, max_range=60.0, radial_velocity=[0.0],
                        ego_velocity=(0.0, 0.0))
    assert n["moving"] == 0 and n["points"] == 1
    assert math.isnan(before) and math.isnan(lo(lm, *c)) or lo(lm, *c) <= before


def test_nan_readings_with_tracking_are_dropped_and_tracks_go_on():
    lm = LocalMap((40.0, 40.0), 0.1, tracking=True)
    rng = np.random.default_rng(3)
    for k in range(30):
        t = 0.1 * k
        r = person_scan(np.array([-6.0 + 1.5 * t, 4.0]))
        r[rng.random(r.size) < 0.1] = np.nan
        c = lm.insert_scan((0.0, 0.0, 0.0), r, ANGLES, t, max_range=30.0)
        assert c["dropped"] == int(np.isnan(r).sum())
    tracks = lm.tracks()
    assert len(tracks) == 1 and tracks.confirmed[0] and np.isfinite(tracks.covariance).all()
    assert abs(tracks.vx[0] - 1.5) < 0.3


def test_an_object_leaving_the_window_coasts_and_is_dropped_cleanly():
    lm = LocalMap((12.0, 12.0), 0.1, tracking=True)  # the window: ±6 m around the origin
    person = lambda t: np.array([1.0 + 2.0 * t, 2.0])  # noqa: E731  out of the window after 2.5 s
    for k in range(60):
        t = 0.1 * k
        c = person(t)
        r = person_scan(c, walls=5.5)
        # nothing seen beyond the walls' ring: the person vanishes behind it
        lm.insert_scan((0.0, 0.0, 0.0), r if np.hypot(*c) < 5.0 else np.full(ANGLES.size, 5.5), ANGLES, t,
                       max_range=30.0)
        cost, _ = lm.costmap(at=t + 1.0)
        assert cost.shape == lm.shape
        if k == 20:
            assert lm.tracks().confirmed.any()
    assert len(lm.tracks()) == 0 and lm.stats["tracks_dropped"] >= 1
    assert lm.predicted_occupancy(lm.time + 1.0).max() == 0.0  # nothing left of it in the costmap


def _ring_scene(walker=None):
    """A 3D scanner's cloud at the origin: a wall 15 m round at its height, two rings of low
    returns 4 and 5 m round (what lower lasers hit within the height band, as an HDL-32's ground
    rings do), every 0.25°; and a ``walker`` (x, y) 0.5 m across, its near side at the scanner's
    height."""
    a = np.radians(np.arange(0.0, 360.0, 0.25))
    parts = [np.c_[r * np.cos(a), r * np.sin(a), np.full(len(a), z)]
             for r, z in ((15.0, 0.0), (4.0, -0.7), (5.0, -0.7))]
    if walker is not None:
        b = np.linspace(-0.5 * np.pi, 0.5 * np.pi, 16) + math.atan2(walker[1], walker[0]) + np.pi
        parts.append(np.c_[walker[0] + 0.25 * np.cos(b), walker[1] + 0.25 * np.sin(b), np.zeros(16)])
    return np.concatenate(parts)


@pytest.mark.parametrize("origin", [(0.0, 0.0, 0.0), (0.0, 0.0)])
def test_lower_rings_do_not_hide_a_walker_from_a_3d_scanner(origin):
    # with the scanner's height known, the returns of the lower rings, nearer at every bearing, do
    # not cut the walker's ends: its views are whole, it gets its velocity and is confirmed; with
    # a 2D origin every view is cut at both ends and it never is (each view restarts its wait)
    lm = LocalMap((40.0, 40.0), 0.1, tracking=True)
    for k in range(5):
        lm.insert_point_cloud(_ring_scene(), origin, 0.1 * k, -1.0, 1.0)
    for k in range(5, 25):
        t = 0.1 * k
        lm.insert_point_cloud(_ring_scene((10.0, -3.0 + 1.2 * t)), origin, t, -1.0, 1.0)
    tracks = lm.tracks()
    assert tracks.confirmed.any() == (len(origin) == 3)
    if len(origin) == 3:
        i = int(np.argmax(tracks.confirmed))
        assert math.hypot(tracks.x[i] - 10.0, tracks.y[i] - (-3.0 + 1.2 * 2.4)) < 0.3
        assert tracks.vy[i] == pytest.approx(1.2, abs=0.3)
