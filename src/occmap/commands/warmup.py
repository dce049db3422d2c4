"""``occmap warmup``: compile every kernel occmap uses, with every argument type it passes, into
Numba's on-disk cache, so that no later command or program waits for the compiler.

``make`` runs it after installing and whenever it clears the kernel cache. It drives each part of
the library through its public interface on small synthetic inputs that take every code path
with its own kernels (the octree's large-scan paths need scans of more than 20,000 rays); a
warm cache makes it a matter of seconds. Each job is independent: they run side by side in
processes of their own.
"""

from __future__ import annotations

import os
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from multiprocessing import get_context
from pathlib import Path

import numpy as np


def add_parser(subparsers):
    return subparsers.add_parser("warmup", help="compile every kernel into the on-disk cache (make runs it after "
                                 "installing), so no later command waits for the compiler")


def geometry(folder: Path) -> None:
    """Every public function of :mod:`occmap.geometry`, on one element and on a batch."""
    from .. import geometry as g

    rng = np.random.default_rng(0)
    for n in ((), (3,)):
        w = rng.normal(size=(*n, 3))
        R = g.exp_so3(w)
        q = g.matrix_to_quat(R)
        g.quat_to_matrix(q)
        g.log_so3(R)
        g.hat(w)
        g.vee(g.hat(w))
        g.is_rotation(R)
        g.nearest_rotation(R + 1e-3)
        axis, angle = g.matrix_to_axis_angle(R)
        g.axis_angle_to_matrix(axis, angle)
        g.axis_angle_to_quat(axis, angle)
        g.quat_to_axis_angle(q)
        g.quat_multiply(q, q)
        g.quat_conjugate(q)
        g.quat_inverse(q)
        g.quat_normalize(2.0 * q)
        g.quat_rotate(q, w)
        g.quat_slerp(q, g.quat_normalize(q + 0.1), 0.3)
        g.quat_to_xyzw(q)
        g.quat_from_xyzw(g.quat_to_xyzw(q))
        g.matrix_to_euler_zyx(R)
        g.euler_zyx_to_matrix(*rng.normal(size=(3, *n)))
        g.rot_x(w[..., 0]), g.rot_y(w[..., 1]), g.rot_z(w[..., 2])
        T = g.make_transform(R, w)
        g.invert_transform(T)
        g.compose_transforms(T, T)
        g.transform_points(T, w)
        g.log_se3(T)
        g.exp_se3(rng.normal(size=(*n, 6)))
        theta = rng.normal(size=n)
        g.rot2(theta)
        g.so2_angle(g.rot2(theta))
        g.wrap_angle(theta)
        pose = rng.normal(size=(*n, 3))
        g.se2_from_matrix(g.se2_matrix(pose[..., 0], pose[..., 1], pose[..., 2]))
        g.unicycle_step(pose, 1.0, 0.1, 0.1)
        g.diff_drive_step(pose, 0.5, 0.6, 0.4, 0.1)
        g.bicycle_step(pose, 1.0, 0.1, 0.8, 0.1)
        g.apply_odometry(pose, g.odometry_delta(pose, pose + 0.1), (0.1, 0.1, 0.1, 0.1), rng)
    g.euler_zyx_to_matrix(0.3, 0.2, 0.1)  # plain floats
    g.se2_matrix(1.0, 2.0, 0.3)
    g.rot2(0.3), g.wrap_angle(4.0), g.rot_x(0.1), g.rot_y(0.1), g.rot_z(0.1)
    g.random_rotations(4, rng=1)
    r = g.SO3.from_rotvec(rng.normal(size=(2, 3)))
    (r @ r.inv()).apply(np.zeros((2, 3)))
    r.as_quat(), r.as_rotvec(), r.as_euler_zyx(), r.magnitude()
    g.SO3.from_quat(r.as_quat())
    s = g.SE3.from_euler_zyx(0.3, 0.2, 0.1, translation=[1.0, 2.0, 3.0])
    (s @ s.inv()).apply(np.zeros((2, 3)))
    g.SE3.exp(s.log()).interpolate(s, 0.3)
    g.SE3.from_quat([1.0, 0.0, 0.0, 0.0], translation=[0.0, 0.0, 1.0])
    (g.SO2.from_angle(0.3) @ g.SO2.from_angle(0.2)).interpolate(g.SO2.from_angle(0.1), 0.5)
    e = g.SE2.from_xytheta(1.0, 2.0, 0.3)
    (e @ e.inv()).apply(np.zeros((2, 2)))
    e.interpolate(e, 0.5)
    tree = g.FrameTree()
    tree.set_transform("map", "odom", np.eye(4), static=True)
    tree.set_transform("odom", "base", s, stamp=0.0)
    tree.set_transform("odom", "base", s @ s, stamp=1.0)
    tree.lookup("map", "base", stamp=0.25)
    tree.transform_points("map", "base", [1.0, 0.0, 0.0], stamp=0.5)
    model = g.OdometryMotionModel(0.05, 0.02, 0.05, 0.01)
    particles = np.zeros((10, 3))
    model.sample(particles, particles[0], particles[0] + 0.1, rng)


