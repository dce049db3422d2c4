"""The message records of a ROS 1 or an MCAP chunk, listed at once by a kernel.

A bag's messages sit in chunks (about a megabyte each, as recorders write them), and a chunk
(once unpacked) is records in a row, each told by a small frame:

* ROS 1 (format 2.0, see :mod:`.ros1_chunks`): ``u32`` header length, the header's fields (each
  a ``u32`` length and ``name=value``), ``u32`` data length, the data. A message data record has
  ``op=0x02``, ``conn`` (``u32``) and ``time`` (``u32`` sec, ``u32`` nsec); a chunk holds those
  and connection records (``op=0x07``), which are skipped.
* MCAP: an opcode byte, a ``u64`` length, the record. A message record (opcode ``0x05``) is
  ``u16`` channel, ``u32`` sequence, ``u64`` log time (ns), ``u64`` publish time, then the
  message; other records (schemas, channels) are skipped.

Integers are little-endian. :func:`chunk_records` walks a chunk in one Numba kernel and gives each
message's connection (channel), time and where its bytes sit (:class:`Records`), so a chunk of a
thousand messages costs a few microseconds rather than the ~8 µs a message that ``rosbags``'
per-message Python costs (the most of reading a bag of laser scans; see docs/inputs.md). The
messages then come out of the chunk together (:class:`Raws`). A record that runs past the chunk's
end, a ROS 1 header field without ``=``, or a message record lacking its fields raises
:class:`~occmap.errors.FormatError` naming the file, the chunk and the byte.
"""

from __future__ import annotations

import io
import mmap
import os
from typing import BinaryIO, NamedTuple

import numpy as np

from ..._jit import inline_kernel, kernel
from ...errors import FormatError

__all__ = ["Raws", "Records", "chunk_records", "read_span"]

_ROS1, _MCAP = 1, 2
# what went wrong at a byte (the kernel's status codes)
_PROBLEMS = {
    1: "a record is cut short (its lengths run past the chunk's end)",
    2: "a record header field is cut short or has no '='",
    3: "a message data record lacks its conn or time field",
    4: "a record that is neither message data (op 0x02) nor a connection (op 0x07)",
    5: "a message record shorter than its 22 bytes of channel, sequence and times",
}


class Records(NamedTuple):
    """The message records of a chunk in the order they sit: record ``i`` is on connection
    (ROS 1 ``conn``, MCAP channel) ``conn[i]``, recorded at ``time_ns[i]``, and its message is
    ``size[i]`` bytes from byte ``start[i]`` of the chunk (int64 arrays)."""

    conn: np.ndarray
    time_ns: np.ndarray
    start: np.ndarray
    size: np.ndarray


def chunk_records(chunk, kind: str, path, where: str) -> Records:
    """The message records of ``chunk`` (an unpacked chunk's bytes: bytes, memoryview or uint8
    array) of ``kind`` ``"ros1"`` or ``"mcap"``. ``path`` and ``where`` (the chunk, e.g. ``"chunk
    at byte 4117"``) name it in a :class:`FormatError`."""
    buf = np.frombuffer(chunk, np.uint8)
    table, n, status, at = _walk(buf, _ROS1 if kind == "ros1" else _MCAP)
    if status:
        raise FormatError(path, f"{where}: {_PROBLEMS[status]}, at byte {at} of its {len(buf)} unpacked bytes")
    return Records(*table[:, :n])


#: Spans of a file at least this long are mapped, not read (:func:`read_span`)
MAP_BYTES = 64 << 10


def read_span(file: BinaryIO, offset: int, n: int) -> bytes | memoryview:
    """The ``n`` bytes of the open binary ``file`` from byte ``offset``, read-only (fewer when
    the file ends before). A span of :data:`MAP_BYTES` or more is a view of a memory map of its
    pages: nothing is copied, and the pages come from the page cache as they are read, many at a
    fault, where bytes read into fresh memory cost a fault a page (a 0.9 MB chunk: 0.04 ms
    against 0.35 ms). The map goes when the view and every view of it do, so a chunk is held no
    longer than when read. A shorter span, or one of a file that cannot be mapped, is read. The
    file must not shrink while a view is held (reading a mapped page past its end kills the
    process with SIGBUS): bags are read once written."""
    if n >= MAP_BYTES:
        try:
            fd = file.fileno()
            if offset + n <= os.fstat(fd).st_size:
                start = offset - offset % mmap.ALLOCATIONGRANULARITY
                view = mmap.mmap(fd, offset + n - start, access=mmap.ACCESS_READ, offset=start)
                return memoryview(view)[offset - start: offset - start + n]
        except (OSError, ValueError, io.UnsupportedOperation):
            pass
    file.seek(offset)
    return file.read(n)


