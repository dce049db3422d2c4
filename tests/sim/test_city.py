"""The procedural town and its drive: size and placement, determinism (the same plan gives the same
bits, scan k alone equals the k-th of the stream, also in another process), points on the truth's
surfaces, a route on the roads clear of every solid, the planar view, and argument checks."""

from __future__ import annotations

import hashlib
import math
import pickle
import subprocess
import sys

import numpy as np
import pytest

from occmap.cloud import PointCloud
from occmap.errors import InvalidArgumentError, OccmapError
from occmap.scan import LaserScan
from occmap.sim.city import (
    CITY_LIDAR,
    City,
    CityDrive,
    CityPlan,
    _build,
    city_drive,
    city_laser_drive,
    city_laser_scan,
    city_scan,
)

OCTOMAP_REACH = 32768 * 0.1  # metres from the origin that 16-bit keys reach at 0.1 m

SMALL = CityPlan(seed=3, size=(420.0, 330.0), route_length=1500.0)
COARSE = CITY_LIDAR.with_azimuth_step(math.radians(2.0))  # 180 columns, 2,880 beams
DRIVE = CityDrive(SMALL, lidar=COARSE, spacing=25.0, laser_beams=360)
EXACT = CityDrive(SMALL, lidar=COARSE, spacing=25.0, noise_std=0.0, laser_sigma=0.0, laser_beams=360)


@pytest.fixture(scope="module")
def town():
    return City.of()


@pytest.fixture(scope="module")
def small():
    return City.of(SMALL)


def digest(*arrays):
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


# ------------------------------------------------------------------ the default town


def test_default_town_is_large_far_and_long(town):
    xmin, ymin, xmax, ymax = town.bounds
    assert xmax - xmin >= 2000.0 and ymax - ymin >= 2000.0
    assert (xmin + xmax) / 2 == 10_000.0 and (ymin + ymax) / 2 == 10_000.0
    w = town.world
    for lo in (w.boxes[:, :2], w.cylinders[:, :2] - w.cylinders[:, 2:3]):
        assert lo.min() > OCTOMAP_REACH  # nothing fits OctoMap's key range at 0.1 m
    assert w.boxes[:, [0, 1]].min() >= xmin and w.boxes[:, [3, 4]].max() <= xmax
    assert len(w.boxes) + len(w.cylinders) > 10_000
    assert town.route_length == pytest.approx(20_000.0, abs=1e-6)
    assert np.all((town.route >= [xmin, ymin]) & (town.route <= [xmax, ymax]))
    assert town.blocks_passed.mean() > 0.8  # the drive passes most blocks
    assert set(town.block_kinds) == {"buildings", "park", "square"}
    assert len(town.streets_x) >= 10 and len(town.streets_y) >= 10
    heights = w.boxes[:, 5]
    assert heights.max() > 40.0 and np.median(heights[heights > 5.0]) < 25.0  # a few towers
    # the whole drive keeps clear of every solid at sensor height
    sensor = town.route_poses(np.arange(0.0, town.route_length, 2.0))
    a = np.linspace(-np.pi, np.pi, 16, endpoint=False)
    o = np.repeat(np.column_stack([sensor[:, :2], np.full(len(sensor), 1.8)]), len(a), axis=0)
    d = np.tile(np.column_stack([np.cos(a), np.sin(a), np.zeros_like(a)]), (len(sensor), 1))
    assert w.cast(o, d, 5.0).min() >= 1.5
    drive = CityDrive()
    assert drive.n_scans == 4001
    cloud = city_scan(1234, drive)
    assert 3000 < len(cloud) < 15_000
    assert np.all(np.abs(cloud.origin[:2]) > OCTOMAP_REACH)


def test_blocks_have_varied_sizes_and_streets_fill_the_town(town):
    for streets, (lo, hi) in ((town.streets_x, town.bounds[0::2]), (town.streets_y, town.bounds[1::2])):
        c, w = streets[:, 0], streets[:, 1]
        assert c[0] - w[0] / 2 == pytest.approx(lo) and c[-1] + w[-1] / 2 == pytest.approx(hi)
        assert set(w) == {16.0, 26.0} and w[0] == w[-1] == 26.0
        blocks = np.diff(c) - (w[:-1] + w[1:]) / 2
        assert blocks.min() > 60.0 and blocks.max() < 180.0 and blocks.std() > 10.0


# ------------------------------------------------------------------ determinism


def test_the_plan_decides_every_bit(small):
    again = _build.__wrapped__(SMALL)  # built anew, not from the cache
    assert again is not small
    for a, b in ((again.world.boxes, small.world.boxes), (again.world.cylinders, small.world.cylinders),
                 (again.route, small.route), (again.blocks, small.blocks)):
        np.testing.assert_array_equal(a, b)
    other = City.of(CityPlan(seed=4, size=SMALL.size, route_length=SMALL.route_length))
    assert other.world.boxes.shape != small.world.boxes.shape or np.any(other.world.boxes != small.world.boxes)


