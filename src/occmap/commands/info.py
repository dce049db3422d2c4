"""``occmap info MAP.bt``: what an OctoMap file holds (resolution, nodes, leaves, bounds, memory)."""

from __future__ import annotations


def add_parser(subparsers):
    p = subparsers.add_parser("info", help="describe an octree file (.bt or .ot)")
    p.add_argument("file")
    return p


def run(args) -> int:
    import numpy as np

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
