"""``occmap map3d CLOUD... -o MAP.bt``: a 3D occupancy octree (OctoMap's semantics) from point
clouds with their sensor poses (from the files, a pose file, or tf in a ROS bag's PointCloud2
topic), written as ``.bt``, ``.ot`` or ``.ply``."""

from __future__ import annotations

import time
from pathlib import Path

from . import _notes, _options, _sources, _tiles
from ._octree_files import check_octree_output, save_octree
from ._outputs import check_outputs


def add_parser(subparsers):
    p = subparsers.add_parser("map3d", help="build a 3D occupancy octree (OctoMap .bt/.ot) from point clouds with sensor poses")
    p.add_argument("inputs", nargs="+", help="point clouds (.pcd .ply .xyz/.txt/.dat[.gz|.bz2|.xz] .bin .3d) or "
                   "OctoMap ScanGraphs (.graph); each cloud carries its sensor pose (PCD viewpoint, 3DTK .frames) "
                   "unless --poses gives them; or one ROS bag with sensor_msgs/PointCloud2")
    p.add_argument("-o", "--output", help="octree to write (.bt maximum likelihood, .ot full values, .ply occupied "
                   "voxels); with --tiles, the whole store joined into one .bt/.ot")
    p.add_argument("--resolution", type=_options.positive, default=0.1, help="voxel size in metres (default: %(default)s)")
    p.add_argument("--max-range", type=_options.positive, help="clear free space only up to this range, no hits "
                   "beyond (default: no limit)")
    p.add_argument("--discretize", action="store_true", help="merge points falling in one voxel before ray casting")
    p.add_argument("--png", help="also write a top-down height picture")
    _tiles.add_tile_options(p, 512, "voxels")
    _sources.add_bag_options(p, "sensor_msgs/PointCloud2", "map")
    return p


def _source(args):
    """The clouds to insert: one bag's topic, or the files (poses from ``--poses`` or their own)."""
    from ..errors import InvalidArgumentError
    from ..io.bags import is_bag
    from ..sources import BagClouds, CloudFiles

    bags = [p for p in args.inputs if is_bag(p)]
    if bags:
        if len(args.inputs) > 1:
            raise InvalidArgumentError(f"one bag at a time: {bags[0]} came with {len(args.inputs) - 1} more inputs")
        if args.tiles is not None:
            raise InvalidArgumentError("--tiles reads files scan by scan; a bag is mapped in one process "
                                       "(drop --tiles)")
        return BagClouds(bags[0], **_sources.bag_options(args))
    _sources.refuse_bag_options(args, "point-cloud files", takes_poses=True)
    return CloudFiles(args.inputs, poses=_sources.pose_track(args))


def _run_tiled(args, source) -> int:
    from ..errors import InvalidArgumentError
    from ..world.build import build_octree
    from ..world.octree_tiles import TiledOcTree

    if args.png is not None or (args.output is not None and not args.output.lower().endswith((".bt", ".ot"))):
        raise InvalidArgumentError("with --tiles, -o is a .bt or .ot export of the whole store and --png is not made")
    summary = build_octree(args.tiles, source, args.resolution, args.tile_size,
                           max_range=-1.0 if args.max_range is None else args.max_range, discretize=args.discretize,
                           **_tiles.build_options(args))
    _notes.identity_poses("map3d", [source.name(k) for k in summary.no_pose], len(source))
    s = summary.stats
    print(f"{s['scans']} scans, {s['points']:,} points ({s['dropped']:,} dropped) into {args.tiles}: {summary.line()}")
    if args.output is not None:
        offset = TiledOcTree.open(args.tiles).export(args.output)
        print(f"wrote {args.output}" + (f" (offset {offset.tolist()} m, in its header)" if offset.any() else ""))
    return 0


def run(args) -> int:
    from .._clock import WorkClock
    from .._progress import Progress
    from .._threads import read_ahead
    from ..errors import InvalidArgumentError
    from ..octree import OcTree

    _tiles.check_tile_options(args)
    if args.tiles is None and args.output is None:
        raise InvalidArgumentError("give -o MAP (.bt, .ot, .ply) or --tiles DIR")
    if args.output is not None:
        check_octree_output(args.output)
    check_outputs({"-o": args.output, "--png": args.png}, {f"input {p}": p for p in args.inputs})
    source = _source(args)
    if args.tiles is not None:
        return _run_tiled(args, source)
    max_range = -1.0 if args.max_range is None else args.max_range
    t0 = time.perf_counter()
    tree = OcTree(args.resolution)
    progress = Progress(len(source), "clouds")
    points = dropped = outside = scans = 0
    no_pose = []
    clock = WorkClock()
    for k, cloud in enumerate(read_ahead(source)):  # the next cloud read while this one is inserted
        if not cloud.has_pose:
            no_pose.append(source.name(k))
        with clock.running():
            s = tree.insert_point_cloud(cloud.world_points(), cloud.origin, max_range, args.discretize)
        scans += 1
        points += s["points"]
        dropped += s["dropped"] + cloud.dropped
        outside += s["outside_key_range"]
        progress.update(scans + sum(source.dropped.values()), f"{points:,} points, {tree.num_nodes():,} nodes")
    progress.close()
    _sources.report("map3d", source)
    if not scans:
        raise InvalidArgumentError("no point clouds given" if not len(source) else f"none of the {len(source):,} "
                                   "clouds could be placed in the map (see the notes above)")
    _notes.identity_poses("map3d", no_pose, scans)
    if outside:
        _notes.note("map3d", f"points outside the octree's key range (±{32768 * args.resolution:g} m at "
                             f"{args.resolution:g} m) skipped: {outside:,}, their rays left out as OctoMap does "
                             "(--tiles has no such limit)")
    save_octree(tree, args.output)
    rate = points / clock.seconds if clock.seconds > 0 else float("inf")
    _sources.print_use(source, scans, "clouds")
    print(f"{scans} scans, {points:,} points ({dropped:,} dropped: no return, not finite or out of range) at {args.resolution:g} m")
    print(f"inserted in {clock.seconds:.3f} s ({rate:,.0f} points/s); {tree.num_nodes():,} nodes, "
          f"{tree.num_leaves():,} leaves, {tree.memory_usage() / 2**20:.1f} MiB")
    print(f"wrote {args.output}")
    if args.png:
        name = Path(args.inputs[0]).name + (f" and {len(args.inputs) - 1} more" if len(args.inputs) > 1 else "")
        tree.save_height_png(args.png, title=f"height map of {name}")
        print(f"wrote {args.png}")
    print(f"total {time.perf_counter() - t0:.2f} s")
    return 0
