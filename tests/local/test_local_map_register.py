"""A registering local map (``register=True``) inserts each scan where it fits the map, keeps the
running correction from the caller's pose frame to its own (ROS's map → odom) and reads out in its
own frame: the walls a steadily drifting odometry sees stay one wall, and nothing on them is
tracked."""

from __future__ import annotations

import math

import numpy as np
import pytest

from occmap.geometry.se2 import compose_poses, relative_poses
from occmap.local import LocalMap
from occmap.sim.street import CAR, PEDESTRIAN, Mover, Street

# a hall 30 m × 8 m (walls on y = ±4) with a recess in each long wall and two pillars, the robot
# driving along it at 1 m/s (as tests/local/test_tracking_drift.py)
WALLS = np.array([[-5, -4, 25, -4], [25, -4, 25, 4], [25, 4, -5, 4], [-5, 4, -5, -4],
                  [4, 4, 4, 2.5], [4, 2.5, 6, 2.5], [6, 2.5, 6, 4],
                  [12, -4, 12, -2.8], [12, -2.8, 13, -2.8], [13, -2.8, 13, -4]], dtype=float)
PILLARS = np.array([[8.0, 1.0, 0.2], [16.0, -1.5, 0.2]])
DURATION = 8.0
#: the odometry frame drifts from the world's: 2.5°/s of heading and 5 cm/s sideways (after 8 s,
#: 20° and 0.4 m)
DRIFT = (0.0, 0.05, math.radians(2.5))


def _odometry_frame(t: float) -> np.ndarray:
    """The world pose of the odometry frame at ``t`` (the identity at 0)."""
    return np.asarray(DRIFT) * t


def _replay(register: bool, walker: bool = False, duration: float = DURATION):
    """The hall seen through a steadily drifting odometry; returns the map, the last scan's true
    and odometry poses, and the confirmed track ids ``(elsewhere, on the walker)`` (a track
    within 1 m of the walker in the map's frame, the world's as the first scan fixes it)."""
    movers = (Mover(1, PEDESTRIAN, 0.5, 0.5, 0.0, (16.0, 3.0, math.pi), ((8.0, 1.2, 0.0),)),) if walker else ()
    robot = Mover(-1, CAR, 0.6, 0.5, 0.0, (0.0, 0.0, 0.0), ((8.0, 1.0, 0.0),))
    street = Street(WALLS, PILLARS, movers, robot, duration, (-5.0, -4.0, 25.0, 4.0))
    rng = np.random.default_rng(0)
    lm = LocalMap((30.0, 30.0), 0.05, half_life=30.0, tracking=True, register=register)
    elsewhere, on_walker = set(), set()
    for t in np.round(np.arange(0.0, street.duration + 1e-9, 0.1), 1):
        scan = street.lidar(float(t), rng=rng, max_range=20.0)
        true = np.asarray(scan.pose)
        odom = relative_poses(_odometry_frame(float(t)), true)  # the true pose seen in the drifting frame
        lm.move_to(*odom[:2])
        lm.insert_scan(odom, scan.ranges, scan.angles, float(t), max_range=20.0)
        tracks = lm.tracks()
        for i in np.flatnonzero(tracks.confirmed):
            w = street.objects(float(t))
            found = walker and math.hypot(tracks.x[i] - w.x[0], tracks.y[i] - w.y[0]) < 1.0
            (on_walker if found else elsewhere).add(int(tracks.id[i]))
    return lm, true, odom, elsewhere, on_walker


def _off_structure(lm: LocalMap, true: np.ndarray) -> float:
    """Share of the map's lethal cells farther than 0.1 m (two cells) from every wall and pillar:
    the cells carried into the world by the map's own pose of the robot (the world seen in the
    map's frame is ``pose ⊖ true``)."""
    centres = lm.cell_to_world(np.argwhere(lm.lethal()))
    world = relative_poses(compose_poses(lm.pose, relative_poses(true, np.zeros(3))),
                           np.c_[centres, np.zeros(len(centres))])[:, :2]
    a, b = WALLS[:, :2], WALLS[:, 2:]
    t = np.clip(np.einsum("nwk,wk->nw", world[:, None] - a, b - a) / np.einsum("wk,wk->w", b - a, b - a), 0.0, 1.0)
    d = np.hypot(*np.moveaxis(world[:, None] - (a + t[..., None] * (b - a)), -1, 0)).min(axis=1)
    d = np.minimum(d, (np.hypot(*np.moveaxis(world[:, None] - PILLARS[:, :2], -1, 0)) - PILLARS[:, 2]).min(axis=1))
    return float(np.mean(d > 0.1))


@pytest.fixture(scope="module")
def drifting():
    return {register: _replay(register) for register in (False, True)}


def test_walls_seen_from_a_drifting_pose_stay_one_wall(drifting):
    lm, true, odom, elsewhere, _ = drifting[True]
    assert elsewhere == set()
    assert _off_structure(lm, true) < 0.15
    # inserted at the poses given, the map holds copies of the walls turned by the drift, and a
    # piece of one is tracked
    lm0, true0, _, elsewhere0, _ = drifting[False]
    assert elsewhere0
    assert _off_structure(lm0, true0) > 0.5


