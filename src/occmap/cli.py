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

    m3 = sub.add_parser("map3d", help="build a 3D occupancy octree (OctoMap .bt/.ot) from point clouds with sensor poses")
    m3.add_argument("inputs", nargs="+", help="point clouds (.pcd .ply .xyz/.txt/.dat[.gz|.bz2|.xz] .bin .3d) or "
                    "OctoMap ScanGraphs (.graph); each cloud carries its sensor pose (PCD viewpoint, 3DTK .frames)")
    m3.add_argument("-o", "--output", required=True, help="octree to write (.bt maximum likelihood, .ot full values)")
    m3.add_argument("--resolution", type=float, default=0.1, help="voxel size in metres (default: %(default)s)")
    m3.add_argument("--max-range", type=float, default=-1.0, help="clear free space only up to this range, no hits "
                    "beyond (default: no limit)")
    m3.add_argument("--discretize", action="store_true", help="merge points falling in one voxel before ray casting")
    m3.add_argument("--png", help="also write a top-down height picture")

    info = sub.add_parser("info", help="describe an octree file (.bt or .ot)")
    info.add_argument("file")

    conv = sub.add_parser("convert", help="convert an octree: .bt <-> .ot, or occupied voxels to .ply")
    conv.add_argument("input")
    conv.add_argument("output")

    ren = sub.add_parser("render", help="draw an octree as a PNG (top-down height map, or a slice)")
    ren.add_argument("file")
    ren.add_argument("-o", "--output", required=True, help="PNG to write")
    ren.add_argument("--slice", type=float, metavar="Z", help="draw the horizontal slice at height Z instead")
    ren.add_argument("--pixel", type=float, help="pixel size in metres (default: the octree's resolution)")

    from .local.replay import add_parser as add_local_parser
    from .localize.replay import add_parser as add_localize_parser

    add_local_parser(sub)
    add_localize_parser(sub)
    return p


def _clouds(paths):
    """Point clouds from files, in order: ScanGraphs give one cloud per node."""
    from .io.pointclouds import read_cloud
    from .io.scangraph import read_scangraph

    for path in paths:
        if str(path).endswith(".graph"):
            yield from read_scangraph(path).nodes
        else:
            yield read_cloud(path)


def _save_octree(tree, path) -> None:
    from .io import octomap

    path = str(path)
    if path.endswith(".bt"):
        octomap.write_bt(tree, path)
    elif path.endswith(".ot"):
        octomap.write_ot(tree, path)
    elif path.endswith(".ply"):
        tree.export_ply(path)
    else:
        raise InvalidArgumentError(f"{path}: unknown octree file type (use .bt, .ot or .ply)")


def _map3d(args) -> int:
    from .octree import OcTree

    t0 = time.perf_counter()
    tree = OcTree(args.resolution)
    show = sys.stderr.isatty()
    points = dropped = scans = 0
    insert_seconds = 0.0
    for cloud in _clouds(args.inputs):
        t1 = time.perf_counter()
        s = tree.insert_point_cloud(cloud.world_points(), cloud.origin, args.max_range, args.discretize)
        insert_seconds += time.perf_counter() - t1
        scans += 1
        points += s["points"]
        dropped += s["dropped"] + cloud.dropped
        if show:
            print(f"\rscan {scans}: {points:,} points, {tree.num_nodes():,} nodes", end="", file=sys.stderr, flush=True)
    if show:
        print(file=sys.stderr)
    if not scans:
        raise InvalidArgumentError("no point clouds given")
    _save_octree(tree, args.output)
    rate = points / insert_seconds if insert_seconds > 0 else float("inf")
    print(f"{scans} scans, {points:,} points ({dropped:,} dropped: no return or not finite) at {args.resolution:g} m")
    print(f"inserted in {insert_seconds:.2f} s ({rate:,.0f} points/s); {tree.num_nodes():,} nodes, "
          f"{tree.num_leaves():,} leaves, {tree.memory_usage() / 2**20:.1f} MiB")
    print(f"wrote {args.output}")
    if args.png:
        tree.save_height_png(args.png)
        print(f"wrote {args.png}")
    print(f"total {time.perf_counter() - t0:.2f} s")
    return 0


def _info(args) -> int:
    from .io import octomap

    tree = octomap.read_octree(args.file)
    lv = tree.leaves()
    occupied = int((lv.log_odds >= tree.occupancy_log_odds).sum())
    lo, hi = tree.metric_bounds()
    print(f"{args.file}")
    print(f"  resolution      {tree.resolution:g} m")
    print(f"  nodes           {tree.num_nodes():,}")
    print(f"  leaves          {len(lv.sizes):,} ({occupied:,} occupied, {len(lv.sizes) - occupied:,} free)")
    print(f"  bounds          [{lo[0]:.3f}, {lo[1]:.3f}, {lo[2]:.3f}] .. [{hi[0]:.3f}, {hi[1]:.3f}, {hi[2]:.3f}] m")
    print(f"  memory          {tree.memory_usage():,} bytes")
    print(f"  volume          {tree.volume():.3f} m³ (bounding box)")
    known = float((lv.sizes ** 3).sum())
    print(f"  known volume    {known:.3f} m³ ({(lv.sizes[lv.log_odds >= tree.occupancy_log_odds] ** 3).sum():.3f} occupied)")
    return 0


def _convert(args) -> int:
    from .io import octomap

    _save_octree(octomap.read_octree(args.input), args.output)
    print(f"wrote {args.output}")
    return 0


def _render(args) -> int:
    from .io import octomap

    tree = octomap.read_octree(args.file)
    if args.slice is None:
        tree.save_height_png(args.output, args.pixel)
    else:
        tree.save_slice_png(args.output, args.slice, args.pixel)
    print(f"wrote {args.output}")
    return 0


def _local(args) -> int:
    from .local.replay import run_cli

    return run_cli(args)


def _localize(args) -> int:
    from .localize.replay import run_cli

    return run_cli(args)


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
        commands = {"map2d": _map2d, "map3d": _map3d, "info": _info, "convert": _convert, "render": _render,
                    "local": _local, "localize": _localize}
        if args.command in commands:
            return commands[args.command](args)
    except (OccmapError, OSError) as e:  # bad input, missing or unreadable files: a message, no traceback
        print(f"occmap {args.command}: error: {e}", file=sys.stderr)
        return 2
    parser.error(f"unknown command {args.command!r}")
    return 2


if __name__ == "__main__":
    raise SystemExit(main())
