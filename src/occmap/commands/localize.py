"""``occmap localize MAP.yaml LOG -o track.csv``: replay a CARMEN log's raw odometry and scans, or
a bag's LaserScan topic with its odometry frame's poses, through Monte Carlo localization in a
map_server map (:mod:`occmap.localize.replay`)."""

from __future__ import annotations

from . import _options, _sources
from ._outputs import check_outputs


def add_parser(subparsers):
    p = subparsers.add_parser(
        "localize", help="localize a laser log's scans in a map (Monte Carlo localization, as ROS AMCL)",
        description="Replay a CARMEN log's raw odometry and scans through a particle filter in a map_server map, "
                    "write the estimated track as CSV and optionally draw it over the map beside the odometry.")
    p.add_argument("map", metavar="MAP.yaml", help="map_server YAML (with its image beside it)")
    p.add_argument("log", metavar="LOG", help="CARMEN log (plain, .gz or .bz2) with odometry in its scan lines, or a "
                   "ROS bag with sensor_msgs/LaserScan whose poses in --fixed-frame (odom) serve as odometry")
    start = p.add_mutually_exclusive_group()
    start.add_argument("--init", type=_options.pose2d, metavar="X,Y,THETA",
                       help="initial pose of the laser in the map (metres, radians); tracking from there")
    start.add_argument("--global", dest="global_localization", action="store_true",
                       help="global localization: start from particles over all free space (the default "
                            "when --init is not given)")
    p.add_argument("-o", "--output", required=True, help="CSV track to write")
    p.add_argument("--png", help="also draw the track over the map")
    p.add_argument("--particles", type=_options.count, default=2000, help="particles (default: %(default)s)")
    p.add_argument("--beams", type=_options.count, default=60, help="beams per update (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default: %(default)s)")
    p.add_argument("--plain", action="store_true", help="plain AMCL: no roughening, no scan-match refinement")
    p.add_argument("--reference", metavar="LOG",
                   help="a corrected log of the same run: report the error against its poses")
    p.add_argument("--record", metavar="RUN.npz",
                   help="also record the run step by step (estimate, particles, reference, map) to scrub through "
                        "with occmap view RUN.npz")
    p.add_argument("--record-particles", type=_options.count, default=None, metavar="N",
                   help="particles recorded a step at most (default 200: an even subsample of the cloud)")
    p.add_argument("--every", type=_options.count, default=1, help="use every N-th scan (default: %(default)s)")
    _sources.add_bag_options(p, "sensor_msgs/LaserScan", "odom", poses=False)
    return p


def run(args) -> int:
    import math
    import sys
    import time
    from pathlib import Path

    import numpy as np

    from ..errors import InvalidArgumentError
    from ..grid2d import OccupancyGrid2D
    from ..sources import CarmenScans
    from ..io.carmen import laser_offset, read_carmen
    from ..localize.recording import MAX_PARTICLES, LocalizationRecording
    from ..localize.replay import make_localizer, pair_scans, replay, save_track_png, track_errors, write_track_csv

    check_outputs({"-o": args.output, "--png": args.png, "--record": args.record},
                  {"MAP.yaml": args.map, "LOG": args.log, "--reference": args.reference})
    t0 = time.perf_counter()
    grid = OccupancyGrid2D.load(args.map)
    source = _sources.laser_source(args, args.log, every=args.every)
    scans = list(source)
    _sources.report("localize", source, max_range_option=False)
    if not scans:
        raise InvalidArgumentError(f"{args.log}: no laser scans found")
    print(f"read {len(scans):,} scans from {args.log} and a {grid.shape[1]} × {grid.shape[0]} map in "
          f"{time.perf_counter() - t0:.2f} s")
    glob = args.init is None
    # a CARMEN log's odometry is the robot's, its scan poses and --init the laser's (replay converts)
    offset = laser_offset(source.stats.params, path=args.log) if isinstance(source, CarmenScans) else (0.0, 0.0, 0.0)
    loc = make_localizer(grid, particles=args.particles, beams=args.beams, seed=args.seed, plain=args.plain,
                         sensor_offset=offset)
    result = replay(loc, scans, init=args.init, cov=np.diag([0.1 ** 2, 0.1 ** 2, math.radians(5) ** 2]),
                    global_localization=glob, progress=sys.stderr.isatty(),
                    keep_particles=(args.record_particles or MAX_PARTICLES) if args.record else 0)
    write_track_csv(args.output, result)
    ms = 1000.0 * result.seconds[result.updated]
    print(f"{len(result):,} scans, {int(result.updated.sum()):,} filter updates "
          f"({np.median(ms) if ms.size else 0:.2f} ms median), {loc.stats.resamples:,} resamplings, "
          f"{loc.stats.injected:,} particles injected")
    for w in sorted(set(result.warnings))[:5]:
        print(f"warning: {w}")
    reference = None
    if args.reference:
        ref = read_carmen(args.reference)
        pairs = pair_scans(scans, ref.scans)
        ok = pairs >= 0
        reference = np.full((len(scans), 3), np.nan)
        reference[pairs[ok]] = np.array([s.pose for s in ref.scans])[ok]
        # a global localization's guesses before it converged are not its track: reported apart
        ok &= result.converged[np.maximum(pairs, 0)]
        before = int((pairs >= 0).sum() - ok.sum())
        pe, he = track_errors(result.poses[pairs[ok]], np.array([s.pose for s in ref.scans])[ok])
        if pe.size:
            print(f"against {int(ok.sum()):,} reference poses{' after it converged' if glob else ''}: position error "
                  f"mean {pe.mean():.3f} m, max {pe.max():.3f} m; heading error mean {math.degrees(he.mean()):.2f}°, "
                  f"max {math.degrees(he.max()):.2f}°")
        if before:
            print(f"{before:,} reference poses fall before the global localization converged")
    print(f"wrote {args.output}")
    if args.record:
        rec = LocalizationRecording.of_replay(result, grid, reference)
        print(f"wrote {rec.save(args.record)} ({len(rec):,} steps, up to {rec.particles.shape[1]} particles each)")
    if args.png:
        title = f"{Path(args.log).name} localized in {Path(args.map).name}"
        print(f"wrote {save_track_png(args.png, loc, result, title=title)}")
    print(f"total {time.perf_counter() - t0:.2f} s")
    return 0