def _office_log(folder: Path) -> Path:
    """A CARMEN log of 40 simulated scans in the office (written once per folder): the commands
    read scans from logs, whose arrays (shared angles, read-only) type the kernels their own way."""
    from ..sim import World2D, simulate_scans

    path = folder / "office.log"
    if not path.exists():
        world = World2D.default()
        scans = simulate_scans(world, world.default_trajectory(n=40), n_beams=180, max_range=10.0, rng=3)
        path.write_text("".join(
            f"FLASER {len(s.ranges)} " + " ".join(f"{r:.3f}" for r in np.minimum(s.ranges, 10.0))
            + f" {s.pose[0]} {s.pose[1]} {s.pose[2]} {s.pose[0]} {s.pose[1]} {s.pose[2]} {k}.0 warmup {k}.0\n"
            for k, s in enumerate(scans)))
    return path


def grids(folder: Path) -> None:
    """The 2D grid (lidar and sonar; fixed, loaded and growing), map_server files, the simulated
    office, a CARMEN log."""
    from ..grid2d import LidarModel, OccupancyGrid2D, SonarModel
    from ..io.carmen import read_carmen
    from ..mapping2d import map_scans
    from ..mapping2d_recording import MappingRecorder
    from ..sim import World2D, simulate_scans, simulate_sonar
    from .demo import map_simulated_office

    map_simulated_office(folder)  # a fixed grid, its files and pictures
    world = World2D.default()
    poses = world.default_trajectory(n=20)
    scans = simulate_scans(world, poses, n_beams=90, max_range=10.0, rng=1)
    P = np.array([s.pose for s in scans])
    R = np.array([s.ranges for s in scans])
    growing = OccupancyGrid2D(0.1)
    growing.insert_scan(P[0], R[0], scans[0].angles, max_range=10.0, model=LidarModel(0.7, 0.45))
    growing.insert_scans(P, R, np.repeat(scans[0].angles[None], len(P), axis=0), max_range=8.0)
    growing.log_odds_at(P[:, :2])
    radar_r, radar_a = R[:2, :20].reshape(-1), np.tile(scans[0].angles[:20], 2)
    growing.insert_radar(P[0], radar_r[:20], radar_a[:20], 8.0)
    growing.insert_radar(P[:2], radar_r, radar_a, 8.0, sweeps=np.repeat(np.arange(2), 20),
                         radial_velocity=np.zeros(40), ego_velocity=np.zeros((2, 2)))
    sonar = simulate_sonar(world, P[0], np.radians(np.arange(0.0, 360.0, 45.0)), rng=2)
    fixed = OccupancyGrid2D.load(folder / "sim_office.yaml")
    fixed.insert_sonar(P[:1], sonar.ranges[None], sonar.angles, 5.0)
    fixed.insert_sonar(P[:1], sonar.ranges[None], sonar.angles, 5.0, model=SonarModel.udacity_exercise())
    world.free_space(0.1)
    world.clearance(P[:, :2])
    for n in (10, 100_000):  # one thread and many
        world.cast(P[0, :2], np.linspace(-np.pi, np.pi, n))
    map_scans(read_carmen(_office_log(folder)).stack(), 0.1, 10.0, recorder=MappingRecorder())  # map2d --record


