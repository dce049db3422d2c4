"""Open a ROS bag of any kind and stream its messages.

Kinds, told apart by their first bytes (a folder by its ``metadata.yaml``):

* ROS 1 ``.bag`` (format 2.0): its index section (connections, chunk infos) read by
  :class:`~occmap.io.bags.ros1_chunks.Ros1Chunks`, its messages one by one by ``rosbags`` (opened
  when first needed), or by ``Ros1Chunks`` when ``rosbags`` rejects the bag's index;
* ROS 2 bag folders (``metadata.yaml`` beside ``.db3`` or ``.mcap`` files), and a lone ``.db3``
  (SQLite) or ``.mcap`` file; an MCAP file (lone, or a folder's only one) by its summary section
  (schemas, channels, statistics, chunk index) read by occmap, ``rosbags`` opening when first
  needed, as for ROS 1 (or at once when the summary lacks what opening needs).

:meth:`Bag.runs` gives the messages a chunk at a time for the sources (ROS 1 and MCAP chunks
listed by the kernel of :mod:`.records`, no Python per message). A message comes as its bytes,
which occmap's decoders read for the types it maps from (:mod:`.wire`), and deserialised by ``rosbags`` on demand (:attr:`Message.msg`) with the type
definitions the bag carries (ROS 1 connections, MCAP schemas, ROS 2 metadata); a ROS 2 bag
without them is deserialised with the standard ROS 2 types ``rosbags`` knows, and so are the
topics :meth:`Bag.require_standard` has found to define their types as ROS does. Type names are in
ROS 2 form, ``sensor_msgs/msg/LaserScan``, for ROS 1 bags too. Times are float seconds since the
epoch: :attr:`Message.time` is when the message was recorded (not its
header stamp, which the decoders read).

Memory: a message is read when the loop reaches it; the readers hold one chunk of the file
(ROS 1 and MCAP recorders write chunks of about a megabyte; sqlite3 stores a message a row; a
chunk stored uncompressed is a view of the file's pages, :func:`~.records.read_span`) and
the bag's index, never the bag (streaming a 20 MB bag of clouds peaks at 1.4-4.3 MB in the tests).

Every problem with the file — not a bag, truncated, corrupt, a type it does not define — raises
:class:`~occmap.errors.FormatError` naming the file; asking for a topic the bag does not have, or
for a message type a topic does not hold, raises :class:`~occmap.errors.InvalidArgumentError`.
"""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Iterable, Iterator, NamedTuple

import numpy as np

from ...errors import FormatError, InvalidArgumentError, MissingFileError
from .definitions import check_definition, standard_store
from .records import Raws, chunk_records, read_span
from .ros1_chunks import Ros1Chunks

__all__ = ["Bag", "Message", "Run", "Topic", "Where", "is_bag", "open_bag"]

_ROS1_MAGIC = b"#ROSBAG V"
_MCAP_MAGIC = b"\x89MCAP0\r\n"
_SQLITE_MAGIC = b"SQLite format 3\x00"
_FORMS = {"MSG": "msg", "IDL": "idl"}  # rosbags' MessageDefinitionFormat names; NONE: no definition


class Topic(NamedTuple):
    """A topic of a bag: its name, message type (``pkg/msg/Name``) and number of messages."""

    name: str
    msgtype: str
    count: int


class Message:
    """One message: its topic and type, when it was recorded (seconds), and its bytes as the bag
    holds them, ``raw``, in ``encoding`` ``"ros1"`` (ROS 1 bags) or ``"cdr"`` (ROS 2), which
    occmap's decoders read (:func:`~occmap.io.bags.decode_laser_scan`, ...).

    :attr:`msg` deserialises the bytes with ``rosbags``, by the type definitions the bag carries
    (the standard ones once :meth:`Bag.require_standard` has passed the topic: the same layout).
    """

    __slots__ = ("topic", "msgtype", "time_ns", "raw", "encoding", "_bag")

    def __init__(self, topic: str, msgtype: str, time_ns: int, raw, encoding: str, bag: Bag):
        self.topic, self.msgtype, self.time_ns, self.raw, self.encoding, self._bag = \
            topic, msgtype, time_ns, raw, encoding, bag

    @property
    def time(self) -> float:
        """When the message was recorded, seconds since the epoch (:attr:`time_ns`: nanoseconds)."""
        return self.time_ns / 1e9

    @property
    def msg(self) -> object:
        """The message as a ``rosbags`` dataclass whose fields carry the ROS names. Raises
        :class:`FormatError` for bytes that do not decode as the type."""
        try:
            return self._bag._decode(self.topic, self.raw, self.msgtype)
        except FormatError:
            raise
        except Exception as e:  # whatever rosbags' decoder raises on bytes that do not fit the type
            raise FormatError(self._bag.path, f"topic {self.topic!r}, message recorded at {self.time:.9f} s: "
                              f"does not decode as {self.msgtype} ({_describe(e)})") from e

    def __repr__(self) -> str:
        return f"Message({self.topic!r}, {self.msgtype}, {self.time:.9f} s, {len(self.raw)} bytes {self.encoding})"


