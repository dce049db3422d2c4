"""Atomic writes leave complete files with ordinary permissions."""

from __future__ import annotations

import os
import stat

from occmap._files import write_atomic


def test_write_atomic_replaces_whole_and_uses_the_umask_mode(tmp_path):
    target = tmp_path / "sub" / "map.pgm"
    write_atomic(target, b"old")
    write_atomic(target, b"new contents")
    assert target.read_bytes() == b"new contents"
    assert [p.name for p in target.parent.iterdir()] == ["map.pgm"]  # no temporary file left behind
    mask = os.umask(0)
    os.umask(mask)
    assert stat.S_IMODE(target.stat().st_mode) == 0o666 & ~mask
