"""3D occupancy octree against OctoMap itself (octomap-python, the PyPI wheel of OctoMap 1.10).

For each dataset and resolution both libraries insert the same clouds from the same sensor
origins (alternating rounds, medians); the table gives points per second, the speed-up, whether
the two trees agree (node count, and the share of finest-level voxels known to either that both
classify alike), and memory (occmap's node arrays against OctoMap's ``memoryUsage()``). Then
batched ray casting against a loop of OctoMap's ``castRay``, and ``.bt`` reading and writing.
Last, one scan per call as a robot streams (``insert_point_cloud`` of one simulated HDL-32E scan
into a growing map), with the default threads and on one thread, idle and beside a process that
keeps one core busy.

Datasets (from ../shared/data, skipped without it): the OctoMap sample scan (scan.dat), the three
Osnabrück scans with their registered poses, the Velodyne HDL-32E pair; and always a simulated
Velodyne HDL-32E drive of 50 scans through :mod:`occmap.sim.world3d`'s default town block (a
1.28° azimuth step, 9,000 beams a scan, to keep OctoMap's share of the run in minutes).

    python benchmarks/bench_octree.py [--quick] [--no-write]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import median_times, per_call_table, write_section  # noqa: E402

import octomap  # noqa: E402

from occmap._data import find_shared_data  # noqa: E402
from occmap.geometry import SE3  # noqa: E402
from occmap.io.pointclouds import read_pcd, read_uos, read_xyz  # noqa: E402
from occmap.io import octomap as formats  # noqa: E402
from occmap.octree import OcTree  # noqa: E402
from occmap.sim.world3d import VELODYNE_HDL32, simulate_drive  # noqa: E402


def datasets(data: Path | None, quick: bool) -> dict[str, list[tuple[np.ndarray, np.ndarray]]]:
    """name → list of (world points (N, 3), sensor origin (3,))."""
    sets = {}
    if data is not None:
        c = read_xyz(data / "octomap" / "scan.dat.bz2")
        sets["scan.dat (1 scan, 88k points)"] = [(c.world_points(), c.origin)]
        uos = [read_uos(data / "scans3d" / "uos_3dtk" / f"scan00{i}.3d") for i in range(3)]
        sets[f"Osnabrück 3DTK (3 scans, {sum(len(c) for c in uos) // 1000}k points)"] = [(c.world_points(), c.origin)
                                                                                     for c in uos]
        d = data / "scans3d" / "hdl32_pair"
        first, second = (read_pcd(p) for p in sorted(d.glob("*.pcd")))
        relative = SE3(np.loadtxt(d / "relative.txt"))
        sets["HDL-32E pair (2 scans, 128k points)"] = [
            (first.world_points(), first.origin),
            (relative.apply(second.world_points()), relative.apply(second.origin)),
        ]
    n = 10 if quick else 50
    drive = simulate_drive(n, VELODYNE_HDL32.with_azimuth_step(np.radians(1.28)), rng=1)
    points = sum(len(c) for c in drive)
    sets[f"simulated HDL-32E drive ({n} scans, {points // 1000}k points)"] = [(c.world_points(), c.origin) for c in drive]
    return sets


def build_occmap(scans, res):
    tree = OcTree(res)
    tree.insert_point_clouds([p for p, _ in scans], [o for _, o in scans])
    return tree


def build_octomap(scans, res):
    tree = octomap.OcTree(res)
    for pts, origin in scans:
        tree.insertPointCloud(pts, np.asarray(origin, dtype=np.float64))
    return tree


def agreement(ours: OcTree, ref, res: float) -> float:
    """Share of leaves known to either tree that both classify alike (occupied / free / unknown):
    1.0 at once when OctoMap's own ``.ot`` serialisation of its tree (every node and value) equals
    occmap's byte for byte, else counted leaf by leaf."""
    if formats.encode_ot(ours) == ref.write():
        return 1.0
    lv = ours.leaves()
    ref_rows = np.array([(*it.getCoordinate(), it.getSize(), it.getValue()) for it in ref.begin_leafs()])
    mine = np.c_[np.rint(lv.centers / res * 2), np.rint(lv.sizes / res), lv.log_odds >= 0].astype(np.int64)
    theirs = np.c_[np.rint(ref_rows[:, :3] / res * 2), np.rint(ref_rows[:, 3] / res), ref_rows[:, 4] >= 0].astype(np.int64)
    keys, inverse = np.unique(np.r_[mine[:, :4], theirs[:, :4]], axis=0, return_inverse=True)
    cls = np.full((len(keys), 2), -1)  # per leaf: class in occmap, in OctoMap (−1 unknown)
    cls[inverse[:len(mine)], 0] = mine[:, 4]
    cls[inverse[len(mine):], 1] = theirs[:, 4]
    return float(np.mean(cls[:, 0] == cls[:, 1]))


def timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


def insertion_rows(sets, resolutions, repeat):
    """Alternating rounds (occmap, OctoMap) after one warm-up of occmap (Numba compilation); the
    trees of the last round are compared."""
    rows = []
    for name, scans in sets.items():
        points = sum(len(p) for p, _ in scans)
        for res in resolutions:
            build_occmap(scans[:1], res)
            t_ours, t_ref = [], []
            for _ in range(repeat):
                t, ours = timed(lambda: build_occmap(scans, res))
                t_ours.append(t)
                t, ref = timed(lambda: build_octomap(scans, res))
                t_ref.append(t)
            t_ours, t_ref = statistics.median(t_ours), statistics.median(t_ref)
            agree = agreement(ours, ref, res)
            rows.append((name, res, points / t_ours, points / t_ref, t_ref / t_ours, ours.num_nodes(), ref.size(),
                         agree, ours.memory_usage(), ref.memoryUsage()))
            print(f"{name} @ {res:g} m: occmap {points / t_ours:,.0f} pts/s, OctoMap {points / t_ref:,.0f} pts/s "
                  f"({t_ref / t_ours:.1f}x); nodes {ours.num_nodes():,} / {ref.size():,}; agreement {agree:.5f}; "
                  f"memory {ours.memory_usage() / 2**20:.1f} / {ref.memoryUsage() / 2**20:.1f} MiB", flush=True)
    return rows


