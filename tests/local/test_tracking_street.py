"""The local map tracking moving objects on the simulated street (occmap.sim.street), against the
street's truth: accuracy of confirmed tracks, no tracks on parked cars or walls, no trails in the
static layer, predicted footprints and timed path checks."""

import math

import numpy as np
import pytest

from occmap.errors import InvalidArgumentError
from occmap.local import LocalMap
from occmap.sim.street import CAR, PARKED, PEDESTRIAN, Street

STREET = Street.default()
RATE = 0.1


def _box(x, y, heading, length, width, xs, ys):
    c, s = math.cos(heading), math.sin(heading)
    dx, dy = xs - x, ys - y
    return (np.abs(c * dx + s * dy) <= length / 2) & (np.abs(-s * dx + c * dy) <= width / 2)


@pytest.fixture(scope="module")
def replay():
    """The whole street (20 s) through a tracking local map: per scan the confirmed tracks matched
    to the nearest truth, and the map at the end."""
    rng = np.random.default_rng(0)
    lm = LocalMap((60.0, 60.0), 0.1, tracking=True)
    rows, ious, snapshots = [], [], {}
    for t in np.arange(0.0, STREET.duration + 1e-9, RATE):
        t = round(float(t), 1)
        scan = STREET.lidar(t, rng=rng)
        lm.move_to(*scan.pose[:2])
        lm.insert_scan(scan.pose, scan.ranges, scan.angles, t, max_range=30.0)
        truth = STREET.objects(t)
        tracks = lm.tracks()
        for i in np.flatnonzero(tracks.confirmed):
            d = np.hypot(truth.x - tracks.x[i], truth.y - tracks.y[i])
            j = int(d.argmin())
            dh = abs(math.remainder(truth.heading[j] - tracks.heading[i], 2 * math.pi))
            rows.append((t, tracks.id[i], truth.id[j] if d[j] < 2.5 else -1, truth.kind[j], d[j],
                         math.hypot(truth.vx[j] - tracks.vx[i], truth.vy[j] - tracks.vy[i]), dh))
        if t + 1.0 <= STREET.duration and round(t * 10) % 5 == 0:  # every half second
            ids, states, _, sizes = lm.objects.tracker.predicted(t + 1.0)
            ahead = STREET.objects(t + 1.0)
            for k in range(len(ids)):
                j = int(np.hypot(ahead.x - states[k, 0], ahead.y - states[k, 1]).argmin())
                g = np.mgrid[-4:4:0.05, -4:4:0.05]
                xs, ys = ahead.x[j] + g[0], ahead.y[j] + g[1]
                a = _box(*states[k, :3], *sizes[k], xs, ys)
                b = _box(ahead.x[j], ahead.y[j], ahead.heading[j], ahead.length[j], ahead.width[j], xs, ys)
                ious.append((ahead.kind[j], (a & b).sum() / max((a | b).sum(), 1)))
        if t == 7.0:
            snapshots[t] = (lm.tracks(), lm.costmap(at=t + 1.0)[0].copy(), lm.origin.copy(), lm.costmap()[0].copy())
    return lm, np.array(rows), np.array(ious), snapshots


def test_confirmed_tracks_follow_cars_and_people(replay):
    _, rows, _, _ = replay
    for kind, pos, speed, heading in ((CAR, 0.2, 0.7, 4.0), (PEDESTRIAN, 0.15, 0.3, 8.0)):
        m = (rows[:, 3] == kind) & (rows[:, 2] >= 0)
        assert m.sum() > 150
        assert np.sqrt(np.mean(rows[m, 4] ** 2)) <= pos
        assert np.sqrt(np.mean(rows[m, 5] ** 2)) <= speed
        assert np.degrees(np.sqrt(np.mean(rows[m, 6] ** 2))) <= heading


def test_no_tracks_on_parked_cars_or_walls_and_one_track_per_passing_car(replay):
    _, rows, _, _ = replay
    assert np.all(rows[:, 2] >= 0), "a confirmed track far from every moving object"
    assert not np.any(rows[:, 3] == PARKED)
    passing = [m.ident for m in STREET.movers if m.kind == CAR and m.start[1] in (-1.5, 1.5) and m.t0 <= 2.0]
    for ident in passing:  # the two cars that pass each other 1.2 m apart keep one track each
        assert len(set(rows[rows[:, 2] == ident, 1])) == 1


def test_moving_objects_leave_no_trail_in_the_static_layer(replay):
    lm, _, _, _ = replay
    lethal = lm.lethal()
    H, W = lethal.shape
    centres = lm.cell_to_world(np.stack(np.meshgrid(np.arange(H), np.arange(W), indexing="ij"), -1))
    lanes = (np.abs(centres[..., 1]) <= 2.5) & ~((centres[..., 0] > 62) & (centres[..., 0] < 78))
    parked = STREET.occupancy(STREET.duration, lm.resolution, lm.origin, (H, W), static_only=True)
    assert lethal[lanes & ~parked].sum() <= 5  # lanes cars drove along stay free


