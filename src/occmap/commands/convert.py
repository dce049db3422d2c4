"""``occmap convert IN OUT``: an octree from ``.bt``/``.ot`` to ``.bt``, ``.ot`` or a ``.ply`` of its
occupied voxels."""

from __future__ import annotations

from ._octree_files import check_octree_output, save_octree
from ._outputs import check_outputs


def add_parser(subparsers):
    p = subparsers.add_parser("convert", help="convert an octree: .bt <-> .ot, or occupied voxels to .ply")
    p.add_argument("input")
    p.add_argument("output")
    return p


def run(args) -> int:
    from ..io.octomap import read_octree

    check_octree_output(args.output)
    check_outputs({"OUTPUT": args.output}, {"INPUT": args.input})
    save_octree(read_octree(args.input), args.output)
    print(f"wrote {args.output}")
    return 0
