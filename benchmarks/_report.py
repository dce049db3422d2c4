"""Shared helpers for the benchmark scripts: robust timing, machine facts, and BENCHMARKS.md sections."""

from __future__ import annotations

import datetime
import os
import platform
import re
import statistics
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BENCHMARKS_MD = ROOT / "BENCHMARKS.md"


def round_times(fns, number: int, repeat: int = 9) -> list[list[float]]:
    """Seconds per call of each function in ``fns`` in each of ``repeat`` alternating rounds.

    Each round times every function once (``number`` calls each), so a noisy stretch of a shared
    machine hits all of them alike and their ratios stay meaningful.
    """
    for fn in fns:
        fn()  # warm-up: JIT compilation and first-touch allocation stay out of the figures
    runs = [[] for _ in fns]
    for _ in range(repeat):
        for fn, out in zip(fns, runs):
            t0 = time.perf_counter()
            for _ in range(number):
                fn()
            out.append((time.perf_counter() - t0) / number)
    return runs


def median_times(fns, number: int, repeat: int = 9) -> list[float]:
    """Median seconds per call of each function in ``fns``, timed in alternating rounds
    (:func:`round_times`)."""
    return [statistics.median(r) for r in round_times(fns, number, repeat)]


@contextmanager
def competing_process():
    """Another program keeping one core busy while the block runs (a robot's computer runs more
    than the mapper)."""
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        time.sleep(0.3)
        yield
    finally:
        busy.kill()
        busy.wait()


def one_thread(fn):
    """``fn`` run with Numba, and so every occmap kernel and worker pool, limited to one thread."""
    import numba

    def run():
        threads = numba.get_num_threads()
        numba.set_num_threads(1)
        try:
            return fn()
        finally:
            numba.set_num_threads(threads)

    return run


def per_call_table(cases, number: int, repeat: int = 9) -> str:
    """Markdown rows timing each ``(label, fn)`` (one call = one scan, as a robot streams) with
    occmap's default threads and on one thread, on an idle machine and beside a competing process;
    the last column is the one-thread time over the default's under competition (≥ 1: the
    default is never the slower)."""
    import numba

    lines = [f"| per call | idle, {numba.get_num_threads()} threads | idle, one thread | busy, "
             f"{numba.get_num_threads()} threads | busy, one thread | busy: one thread / default |",
             "|---|---:|---:|---:|---:|---:|"]
    for label, fn in cases:
        idle = median_times([fn, one_thread(fn)], number, repeat)
        with competing_process():
            busy = median_times([fn, one_thread(fn)], number, repeat)
        cells = [f"{t * 1e3:.3f} ms" for t in (*idle, *busy)]
        lines.append(f"| {label} | " + " | ".join(cells) + f" | {busy[1] / busy[0]:.2f}× |")
    return "\n".join(lines)


def machine() -> str:
    """One line naming the CPU, cores, Python and the numeric libraries in this run."""
    import numba
    import numpy
    import scipy

    cpu = platform.processor() or "unknown CPU"
    try:
        text = Path("/proc/cpuinfo").read_text()
        cpu = re.search(r"model name\s*:\s*(.+)", text).group(1).strip()
    except (OSError, AttributeError):
        pass
    return (
        f"{cpu}, {os.cpu_count()} cores; Python {platform.python_version()}, NumPy {numpy.__version__}, "
        f"Numba {numba.__version__}, SciPy {scipy.__version__}"
    )


def publish(name: str, body: str, write: bool = True) -> None:
    """Write the section ``name`` of BENCHMARKS.md (:func:`write_section`), or only print it."""
    if write:
        write_section(name, body)
    else:
        print(body)


def write_section(name: str, body: str) -> None:
    """Replace (or append) the section of BENCHMARKS.md between the markers for ``name``."""
    start, end = f"<!-- {name}:start -->", f"<!-- {name}:end -->"
    stamp = datetime.date.today().isoformat()
    block = f"{start}\n{body.rstrip()}\n\n_Measured {stamp} on {machine()}._\n{end}"
    text = BENCHMARKS_MD.read_text() if BENCHMARKS_MD.exists() else "# Benchmarks\n\nRun with `make bench`; each script rewrites its own section.\n"
    if start in text and end in text:
        text = text[: text.index(start)] + block + text[text.index(end) + len(end):]
    else:
        text = text.rstrip() + "\n\n" + block + "\n"
    tmp = BENCHMARKS_MD.with_suffix(".md.tmp")
    tmp.write_text(text)
    tmp.replace(BENCHMARKS_MD)


def grids_side_by_side(path: Path, grids, gap: int = 20, crop=True) -> None:
    """The labelled figures of 2D grids (``grid.save_png(title=..., crop=crop)``) for ``(title,
    grid)`` pairs, side by side on white into ``path``."""
    import tempfile

    from PIL import Image

    with tempfile.TemporaryDirectory() as tmp:
        pictures = [Image.open(grid.save_png(Path(tmp) / f"{k}.png", title, crop)).convert("RGB")
                    for k, (title, grid) in enumerate(grids)]
    canvas = Image.new("RGB", (sum(p.width for p in pictures) + gap * (len(pictures) - 1),
                               max(p.height for p in pictures)), (255, 255, 255))
    x = 0
    for p in pictures:
        canvas.paste(p, (x, 0))
        x += p.width + gap
    path.parent.mkdir(parents=True, exist_ok=True)
    canvas.save(path)


def shared_data() -> Path | None:
    """``../shared/data`` (or ``$OCCMAP_DATA``); None, after saying so, when it is not there."""
    from occmap._data import find_shared_data

    data = find_shared_data(ROOT)
    if data is None:
        print("shared data not found (../shared/data or $OCCMAP_DATA): nothing to measure", file=sys.stderr)
    return data