class Run:
    """Messages of a bag that were read together (a chunk's, :meth:`Bag.runs`), in time order:
    message ``i`` is on ``topics[which[i]]``, recorded at ``times_ns[i]`` (int64 nanoseconds),
    its bytes ``raws[i]`` (a :class:`~.records.Raws`)."""

    __slots__ = ("topics", "which", "times_ns", "raws")

    def __init__(self, topics: tuple[str, ...], which: np.ndarray, times_ns: np.ndarray, raws: Raws):
        self.topics, self.which, self.times_ns, self.raws = topics, which, times_ns, raws

    def __len__(self) -> int:
        return len(self.which)

    def take(self, rows) -> Run:
        return Run(self.topics, self.which[rows], self.times_ns[rows], self.raws.take(rows))


class Where:
    """Names message ``index`` of ``topic`` (recorded at ``time`` seconds) of the bag at ``path``
    in errors; formatted only when an error needs it (decoders take one for every message)."""

    __slots__ = ("path", "topic", "index", "time")

    def __init__(self, path, topic: str, index: int, time: float):
        self.path, self.topic, self.index, self.time = path, topic, index, time

    def __str__(self) -> str:
        return f"{self.path}: topic {self.topic!r}, message {self.index} (recorded at {self.time:.9f} s)"


def open_bag(path) -> Bag:
    """Open a ROS 1 ``.bag``, a ROS 2 bag folder, or a lone ``.db3`` / ``.mcap`` file (see
    :mod:`occmap.io.bags.bag`). Use it as a context manager, or call :meth:`Bag.close`."""
    return Bag(path)


