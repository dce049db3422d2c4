"""Atomic writes leave complete files with ordinary permissions, through links, with the folder
synced and no temporary files of killed writes left (the kills themselves:
tests/io/test_killed_writes.py)."""

from __future__ import annotations

import fcntl
import os
import stat

from occmap._files import TEMP_SUFFIX, write_atomic


def test_write_atomic_replaces_whole_and_uses_the_umask_mode(tmp_path):
    target = tmp_path / "sub" / "map.pgm"
    write_atomic(target, b"old")
    write_atomic(target, b"new contents")
    assert target.read_bytes() == b"new contents"
    assert [p.name for p in target.parent.iterdir()] == ["map.pgm"]  # no temporary file left behind
    mask = os.umask(0)
    os.umask(mask)
    assert stat.S_IMODE(target.stat().st_mode) == 0o666 & ~mask


def test_write_through_a_symlink_replaces_the_target_and_keeps_the_link(tmp_path):
    real = tmp_path / "real" / "map.pgm"
    real.parent.mkdir()
    real.write_bytes(b"old")
    link = tmp_path / "link.pgm"
    link.symlink_to(real)
    assert write_atomic(link, b"new") == link
    assert link.is_symlink() and os.readlink(link) == str(real)
    assert real.read_bytes() == b"new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link.pgm", "real"]
    assert [p.name for p in real.parent.iterdir()] == ["map.pgm"]
    dangling = tmp_path / "dangling.pgm"
    dangling.symlink_to(tmp_path / "made.pgm")
    write_atomic(dangling, b"made")
    assert dangling.is_symlink() and (tmp_path / "made.pgm").read_bytes() == b"made"


def test_permissions_of_a_replaced_file_are_kept(tmp_path):
    target = tmp_path / "map.yaml"
    target.write_bytes(b"old")
    for mode in (0o600, 0o640, 0o755):
        target.chmod(mode)
        write_atomic(target, b"new")
        assert stat.S_IMODE(target.stat().st_mode) == mode


def test_folder_is_synced_after_the_rename(tmp_path, monkeypatch):
    synced = []
    real_fsync = os.fsync

    def spy(fd):
        st = os.fstat(fd)
        synced.append("folder" if stat.S_ISDIR(st.st_mode) else "file")
        if stat.S_ISDIR(st.st_mode):
            assert (tmp_path / "m.pgm").read_bytes() == b"x"  # after the rename
        return real_fsync(fd)

    monkeypatch.setattr(os, "fsync", spy)
    write_atomic(tmp_path / "m.pgm", b"x")
    assert synced == ["file", "folder"]


def test_stale_temporary_files_are_swept_but_not_live_ones(tmp_path):
    target = tmp_path / "map.pgm"
    stale = tmp_path / f".map.pgm.abc123{TEMP_SUFFIX}"
    stale.write_bytes(b"half a file")
    live = tmp_path / f".map.pgm.xyz789{TEMP_SUFFIX}"
    live.write_bytes(b"being written")
    other = tmp_path / f".other.pgm.abc123{TEMP_SUFFIX}"
    other.write_bytes(b"another target's")
    with open(live, "rb") as held:
        fcntl.flock(held.fileno(), fcntl.LOCK_EX)  # as a running write holds it
        write_atomic(target, b"new")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["map.pgm", live.name, other.name])
    write_atomic(target, b"newer")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["map.pgm", other.name])