def local_map(folder: Path) -> None:
    """The rolling costmap: moving, scans, clouds, costs, path checks."""
    from ..io.carmen import iter_carmen
    from ..local import LocalMap, inflate
    from ..local.replay import frame_image

    replayed = LocalMap(size=(8.0, 8.0), resolution=0.1, half_life=30.0)
    for scan in iter_carmen(_office_log(folder)):
        replayed.move_to(float(scan.pose[0]), float(scan.pose[1]))
        replayed.insert_scan(scan.pose, scan.ranges, scan.angles, scan.stamp, max_range=scan.max_range)
    replayed.costmap()
    for half_life in (None, 2.0):
        local = LocalMap(size=(8.0, 8.0), resolution=0.1, half_life=half_life)
        angles = np.linspace(-np.pi, np.pi, 360, endpoint=False)
        for k, t in enumerate(np.arange(0.0, 0.5, 0.1)):
            local.move_to(0.3 * k, 0.1 * k)
            local.insert_scan((0.3 * k, 0.1 * k, 0.1), np.full(360, 2.5), angles, stamp=t, max_range=4.0)
        pts = np.random.default_rng(0).uniform(-3, 3, size=(200, 3))
        local.insert_point_cloud(pts, np.array([0.0, 0.0, 1.0]), 0.6, z_min=0.1, z_max=2.0)
        cost, _ = local.costmap()
        frame_image(cost, (10, 10), 2)
        local.cost_at(pts[:, :2])
        local.cost_at(pts[:5, :2], frame="body", robot_pose=(0.0, 0.0, 0.3))
        path = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.1], [2.0, 0.5, 0.2]])
        local.check_path(path, footprint=[[0.3, 0.2], [-0.3, 0.2], [-0.3, -0.2], [0.3, -0.2]])
        local.check_path(path, footprint=0.3, unknown_is_collision=True)
        local.time_to_clear()
        local.occupancy()
        local.insert_radar((0.0, 0.0, 0.0), np.full(8, 2.0), angles[::45], 0.9, max_range=30.0,
                           radial_velocity=np.zeros(8), ego_velocity=(1.0, 0.0))
        local.advance_time(1.0)
    lethal = np.zeros((20, 20), bool)
    lethal[10, 10] = True
    inflate(lethal, ~lethal, resolution=0.1)
    moving_objects()


def moving_objects() -> None:
    """A tracking local map on the first seconds of the simulated street (lidar and radar): tracks
    confirmed, predicted into the costmap, the path check and the frames (``occmap demo``)."""
    from ..local import LocalMap
    from ..local.replay import frame_image, tracked_objects
    from ..sim.street import Street

    street = Street.default()
    rng = np.random.default_rng(0)
    lm = LocalMap((40.0, 40.0), 0.1, tracking=True)
    for t in np.round(np.arange(0.0, 4.0, 0.1), 1):
        scan, sweep = street.lidar(t, rng=rng), street.radar(t, rng=rng)
        lm.move_to(*scan.pose[:2])
        lm.insert_scan(scan.pose, scan.ranges, scan.angles, t, max_range=30.0)
        lm.insert_radar(sweep.pose, sweep.range, sweep.azimuth, t, 60.0, sweep.radial_velocity, sweep.ego_velocity)
    cost, _ = lm.costmap(at=lm.time + 1.0)
    frame_image(cost, (5, 5), 2, tracked_objects(lm, 1.0))
    lm.check_path(np.array([[50.0, -6.8, 0.0], [52.0, -6.8, 0.0]]), footprint=0.3, stamps=[lm.time, lm.time + 1.0])


def localization(folder: Path) -> None:
    """Monte Carlo localization, tracking and global, plain and refined, in the simulated office
    (the map and the scans from its log, as ``occmap localize`` reads them)."""
    from ..grid2d import OccupancyGrid2D
    from ..io.carmen import read_carmen
    from ..localize.replay import make_localizer, replay, save_track_png, write_track_csv
    from ..mapping2d import map_scans

    log = read_carmen(_office_log(folder))
    map_scans(log.stack(), 0.1, 10.0).grid.save(folder / "localize.yaml")
    grid = OccupancyGrid2D.load(folder / "localize.yaml")
    scans = log.scans[:10]
    for plain in (False, True):
        # the default 20,000 particles of a global start score on many threads, 200 on one
        loc = make_localizer(grid, particles=200, beams=30, seed=0, plain=plain, kld=plain)
        result = replay(loc, scans, init=tuple(scans[0].pose), cov=np.diag([0.01, 0.01, 0.01]))
        replay(loc, scans, global_localization=True)
    write_track_csv(folder / "track.csv", result)
    save_track_png(folder / "track.png", loc, result)


