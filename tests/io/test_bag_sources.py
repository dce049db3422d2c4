"""Maps from bags and pose files (occmap.sources, map2d / map3d on bags): real data written into
bags with rosbags' own writers gives the very map the same scans give through the API; the
poses come from tf (static mount + moving odometry), an odometry topic, or a pose file; what
cannot be placed is dropped and counted, what cannot be mapped at all is a clear error."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from occmap.cli import main
from occmap.errors import InvalidArgumentError
from occmap.geometry.se3 import SE3
from occmap.mapping2d import map_scan_stream, map_scans
from occmap.io.octomap import write_bt
from occmap.io.poses import read_poses
from occmap.octree import OcTree
from occmap.scan import LaserScan, stack_scans
from occmap.sources import BagClouds, BagScans, CloudFiles

pytest.importorskip("rosbags")
from bag_writing import (  # noqa: E402
    CLOUD, MOUNT, ODOM, ROS_TYPE, SCAN, SHARED_BAG, TF, TF_STATIC, packed, write_bag,
)

KINDS = ("ros1", "sqlite3", "mcap")


def ros_stamp(stamp):
    """A stamp as a header carries it (whole nanoseconds) and decodes it."""
    sec = math.floor(stamp)
    return sec + round((stamp - sec) * 1e9) * 1e-9


# ---------------------------------------------------------------------- 2D: CARMEN scans as LaserScan + tf


@pytest.fixture(scope="module")
def intel(data_dir):
    """The first 200 scans of the corrected Intel log."""
    from occmap.io.carmen import iter_carmen

    return list(itertools.islice(iter_carmen(data_dir / "carmen" / "intel-corrected.log.gz"), 200))


def robot_poses(scans):
    """``T_odom_base_link`` that puts the laser (mounted at MOUNT on base_link) at each scan's pose."""
    poses = np.array([s.pose for s in scans])
    laser = SE3.from_euler_zyx(poses[:, 2], 0.0, 0.0, np.c_[poses[:, :2], np.zeros(len(poses))])
    return laser @ SE3.from_quat((1.0, 0.0, 0.0, 0.0), MOUNT).inv()


def laser_bag(scans, tf=True, odom=False, drop_tf_after=None):
    """/scan (frame laser) with the static mount on /tf_static and odom -> base_link on /tf (and/or
    /odom) at each scan stamp; tf stops after ``drop_tf_after`` scans when given."""
    robots = robot_poses(scans)

    def build(m):
        yield "/tf_static", TF_STATIC, scans[0].stamp - 0.5, m.tf([m.transform(0.0, "base_link", "laser", MOUNT,
                                                                                (0, 0, 0, 1))])
        for k, (s, robot) in enumerate(zip(scans, robots)):
            t = robot.translation
            q = robot.rotation.as_quat()  # (w, x, y, z)
            xyzw = (q[1], q[2], q[3], q[0])
            if tf and (drop_tf_after is None or k < drop_tf_after):
                yield "/tf", TF, s.stamp, m.tf([m.transform(s.stamp, "odom", "base_link", t, xyzw)])
            if odom:
                yield "/odom", ODOM, s.stamp, m.odometry(s.stamp, "odom", "base_link", t, xyzw)
            inc = float(s.angles[1] - s.angles[0])
            yield "/scan", SCAN, s.stamp, m.laser_scan(s.stamp, "laser", s.ranges, float(s.angles[0]), inc, 0.0,
                                                       s.max_range)

    return build


def as_recorded(scans):
    """The scans as a LaserScan message holds them: float32 ranges, angles from float32
    angle_min / angle_increment, float32 range_max, the stamp in whole nanoseconds."""
    out = []
    for s in scans:
        a0, inc = float(np.float32(s.angles[0])), float(np.float32(s.angles[1] - s.angles[0]))
        out.append(LaserScan(s.pose, s.ranges.astype(np.float32).astype(np.float64),
                             a0 + inc * np.arange(len(s.ranges)), float(np.float32(s.max_range)), ros_stamp(s.stamp)))
    return out


