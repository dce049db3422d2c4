"""``occmap info MAP.bt`` / ``occmap info DIR``: what an OctoMap file holds (resolution, nodes, leaves,
bounds, memory), or what a tile store holds (kind, resolution, tiles, scans, bounds, size on disk)."""

from __future__ import annotations


def add_parser(subparsers):
    p = subparsers.add_parser("info", help="describe an octree file (.bt or .ot) or a tile store folder")
    p.add_argument("file", help="a .bt / .ot file or a tile store folder")
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


def run(args) -> int:
    import os

    import numpy as np

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
