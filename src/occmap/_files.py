"""File helpers shared by every writer: :func:`write_atomic`."""

from __future__ import annotations

import errno
import fcntl
import os
import stat
import tempfile
from pathlib import Path

#: Ending of the temporary files of :func:`write_atomic` (``.<target name>.<random>`` before it).
TEMP_SUFFIX = ".occmap-tmp"


def write_atomic(path, data: bytes) -> Path:
    """Replace the file at ``path`` by ``data``, all or nothing; returns ``path``.

    * The data goes to a temporary file ``.<name>.<random>.occmap-tmp`` in the target's folder,
      flushed to disk, renamed over the target, and the folder is flushed after the rename: a
      kill or a crash at any moment leaves the old file or the new one, never a mix or half of
      one.
    * Through a symbolic link the link's target is replaced (the link stays a link).
    * A file that exists keeps its permission bits; a new one gets ``0o666`` less the umask, as
      ``open()`` would give it.
    * Temporary files that killed writes of the same target left behind are deleted by the next
      successful write. A write holds an exclusive ``flock`` on its temporary file until the
      rename, so only files no live process holds are deleted (a write started at that very
      instant, between creating its file and locking it, may lose it and fail: concurrent writes
      of one file race anyway, the last rename wins).
    """
    path = Path(path)
    target = Path(os.path.realpath(path))
    folder = target.parent
    folder.mkdir(parents=True, exist_ok=True)
    try:
        mode = stat.S_IMODE(os.stat(target).st_mode)
    except FileNotFoundError:
        mode = 0o666 & ~_umask()
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=TEMP_SUFFIX, dir=folder)
    try:
        with os.fdopen(fd, "wb") as handle:
            fcntl.flock(handle.fileno(), fcntl.LOCK_EX)
            os.fchmod(handle.fileno(), mode)  # mkstemp makes the file private (0600)
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
            os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    _fsync_folder(folder)
    _sweep(folder, target.name)
    return path


def _fsync_folder(folder: Path) -> None:
    """Flush the folder's entries (the rename) to disk, where the file system allows it."""
    fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    except OSError as e:  # some file systems cannot sync a folder
        if e.errno not in (errno.EINVAL, errno.ENOTSUP, errno.EBADF):
            raise
    finally:
        os.close(fd)


def _sweep(folder: Path, name: str) -> None:
    """Delete the temporary files of earlier writes of ``folder/name`` that no process holds."""
    prefix = f".{name}."
    with os.scandir(folder) as entries:
        stale = [e.path for e in entries if e.name.startswith(prefix) and e.name.endswith(TEMP_SUFFIX)]
    for tmp in stale:
        try:
            fd = os.open(tmp, os.O_RDONLY | os.O_NOFOLLOW)
        except OSError:
            continue  # gone already, or not ours to open
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            continue  # a live write holds it
        try:
            if os.path.samestat(os.fstat(fd), os.lstat(tmp)):
                os.unlink(tmp)
        except OSError:
            pass
        finally:
            os.close(fd)


def _umask() -> int:
    """The process's umask, read without changing it where Linux allows (``os.umask`` sets it
    for every thread for a moment)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except OSError:
        pass
    mask = os.umask(0)
    os.umask(mask)
    return mask