def scan_matching(folder: Path) -> None:
    """Scan-to-map matching as ``map2d --scan-match`` runs it (odometry from the log as the prior,
    and without), a jump that sends it to its correlative search, and the relative pose error."""
    from dataclasses import replace

    from ..io.carmen import read_carmen
    from ..slam import match_scans, relative_pose_error

    scans = read_carmen(_office_log(folder)).scans
    track = match_scans(scans[:12])
    match_scans([replace(s, odom=None) for s in scans[:10] + scans[30:31]])
    relative_pose_error(track.poses, np.array([s.pose for s in scans[:12]]))


def octree(folder: Path) -> None:
    """Octree insertion (small and large scans, discretized, lazy), queries, ray casts, files."""
    from ..io.octomap import read_octree, write_bt, write_ot
    from ..io.pointclouds import read_cloud, write_pcd
    from ..octree import OcTree
    from ..sim.world3d import VELODYNE_HDL32, World3D, simulate_drive

    clouds = simulate_drive(2, VELODYNE_HDL32.with_azimuth_step(np.radians(0.32)), rng=3)  # 36,000 rays each
    tree = OcTree(0.2)
    for c in clouds:
        tree.insert_point_cloud(c.world_points(), c.origin, max_range=40.0)
    small = clouds[0].world_points()[::40]
    tree.insert_point_cloud(small, clouds[0].origin)
    tree.insert_point_cloud(small, clouds[0].origin, 10.0, discretize=True)
    tree.insert_point_clouds([small, small], [clouds[0].origin, clouds[1].origin], max_range=20.0)
    tree.insert_rays(np.repeat(clouds[0].origin[None], 3, axis=0), small[:3])
    tree.insert_ray(clouds[0].origin, small[0], lazy=True)
    tree.update_nodes(small[:10], np.arange(10) % 2 == 0, lazy=True)
    tree.update_inner_occupancy()
    tree.bbx = (np.array([-5.0, -5.0, -1.0]), np.array([5.0, 5.0, 3.0]))
    tree.insert_point_cloud(small, clouds[0].origin)
    tree.bbx = None
    tree.prune()
    tree.occupancy_at(small)
    tree.log_odds_at(small, depth=14)
    tree.coord_to_key(small)
    tree.key_to_coord(tree.coord_to_key(small), depth=15)
    tree.cast_ray(clouds[0].origin, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], max_range=30.0)
    tree.cast_ray(np.repeat(clouds[0].origin[None], 2, axis=0), [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                  ignore_unknown=True)
    tree.leaves(bbx_min=[-5, -5, -1], bbx_max=[5, 5, 3], depth=14)
    tree.occupied_centers()
    tree.num_leaves()
    tree.metric_bounds()
    write_bt(tree, folder / "t.bt")
    write_ot(tree, folder / "t.ot")
    read_octree(folder / "t.bt")
    read_octree(folder / "t.ot")
    tree.save_height_png(folder / "h.png")
    tree.save_slice_png(folder / "s.png", 1.0)
    tree.export_ply(folder / "t.ply")
    tree.expand()
    tree.to_max_likelihood()
    write_pcd(folder / "c.pcd", clouds[0].points[:100], viewpoint=clouds[0].pose)
    read = read_cloud(folder / "c.pcd")
    for discretize in (False, True):  # as map3d inserts a cloud it read
        OcTree(0.2).insert_point_cloud(read.world_points(), read.origin, 20.0, discretize)
    world = World3D.default()
    for n in (10, 100_000):  # one thread and many
        world.cast(np.zeros((n, 3)) + [5.0, 5.0, 1.8], np.repeat([[1.0, 0.2, 0.0]], n, axis=0))
    world.occupied(small)
    world.truth_voxels(0.5)


def world(folder: Path) -> None:
    """Tiled octrees: insertion (small and large scans, a region), queries, joining, a store."""
    from ..sim.world3d import VELODYNE_HDL32, simulate_drive
    from ..world.octree_tiles import TiledOcTree

    clouds = simulate_drive(2, VELODYNE_HDL32.with_azimuth_step(np.radians(0.32)), rng=3)  # 36,000 rays each
    with TiledOcTree.create(folder / "tiles", 0.2, 64, memory_limit=1) as tiled:
        for c in clouds:
            tiled.insert_point_cloud(c.world_points(), c.origin, max_range=40.0)
        small = clouds[0].world_points()[::40]
        tiled.insert_point_cloud(small, clouds[0].origin, 10.0, discretize=True)
    part = TiledOcTree(0.2, 64, region=((0, 0, -1), (3, 3, 1)))
    part.insert_point_cloud(small, clouds[0].origin)
    tiled = TiledOcTree.open(folder / "tiles")
    tiled.occupancy_at(small)
    tiled.cast_ray(clouds[0].origin, small[:50] - clouds[0].origin, max_range=30.0)
    tiled.cast_ray(clouds[0].origin, small[:50] - clouds[0].origin, ignore_unknown=True)
    tiled.leaves(bbx_min=[-5.0, -5.0, -1.0], bbx_max=[5.0, 5.0, 3.0])
    tiled.export(folder / "tiles.bt")
    tiled.export(folder / "tiles.ot", box=([-5.0, -5.0, -1.0], [5.0, 5.0, 3.0]))
    grid_tiles(folder)


def grid_tiles(folder: Path) -> None:
    """Tiled 2D grids: insertion (on one thread and on several, a region, evicting), a store, queries,
    a build from a log."""
    from ..world.grid_tiles import TiledGrid2D

    angles = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 0.5, 0.3]])
    ranges = np.full((2, 360), 8.0)
    with TiledGrid2D.create(folder / "grid_tiles", 0.05, 16, memory_limit=1 << 20) as grid:
        for _ in range(4):  # the thread choice tries both paths
            grid.insert_scans(poses, ranges, angles, max_range=10.0)
    TiledGrid2D(0.05, 16, region=((0, 0), (3, 3))).insert_scans(poses, ranges, angles, max_range=10.0)
    grid = TiledGrid2D.open(folder / "grid_tiles")
    grid.occupancy_at(poses[:, :2])
    grid.export((-2.0, -2.0, 2.0, 2.0), folder / "grid_tiles.yaml")
    from ..world.build import build_grid
    from ..sources import CarmenScans

    build_grid(folder / "grid_build", CarmenScans(_office_log(folder)), 0.05, 64)  # scan by scan, as map2d --tiles
    TiledGrid2D.open(folder / "grid_build").export(None, folder / "grid_build.yaml")


