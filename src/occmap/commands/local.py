"""``occmap local LOG -o local.gif``: replay a CARMEN log or a bag's LaserScan topic (placed by
tf, odometry or a pose file) through a :class:`~occmap.LocalMap` and write an animation of the
costmap following the robot.

Each scan moves the window to the laser's position and integrates the scan at its logger stamp;
every ``--frame-every`` scans a frame is drawn (:func:`occmap.local.replay.frame_image`). Frames
(and recorded costmaps) stay in memory until the end: ``--max-frames`` is lowered, with a note,
to what a third of the memory available at the start holds (the GIF's writer needs as much again).
"""

from __future__ import annotations

import os

from . import _options, _scan_match, _sources
from ._outputs import check_outputs


def add_parser(subparsers):
    p = subparsers.add_parser("local", help="replay a CARMEN log or a ROS bag through the rolling local costmap and "
                              "write a GIF")
    p.add_argument("log", help="CARMEN log with FLASER / RLASER / ROBOTLASER1 lines (plain, .gz or .bz2), or a ROS "
                   "bag with sensor_msgs/LaserScan")
    p.add_argument("-o", "--output", required=True, help="animated GIF to write")
    p.add_argument("--size", type=_options.positive, default=20.0, help="window side in metres (default: %(default)s)")
    p.add_argument("--resolution", type=_options.positive, default=0.1,
                   help="cell size in metres (default: %(default)s)")
    p.add_argument("--half-life", type=_options.non_negative, default=30.0,
                   help="seconds for unobserved evidence to halve; 0 never forgets (default: %(default)s)")
    p.add_argument("--max-range", type=_options.positive,
                   help="readings at or beyond this many metres clear only (default: the log's)")
    p.add_argument("--every", type=_options.count, default=1, help="use every N-th scan (default: %(default)s)")
    p.add_argument("--frame-every", type=_options.count, default=2,
                   help="one frame per N used scans (default: %(default)s)")
    p.add_argument("--max-frames", type=_options.count, default=300,
                   help="stop after this many frames (default: %(default)s)")
    p.add_argument("--scale", type=_options.count, default=2, help="pixels per cell (default: %(default)s)")
    p.add_argument("--title", help="the animation's title (default: \"local costmap: \" and the log's name)")
    p.add_argument("--fps", type=_options.positive, default=10.0,
                   help="frames per second of the animation (default: %(default)s)")
    p.add_argument("--tracking", action="store_true",
                   help="track moving objects: they stay out of the static layer, and the frames show the confirmed "
                   "tracks and where they will be in one second")
    p.add_argument("--register", action="store_true",
                   help="insert each scan where it fits the map, not at the log's pose (LocalMap(register=True), "
                   "for poses that drift: raw odometry); the frames are then in the map's frame")
    p.add_argument("--record", metavar="RUN.npz",
                   help="also record each frame's costmap, pose and tracks to scrub through with occmap view RUN.npz")
    _scan_match.add_option(p)
    _sources.add_bag_options(p, "sensor_msgs/LaserScan", "odom")
    return p


