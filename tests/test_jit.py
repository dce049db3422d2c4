"""Compiled kernels are never stale: a change to any source recompiles the kernels that use it."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import occmap

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