class Bag:
    """An open bag: its topics, its time span, and its messages streamed in time order.

    Attributes
    ----------
    path : Path
    kind : str
        ``"ROS 1"``, ``"ROS 2 sqlite3"`` or ``"ROS 2 MCAP"`` (a ROS 2 bag folder or a lone file
        of that storage).
    encoding : str
        How its messages are serialised: ``"ros1"`` or ``"cdr"`` (see :mod:`.wire`).
    topics : dict[str, Topic]
        Every topic, by name, sorted by name.
    start, end : float or None
        Record times of the first and the last message in seconds; None for an empty bag.
    """

    def __init__(self, path):
        self.path = Path(path)
        self._standard: set[str] = set()  # topics that require_standard passed
        self.kind, suffix = _kind(self.path)
        if self.kind == "ROS 1":
            self._source = _Ros1(self.path)
        else:
            if suffix is not None and self.path.suffix != suffix:
                raise FormatError(self.path, f"holds {self.kind} data; name it *{suffix} to read it")
            path = _lone_mcap(self.path) or self.path
            self._source = (_Mcap.of(path) if self.kind == "ROS 2 MCAP" else None) or _Rosbags(path, self.kind)
        self.encoding = self._source.encoding
        try:
            self.topics = dict(sorted((t.name, t) for t in self._source.topics()))
            self.start, self.end = self._source.span()
        except BaseException:
            self._source.close()
            raise

    @property
    def note(self) -> str:
        """Empty, or how the bag was read when the usual way failed (a ROS 1 index ``rosbags``
        rejects; asking opens ``rosbags``' reader of a ROS 1 bag, see :class:`_Ros1`)."""
        return getattr(self._source, "note", "")

    def messages(self, topics: str | Iterable[str] | None = None, msgtype: str | None = None) -> Iterator[Message]:
        """The messages of ``topics`` (a name, several, or None for all) in time order (in
        the order recorded, for a ROS 1 bag read from its chunks).

        ``msgtype`` (e.g. ``"sensor_msgs/msg/LaserScan"``), when given, must be the type of every
        topic asked for. Raises :class:`InvalidArgumentError` for a topic the bag lacks or holding
        another type, :class:`FormatError` for a bag that cannot be read.
        """
        names = list(self.topics) if topics is None else [topics] if isinstance(topics, str) else list(topics)
        for name in names:
            topic = self.topics.get(name)
            if topic is None:
                raise InvalidArgumentError(f"{self.path}: no topic {name!r}; its topics: "
                                           f"{', '.join(self.topics) or '(none)'}")
            if msgtype is not None and topic.msgtype != msgtype:
                raise InvalidArgumentError(f"{self.path}: topic {name!r} holds {topic.msgtype}, not {msgtype}")
        return self._stream(set(names))

    def runs(self, topics: Iterable[str]) -> Iterator[Run]:
        """The messages of ``topics`` (names the bag has) as :meth:`messages` gives them, in
        runs: the messages of a chunk together for a ROS 1 or MCAP bag whose chunks follow one
        another in time (listed by :func:`~.records.chunk_records`, with no Python per message),
        else in runs of up to 64 messages (or a megabyte) as :meth:`messages` reads them."""
        return self._source.runs(set(topics))

    def require_standard(self, topics: str | Iterable[str]) -> None:
        """Raise :class:`FormatError` (naming the bag, the topic, the type and what differs) when
        a connection of ``topics`` defines its type otherwise than ROS does: occmap's decoders
        read the standard layout from the bytes (see :mod:`.definitions`). Types ``rosbags``
        does not ship pass."""
        names = {topics} if isinstance(topics, str) else set(topics)
        known = standard_store(self._source.encoding).fielddefs
        checked = set()
        for topic, msgtype, digest, form, text in self._source.definitions(names):
            check_definition(self.path, topic, msgtype, self._source.encoding, digest, form, text)
            if msgtype in known:
                checked.add(topic)
        self._standard |= checked

    def _decode(self, topic: str, raw, msgtype: str) -> object:
        """A message deserialised by ``rosbags``: by the standard types for a topic that
        :meth:`require_standard` passed (the same layout, and the store is made once per process
        where the bag's own types cost an ``AnyReader`` per bag, 20-50 ms), else by the bag's."""
        if topic not in self._standard:
            return self._source.decode(raw, msgtype)
        store = standard_store(self._source.encoding)
        return store.deserialize_cdr(raw, msgtype) if self._source.encoding == "cdr" else \
            store.deserialize_ros1(raw, msgtype)

    def _stream(self, names: set[str]) -> Iterator[Message]:
        encoding = self._source.encoding
        for topic, kind, time_ns, raw in self._source.raw(names):
            yield Message(topic, kind, time_ns, raw, encoding, self)

    def close(self) -> None:
        self._source.close()

    def __enter__(self) -> Bag:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"Bag({str(self.path)!r}, {self.kind}, {len(self.topics)} topics)"


def is_bag(path) -> bool:
    """Whether ``path`` looks like a bag (a folder with ``metadata.yaml``, or a file starting as a
    ROS 1 bag, an MCAP or an SQLite file does); it may still fail to open."""
    try:
        _kind(Path(path))
    except FormatError:
        return False
    return True


def _kind(path: Path) -> tuple[str, str | None]:
    """The bag's kind from its content, and the file suffix ``rosbags`` needs to read it."""
    if path.is_dir():
        if not (path / "metadata.yaml").is_file():
            raise FormatError(path, "a folder, but not a ROS 2 bag (no metadata.yaml in it)")
        storage = {f.suffix for f in path.iterdir()} & {".db3", ".mcap"}
        return "ROS 2 " + " + ".join(sorted("MCAP" if s == ".mcap" else "sqlite3" for s in storage)), None
    if not path.exists():
        raise MissingFileError(path, "no such file")
    with open(path, "rb") as f:
        magic = f.read(16)
    if magic.startswith(_ROS1_MAGIC):
        if not magic.startswith(_ROS1_MAGIC + b"2.0\n"):
            raise FormatError(path, f"ROS bag version {magic[9:12].decode(errors='replace')!r}; only 2.0 is read", offset=0)
        return "ROS 1", None
    if magic.startswith(_MCAP_MAGIC):
        return "ROS 2 MCAP", ".mcap"
    if magic.startswith(_SQLITE_MAGIC):
        return "ROS 2 sqlite3", ".db3"
    raise FormatError(path, "not a bag: expected a ROS 1 .bag, a ROS 2 bag folder, or a .db3 / .mcap file", offset=0)


