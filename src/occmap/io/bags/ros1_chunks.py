"""ROS 1 bags (format 2.0) read from their chunk records, without the per-chunk index.

A bag 2.0 file is ``#ROSBAG V2.0\\n`` followed by records. Each record is a header (``u32``
length, then fields ``u32 length`` + ``name=value``) and data (``u32`` length, then bytes); the
header field ``op`` (one byte) says what the record is:

====  ============  ===========================================================================
op    record        header fields (data)
====  ============  ===========================================================================
0x03  bag header    ``index_pos`` u64, ``conn_count`` u32, ``chunk_count`` u32 (padding)
0x05  chunk         ``compression`` (none, bz2, lz4), ``size`` u32 unpacked (connection and
                    message data records)
0x04  index data    ``ver``, ``conn``, ``count`` (``count`` × time u64 + offset u32)
0x07  connection    ``conn`` u32, ``topic`` (a header: ``type``, ``md5sum``,
                    ``message_definition``, ``callerid``, ``latching``)
0x06  chunk info    ``ver``, ``chunk_pos`` u64, ``start_time``, ``end_time``, ``count`` u32
                    (``count`` × conn u32 + message count u32)
0x02  message data  ``conn`` u32, ``time`` (sec u32, nsec u32) (the serialised message)
====  ============  ===========================================================================

The index section at ``index_pos`` holds the connection records and one chunk info per chunk.
``rosbags`` also reads the index data records after each chunk and rejects a bag whose index data
length disagrees with its count (the shared ``laser_scan_matcher_demo.bag`` says 5,560 bytes for
278 entries of 12). This reader needs only the index section: it finds each chunk from its chunk
info, unpacks it, and lists the message records inside (:func:`~.records.chunk_records`, the
kernel the indexed path uses too), so it yields messages in the order they were recorded, one
chunk in memory at a time. Integers are little-endian.
"""

from __future__ import annotations

import bz2
import struct
from typing import BinaryIO, Iterator, NamedTuple

from ...errors import FormatError
from .records import Records, chunk_records, read_span

_U32 = struct.Struct("<I")
_OP_BAG_HEADER, _OP_CHUNK, _OP_CONNECTION, _OP_CHUNK_INFO = 0x03, 0x05, 0x07, 0x06
_MAGIC = b"#ROSBAG V2.0\n"


class Connection(NamedTuple):
    """One ROS 1 connection: a topic with its message type (``pkg/Name``), definition and the
    definition's md5sum."""

    id: int
    topic: str
    msgtype: str
    definition: str
    md5sum: str


class ChunkInfo(NamedTuple):
    position: int
    start: int  # nanoseconds
    end: int
    counts: dict[int, int]  # messages per connection


def _time_ns(raw: bytes) -> int:
    sec, nsec = struct.unpack("<II", raw)
    return sec * 1_000_000_000 + nsec


