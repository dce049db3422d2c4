"""World-scale maps: one-process ``OcTree`` against a tiled build in one process and on a local Dask
cluster of two workers, on the same scans in one run.

The scans are a simulated LiDAR drive written once as PCD files (each with its pose), and every
variant reads them from those files, in a fresh process of its own, in alternating rounds
(medians): the one-process tree (read, insert, write ``.bt``), the tiled build in this process
(``occmap.world.build`` with ``workers=1``) and on a two-worker local cluster (the cluster's start
counted: it is part of what a user waits for). Each reports points per second, its peak resident
memory per process (the driver and each worker), and the size of what it wrote; the maps are
checked equal (the tiled store exported as one ``.bt`` against the tree's).

Then, on paper: the load balance and expected speed-up of the build's partition for 16 and 64
workers, from this drive's scans and the measured cost of a scan (its rays walked by every worker
whose region it reaches, its voxels applied by the one that owns them).

    python benchmarks/bench_world.py [--scans N] [--rounds N] [--no-write]
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import write_section  # noqa: E402

RES = 0.1
TILE = 512
MAX_RANGE = 60.0

ONE_TREE = """
import json, resource, sys, time
from occmap.io.octomap import write_bt
from occmap.octree import OcTree
from occmap.world.sources import CloudFiles
source = CloudFiles(sys.argv[2:])
t0 = time.perf_counter()
tree = OcTree(float(sys.argv[1].split(",")[0]))
points = 0
for k in range(len(source)):
    cloud = source.cloud(k)
    points += tree.insert_point_cloud(cloud.world_points(), cloud.origin, float(sys.argv[1].split(",")[1]))["points"]
write_bt(tree, sys.argv[1].split(",")[2])
print(json.dumps({"seconds": time.perf_counter() - t0, "points": points,
                  "peak": [resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024]}))
"""

TILED = """
import json, resource, shutil, sys, time
from occmap.world.build import build_octree
from occmap.world.sources import CloudFiles
res, max_range, store, tile, workers = sys.argv[1].split(",")
source = CloudFiles(sys.argv[2:])
shutil.rmtree(store, ignore_errors=True)
t0 = time.perf_counter()
s = build_octree(store, source, float(res), int(tile), max_range=float(max_range), workers=int(workers))
seconds = time.perf_counter() - t0
peaks = [p["peak_rss"] for p in s.parts]
if int(workers) > 1:
    peaks = [resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024] + peaks
print(json.dumps({"seconds": seconds, "points": s.stats["points"], "peak": peaks,
                  "parts": [(p["scans"], p["points"], p["seconds"]) for p in s.parts]}))
