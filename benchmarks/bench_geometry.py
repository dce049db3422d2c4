"""Geometry core against scipy.spatial.transform, numpy-quaternion and rowan, in the same process.

Two regimes: one element per call (µs per call: Python overhead dominates) and N = 10⁶ elements
per call (ns per element: memory traffic dominates). Each row times occmap and, for every peer
that has the operation, the call a user of that peer would write for the same job, all in
alternating rounds; it reports medians over 9 rounds and the speed-up over the fastest peer (its
time / occmap's), and checks the issue's targets. The calls are written as expressions, as for
``timeit``, so the notes under the table show exactly what ran; inputs are built outside the
timed calls in each library's own types (scipy ``Rotation`` objects, arrays of numpy-quaternion's
``np.quaternion``), as a user holding them would call. Before timing, every peer's result is
compared with occmap's on one element and on a small batch, so each row times one job. Writes
the table to BENCHMARKS.md.

    python benchmarks/bench_geometry.py [--n 1000000] [--no-write]
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import quaternion
import rowan
from scipy.spatial.transform import RigidTransform, Rotation, Slerp

sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parent))
from _report import median_times, write_section  # noqa: E402

from occmap import geometry as g  # noqa: E402

PEERS = ("scipy", "numpy-quaternion", "rowan")


def w_positive(q: np.ndarray) -> np.ndarray:
    """``q`` or ``−q``, whichever has w ≥ 0: one form for the one rotation they are."""
    return np.where(q[..., :1] < 0, -q, q)


@dataclass
class Row:
    name: str
    ours: str
    #: peer → its call; a pair is (one element, batch) where the peer has one call for each
    peers: dict[str, str | tuple[str, str]] = field(default_factory=dict)
    target_ns: float | None = None  # per element at N = 10⁶
    #: maps results to one form before they are compared (q and −q are one rotation, as are
    #: rotation vectors whose angles differ by 2π)
    canonical: Callable[[np.ndarray], np.ndarray] | None = None

    def call(self, peer: str, single: bool) -> str:
        expr = self.ours if peer == "occmap" else self.peers[peer]
        return expr if isinstance(expr, str) else expr[0 if single else 1]


def data(n: int, seed: int = 0) -> dict:
    """The names the calls use, for one regime: single elements when n == 1 (shapes without the
    batch axis), else batches of n."""
    rng = np.random.default_rng(seed)
    m = max(n, 2)
    keys = rng.standard_normal((m + 1, 4))
    keys /= np.linalg.norm(keys, axis=1, keepdims=True)
    # consecutive keys on one hemisphere (q and −q are one rotation): numpy-quaternion's slerp
    # does not take the shorter arc itself, so this way every slerp does the same job
    keys[1:] *= np.cumprod(np.sign(np.sum(keys[:-1] * keys[1:], axis=1)))[:, None]
    R = g.quat_to_matrix(keys)
    rv = g.log_so3(R)
    xi = np.concatenate([rng.standard_normal((m + 1, 3)), rv], axis=1)  # twists (ρ, φ)
    T = g.exp_se3(xi)
    ypr = rng.uniform(-1.5, 1.5, (m, 3))
    one = (lambda a: a[0]) if n == 1 else (lambda a: a[:n])
    d = dict(
        q=one(keys[:-1]), q2=one(keys[1:]), R=one(R), yaw=one(ypr[:, 0]), pitch=one(ypr[:, 1]), roll=one(ypr[:, 2]),
        ypr=one(ypr), rv=one(rv), xi=one(xi), T=one(T[:-1]), T2=one(T[1:]), pts=one(rng.standard_normal((m, 3))),
        q0=keys[0], T0=T[0], t=0.3 if n == 1 else np.full(n, 0.3),
    )
    d["nq"], d["nq2"], d["nq0"] = (quaternion.from_float_array(d[k]) for k in ("q", "q2", "q0"))
    d["rot"], d["rot2"], d["rot0"] = (Rotation.from_quat(d[k], scalar_first=True) for k in ("q", "q2", "q0"))
    d["tf"], d["tf2"], d["tf0"] = (RigidTransform.from_matrix(d[k]) for k in ("T", "T2", "T0"))
    d["xi_scipy"] = d["xi"][..., [3, 4, 5, 0, 1, 2]]  # scipy's exponential coordinates are (φ, ρ)
    d["slerp"] = Slerp(np.arange(n + 1), Rotation.from_quat(keys[: n + 1], scalar_first=True))
    d["times"] = 0.3 if n == 1 else np.arange(n) + 0.3
    return d


ROWS = [
    Row("quaternion → matrix", "g.quat_to_matrix(q)", {
        "scipy": "Rotation.from_quat(q, scalar_first=True).as_matrix()",
        "numpy-quaternion": "quaternion.as_rotation_matrix(nq)",
        "rowan": "rowan.to_matrix(q)"}, 25),
    Row("matrix → quaternion", "g.matrix_to_quat(R)", {
        "scipy": "Rotation.from_matrix(R).as_quat(scalar_first=True)",
        "numpy-quaternion": "quaternion.from_rotation_matrix(R, nonorthogonal=False)",
        "rowan": "rowan.from_matrix(R)"}, 60, w_positive),
    Row("compose quaternions", "g.quat_multiply(q, q2)", {
        "scipy": "rot * rot2",
        "numpy-quaternion": "nq * nq2",
        "rowan": "rowan.multiply(q, q2)"}, 25, w_positive),
    Row("rotate points (one rotation)", "g.quat_rotate(q0, pts)", {
        "scipy": "rot0.apply(pts)",
        "numpy-quaternion": "quaternion.rotate_vectors(nq0, pts)",
        "rowan": "rowan.rotate(q0, pts)"}, 12),
    Row("Euler ZYX → matrix", "g.euler_zyx_to_matrix(yaw, pitch, roll)", {
        "scipy": 'Rotation.from_euler("ZYX", ypr).as_matrix()',
        "rowan": 'rowan.to_matrix(rowan.from_euler(yaw, pitch, roll, "zyx", "intrinsic"))'}, 100),
    Row("matrix → Euler ZYX", "g.matrix_to_euler_zyx(R)", {
        "scipy": 'Rotation.from_matrix(R).as_euler("ZYX")',
        "rowan": 'rowan.to_euler(rowan.from_matrix(R), "zyx", "intrinsic")'}),
    Row("rotation vector → matrix (exp)", "g.exp_so3(rv)", {
        "scipy": "Rotation.from_rotvec(rv).as_matrix()",
        "numpy-quaternion": "quaternion.as_rotation_matrix(quaternion.from_rotation_vector(rv))"}),
    Row("matrix → rotation vector (log)", "g.log_so3(R)", {
        "scipy": "Rotation.from_matrix(R).as_rotvec()",
        "numpy-quaternion": "quaternion.as_rotation_vector(quaternion.from_rotation_matrix(R, nonorthogonal=False))"},
        canonical=g.exp_so3),
    Row("slerp", "g.quat_slerp(q, q2, t)", {
        "scipy": "slerp(times)",
        "numpy-quaternion": ("quaternion.slerp_evaluate(nq, nq2, t)", "np.slerp_vectorized(nq, nq2, t)"),
        "rowan": "rowan.interpolate.slerp(q, q2, t)"}, canonical=w_positive),
    Row("transform points (one SE3)", "g.transform_points(T0, pts)", {"scipy": "tf0.apply(pts)"}),
    Row("compose SE3", "g.compose_transforms(T, T2)", {"scipy": "tf * tf2"}),
    Row("invert SE3", "g.invert_transform(T)", {"scipy": "tf.inv()"}),
    Row("twist → SE3 (exp)", "g.exp_se3(xi)", {"scipy": "RigidTransform.from_exp_coords(xi_scipy).as_matrix()"}),
]

SINGLE_TARGET_US = 3.0


def timed(expr: str, names: dict):
    """``expr`` as a function of no arguments, its names looked up in ``names`` (as timeit does)."""
    return eval(compile(f"lambda: {expr}", expr, "eval"), {**globals(), **names})


def values(result) -> np.ndarray:
    """A result as a float array: rotations as (w, x, y, z), transforms as matrices, tuples of
    arrays stacked on a last axis."""
    if isinstance(result, Rotation):
        return result.as_quat(scalar_first=True)
    if isinstance(result, RigidTransform):
        return result.as_matrix()
    if isinstance(result, tuple):
        return np.stack(result, axis=-1)
    a = np.asarray(result)
    return quaternion.as_float_array(a) if a.dtype == np.quaternion else a


def check(row: Row, names: dict, single: bool) -> None:
    """Raise when a peer's result differs from occmap's (beyond 1e-9) on the inputs ``names``."""
    same = row.canonical or (lambda a: a)
    ours = values(timed(row.ours, names)())
    for peer in row.peers:
        theirs = values(timed(row.call(peer, single), names)()).reshape(ours.shape)
        err = np.abs(same(ours) - same(theirs)).max()
        if not err <= 1e-9:
            raise AssertionError(f"{row.name}: {peer} differs from occmap by {err:.3g}")


def cells(ours: float, peers: dict[str, float], digits: int) -> tuple[list[str], str, str | None]:
    """Table cells of one regime: occmap's figure, each peer's (the fastest in bold, – where the
    peer has no such call), the speed-up over the fastest peer, and that peer when it wins."""
    best = min(peers, key=peers.get)
    row = [f"{ours:.{digits}f}"]
    for peer in PEERS:
        if peer not in peers:
            row.append("–")
        else:
            row.append(f"**{peers[peer]:.{digits}f}**" if peer == best else f"{peers[peer]:.{digits}f}")
    return row, f"{peers[best] / ours:.1f}×", best if peers[best] < ours else None


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1_000_000, help="batch size of the large regime")
    ap.add_argument("--no-write", action="store_true", help="print only, leave BENCHMARKS.md alone")
    args = ap.parse_args()

    for row in ROWS:
        check(row, data(1), single=True)
        check(row, data(5), single=False)

    single, large = data(1), data(args.n)
    peer_cols = " | ".join(PEERS)
    lines = [
        f"| operation | occmap 1 call (µs) | {peer_cols} | speed-up | occmap N={args.n:,} (ns/elem) | {peer_cols} "
        "| speed-up | target (ns/elem) |",
        "|---|" + "---:|" * (2 * (len(PEERS) + 2) + 1),
    ]
    print(lines[0])
    misses = []
    for row in ROWS:
        who = ["occmap", *(p for p in PEERS if p in row.peers)]
        t1 = median_times([timed(row.call(p, True), single) for p in who], number=2000)
        tN = median_times([timed(row.call(p, False), large) for p in who], number=1)
        one, one_up, one_lost = cells(t1[0] * 1e6, {p: t * 1e6 for p, t in zip(who[1:], t1[1:])}, 2)
        big, big_up, big_lost = cells(tN[0] * 1e9 / args.n, {p: t * 1e9 / args.n for p, t in zip(who[1:], tN[1:])}, 1)
        target = "–" if row.target_ns is None else f"≤ {row.target_ns:g}"
        if row.target_ns is not None and tN[0] * 1e9 / args.n > row.target_ns:
            misses.append(f"{row.name}: {big[0]} ns/elem > {row.target_ns:g}")
        if t1[0] * 1e6 > SINGLE_TARGET_US:
            misses.append(f"{row.name}: single call {one[0]} µs > {SINGLE_TARGET_US:g}")
        if one_lost:
            misses.append(f"{row.name}: {one_lost} faster for one call")
        if big_lost:
            misses.append(f"{row.name}: {big_lost} faster at N = {args.n:,}")
        lines.append(f"| {row.name} | " + " | ".join([*one, one_up, *big, big_up, target]) + " |")
        print(lines[-1], flush=True)
    summary = "All targets met; occmap fastest in every row." if not misses else "Missed: " + "; ".join(misses) + "."
    print(summary)
    if not args.no_write:
        calls = "\n".join(
            f"- {row.name}: occmap `{row.ours}`; "
            + "; ".join(f"{p} `{row.call(p, True)}`" + (f" (batches: `{row.call(p, False)}`)" if row.call(p, False) != row.call(p, True) else "")
                        for p in PEERS if p in row.peers)
            for row in ROWS
        )
        body = (
            "## Geometry core vs scipy.spatial.transform, numpy-quaternion and rowan (`benchmarks/bench_geometry.py`)\n\n"
            f"Medians of 9 alternating runs of every library's call, all in one process (numpy-quaternion "
            f"{quaternion.__version__}, rowan {rowan.__version__}); the fastest peer in bold; speed-up = the fastest "
            "peer's time / occmap's; – where a peer has no such operation. "
            f"Targets: single calls ≤ {SINGLE_TARGET_US:g} µs, and the per-element figures in the last column.\n\n"
            + "\n".join(lines) + f"\n\n{summary}\n\n"
            "The calls timed. Names: `q`, `q2` unit quaternions (w, x, y, z), `R` rotation matrices, `yaw`, `pitch`, "
            "`roll` and `ypr` angles, `rv` rotation vectors, `xi` twists (ρ, φ) and `xi_scipy` the same as scipy orders them "
            "(φ, ρ), `T`, `T2` transforms, `pts` points, `q0`, `T0` one quaternion and one transform, `t` = 0.3; `nq…` the "
            "quaternions as numpy-quaternion arrays (`quaternion.from_float_array`), `rot…`, `tf…` as scipy objects, "
            "`slerp` a scipy `Slerp` over the keys `q`, `q2` at `times`; all built before timing. numpy-quaternion's "
            "`from_rotation_matrix` runs with `nonorthogonal=False`, its formula for rotation matrices (the default fits "
            "a quaternion to any matrix by an eigen-decomposition). Every result is checked equal to "
            "occmap's first (quaternions up to sign, rotation vectors as rotations). occmap's single calls go from a C "
            "entry (`geometry/_single.c`) straight to the Numba kernel; numpy-quaternion's product and slerp return its "
            "own scalar type, occmap's functions a NumPy array: one returned before that nothing holds any more is "
            "written again (allocating one took ~45 ns, half of a call).\n\n" + calls
        )
        write_section("bench_geometry", body)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
