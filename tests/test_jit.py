"""Compiled kernels are never stale: a change to any source recompiles the kernels that use it; and
processes compiling at once keep every kernel's cache index whole."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import threading
from pathlib import Path

from numba.core.caching import IndexDataCacheFile

import occmap
from occmap._jit import cache_lock

CALLER = '''
from ._jit import kernel
from ._probe_callee import value

@kernel
def probe():
    return value() + 1
'''
CALLEE = '''
from ._jit import kernel

@kernel
def value():
    return {v}
'''


def _run(root: Path) -> str:
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_CACHE")}
    env["PYTHONPATH"] = str(root)
    code = "from occmap._probe_caller import probe; import occmap; print(occmap.__file__, probe())"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert out.returncode == 0, out.stderr
    return out.stdout.split()


def test_a_kernel_recompiles_when_a_kernel_it_calls_from_another_file_changes(tmp_path):
    package = tmp_path / "occmap"
    shutil.copytree(Path(occmap.__file__).parent, package, ignore=shutil.ignore_patterns("__pycache__"))
    (package / "_probe_caller.py").write_text(CALLER)
    (package / "_probe_callee.py").write_text(CALLEE.format(v=1))
    where, first = _run(tmp_path)
    assert Path(where).parent == package and first == "2"
    cached = list((package / "__pycache__").glob("occmap-*/_probe_caller.probe-*.nbi"))
    assert len(cached) == 1, "the kernel was not cached, or not in its version's folder"
    (package / "_probe_callee.py").write_text(CALLEE.format(v=41))  # the caller's own file is unchanged
    assert _run(tmp_path)[1] == "42"
    # the new version's kernels live in a folder of their own; the old version's folder is gone
    now = list((package / "__pycache__").glob("occmap-*/_probe_caller.probe-*.nbi"))
    assert len(now) == 1 and now[0].parent != cached[0].parent


def test_a_kernel_saved_while_another_process_adds_to_its_index_keeps_both_entries(tmp_path):
    # Numba reads a kernel's index, picks the next free data file and writes both back: interleaved
    # with another process doing the same, both signatures got one data file, the index one of them.
    folder = tmp_path / ("occmap-" + "0" * 16)
    folder.mkdir()
    mine, other = (IndexDataCacheFile(str(folder), "kernel-1.py311", "stamp") for _ in range(2))
    with cache_lock(str(folder)):  # the other process, between reading the index and writing it
        index = other._load_index()
        saving = threading.Thread(target=mine.save, args=(("sig-a",), b"a"))
        saving.start()
        saving.join(0.5)
        index[("sig-b",)] = other._data_name(1)
        other._save_index(index)
        other._save_data(index[("sig-b",)], b"b")
    saving.join()
    assert mine.load(("sig-a",)) == b"a" and mine.load(("sig-b",)) == b"b"
