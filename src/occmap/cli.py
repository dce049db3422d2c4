"""The ``occmap`` command."""

from __future__ import annotations

import argparse
import sys
import time

from . import __version__
from .errors import InvalidArgumentError, OccmapError


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="occmap",
        description="Probabilistic occupancy maps from range sensors and robot poses.",
    )
    p.add_argument("--version", action="version", version=f"occmap {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    demo = sub.add_parser("demo", help="run the built-in demo (no data needed) and write its pictures")
    demo.add_argument("--out", default="demo_output", help="folder for the demo's files (default: %(default)s)")

    m2 = sub.add_parser("map2d", help="build a 2D occupancy grid from a CARMEN laser log (plain, .gz or .bz2)")
    m2.add_argument("log", help="CARMEN log with FLASER / RLASER / ROBOTLASER1 lines")
    m2.add_argument("-o", "--output", required=True, help="map_server YAML to write (the .pgm goes beside it)")
    m2.add_argument("--resolution", type=float, default=0.05, help="cell size in metres (default: %(default)s)")
    m2.add_argument("--png", help="also write a probability picture")
    m2.add_argument("--max-range", type=float, help="ignore the parts of beams beyond this many metres")
    m2.add_argument("--every", type=int, default=1, help="use every N-th scan (default: %(default)s)")
    m2.add_argument("--lenient", action="store_true", help="skip and count malformed lines instead of stopping")
    m2.add_argument("--p-hit", type=float, default=0.7, help="P(occupied) for a beam's end cell (default: %(default)s, OctoMap's)")
    m2.add_argument("--p-miss", type=float, default=0.4,
                    help="P(occupied) for cells a beam passes (default: %(default)s, OctoMap's; 0.45 keeps walls "
                    "that many grazing beams cross more continuous)")
    return p


def _map2d(args) -> int:
    from .grid2d import LidarModel
    from .io.carmen import read_carmen
    from .mapping2d import map_scans

    t0 = time.perf_counter()
    log = read_carmen(args.log, lenient=args.lenient, every=args.every)
    print(f"read {len(log):,} scans from {args.log} in {time.perf_counter() - t0:.2f} s"
          + (f" ({log.skipped_malformed:,} malformed lines skipped)" if log.skipped_malformed else ""))
    if not len(log):
        raise InvalidArgumentError(f"{args.log}: no laser scans found")
    model = LidarModel(args.p_hit, args.p_miss)
    summary = map_scans(log.stack(), args.resolution, args.max_range, progress=sys.stderr.isatty(), model=model)
    image = summary.grid.save(args.output)
    for line in summary.lines():
        print(line)
    print(f"wrote {args.output} and {image}")
    if args.png:
        print(f"wrote {summary.grid.save_png(args.png)}")
    print(f"total {time.perf_counter() - t0:.2f} s")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 0
    try:
        if args.command == "demo":
            from .demo import run

            return run(args.out)
        if args.command == "map2d":
            return _map2d(args)
    except OccmapError as e:
        print(f"occmap {args.command}: error: {e}", file=sys.stderr)
        return 2
    parser.error(f"unknown command {args.command!r}")
    return 2


if __name__ == "__main__":
    raise SystemExit(main())
