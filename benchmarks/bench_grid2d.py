"""2D occupancy grid throughput, against the hand-written NumPy mapper users write today.

Rows: 10 m beams at 0.05 m (beams per second; with Numba's default threads, which cut the grid
into strips of rows updated side by side, one per thread, and on one thread), the Intel Research Lab corrected log end
to end after warm-up (default maximum range, and capped at 30 m), and ``occmap map2d`` on that
log from a cold start (a fresh process, reading the file included). On a shared machine the
two-thread figures depend on the second core being free. Then one scan per call, as a robot
streams (3,600 and 360 beams of 2-10 m), with the default threads and on one thread, on an idle
machine and beside a process that keeps one core busy. The peer does the same update
in vectorised NumPy: points sampled every half cell along each beam, cells deduplicated per scan
with ``np.unique``, hits applied after misses. Writes its table to BENCHMARKS.md.

    python benchmarks/bench_grid2d.py [--no-write]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numba
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import ROOT, median_times, per_call_table, write_section  # noqa: E402

from occmap import OccupancyGrid2D  # noqa: E402
from occmap._data import find_shared_data  # noqa: E402
from occmap.grid2d import LidarModel  # noqa: E402
from occmap.io.carmen import read_carmen  # noqa: E402
from occmap.mapping2d import map_scans  # noqa: E402


def numpy_mapper(L, origin, res, poses, ranges, angles, max_range, model=LidarModel(), clamp=(-2.0, 3.5)):
    """The peer: one scan at a time, all beams vectorised (approximate cell sets: sampling)."""
    H, W = L.shape
    step = 0.5 * res
    for pose, r in zip(poses, ranges):
        ok = r > 0
        hit = ok & (r < max_range)
        rr = np.minimum(r[ok], max_range)
        a = pose[2] + angles[ok]
        t = np.arange(0.0, max_range, step)
        inside = t[None, :] < rr[:, None] - step
        px = pose[0] + np.cos(a)[:, None] * t[None, :]
        py = pose[1] + np.sin(a)[:, None] * t[None, :]
        ix = np.floor((px[inside] - origin[0]) / res).astype(np.int64)
        iy = np.floor((py[inside] - origin[1]) / res).astype(np.int64)
        keep = (ix >= 0) & (ix < W) & (iy >= 0) & (iy < H)
        free = np.unique(iy[keep] * W + ix[keep])
        ex = np.floor((pose[0] + r[hit] * np.cos(pose[2] + angles[hit]) - origin[0]) / res).astype(np.int64)
        ey = np.floor((pose[1] + r[hit] * np.sin(pose[2] + angles[hit]) - origin[1]) / res).astype(np.int64)
        keep = (ex >= 0) & (ex < W) & (ey >= 0) & (ey < H)
        hits = np.unique(ey[keep] * W + ex[keep])
        free = np.setdiff1d(free, hits, assume_unique=True)
        flat = L.reshape(-1)
        flat[free] = np.clip(flat[free] + model.l_miss, *clamp)
        flat[hits] = np.clip(flat[hits] + model.l_hit, *clamp)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args()
    rows = []

    rng = np.random.default_rng(0)
    n_scans, n_beams = 100, 360
    poses = np.column_stack([rng.uniform(-5, 5, n_scans), rng.uniform(-5, 5, n_scans), rng.uniform(-np.pi, np.pi, n_scans)])
    angles = np.linspace(-np.pi, np.pi, n_beams, endpoint=False)
    ranges = np.full((n_scans, n_beams), 9.99)

    def ours():
        OccupancyGrid2D(0.05, size=(40, 40), origin=(-20, -20)).insert_scans(poses, ranges, angles, max_range=10.0)

    def ours_one_thread():
        threads = numba.get_num_threads()
        numba.set_num_threads(1)
        try:
            ours()
        finally:
            numba.set_num_threads(threads)

    def peer():
        numpy_mapper(np.zeros((800, 800), np.float32), (-20.0, -20.0), 0.05, poses, ranges, angles, 10.0)

    t_ours, t_one, t_peer = median_times([ours, ours_one_thread, peer], number=1, repeat=9)
    beams = n_scans * n_beams
    rows.append((f"10 m beams at 0.05 m, {numba.get_num_threads()} threads (M beams/s)", beams / t_ours / 1e6,
                 beams / t_peer / 1e6, "≥ 2", True))
    rows.append(("10 m beams at 0.05 m, one thread (M beams/s)", beams / t_one / 1e6, beams / t_peer / 1e6, "–", True))

    data = find_shared_data(ROOT)
    if data is not None:
        log = data / "carmen" / "intel-corrected.log.gz"
        stack = read_carmen(log).stack()
        for cap in (None, 30.0):
            t = median_times([lambda: map_scans(stack, 0.05, cap)], number=1, repeat=7)[0]
            label = "default max range (81 m)" if cap is None else f"max range {cap:g} m"
            rows.append((f"Intel corrected log, 910 scans, {label} (s)", t, None, "≤ 0.3", False))
        with tempfile.TemporaryDirectory() as tmp:
            cmd = [sys.executable, "-m", "occmap", "map2d", str(log), "-o", f"{tmp}/intel.yaml"]
            runs = []
            for _ in range(3):
                t0 = time.perf_counter()
                subprocess.run(cmd, check=True, capture_output=True)
                runs.append(time.perf_counter() - t0)
            rows.append(("`occmap map2d` on the Intel log, cold process (s)", float(np.median(runs)), None, "≤ 5", False))

    def streaming(n_beams):
        grid = OccupancyGrid2D(0.05, size=(40, 40), origin=(-20, -20))
        beam_angles = np.linspace(-np.pi, np.pi, n_beams, endpoint=False)
        scans = np.random.default_rng(1).uniform(2.0, 10.0, (16, n_beams))
        k = [0]

        def call():
            k[0] += 1
            grid.insert_scan((0.01 * (k[0] % 16), 0.0, 0.0), scans[k[0] % 16], beam_angles, max_range=30.0)

        return call

    per_call = per_call_table([(f"{n:,}-beam scan (2-10 m) at 0.05 m", streaming(n)) for n in (3600, 360)], number=20)

    lines = ["| measurement | occmap | NumPy peer | speed-up | target |", "|---|---:|---:|---:|---:|"]
    for name, ours_v, peer_v, target, higher_better in rows:
        if peer_v is None:
            lines.append(f"| {name} | {ours_v:.3g} | – | – | {target} |")
        else:
            ratio = ours_v / peer_v if higher_better else peer_v / ours_v
            lines.append(f"| {name} | {ours_v:.3g} | {peer_v:.3g} | {ratio:.1f}× | {target} |")
    table = "\n".join(lines) + "\n\nOne scan per call:\n\n" + per_call
    print(table)
    if not args.no_write:
        write_section(
            "bench_grid2d",
            "## 2D occupancy grid (`benchmarks/bench_grid2d.py`)\n\nMedians of 9 runs (beams) and 7 runs (Intel "
            "log); the peer is a vectorised NumPy mapper measured in the same run, interleaved with occmap.\n\n"
            + table,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
