"""``occmap render MAP.bt -o PICTURE.png``: a labelled figure of an octree seen from above (height
map; an indoor map cut under its ceiling unless told otherwise) or of a horizontal slice."""

from __future__ import annotations

from . import _options
from ._outputs import check_outputs


def add_parser(subparsers):
    p = subparsers.add_parser("render", help="draw an octree as a PNG (top-down height map, or a slice)")
    p.add_argument("file")
    p.add_argument("-o", "--output", required=True, help="PNG to write")
    p.add_argument("--slice", type=_options.finite, metavar="Z", help="draw the horizontal slice at height Z instead")
    p.add_argument("--pixel", type=_options.positive, help="pixel size in metres (default: the octree's resolution)")
    cut = p.add_mutually_exclusive_group()
    cut.add_argument("--z-max", type=_options.finite, metavar="Z",
                     help="height map: leave out what is occupied from height Z up (default: under the ceiling, "
                          "when the map has one)")
    cut.add_argument("--no-cut", action="store_true", help="height map: draw the whole height, ceiling included")
    return p


def run(args) -> int:
    from ..io.octomap import read_octree

    check_outputs({"-o": args.output}, {"FILE": args.file})
    tree = read_octree(args.file)
    if args.slice is None:
        tree.save_height_png(args.output, args.pixel, None if args.no_cut else "ceiling" if args.z_max is None
                             else args.z_max)
    else:
        tree.save_slice_png(args.output, args.slice, args.pixel)
    print(f"wrote {args.output}")
    return 0
