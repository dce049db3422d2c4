"""Geometry core against scipy.spatial.transform, in the same process.

Two regimes: one element per call (µs per call: Python overhead dominates) and N = 10⁶ elements
per call (ns per element: memory traffic dominates). Each row times occmap and the scipy call a
user would write for the same job, reports medians over 7 runs and the speed-up (scipy time /
occmap time), and checks the issue's targets. Writes the table to BENCHMARKS.md.

    python benchmarks/bench_geometry.py [--n 1000000] [--no-write]
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.spatial.transform import RigidTransform, Rotation, Slerp

sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parent))
from _report import median_times, write_section  # noqa: E402

from occmap import geometry as g  # noqa: E402


@dataclass
class Row:
    name: str
    ours: Callable[[dict], Callable[[], object]]
    peer: Callable[[dict], Callable[[], object]]
    target_ns: float | None = None  # per element at N = 10⁶


def data(n: int, seed: int = 0) -> dict:
    """Inputs for one regime: single elements when n == 1 (shapes without the batch axis)."""
    rng = np.random.default_rng(seed)
    m = max(n, 2)
    q = rng.standard_normal((m + 1, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    R = g.quat_to_matrix(q)
    ypr = rng.uniform(-1.5, 1.5, (m, 3))
    rv = g.log_so3(R)
    xi = np.concatenate([rng.standard_normal((m + 1, 3)), rv], axis=1)
    T = g.exp_se3(xi)
    pts = rng.standard_normal((m, 3))
    one = (lambda a: a[0]) if n == 1 else (lambda a: a[:n])
    d = dict(
        q=one(q), q2=one(q[1:]), R=one(R), y=one(ypr[:, 0]), p=one(ypr[:, 1]), r=one(ypr[:, 2]), ypr=one(ypr),
        rv=one(rv), xi=one(xi), T=one(T), T2=one(T[1:]), pts=one(pts), q0=q[0], T0=T[0], t=0.3,
    )
    d["rot"] = Rotation.from_quat(d["q"], scalar_first=True)
    d["rot2"] = Rotation.from_quat(d["q2"], scalar_first=True)
    d["rot0"] = Rotation.from_quat(q[0], scalar_first=True)
    d["tf"] = RigidTransform.from_matrix(d["T"])
    d["tf2"] = RigidTransform.from_matrix(d["T2"])
    d["tf0"] = RigidTransform.from_matrix(T[0])
    keys = q[: n + 1] if n > 1 else q[:2]
    d["slerp_ours"] = (keys[:-1], keys[1:], np.full(len(keys) - 1, 0.3)) if n > 1 else (keys[0], keys[1], 0.3)
    d["slerp_peer"] = (Slerp(np.arange(len(keys)), Rotation.from_quat(keys, scalar_first=True)), np.arange(len(keys) - 1) + 0.3 if n > 1 else 0.3)
    return d


ROWS = [
    Row("quaternion → matrix", lambda d: lambda: g.quat_to_matrix(d["q"]),
        lambda d: lambda: Rotation.from_quat(d["q"], scalar_first=True).as_matrix(), 25),
    Row("matrix → quaternion", lambda d: lambda: g.matrix_to_quat(d["R"]),
        lambda d: lambda: Rotation.from_matrix(d["R"]).as_quat(scalar_first=True), 60),
    Row("compose quaternions", lambda d: lambda: g.quat_multiply(d["q"], d["q2"]),
        lambda d: lambda: d["rot"] * d["rot2"], 25),
    Row("rotate points (one rotation)", lambda d: lambda: g.quat_rotate(d["q0"], d["pts"]),
        lambda d: lambda: d["rot0"].apply(d["pts"]), 12),
    Row("Euler ZYX → matrix", lambda d: lambda: g.euler_zyx_to_matrix(d["y"], d["p"], d["r"]),
        lambda d: lambda: Rotation.from_euler("ZYX", d["ypr"]).as_matrix(), 100),
    Row("matrix → Euler ZYX", lambda d: lambda: g.matrix_to_euler_zyx(d["R"]),
        lambda d: lambda: Rotation.from_matrix(d["R"]).as_euler("ZYX")),
    Row("rotation vector → matrix (exp)", lambda d: lambda: g.exp_so3(d["rv"]),
        lambda d: lambda: Rotation.from_rotvec(d["rv"]).as_matrix()),
    Row("matrix → rotation vector (log)", lambda d: lambda: g.log_so3(d["R"]),
        lambda d: lambda: Rotation.from_matrix(d["R"]).as_rotvec()),
    Row("slerp", lambda d: lambda: g.quat_slerp(*d["slerp_ours"]),
        lambda d: lambda: d["slerp_peer"][0](d["slerp_peer"][1])),
    Row("transform points (one SE3)", lambda d: lambda: g.transform_points(d["T0"], d["pts"]),
        lambda d: lambda: d["tf0"].apply(d["pts"])),
    Row("compose SE3", lambda d: lambda: g.compose_transforms(d["T"], d["T2"]),
        lambda d: lambda: d["tf"] * d["tf2"]),
    Row("invert SE3", lambda d: lambda: g.invert_transform(d["T"]),
        lambda d: lambda: d["tf"].inv()),
    Row("twist → SE3 (exp)", lambda d: lambda: g.exp_se3(d["xi"]),
        lambda d: lambda: RigidTransform.from_exp_coords(d["xi"]).as_matrix()),
]

SINGLE_TARGET_US = 3.0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1_000_000, help="batch size of the large regime")
    ap.add_argument("--no-write", action="store_true", help="print only, leave BENCHMARKS.md alone")
    args = ap.parse_args()

    single, large = data(1), data(args.n)
    lines = [
        f"| operation | occmap 1 call (µs) | scipy 1 call (µs) | speed-up | occmap N={args.n:,} (ns/elem) "
        "| scipy (ns/elem) | speed-up | target (ns/elem) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    misses = []
    print(f"{'operation':32s} {'ours µs':>8s} {'scipy µs':>9s} {'×':>6s} {'ours ns':>8s} {'scipy ns':>9s} {'×':>6s}")
    for row in ROWS:
        o1, p1 = (t * 1e6 for t in median_times([row.ours(single), row.peer(single)], number=2000))
        oN, pN = (t * 1e9 / args.n for t in median_times([row.ours(large), row.peer(large)], number=1))
        print(f"{row.name:32s} {o1:8.2f} {p1:9.2f} {p1 / o1:6.1f} {oN:8.1f} {pN:9.1f} {pN / oN:6.1f}")
        target = "–" if row.target_ns is None else f"≤ {row.target_ns:g}"
        if row.target_ns is not None and oN > row.target_ns:
            misses.append(f"{row.name}: {oN:.1f} ns/elem > {row.target_ns:g}")
        if o1 > SINGLE_TARGET_US:
            misses.append(f"{row.name}: single call {o1:.2f} µs > {SINGLE_TARGET_US:g}")
        if p1 < o1 or pN < oN:
            misses.append(f"{row.name}: scipy faster")
        lines.append(f"| {row.name} | {o1:.2f} | {p1:.2f} | {p1 / o1:.1f}× | {oN:.1f} | {pN:.1f} | {pN / oN:.1f}× | {target} |")
    summary = "All targets met." if not misses else "Missed: " + "; ".join(misses) + "."
    print(summary)
    if not args.no_write:
        body = (
            "## Geometry core vs scipy.spatial.transform (`benchmarks/bench_geometry.py`)\n\n"
            "Medians of 9 alternating runs; speed-up = scipy time / occmap time, both measured in the same process. "
            f"Targets: single calls ≤ {SINGLE_TARGET_US:g} µs, and the per-element figures in the last column.\n\n"
            + "\n".join(lines) + f"\n\n{summary}"
        )
        write_section("bench_geometry", body)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