def raycast_rows(scans, res, n_rays=20_000):
    """Batched cast_ray against a Python loop of OctoMap's castRay, same rays, for a long and a
    short maximum range (per call, OctoMap's time is its walk plus the Python call)."""
    ours, ref = build_occmap(scans, res), build_octomap(scans, res)
    rng = np.random.default_rng(3)
    origin = np.asarray(scans[0][1], dtype=np.float64)
    D = rng.normal(size=(n_rays, 3))
    D[:, 2] *= 0.2
    end = np.zeros(3)
    rows = []
    for max_range in (30.0, 5.0):
        def ours_cast():
            ours.cast_ray(origin, D, max_range=max_range)

        def ref_cast():
            for d in D:
                ref.castRay(origin, d, end, ignoreUnknownCells=False, maxRange=max_range)

        t_ours, t_ref = median_times([ours_cast, ref_cast], number=1, repeat=5)
        hit, _ = ours.cast_ray(origin, D, max_range=max_range)
        rows.append((max_range, n_rays / t_ours, n_rays / t_ref, t_ref / t_ours, int(hit.sum())))
    return rows


def bt_rows(path: Path):
    tree = formats.read_octree(path)
    out = Path(tempfile.mkdtemp()) / "out.bt"
    ref = octomap.OcTree(0.1)
    t_read, t_read_ref = median_times(
        [lambda: formats.read_bt(path), lambda: octomap.OcTree(0.1).readBinary(str(path).encode())],
        number=1, repeat=5)
    ref.readBinary(str(path).encode())
    t_write, t_write_ref = median_times(
        [lambda: formats.write_bt(tree, out), lambda: ref.writeBinary(str(out).encode())], number=1, repeat=5)
    return (t_read, t_read_ref), (t_write, t_write_ref), tree.num_nodes()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a short drive and fewer rounds (a smoke run)")
    ap.add_argument("--no-write", action="store_true", help="print only; leave BENCHMARKS.md alone")
    args = ap.parse_args()
    data = find_shared_data()
    sets = datasets(data, args.quick)
    resolutions = (0.2, 0.1, 0.05)
    rows = insertion_rows(sets, resolutions, repeat=1 if args.quick else 3)

    lines = [
        "## 3D occupancy octree vs OctoMap (`benchmarks/bench_octree.py`)",
        "",
        "OctoMap 1.10 through octomap-python (its PyPI wheel), same clouds, same origins, default parameters "
        "(hit 0.7, miss 0.4, clamping 0.1192/0.971), eager updates; medians of alternating rounds. Agreement: share "
        "of leaves known to either tree that both classify alike (1 = identical trees). Memory: occmap's node "
        "arrays against OctoMap's `memoryUsage()`. Targets: insertion ≥ 10× OctoMap, agreement ≥ 0.999, "
        "memory ≤ OctoMap's.",
        "",
        "| dataset | resolution (m) | occmap (points/s) | OctoMap (points/s) | speed-up | nodes occmap / OctoMap | agreement | memory occmap / OctoMap (MiB) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for name, res, po, pr, sp, no, nr, ag, mo, mr in rows:
        lines.append(f"| {name} | {res:g} | {po:,.0f} | {pr:,.0f} | {sp:.1f}× | {no:,} / {nr:,} | {ag:.5f} | "
                     f"{mo / 2**20:.1f} / {mr / 2**20:.1f} |")
    first = next(iter(sets.values()))
    for max_range, ours, theirs, ratio, hits in raycast_rows(first, 0.1):
        lines += ["", f"Ray casting, {next(iter(sets))} at 0.1 m, 20,000 rays, max range {max_range:g} m: occmap "
                  f"{ours:,.0f} rays/s batched, a Python loop of OctoMap's `castRay` {theirs:,.0f} rays/s: "
                  f"**{ratio:.1f}×** ({hits:,} hits). Target ≥ 10×."]
        print(lines[-1])
    if data is not None:
        (r, rr_), (w, wr), nodes = bt_rows(data / "octomap" / "fr_079.bt")
        lines += ["", f"`.bt` files, fr_079.bt ({nodes:,} nodes): read occmap {r * 1e3:.0f} ms, OctoMap "
                  f"{rr_ * 1e3:.0f} ms (**{rr_ / r:.1f}×**); write occmap {w * 1e3:.0f} ms, OctoMap {wr * 1e3:.0f} ms "
                  f"(**{wr / w:.1f}×**). Target ≥ 2×."]
        print(lines[-1])
    stream = simulate_drive(8, VELODYNE_HDL32.with_azimuth_step(np.radians(0.4)), rng=2)
    for res in (0.2, 0.1):
        tree, k = OcTree(res), [0]

        def one_scan(tree=tree, k=k):
            c = stream[k[0] % len(stream)]
            k[0] += 1
            tree.insert_point_cloud(c.world_points(), c.origin)

        lines += ["", f"One scan per call at {res:g} m (simulated HDL-32E, {len(stream[0]):,} points a scan):", "",
                  per_call_table([(f"`insert_point_cloud` at {res:g} m", one_scan)], number=4,
                                 repeat=3 if args.quick else 7)]
        print(lines[-1])
    if not args.no_write and not args.quick:
        write_section("bench_octree", "\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
