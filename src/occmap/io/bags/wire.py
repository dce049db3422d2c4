"""ROS messages read straight from their serialised bytes: the cursor the message decoders share.

Two serialisations, named as :attr:`Message.encoding <occmap.io.bags.Message>` names them:

* ``"ros1"`` (ROS 1 bags): little-endian, packed without padding; a string is a ``uint32``
  length and that many bytes; ``time`` is ``uint32 sec, uint32 nsec``; ``std_msgs/Header`` is
  ``uint32 seq, time stamp, string frame_id``.
* ``"cdr"`` (ROS 2 bags; OMG XCDR1 as ROS 2's middlewares write it): a 4-byte encapsulation
  header, ``00 00`` for big-endian or ``00 01`` for little-endian data and two option bytes,
  then the fields, each primitive aligned to its own size (at most 8) counted from the end of
  that header; a string is a ``uint32`` length that counts a closing NUL, the bytes and the
  NUL; ``std_msgs/Header`` is ``int32 sec, uint32 nanosec, string frame_id``, no ``seq``.

In both, a sequence is a ``uint32`` count and its items. Arrays of numbers come out as NumPy
views of the message's bytes (no copy, nothing done per element in Python). Messages of one
layout (a sensor's scans, a broadcaster's tf: the same size, frames and counts) are read many at
once, where they lie (a chunk's buffer, :class:`~.records.Raws`): :func:`by_layout` groups them
and :func:`column` reads a field of every one into float64 rows, one kernel pass over the
messages (no copy of them, no intermediate arrays). A message shorter
than its fields need, a length past its end, or a string that is not UTF-8 raises
:class:`~occmap.errors.FormatError` naming the message (``where``), the field and the value.
"""

from __future__ import annotations

import struct
import sys
from functools import cache

import numpy as np

from ..._intrinsics import load_at
from ..._jit import kernel
from ...errors import FormatError, InvalidArgumentError
from .records import Raws

__all__ = ["ENCODINGS", "Wire", "by_layout", "column", "frame_name", "stamps"]

ENCODINGS = ("ros1", "cdr")
_U32 = {"<": struct.Struct("<I"), ">": struct.Struct(">I")}
# a Header up to its frame's bytes: ROS 1's seq (skipped), the stamp, the frame's length
_HEADER = {False: {"<": struct.Struct("<4xiII")}, True: {"<": struct.Struct("<iII"), ">": struct.Struct(">iII")}}


@cache
def _dtype(code: str) -> np.dtype:
    return np.dtype(code)


@cache
def _struct(fmt: str) -> tuple[struct.Struct, int]:
    """The :class:`struct.Struct` of ``fmt`` (a byte order and one type, ``"<7f"``) and the size
    of one of its values, which CDR aligns to."""
    return struct.Struct(fmt), struct.calcsize(fmt[0] + fmt[-1])


def by_layout(raws, layout_of):
    """The messages ``raws`` (a sequence of messages, or a :class:`~.records.Raws`) in groups of
    one layout: ``(indices, layout, group)`` for each, the group of the first message first, its
    messages a :class:`~.records.Raws` (where they lie, not copied; see :func:`column`).
    ``layout_of(i)`` reads message ``i``'s layout (raising for a message it cannot read), an object
    with ``size`` (bytes) and ``same``: the ``(start, stop)`` byte spans (its frames, counts, byte
    order: what fixes where the other fields sit) that the messages of the group hold alike."""
    raws = Raws.of(raws)
    left = np.arange(len(raws))
    while len(left):
        layout = layout_of(int(left[0]))
        same = np.empty(len(left), dtype=np.bool_)
        _alike(raws.buf, raws.starts[left], raws.sizes[left], layout.size,
               np.array(layout.same, dtype=np.int64).reshape(-1, 2), same)
        whole = same.all()
        group = left if whole else left[same]
        yield group, layout, raws.take(group)
        if whole:
            return
        left = left[~same]


@kernel
def _alike(buf, starts, sizes, size, spans, same):
    """``same[i]``: message ``i`` is ``size`` bytes and holds message 0's bytes in every span
    ``spans[k] = (start, stop)``."""
    ref = starts[0]
    for i in range(len(starts)):
        ok = sizes[i] == size
        k = 0
        while ok and k < len(spans):
            for b in range(spans[k, 0], spans[k, 1]):
                if buf[starts[i] + b] != buf[ref + b]:
                    ok = False
                    break
            k += 1
        same[i] = ok


