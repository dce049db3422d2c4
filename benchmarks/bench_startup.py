"""What a user waits for before any work: ``import occmap``, a command's start with compiled
kernels, and a fresh clone's ``make demo``.

Each row runs in a fresh process (wall time of the whole process, medians of alternating rounds,
after one unmeasured run so that bytecode, compiled kernels and the file cache are warm):

* ``import occmap``, beside the bare interpreter and Numba's own floor: a fresh process that
  calls one trivial kernel from Numba's cache (importing Numba, which imports SciPy's linear
  algebra, and setting up its compiler's registries);
* ``occmap info fr_079.bt`` and ``occmap map3d scan.dat`` (OctoMap's sample files), and the same
  commands on a two-point file: that time is the command's fixed cost (interpreter, imports,
  loading the kernels it uses);
* OctoMap on the same work in a fresh process. The octomap-python wheel ships no command-line
  tools (OctoMap's ``graph2tree`` and the like are not in it), so its Python binding runs the
  same steps: read the ``.bt`` and report its size, leaves, bounds, memory and volume (info); read
  the points with NumPy, insert them, write the ``.bt`` (map3d);
* once, a fresh clone's ``make demo`` (a new ``.venv``, every kernel compiled by ``occmap
  warmup``, then the demo), unless ``--no-clone``.

    python benchmarks/bench_startup.py [--rounds N] [--no-clone] [--no-write]
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import ROOT, write_section  # noqa: E402

from occmap._data import find_shared_data  # noqa: E402

BIN = Path(sys.executable).parent
#: As a user runs: bytecode written and reused.
ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}

NUMBA_FLOOR = """
import sys
sys.path.insert(0, sys.argv[1])
import numpy as np
from trivial import twice
twice(np.ones(3))
"""
TRIVIAL_KERNEL = """
from numba import njit

@njit(cache=True)
def twice(a):
    return 2.0 * a
"""
OCTOMAP_INFO = """
import sys, octomap
t = octomap.OcTree(0.1)
t.readBinary(sys.argv[1].encode())
print(t.size(), t.getNumLeafNodes(), t.getMetricMin(), t.getMetricMax(), t.memoryUsage(), t.volume())
"""
OCTOMAP_MAP3D = """
import bz2, sys, numpy as np, octomap
with bz2.open(sys.argv[1], "rt") as f:
    points = np.loadtxt(f, dtype=np.float64)