@pytest.mark.parametrize("kind", KINDS)
def test_map2d_from_a_bag_is_map_scans_of_the_same_scans(tmp_path, intel, kind, capsys):
    path = write_bag(tmp_path, kind, laser_bag(intel))
    source = BagScans(path)
    assert (source.topic, source.sensor_frame, source.fixed_frame, len(source)) == ("/scan", "laser", "odom", 200)
    placed = list(source)
    assert not source.dropped and source.tilted == 0
    # tf: laser = (odom -> base_link) · (static mount), back to the CARMEN poses but for rounding
    got = np.array([s.pose for s in placed])
    want = np.array([s.pose for s in intel])
    np.testing.assert_allclose(got[:, :2], want[:, :2], rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.angle(np.exp(1j * (got[:, 2] - want[:, 2]))), 0.0, atol=1e-12)

    expected = map_scans(stack_scans(as_recorded(intel)), 0.1)
    assert main(["map2d", str(path), "-o", str(tmp_path / "bag.yaml"), "--resolution", "0.1"]) == 0
    out = capsys.readouterr().out
    assert "/scan in odom: 200 messages, 200 scans used, 0 dropped" in out
    expected.grid.save(tmp_path / "api.yaml")
    # the poses differ from the log's in the last bits only: not one cell of 200 scans changes
    assert (tmp_path / "bag.pgm").read_bytes() == (tmp_path / "api.pgm").read_bytes()
    assert (tmp_path / "bag.yaml").read_text() == (tmp_path / "api.yaml").read_text().replace("api.pgm", "bag.pgm")
    streamed = map_scan_stream(BagScans(path), 0.1)
    np.testing.assert_array_equal(streamed.grid.log_odds(), map_scans(stack_scans(placed), 0.1).grid.log_odds())


def test_odometry_topic_places_scans_without_tf(tmp_path, intel):
    scans = intel[:60]
    path = write_bag(tmp_path, "mcap", laser_bag(scans, tf=False, odom=True))
    with pytest.raises(InvalidArgumentError, match=r"odom"):  # tf_static alone does not reach the fixed frame
        list(BagScans(path, fixed_frame="odom"))
    from_odom = [s.pose for s in BagScans(path, odom_topic="/odom")]
    from_tf = [s.pose for s in BagScans(write_bag(tmp_path, "mcap", laser_bag(scans), name="tf"))]
    np.testing.assert_array_equal(from_odom, from_tf)


def lagging_tf(build, lag, static_last=False):
    """The messages of ``build`` with each tf message recorded when the scan ``lag`` places later
    arrives (its header stamp unchanged), and the static mount, with ``static_last``, at the end."""
    def lagged(m):
        messages = list(build(m))
        scan_times = [t for topic, _, t, _ in messages if topic == "/scan"]
        end = scan_times[-1] + 1.0
        out = []
        for topic, kind, t, msg in messages:
            if topic == "/tf":
                later = [s for s in scan_times if s >= t]
                t = later[lag] + 1e-4 if lag < len(later) else end
            elif topic == "/tf_static" and static_last:
                t = end + 1.0
            out.append((topic, kind, t, msg))
        return out

    return lagged


@pytest.mark.parametrize("lag, static_last", [(3, False), (70, False), (10_000, False), (0, True)])
def test_tf_recorded_after_the_scans_it_places_gives_the_same_poses(tmp_path, intel, lag, static_last):
    """tf is read in the same pass as the scans: a scan waits until tf has passed its stamp (tf
    lagging a few scans, or more than a batch), and when tf lags too far (all of it at the end) or
    the static mount comes last, the whole tf is read first; the poses are the same throughout."""
    scans = intel[:120]
    want = [s.pose for s in BagScans(write_bag(tmp_path, "ros1", laser_bag(scans), name="timely"))]
    source = BagScans(write_bag(tmp_path, "ros1", lagging_tf(laser_bag(scans), lag, static_last), name="late"),
                      fixed_frame="odom")
    got = [s.pose for s in source]
    assert not source.dropped
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)  # poses looked up in other batches: rounding apart