def _lone_mcap(path: Path) -> Path | None:
    """The MCAP file of a ROS 2 bag folder that holds no other data (one file, not compressed
    as a whole), which ``rosbags`` then reads as it reads a lone file: the same topics, types and
    messages, opened in 2 ms where the folder costs 10 ms (parsing ``metadata.yaml``)."""
    if not path.is_dir():
        return None
    data = [f for f in path.iterdir() if f.name != "metadata.yaml"]
    return data[0] if len(data) == 1 and data[0].suffix == ".mcap" else None


class _Rosbags:
    """A bag read through ``rosbags``' reader of its kind; its errors become :class:`FormatError`.

    The bag's types are parsed (a ``rosbags`` ``AnyReader`` opened for them alone) only when a
    message is first deserialised: opening a bag with them costs 20 ms, which occmap's own
    decoders do not need."""

    def __init__(self, path: Path, kind: str):
        from rosbags.rosbag1 import Reader as Reader1
        from rosbags.rosbag2 import Reader as Reader2

        self.path, self.kind = path, kind
        self.encoding = "ros1" if kind == "ROS 1" else "cdr"
        self._typestore = None
        try:
            self._reader = (Reader1 if kind == "ROS 1" else Reader2)(path)
            self._reader.open()
        except Exception as e:  # rosbags raises ReaderError, AssertionError, struct.error, ... on bad files
            raise FormatError(path, f"not a readable {kind} bag ({_describe(e)})") from e

    def topics(self) -> list[Topic]:
        return [Topic(name, info.msgtype or "(mixed types)", info.msgcount) for name, info in self._reader.topics.items()]

    def span(self) -> tuple[float | None, float | None]:
        if self._reader.message_count == 0:
            return None, None
        # rosbags' end time is one nanosecond after the last message
        return self._reader.start_time / 1e9, (self._reader.end_time - 1) / 1e9

    def raw(self, topics: set[str]) -> Iterator[tuple[str, str, int, bytes]]:
        connections = [c for c in self._reader.connections if c.topic in topics]
        if not connections:
            return
        try:  # what the consumer raises is not thrown in here: an error in here is the reader's
            for connection, time_ns, raw in self._reader.messages(connections=connections):
                yield connection.topic, connection.msgtype, time_ns, raw
        except Exception as e:
            raise FormatError(self.path, f"cannot read the messages ({_describe(e)})") from e

    def runs(self, topics: set[str]) -> Iterator[Run]:
        from rosbags.rosbag2.storage_mcap import McapReader

        connections = [c for c in self._reader.connections if c.topic in topics]
        storage = getattr(self._reader, "storage", None)
        mcap = isinstance(storage, McapReader)
        return _mcap_runs(self, {c.id: c.topic for c in connections}, storage.chunks if mcap else [],
                          storage.bio if mcap else None, topics)

    def definitions(self, topics: set[str]) -> Iterator[tuple[str, str, str, str, str]]:
        """``(topic, type, digest, "msg" | "idl" | "", definition)`` of each connection of ``topics``."""
        for c in self._reader.connections:
            if c.topic in topics:
                yield c.topic, c.msgtype, c.digest, _FORMS.get(c.msgdef.format.name, ""), c.msgdef.data

    def decode(self, raw: bytes, msgtype: str) -> object:
        if self._typestore is None:
            self._typestore = self._types()
        if self.encoding == "cdr":
            return self._typestore.deserialize_cdr(raw, msgtype)
        return self._typestore.deserialize_ros1(raw, msgtype)

    def _types(self):
        """The bag's types as ``rosbags``' ``AnyReader`` reads them (the standard ROS 2 ones for a
        ROS 2 bag without definitions), checked against the digests the bag records."""
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore

        try:
            with AnyReader([self.path], default_typestore=get_typestore(Stores.LATEST)) as reader:
                return reader.typestore
        except Exception as e:
            raise FormatError(self.path, f"the type definitions of this {self.kind} bag do not parse "
                              f"({_describe(e)})") from e

    def close(self) -> None:
        self._reader.close()


class _McapChunk(NamedTuple):
    """An MCAP chunk index record, with the fields :func:`_mcap_runs` reads as rosbags names them."""

    message_start_time: int
    message_end_time: int
    chunk_start_offset: int
    channel_count: dict  # channel id -> its messages in the chunk (those with any)
    compression: str
    compressed_size: int
    uncompressed_size: int