class Ros1Chunks:
    """The index section of an open ROS 1 bag file and its messages, chunk by chunk.

    Raises :class:`~occmap.errors.FormatError` naming the file and the byte offset of any record
    that does not follow the format.
    """

    def __init__(self, path, file: BinaryIO):
        self.path = path
        self._file = file
        file.seek(0)
        if file.read(len(_MAGIC)) != _MAGIC:
            raise FormatError(path, "not a ROS bag 2.0 file (no '#ROSBAG V2.0' line)", offset=0)
        fields, _, _ = self._record(len(_MAGIC), _OP_BAG_HEADER)
        index_pos = self._uint(fields, "index_pos", len(_MAGIC))
        conn_count = self._uint(fields, "conn_count", len(_MAGIC))
        chunk_count = self._uint(fields, "chunk_count", len(_MAGIC))
        if index_pos == 0:
            raise FormatError(path, "the bag has no index (its recording did not finish); "
                              "run 'rosbag reindex' on it first")
        self.connections: dict[int, Connection] = {}
        self.chunks: list[ChunkInfo] = []
        pos = index_pos
        for _ in range(conn_count):
            fields, data, pos = self._record(pos, _OP_CONNECTION)
            conn = self._uint(fields, "conn", pos)
            info = _fields(self.path, data, pos)
            self.connections[conn] = Connection(
                conn,
                fields.get(b"topic", b"").decode(errors="replace"),
                info.get(b"type", b"").decode(errors="replace"),
                info.get(b"message_definition", b"").decode(errors="replace"),
                info.get(b"md5sum", b"").decode(errors="replace"),
            )
        for _ in range(chunk_count):
            start = pos
            fields, data, pos = self._record(pos, _OP_CHUNK_INFO)
            count = self._uint(fields, "count", start)
            if len(data) < 8 * count:
                raise FormatError(path, f"chunk info lists {count} connections in {len(data)} bytes", offset=start)
            pairs = struct.unpack_from(f"<{2 * count}I", data)
            self.chunks.append(ChunkInfo(
                self._uint(fields, "chunk_pos", start),
                _time_ns(self._field(fields, "start_time", start)),
                _time_ns(self._field(fields, "end_time", start)),
                dict(zip(pairs[::2], pairs[1::2])),
            ))
        self.chunks.sort(key=lambda c: c.start)

    def counts(self) -> dict[int, int]:
        """Messages per connection, summed over the chunk infos."""
        total: dict[int, int] = {}
        for chunk in self.chunks:
            for conn, n in chunk.counts.items():
                total[conn] = total.get(conn, 0) + n
        return total

    def messages(self, connections: set[int]) -> Iterator[tuple[int, int, bytes]]:
        """``(connection id, time in ns, serialised message)`` of the given connections, in the
        order recorded; chunks holding none of them are not read."""
        for data, records in self.chunks_of(connections):
            for conn, time_ns, start, size in zip(*(a.tolist() for a in records)):
                if conn in connections:
                    yield conn, time_ns, bytes(data[start: start + size])

    def chunks_of(self, connections: set[int]) -> Iterator[tuple[object, Records]]:
        """``(unpacked chunk, its message records)`` of each chunk holding messages of
        ``connections`` (and maybe others), in time order (:meth:`records_of`)."""
        return self.records_of([c for c in self.chunks if connections.intersection(c.counts)])

    def records_of(self, chunks: list[ChunkInfo]) -> Iterator[tuple[object, Records]]:
        """``(unpacked chunk, its message records)`` of each of ``chunks``, the records listed by
        :func:`~.records.chunk_records`."""
        for chunk in chunks:
            data = self._unpack(chunk.position)
            yield data, chunk_records(data, "ros1", self.path, f"chunk at byte {chunk.position}")

    # ------------------------------------------------------------------ records

    def _unpack(self, position: int):
        """The records held by the chunk at ``position``, decompressed: bytes, or for a chunk
        stored uncompressed a read-only view of the file (:func:`~.records.read_span`)."""
        fields, (at, n), _ = self._record(position, _OP_CHUNK, read_data=False)
        compression = fields.get(b"compression", b"").decode(errors="replace")
        size = self._uint(fields, "size", position)
        if compression not in ("none", "bz2", "lz4"):
            raise FormatError(self.path, f"chunk compression {compression!r} is not none, bz2 or lz4", offset=position)
        data = read_span(self._file, at, n)
        if len(data) != n:
            raise FormatError(self.path, f"the file ends inside a record (wanted {n} bytes, found {len(data)})", offset=at)
        try:
            if compression == "bz2":
                unpacked = bz2.decompress(data)
            elif compression == "lz4":
                import lz4.frame  # installed with rosbags

                unpacked = lz4.frame.decompress(data)
            else:
                unpacked = data
        except (OSError, ValueError, RuntimeError) as e:
            raise FormatError(self.path, f"{compression} chunk does not decompress: {e}", offset=position) from e
        if len(unpacked) != size:
            raise FormatError(self.path, f"chunk unpacks to {len(unpacked)} bytes, its header says {size}", offset=position)
        return unpacked

    def _record(self, pos: int, op: int, read_data: bool = True) -> tuple[dict[bytes, bytes], object, int]:
        """Header fields, data and the next position of the record at ``pos``, which must be
        of kind ``op``; unless ``read_data``, the data's ``(start, length)`` in its place."""
        self._file.seek(pos)
        head = self._read(pos, 4)
        header = self._read(pos + 4, _U32.unpack(head)[0])
        at = pos + 8 + len(header)
        n = _U32.unpack(self._read(at - 4, 4))[0]
        data = self._read(at, n) if read_data else (at, n)
        fields = _fields(self.path, header, pos)
        found = fields.get(b"op")
        if found != bytes([op]):
            what = "no op field" if found is None else f"op 0x{found.hex()}"
            raise FormatError(self.path, f"expected a record with op 0x{op:02x}, found {what}", offset=pos)
        return fields, data, at + n

    def _read(self, pos: int, n: int) -> bytes:
        raw = self._file.read(n)
        if len(raw) != n:
            raise FormatError(self.path, f"the file ends inside a record (wanted {n} bytes, found {len(raw)})", offset=pos)
        return raw

    def _field(self, fields, name: str, pos: int) -> bytes:
        return _get(self.path, fields, name, pos, None)

    def _uint(self, fields, name: str, pos: int) -> int:
        return _unpack_uint(self.path, fields, name, pos)


def _fields(path, header: bytes, pos: int) -> dict[bytes, bytes]:
    """The ``name=value`` fields of a record header."""
    fields = {}
    at, end = 0, len(header)
    while at < end:
        if at + 4 > end:
            raise FormatError(path, "record header ends inside a field length", offset=pos)
        n = _U32.unpack_from(header, at)[0]
        field = header[at + 4: at + 4 + n]
        name, eq, value = field.partition(b"=")
        if len(field) != n or not eq:
            raise FormatError(path, "record header field is cut short or has no '='", offset=pos)
        fields[name] = value
        at += 4 + n
    return fields


def _get(path, fields, name: str, pos: int, size: int | None) -> bytes:
    value = fields.get(name.encode())
    if value is None or (size is not None and len(value) != size):
        raise FormatError(path, f"record lacks a valid {name!r} field", offset=pos)
    return value


def _unpack_uint(path, fields, name: str, pos: int) -> int:
    value = fields.get(name.encode())
    if value is None or len(value) not in (4, 8):
        raise FormatError(path, f"record lacks a valid {name!r} field", offset=pos)
    return int.from_bytes(value, "little")
