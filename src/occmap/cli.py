"""The ``occmap`` command."""

from __future__ import annotations

import argparse
import sys

from . import __version__
from .errors import OccmapError


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="occmap",
        description="Probabilistic occupancy maps from range sensors and robot poses.",
    )
    p.add_argument("--version", action="version", version=f"occmap {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    demo = sub.add_parser("demo", help="run the built-in demo (no data needed) and write its pictures")
    demo.add_argument("--out", default="demo_output", help="folder for the demo's files (default: %(default)s)")
    return p


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
    except OccmapError as e:
        print(f"occmap {args.command}: error: {e}", file=sys.stderr)
        return 2
    parser.error(f"unknown command {args.command!r}")
    return 2


if __name__ == "__main__":
    raise SystemExit(main())