def run(args) -> int:
    import math
    import time
    from pathlib import Path

    import numpy as np

    from .._clock import WorkClock
    from ..errors import InvalidArgumentError
    from ..local import LocalMap
    from ..local.recording import LocalMapRecorder
    from ..local.replay import tracked_objects
    from ..viz.animation import CostmapAnimation

    check_outputs({"-o": args.output, "--record": args.record}, {"LOG": args.log})
    source = _sources.laser_source(args, args.log, every=args.every)
    matcher = None
    if args.scan_match:  # poses matched scan by scan, as a robot would
        from dataclasses import replace

        from ..slam import ScanMatcher
        from ..slam.scan_matching import describe

        matcher = ScanMatcher()
    lm = LocalMap((args.size, args.size), args.resolution, half_life=args.half_life or None, tracking=args.tracking,
                  register=args.register)
    title = args.title if args.title is not None else f"local costmap: {Path(args.log).name}"
    frames = CostmapAnimation(lm.shape, args.resolution, args.scale, title, args.tracking)
    recorder = LocalMapRecorder() if args.record is not None else None
    max_frames = _frames_that_fit(args.max_frames, frames.frame_bytes + (2 * lm.shape[0] * lm.shape[1] if recorder else 0))
    used = 0
    clamped = 0
    clock = WorkClock()
    t0 = time.perf_counter()
    last = first = None
    for scan in source:
        if matcher is not None:
            scan = replace(scan, pose=matcher.add(_scan_match.with_prior(source, scan)))
        stamp = float(scan.stamp)
        if last is not None and stamp < last:
            clamped += 1  # logs with wrapped or shuffled stamps: hold the clock
            stamp = last
        last = stamp
        first = stamp if first is None else first
        x, y = float(scan.pose[0]), float(scan.pose[1])
        if not (math.isfinite(x) and math.isfinite(y)):
            lm.stats["dropped_poses"] += 1
            continue
        with clock.running():
            lm.move_to(x, y)
            lm.insert_scan(scan.pose, scan.ranges, scan.angles, stamp, max_range=scan.max_range)
            cost = lm.costmap()[0] if used % args.frame_every == 0 else None
        if cost is not None:
            # where the scan went in, in the map's frame (with --register registered, not the log's pose)
            pose = np.asarray(scan.pose, np.float64) if lm.pose is None else lm.pose
            robot = lm.world_to_cell(pose[:2])
            frames.add(cost, (int(robot[0]), int(robot[1])), tracked_objects(lm, 1.0) if args.tracking else None,
                       f"t = {stamp - first:.1f} s")
            if recorder is not None:
                recorder.add(lm, stamp, pose, cost)
        used += 1
        if len(frames) >= max_frames:
            break
    _sources.report("local", source)
    if matcher is not None:
        print(describe(matcher.stats))
    if not frames:
        raise InvalidArgumentError(f"{args.log}: no laser scans to replay")
    path = frames.save(args.output, args.fps)
    H, W = lm.shape
    print(f"{used} scans through a {W}×{H} local map at {args.resolution:g} m "
          f"(half-life {args.half_life:g} s): {1e3 * clock.seconds / max(used, 1):.2f} ms per scan for move + "
          f"integrate (+ costmap on frames); {len(frames)} frames → {path} in {time.perf_counter() - t0:.1f} s")
    if recorder is not None:
        rec = recorder.finish()
        saved = rec.save(args.record)
        print(f"wrote {saved} ({len(rec):,} steps, {rec.costs[0].nbytes:,} bytes of costmap a step in memory, "
              f"{Path(saved).stat().st_size / 1e6:.2f} MB on disk)")
    if args.tracking:
        print(f"tracking: {lm.stats['tracks_confirmed']} tracks confirmed of {lm.stats['tracks_started']} started, "
              f"{lm.stats['moving_returns']:,} returns taken as moving")
    if lm.stats["dropped"] or lm.stats["dropped_poses"] or clamped:
        print(f"dropped: {lm.stats['dropped']} readings (NaN, ≤ 0), {lm.stats['dropped_poses']} poses; "
              f"{clamped} stamps going backwards held at the previous one")
    return 0


def _frames_that_fit(requested: int, frame_bytes: int) -> int:
    """``requested`` frames, or fewer (with a note) when they would take more than a third of the
    memory available now."""
    available = _available_memory()
    if available is None or requested * frame_bytes <= available // 3:
        return requested
    fit = max(1, available // 3 // frame_bytes)
    print(f"--max-frames {requested:,} lowered to {fit:,}: each frame holds {frame_bytes / 1e6:.1f} MB in memory until "
          f"the GIF is written, and {available / 1e9:.1f} GB are available (--frame-every thins the frames)")
    return fit


def _available_memory() -> int | None:
    """Bytes of memory available to a new allocation without swapping (Linux ``MemAvailable``;
    free pages elsewhere); None where the system does not say."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        return None
