"""Input files: regular files only, plain or compressed with gzip, bzip2 or xz (recognised by
their first bytes), decompressed within the limits of :mod:`occmap.io._limits`.

Every reader opens its file here. The *content* decides: a file that starts with a compression
signature (gzip ``1f 8b``, bzip2 ``BZh``, xz ``fd 37 7a 58 5a 00``) is decompressed whatever its
name, and a plain file is read as it is even when named ``.gz``. The *name* only matters when a
file starts with a signature but does not decompress: with a compressed extension
(:data:`EXTENSIONS`) that is a :class:`~occmap.errors.FormatError` (truncated or corrupt), without
one the bytes are taken as they are (a binary scan may begin with those bytes by chance).

A FIFO, a device or a folder is refused (:func:`occmap.io._limits.regular_file_size`), and a stream that decompresses beyond the budget of
:func:`occmap.io.read_limits` (by default 100 bytes per byte of the file, at least 16 MiB) raises
a FormatError as soon as it passes it.
"""

from __future__ import annotations

import bz2
import gzip
import io
import lzma
import zlib
from typing import BinaryIO

from ..errors import FormatError
from . import _limits

__all__ = ["CORRUPT", "EXTENSIONS", "compression", "open_binary", "read_bytes"]

#: Extensions of compressed files (lower case); readers look through them to the format's own.
EXTENSIONS = (".gz", ".bz2", ".xz")

#: What reading a truncated or corrupt stream from :func:`open_binary` raises (one ``except``;
#: not ValueError, so a reader's own FormatError raised in the same block passes through).
CORRUPT = (OSError, EOFError, zlib.error, lzma.LZMAError)

_SIGNATURES = ((b"\x1f\x8b", "gzip"), (b"BZh", "bzip2"), (b"\xfd7zXZ\x00", "xz"))
_OPEN = {
    "gzip": lambda f: gzip.GzipFile(fileobj=f, mode="rb"),
    "bzip2": lambda f: bz2.BZ2File(f, "rb"),
    "xz": lambda f: lzma.LZMAFile(f, "rb"),
}  # each leaves the file object it reads open


def compression(head: bytes) -> str | None:
    """``"gzip"``, ``"bzip2"``, ``"xz"`` or None (plain) for a file's first (at least 6) bytes."""
    for signature, name in _SIGNATURES:
        if head.startswith(signature):
            return name
    return None


def _open_regular(path) -> tuple[BinaryIO, int]:
    """``path`` opened for reading and its size; refuses what is not a regular file *before*
    opening it (opening a FIFO blocks)."""
    _limits.regular_file_size(path)
    try:
        f = open(path, "rb")
    except OSError as e:
        raise FormatError(path, f"cannot read the file ({e.strerror or e})") from None
    try:
        return f, _limits.regular_file_size(path, f)  # the file opened may not be the one stat'ed
    except BaseException:
        f.close()
        raise


class _Bounded(io.RawIOBase):
    """A decompressing stream that raises FormatError once it has given more than its budget."""

    def __init__(self, file, kind: str, path, size: int):
        self._file, self._stream, self._path, self._size = file, _OPEN[kind](file), path, size
        self._limits = _limits.current()
        self._budget = self._limits.budget(size)
        self._total = 0

    def readable(self) -> bool:
        return True

    def readinto(self, buffer) -> int:
        n = self._stream.readinto(buffer)
        self._total += n
        if self._total > self._budget:
            self._limits.check(self._path, "the decompressed stream", self._total, self._size)
        return n

    def close(self) -> None:
        if not self.closed:
            self._stream.close()
            self._file.close()
        super().close()


def open_binary(path) -> BinaryIO:
    """``path`` opened for streaming reads, decompressing when its first bytes say so. A corrupt
    stream raises one of :data:`CORRUPT` while it is read, a stream beyond the limits a
    FormatError."""
    f, size = _open_regular(path)
    kind = compression(f.read(6))
    f.seek(0)
    if kind is None:
        return f
    return io.BufferedReader(_Bounded(f, kind, path, size))


def read_bytes(path) -> bytes:
    """The whole file, decompressed when its first bytes say so (see the module's rule)."""
    f, size = _open_regular(path)
    with f:
        raw = f.read()
    kind = compression(raw[:6])
    if kind is None:
        return raw
    limits = _limits.current()
    budget = limits.budget(len(raw))
    try:
        with _OPEN[kind](io.BytesIO(raw)) as stream:
            data = stream.read(budget + 1)
    except (*CORRUPT, ValueError) as e:  # bz2 raises ValueError for a truncated whole
        if str(path).lower().endswith(EXTENSIONS):
            raise FormatError(path, f"compressed data is truncated or corrupt ({e})") from None
        return raw
    if len(data) > budget:
        limits.check(path, "the decompressed data", len(data), len(raw))
    return data
