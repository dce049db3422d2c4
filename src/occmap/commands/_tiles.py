"""The options of a tiled (world-scale) build, shared by ``map2d`` and ``map3d``."""

from __future__ import annotations

import os

from . import _options


def add_tile_options(p, default_tile: int, unit: str) -> None:
    """``--tiles DIR`` and the options that only go with it."""
    g = p.add_argument_group("world-scale maps", "build into a tile store folder (occmap.world): no extent "
                             "limit, out of core, in parallel on Dask; the same map as one process")
    g.add_argument("--tiles", metavar="DIR", help="tile store to build, or to add these scans to (mapping resumes)")
    g.add_argument("--tile-size", type=_options.power_of_two, default=None,
                   help=f"{unit} per tile side, a power of two (default {default_tile}; a new store only)")
    g.add_argument("--workers", type=_options.count, default=None,
                   help="worker processes of a local Dask cluster (default 1: this process alone)")
    g.add_argument("--scheduler", metavar="ADDRESS", help="a running Dask scheduler (tcp://host:8786) to build on; "
                   "its workers must see DIR and the inputs at the same paths")
    g.add_argument("--memory-limit", type=_options.size, default=None,
                   help="bytes of tiles held in memory in all (e.g. 4GiB); the rest is written out and reloaded")


def check_tile_options(args) -> None:
    """Refuse tile options without ``--tiles`` (before any data is read)."""
    from ..errors import InvalidArgumentError

    if args.tiles is None:
        given = [f"--{name.replace('_', '-')}" for name in ("tile_size", "workers", "scheduler", "memory_limit")
                 if getattr(args, name) is not None]
        if given:
            raise InvalidArgumentError(f"{', '.join(given)}: only with --tiles DIR")
    elif args.workers is not None and args.scheduler is not None:
        raise InvalidArgumentError("--workers starts a local cluster, --scheduler uses a running one: give one")
    elif os.path.isfile(args.tiles):
        raise InvalidArgumentError(f"--tiles {args.tiles!r} is a file: a tile store is a folder")


def build_options(args) -> dict:
    """The keywords of :func:`occmap.world.build.build` the options give."""
    return {"workers": args.workers or 1, "scheduler": args.scheduler, "memory_limit": args.memory_limit,
            "progress": lambda text: print(text, flush=True)}
