"""3D occupancy octree against OctoMap itself (octomap-python, the PyPI wheel of OctoMap 1.10) and,
per core, against Bonxai's ``ProbabilisticMap`` (C++).

For each dataset, resolution and maximum range (none, 30 m) every mapper inserts the same clouds
from the same sensor origins (alternating rounds, medians): occmap on two threads, occmap on one
core (a process pinned to one CPU, :mod:`_peers`), Bonxai on the same core, and, with no maximum
range, OctoMap (single-threaded). The table gives points per second, the per-core and two-thread
ratios with their targets, Bonxai's free voxels against OctoMap's (Bonxai is not exact), and, in
the OctoMap rows, the speed-up, whether the two trees agree (node count, and the share of
finest-level voxels known to either that both classify alike), and memory (occmap's node arrays
against OctoMap's ``memoryUsage()``). Then batched ray casting against a loop of OctoMap's
``castRay``, and ``.bt`` reading and writing. Last, one scan per call as a robot streams
(``insert_point_cloud`` of one simulated HDL-32E scan into a growing map), with the default
threads and on one thread, idle and beside a process that keeps one core busy.

Bonxai runs as a program given with ``--bonxai`` (default: the environment variable
``BONXAI_INSERT``) that speaks the protocol of :mod:`_peers`; this repository neither holds nor
builds one. Without it the table quotes issue 16's measurement of Bonxai and says so.

Datasets (from ../shared/data, skipped without it): the OctoMap sample scan (scan.dat), the three
Osnabrück scans with their registered poses, the Velodyne HDL-32E pair; and always a simulated
Velodyne HDL-32E drive of 50 scans through :mod:`occmap.sim.world3d`'s default town block (a
1.28° azimuth step, 9,000 beams a scan, to keep OctoMap's share of the run in minutes).

    python benchmarks/bench_octree.py [--quick] [--no-write] [--bonxai PROGRAM]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _peers import OccmapProcess, pinned_cpu, run_native, write_scans  # noqa: E402
from _report import median_times, per_call_table, write_section  # noqa: E402

import numba  # noqa: E402
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


#: Bonxai's ProbabilisticMap on one thread, points/s, as issue 16 measured it in another run (with
#: occmap then on two threads): (dataset's first word, resolution) → points/s.
ISSUE_16_BONXAI = {("scan.dat", 0.2): 6.18e6, ("Osnabrück", 0.2): 6.87e6, ("HDL-32E", 0.2): 5.76e6,
                   ("Osnabrück", 0.1): 1.79e6, ("HDL-32E", 0.1): 1.45e6, ("scan.dat", 0.05): 0.29e6}
#: Rounds a row (their medians): the two-thread and one-core figures swing by 15 - 20 % from round to round on this
#: shared machine (quartiles of paired ratios); OctoMap, far slower (a minute a round at 0.05 m), runs in the first
#: few only.
ROUNDS, OCTOMAP_ROUNDS = 5, 3
#: Targets: occmap on one core at least as fast as Bonxai on one; two threads this much faster than one core.
PER_CORE_TARGET, TWO_THREADS_TARGET = 1.0, 1.7


def build_occmap(scans, res, max_range=-1.0, discretize=False):
    tree = OcTree(res)
    tree.insert_point_clouds([p for p, _ in scans], [o for _, o in scans], max_range=max_range, discretize=discretize)
    return tree


def build_octomap(scans, res):
    tree = octomap.OcTree(res)
    for pts, origin in scans:
        tree.insertPointCloud(pts, np.asarray(origin, dtype=np.float64))
    return tree


def free_voxels(tree: OcTree) -> int:
    """Finest-level voxels the tree holds free (a pruned leaf of edge s counts (s / resolution)³)."""
    lv = tree.leaves()
    edges = np.rint(lv.sizes[lv.log_odds < 0] / tree.resolution).astype(np.int64)
    return int(np.sum(edges ** 3))


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


def insertion_rows(sets, resolutions, max_ranges, repeat, bonxai: Path | None, workdir: Path):
    """One row a dataset, resolution and max range (< 0: none), from alternating rounds of occmap
    on two threads and on one core (each in a process of its own, :class:`_peers.OccmapProcess`),
    occmap here on two threads plain and with ``discretize=True`` (their ratio), Bonxai on the
    one-core CPU (with a program) and, with no max range, OctoMap; occmap's first warm-up here is
    one scan (the processes warm up by themselves). The trees of the last round are compared. OctoMap's free voxels are counted in
    occmap's tree, which is OctoMap's (the agreement column, and the tests with a max range)."""
    rows = []
    cpu = pinned_cpu()
    one_core = OccmapProcess(cpu)
    two_threads = OccmapProcess(None, min(2, numba.config.NUMBA_NUM_THREADS))
    threads = numba.get_num_threads()
    numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
    try:
        for i, (name, scans) in enumerate(sets.items()):
            points = sum(len(p) for p, _ in scans)
            path = workdir / f"scans-{i}.bin"  # (a new name: the one-core process keeps the file it read last)
            write_scans(path, scans)
            for res in resolutions:
                for max_range in max_ranges:
                    row = {"name": name, "res": res, "max_range": max_range, "points": points}
                    build_occmap(scans[:1], res, max_range)
                    build_occmap(scans[:1], res, max_range, True)
                    times = {"two": [], "plain": [], "discretize": [], "one": [], "one_discretize": [], "bonxai": [],
                             "octomap": []}
                    for r in range(repeat):
                        times["two"].append(two_threads.seconds(path, res, max_range))
                        t, ours = timed(lambda: build_occmap(scans, res, max_range))
                        times["plain"].append(t)
                        times["discretize"].append(timed(lambda: build_occmap(scans, res, max_range, True))[0])
                        times["one"].append(one_core.seconds(path, res, max_range))
                        times["one_discretize"].append(one_core.seconds(path, res, max_range, True))
                        if bonxai is not None:
                            native = run_native(bonxai, path, res, max_range, cpu)
                            times["bonxai"].append(native["seconds"])
                        if max_range < 0 and r < OCTOMAP_ROUNDS:
                            t, ref = timed(lambda: build_octomap(scans, res))
                            times["octomap"].append(t)
                    row.update({k: statistics.median(v) if v else None for k, v in times.items()})
                    row["free"] = free_voxels(ours)
                    if bonxai is not None:
                        row["bonxai_free"] = native["free"]
                    else:
                        quoted = ISSUE_16_BONXAI.get((name.split()[0], res)) if max_range < 0 else None
                        row["bonxai"] = None if quoted is None else points / quoted
                    if max_range < 0:
                        row.update(agree=agreement(ours, ref, res), nodes=(ours.num_nodes(), ref.size()),
                                   memory=(ours.memory_usage(), ref.memoryUsage()))
                    rows.append(row)
                    print(row_line(row, bonxai is None), flush=True)
    finally:
        numba.set_num_threads(threads)
        one_core.close()
        two_threads.close()
    return rows


def row_line(row, quoted: bool) -> str:
    """The table's row for an :func:`insertion_rows` row (Bonxai's figure ``quoted`` or measured)."""
    n = row["points"]
    max_range = "none" if row["max_range"] < 0 else f"{row['max_range']:g}"
    cells = [row["name"], f"{row['res']:g}", max_range, f"{n / row['two']:,.0f}", f"{n / row['one']:,.0f}"]
    scaling = row["one"] / row["two"]
    per_core = None if row["bonxai"] is None else row["bonxai"] / row["one"]
    like_for_like = None if row["bonxai"] is None else row["bonxai"] / row["one_discretize"]
    cells.append(f"{n / row['one_discretize']:,.0f}")
    if per_core is None:
        cells += ["—", "—", "—"]
    else:
        cells += [f"{n / row['bonxai']:,.0f}" + (" (quoted)" if quoted else ""), f"**{per_core:.2f}×**",
                  f"**{like_for_like:.2f}×**"]
    cells.append(f"{scaling:.2f}×")
    cells.append(f"{row['bonxai_free'] / 1e6:.2f} M / {row['free'] / 1e6:.2f} M" if "bonxai_free" in row else
                 f"— / {row['free'] / 1e6:.2f} M")
    discretize = row["plain"] / row["discretize"]
    cells.append(f"{discretize:.2f}×")
    cells.append("; ".join(f"{what}: {'—' if ratio is None else 'met' if ratio >= target else '**not met**'}"
                           for what, ratio, target in (("one core", per_core, PER_CORE_TARGET),
                                                       ("one core, one ray per end voxel", like_for_like,
                                                        PER_CORE_TARGET),
                                                       ("two threads", scaling, TWO_THREADS_TARGET),
                                                       ("discretize", discretize, 1.0))))
    if row["octomap"] is None:
        cells += ["—"] * 5
    else:
        (no, nr), (mo, mr) = row["nodes"], row["memory"]
        cells += [f"{n / row['octomap']:,.0f}", f"{row['octomap'] / row['two']:.1f}×", f"{no:,} / {nr:,}",
                  f"{row['agree']:.5f}", f"{mo / 2**20:.1f} / {mr / 2**20:.1f}"]
    return "| " + " | ".join(cells) + " |"


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


#: A long drive streamed scan by scan in a fresh process. ``memory``: the scans are simulated one
#: at a time (not held), so resident memory is the interpreter, the kernels, one scan and the
#: tree. ``rates``: each stretch of scans (simulated, then held) goes into the drive's tree and
#: into a tree of its own, in turn (which first alternates), so that the two rates of a stretch
#: are measured side by side on this shared machine, not minutes apart.
DRIVE = """
import json, sys, time
import numpy as np
from occmap.geometry import SE3
from occmap.octree import OcTree
from occmap.sim.world3d import VELODYNE_HDL32, World3D, simulate_lidar
mode = sys.argv[1]
n, res, chunk = (float(a) for a in sys.argv[2:5])
n, chunk = int(n), int(chunk)
model = VELODYNE_HDL32.with_azimuth_step(np.radians(1.28))
world = World3D.default()
poses = world.default_trajectory(n, 1.8)
def scan(i):  # (its own noise, so that any scan can be simulated again)
    cloud = simulate_lidar(world, SE3(poses[i]), model, rng=np.random.default_rng((1, i)))
    return cloud.world_points(), cloud.origin