def test_the_correction_carries_the_callers_poses_into_the_map(drifting):
    lm, true, odom, *_ = drifting[True]
    # the last scan was inserted at the caller's pose carried by the correction ...
    np.testing.assert_allclose(compose_poses(lm.correction, odom), lm.pose, atol=1e-9)
    # ... which undoes the drift of 20° and 0.4 m but for what a lidar odometry of 8 s drifts (the
    # map's frame is the world's, as the first scan fixed it, to 0.3 m and 1.5°)
    assert math.hypot(*(lm.pose[:2] - true[:2])) < 0.3
    assert abs(math.remainder(lm.pose[2] - true[2], 2 * math.pi)) < math.radians(1.5)
    drift = _odometry_frame(DURATION)
    assert abs(math.remainder(lm.correction[2] - drift[2], 2 * math.pi)) < math.radians(1.5)


def test_check_path_in_the_map_frame_meets_the_wall_the_map_holds(drifting):
    lm, *_ = drifting[True]
    x, y, th = lm.pose
    ahead = np.stack([x + np.linspace(0.0, 3.0, 7) * math.cos(th), y + np.linspace(0.0, 3.0, 7) * math.sin(th),
                      np.full(7, th)], -1)
    assert lm.check_path(ahead, footprint=0.3).first_collision == -1  # down the hall: free
    # the wall the map holds 4 m to the robot's right (y = −4 in the world)
    centres = lm.cell_to_world(np.argwhere(lm.lethal()))
    right = np.array([x + 4.0 * math.sin(th), y - 4.0 * math.cos(th)])
    wall = centres[np.argmin(np.hypot(*(centres - right).T))]
    assert math.hypot(*(wall - right)) < 0.3
    toward = np.linspace(lm.pose[:2], wall, 9)
    check = lm.check_path(np.c_[toward, np.full(9, th)], footprint=0.3)
    assert check.first_collision == 8 and check.max_cost[-1] >= 254  # 0.5 m from it the disc is clear
    # the same point in the caller's (odometry) frame lies over a metre off: the map holds no wall there
    there = relative_poses(lm.correction, np.r_[wall, th])
    assert math.hypot(*(there[:2] - wall)) > 1.0
    assert lm.occupancy_at(there[None, :2]).tolist() != [1]


def test_clouds_and_radar_land_in_the_scans_frame(drifting):
    lm, true, odom, *_ = drifting[True]

    def in_map(p):  # a world point where the last scan put it: the map's frame is pose ⊖ true there
        return compose_poses(lm.pose, relative_poses(true, np.r_[p, 0.0]))[:2]

    def in_odometry(p):  # ... and where the caller's frame puts it
        return compose_poses(odom, relative_poses(true, np.r_[p, 0.0]))[:2]

    post, other = np.array([10.0, -2.0]), np.array([10.0, 2.0])  # 2 m ahead of the robot, 2 m aside
    stamp = DURATION + 0.1
    assert lm.occupancy_at(np.array([in_map(post), in_map(other)])).tolist() == [0, 0]
    # something standing where the map has seen free space is taken as moving: the tracker gets it
    # where the scans would have put it
    cloud = np.c_[np.repeat(in_odometry(post)[None], 5, 0), np.linspace(0.2, 0.6, 5)]
    lm.insert_point_cloud(cloud, odom[:2], stamp, 0.0, 1.0)
    np.testing.assert_allclose(lm.objects.moving, np.repeat(in_map(post)[None], 5, 0), atol=1e-9)
    d = in_odometry(other) - odom[:2]
    for k in range(5):  # seen free until now: a few detections make it occupied
        lm.insert_radar(odom, [math.hypot(*d)], [math.atan2(d[1], d[0]) - odom[2]], stamp + 0.1 * (k + 1), 30.0)
    assert lm.occupancy_at(in_map(other)[None]).tolist() == [1]


def test_a_walker_beside_the_wall_is_still_tracked():
    _, _, _, elsewhere, on_walker = _replay(True, walker=True)
    assert on_walker and not elsewhere


def test_exact_poses_keep_the_map_in_their_frame():
    robot = Mover(-1, CAR, 0.6, 0.5, 0.0, (0.0, 0.0, 0.0), ((4.0, 1.0, 0.0),))
    street = Street(WALLS, PILLARS, (), robot, 4.0, (-5.0, -4.0, 25.0, 4.0))
    rng = np.random.default_rng(2)
    lm = LocalMap((30.0, 30.0), 0.05, half_life=30.0, tracking=True, register=True)
    for t in np.round(np.arange(0.0, street.duration + 1e-9, 0.1), 1):
        scan = street.lidar(float(t), rng=rng, max_range=20.0)
        lm.move_to(*scan.pose[:2])
        lm.insert_scan(scan.pose, scan.ranges, scan.angles, float(t), max_range=20.0)
        assert lm.correction.tolist() == [0.0, 0.0, 0.0]  # registration within a cell moves nothing
        np.testing.assert_array_equal(lm.pose, scan.pose)


def test_without_register_the_map_keeps_the_callers_frame():
    lm = LocalMap((10.0, 10.0), 0.1, tracking=True)
    assert lm.pose is None and lm.correction.tolist() == [0.0, 0.0, 0.0]
    pose = np.array([1.0, 2.0, 0.3])
    lm.insert_scan(pose, np.full(8, 3.0), np.linspace(-1, 1, 8), 0.0)
    np.testing.assert_array_equal(lm.pose, pose)
    assert lm.correction.tolist() == [0.0, 0.0, 0.0]