class Raws:
    """Serialised messages held in one buffer: message ``i`` is ``sizes[i]`` bytes from byte
    ``starts[i]`` of ``buf`` (a uint8 array; a chunk's, or messages joined end to end). ``raws[i]``
    is a uint8 view of one message, :meth:`take` picks messages without copying them (the
    decoders read fields of many where they lie, :func:`~.wire.column`), :meth:`joined` puts them
    end to end."""

    __slots__ = ("buf", "starts", "sizes")

    def __init__(self, buf: np.ndarray, starts: np.ndarray, sizes: np.ndarray):
        self.buf, self.starts, self.sizes = buf, starts, sizes

    @classmethod
    def of(cls, raws) -> Raws:
        """A sequence of messages (bytes-like each) copied into one buffer."""
        if isinstance(raws, Raws):
            return raws
        sizes = np.fromiter(map(len, raws), np.int64, len(raws))
        return cls(np.frombuffer(b"".join(raws), np.uint8), _end_to_end(sizes), sizes)

    @classmethod
    def concat(cls, parts: list[Raws]) -> Raws:
        """The messages of ``parts`` in a row (copied into one buffer when there are several)."""
        if len(parts) == 1:
            return parts[0]
        whole = [p.joined() for p in parts]
        sizes = np.concatenate([p.sizes for p in parts])
        buf = np.concatenate(whole)
        buf.setflags(write=False)  # as a chunk's: the kernels see one array type
        return cls(buf, _end_to_end(sizes), sizes)

    def __len__(self) -> int:
        return len(self.sizes)

    def __getitem__(self, i: int) -> np.ndarray:
        start = int(self.starts[i])
        return self.buf[start: start + int(self.sizes[i])]

    def take(self, rows) -> Raws:
        return Raws(self.buf, self.starts[rows], self.sizes[rows])

    def compact(self) -> Raws:
        """The messages in a buffer of their own, which lets go of a chunk's buffer."""
        buf = self.joined().copy()
        buf.setflags(write=False)
        return Raws(buf, _end_to_end(self.sizes), self.sizes)

    def joined(self) -> np.ndarray:
        """The messages end to end, a uint8 array (a view when they already are)."""
        n = len(self.sizes)
        if n == 0:
            return np.zeros(0, np.uint8)
        first, total = int(self.starts[0]), int(self.sizes.sum())
        if n == 1 or (self.starts[1:] == self.starts[:-1] + self.sizes[:-1]).all():
            return self.buf[first: first + total]
        out = np.empty(total, np.uint8)
        _gather(self.buf, self.starts, self.sizes, out)
        return out


def _end_to_end(sizes: np.ndarray) -> np.ndarray:
    """Where messages of ``sizes`` bytes start when they lie end to end from byte 0 (int64)."""
    starts = np.zeros(len(sizes), np.int64)
    np.cumsum(sizes[:-1], out=starts[1:])
    return starts


@kernel
def _gather(buf, starts, sizes, out):
    at = 0
    for i in range(len(starts)):
        s, n = starts[i], sizes[i]
        out[at: at + n] = buf[s: s + n]
        at += n


@kernel
def _uint(buf, at, nbytes):
    value = np.int64(0)
    for k in range(nbytes - 1, -1, -1):
        value = (value << 8) | np.int64(buf[at + k])
    return value


@kernel
def _walk(buf, kind):
    """The message records of ``buf`` in one pass: ``(table, count, status, byte)``, the table's
    rows conn, time_ns, start and size (:class:`Records`) in its first ``count`` columns (a table
    that doubles when full), status 0 when the chunk reads to its end, else what went wrong
    (:data:`_PROBLEMS`) at the record starting at that byte."""
    table = np.empty((4, 256), np.int64)
    end = len(buf)
    pos = 0
    n = 0
    while pos < end:
        if kind == _MCAP:
            if end - pos < 9:
                return table, n, 1, pos
            op = buf[pos]
            length = _uint(buf, pos + 1, 8)
            body = pos + 9
            if length < 0 or length > end - body:
                return table, n, 1, pos
            if op == 0x05:
                if length < 22:
                    return table, n, 5, pos
                table = _room(table, n)
                table[0, n], table[1, n] = _uint(buf, body, 2), _uint(buf, body + 6, 8)
                table[2, n], table[3, n] = body + 22, length - 22
                n += 1
            pos = body + length
            continue
        if end - pos < 4:
            return table, n, 1, pos
        header = pos + 4
        header_end = header + _uint(buf, pos, 4)
        if header_end > end - 4:
            return table, n, 1, pos
        data = header_end + 4
        data_end = data + _uint(buf, header_end, 4)
        if data_end > end:
            return table, n, 1, pos
        op, c, t = -1, np.int64(-1), np.int64(-1)
        at = header
        while at < header_end:
            if header_end - at < 4:
                return table, n, 2, pos
            field = at + 4
            field_end = field + _uint(buf, at, 4)
            if field_end > header_end:
                return table, n, 2, pos
            eq = field
            while eq < field_end and buf[eq] != 61:  # '='
                eq += 1
            if eq == field_end:
                return table, n, 2, pos
            name, value = eq - field, field_end - eq - 1
            if name == 2 and value == 1 and buf[field] == 111 and buf[field + 1] == 112:  # op
                op = buf[eq + 1]
            elif name == 4 and buf[field] == 99 and buf[field + 1] == 111 and buf[field + 2] == 110 \
                    and buf[field + 3] == 110 and value == 4:  # conn
                c = _uint(buf, eq + 1, 4)
            elif name == 4 and buf[field] == 116 and buf[field + 1] == 105 and buf[field + 2] == 109 \
                    and buf[field + 3] == 101 and value == 8:  # time
                t = _uint(buf, eq + 1, 4) * 1_000_000_000 + _uint(buf, eq + 5, 4)
            at = field_end
        if op == 0x02:
            if c < 0 or t < 0:
                return table, n, 3, pos
            table = _room(table, n)
            table[0, n], table[1, n], table[2, n], table[3, n] = c, t, data, data_end - data
            n += 1
        elif op != 0x07:
            return table, n, 4, pos
        pos = data_end
    return table, n, 0, 0


@inline_kernel
def _room(table, n):
    """``table``, or a copy twice as wide when its ``n`` columns fill it."""
    if n < table.shape[1]:
        return table
    wider = np.empty((4, 2 * n), np.int64)
    wider[:, :n] = table
    return wider
