"""``occmap demo``: the main job on an embedded default, runnable with no data and no arguments.

1. Maps: a simulated office (noisy lidar along a path through every room) mapped at 0.05 m and
   written as ROS map_server files and a picture; with the shared data present, the Intel
   Research Lab (D. Hähnel's corrected log) too.
2. Octrees: a simulated Velodyne HDL-32E drive through a town block, written as OctoMap ``.bt``
   and drawn from above and as a slice; with the shared data, OctoMap's sample scan (scan.dat).
3. Moving objects: the simulated street (cars passing, turning and crossing, people, parked
   cars) seen by the robot's lidar and Doppler radar through a tracking local map, animated with
   the confirmed tracks and their footprints one second ahead.
4. A tour of the geometry core (printed) and of the motion models (drawn): a differential-drive
   robot and a car follow their controls exactly, and the odometry motion model spreads 400
   particles into the crescent-shaped clouds of Thrun, Burgard & Fox, *Probabilistic Robotics*,
   Fig. 5.3.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np


def add_parser(subparsers):
    p = subparsers.add_parser("demo", help="run the built-in demo (no data needed) and write its pictures")
    p.add_argument("--out", default="demo_output", help="folder for the demo's files (default: %(default)s)")
    return p


def geometry_tour() -> list[str]:
    """A few conversions and a frame-tree lookup, as lines of text."""
    from .. import geometry as g

    lines = []
    R = g.euler_zyx_to_matrix(np.radians(30.0), np.radians(20.0), np.radians(10.0))
    q = g.matrix_to_quat(R)
    yaw, pitch, roll = np.degrees(g.matrix_to_euler_zyx(R))
    lines.append(f"Euler ZYX (30°, 20°, 10°) -> quaternion (w, x, y, z) = {np.round(q, 6)}")
    lines.append(f"  back to Euler: yaw {yaw:.6f}°, pitch {pitch:.6f}°, roll {roll:.6f}°")
    w = g.log_so3(R)
    lines.append(f"  rotation vector {np.round(w, 6)}, angle {np.degrees(np.linalg.norm(w)):.6f}°")
    lock = g.euler_zyx_to_matrix(0.4, np.pi / 2, 0.1)
    y, p, r = g.matrix_to_euler_zyx(lock)
    lines.append(f"Gimbal lock (yaw 0.4, pitch 90°, roll 0.1) -> yaw {y:.6f}, pitch {p:.6f}, roll {r:.1f} (roll = 0 by convention)")
    near_pi = g.exp_so3([0.0, 0.0, np.pi - 1e-9])
    lines.append(f"Angle of a turn of π − 1e-9 rad recovered as π − {np.pi - g.matrix_to_axis_angle(near_pi)[1]:.3e}")

    tree = g.FrameTree()
    tree.set_transform("map", "odom", g.SE3.from_euler_zyx(0.1, 0.0, 0.0, [1.0, 2.0, 0.0]), static=True)
    for t, x in ((0.0, 0.0), (1.0, 0.5)):
        tree.set_transform("odom", "base_link", g.SE3.from_euler_zyx(0.2 * t, 0.0, 0.0, [x, 0.0, 0.0]), stamp=t)
    tree.set_transform("base_link", "laser", g.SE3.from_rt(np.eye(3), [0.2, 0.0, 0.3]), static=True)
    hit = tree.transform_points("map", "laser", [2.0, 0.0, 0.0], stamp=0.5)
    lines.append(f"Frame tree map->odom->base_link->laser at t=0.5 s: a laser return 2 m ahead lies at {np.round(hit, 4)} in map")
    return lines


def motion_picture(path: Path, seed: int = 7) -> dict:
    """Draw the motion-model demo to ``path``; returns a few figures for the summary."""
    from .. import geometry as g
    from ..viz import figure

    dt = 0.1
    # differential drive: straight, left arc, straight, right arc (wheel speeds in m/s)
    wheels = [(0.5, 0.5)] * 30 + [(0.3, 0.6)] * 35 + [(0.5, 0.5)] * 20 + [(0.6, 0.3)] * 35
    robot = np.zeros((len(wheels) + 1, 3))
    for k, (vl, vr) in enumerate(wheels):
        robot[k + 1] = g.diff_drive_step(robot[k], vl, vr, wheel_base=0.4, dt=dt)

    # car: the same start shifted down, steering through a lane change and a turn
    steer = np.radians([0.0] * 20 + [15.0] * 15 + [-15.0] * 15 + [0.0] * 10 + [25.0] * 30)
    car = np.zeros((len(steer) + 1, 3))
    car[0] = (0.0, -2.0, 0.0)
    for k, d in enumerate(steer):
        car[k + 1] = g.bicycle_step(car[k], 1.0, d, wheelbase=0.8, dt=dt)

    # odometry model: particles follow the robot's odometry with Probabilistic Robotics' noise
    rng = np.random.default_rng(seed)
    model = g.OdometryMotionModel(0.05, 0.02, 0.05, 0.01)
    particles = np.repeat(robot[:1], 400, axis=0)
    snapshots = []
    for k in range(1, len(robot)):
        particles = model.sample(particles, robot[k - 1], robot[k], rng)
        if k % 30 == 0 or k == len(robot) - 1:
            snapshots.append(particles.copy())

    lo = np.minimum(robot[:, :2].min(0), car[:, :2].min(0)) - 1.0
    hi = np.maximum(robot[:, :2].max(0), car[:, :2].max(0)) + 1.0
    fig = figure.figure(1000, 620)
    ax = fig.add_subplot()
    ax.grid(True, color="0.92")
    cloud = np.concatenate(snapshots)
    ax.plot(cloud[:, 0], cloud[:, 1], ",", color="#e67828", label="odometry-model particles (every 3 s)")
    for poses, colour, label in ((robot, "#1e5ac8", "differential drive"), (car, "#289628", "car (bicycle model)")):
        ax.plot(poses[:, 0], poses[:, 1], color=colour, lw=2, label=label)
        every = poses[::15]
        ax.quiver(every[:, 0], every[:, 1], np.cos(every[:, 2]), np.sin(every[:, 2]), color=colour, angles="xy",
                  scale_units="xy", scale=1 / 0.35, width=0.004)
    figure.map_axes(ax, (lo[0], hi[0], lo[1], hi[1]), "motion models, stepped every 0.1 s (arrows: heading every 1.5 s)")
    ax.legend(loc="upper left", fontsize="small", markerscale=8)
    figure.save(fig, path)
    spread = np.linalg.norm(snapshots[-1][:, :2] - robot[-1, :2], axis=1)
    return {"robot_end": robot[-1], "car_end": car[-1], "particles": len(particles), "spread_m": float(np.median(spread))}


def map_simulated_office(out: Path, seed: int = 1) -> list[str]:
    """Map the simulated office; returns lines describing the result."""
    from .._clock import WorkClock
    from ..grid2d import OccupancyGrid2D
    from ..sim import World2D, simulate_scans

    world = World2D.default()
    poses = world.default_trajectory(n=600)
    scans = simulate_scans(world, poses, n_beams=360, max_range=10.0, sigma=0.01, p_outlier=0.01, rng=seed)
    P = np.array([s.pose for s in scans])
    R = np.array([s.ranges for s in scans])
    xmin, ymin, xmax, ymax = world.bounds
    grid = OccupancyGrid2D(0.05, size=(xmax - xmin, ymax - ymin), origin=(xmin, ymin))
    clock = WorkClock()
    with clock.running():
        counts = grid.insert_scans(P, np.where(R >= 10.0, np.inf, R), scans[0].angles, max_range=10.0)
    seconds = clock.seconds
    grid.save(out / "sim_office.yaml")
    grid.save_png(out / "sim_office.png", "simulated office, mapped from its noisy scans")
    world.render_png(out / "sim_office_truth.png", poses=poses)
    return [
        f"simulated office: {counts['scans']} scans, {counts['points']:,} beams (σ 1 cm, 1 % outliers) in {seconds:.2f} s",
        f"  wrote {out / 'sim_office.yaml'} (+ .pgm), {out / 'sim_office.png'}, truth {out / 'sim_office_truth.png'}",
    ]


def map_intel(out: Path, data: Path) -> list[str]:
    """Map the Intel Research Lab corrected log from the shared data."""
    from ..io.carmen import read_carmen
    from ..mapping2d import map_scans

    log = read_carmen(data / "carmen" / "intel-corrected.log.gz")
    summary = map_scans(log.stack(), 0.05, max_range=30.0)
    summary.grid.save(out / "intel.yaml")
    summary.grid.save_png(out / "intel.png", "Intel Research Lab (corrected log)")
    return ["Intel Research Lab (corrected log, D. Hähnel):"] + ["  " + line for line in summary.lines()] + [
        f"  wrote {out / 'intel.yaml'} (+ .pgm) and {out / 'intel.png'}"
    ]


def street_tracking(out: Path, seed: int = 0) -> list[str]:
    """The simulated street (20 s, lidar and radar at 10 Hz) through a tracking local map that
    follows the robot: an animation of its costmap with the confirmed tracks, and how far the
    tracks were from the objects they follow; returns lines describing it."""
    from .._clock import WorkClock
    from ..local import LocalMap
    from ..local.replay import tracked_objects
    from ..sim.street import PARKED, Street
    from ..viz.animation import CostmapAnimation

    street = Street.default()
    lidar_rng, radar_rng = np.random.default_rng(seed), np.random.default_rng(1000 + seed)
    lm = LocalMap((40.0, 40.0), 0.1, tracking=True)
    frames = CostmapAnimation(lm.shape, lm.resolution, 2, "simulated street: costmap and tracks (lidar + radar)",
                              tracking=True)
    errors = []
    clock = WorkClock()
    stamps = np.round(np.arange(0.0, street.duration + 1e-9, 0.1), 1)
    for k, t in enumerate(stamps):
        scan, sweep = street.lidar(t, rng=lidar_rng), street.radar(t, rng=radar_rng)
        with clock.running():
            lm.move_to(*scan.pose[:2])
            lm.insert_scan(scan.pose, scan.ranges, scan.angles, t, max_range=30.0)
            lm.insert_radar(sweep.pose, sweep.range, sweep.azimuth, t, 60.0, sweep.radial_velocity,
                            sweep.ego_velocity)
        tracks, truth = lm.tracks(), street.objects(t)
        moving = truth.kind != PARKED
        for i in np.flatnonzero(tracks.confirmed):
            d = np.hypot(truth.x[moving] - tracks.x[i], truth.y[moving] - tracks.y[i])
            errors.append(d.min() if d.size else np.inf)
        if k % 2 == 0:
            robot = lm.world_to_cell(scan.pose[:2])
            frames.add(lm.costmap()[0], (int(robot[0]), int(robot[1])), tracked_objects(lm, 1.0), f"t = {t:.1f} s")
    path = frames.save(out / "street.gif", 10.0)
    errors = np.array(errors)
    near = errors[errors < 2.5]
    return [
        f"street: {len(stamps)} lidar scans and radar sweeps in {clock.seconds:.2f} s "
        f"({1e3 * clock.seconds / len(stamps):.1f} ms a cycle); {lm.stats['tracks_confirmed']} tracks confirmed of "
        f"{lm.stats['tracks_started']} started",
        f"  confirmed tracks {np.sqrt(np.mean(near ** 2)):.2f} m (RMS) from the object they follow; "
        f"{int((errors >= 2.5).sum())} track-scans on nothing moving",
        f"  animation (costmap, tracks green, their footprints 1 s ahead light green): {path}",
    ]


def map_town_3d(out: Path, n_scans: int = 30, resolution: float = 0.2) -> list[str]:
    """Drive a simulated Velodyne HDL-32E through the synthetic town block, build the octree,
    save it as OctoMap .bt and draw it from above and as a slice at 1 m."""
    from .._clock import WorkClock
    from ..io.octomap import write_bt
    from ..octree import OcTree
    from ..sim.world3d import VELODYNE_HDL32, simulate_drive

    clouds = simulate_drive(n_scans, VELODYNE_HDL32.with_azimuth_step(np.radians(0.32)), rng=3)
    tree = OcTree(resolution)
    clock = WorkClock()
    with clock.running():
        for cloud in clouds:
            tree.insert_point_cloud(cloud.world_points(), cloud.origin, max_range=40.0)
    seconds = clock.seconds
    points = sum(len(c) for c in clouds)
    write_bt(tree, out / "town.bt")
    tree.save_height_png(out / "town_height.png", title="simulated town")
    tree.save_slice_png(out / "town_slice_1m.png", 1.0, title="simulated town")
    occupied = len(tree.occupied_centers())
    return [
        f"simulated town, HDL-32E drive: {n_scans} scans, {points:,} points at {resolution:g} m in {seconds:.2f} s "
        f"({points / seconds:,.0f} points/s)",
        f"  {tree.num_nodes():,} nodes, {occupied:,} occupied leaves, {tree.memory_usage() / 2**20:.1f} MiB",
        f"  wrote {out / 'town.bt'} (opens in OctoMap's octovis), {out / 'town_height.png'}, "
        f"{out / 'town_slice_1m.png'}",
    ]


def map_scan_dat(out: Path, data: Path, resolution: float = 0.1) -> list[str]:
    """OctoMap's sample 3D scan (scan.dat) mapped and drawn."""
    from .._clock import WorkClock
    from ..io.octomap import write_bt
    from ..io.pointclouds import read_xyz
    from ..octree import OcTree

    cloud = read_xyz(data / "octomap" / "scan.dat.bz2")
    tree = OcTree(resolution)
    clock = WorkClock()
    with clock.running():
        tree.insert_point_cloud(cloud.world_points(), cloud.origin)
    seconds = clock.seconds
    write_bt(tree, out / "scan_dat.bt")
    tree.save_height_png(out / "scan_dat_height.png", title="scan.dat (OctoMap's sample scans)")
    return [
        f"OctoMap sample scan (scan.dat): {len(cloud):,} points at {resolution:g} m in {seconds:.2f} s, "
        f"{tree.num_nodes():,} nodes",
        f"  wrote {out / 'scan_dat.bt'} and {out / 'scan_dat_height.png'}",
    ]


