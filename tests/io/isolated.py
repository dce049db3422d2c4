"""Run readers in child processes with a memory and a time limit (see ``read_worker.py``)."""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

WORKER = Path(__file__).with_name("read_worker.py")


def run_readers(cases, *, memory: int = 1 << 30, seconds: float = 10.0) -> list[tuple[str, str, str, str]]:
    """``(reader, path, outcome, detail)`` for each ``(reader, path)`` case, in order; many cases
    share one child process. A child that dies (a signal, the memory limit hit in C code) marks
    the case it was on as ``died`` and the remaining cases go on in a new child."""
    cases = [(reader, str(path)) for reader, path in cases]
    results = []
    while len(results) < len(cases):
        rest = cases[len(results):]
        with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as f:
            json.dump({"memory": memory, "seconds": seconds, "cases": rest}, f)
        try:
            proc = subprocess.run(
                [sys.executable, str(WORKER), f.name], capture_output=True, text=True,
                timeout=60 + seconds * len(rest),
            )
        finally:
            Path(f.name).unlink()
        done = [tuple(json.loads(line)) for line in proc.stdout.splitlines() if line.startswith("[")]
        results += done
        if len(done) < len(rest):
            reader, path = rest[len(done)]
            results.append((reader, path, "died", f"exit {proc.returncode}: {proc.stderr[-2000:]}"))
    return results


def outcome(reader, path, **kw) -> str:
    """The outcome of one case (``ok``, ``error``, ...; a crash comes with its traceback)."""
    (_, _, result, detail), = run_readers([(reader, path)], **kw)
    return result if result != "crash" else f"crash\n{detail}"