def test_scan_k_alone_equals_the_kth_of_the_stream():
    stream = list(city_drive(DRIVE, start=3, stop=9))
    lasers = list(city_laser_drive(DRIVE, start=3, stop=9))
    assert len(stream) == len(lasers) == 6
    for k, cloud, laser in zip(range(3, 9), stream, lasers):
        alone = city_scan(k, DRIVE)
        assert isinstance(cloud, PointCloud) and cloud.has_pose
        np.testing.assert_array_equal(alone.points, cloud.points)
        np.testing.assert_array_equal(alone.pose.matrix, cloud.pose.matrix)
        assert alone.stamp == cloud.stamp == k * DRIVE.spacing / DRIVE.speed
        one = city_laser_scan(k, DRIVE)
        assert isinstance(laser, LaserScan)
        np.testing.assert_array_equal(one.ranges, laser.ranges)
        np.testing.assert_array_equal(one.pose, laser.pose)
        assert one.stamp == laser.stamp == cloud.stamp
    # the whole stream, from the start
    assert len(list(city_drive(DRIVE))) == DRIVE.n_scans


def test_a_drive_travels_as_a_few_bytes():
    blob = pickle.dumps(DRIVE)
    assert len(blob) < 2000
    back = pickle.loads(blob)
    assert back == DRIVE and hash(back) == hash(DRIVE)
    assert back.city is DRIVE.city  # the process's town, not a copy


