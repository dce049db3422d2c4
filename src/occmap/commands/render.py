"""``occmap render MAP.bt -o PICTURE.png``: a labelled figure of an octree seen from above (height
map; an indoor map cut under its ceiling unless told otherwise) or of a horizontal slice;
``-o SCENE.html``: the occupied voxels as a 3D scene in one HTML file any browser turns offline
(:mod:`occmap.viz.inline`, cut the same way)."""

from __future__ import annotations

from . import _options
from ._outputs import check_outputs


def add_parser(subparsers):
    p = subparsers.add_parser("render", help="draw an octree as a PNG (top-down height map, or a slice) or as a "
                                             "3D scene in an HTML file")
    p.add_argument("file")
    p.add_argument("-o", "--output", required=True, help="PNG to write, or .html for a 3D scene")
    p.add_argument("--slice", type=_options.finite, metavar="Z", help="draw the horizontal slice at height Z instead")
    p.add_argument("--pixel", type=_options.positive, help="pixel size in metres (default: the octree's resolution)")
    cut = p.add_mutually_exclusive_group()
    cut.add_argument("--z-max", type=_options.finite, metavar="Z",
                     help="height map: leave out what is occupied from height Z up (default: under the ceiling, "
                          "when the map has one)")
    cut.add_argument("--no-cut", action="store_true", help="height map: draw the whole height, ceiling included")
    p.add_argument("--max-voxels", type=_options.count, metavar="K",
                   help="3D scene: boxes at most (coarser nodes beyond; default 150000)")
    return p


def run(args) -> int:
    from ..errors import InvalidArgumentError
    from ..io.octomap import read_octree

    check_outputs({"-o": args.output}, {"FILE": args.file})
    html = str(args.output).lower().endswith((".html", ".htm"))
    for given, name in ((args.slice is not None, "--slice"), (args.pixel is not None, "--pixel")):
        if html and given:
            raise InvalidArgumentError(f"{name} draws a PNG, and -o {args.output} is an HTML scene")
    if args.max_voxels is not None and not html:
        raise InvalidArgumentError(f"--max-voxels sizes a 3D scene: give -o a .html name, not {args.output}")
    tree = read_octree(args.file)
    z_max = None if args.no_cut else "ceiling" if args.z_max is None else args.z_max
    if html:
        tree.save_html(args.output, args.max_voxels, z_max)
    elif args.slice is None:
        tree.save_height_png(args.output, args.pixel, z_max)
    else:
        tree.save_slice_png(args.output, args.slice, args.pixel)
    print(f"wrote {args.output}")
    return 0