def test_footprints_predicted_one_second_ahead_overlap_the_truth(replay):
    _, _, ious, _ = replay
    assert ious[ious[:, 0] == CAR, 1].mean() >= 0.6
    assert ious[:, 1].mean() >= 0.5


def test_costmap_ahead_holds_the_crossing_car_where_it_will_be(replay):
    _, _, _, snapshots = replay
    _, ahead, origin, now = snapshots[7.0]
    car = STREET.objects(8.0)
    k = list(car.id).index(next(m.ident for m in STREET.movers if m.kind == CAR and m.start[2] == -math.pi / 2))
    col, row = np.floor((np.array([car.x[k], car.y[k]]) - origin) / 0.1).astype(int)
    assert ahead[row, col] >= 64 and now[row, col] == 0  # where the car will be costs, not yet now
    was = STREET.objects(7.0)
    col, row = np.floor((np.array([was.x[k], was.y[k]]) - origin) / 0.1).astype(int)
    assert now[row, col] == 254 and ahead[row, col] < 64  # where it is now is lethal, in 1 s it is not


def test_timed_path_check_sees_the_crossing_car_and_not_the_one_gone(replay):
    rng = np.random.default_rng(1)
    lm = LocalMap((60.0, 60.0), 0.1, tracking=True)
    for t in np.arange(0.0, 7.01, RATE):
        scan = STREET.lidar(round(float(t), 1), rng=rng)
        lm.move_to(*scan.pose[:2])
        lm.insert_scan(scan.pose, scan.ranges, scan.angles, round(float(t), 1), max_range=30.0)
    crossing = next(m for m in STREET.movers if m.kind == CAR and m.start[2] == -math.pi / 2)
    t_cross = crossing.t0 + (45.0 - 0.0) / 13.0  # when it crosses y = 0
    # a path across its lane at x = 68.5, at y = 0 when the car is there
    path = np.array([[66.0 + 0.5 * k, 0.0, 0.0] for k in range(11)])  # 10 m/s
    stamps = t_cross - 0.25 + 0.05 * np.arange(11)
    check = lm.check_path(path, footprint=0.3, stamps=stamps)
    assert check.first_collision >= 0
    assert path[check.first_collision, 0] == pytest.approx(68.5, abs=2.5)
    assert check.max_cost.max() == 254 and check.max_cost[0] < 254
    # the same path two seconds later: the car has gone south
    later = lm.check_path(path, footprint=0.3, stamps=stamps + 2.0)
    assert later.first_collision == -1
    with pytest.raises(InvalidArgumentError, match="before the map's time"):
        lm.check_path(path, stamps=np.zeros(11))


def test_tracking_needs_to_be_asked_for():
    lm = LocalMap((10.0, 10.0), 0.1)
    with pytest.raises(InvalidArgumentError, match="tracking=True"):
        lm.tracks()
    lm.insert_scan((0, 0, 0), np.full(8, 2.0), np.linspace(-3, 3, 8), 1.0)
    np.testing.assert_array_equal(lm.costmap(at=5.0)[0], lm.costmap()[0])  # nothing moves


def test_frames_draw_confirmed_tracks(replay):
    from occmap.local.replay import frame_image, tracked_objects

    lm = LocalMap((60.0, 60.0), 0.1, tracking=True)
    rng = np.random.default_rng(2)
    for t in np.arange(0.0, 3.01, RATE):
        scan = STREET.lidar(round(float(t), 1), rng=rng)
        lm.move_to(*scan.pose[:2])
        lm.insert_scan(scan.pose, scan.ranges, scan.angles, round(float(t), 1), max_range=30.0)
    corners, ahead = tracked_objects(lm, 1.0)
    assert len(corners) == len(ahead) == lm.tracks().confirmed.sum() >= 1
    # the predicted footprint lies where the track's velocity carries it
    t = lm.tracks()
    keep = t.confirmed
    moved = (ahead.mean(axis=1) - corners.mean(axis=1)) * lm.resolution
    np.testing.assert_allclose(np.hypot(*moved.T), np.hypot(t.vx[keep], t.vy[keep]), rtol=0.3, atol=0.1)
    plain = np.asarray(frame_image(lm.costmap()[0], None, 2))
    drawn = np.asarray(frame_image(lm.costmap()[0], None, 2, (corners, ahead)))
    assert not (plain == 131).any() and (drawn == 131).sum() > 20 and (drawn == 132).sum() > 20
    assert lm.stats["tracks_confirmed"] >= 1 and lm.stats["moving_returns"] > 0