def test_another_process_makes_the_same_scan():
    code = (
        "import hashlib, math, numpy as np\n"
        "from occmap.sim.city import CITY_LIDAR, CityDrive, CityPlan, city_scan, city_laser_scan\n"
        "d = CityDrive(CityPlan(seed=3, size=(420.0, 330.0), route_length=1500.0),\n"
        "              lidar=CITY_LIDAR.with_azimuth_step(math.radians(2.0)), spacing=25.0, laser_beams=360)\n"
        "c = city_scan(41, d); s = city_laser_scan(41, d); h = hashlib.sha256()\n"
        "for a in (c.points, c.pose.matrix, s.ranges, s.pose): h.update(np.ascontiguousarray(a).tobytes())\n"
        "print(h.hexdigest())\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    c = city_scan(41, DRIVE)
    s = city_laser_scan(41, DRIVE)
    assert out.stdout.strip() == digest(c.points, c.pose.matrix, s.ranges, s.pose)


def test_noise_seed_changes_the_noise_only():
    a = city_scan(7, EXACT)
    b = city_scan(7, DRIVE)
    c = city_scan(7, CityDrive(SMALL, lidar=COARSE, spacing=25.0, laser_beams=360, seed=1))
    np.testing.assert_array_equal(a.pose.matrix, b.pose.matrix)
    assert len(a) == len(b)  # no beam near the range limits here
    ra, rb, rc = (np.linalg.norm(x.points, axis=1) for x in (a, b, c))
    assert np.std(rb - ra) == pytest.approx(0.02, rel=0.15)
    assert np.abs(np.mean(rb - ra)) < 0.003
    assert not np.array_equal(rb, rc)


# ------------------------------------------------------------------ truth


def test_points_lie_on_the_truth_surfaces(small):
    for k in (0, 17, 40, EXACT.n_scans - 1):
        cloud = city_scan(k, EXACT)
        o = cloud.origin
        p = cloud.world_points()
        r = np.linalg.norm(p - o, axis=1)
        u = (p - o) / r[:, None]
        assert len(p) > 1000
        # just past the point lies a solid (except where the beam only grazes an edge or a tangent)
        assert small.occupied(p + 1e-6 * u).mean() > 0.995
        # and nothing on the way there
        t = np.linspace(0.0, 1.0, 25)[:-1]
        before = o + (t[None, :, None] * r[:, None, None] - 1e-6) * u[:, None, :]
        assert not small.occupied(before.reshape(-1, 3)).any()
        # every beam that found nothing within the range has nothing there
        dirs = cloud.pose.apply(EXACT.lidar.directions().reshape(-1, 3)) - o
        assert np.isfinite(small.world.cast(o, dirs, EXACT.lidar.max_range)).sum() == len(p)


def test_voxel_truth_far_from_the_origin_holds_every_hit(small):
    cloud = city_scan(20, EXACT)
    o = cloud.origin
    truth = small.world.truth_voxels(0.2, o - [15.0, 15.0, 3.0], o + [15.0, 15.0, 8.0], mode="overlap")
    assert truth.index_min[0] * 0.2 > OCTOMAP_REACH
    p = cloud.world_points()
    p = p[np.all((p >= o - [14.0, 14.0, 2.0]) & (p <= o + [14.0, 14.0, 7.0]), axis=1)]
    assert len(p) > 500
    k = np.floor(p * (1.0 / 0.2)).astype(np.int64) - truth.index_min
    assert truth.occupied[k[:, 0], k[:, 1], k[:, 2]].all()


def test_laser_scan_reads_the_section_at_sensor_height(small):
    for k in (5, 25, 50):
        scan = city_laser_scan(k, EXACT)
        x, y, th = scan.pose
        assert scan.max_range == EXACT.laser_max_range and len(scan) == 360
        u = np.column_stack([np.cos(th + scan.angles), np.sin(th + scan.angles)])
        hit = scan.ranges < scan.max_range
        assert 0.2 < hit.mean() < 1.0
        assert np.all(scan.ranges[~hit] == scan.max_range)  # no return reads max_range
        p = np.array([x, y]) + scan.ranges[:, None] * u
        assert small.occupied_2d(p[hit] + 1e-6 * u[hit], EXACT.height).mean() > 0.99
        t = np.linspace(0.0, 1.0, 40)[:-1]
        before = np.array([x, y]) + (t[None, :, None] * scan.ranges[:, None, None] - 1e-6) * u[:, None]
        assert not small.occupied_2d(before.reshape(-1, 2), EXACT.height).any()


def test_route_runs_on_the_roads_clear_of_every_solid(small):
    poses = DRIVE.poses2d()
    assert poses.shape == (DRIVE.n_scans, 3) and DRIVE.n_scans == 61
    steps = np.linalg.norm(np.diff(poses[:, :2], axis=0), axis=1)
    # chords across turns are shorter than the arc length between the poses
    assert np.all(steps <= DRIVE.spacing + 1e-9) and np.all(steps > 0.7 * DRIVE.spacing)
    route = small.route
    assert np.linalg.norm(np.diff(route, axis=0), axis=1).sum() == pytest.approx(1500.0)
    # the route runs on the streets' centre lines, cutting the corners by arcs (whose middle is
    # r·(1 − 1/√2) off both lines)
    dense = small.route_poses(np.arange(0.0, small.route_length, 0.5))
    off = np.minimum(np.abs(dense[:, :1] - small.streets_x[:, 0]).min(axis=1),
                     np.abs(dense[:, 1:2] - small.streets_y[:, 0]).min(axis=1))
    assert off.max() <= SMALL.turn_radius * (1 - math.sqrt(0.5)) + 1e-9
    assert np.mean(off < 1e-9) > 0.9
    # horizontal clearance of at least 1.5 m at car and sensor height, all along the route
    a = np.linspace(-np.pi, np.pi, 48, endpoint=False)
    dirs = np.column_stack([np.cos(a), np.sin(a), np.zeros_like(a)])
    for z in (0.5, 1.2, 1.8, 2.4):
        o = np.repeat(np.column_stack([dense[:, :2], np.full(len(dense), z)]), len(a), axis=0)
        r = small.world.cast(o, np.tile(dirs, (len(dense), 1)), 3.0)
        assert r.min() >= 1.5
    # headings follow the route
    ahead = small.route_poses(np.arange(0.0, small.route_length, 0.5) + 0.5)[:, :2] - dense[:, :2]
    assert np.median(np.cos(np.arctan2(ahead[:, 1], ahead[:, 0]) - dense[:, 2])) > 0.999


def test_truth_of_buildings_streets_and_ground(small):
    b = small.world.boxes
    tall = b[(b[:, 2] == 0.0) & (b[:, 5] > 6.0)][:50]
    centres = np.column_stack([(tall[:, :2] + tall[:, 3:5]) / 2, tall[:, 5] / 2])
    assert small.occupied(centres).all()
    assert small.occupied_2d(centres[:, :2], 1.8).all()
    road = np.column_stack([small.route, np.full(len(small.route), 1.8)])
    assert not small.occupied(road).any()
    assert small.occupied(road - [0, 0, 1.8]).all()  # the ground, z <= 0
    assert not small.occupied_2d(small.route, 1.8).any()


# ------------------------------------------------------------------ checks


def test_bad_arguments_are_refused():
    for bad in (dict(size=(100.0,)), dict(size=(50.0, 500.0)), dict(block=(100.0, 50.0)),
                dict(street_width=8.0), dict(route_length=0.0), dict(seed=-1), dict(park_share=1.5),
                dict(turn_radius=30.0), dict(centre=(np.nan, 0.0))):
        with pytest.raises(OccmapError):
            CityPlan(**bad)
    for bad in (dict(spacing=0.0), dict(noise_std=-1.0), dict(dropout=2.0), dict(laser_beams=0),
                dict(plan="town"), dict(lidar=None)):
        with pytest.raises(OccmapError):
            CityDrive(**bad)
    with pytest.raises(InvalidArgumentError, match="past the drive's end"):
        city_scan(DRIVE.n_scans, DRIVE)
    with pytest.raises(InvalidArgumentError, match="past the drive's end"):
        city_drive(DRIVE, stop=DRIVE.n_scans + 1)
    with pytest.raises(OccmapError):
        city_laser_scan(-1, DRIVE)


def test_plan_picture(small, tmp_path):
    from PIL import Image

    small.render_png(tmp_path / "town.png", resolution=2.0)
    px = np.asarray(Image.open(tmp_path / "town.png").convert("RGB")).astype(int)
    red = (px[..., 0] > 180) & (px[..., 1] < 90) & (px[..., 2] < 90)
    assert red.sum() > 300  # the route
    grey = (px[..., 0] == px[..., 1]) & (px[..., 1] == px[..., 2])
    assert (px[grey][:, 0] < 150).sum() > 2000 and (px[grey][:, 0] == 255).sum() > 5000  # buildings, ground