# the number types column() reads, as empty arrays of each: the kernel's dispatcher takes 0.3 µs
# to recognise an array, 4 µs a type object
_TYPES = {kind: np.empty(0, kind) for kind in ("f4", "f8", "i4", "u4")}
_NATIVE = "<" if sys.byteorder == "little" else ">"


def column(raws: Raws, at: int, dtype: str, n: int = 1) -> np.ndarray:
    """The ``n`` values of type ``dtype`` (with its byte order: ``"<f4"``, ``">f8"``, ``"<i4"``,
    ``"<u4"``) at byte ``at`` of each message of ``raws``, as float64 rows (messages, n), read
    where the messages lie in one kernel pass; every message must hold those bytes."""
    order, kind = dtype[0], dtype[1:]
    width = 8 if kind == "f8" else 4
    _check_holds(raws, at, n * width)
    out = np.empty((len(raws), n))
    _read_column(raws.buf, raws.starts, at, _TYPES[kind], width, order != _NATIVE, n, out)
    return out


def stamps(raws: Raws, at: int, order: str) -> np.ndarray:
    """The header stamps in seconds (``sec + nanosec * 1e-9``) whose ``sec`` starts at byte ``at``
    (:meth:`Wire.header_at`) of each message of ``raws``, in byte order ``order``, (messages,)."""
    _check_holds(raws, at, 8)
    out = np.empty(len(raws))
    _read_stamps(raws.buf, raws.starts, at, order != _NATIVE, out)
    return out


def _check_holds(raws: Raws, at: int, nbytes: int) -> None:
    """Raise unless every message of ``raws`` holds ``nbytes`` bytes from byte ``at``."""
    if len(raws) and int(raws.sizes.min()) < at + nbytes:
        i = int(np.argmax(raws.sizes < at + nbytes))
        raise InvalidArgumentError(f"message {i} is {int(raws.sizes[i])} bytes; {nbytes} are read from byte {at}")


@kernel
def _read_column(buf, starts, at, like, width, swap, n, out):
    """``out[i]``: the ``n`` values of the type of the array ``like`` (``width`` bytes each) at
    byte ``at`` of the message starting at ``buf[starts[i]]``, each value's bytes reversed when
    ``swap``."""
    kind = like.dtype
    for i in range(len(starts)):
        s = starts[i] + at
        for k in range(n):
            out[i, k] = load_at(buf, s + width * k, kind, swap)


@kernel
def _read_stamps(buf, starts, at, swap, out):
    """``out[i]``: ``sec + nanosec * 1e-9`` of the int32 ``sec`` and uint32 ``nanosec`` at byte
    ``at`` of the message starting at ``buf[starts[i]]``, bytes reversed when ``swap``."""
    for i in range(len(starts)):
        s = starts[i] + at
        out[i] = np.float64(load_at(buf, s, np.int32, swap)) + np.float64(load_at(buf, s + 4, np.uint32, swap)) * 1e-9


def frame_name(frame_id: str) -> str:
    """A frame id without ROS 1's leading slash (``/laser`` → ``laser``), as tf2 strips it."""
    return frame_id.lstrip("/")


