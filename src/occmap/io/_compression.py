"""Compressed input files: gzip, bzip2 and xz, recognised by their first bytes.

Every reader opens its file here. The *content* decides: a file that starts with a compression
signature (gzip ``1f 8b``, bzip2 ``BZh``, xz ``fd 37 7a 58 5a 00``) is decompressed whatever its
name, and a plain file is read as it is even when named ``.gz``. The *name* only matters when a
file starts with a signature but does not decompress: with a compressed extension
(:data:`EXTENSIONS`) that is a :class:`~occmap.errors.FormatError` (truncated or corrupt), without
one the bytes are taken as they are (a binary scan may begin with those bytes by chance).
"""

from __future__ import annotations

import bz2
import gzip
import lzma
import zlib
from typing import BinaryIO

from ..errors import FormatError

__all__ = ["CORRUPT", "EXTENSIONS", "compression", "open_binary", "read_bytes"]

#: Extensions of compressed files (lower case); readers look through them to the format's own.
EXTENSIONS = (".gz", ".bz2", ".xz")

#: What reading a truncated or corrupt stream from :func:`open_binary` raises (one ``except``;
#: not ValueError, so a reader's own FormatError raised in the same block passes through).
CORRUPT = (OSError, EOFError, zlib.error, lzma.LZMAError)

_SIGNATURES = ((b"\x1f\x8b", "gzip"), (b"BZh", "bzip2"), (b"\xfd7zXZ\x00", "xz"))
_OPEN = {"gzip": gzip.open, "bzip2": bz2.open, "xz": lzma.open}
_DECOMPRESS = {"gzip": gzip.decompress, "bzip2": bz2.decompress, "xz": lzma.decompress}


def compression(head: bytes) -> str | None:
    """``"gzip"``, ``"bzip2"``, ``"xz"`` or None (plain) for a file's first (at least 6) bytes."""
    for signature, name in _SIGNATURES:
        if head.startswith(signature):
            return name
    return None


def open_binary(path) -> BinaryIO:
    """``path`` opened for streaming reads, decompressing when its first bytes say so. A corrupt
    stream raises one of :data:`CORRUPT` while it is read."""
    with open(path, "rb") as f:
        kind = compression(f.read(6))
    return open(path, "rb") if kind is None else _OPEN[kind](path, "rb")


def read_bytes(path) -> bytes:
    """The whole file, decompressed when its first bytes say so (see the module's rule)."""
    with open(path, "rb") as f:
        raw = f.read()
    kind = compression(raw[:6])
    if kind is None:
        return raw
    try:
        return _DECOMPRESS[kind](raw)
    except (*CORRUPT, ValueError) as e:  # bz2 raises ValueError for a truncated whole
        if str(path).lower().endswith(EXTENSIONS):
            raise FormatError(path, f"compressed data is truncated or corrupt ({e})") from None
        return raw
