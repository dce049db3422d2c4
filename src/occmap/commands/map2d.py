"""``occmap map2d LOG -o MAP.yaml``: a 2D occupancy grid from a CARMEN laser log or the
LaserScan topic of a ROS bag (placed by tf, odometry or a pose file), written as a ROS map_server
pair (the ``.pgm`` beside the YAML) and optionally a picture."""

from __future__ import annotations

import sys
import time
from pathlib import Path

from . import _notes, _options, _scan_match, _sources, _tiles
from ._outputs import check_outputs, check_suffix


def add_parser(subparsers):
    p = subparsers.add_parser("map2d", help="build a 2D occupancy grid from a CARMEN laser log (plain, .gz or .bz2) "
                              "or a ROS bag's LaserScan topic")
    p.add_argument("log", help="CARMEN log with FLASER / RLASER / ROBOTLASER1 lines, or a ROS bag (.bag, ROS 2 "
                   "folder, .db3, .mcap) with sensor_msgs/LaserScan")
    p.add_argument("-o", "--output",
                   help="map_server YAML to write (.yaml or .yml; the .pgm goes beside it); with --tiles, the whole "
                   "store's known cells")
    p.add_argument("--resolution", type=_options.positive, default=0.05,
                   help="cell size in metres (default: %(default)s)")
    p.add_argument("--png", help="also write a probability picture")
    p.add_argument("--max-range", type=_options.positive, help="the laser's maximum range in metres: readings at or beyond it are no "
                   "return, and beams clear space up to it (default: the log's own, else 81)")
    p.add_argument("--max-extent", type=_options.positive, default=10_000.0,
                   help="largest side of the map in metres; a pose or beam that would grow it further stops the "
                   "command, naming the scan (default: %(default)s)")
    p.add_argument("--every", type=_options.count, default=1, help="use every N-th scan (default: %(default)s)")
    p.add_argument("--lenient", action="store_true", help="skip and count malformed lines instead of stopping")
    p.add_argument("--prob-hit", type=_options.probability, default=0.7,
                   help="P(occupied) for a beam's end cell (default: %(default)s, OctoMap's)")
    p.add_argument("--prob-miss", type=_options.probability, default=0.4,
                   help="P(occupied) for cells a beam passes (default: %(default)s, OctoMap's; 0.45 keeps walls "
                   "that many grazing beams cross more continuous)")
    p.add_argument("--record", metavar="RUN.npz",
                   help="also record the run scan by scan (poses, the map growing) to scrub through with "
                        "occmap view RUN.npz")
    p.add_argument("--record-every", type=_options.count, default=None, metavar="K",
                   help="scans between two recorded states of the map (default 10)")
    _scan_match.add_option(p)
    _tiles.add_tile_options(p, 256, "cells")
    _sources.add_bag_options(p, "sensor_msgs/LaserScan", "odom")
    return p


def _run_tiled(args, model) -> int:
    from ..errors import InvalidArgumentError
    from ..world.build import build_grid
    from ..world.grid_tiles import TiledGrid2D
    from ..sources import CarmenScans

    if args.png is not None:
        raise InvalidArgumentError("with --tiles, --png is not made (export a box, then draw it)")
    source = CarmenScans(args.log, lenient=args.lenient, every=args.every, max_range=args.max_range)
    if not len(source):
        raise InvalidArgumentError(f"{args.log}: no laser scans found")
    _notes.carmen_assumptions("map2d", source.stats)
    summary = build_grid(args.tiles, source, args.resolution, args.tile_size, model=model,
                         **_tiles.build_options(args))
    s = summary.stats
    print(f"{s['scans']:,} scans, beams {s['points']:,}, dropped readings {s['dropped']:,}, no-return readings "
          f"{s['beyond_max_range']:,} into {args.tiles}: {summary.line()}")
    if args.output is not None:
        image = TiledGrid2D.open(args.tiles).export(None, args.output)
        print(f"wrote {args.output} and {image}")
    return 0


