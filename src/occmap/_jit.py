"""The Numba decorators every kernel module uses, and where their compiled code is kept.

``cache=True`` keeps compiled code between runs; ``error_model="numpy"`` makes a division by zero
give inf/NaN (caught by the kernels' own checks) instead of raising inside a loop; ``nogil=True``
lets Python threads run kernels side by side. No fastmath: the kernels' NaN checks must survive
compilation. Importing this module sets up the threading layer first (see :mod:`occmap._threads`).

Numba checks a cached kernel against its own source file only, yet a kernel has the kernels it
calls from other files compiled into it: after an edit or an upgrade a stale kernel could run
(it once crashed the tests). Here the package's kernels are cached in a folder named after a
digest of all the package's sources (:func:`sources_stamp`), inside the folder Numba would use:
any change anywhere starts an empty one (and removes the folders of other versions), and two
processes running different versions at once never read each other's files.

Several processes may compile the same kernel at once (``occmap warmup``'s workers, Dask workers
on a fresh machine). Numba adds an entry to a kernel's index by reading the index, choosing the
next free data file and writing both back; two processes doing that together both choose the same
data file, and the index then points one signature at the other's machine code. Here those saves
hold an exclusive ``flock`` on the cache folder's ``.lock`` (:func:`cache_lock`).
"""

from __future__ import annotations

import contextlib
import fcntl
import functools
import hashlib
import os
import shutil
from pathlib import Path

from numba import njit
from numba.core.caching import (CacheImpl, IndexDataCacheFile, InTreeCacheLocator, UserProvidedCacheLocator,
                                 UserWideCacheLocator)

from ._threads import prefer_tbb

prefer_tbb()

_PACKAGE = __name__.split(".")[0]
_PACKAGE_DIR = Path(__file__).resolve().parent


@functools.cache
def sources_stamp() -> str:
    """SHA-256 of every ``.py`` file of the package (names and contents), once per process."""
    digest = hashlib.sha256()
    for path in sorted(_PACKAGE_DIR.rglob("*.py")):
        digest.update(str(path.relative_to(_PACKAGE_DIR)).encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()


_FOLDER_PREFIX = f"{_PACKAGE}-"


class _PackageStamp:
    """A cache locator of Numba's, for this package's kernels only: their cache folder is named
    after :func:`sources_stamp`, which is also their stamp."""

    def get_source_stamp(self):
        return sources_stamp()

    def get_cache_path(self):
        return os.path.join(super().get_cache_path(), _FOLDER_PREFIX + sources_stamp()[:16])

    def ensure_cache_path(self):
        path = self.get_cache_path()
        if not os.path.isdir(path):  # a new version: the other versions' kernels go
            parent = os.path.dirname(path)
            for name in os.listdir(parent) if os.path.isdir(parent) else ():
                if name.startswith(_FOLDER_PREFIX):
                    shutil.rmtree(os.path.join(parent, name), ignore_errors=True)
        super().ensure_cache_path()

    @classmethod
    def from_function(cls, py_func, py_file):
        if py_func.__module__.split(".")[0] != _PACKAGE:
            return None
        return super().from_function(py_func, py_file)


CacheImpl._locator_classes = [
    *(type(f"Package{base.__name__}", (_PackageStamp, base), {})
      for base in (UserProvidedCacheLocator, InTreeCacheLocator, UserWideCacheLocator)),
    *CacheImpl._locator_classes,
]


@contextlib.contextmanager
def cache_lock(folder: str):
    """Held while a kernel is added to the cache folder ``folder``: an exclusive ``flock`` on its
    ``.lock`` file, which waits for another process's."""
    fd = os.open(os.path.join(folder, ".lock"), os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # releases the flock


def _save_locked(self, key, data, _save=IndexDataCacheFile.save):
    if not os.path.basename(self._cache_path).startswith(_FOLDER_PREFIX):
        return _save(self, key, data)
    with cache_lock(self._cache_path):  # Numba's save reads the index again, under the lock
        return _save(self, key, data)


IndexDataCacheFile.save = _save_locked

kernel = njit(cache=True, error_model="numpy", nogil=True)
kernel_parallel = njit(cache=True, error_model="numpy", nogil=True, parallel=True)

#: For small helpers that take arrays and run in hot loops: Numba inlines them into each caller
#: (a call passing arrays costs ~25 ns of reference counting, more than such a helper's work).
inline_kernel = njit(cache=True, error_model="numpy", nogil=True, inline="always")

#: For hot kernels that allocate nothing (their scratch comes from the caller) and return no
#: arrays: compiled without Numba's reference counting. Where an inlined helper that takes an
#: array branches, Numba's pruning of the counts leaves an atomic count and release around it, a
#: call each; in applying a scan's updates they took a tenth of the time.
kernel_without_refcounts = njit(cache=True, error_model="numpy", nogil=True, _nrt=False)