warm = simulate_lidar(world, SE3(poses[0]), model, rng=np.random.default_rng(0))
OcTree(res).insert_point_cloud(warm.world_points(), warm.origin)  # kernels loaded: the baseline
def rss():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096
def peak():  # (VmHWM: this process's own peak; getrusage's maxrss keeps the parent's size from before exec)
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) * 1024 for line in f if line.startswith("VmHWM:"))
def rate(tree, clouds):
    t0 = time.perf_counter()
    points = sum(tree.insert_point_cloud(p, o)["points"] for p, o in clouds)
    return points / (time.perf_counter() - t0)
base = rss()
tree = OcTree(res)
if mode == "memory":
    for i in range(n):
        tree.insert_point_cloud(*scan(i))
    out = {"base": base, "peak": peak(), "end": rss(), "usage": tree.memory_usage(),
           "allocated": tree.memory_allocated(), "nodes": tree.num_nodes()}
else:
    out = {"rates": [], "alone": []}
    for k, first in enumerate(range(0, n - chunk + 1, chunk)):
        clouds = [scan(i) for i in range(first, first + chunk)]
        for which in (("rates", "alone") if k % 2 == 0 else ("alone", "rates")):
            out[which].append(rate(tree if which == "rates" else OcTree(res), clouds))
print(json.dumps(out))
"""


def drive_memory(n_scans: int, res: float, chunk: int) -> dict:
    """Peak resident memory of a drive of ``n_scans`` streamed into one tree, and the rate of each
    stretch of ``chunk`` scans into it and into a tree of its own (:data:`DRIVE`, a fresh process
    each)."""
    out = {}
    for mode in ("memory", "rates"):
        run = subprocess.run([sys.executable, "-c", DRIVE, mode, str(n_scans), str(res), str(chunk)], check=True,
                             stdout=subprocess.PIPE, text=True)
        out.update(json.loads(run.stdout.strip().splitlines()[-1]))
    return out


def drive_lines(n_scans: int, res: float) -> list[str]:
    chunk = max(1, n_scans // 8)
    d = drive_memory(n_scans, res, chunk)
    mib = 2 ** 20
    growth = d["peak"] - d["base"]
    rates = d["rates"]
    return ["", f"Memory and throughput over a long drive: {n_scans} simulated HDL-32E scans at {res:g} m (9,000 "
            f"beams a scan, one `insert_point_cloud` a scan, scans simulated one at a time in a fresh process). "
            f"Baseline (interpreter, NumPy, Numba, occmap's kernels loaded) {d['base'] / mib:,.0f} MiB; peak "
            f"resident {d['peak'] / mib:,.0f} MiB: growth **{growth / mib:,.1f} MiB** for a tree of "
            f"{d['nodes']:,} nodes whose memory figure (`memory_usage()`, OctoMap's count) is "
            f"{d['usage'] / mib:,.1f} MiB (**{growth / d['usage']:.1f}×**; target ≤ 3×) and whose pool reserves "
            f"{d['allocated'] / mib:,.1f} MiB. Points/s per {chunk} scans (in another fresh process, each "
            f"stretch's scans held and inserted into the drive's tree and into a tree of their own in turn): "
            + ", ".join(f"{r / 1e6:.2f} M" for r in rates)
            + f"; the same stretches each into a tree of their own: "
            + ", ".join(f"{r / 1e6:.2f} M" for r in d["alone"])
            + "; in the drive's tree / alone: " + ", ".join(f"{r / a:.2f}" for r, a in zip(rates, d["alone"]))
            + " (flat in the number of scans when near 1: what the tree's size costs, apart from the "
            "scenery's)."]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a short drive and fewer rounds (a smoke run)")
    ap.add_argument("--no-write", action="store_true", help="print only; leave BENCHMARKS.md alone")
    ap.add_argument("--bonxai", type=Path, default=os.environ.get("BONXAI_INSERT"), metavar="PROGRAM",
                    help="a program inserting scans with Bonxai's ProbabilisticMap, called as benchmarks/_peers.py "
                         "describes (default: $BONXAI_INSERT; without it, issue 16's figures are quoted)")
    args = ap.parse_args()
    if args.bonxai is not None and not os.access(args.bonxai, os.X_OK):
        ap.error(f"--bonxai {args.bonxai}: not an executable file")
    data = find_shared_data()
    sets = datasets(data, args.quick)
    with tempfile.TemporaryDirectory() as workdir:
        rows = insertion_rows(sets, (0.2, 0.1, 0.05), (-1.0, 30.0), 1 if args.quick else ROUNDS, args.bonxai,
                             Path(workdir))

    if args.bonxai is None:
        bonxai = ("Bonxai was not run (no `--bonxai` program): its figures are **quoted** from issue 16's "
                  "measurement (another run: Bonxai on one thread, occmap then on two), in the rows with no max "
                  "range where it has them; this run's anchor for them is OctoMap, single-threaded, in those rows.")
    else:
        bonxai = (f"Bonxai: `ProbabilisticMap::insertPointCloud` (C++, `{args.bonxai.name}` compiled with `-O3 "
                  "-march=native` outside this repository) in a process of its own on the same CPU as occmap's "
                  "one-core process, a fresh map each round, time of the insertion alone; with no max range it is "
                  "given an infinite one.")
    lines = [
        "## 3D occupancy octree vs OctoMap and Bonxai (`benchmarks/bench_octree.py`)",
        "",
        f"Same clouds, same origins, fresh maps each round, medians of {ROUNDS} alternating rounds (occmap on two "
        f"threads, occmap on one core, Bonxai, OctoMap in the first {OCTOMAP_ROUNDS}). occmap on one core: a process "
        "with `NUMBA_NUM_THREADS=1` pinned to one CPU (`sched_setaffinity`), so that every thread it starts shares "
        "that core; occmap on two threads: a process of its own too (`NUMBA_NUM_THREADS=2`, not pinned), so both are "
        "timed alike (in the benchmark's own process, between the other mappers' rounds, some rows' two-thread "
        "figures read far lower: the HDL-32E pair at 0.05 m 0.66× one core there, 1.53× in a process of its own); "
        "each of its rounds starts once occmap sees the cores free (it takes one thread while other processes keep "
        "them busy, judged over the last tenth of a second or more, and the round before was another mapper's); the "
        "ratio plain / "
        "`discretize=True` is timed in the benchmark's process, both alike. " + bonxai,
        "",
        "OctoMap 1.10 through octomap-python (its PyPI wheel, single-threaded), default parameters "
        "(hit 0.7, miss 0.4, clamping 0.1192/0.971), eager updates; it runs only in the rows with no max range "
        "(its 0.05 m rows take minutes). Speed-up: OctoMap's time over occmap's on two threads. Agreement: share "
        "of leaves known to either tree that both classify alike (1 = identical trees). Memory: occmap's node "
        "arrays against OctoMap's `memoryUsage()`. Free voxels: finest-level voxels held free, Bonxai's against "
        "OctoMap's (counted in occmap's tree, which is OctoMap's; Bonxai is not exact: its rays walk other voxels).",
        "",
        "Bonxai walks one ray per end voxel, not per point: `ProbabilisticMap::addHitPoint` queues a point's "
        "voxel for a ray only when the voxel has not been updated in this scan yet (`update_id`, "
        "`bonxai_map/src/probabilistic_map.cpp`), then `updateFreeCells` casts one integer line a queued voxel "
        "(5 % of the rays of the Osnabrück scans at 0.2 m, 13 % at 0.1 m). That is OctoMap's `discretize=True` "
        "work (`computeDiscreteUpdate`: one ray per end voxel, to its centre), which occmap also does to the bit; "
        "plain insertion walks every point's ray, as OctoMap's `insertPointCloud` does. Both ratios are given; "
        "where points are sparse (the simulated drive: a voxel a point) the two are the same work. The Bonxai "
        "measured is the newest this machine can fetch (October 2025), before its pull request #61 (July 2026) "
        "fixed the update gate's aliasing (a cell last updated exactly 3n scans earlier skipped, with its ray) and "
        "its lines' under-carving: it does less than OctoMap's work.",
        "",
        f"Targets: occmap on one core at least as fast as Bonxai on one (Bonxai's time / occmap's ≥ "
        f"{PER_CORE_TARGET:g}), two threads ≥ {TWO_THREADS_TARGET:g}× one core, `discretize=True` no slower than "
        "plain insertion (as in OctoMap, which casts one ray per end voxel); against OctoMap, insertion ≥ 10×, "
        "agreement ≥ 0.999, memory ≤ OctoMap's.",
        "",
        "| dataset | resolution (m) | max range (m) | occmap, 2 threads (points/s) | occmap, one core (points/s) "
        "| occmap, one core, `discretize=True` (points/s) "
        "| Bonxai, one core (points/s) | Bonxai time / occmap one-core time "
        "| Bonxai time / occmap one-core `discretize=True` time | 2 threads / one core "
        "| free voxels Bonxai / OctoMap | plain / `discretize=True` time (2 threads) | targets | OctoMap (points/s) | speed-up vs OctoMap "
        "| nodes occmap / OctoMap | agreement | memory occmap / OctoMap (MiB) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|",
    ]
    lines += [row_line(row, args.bonxai is None) for row in rows]
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
    lines += drive_lines(100 if args.quick else 800, 0.2)
    print(lines[-1])
    if not args.no_write and not args.quick:
        write_section("bench_octree", "\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