def run(args) -> int:
    """Run the demo, writing its files under ``args.out``; prints what it did."""
    from .._data import find_shared_data

    t0 = time.perf_counter()
    out = Path(args.out)
    print("occmap demo: 2D occupancy maps")
    for line in map_simulated_office(out):
        print("  " + line)
    data = find_shared_data()
    if data is None:
        print("  (shared robot data not found: set OCCMAP_DATA to map the Intel Research Lab too)")
    else:
        for line in map_intel(out, data):
            print("  " + line)
    print("occmap demo: 3D occupancy octree")
    for line in map_town_3d(out):
        print("  " + line)
    if data is not None:
        for line in map_scan_dat(out, data):
            print("  " + line)
    print("occmap demo: moving objects")
    for line in street_tracking(out):
        print("  " + line)
    print("occmap demo: geometry core")
    for line in geometry_tour():
        print("  " + line)
    png = out / "motion.png"
    info = motion_picture(png)
    print("occmap demo: motion models")
    x, y, th = info["robot_end"]
    print(f"  differential drive ends at x={x:.3f} m, y={y:.3f} m, heading {np.degrees(th):.1f}°")
    x, y, th = info["car_end"]
    print(f"  car ends at x={x:.3f} m, y={y:.3f} m, heading {np.degrees(th):.1f}°")
    print(f"  {info['particles']} odometry-model particles, median distance from the true end pose {info['spread_m']:.2f} m")
    print(f"  picture: {png.resolve()}")
    print(f"done in {time.perf_counter() - t0:.1f} s")
    return 0
