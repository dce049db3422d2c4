"""How much memory a file may make a reader use: one rule for every reader.

A reader never trusts a size the file declares (a point count, an image's width and height, a
node count) nor a compressed stream's promise. What it may produce is bounded by the size of the
file on disk, by one rule: at most :attr:`ReadLimits.expansion` units per byte of the file, and
never less than :attr:`ReadLimits.floor` units, so small files are not held to a tiny budget. A
unit is a byte of decompressed data, or a pixel of an image. With the defaults (100 per byte,
16 MiB floor) a 448 KB ``.log.gz`` may decompress to 44.8 MB (the shared CARMEN logs expand 5 to
10 times), and a 168 KB PNG may hold 16.8 M pixels (a 4096 × 4096 map); a file beyond the rule
raises :class:`~occmap.errors.FormatError` naming it and the limit, before the memory is taken.

Only regular files are read: a FIFO, a device (``/dev/zero``) or a folder is refused, since
their size says nothing and a FIFO blocks forever.

Raise the limits for a file you trust with :func:`read_limits`, a context manager (per thread and
per asyncio task, as a :mod:`contextvars` variable)::

    with occmap.io.read_limits(expansion=2000):
        grid = load_map("huge_map.yaml")
"""

from __future__ import annotations

import contextvars
import os
import stat
from contextlib import contextmanager
from dataclasses import dataclass, replace

from .. import checks
from ..errors import FormatError, MissingFileError

__all__ = ["ReadLimits", "current", "read_limits", "regular_file_size"]


@dataclass(frozen=True)
class ReadLimits:
    """The rule of the module: ``budget(size) = max(expansion · size, floor)`` units."""

    #: Decompressed bytes (or image pixels) allowed per byte of the file on disk.
    expansion: float = 100.0
    #: Units every file may use, however small it is.
    floor: int = 16 << 20

    def budget(self, file_size: int) -> int:
        """Units a file of ``file_size`` bytes may produce."""
        return max(int(self.expansion * file_size), int(self.floor))

    def check(self, path, what: str, units: int, file_size: int, unit: str = "bytes") -> None:
        """Raise FormatError when ``units`` of ``what`` exceed the budget of a ``file_size`` file."""
        budget = self.budget(file_size)
        if units > budget:
            raise FormatError(
                path,
                f"{what} needs {units} {unit}, more than this {file_size}-byte file may ask for "
                f"({budget} {unit}: {self.expansion:g} per byte of the file, at least "
                f"{self.floor}); raise the limit with occmap.io.read_limits() if you trust the file",
            )


_CURRENT: contextvars.ContextVar[ReadLimits] = contextvars.ContextVar("occmap_read_limits", default=ReadLimits())


def current() -> ReadLimits:
    """The limits in force in this thread / task."""
    return _CURRENT.get()


@contextmanager
def read_limits(*, expansion: float | None = None, floor: int | None = None):
    """Within the ``with`` block, readers use these limits (the others stay as they were).

    ``expansion``: units (decompressed bytes, pixels) per byte of the file, > 0; ``floor``: units
    any file may use, >= 0. Yields the :class:`ReadLimits` in force."""
    changes = {}
    if expansion is not None:
        changes["expansion"] = checks.positive("expansion", expansion)
    if floor is not None:
        changes["floor"] = checks.count("floor", floor, minimum=0)
    token = _CURRENT.set(replace(_CURRENT.get(), **changes))
    try:
        yield _CURRENT.get()
    finally:
        _CURRENT.reset(token)


def regular_file_size(path, handle=None) -> int:
    """The size of ``path`` (stat of the open ``handle`` when given); FormatError when it is not
    a regular file (a FIFO, a device, a folder) and FileNotFoundError-free: a missing file is a
    FormatError too."""
    try:
        st = os.fstat(handle.fileno()) if handle is not None else os.stat(path)
    except FileNotFoundError:
        raise MissingFileError(path, "file not found") from None
    except OSError as e:
        raise FormatError(path, f"cannot read the file ({e.strerror or e})") from None
    if not stat.S_ISREG(st.st_mode):
        kind = "a folder" if stat.S_ISDIR(st.st_mode) else "a FIFO" if stat.S_ISFIFO(st.st_mode) else "not a regular file"
        raise FormatError(path, f"cannot read {kind}: only regular files are read")
    return st.st_size
