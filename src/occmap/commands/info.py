"""``occmap info MAP.bt`` / ``occmap info DIR`` / ``occmap info BAG``: what an OctoMap file holds
(resolution, nodes, leaves, bounds, memory), what a tile store holds (kind, resolution, tiles,
scans, bounds, size on disk), or what a ROS bag holds (topics with their types, message counts and
frames, the tf tree, the time span)."""

from __future__ import annotations


def add_parser(subparsers):
    p = subparsers.add_parser("info", help="describe an octree file (.bt or .ot), a tile store folder or a ROS bag")
    p.add_argument("file", help="a .bt / .ot file, a tile store folder, or a ROS 1 .bag / ROS 2 bag (folder, .db3, .mcap)")
    return p


def _store_info(path) -> int:
    from ..world.store import TileStore

    store = TileStore.open(path, incomplete_ok=True)
    tiles = list(store.tiles.values())
    print(f"{path}")
    print(f"  kind            {store.kind} tile store" + ("" if store.state == "complete" else
                                                         "  (INCOMPLETE: its last build did not finish)"))
    print(f"  resolution      {store.resolution:g} m")
    print(f"  tile size       {store.tile_size} × {store.resolution:g} m = {store.tile_metres:g} m")
    print(f"  tiles           {len(tiles):,}")
    print(f"  scans           {store.scans:,}")
    if tiles and all("min" in t for t in tiles):
        lo = [min(t["min"][a] for t in tiles) for a in range(len(tiles[0]["min"]))]
        hi = [max(t["max"][a] for t in tiles) for a in range(len(tiles[0]["max"]))]
        print(f"  bounds          [{', '.join(f'{v:.1f}' for v in lo)}] .. [{', '.join(f'{v:.1f}' for v in hi)}] m")
    size = sum(f.stat().st_size for f in store.path.rglob("*") if f.is_file())
    print(f"  on disk         {size:,} bytes")
    return 0


def _bag_info(path) -> int:
    from datetime import datetime, timezone

    from ..io.bags import open_bag, read_frame_tree
    from ..io.bags.transforms import TF_TYPES

    with open_bag(path) as bag:
        print(f"{path}")
        print(f"  kind            {bag.kind} bag" + (f"  ({bag.note})" if bag.note else ""))
        if bag.start is None:
            print("  messages        0")
        else:
            first = datetime.fromtimestamp(bag.start, timezone.utc).isoformat(timespec="milliseconds")
            print(f"  time span       {bag.end - bag.start:.3f} s from {first}")
            print(f"  messages        {sum(t.count for t in bag.topics.values()):,}")
        print("  topics")
        width = max((len(name) for name in bag.topics), default=0)
        for name, topic in bag.topics.items():
            frame = _first_frame(bag, name) if topic.count else None
            print(f"    {name:<{width}}  {topic.msgtype:<32} {topic.count:>9,}" + (f"  frame {frame}" if frame else ""))
        tf = [name for name, topic in bag.topics.items() if topic.msgtype in TF_TYPES]
        if tf:
            tree = read_frame_tree(bag, tf)
            print(f"  tf frames       {len(tree.frames)} on {', '.join(tf)}")
            for line in repr(tree).splitlines()[1:]:
                print("  " + line)
    return 0


def _first_frame(bag, topic) -> str | None:
    """The header frame of the topic's first message, if its messages have a header."""
    from ..io.bags import frame_name

    for m in bag.messages(topic):
        header = getattr(m.msg, "header", None)
        return None if header is None else frame_name(header.frame_id)
    return None


def run(args) -> int:
    import os

    import numpy as np

    from ..io.bags import is_bag

    if is_bag(args.file):
        return _bag_info(args.file)
    if os.path.isdir(args.file):
        return _store_info(args.file)

    from ..io.octomap import read_octree

    tree = read_octree(args.file)
    lv = tree.leaves()
    occupied = lv.log_odds >= tree.occupied_log_odds
    n_occupied = int(occupied.sum())
    lo, hi = tree.metric_bounds()
    print(f"{args.file}")
    print(f"  resolution      {tree.resolution:g} m")
    print(f"  nodes           {tree.num_nodes():,}")
    print(f"  leaves          {len(lv.sizes):,} ({n_occupied:,} occupied, {len(lv.sizes) - n_occupied:,} free)")
    print(f"  bounds          [{lo[0]:.3f}, {lo[1]:.3f}, {lo[2]:.3f}] .. [{hi[0]:.3f}, {hi[1]:.3f}, {hi[2]:.3f}] m")
    print(f"  memory          {tree.memory_usage():,} bytes")
    print(f"  volume          {float(np.prod(hi - lo)):.3f} m³ (bounding box)")
    cubes = lv.sizes ** 3
    print(f"  known volume    {float(cubes.sum()):.3f} m³ ({cubes[occupied].sum():.3f} occupied)")
    return 0
