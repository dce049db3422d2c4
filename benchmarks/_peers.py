"""Mappers timed in processes of their own (pinned to one CPU, or for occmap on two threads not), fed
the same scans through one file.

**Scan file** (:func:`write_scans`): scans one after another until the end of the file, each as
little-endian float64 ``origin[3]``, int64 ``n``, float64 ``points[n][3]`` (metres, map frame).

**occmap in a process of its own** (:class:`OccmapProcess`): a Python process started with
``NUMBA_NUM_THREADS`` set; on one core with 1 (occmap then runs every kernel on the calling thread)
and its CPU affinity set to one CPU before it runs anything, so that any thread at all shares that
one core. Its two-thread figures come from such a process too (unpinned), so that both are timed
alike: in a process that does nothing else, its caches and allocator its own.

**A native peer** (:func:`run_native`): a program called as ``PROGRAM SCANS RESOLUTION MAX_RANGE
ROUNDS`` (MAX_RANGE ``inf``: none) that inserts every scan, in order, into a fresh map each round
and prints one JSON line ``{"seconds": [per round], "occupied": n, "free": n}``: the seconds of
each round's insertion (reading the file excluded) and the finest-level voxels the last round's
map holds occupied and free. ``bench_octree.py --bonxai`` takes such a program built around
Bonxai's ``ProbabilisticMap``; this repository neither holds nor builds one.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np


def pinned_cpu() -> int:
    """The CPU the one-core runs share: the last one this process may use."""
    return max(os.sched_getaffinity(0))


def write_scans(path: Path, scans) -> None:
    """Write ``scans`` (pairs of points (N, 3) and origin (3,)) as a scan file."""
    with open(path, "wb") as f:
        for points, origin in scans:
            P = np.ascontiguousarray(points, dtype="<f8").reshape(-1, 3)
            f.write(np.asarray(origin, dtype="<f8").reshape(3).tobytes())
            f.write(np.int64(len(P)).astype("<i8").tobytes())
            f.write(P.tobytes())


def read_scans(path: Path) -> list[tuple[np.ndarray, np.ndarray]]:
    """The scans of a scan file, as :func:`write_scans` takes them."""
    data, scans, at = Path(path).read_bytes(), [], 0
    while at < len(data):
        origin = np.frombuffer(data, "<f8", 3, at)
        n = int(np.frombuffer(data, "<i8", 1, at + 24)[0])
        scans.append((np.frombuffer(data, "<f8", 3 * n, at + 32).reshape(n, 3), origin))
        at += 32 + 24 * n
    return scans


def _pin(cpu: int):
    return lambda: os.sched_setaffinity(0, {cpu})


class OccmapProcess:
    """occmap's ``OcTree.insert_point_clouds`` timed in a child process with ``threads`` Numba
    threads, pinned to CPU ``cpu`` unless it is None.

    Each :meth:`seconds` call builds a fresh tree from a scan file, read once while calls name
    it (a file of a name called before is not read again); the first call for a scan file,
    resolution and max range first inserts the first scan into a tree it throws away (so that
    loading compiled kernels stays out of the figures)."""

    def __init__(self, cpu: int | None, threads: int = 1):
        env = {**os.environ, "NUMBA_NUM_THREADS": str(threads)}
        self._child = subprocess.Popen([sys.executable, __file__], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                       text=True, env=env, preexec_fn=None if cpu is None else _pin(cpu))

    def seconds(self, scans: Path, resolution: float, max_range: float, discretize: bool = False) -> float:
        """Seconds to insert the scans of the file ``scans`` into a fresh tree (``max_range`` < 0: none;
        ``discretize``: one ray per end voxel, as ``insert_point_clouds`` takes it)."""
        self._child.stdin.write(json.dumps([str(scans), resolution, max_range, discretize]) + "\n")
        self._child.stdin.flush()
        answer = self._child.stdout.readline()
        if not answer:
            raise RuntimeError(f"the occmap process ended (exit status {self._child.wait()})")
        return float(answer)

    def close(self) -> None:
        self._child.stdin.close()
        self._child.wait()


def _serve() -> None:
    """The child of :class:`OccmapProcess`: one request a line on stdin, seconds a line on stdout."""
    from occmap._threads import free_for_parallel, thread_count
    from occmap.octree import OcTree

    loaded, warm = {}, set()
    for line in sys.stdin:
        path, res, max_range, discretize = json.loads(line)
        if path not in loaded:
            loaded = {path: read_scans(path)}
        scans = loaded[path]
        if (path, res, max_range, discretize) not in warm:
            OcTree(res).insert_point_clouds([scans[0][0]], [scans[0][1]], max_range=max_range, discretize=discretize)
            warm.add((path, res, max_range, discretize))
        if thread_count() >= 2:  # the other mappers' rounds have just ended: wait until occmap sees the cores free
            deadline = time.monotonic() + 1.0
            while not free_for_parallel() and time.monotonic() < deadline:
                time.sleep(0.02)
        tree = OcTree(res)
        t0 = time.perf_counter()
        tree.insert_point_clouds([p for p, _ in scans], [o for _, o in scans], max_range=max_range,
                                 discretize=discretize)
        print(time.perf_counter() - t0, flush=True)


def run_native(program: Path, scans: Path, resolution: float, max_range: float, cpu: int) -> dict:
    """One round of a native peer on CPU ``cpu`` (``max_range`` < 0: none): its JSON answer with
    ``seconds`` a float."""
    limit = "inf" if max_range < 0 else repr(float(max_range))
    out = subprocess.run([str(program), str(scans), repr(float(resolution)), limit, "1"], capture_output=True,
                         text=True, preexec_fn=_pin(cpu))
    if out.returncode:
        raise RuntimeError(f"{program} failed (exit status {out.returncode}): {out.stderr.strip()}")
    answer = json.loads(out.stdout)
    return {**answer, "seconds": answer["seconds"][0]}


if __name__ == "__main__":
    _serve()