class _Mcap:
    """A lone MCAP file whose summary section holds what opening needs (schemas, channels,
    statistics or a chunk index), read by occmap: ``rosbags``' reader, whose opening parses each
    channel's QoS profiles (YAML, 0.3 ms for two channels), opens only for what needs it: the
    messages one by one (:meth:`Bag.messages`), the bag's types, runs of chunks that overlap in
    time. Topics, counts, time span and definitions are those ``rosbags`` gives (the tests check);
    a file whose summary is missing, partial or not as expected is left to ``rosbags``
    (:meth:`of` gives None), which reads it as before, errors included."""

    encoding = "cdr"
    kind = "ROS 2 MCAP"

    def __init__(self, path: Path, file, schemas: dict, channels: list, chunks: list, counts: dict, span):
        self.path, self._file, self._schemas, self._channels = path, file, schemas, channels
        self._chunk_index, self._counts, self._span = chunks, counts, span
        self._reader = None

    @classmethod
    def of(cls, path: Path) -> _Mcap | None:
        if not path.is_file():
            return None
        file = open(path, "rb")
        try:
            found = _mcap_summary(file)
        except (struct.error, UnicodeDecodeError, ValueError, OSError):
            found = None
        if found is None:
            file.close()
            return None
        return cls(path, file, *found)

    @property
    def reader(self) -> _Rosbags:
        if self._reader is None:
            self._reader = _Rosbags(self.path, self.kind)
        return self._reader

    def topics(self) -> list[Topic]:
        by_name: dict[str, Topic] = {}
        for cid, topic, msgtype in self._channels:
            old = by_name.get(topic)
            n = self._counts.get(cid, 0) + (old.count if old else 0)
            by_name[topic] = Topic(topic, msgtype if old is None or old.msgtype == msgtype else "(mixed types)", n)
        return list(by_name.values())

    def span(self) -> tuple[float | None, float | None]:
        return self._span

    def definitions(self, topics: set[str]) -> Iterator[tuple[str, str, str, str, str]]:
        for cid, topic, msgtype in self._channels:
            if topic in topics:
                yield (topic, msgtype, "", *self._schemas.get(cid, ("", "")))

    def runs(self, topics: set[str]) -> Iterator[Run]:
        return _mcap_runs(self, {cid: t for cid, t, _ in self._channels if t in topics}, self._chunk_index,
                          self._file, topics)

    def raw(self, topics: set[str]) -> Iterator[tuple[str, str, int, bytes]]:
        return self.reader.raw(topics)

    def decode(self, raw, msgtype: str) -> object:
        return self.reader.decode(raw, msgtype)

    def close(self) -> None:
        if self._reader is not None:
            self._reader.close()
        self._file.close()


#: MCAP schema encodings as rosbags reads them (others it refuses: left to it)
_MCAP_FORMS = {"ros2msg": "msg", "ros2idl": "idl", "omgidl": "idl", "": ""}


