"""``occmap export DIR -o OUT [--box …]``: a box of a tile store (or all of it) as one map file."""

from __future__ import annotations

from . import _options
from ._outputs import check_outputs


def add_parser(subparsers):
    p = subparsers.add_parser("export", help="write a box of a tile store (or all of it) as one map file")
    p.add_argument("store", help="tile store folder (from map3d/map2d --tiles)")
    p.add_argument("-o", "--output", required=True, help="an octree store: .bt or .ot (OctoMap)")
    p.add_argument("--box", type=_options.finite, nargs=6, metavar=("XMIN", "YMIN", "ZMIN", "XMAX", "YMAX", "ZMAX"),
                   help="the tiles meeting this box, metres (default: all)")
    return p


def run(args) -> int:
    from ..errors import InvalidArgumentError
    from ..world.octree_tiles import TiledOcTree

    check_outputs({"-o": args.output}, {"STORE": args.store})
    if not args.output.lower().endswith((".bt", ".ot")):
        raise InvalidArgumentError(f"-o {args.output!r}: an octree store exports to .bt or .ot")
    box = None if args.box is None else (args.box[:3], args.box[3:])
    tiled = TiledOcTree.open(args.store)
    offset = tiled.export(args.output, box)
    print(f"wrote {args.output}" + (f": coordinates less the offset {offset.tolist()} m (in its header)"
                                    if offset.any() else ""))
    return 0