def city(folder: Path) -> None:
    """The procedural town's scans and truth: casts and point tests through its grid of solids."""
    from ..sim.city import CityDrive, CityPlan, city_laser_scan, city_scan

    drive = CityDrive(CityPlan(size=(300.0, 300.0), route_length=300.0))
    cloud = city_scan(1, drive)  # 14,400 rays: the parallel kernel
    city_laser_scan(1, drive)  # 720 rays: the serial one
    drive.city.occupied(cloud.world_points())


def bags(folder: Path) -> None:
    """A ROS 1 bag and an MCAP file of laser scans and tf, written by rosbags and streamed: the
    kernel that lists a chunk's records, and the one that gathers messages; and PointCloud2
    coordinates of both types the decoder's kernel reads, with a point to leave out."""
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin, Writer as Writer2
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    from ..sources import BagScans

    for ros1 in (True, False):
        ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.LATEST)
        if ros1:
            ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
        T = ts.types
        path = folder / ("warm.bag" if ros1 else "warm")
        writer = Writer1(path) if ros1 else Writer2(path, version=9, storage_plugin=StoragePlugin.MCAP)
        serialize = ts.serialize_ros1 if ros1 else ts.serialize_cdr
        with writer:
            tf = writer.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=ts)
            scan = writer.add_connection("/scan", "sensor_msgs/msg/LaserScan", typestore=ts)
            for k in range(30):
                header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=k + 1, nanosec=0),
                                                  frame_id="laser", **({"seq": 0} if ros1 else {}))
                vector = T["geometry_msgs/msg/Vector3"](x=0.1 * k, y=0.0, z=0.0)
                transform = T["geometry_msgs/msg/Transform"](
                    translation=vector, rotation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0))
                stamped = T["geometry_msgs/msg/TransformStamped"](
                    header=T["std_msgs/msg/Header"](stamp=header.stamp, frame_id="odom", **({"seq": 0} if ros1 else {})),
                    child_frame_id="laser", transform=transform)
                writer.write(tf, (k + 1) * 10**9, serialize(T["tf2_msgs/msg/TFMessage"](transforms=[stamped]),
                                                            "tf2_msgs/msg/TFMessage"))
                message = T["sensor_msgs/msg/LaserScan"](
                    header=header, angle_min=-1.0, angle_max=1.0, angle_increment=0.02, time_increment=0.0,
                    scan_time=0.0, range_min=0.0, range_max=10.0, ranges=np.full(101, 2.0, np.float32),
                    intensities=np.zeros(0, np.float32))
                writer.write(scan, (k + 1) * 10**9, serialize(message, "sensor_msgs/msg/LaserScan"))
        for _ in BagScans(path).stacks():
            pass
    from ..io.bags import decode_point_cloud2

    T = get_typestore(Stores.LATEST).types
    header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=1, nanosec=0), frame_id="s")
    for datatype, kind in ((7, np.float32), (8, np.float64)):
        xyz = np.array([[1.0, 2.0, 3.0], [np.nan, 0.0, 0.0]], kind)
        fields = [T["sensor_msgs/msg/PointField"](name=axis, offset=k * xyz.itemsize, datatype=datatype, count=1)
                  for k, axis in enumerate("xyz")]
        decode_point_cloud2(T["sensor_msgs/msg/PointCloud2"](
            header=header, height=1, width=2, fields=fields, is_bigendian=False, point_step=3 * xyz.itemsize,
            row_step=6 * xyz.itemsize, data=np.frombuffer(xyz.tobytes(), np.uint8), is_dense=False))


