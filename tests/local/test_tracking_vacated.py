"""Objects that stand when first seen and then walk on inside their own shadow: found by the cells
they vacate (hit by an earlier scan, then seen through), while parked cars stay static."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from occmap.local import LocalMap
from occmap.local.tracking import _kernels as K
from occmap.sim.street import CAR, PARKED, PEDESTRIAN, Mover, Street

WALK = 1.0  # the person starts walking at this time (s)


@pytest.mark.parametrize("radius", [0.3, 1.0, 2.5])
def test_near_any_equals_a_kd_tree(radius):
    rng = np.random.default_rng(3)
    pts = rng.uniform(-10, 10, (500, 2))
    seeds = rng.uniform(-10, 10, (60, 2))
    out = np.empty(len(pts), np.bool_)
    K.near_any(pts, seeds, radius, out)
    expected = np.isfinite(cKDTree(seeds).query(pts, distance_upper_bound=radius)[0])
    assert out.any() and not out.all()
    np.testing.assert_array_equal(out, expected)
    K.near_any(pts, np.empty((0, 2)), radius, out)
    assert not out.any()


def _scene() -> Street:
    """A still robot at the origin facing +x in a 24 m × 12 m yard; a person standing 8 m ahead
    until ``WALK``, then walking straight away at 1.4 m/s (always in their own shadow); a parked
    car to the side."""
    walls = np.array([[-4.0, -6.0, 20.0, -6.0], [20.0, -6.0, 20.0, 6.0], [20.0, 6.0, -4.0, 6.0],
                      [-4.0, 6.0, -4.0, -6.0]])
    person = Mover(1, PEDESTRIAN, 0.5, 0.5, 0.0, (8.0, 0.0, 0.0), ((WALK, 0.0, 0.0), (5.0, 1.4, 0.0)))
    parked = Mover(2, PARKED, 4.5, 1.8, 0.0, (6.0, 3.5, 0.0), ((6.0, 0.0, 0.0),))
    robot = Mover(-1, CAR, 0.6, 0.5, 0.0, (0.0, 0.0, 0.0), ((6.0, 0.0, 0.0),))
    return Street(walls, np.empty((0, 3)), (person, parked), robot, 6.0, (-4.0, -6.0, 20.0, 6.0))


def _first_confirmed(vacated_within: float):
    """Replay the scene; the first time a confirmed track lies on the person (None if never), and
    how many scans had a confirmed track near the parked car."""
    street = _scene()
    rng = np.random.default_rng(0)
    lm = LocalMap((40.0, 40.0), 0.1, tracking=True)
    lm.objects.vacated_within = vacated_within
    first, on_parked = None, 0
    for t in np.arange(0.0, street.duration + 1e-9, 0.1):
        t = round(float(t), 1)
        scan = street.lidar(t, rng=rng)
        lm.insert_scan(scan.pose, scan.ranges, scan.angles, t, max_range=30.0)
        truth = street.objects(t)
        tracks = lm.tracks()
        conf = tracks.confirmed
        d_person = np.hypot(tracks.x - truth.x[0], tracks.y - truth.y[0])
        d_parked = np.hypot(tracks.x - truth.x[1], tracks.y - truth.y[1])
        if first is None and np.any(conf & (d_person < 1.0)):
            first = t
        on_parked += int(np.any(conf & (d_parked < 2.5)))
    return first, on_parked


def test_a_person_walking_off_from_standing_is_confirmed_and_a_parked_car_never():
    # the cells the person stood on (hit ten times) need about 0.7 s of seeing through to count as
    # vacated; the track then needs its speed known to 0.4 m/s
    first, on_parked = _first_confirmed(2.0)
    assert first is not None and WALK < first <= WALK + 1.6, first
    assert on_parked == 0
    # without the vacated cells (the earlier rule) the person, never leaving their shadow, is static
    first, on_parked = _first_confirmed(0.0)
    assert first is None and on_parked == 0