def run(args) -> int:
    from ..errors import InvalidArgumentError
    from ..grid2d import LidarModel
    from ..io.bags import is_bag
    from ..io.carmen import read_carmen
    from ..mapping2d import map_scans
    from ..scan import stack_scans

    _tiles.check_tile_options(args)
    if args.tiles is None and args.output is None:
        raise InvalidArgumentError("give -o MAP.yaml or --tiles DIR")
    if args.tiles is not None and args.record is not None:
        raise InvalidArgumentError("--record keeps the map in memory as it grows: leave out --tiles")
    if args.record_every is not None and args.record is None:
        raise InvalidArgumentError("--record-every sets how --record records: give --record RUN.npz")
    image = None
    if args.output is not None:
        check_suffix("-o", args.output, (".yaml", ".yml"))
        image = Path(args.output).with_suffix(".pgm")
    check_outputs({"-o": args.output, "the map's image": image, "--png": args.png, "--record": args.record},
                  {"LOG": args.log})
    model = LidarModel(args.prob_hit, args.prob_miss)  # checks the pair before the log is read
    if is_bag(args.log):
        return _run_bag(args, model)
    _sources.refuse_bag_options(args, "a CARMEN log (it carries its poses)")
    if args.tiles is not None:
        if args.scan_match:
            raise InvalidArgumentError("--scan-match builds one map in memory: leave out --tiles")
        return _run_tiled(args, model)

    t0 = time.perf_counter()
    log = read_carmen(args.log, lenient=args.lenient, every=args.every, max_range=args.max_range)
    print(f"read {len(log):,} scans from {args.log} in {time.perf_counter() - t0:.2f} s"
          + (f" ({log.skipped_malformed:,} malformed lines skipped)" if log.skipped_malformed else ""))
    if not len(log):
        raise InvalidArgumentError(f"{args.log}: no laser scans found")
    _notes.carmen_assumptions("map2d", log.stats)
    stack = stack_scans(_scan_match.scan_matched(log.scans)) if args.scan_match else log.stack()
    recorder = _recorder(args)
    summary = map_scans(stack, args.resolution, args.max_range, progress=sys.stderr.isatty(), model=model,
                        max_extent=args.max_extent, recorder=recorder)
    return _write(args, summary, t0, recorder)


def _run_bag(args, model) -> int:
    from .._progress import Progress
    from ..errors import InvalidArgumentError
    from ..mapping2d import map_scan_stream
    from ..sources import BagScans

    if args.tiles is not None:
        raise InvalidArgumentError("--tiles reads files scan by scan; a bag is mapped in one process (drop --tiles)")
    if args.lenient:
        raise InvalidArgumentError("--lenient skips malformed CARMEN lines; a bag has none")
    t0 = time.perf_counter()
    recorder = _recorder(args)
    source = BagScans(args.log, every=args.every, max_range=args.max_range, unposed=args.scan_match,
                      **_sources.bag_options(args))
    if args.scan_match:
        # poses from tf, odometry or a pose file, where the bag has them, are the matcher's prior
        scans = [_scan_match.with_prior(source, s) for s in source]
        summary = map_scan_stream(_scan_match.scan_matched(scans), args.resolution, args.max_range, model=model,
                                  max_extent=args.max_extent, progress=Progress(len(scans), "scans"),
                                  recorder=recorder)
    else:
        summary = map_scan_stream(source, args.resolution, args.max_range, model=model, max_extent=args.max_extent,
                                  progress=Progress(len(source), "messages"), recorder=recorder)
    _sources.report("map2d", source)
    if not summary.scans:
        raise InvalidArgumentError(f"{args.log}: none of the {len(source):,} scans on {source.topic} could be placed "
                                   "in the map (see the notes above)")
    _sources.print_use(source, summary.scans, "scans")
    return _write(args, summary, t0, recorder)


def _recorder(args):
    from ..mapping2d_recording import EVERY, MappingRecorder

    return MappingRecorder(args.record_every or EVERY) if args.record is not None else None


def _write(args, summary, t0: float, recorder) -> int:
    image = summary.grid.save(args.output)
    for line in summary.lines():
        print(line)
    print(f"wrote {args.output} and {image}")
    if recorder is not None:
        rec = recorder.finish(summary.grid)
        path = rec.save(args.record)
        print(f"wrote {path} ({len(rec):,} scans, {len(rec.delta_steps):,} map states every {recorder.every} scans, "
              f"{len(rec.delta_cells):,} cell changes; {Path(path).stat().st_size / 1e6:.1f} MB)")
    if args.png:
        print(f"wrote {summary.grid.save_png(args.png, f'occupancy grid of {Path(args.log).name}')}")
    print(f"total {time.perf_counter() - t0:.2f} s")
    return 0