class Wire:
    """A read position in one serialised message (``raw``: bytes, memoryview or a uint8 array)
    of ``encoding`` ``"ros1"`` or ``"cdr"``; ``where`` names the message in errors (a string, or
    a :class:`~occmap.io.bags.bag.Where`, formatted only then).

    Each read method takes the ROS name of the field it reads, for errors, and moves past it.
    """

    __slots__ = ("raw", "size", "pos", "base", "cdr", "order", "where")

    def __init__(self, raw, encoding: str, where: str):
        self.raw, self.size, self.where = raw, len(raw), where
        if encoding == "ros1":
            self.cdr, self.order, self.pos, self.base = False, "<", 0, 0
        elif encoding == "cdr":
            if self.size < 4:
                raise FormatError(where, f"{self.size} bytes, fewer than the 4 of a CDR encapsulation header")
            if raw[0] != 0 or raw[1] > 1:
                raise FormatError(where, f"CDR encapsulation {bytes(raw[:2]).hex(' ')}, not 00 00 (big-endian CDR) "
                                  "or 00 01 (little-endian CDR)")
            self.cdr, self.order, self.pos, self.base = True, "<" if raw[1] else ">", 4, 4
        else:
            raise InvalidArgumentError(f"{where}: encoding {encoding!r}, not one of {', '.join(ENCODINGS)}")

    def _take(self, field: str, nbytes: int, align: int, part: str = "") -> int:
        """Align to ``align`` (CDR), check ``nbytes`` remain, move past them; their start. The
        error names ``field + part`` (joined only then: the decoders call this for every field)."""
        if self.cdr:
            self.pos += -(self.pos - self.base) % align
        start = self.pos
        if start + nbytes > self.size:
            raise FormatError(self.where, f"field {field}{part}: {nbytes} bytes from byte {start} run past the "
                              f"message's {self.size} (truncated)")
        self.pos = start + nbytes
        return start

    def values(self, fmt: str, field: str, part: str = "") -> tuple:
        """Primitives of one size in a row, by :mod:`struct` format ``fmt`` (``"7f"``, ``"3d"``)."""
        s, align = _struct(self.order + fmt)
        return s.unpack_from(self.raw, self._take(field, s.size, align, part))

    def count(self, field: str, least: int = 0, part: str = "") -> int:
        """A sequence's ``uint32`` length, checked against the bytes left when each item takes
        at least ``least`` bytes."""
        n = _U32[self.order].unpack_from(self.raw, self._take(field, 4, 4, part))[0]
        if n * least > self.size - self.pos:
            raise FormatError(self.where, f"field {field}{part}: {n} items of {least} bytes or more from byte "
                              f"{self.pos} run past the message's {self.size} bytes (truncated or corrupt)")
        return n

    def array(self, dtype: str, field: str) -> np.ndarray:
        """A sequence of numbers of NumPy type ``dtype`` (``"f4"``), a read-only view in the
        message's byte order."""
        kind = _dtype(self.order + dtype)
        n = self.count(field, kind.itemsize)
        return np.frombuffer(self.raw, dtype=kind, count=n, offset=self._take(field, n * kind.itemsize, kind.itemsize))

    def skip(self, nbytes: int, align: int, field: str) -> None:
        """Fields read for their length alone (``nbytes`` bytes aligned to ``align``)."""
        self._take(field, nbytes, align)

    def skip_array(self, itemsize: int, field: str) -> None:
        """A sequence of ``itemsize``-byte numbers read for its length alone."""
        self._take(field, self.count(field, itemsize) * itemsize, itemsize)

    def string(self, field: str, part: str = "") -> str:
        return self._text(self.count(field, 1, part), field, part)

    def _text(self, n: int, field: str, part: str) -> str:
        """The string of ``n`` bytes (CDR: with its NUL) that starts here."""
        start = self._take(field, n, 1, part)
        text = bytes(self.raw[start: start + n - 1 if self.cdr and n else start + n])
        try:
            return text.decode()
        except UnicodeDecodeError as e:
            raise FormatError(self.where, f"field {field}{part}: {text[:40]!r} is not UTF-8 ({e.reason})") from None

    def header(self, field: str = "header") -> tuple[float, str]:
        """A ``std_msgs/Header``: its stamp in seconds and its frame (without ROS 1's leading
        slash)."""
        at, frame = self.header_at(field)
        sec, nanosec = _HEADER[True][self.order].unpack_from(self.raw, at)[:2]
        return sec + nanosec * 1e-9, frame

    def header_at(self, field: str = "header") -> tuple[int, str]:
        """A ``std_msgs/Header`` as :meth:`header` reads it, but the byte where its stamp
        (``sec``, ``nanosec``) starts in place of the stamp (for :func:`stamps`)."""
        layout = _HEADER[self.cdr][self.order]
        start = self._take(field, layout.size, 4, ".stamp")
        n = layout.unpack_from(self.raw, start)[2]
        return start + layout.size - 12, frame_name(self._text(n, field, ".frame_id"))
