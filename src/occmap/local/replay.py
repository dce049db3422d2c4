"""``occmap local LOG -o local.gif``: replay a CARMEN log through a :class:`LocalMap` and write an
animation of the costmap following the robot.

Each scan moves the window to the laser's position, integrates the scan at its logger stamp and,
every ``--frame-every`` scans, adds a frame: the costmap drawn with its Nav2 values (white free,
yellow → red graded, purple inscribed, black lethal, grey unknown), north up, the robot as a blue
dot. Frames are palette images (the cost is the colour index, no quantisation), so a few hundred
frames write in seconds.
"""

from __future__ import annotations

import io
import math
import time

import numpy as np

__all__ = ["add_parser", "run_cli", "cost_palette", "frame_image"]

_ROBOT = 130  # palette index of the robot marker (graded costs use indices 1 … 126)


def add_parser(subparsers):
    """Add the ``local`` command to an ``argparse`` subparsers object; returns its parser."""
    p = subparsers.add_parser("local", help="replay a CARMEN log through the rolling local costmap and write a GIF")
    p.add_argument("log", help="CARMEN log with FLASER / RLASER / ROBOTLASER1 lines (plain, .gz or .bz2)")
    p.add_argument("-o", "--output", required=True, help="animated GIF to write")
    p.add_argument("--size", type=float, default=20.0, help="window side in metres (default: %(default)s)")
    p.add_argument("--resolution", type=float, default=0.1, help="cell size in metres (default: %(default)s)")
    p.add_argument("--half-life", type=float, default=30.0,
                   help="seconds for unobserved evidence to halve; 0 never forgets (default: %(default)s)")
    p.add_argument("--max-range", type=float, help="readings at or beyond this many metres clear only (default: the log's)")
    p.add_argument("--every", type=int, default=1, help="use every N-th scan (default: %(default)s)")
    p.add_argument("--frame-every", type=int, default=2, help="one frame per N used scans (default: %(default)s)")
    p.add_argument("--max-frames", type=int, default=300, help="stop after this many frames (default: %(default)s)")
    p.add_argument("--scale", type=int, default=2, help="pixels per cell (default: %(default)s)")
    p.add_argument("--fps", type=float, default=10.0, help="frames per second of the animation (default: %(default)s)")
    return p


def cost_palette() -> list[int]:
    """768 palette entries: index 0 free (white), 1–126 graded costs (yellow → red), 130 the
    robot (blue), 253 inscribed (purple), 254 lethal (black), 255 unknown (grey)."""
    pal = np.zeros((256, 3), dtype=np.uint8)
    pal[:] = (255, 0, 255)
    pal[0] = (255, 255, 255)
    t = np.linspace(0.0, 1.0, 126)
    pal[1:127, 0] = 255
    pal[1:127, 1] = np.rint(230 * (1 - t)).astype(np.uint8)
    pal[1:127, 2] = np.rint(120 * (1 - t)).astype(np.uint8)
    pal[_ROBOT] = (30, 90, 255)
    pal[253] = (120, 40, 140)
    pal[254] = (0, 0, 0)
    pal[255] = (200, 200, 205)
    return pal.reshape(-1).tolist()


def frame_image(cost: np.ndarray, robot_cell=None, scale: int = 1):
    """A palette ``PIL.Image`` of a costmap (row 0 at the bottom, as the map's y grows up)."""
    from PIL import Image

    idx = cost.copy()
    graded = (cost >= 1) & (cost <= 252)
    idx[graded] = 1 + (cost[graded].astype(np.int32) - 1) // 2
    if robot_cell is not None:
        r, c = robot_cell
        idx[max(r - 1, 0):r + 2, max(c - 1, 0):c + 2] = _ROBOT
    img = Image.fromarray(np.ascontiguousarray(idx[::-1]), mode="P")
    img.putpalette(cost_palette())
    if scale > 1:
        img = img.resize((img.width * scale, img.height * scale), Image.NEAREST)
    return img


def run_cli(args) -> int:
    """Run ``occmap local`` with parsed ``args`` (see :func:`add_parser`); returns the exit code."""
    from .._files import write_atomic
    from ..errors import InvalidArgumentError
    from ..io.carmen import CarmenStats, iter_carmen
    from .local_map import LocalMap

    for name in ("size", "resolution"):
        v = getattr(args, name)
        if not (math.isfinite(v) and v > 0):
            raise InvalidArgumentError(f"--{name} must be a positive number, got {v}")
    if not (math.isfinite(args.half_life) and args.half_life >= 0):
        raise InvalidArgumentError(f"--half-life must be ≥ 0 seconds, got {args.half_life}")
    for name in ("every", "frame_every", "max_frames", "scale"):
        if getattr(args, name) < 1:
            raise InvalidArgumentError(f"--{name.replace('_', '-')} must be at least 1, got {getattr(args, name)}")
    lm = LocalMap((args.size, args.size), args.resolution, half_life=args.half_life or None)
    stats = CarmenStats()
    frames = []
    used = 0
    clamped = 0
    t_map = 0.0
    t0 = time.perf_counter()
    last = None
    for scan in iter_carmen(args.log, every=args.every, max_range=args.max_range, stats=stats):
        stamp = float(scan.stamp)
        if last is not None and stamp < last:
            clamped += 1  # logs with wrapped or shuffled stamps: hold the clock
            stamp = last
        last = stamp
        x, y = float(scan.pose[0]), float(scan.pose[1])
        if not (math.isfinite(x) and math.isfinite(y)):
            lm.stats["dropped_poses"] += 1
            continue
        t1 = time.perf_counter()
        lm.move_to(x, y)
        lm.integrate_scan(scan.pose, scan.ranges, scan.angles, stamp, max_range=scan.max_range)
        if used % args.frame_every == 0:
            cost, _ = lm.costmap()
            t_map += time.perf_counter() - t1
            robot = lm.world_to_cell(np.array([x, y]))
            frames.append(frame_image(cost, (int(robot[0]), int(robot[1])), args.scale))
        else:
            t_map += time.perf_counter() - t1
        used += 1
        if len(frames) >= args.max_frames:
            break
    if not frames:
        raise InvalidArgumentError(f"{args.log}: no laser scans to replay")
    buf = io.BytesIO()
    frames[0].save(buf, format="GIF", save_all=True, append_images=frames[1:], loop=0,
                   duration=max(20, int(round(1000.0 / args.fps))), optimize=False)
    path = write_atomic(args.output, buf.getvalue())
    H, W = lm.shape
    print(f"{used} scans through a {W}×{H} local map at {args.resolution:g} m "
          f"(half-life {args.half_life:g} s): {1e3 * t_map / max(used, 1):.2f} ms per scan for move + integrate "
          f"(+ costmap on frames); {len(frames)} frames → {path} in {time.perf_counter() - t0:.1f} s")
    if lm.stats["dropped_points"] or lm.stats["dropped_poses"] or clamped:
        print(f"dropped: {lm.stats['dropped_points']} readings (NaN, ≤ 0), {lm.stats['dropped_poses']} poses; "
              f"{clamped} stamps going backwards held at the previous one")
    return 0
