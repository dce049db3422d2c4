"""The simulated street: its movers follow their legs, the sensors see the truth."""

import math

import numpy as np
import pytest

from occmap.sim.street import CAR, CLUTTER, GHOST, PARKED, PEDESTRIAN, STATIC, Street

STREET = Street.default()


def _mover(ident):
    return next(m for m in STREET.movers if m.ident == ident)


def test_the_turning_car_leaves_the_side_street_eastbound_in_its_lane():
    car = next(m for m in STREET.movers if len(m.legs) > 3)
    t = car.t_end - car.legs[-1][0]  # the bend driven, the last straight ahead
    o = STREET.objects(t)
    k = list(o.id).index(car.ident)
    assert (o.y[k], o.heading[k]) == pytest.approx((-1.5, 0.0), abs=1e-9)
    assert o.x[k] > 75.0 and o.speed[k] == pytest.approx(6.0)
    assert STREET.objects(car.t0 + 1.0).x[k] == pytest.approx(71.5)  # northbound lane of the side street
    rates = [leg[2] for leg in car.legs]
    assert max(abs(np.diff(rates))) < 0.2  # eased into and out of the bend, no jump of yaw rate


def test_kinds_speeds_and_presence():
    o = STREET.objects(10.0)
    assert set(o.kind.tolist()) == {CAR, PEDESTRIAN, PARKED}
    assert np.all(o.speed[o.kind == PARKED] == 0.0)
    assert np.all((o.speed[o.kind == CAR] >= 5.0) & (o.speed[o.kind == CAR] <= 15.0))
    assert np.all((o.speed[o.kind == PEDESTRIAN] >= 1.0) & (o.speed[o.kind == PEDESTRIAN] <= 2.0))
    np.testing.assert_allclose(np.hypot(o.vx, o.vy), o.speed)
    late = max(m.t_end for m in STREET.movers if m.kind != PARKED)
    assert set(STREET.objects(late + 1.0).kind.tolist()) <= {PARKED}


def test_cars_passing_each_other_keep_more_than_a_metre_apart():
    east = next(m for m in STREET.movers if m.kind == CAR and m.start[1] == -1.5 and m.t0 == 0.0)
    west = next(m for m in STREET.movers if m.kind == CAR and m.start[2] == math.pi)
    times = np.arange(west.t0, min(east.t_end, west.t_end), 0.05)
    gaps, ahead = [], []
    for t in times:
        o = STREET.objects(float(t))
        ce, cw = (o.corners()[list(o.id).index(m.ident)] for m in (east, west))
        gaps.append(cw[:, 1].min() - ce[:, 1].max())
        ahead.append(o.x[list(o.id).index(east.ident)] < o.x[list(o.id).index(west.ident)])
    assert ahead[0] and not ahead[-1]  # they do pass
    assert min(gaps) == pytest.approx(1.2)


def test_lidar_returns_lie_on_what_the_labels_say():
    scan = STREET.lidar(7.0, sigma=0.0, rng=0)
    hit = scan.ranges < scan.max_range
    a = scan.pose[2] + scan.angles[hit]
    pts = scan.pose[:2] + scan.ranges[hit, None] * np.c_[np.cos(a), np.sin(a)]
    label = STREET.label(pts, 7.0, margin=1e-6)
    o = STREET.objects(7.0)
    seen = set(label[label >= 0].tolist())
    assert {i for i, k in zip(o.id, o.kind) if k == CAR} & seen  # moving cars are in view
    # every return on an object lies on its outline (within the margin), the others on walls or poles
    inner = STREET.label(pts, 7.0, margin=-1e-3)
    assert np.all(inner == STATIC)


def test_radar_measures_radial_velocity_relative_to_the_moving_sensor():
    r = STREET.radar(9.0, rng=3, sigma_range=0.0, sigma_azimuth=0.0, sigma_velocity=0.0,
                     clutter_rate=0.0, p_ghost=0.0)
    assert len(r.range) > 20 and not np.isin(r.truth, [CLUTTER, GHOST]).any()
    u = np.c_[np.cos(r.pose[2] + r.azimuth), np.sin(r.pose[2] + r.azimuth)]
    o = STREET.objects(9.0)
    vel = np.zeros((len(r.truth), 2))
    for k, ident in enumerate(o.id):
        vel[r.truth == ident] = (o.vx[k], o.vy[k])
    np.testing.assert_allclose(r.radial_velocity, np.einsum("ij,ij->i", vel - r.ego_velocity, u), atol=1e-9)
    assert np.any(r.truth >= 0) and np.any(r.truth == STATIC)
    assert r.ego_velocity == pytest.approx((1.5, 0.0))


def test_radar_false_alarms_and_ghosts_are_labelled():
    r = STREET.radar(9.0, rng=4, clutter_rate=20.0, p_ghost=1.0)
    assert np.sum(r.truth == CLUTTER) > 5
    ghosts = r.truth == GHOST
    x = r.pose[0] + r.range * np.cos(r.pose[2] + r.azimuth)
    assert ghosts.sum() > 3
    # a ghost lies beyond a building front
    y = r.pose[1] + r.range * np.sin(r.pose[2] + r.azimuth)
    assert np.all(np.abs(y[ghosts]) > 8.0 - 0.5) and np.all((x[ghosts] < 62.5) | (x[ghosts] > 77.5))
    assert math.isfinite(r.rcs.sum())
