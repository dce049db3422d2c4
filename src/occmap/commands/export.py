"""``occmap export DIR -o OUT [--box …]``: a box of a tile store (or all of it) as one map file."""

from __future__ import annotations

from . import _options
from ._outputs import check_outputs, check_suffix


def add_parser(subparsers):
    p = subparsers.add_parser("export", help="write a box of a tile store (or all of it) as one map file")
    p.add_argument("store", help="tile store folder (from map3d/map2d --tiles)")
    p.add_argument("-o", "--output", required=True, help="an octree store: .bt or .ot (OctoMap); a grid store: a "
                   "map_server .yaml (the .pgm beside it)")
    p.add_argument("--box", type=_options.finite, nargs="+", metavar="V",
                   help="metres: XMIN YMIN ZMIN XMAX YMAX ZMAX (octree: the tiles meeting it) or XMIN YMIN XMAX YMAX "
                   "(grid: the cells whose centres lie in it); default all")
    return p


def run(args) -> int:
    from pathlib import Path

    from ..errors import InvalidArgumentError
    from ..world.store import TileStore

    kind = TileStore.open(args.store).kind
    dims = 3 if kind == "octree" else 2
    if args.box is not None and len(args.box) != 2 * dims:
        raise InvalidArgumentError(f"--box takes {2 * dims} numbers for a {kind} store, got {len(args.box)}")
    if kind == "octree":
        from ..world.octree_tiles import TiledOcTree

        check_suffix("-o", args.output, (".bt", ".ot"))
        check_outputs({"-o": args.output}, {"STORE": args.store})
        box = None if args.box is None else (args.box[:3], args.box[3:])
        offset = TiledOcTree.open(args.store).export(args.output, box)
        print(f"wrote {args.output}" + (f": coordinates less the offset {offset.tolist()} m (in its header)"
                                        if offset.any() else ""))
    else:
        from ..world.grid_tiles import TiledGrid2D

        check_suffix("-o", args.output, (".yaml", ".yml"))
        image = Path(args.output).with_suffix(".pgm")
        check_outputs({"-o": args.output, "the map's image": image}, {"STORE": args.store})
        image = TiledGrid2D.open(args.store).export(args.box, args.output)
        print(f"wrote {args.output} and {image}")
    return 0