"""


def _run(script: str, args: list[str]) -> dict:
    out = subprocess.run([sys.executable, "-c", script, *args], check=True, capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _drive(folder: Path, n_scans: int) -> list[str]:
    """The scans as PCD files (sensor-frame points, pose in VIEWPOINT)."""
    from occmap.io.pointclouds import write_pcd
    from occmap.sim.world3d import VELODYNE_HDL32, simulate_drive

    paths = []
    for i, cloud in enumerate(simulate_drive(n_scans, VELODYNE_HDL32.with_azimuth_step(np.radians(0.6)), rng=7)):
        paths.append(str(folder / f"scan{i:05d}.pcd"))
        write_pcd(paths[-1], cloud)
    return paths


def _on_paper(paths: list[str], seconds_per_point: float, mark_share: float) -> list[str]:
    """Expected speed-up of the partition for 16 and 64 workers (see the module docstring)."""
    from occmap.world.build import footprint, partition, reaching
    from occmap.world.sources import CloudFiles

    source = CloudFiles(paths)
    feet = [footprint(source, k, MAX_RANGE) for k in range(len(source))]
    origins = np.array([f[0] for f in feet])
    lo, hi = np.array([f[1] for f in feet]), np.array([f[2] for f in feet])
    points = np.array([f[3] for f in feet], np.float64)
    side = TILE * RES
    cells = np.floor(origins[:, :2] / side).astype(np.int64)
    # a scan's voxels spread over its reach box: the share a region owns is the share of the box it covers
    lines = ["| workers | regions | scans read per region (mean / max) | work per region: max / mean | "
             "expected speed-up |", "|---:|---:|---:|---:|---:|"]
    total = float((points * seconds_per_point).sum())
    for workers in (2, 16, 64):
        regions = partition(cells, points + 1.0, workers)
        cost, reads = [], []
        for region in regions:
            r_lo = np.asarray(region[0][:2], np.float64) * side
            r_hi = (np.asarray(region[1][:2], np.float64) + 1) * side
            idx = reaching(region, lo, hi, side)
            over = np.clip(np.minimum(hi[idx, :2], r_hi) - np.maximum(lo[idx, :2], r_lo), 0, None)
            area = np.prod(np.maximum(hi[idx, :2] - lo[idx, :2], 1e-9), axis=1)
            share = np.prod(over, axis=1) / area
            t = points[idx] * seconds_per_point
            cost.append(float((t * (mark_share + (1 - mark_share) * share)).sum()))
            reads.append(len(idx))
        cost = np.array(cost)
        lines.append(f"| {workers} | {len(regions)} | {np.mean(reads):,.0f} / {max(reads):,} | "
                     f"{cost.max() / cost.mean():.2f} | {total / cost.max():.1f}× |")
    return lines


def _mark_share(paths: list[str]) -> float:
    """Share of a scan's insertion spent walking its rays (the part every reaching worker does)."""
    import time

    from occmap.octree import OcTree, insertion
    from occmap.octree.keys import NO_SHIFT
    from occmap.world.sources import CloudFiles

    source = CloudFiles(paths[: min(20, len(paths))])
    tree = OcTree(RES)
    walk = apply = 0.0
    for k in range(len(source)):
        cloud = source.cloud(k)
        o32 = cloud.origin.astype(np.float32)
        t0 = time.perf_counter()
        keys, is_hit, _, _ = insertion.cloud_voxels(cloud.world_points(), o32, MAX_RANGE, False, RES,
                                                    np.empty((0, 3), np.float32), np.empty((0, 3), np.int64),
                                                    NO_SHIFT, True)
        t1 = time.perf_counter()
        tree.update_voxels(keys, is_hit, threads=True)
        t2 = time.perf_counter()
        if k:  # the first scan compiles nothing (warm cache) but touches fresh memory
            walk += t1 - t0
            apply += t2 - t1
    return walk / (walk + apply)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scans", type=int, default=300, help="scans of the drive (default %(default)s)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="occmap-bench-world-") as tmp:
        folder = Path(tmp)
        paths = _drive(folder, args.scans)
        variants = {
            "one process, OcTree": (ONE_TREE, f"{RES},{MAX_RANGE},{folder / 'one.bt'}"),
            "tiled, this process": (TILED, f"{RES},{MAX_RANGE},{folder / 'store1'},{TILE},1"),
            "tiled, 2 Dask workers": (TILED, f"{RES},{MAX_RANGE},{folder / 'store2'},{TILE},2"),
        }
        runs = {name: [] for name in variants}
        for name, (script, spec) in variants.items():  # unmeasured: file cache, kernels loaded once
            _run(script, [spec, *paths[:2]])
        for _ in range(args.rounds):
            for name, (script, spec) in variants.items():
                runs[name].append(_run(script, [spec, *paths]))
                print(name, f"{runs[name][-1]['seconds']:.1f} s", flush=True)
        from occmap.io.octomap import encode_bt
        from occmap.world.octree_tiles import TiledOcTree

        one_bt = (folder / "one.bt").read_bytes()
        equal = all(encode_bt(TiledOcTree.open(folder / s).to_octree()) == one_bt for s in ("store1", "store2"))
        sizes = {s: sum(f.stat().st_size for f in (folder / s).rglob("*") if f.is_file()) for s in ("store1",)}
        med = {name: statistics.median(r["seconds"] for r in rs) for name, rs in runs.items()}
        points = runs["one process, OcTree"][0]["points"]
        lines = [f"A simulated HDL-32E drive of {args.scans} scans ({points:,} points) at {RES} m, max range "
                 f"{MAX_RANGE:g} m, tiles of {TILE} voxels ({TILE * RES:g} m), read from PCD files; medians of "
                 f"{args.rounds} alternating rounds, each variant in a fresh process.", "",
                 "| variant | seconds | points/s | peak memory per process |", "|---|---:|---:|---|"]
        for name, rs in runs.items():
            peaks = ", ".join(f"{p / 2**20:,.0f} MiB" for p in rs[-1]["peak"])
            lines.append(f"| {name} | {med[name]:.2f} | {points / med[name]:,.0f} | {peaks} |")
        one, t1, t2 = med["one process, OcTree"], med["tiled, this process"], med["tiled, 2 Dask workers"]
        lines += ["", f"- Tiled in this process / one `OcTree`: **{t1 / one:.2f}×** the time (target ≤ 1.3×).",
                  f"- Two Dask workers against the tiled build in one process: **{t1 / t2:.2f}×** faster "
                  f"(target ≥ 1.6× on this 2-core machine; the cluster's start included).",
                  f"- Maps equal (the stores exported as one `.bt`, byte for byte): **{equal}**.",
                  f"- Size on disk: the store {sizes['store1'] / 2**20:,.1f} MiB (tiles as `.ot`, full log-odds), "
                  f"one `.bt` {len(one_bt) / 2**20:,.1f} MiB (maximum likelihood only)."]
        share = _mark_share(paths)
        per_point = t1 / points
        lines += ["", f"On paper, for more workers: the partition of this drive's sensors into regions; a scan "
                  f"costs {per_point * 1e6:.2f} µs a point (the one-process tiled build), of which "
                  f"{share:.0%} is walking its rays (done by every worker whose region the scan reaches) and the "
                  f"rest applying voxels (by their owner, in proportion to the part of the scan's reach in its "
                  f"region).", ""]
        lines += _on_paper(paths, per_point, share)
    text = "\n".join(lines)
    print(text)
    if not args.no_write:
        write_section("bench_world", "## World-scale maps (`benchmarks/bench_world.py`)\n\n" + text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
