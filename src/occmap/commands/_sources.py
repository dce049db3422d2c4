"""The options that say where a command's scans come from and where they were taken — a bag's
topic, its fixed frame, odometry, a pose file — and the scan source they open
(:mod:`occmap.sources`), with the summary of what it dropped."""

from __future__ import annotations

from . import _options

POSE_FORMATS = ("kitti", "tum", "matrix")


def add_bag_options(p, kind: str, fixed_frame: str, poses: bool = True) -> None:
    """``--topic``, ``--fixed-frame``, ``--odom-topic`` for bag inputs, and with ``poses``
    ``--poses`` / ``--pose-format`` / ``--calib`` / ``--pose-tolerance``."""
    g = p.add_argument_group("bags (ROS 1 .bag, ROS 2 folder, .db3, .mcap)")
    g.add_argument("--topic", help=f"the {kind} topic (default: the bag's only one)")
    g.add_argument("--fixed-frame", help="the frame to map in, where tf places each message's sensor frame at its "
                   f"stamp (default: the root of the sensor frame's tf tree, else {fixed_frame})")
    g.add_argument("--odom-topic", help="nav_msgs/Odometry topic whose poses join tf (for bags without tf, or "
                   "with only a static sensor mount)")
    if poses:
        g = p.add_argument_group("pose files")
        g.add_argument("--poses", metavar="FILE", help="sensor poses, one per scan: KITTI poses.txt (12 numbers a "
                       "line), TUM 'timestamp tx ty tz qx qy qz qw' (8; matched by stamp), or a 4×4 matrix "
                       "row-major (16); told apart by the count, else --pose-format")
        g.add_argument("--pose-format", choices=POSE_FORMATS, help="the --poses format, when the count does not tell")
        g.add_argument("--calib", metavar="FILE", help="KITTI calib.txt: its Tr (velodyne → camera) turns "
                       "KITTI camera poses into the velodyne's (Tr⁻¹·P·Tr)")
        g.add_argument("--pose-tolerance", type=_options.positive, default=0.05,
                       help="seconds a stamp may lie beyond a TUM track's ends and still take its end pose "
                       "(default: %(default)s)")


def pose_track(args):
    """The :class:`~occmap.io.poses.PoseTrack` of ``--poses``, or None."""
    from ..errors import InvalidArgumentError
    from ..io.poses import read_kitti_calibration, read_poses

    if getattr(args, "poses", None) is None:
        if getattr(args, "calib", None) is not None or getattr(args, "pose_format", None) is not None:
            raise InvalidArgumentError("--calib and --pose-format go with --poses FILE")
        return None
    calibration = None if args.calib is None else read_kitti_calibration(args.calib)
    return read_poses(args.poses, args.pose_format, calibration)


def bag_options(args) -> dict:
    """The keyword arguments of :class:`~occmap.sources.BagScans` / ``BagClouds`` from the options."""
    return dict(topic=args.topic, fixed_frame=args.fixed_frame, odom_topic=args.odom_topic,
                poses=pose_track(args), tolerance=getattr(args, "pose_tolerance", 0.05))


def refuse_bag_options(args, input_kind: str, takes_poses: bool = False) -> None:
    """Bag options (and, unless the input ``takes_poses``, pose-file options) given for an input
    that is not a bag: say so rather than ignore them."""
    from ..errors import InvalidArgumentError

    names = ("topic", "fixed_frame", "odom_topic") + (() if takes_poses else ("poses", "pose_format", "calib"))
    given = [f"--{name.replace('_', '-')}" for name in names if getattr(args, name, None) is not None]
    if given:
        raise InvalidArgumentError(f"{', '.join(given)}: not for {input_kind}")


def laser_source(args, path, every: int = 1):
    """A scan source of laser scans: a bag's (:class:`~occmap.sources.BagScans`) or a CARMEN
    log's (:class:`~occmap.sources.CarmenScans`)."""
    from ..io.bags import is_bag
    from ..sources import BagScans, CarmenScans

    if is_bag(path):
        return BagScans(path, every=every, max_range=getattr(args, "max_range", None),
                        unposed=getattr(args, "scan_match", False), **bag_options(args))
    refuse_bag_options(args, "a CARMEN log (it carries its poses)")
    return CarmenScans(path, every=every, max_range=getattr(args, "max_range", None))


def report(command: str, source, max_range_option: bool = True) -> None:
    """Notes on what the source assumed (a CARMEN log's defaults), tilted, or could not use, by
    reason (nothing when it used everything as it came)."""
    from ..sources import CarmenScans
    from ._notes import carmen_assumptions, note

    if isinstance(source, CarmenScans):
        carmen_assumptions(command, source.stats, max_range_option)
    if source.dropped:
        reasons = "; ".join(f"{n:,} {why}" for why, n in source.dropped.most_common())
        note(command, f"messages dropped: {reasons}")
    if getattr(source, "tilted", 0):
        note(command, f"{source.tilted:,} scans lean more than 5° from the {source.fixed_frame} frame's plane: "
                      "mapped as if level")


def print_use(source, used: int, unit: str) -> None:
    """For a bag: the topic, the frame, and the messages looked at, used and dropped (stdout)."""
    from ..sources import BagClouds, BagScans

    if isinstance(source, (BagScans, BagClouds)):
        frame = source.fixed_frame or (f"the frame of {source.pose_track.path}" if source.pose_track is not None
                                       else "the frame of its first scan (scan-matched)")
        print(f"{source.topic} in {frame}: {len(source):,} messages, {used:,} {unit} used, "
              f"{sum(source.dropped.values()):,} dropped")