#: longest first (seconds on a fresh cache, 2 cores): 60, 30, 20, 15, 13, ...
JOBS = (geometry, octree, local_map, world, grids, localization, scan_matching, bags, city)


def _job(name: str, folder: str) -> tuple[int, float]:
    """Runs the job ``name`` in ``folder``, once with every call that has the work for several
    threads on several and once on one (whichever a command's process will choose for its load):
    the kernels it compiled and its seconds."""
    from numba.core.event import Listener, install_listener

    from .._threads import forced_path

    class Compiles(Listener):
        count = 0

        def on_start(self, event):
            self.count += 1

        def on_end(self, event):
            pass

    t0 = time.perf_counter()
    compiles = Compiles()
    with install_listener("numba:compile", compiles):
        for parallel in (True, False):
            scratch = Path(folder) / ("parallel" if parallel else "serial")
            scratch.mkdir(parents=True)
            with forced_path(parallel):
                globals()[name](scratch)
    return compiles.count, time.perf_counter() - t0


def run(args) -> int:
    """The jobs in one process per core (at most one per job), each in a scratch folder of its own.
    Compiling is one thread's work; the processes share the kernels through the disk cache, whose
    index files are written under a lock (:mod:`occmap._jit`)."""
    t0 = time.perf_counter()
    workers = min(len(os.sched_getaffinity(0)), len(JOBS))
    total = 0
    with tempfile.TemporaryDirectory(prefix="occmap-warmup-") as tmp, \
            ProcessPoolExecutor(workers, mp_context=get_context("spawn")) as pool:
        running = {pool.submit(_job, job.__name__, str(Path(tmp) / job.__name__)): job.__name__ for job in JOBS}
        for done in as_completed(running):
            count, seconds = done.result()
            total += count
            print(f"{running[done]}: {count} kernels compiled in {seconds:.1f} s", flush=True)
    print(f"warm: {total} kernels compiled in {time.perf_counter() - t0:.1f} s ({workers} processes)")
    return 0