@pytest.mark.parametrize("kind", ("ros1", "mcap"))
def test_first_iteration_goes_on_from_what_opening_read(tmp_path, intel, kind, monkeypatch):
    """Opening a source reads up to the sensor's first message and 1 s of tf past it (the root
    frame); the first iteration goes on from there, the next ones read the bag anew, and when
    what opening read passes HEAD_BYTES the first one does too: the same scans every time."""
    import occmap.sources.bags as bags

    path = write_bag(tmp_path, kind, laser_bag(intel[:80]))
    source = BagScans(path)
    assert source.fixed_frame == "odom" and source.sensor_frame == "laser"
    first = next(m.time for m in source._head if m.topic == "/scan")
    times = [m.time for m in source._head]
    assert times[-1] > first + 1.0 >= times[-2]  # held: up to the first message 1 s past the first scan
    runs = [stack_scans(source), stack_scans(source)]
    monkeypatch.setattr(bags, "HEAD_BYTES", 500)  # less than a scan
    reread = BagScans(path)
    assert reread._head == [] and reread.fixed_frame == "odom"
    runs.append(stack_scans(reread))
    assert len(runs[0].poses) == 80
    for run in runs[1:]:
        for a, b in zip(runs[0], run):
            np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("kind", ("ros1", "mcap"))
def test_the_first_scans_wait_only_for_the_tf_they_need(tmp_path, intel, kind, monkeypatch):
    """A run's tf goes into the tree as its batches need it: the first 25 scans are placed with
    the tf recorded up to TF_AHEAD after the 25th, not with the whole chunk's (the 120 scans' tf
    here); then the rest comes in, and the poses are those of the whole tf."""
    import occmap.sources.bags as bags
    from occmap.io.bags.transforms import TransformFeed

    scans = intel[:120]
    path = write_bag(tmp_path, kind, laser_bag(scans))
    added = []
    add = TransformFeed.add
    monkeypatch.setattr(TransformFeed, "add", lambda self, run: (added.append(len(run)), add(self, run))[1])
    stacks = BagScans(path, fixed_frame="odom").stacks()
    first = next(stacks)
    assert len(first.poses) == 25
    ahead = bags.TF_AHEAD + 1e-9
    due = sum(1 for s in scans if s.stamp <= scans[24].stamp + ahead)  # odom -> base_link messages by then
    assert sum(added) == due + 1  # and the static mount
    rest = list(stacks)
    assert sum(added) >= len(scans) + 1
    got = np.concatenate([first.poses] + [r.poses for r in rest])
    np.testing.assert_allclose(got, [s.pose for s in BagScans(path)], rtol=0, atol=0)


def test_scans_outside_the_tf_data_are_dropped_and_counted(tmp_path, intel, capsys):
    path = write_bag(tmp_path, "sqlite3", laser_bag(intel[:50], drop_tf_after=40))
    assert main(["map2d", str(path), "-o", str(tmp_path / "m.yaml")]) == 0
    cap = capsys.readouterr()
    assert "50 messages, 40 scans used, 10 dropped" in cap.out
    assert "10 no tf at that time (outside the tf data)" in cap.err


def test_upside_down_laser_sweeps_clockwise(tmp_path, intel):
    """A laser mounted upside down (rolled by π): its beams land where a level laser's do when the
    beam angles are negated."""
    s = intel[0]

    def build(m):
        yield "/tf", TF, s.stamp, m.tf([m.transform(s.stamp, "odom", "laser", (1.0, 2.0, 0.3), (1.0, 0.0, 0.0, 0.0))])
        inc = float(s.angles[1] - s.angles[0])
        yield "/scan", SCAN, s.stamp, m.laser_scan(s.stamp, "laser", s.ranges, float(s.angles[0]), inc, 0.0,
                                                   s.max_range)

    (scan,) = list(BagScans(write_bag(tmp_path, "ros1", build)))
    np.testing.assert_allclose(scan.pose, (1.0, 2.0, 0.0), atol=1e-15)
    ends = np.c_[np.cos(scan.angles), np.sin(scan.angles)][:5]
    # the laser's beam (cos a, sin a, 0) in odom is (cos a, -sin a, 0)
    a0 = float(np.float32(s.angles[0]))
    np.testing.assert_allclose(ends[0], (math.cos(a0), -math.sin(a0)), atol=1e-12)


