"""The ``occmap`` command: builds the parser from the command modules of :mod:`occmap.commands`
and runs the chosen one.

Bad input (an :class:`~occmap.errors.OccmapError`, or a file that cannot be opened) ends the
command with one line on stderr and exit code 2, as ``argparse`` does for bad options; never a
traceback.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from . import __version__
from .commands import NAMES
from .errors import OccmapError


def build_parser() -> argparse.ArgumentParser:
    """The parser of every command; each sets ``args.run`` to its module's ``run``."""
    p = argparse.ArgumentParser(
        prog="occmap",
        description="Probabilistic occupancy maps from range sensors and robot poses.",
    )
    p.add_argument("--version", action="version", version=f"occmap {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    for name in NAMES:
        module = importlib.import_module(f"{__package__}.commands.{name}")
        module.add_parser(sub).set_defaults(run=module.run)
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 0
    try:
        return args.run(args)
    except (OccmapError, OSError) as e:  # bad input, missing or unreadable files: a message, no traceback
        print(f"occmap {args.command}: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