def _mcap_summary(file):
    """``(definitions, channels, chunks, counts, span)`` from the summary section of the MCAP
    ``file`` as rosbags' reader takes them: definitions ``{channel: (form, text)}``, channels
    ``[(id, topic, type)]`` in file order, the chunk index (:class:`_McapChunk`), messages per
    channel and the time span in seconds; None where rosbags would read more than the summary
    (no summary, no statistics and no chunk index, statistics without schemas) or the file is not
    as it expects (rosbags then says why)."""
    u16, u32, u64 = struct.Struct("<H"), struct.Struct("<I"), struct.Struct("<Q")
    head = file.read(8 + 9)
    if len(head) < 17 or head[:8] != _MCAP_MAGIC or head[8] != 0x01:
        return None
    header = file.read(u64.unpack_from(head, 9)[0])
    if header[4: 4 + u32.unpack_from(header)[0]] != b"ros2":
        return None
    data_start = file.tell()
    file.seek(-37, 2)
    footer_start = file.tell()
    footer = file.read(37)
    if footer[-8:] != _MCAP_MAGIC or footer[:9] != b"\x02\x14" + bytes(7):
        return None
    summary_start = u64.unpack_from(footer, 9)[0]
    if not summary_start or not data_start <= summary_start <= footer_start:
        return None
    file.seek(summary_start)
    summary = file.read(footer_start - summary_start)

    def string(at):
        n = u32.unpack_from(summary, at)[0]
        if at + 4 + n > len(summary):
            raise ValueError("past the summary")
        return summary[at + 4: at + 4 + n].decode(), at + 4 + n

    schemas, channels, chunks, stats = {}, [], [], None
    pos = 0
    while pos + 9 <= len(summary):
        op, body = summary[pos], pos + 9
        end = body + u64.unpack_from(summary, pos + 1)[0]
        if op in (0x02, 0x0E):
            break
        if end > len(summary):
            return None
        if op == 0x03:
            name, at = string(body + 2)
            encoding, at = string(at)
            text, _ = string(at)
            if encoding not in _MCAP_FORMS:
                return None
            schemas[u16.unpack_from(summary, body)[0]] = (name, _MCAP_FORMS[encoding], text)
        elif op == 0x04:
            cid, sid = u16.unpack_from(summary, body)[0], u16.unpack_from(summary, body + 2)[0]
            topic, _ = string(body + 4)
            if all(cid != c for c, _, _ in channels):  # rosbags keeps a channel's first record
                channels.append((cid, topic, sid))
        elif op == 0x08:
            start, stop, offset = struct.unpack_from("<QQQ", summary, body)
            n = u32.unpack_from(summary, body + 32)[0]
            index = sorted((o, c) for c, o in struct.iter_unpack("<HQ", summary[body + 36: body + 36 + n]))
            at = body + 36 + n
            index_length = u64.unpack_from(summary, at)[0]
            compression, at = string(at + 8)
            packed, unpacked = struct.unpack_from("<QQ", summary, at)
            ends = [o for o, _ in index[1:]] + [offset + u64.unpack_from(summary, body + 24)[0] + index_length]
            counts = {c: (e - o - 15) // 16 for (o, c), e in zip(index, ends) if e - o - 15}
            chunks.append(_McapChunk(start, stop, offset, counts, compression, packed, unpacked))
        elif op == 0x0B:
            message_count, = u64.unpack_from(summary, body)
            start, stop = struct.unpack_from("<QQ", summary, body + 26)
            n = u32.unpack_from(summary, body + 42)[0]
            stats = (message_count, start, stop, dict(struct.iter_unpack("<HQ", summary[body + 46: body + 46 + n])))
        pos = end
    if stats is None:
        if not chunks:
            return None
        counts: dict[int, int] = {}
        for c in chunks:
            for cid, n in c.channel_count.items():
                counts[cid] = counts.get(cid, 0) + n
        stats = (sum(counts.values()), min(c.message_start_time for c in chunks),
                 max(c.message_end_time for c in chunks), counts)
    elif not schemas:
        return None
    message_count, start, stop, counts = stats
    typed = [(cid, topic, schemas[sid][0] if sid in schemas else "__schemaless__") for cid, topic, sid in channels]
    definitions = {cid: schemas[sid][1:] for cid, _, sid in channels if sid in schemas}
    span = (start / 1e9, stop / 1e9) if message_count else (None, None)
    return definitions, typed, chunks, counts, span


class _Ros1:
    """A ROS 1 bag: its index section read by :class:`Ros1Chunks` (connections, and where each
    chunk is and what it holds), its chunks listed by :func:`~.records.chunk_records` for
    :meth:`Bag.runs`. ``rosbags``' reader, whose opening reads every message's index entry (1.5 ms
    for 1,820 messages, a list entry each), opens only for what needs it: the messages one by one
    (:meth:`Bag.messages`), the bag's types, runs of chunks that overlap in time (which ``rosbags``
    merges), and :attr:`note`. When ``rosbags`` rejects the index, :class:`_Ros1FromChunks` does
    those instead, and :attr:`note` says so."""

    encoding = "ros1"

    def __init__(self, path: Path):
        self.path = path
        self._file = open(path, "rb")
        try:
            self._bag = Ros1Chunks(path, self._file)
        except BaseException:
            self._file.close()
            raise
        self._types = {conn.id: _ros2_name(conn.msgtype) for conn in self._bag.connections.values()}
        self._reader = None  # _Rosbags, or _Ros1FromChunks when rosbags rejects the index
        self._note = ""

    @property
    def reader(self):
        """What reads the messages one by one and deserialises them, opened on first use."""
        if self._reader is None:
            try:
                self._reader = _Rosbags(self.path, "ROS 1")
            except FormatError as e:
                self._reader = _Ros1FromChunks(self.path, self._bag, self._types)
                self._note = f"rosbags rejects its index ({_describe(e.__cause__)}); read from its chunk records"
        return self._reader

    @property
    def note(self) -> str:
        self.reader
        return self._note

    def topics(self) -> list[Topic]:
        counts = self._bag.counts()
        by_name: dict[str, Topic] = {}
        for conn in self._bag.connections.values():
            kind = self._types[conn.id]
            old = by_name.get(conn.topic)
            n = counts.get(conn.id, 0) + (old.count if old else 0)
            by_name[conn.topic] = Topic(conn.topic, kind if old is None or old.msgtype == kind else "(mixed types)", n)
        return list(by_name.values())

    def span(self) -> tuple[float | None, float | None]:
        chunks = [c for c in self._bag.chunks if c.counts]
        if not chunks:
            return None, None
        return min(c.start for c in chunks) / 1e9, max(c.end for c in chunks) / 1e9

    def definitions(self, topics: set[str]) -> Iterator[tuple[str, str, str, str, str]]:
        for c in self._bag.connections.values():
            if c.topic in topics:
                yield c.topic, self._types[c.id], c.md5sum, "msg", c.definition

    def raw(self, topics: set[str]) -> Iterator[tuple[str, str, int, bytes]]:
        return self.reader.raw(topics)

    def decode(self, raw, msgtype: str) -> object:
        return self.reader.decode(raw, msgtype)

    def runs(self, topics: set[str]) -> Iterator[Run]:
        topic_of = {c.id: c.topic for c in self._bag.connections.values() if c.topic in topics}
        chunks = sorted((c for c in self._bag.chunks if not set(topic_of).isdisjoint(c.counts)),
                        key=lambda c: c.position)
        if any(a.end > b.start for a, b in zip(chunks, chunks[1:])):
            yield from self.reader.runs(topics)
            return
        for data, records in self._bag.records_of(chunks):
            run = _chunk_run(data, records, topic_of, sort=True)
            if len(run):
                yield run

    def close(self) -> None:
        if self._reader is not None:
            self._reader.close()
        self._file.close()


class _Ros1FromChunks:
    """The messages of a ROS 1 bag whose index ``rosbags`` rejects, read from its chunks
    (:class:`Ros1Chunks`, in the order recorded), and its types from the connections' definitions."""

    encoding = "ros1"

    def __init__(self, path: Path, chunks: Ros1Chunks, types: dict[int, str]):
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore

        self.path, self._bag, self._types = path, chunks, types
        defined = {}
        for conn in self._bag.connections.values():
            try:
                defined.update(get_types_from_msg(conn.definition, types[conn.id]))
            except Exception as e:
                raise FormatError(path, f"connection {conn.id} ({conn.topic!r}): the definition of "
                                  f"{conn.msgtype} does not parse ({_describe(e)})") from e
        # Bags from before ROS C Turtle (2010) define Header as roslib/Header; "Header" in a
        # definition means std_msgs/Header to rosbags.
        if "roslib/msg/Header" in defined:
            defined.setdefault("std_msgs/msg/Header", defined["roslib/msg/Header"])
        self._typestore = get_typestore(Stores.EMPTY)
        self._typestore.register(defined)

    def raw(self, topics: set[str]) -> Iterator[tuple[str, str, int, bytes]]:
        conns = {c.id: c for c in self._bag.connections.values() if c.topic in topics}
        for conn, time_ns, raw in self._bag.messages(set(conns)):
            yield conns[conn].topic, self._types[conn], time_ns, raw

    def runs(self, topics: set[str]) -> Iterator[Run]:
        topic_of = {c.id: c.topic for c in self._bag.connections.values() if c.topic in topics}
        for data, records in self._bag.chunks_of(set(topic_of)):
            run = _chunk_run(data, records, topic_of, sort=False)
            if len(run):
                yield run

    def decode(self, raw, msgtype: str) -> object:
        return self._typestore.deserialize_ros1(raw, msgtype)

    def close(self) -> None:
        pass  # the file is _Ros1's


def _ros2_name(msgtype: str) -> str:
    """``pkg/Name`` → ``pkg/msg/Name`` (ROS 1 names in the ROS 2 form rosbags uses)."""
    parts = msgtype.split("/")
    return "/".join((parts[0], "msg", parts[1])) if len(parts) == 2 else msgtype


#: Largest runs :meth:`Bag.runs` makes of messages read one by one: messages, bytes
_RUN_MESSAGES, _RUN_BYTES = 64, 1 << 20


def _runs_of(messages) -> Iterator[Run]:
    """``(topic, time_ns, raw)`` in runs of :data:`_RUN_MESSAGES` (fewer past :data:`_RUN_BYTES`)."""
    slots: dict[str, int] = {}
    which, times, raws, held = [], [], [], 0
    for topic, time_ns, raw in messages:
        which.append(slots.setdefault(topic, len(slots)))
        times.append(time_ns)
        raws.append(raw)
        held += len(raw)
        if len(raws) == _RUN_MESSAGES or held >= _RUN_BYTES:
            yield Run(tuple(slots), np.array(which, np.intp), np.array(times, np.int64), Raws.of(raws))
            which, times, raws, held = [], [], [], 0
    if raws:
        yield Run(tuple(slots), np.array(which, np.intp), np.array(times, np.int64), Raws.of(raws))


def _chunk_run(data, records, topic_of: dict[int, str], sort: bool) -> Run:
    """The messages of a chunk (``data``, its :class:`~.records.Records`) on the connections
    ``topic_of`` names, in the order recorded or, when ``sort``, by time (ties in the order
    recorded, as ``rosbags`` gives them)."""
    topics = tuple(dict.fromkeys(topic_of.values()))
    ids = np.array(sorted(topic_of), dtype=np.int64)
    slots = np.array([topics.index(topic_of[i]) for i in ids.tolist()], dtype=np.intp)
    at = np.minimum(np.searchsorted(ids, records.conn), len(ids) - 1)
    rows = np.flatnonzero(ids[at] == records.conn)
    if sort:
        rows = rows[np.argsort(records.time_ns[rows], kind="stable")]
    return Run(topics, slots[at[rows]], records.time_ns[rows],
               Raws(np.frombuffer(data, np.uint8), records.start[rows], records.size[rows]))


def _mcap_runs(source, topic_of: dict[int, str], chunks, file, topics: set[str]) -> Iterator[Run]:
    """:meth:`Bag.runs` of an MCAP file: the channels ``topic_of`` names (id → topic), a chunk at a
    time (``chunks``: its chunk index, whose items have rosbags' ``ChunkInfo`` fields, read from
    ``file``), or, where the file has no chunks or they overlap in time (then rosbags merges their
    messages), runs of ``source.raw(topics)``'s messages."""
    if not topic_of:
        return
    infos = sorted((c for c in chunks if any(c.channel_count.get(i) for i in topic_of)),
                   key=lambda c: c.chunk_start_offset)
    if not chunks or any(a.message_end_time > b.message_start_time for a, b in zip(infos, infos[1:])):
        yield from _runs_of((topic, time_ns, raw) for topic, _, time_ns, raw in source.raw(topics))
        return
    for c in infos:
        where = f"chunk at byte {c.chunk_start_offset}"
        try:
            data = _mcap_chunk(file, c)
        except Exception as e:  # rosbags' decompressors and checks raise their own errors
            raise FormatError(source.path, f"{where}: cannot read it ({_describe(e)})") from e
        run = _chunk_run(data, chunk_records(data, "mcap", source.path, where), topic_of, sort=True)
        if len(run):
            yield run


def _mcap_chunk(file, chunk):
    """The records of an MCAP chunk record (opcode, length, start and end times, size; the CRC at
    byte 33, then the compression's name and the compressed records), unpacked and checked by
    ``rosbags``: bytes, or for a chunk stored uncompressed a read-only view of the file
    (:func:`~.records.read_span`)."""
    from rosbags.rosbag2.storage_mcap import decompress

    file.seek(chunk.chunk_start_offset + 9 + 24)
    crc = int.from_bytes(_read_exact(file, 4), "little")
    data = read_span(file, chunk.chunk_start_offset + 9 + 40 + len(chunk.compression), chunk.compressed_size)
    if len(data) != chunk.compressed_size:
        raise EOFError(f"the file ends {chunk.compressed_size - len(data)} bytes early")
    return decompress(data, chunk.compression, chunk.uncompressed_size, crc)


def _read_exact(file, n: int) -> bytes:
    data = file.read(n)
    if len(data) != n:
        raise EOFError(f"the file ends {n - len(data)} bytes early")
    return data


def _describe(e: BaseException | None) -> str:
    """An exception from inside rosbags in a few words: its type, and its message if it has one."""
    if e is None:
        return "no reason given"
    return f"{type(e).__name__}: {e}" if str(e) else type(e).__name__