t = octomap.OcTree(0.1)
t.insertPointCloud(points, np.zeros(3))
t.writeBinary(sys.argv[2].encode())
"""


def _seconds(argv) -> float:
    t0 = time.perf_counter()
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=ENV)
    return time.perf_counter() - t0


def median_runs(commands: dict[str, list[str]], rounds: int) -> dict[str, float]:
    """Median wall seconds of each command in a fresh process, in alternating rounds."""
    for argv in commands.values():
        _seconds(argv)
    runs = {name: [] for name in commands}
    for _ in range(rounds):
        for name, argv in commands.items():
            runs[name].append(_seconds(argv))
    return {name: statistics.median(r) for name, r in runs.items()}


def fresh_clone_demo(data: Path | None) -> tuple[float, str, str]:
    """Seconds of ``make demo`` in a fresh clone of this checkout's last commit, and the lines in
    which warmup and the demo report their own time."""
    with tempfile.TemporaryDirectory(prefix="occmap-clone-") as tmp:
        clone = Path(tmp) / "occmap"
        subprocess.run(["git", "clone", "--quiet", str(ROOT), str(clone)], check=True)
        env = dict(ENV, **({"OCCMAP_DATA": str(data)} if data else {}))
        t0 = time.perf_counter()
        out = subprocess.run(["make", "demo"], cwd=clone, check=True, capture_output=True, text=True, env=env).stdout
        seconds = time.perf_counter() - t0
        warm = re.search(r"warm: (\d+ kernels compiled in \S+ s)", out)
        demo = re.search(r"done in (\S+ s)", out)
        return seconds, warm.group(1) if warm else "?", demo.group(1) if demo else "?"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--no-clone", action="store_true", help="skip the fresh clone's make demo (minutes)")
    ap.add_argument("--no-write", action="store_true", help="print only; leave BENCHMARKS.md alone")
    args = ap.parse_args()
    data = find_shared_data(ROOT)
    if data is None:
        print("shared data not found: the OctoMap sample files are needed", file=sys.stderr)
        return 1
    bt, scan = data / "octomap" / "fr_079.bt", data / "octomap" / "scan.dat.bz2"
    py, occmap = str(BIN / "python"), str(BIN / "occmap")
    with tempfile.TemporaryDirectory(prefix="occmap-startup-") as tmp:
        tmp = Path(tmp)
        (tmp / "two.xyz").write_text("1 0 0\n0 2 0\n")
        (tmp / "trivial.py").write_text(TRIVIAL_KERNEL)
        subprocess.run([occmap, "map3d", str(tmp / "two.xyz"), "-o", str(tmp / "two.bt")], check=True,
                       stdout=subprocess.DEVNULL, env=ENV)
        t = median_runs({
            "python": [py, "-c", "pass"],
            "import": [py, "-c", "import occmap"],
            "numba": [py, "-c", NUMBA_FLOOR, str(tmp)],
            "info": [occmap, "info", str(bt)],
            "info two": [occmap, "info", str(tmp / "two.bt")],
            "octomap info": [py, "-c", OCTOMAP_INFO, str(bt)],
            "map3d": [occmap, "map3d", str(scan), "-o", str(tmp / "scan.bt")],
            "map3d two": [occmap, "map3d", str(tmp / "two.xyz"), "-o", str(tmp / "two.bt")],
            "octomap map3d": [py, "-c", OCTOMAP_MAP3D, str(scan), str(tmp / "octomap.bt")],
        }, args.rounds)
    for name, s in t.items():
        print(f"{name:>14}: {s:.3f} s")
    lines = [
        "## Start-up: import, a command's fixed cost, a fresh clone's demo",
        "",
        f"Wall time of a fresh process, median of {args.rounds} alternating rounds after one unmeasured run "
        "(bytecode and compiled kernels warm, as after `make`). The two-point rows are each command's fixed "
        "cost. OctoMap's rows run its Python binding in a fresh process (the octomap-python wheel ships no "
        "command-line tools): info reads the `.bt` and reports size, leaves, bounds, memory and volume (not "
        "occupied counts); map3d reads the points with NumPy, inserts them and writes the `.bt`. "
        "Targets: `import occmap` ≤ 0.3 s, a command's fixed cost ≤ 1 s. On this shared two-core machine "
        "the figures swing by tens of per cent between runs.",
        "",
        "| what | occmap (s) | OctoMap (s) |",
        "|---|---:|---:|",
        f"| `python -c pass` (the interpreter alone) | {t['python']:.2f} | |",
        f"| `import occmap` | {t['import']:.2f} | |",
        f"| one trivial cached Numba kernel (Numba's floor: its import, SciPy's linear algebra, its registries) | "
        f"{t['numba']:.2f} | |",
        f"| `occmap info fr_079.bt` ({bt.stat().st_size / 2**20:.1f} MiB, 1.8 M nodes) | {t['info']:.2f} | "
        f"{t['octomap info']:.2f} |",
        f"| `occmap info` on a two-point tree (fixed cost) | {t['info two']:.2f} | |",
        f"| `occmap map3d scan.dat.bz2` at 0.1 m (88,206 points) | {t['map3d']:.2f} | {t['octomap map3d']:.2f} |",
        f"| `occmap map3d` on a two-point file (fixed cost) | {t['map3d two']:.2f} | |",
    ]
    if not args.no_clone:
        demo, warm, run = fresh_clone_demo(data)
        print(f"fresh clone make demo: {demo:.0f} s (warmup: {warm}; demo: {run})")
        lines += ["", f"A fresh clone's `make demo` (new `.venv`, packages from the local pip cache, every kernel "
                  f"compiled once by `occmap warmup`, then the demo): **{demo // 60:.0f} min {demo % 60:.0f} s** in "
                  f"all; warmup {warm}, the demo itself then {run} (3 min 22 s in all before `occmap warmup`, "
                  "when the demo compiled its kernels as it went)."]
    if not args.no_write:
        write_section("bench_startup", "\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