def test_missing_tf_link_names_both_frames_and_the_time(tmp_path, intel, capsys):
    s = intel[0]

    def build(m):
        yield "/tf", TF, s.stamp, m.tf([m.transform(s.stamp, "odom", "base_link", (0, 0, 0), (0, 0, 0, 1))])
        yield "/scan", SCAN, s.stamp, m.laser_scan(s.stamp, "laser", s.ranges, -1.5, 0.01, 0.0, s.max_range)

    path = write_bag(tmp_path, "mcap", build)
    assert main(["map2d", str(path), "-o", str(tmp_path / "m.yaml")]) == 2
    err = capsys.readouterr().err
    assert "no tf from 'odom' to the sensor frame 'laser'" in err and f"at {ros_stamp(s.stamp):.9f} s" in err


def test_shared_bag_without_poses_suggests_scan_matching(data_dir, tmp_path, capsys):
    assert main(["map2d", str(data_dir / SHARED_BAG), "-o", str(tmp_path / "m.yaml")]) == 2
    err = capsys.readouterr().err
    assert "no tf" in err and "--scan-match" in err and "--poses" in err
    assert not (tmp_path / "m.yaml").exists()


def test_wrong_topic_type_and_truncated_bag(tmp_path, intel, capsys):
    path = write_bag(tmp_path, "ros1", laser_bag(intel[:5]))
    assert main(["map3d", str(path), "--topic", "/scan", "-o", str(tmp_path / "m.bt")]) == 2
    assert "topic '/scan' holds sensor_msgs/msg/LaserScan, not sensor_msgs/msg/PointCloud2" in capsys.readouterr().err
    assert main(["map3d", str(path), "-o", str(tmp_path / "m.bt")]) == 2
    assert "no PointCloud2 topics" in capsys.readouterr().err
    cut = tmp_path / "cut.bag"
    cut.write_bytes(path.read_bytes()[: path.stat().st_size * 2 // 3])
    assert main(["map2d", str(cut), "-o", str(tmp_path / "m.yaml")]) == 2
    assert "cut.bag" in capsys.readouterr().err


# ---------------------------------------------------------------------- 3D: HDL-32 and UOS scans as PointCloud2 + tf


@pytest.fixture(scope="module", params=["hdl32", "uos"])
def scan_pair(request, data_dir):
    """Two real 3D scans, 8,192 points of each (float32 as a PointCloud2 carries them, no-returns
    NaN), and their poses: the HDL-32 pair (the second placed by its registration), or UOS scans
    0 and 1 with their registered poses."""
    from occmap.io.pointclouds import read_pcd, read_uos

    if request.param == "hdl32":
        folder = data_dir / "scans3d" / "hdl32_pair"
        clouds = []
        for name in ("251370668.pcd", "251371071.pcd"):
            pts = read_pcd(folder / name, drop_origin=False).points[::8][:8192].astype(np.float32)
            pts[~pts.any(axis=1)] = np.nan
            clouds.append(pts)
        relative = np.loadtxt(folder / "relative.txt")
        u, _, vt = np.linalg.svd(relative[:3, :3])
        relative[:3, :3] = u @ vt  # printed with six digits
        start = SE3.from_quat((1.0, 0.0, 0.0, 0.0), (0.5, -1.0, 1.8))
        return clouds, [start, start @ SE3(relative)]
    scans = [read_uos(data_dir / "scans3d" / "uos_3dtk" / f"scan00{k}.3d") for k in (0, 1)]
    return [c.points[::9][:8192].astype(np.float32) for c in scans], [c.pose for c in scans]


def layouts(xyz):
    """PointCloud2 keyword arguments of four field layouts holding ``xyz`` (float32 (N, 3))."""
    n = len(xyz)
    x, y, z = xyz.T
    ring, intensity = (np.arange(n) % 32).astype(np.uint16), np.linspace(0, 1, n).astype(np.float32)

    def cloud(columns, step, order="<", height=1):
        fields = [(name, off, ROS_TYPE[np.dtype(t).str[1:]], 1) for name, off, t, _ in columns]
        width = n // height
        return dict(height=height, width=width, fields=fields, point_step=step, row_step=width * step,
                    data=packed(columns, step, order), big_endian=order == ">", dense=False)

    return {
        "/padded": cloud([("x", 0, "f4", x), ("y", 4, "f4", y), ("z", 8, "f4", z)], 16),
        "/float64": cloud([("x", 0, "f8", x.astype(np.float64)), ("y", 8, "f8", y.astype(np.float64)),
                           ("z", 16, "f8", z.astype(np.float64))], 24),
        "/big_endian_intensity_ring": cloud([("x", 0, "f4", x), ("y", 4, "f4", y), ("z", 8, "f4", z),
                                             ("intensity", 12, "f4", intensity), ("ring", 16, "u2", ring)], 20, ">"),
        "/organised": cloud([("x", 0, "f4", x), ("y", 4, "f4", y), ("z", 8, "f4", z), ("ring", 12, "u2", ring)],
                            16, height=32),
    }


def cloud_bag(clouds, poses, empty_at=None):
    """Each cloud in every layout at stamps 10 s, 11 s, ... in frame velodyne, placed by a static
    mount base_link -> velodyne and moving map -> base_link tf."""
    mount = SE3.from_quat((1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 1.8))

    def build(m):
        yield "/tf_static", TF_STATIC, 9.0, m.tf([m.transform(0.0, "base_link", "velodyne", (0.0, 0.0, 1.8),
                                                              (0, 0, 0, 1))])
        for k, (xyz, pose) in enumerate(zip(clouds, poses)):
            robot = pose @ mount.inv()
            q = robot.rotation.as_quat()
            stamp = 10.0 + k
            yield "/tf", TF, stamp, m.tf([m.transform(stamp, "map", "base_link", robot.translation,
                                                      (q[1], q[2], q[3], q[0]))])
            for topic, kw in layouts(xyz).items():
                yield topic, CLOUD, stamp, m.cloud(stamp, "velodyne", **kw)
        if empty_at is not None:
            kw = layouts(np.zeros((0, 3), np.float32))["/padded"]
            yield "/padded", CLOUD, empty_at, m.cloud(empty_at, "velodyne", **kw)

    return build


def octree_bytes(clouds, poses, tmp_path, resolution=0.2):
    """The .bt of the clouds inserted through the API at ``poses``."""
    tree = OcTree(resolution)
    for xyz, pose in zip(clouds, poses):
        pts = xyz.astype(np.float64)
        pts = pts[np.isfinite(pts).all(axis=1)]
        tree.insert_point_cloud(pose.apply(pts), pose.translation, -1.0, False)
    write_bt(tree, tmp_path / "api.bt")
    return (tmp_path / "api.bt").read_bytes()


@pytest.mark.parametrize("kind", KINDS)
def test_map3d_from_a_bag_is_octree_inserts_of_the_same_clouds(tmp_path, scan_pair, kind, capsys):
    clouds, poses = scan_pair
    path = write_bag(tmp_path, kind, cloud_bag(clouds, poses, empty_at=10.5))
    placed = list(BagClouds(path, topic="/padded"))
    want = octree_bytes(clouds, [SE3(c.pose.matrix) for c in placed], tmp_path)
    for c, pose in zip(placed, poses):  # tf composes the mount back: equal but for rounding
        np.testing.assert_allclose(c.pose.matrix, pose.matrix, atol=1e-12)
    assert want == octree_bytes(clouds, poses, tmp_path)  # and the rounding moves no voxel
    for topic in layouts(clouds[0]):
        out = tmp_path / f"{topic[1:]}.bt"
        assert main(["map3d", str(path), "--topic", topic, "-o", str(out), "--resolution", "0.2"]) == 0, topic
        assert out.read_bytes() == want, topic
        cap = capsys.readouterr()
        assert f"{topic} in map:" in cap.out
        if topic == "/padded":
            assert "3 messages, 2 clouds used, 1 dropped" in cap.out and "1 cloud with no points" in cap.err


# ---------------------------------------------------------------------- pose files


def test_map3d_cloud_files_with_a_pose_file(tmp_path, scan_pair, capsys):
    from occmap.io.pointclouds import write_xyz

    clouds, poses = scan_pair
    files = []
    for k, xyz in enumerate(clouds):
        files.append(tmp_path / f"c{k}.xyz")
        write_xyz(files[-1], xyz[np.isfinite(xyz).all(axis=1)].astype(np.float64))
    (tmp_path / "poses.txt").write_text("".join(" ".join(f"{v:.17g}" for v in p.matrix.reshape(-1)) + "\n"
                                                for p in poses))
    track = read_poses(tmp_path / "poses.txt")
    assert track.format == "matrix" and track.stamps is None
    np.testing.assert_allclose(track.poses.matrix, np.array([p.matrix for p in poses]), atol=1e-15)
    want = octree_bytes(clouds, list(track.poses), tmp_path)
    assert [c.pose.matrix.tolist() for c in CloudFiles(files, poses=track)] == track.poses.matrix.tolist()
    assert main(["map3d", *map(str, files), "--poses", str(tmp_path / "poses.txt"), "-o", str(tmp_path / "p.bt"),
                 "--resolution", "0.2"]) == 0
    assert (tmp_path / "p.bt").read_bytes() == want
    assert "carry no sensor pose" not in capsys.readouterr().err
    # one pose for two clouds
    (tmp_path / "one.txt").write_text((tmp_path / "poses.txt").read_text().splitlines()[0] + "\n")
    assert main(["map3d", *map(str, files), "--poses", str(tmp_path / "one.txt"), "-o", str(tmp_path / "q.bt")]) == 2
    assert "one.txt: 1 poses for 2 point clouds" in capsys.readouterr().err


# ---------------------------------------------------------------------- local and localize


def carmen_twin(path, scans):
    """A CARMEN log of ROBOTLASER1 lines holding exactly ``scans`` (placed LaserScans whose angles
    are ``a0 + i * step``): the robot pose is the laser's, ``repr`` keeps every bit."""
    lines = []
    for s in scans:
        a0, step = float(s.angles[0]), float(np.float32(s.angles[1] - s.angles[0]))
        assert np.array_equal(s.angles, a0 + step * np.arange(len(s)))
        x, y, th = map(repr, map(float, s.pose))
        lines.append(" ".join(["ROBOTLASER1 0", repr(a0), "3.14", repr(step), repr(float(s.max_range)), "0 0",
                               str(len(s)), *map(repr, s.ranges.tolist()), "0", x, y, th, x, y, th, "0 0 0 0 0",
                               repr(float(s.stamp)), "host", repr(float(s.stamp))]))
    path.write_text("\n".join(lines) + "\n")
    return path


def test_local_and_localize_read_a_bag_as_they_read_the_same_log(tmp_path, intel, capsys):
    bag = write_bag(tmp_path, "mcap", laser_bag(intel[:80]))
    log = carmen_twin(tmp_path / "twin.log", list(BagScans(bag)))
    for name, source in (("bag", bag), ("log", log)):
        assert main(["local", str(source), "-o", str(tmp_path / f"{name}.gif"), "--max-frames", "10",
                     "--title", "the same scans"]) == 0
    assert (tmp_path / "bag.gif").read_bytes() == (tmp_path / "log.gif").read_bytes()

    assert main(["map2d", str(bag), "-o", str(tmp_path / "map.yaml")]) == 0
    x, y, th = intel[0].pose
    for name, source in (("bag", bag), ("log", log)):
        assert main(["localize", str(tmp_path / "map.yaml"), str(source), "-o", str(tmp_path / f"{name}.csv"),
                     "--init", f"{x},{y},{th}", "--particles", "300", "--beams", "30"]) == 0
    assert (tmp_path / "bag.csv").read_text() == (tmp_path / "log.csv").read_text()
    out = capsys.readouterr().out
    assert out.count("read 80 scans from") == 2


def test_tum_poses_place_a_bags_scans_by_stamp(data_dir, tmp_path, capsys):
    """The shared bag (no tf) with a TUM track over its first half: scans there are placed at the
    interpolated pose, the others dropped and counted."""
    from occmap.io.bags import decode_laser_scan, open_bag

    bag = data_dir / SHARED_BAG
    with open_bag(bag) as b:
        stamps = np.array([decode_laser_scan(m.raw, m.encoding).scan.stamp for m in b.messages("/scan")])
    knots = np.linspace(stamps[0], stamps[len(stamps) // 2], 20)
    track = tmp_path / "track.txt"
    track.write_text("# timestamp tx ty tz qx qy qz qw\n" + "".join(
        f"{float(t)!r} {0.1 * k!r} 0 0 0 0 {math.sin(0.05 * k)!r} {math.cos(0.05 * k)!r}\n"
        for k, t in enumerate(knots)))
    source = BagScans(bag, poses=read_poses(track))
    placed = list(source)
    covered = stamps <= knots[-1] + 0.05
    assert len(placed) == covered.sum() and dict(source.dropped) == {
        f"no pose in {track} within 0.05 s": int((~covered).sum())}
    got = np.array([s.pose for s in placed])
    np.testing.assert_allclose(got[:, 0], np.interp(stamps[covered], knots, 0.1 * np.arange(20)), atol=1e-12)
    np.testing.assert_allclose(got[:, 2], np.interp(stamps[covered], knots, 0.1 * np.arange(20)), atol=1e-12)
    assert main(["map2d", str(bag), "--poses", str(track), "-o", str(tmp_path / "m.yaml")]) == 0
    out = capsys.readouterr().out
    assert f"/scan in the frame of {track}: {len(stamps)} messages, {covered.sum()} scans used" in out


def test_bag_options_are_refused_for_other_inputs(data_dir, tmp_path, capsys):
    log = data_dir / "carmen" / "intel-corrected.log.gz"
    assert main(["map2d", str(log), "--poses", str(log), "--topic", "/scan", "-o", str(tmp_path / "m.yaml")]) == 2
    assert "--topic, --poses: not for a CARMEN log (it carries its poses)" in capsys.readouterr().err
    assert main(["local", str(log), "--fixed-frame", "map", "-o", str(tmp_path / "m.gif")]) == 2
    assert "--fixed-frame: not for a CARMEN log" in capsys.readouterr().err
    pcd = data_dir / "scans3d" / "hdl32_pair" / "251370668.pcd"
    assert main(["map3d", str(pcd), "--odom-topic", "/odom", "-o", str(tmp_path / "m.bt")]) == 2
    assert "--odom-topic: not for point-cloud files" in capsys.readouterr().err
    assert main(["map3d", str(pcd), "--calib", str(pcd), "-o", str(tmp_path / "m.bt")]) == 2
    assert "--calib and --pose-format go with --poses FILE" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


def test_map2d_scan_matches_a_bag_without_poses(tmp_path, intel, capsys):
    from dataclasses import replace

    from occmap.mapping2d import map_scan_stream
    from occmap.scan import with_poses
    from occmap.slam import match_scans

    from occmap.sim.world2d import World2D, simulate_scans

    world = World2D.default()  # dense scans, 0.1 m apart: the ranges alone place them
    sim = simulate_scans(world, world.default_trajectory(1000)[:120], n_beams=181, fov=np.pi, max_range=10.0,
                         sigma=0.01, rng=4, stamps=1.0 + 0.1 * np.arange(120))
    path = write_bag(tmp_path, "mcap", laser_bag(sim, tf=False))
    out = tmp_path / "m.yaml"
    assert main(["map2d", str(path), "--scan-match", "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "scan matching: 120 scans, 119 matched, 0 failed and 0 rejected" in printed
    scans = [replace(s, odom=s.pose) for s in BagScans(path, unposed=True)]  # the mount's pose, the prior
    api = map_scan_stream(with_poses(scans, match_scans(scans).poses), 0.05, None).grid  # what map2d does
    api.save(tmp_path / "api.yaml")
    assert (tmp_path / "api.pgm").read_bytes() == (tmp_path / "m.pgm").read_bytes()
    # with tf the bag's poses are the matcher's prior: Intel's scans, too far apart for the ranges
    # alone (0.67 m and 22° between them), are matched
    posed = write_bag(tmp_path, "mcap", laser_bag(intel[:120]), name="tf")
    assert main(["map2d", str(posed), "--scan-match", "-o", str(tmp_path / "p.yaml")]) == 0
    assert "120 scans, 119 matched, 0 failed and 0 rejected" in capsys.readouterr().out


def test_shared_bag_maps_with_scan_matching(data_dir, tmp_path, capsys):
    assert main(["map2d", str(data_dir / SHARED_BAG), "--scan-match", "-o", str(tmp_path / "m.yaml")]) == 0
    out = capsys.readouterr().out
    assert "360 scans, 359 matched, 0 failed and 0 rejected" in out
    assert "in the frame of its first scan (scan-matched): 360 messages, 360 scans used" in out


# ---------------------------------------------------------------------- memory


@pytest.mark.parametrize("kind", ("ros1", "mcap"))
def test_scan_stream_memory_does_not_grow_with_the_bag(tmp_path, kind):
    """Streaming BagScans holds a chunk or two of the file (the writers' chunks are of 1 MiB) and
    a batch of scans (256 KiB of messages), whatever the bag's length: the peak for 2,400 scans of
    1,000 beams (9.6 MB of ranges) is that for 800 (3.2 MB), and below 4 MB."""
    import tracemalloc

    def build(count):
        def messages(m):
            yield "/tf_static", TF_STATIC, 0.5, m.tf([m.transform(0.0, "base_link", "laser", MOUNT, (0, 0, 0, 1))])
            for k in range(count):
                yield "/scan", SCAN, 1.0 + 0.1 * k, m.laser_scan(1.0 + 0.1 * k, "laser", np.full(1000, 1.0 + k % 7),
                                                                 -1.5, 0.003, 0.0, 20.0)
        return messages

    peaks = {}
    for count in (800, 2400):
        path = write_bag(tmp_path, kind, build(count), name=f"scans{count}")
        source = BagScans(path)  # opened, tf read: a cost fixed per bag
        tracemalloc.start()
        try:
            n = sum(1 for _ in source)
            peaks[count] = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert n == count and source.fixed_frame == "base_link"
    assert peaks[2400] < 1.2 * peaks[800] and peaks[2400] < 4e6, peaks


def test_stream_cuts_a_sources_stacks_without_copying(intel):
    """map_scan_stream takes a source's stacks (a bag's) in chunks of its schedule at most, cut
    where a stack ends rather than copied together with the next, as views of the stacks; the
    map is map_scans' to the bit. With a recorder the chunks are its batches exactly."""
    from occmap.mapping2d import _restacked

    whole = stack_scans(intel)
    cuts = [0, 25, 140, 147, 200]
    stacks = [whole.take(slice(a, b)) for a, b in zip(cuts, cuts[1:])]
    chunks = list(_restacked(iter(stacks), 50, 10, exact=False))
    assert [len(c.poses) for c in chunks] == [10, 10, 5, 10, 20, 40, 45, 7, 50, 3]
    assert all(np.shares_memory(c.ranges, whole.ranges) for c in chunks)
    np.testing.assert_array_equal(np.concatenate([c.ranges for c in chunks]), whole.ranges)
    assert [len(c.poses) for c in _restacked(iter(stacks), 60, 60, exact=True)] == [60, 60, 60, 20]

    class Stacked:
        def stacks(self):
            return iter(stacks)

    np.testing.assert_array_equal(map_scan_stream(Stacked(), 0.1).grid.log_odds(),
                                  map_scans(whole, 0.1).grid.log_odds())
