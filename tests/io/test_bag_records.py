"""The record layer: chunks listed by :func:`occmap.io.bags.records.chunk_records`, and the runs
:meth:`Bag.runs` makes of them, checked against rosbags' own reading of bags its writers wrote."""

from __future__ import annotations

import itertools
import struct

import numpy as np
import pytest

from occmap.errors import FormatError
from occmap.io.bags import open_bag
from occmap.io.bags.records import MAP_BYTES, Raws, chunk_records, read_span

rosbags = pytest.importorskip("rosbags")
from rosbags.rosbag1 import Writer as Writer1  # noqa: E402
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer as Writer2  # noqa: E402

from bag_writing import SCAN, TF, Msgs, quat_xyzw_of_yaw, standard_store  # noqa: E402


@pytest.fixture(scope="module")
def carmen_scans(data_dir):
    from occmap.io.carmen import iter_carmen

    return list(itertools.islice(iter_carmen(data_dir / "carmen" / "intel-corrected.log.gz"), 60))


def write(path, kind, scans, compression=None, widen=1, back=0.0):
    """The scans as /scan and their poses as /tf (odom -> laser) in a bag of ``kind`` ("ros1",
    "mcap") written by rosbags, in several chunks; ``widen`` repeats each scan's ranges (bigger
    messages: MCAP's writer cuts chunks at 1 MiB), ``back`` seconds the second half's record times
    go back by (chunks that overlap in time)."""
    ts = standard_store(kind)
    m = Msgs(ts)
    if kind == "ros1":
        path = path.with_suffix(".bag")
        writer, serialize = Writer1(path), ts.serialize_ros1
        if compression:
            writer.set_compression(getattr(Writer1.CompressionFormat, compression))
        writer.chunk_threshold = 16384  # several chunks (rosbags has no setter for it)
    else:
        writer, serialize = Writer2(path, version=9, storage_plugin=StoragePlugin.MCAP), ts.serialize_cdr
        if compression:
            writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    with writer:
        tf = writer.add_connection("/tf", TF, typestore=ts)
        scan = writer.add_connection("/scan", SCAN, typestore=ts)
        for k, s in enumerate(scans):
            time = round((s.stamp - (back if k >= len(scans) // 2 else 0.0)) * 1e9)
            x, y, theta = s.pose
            writer.write(tf, time, serialize(m.tf([m.transform(s.stamp, "odom", "laser", (x, y, 0.0),
                                                                quat_xyzw_of_yaw(theta))]), TF))
            writer.write(scan, time, serialize(m.laser_scan(s.stamp, "laser", np.tile(s.ranges, widen), -1.5, 0.0175,
                                                            0.0, 81.0), SCAN))
    return path


def flattened(runs):
    return [(run.topics[w], t, run.raws[i].tobytes())
            for run in runs for i, (w, t) in enumerate(zip(run.which.tolist(), run.times_ns.tolist()))]


@pytest.mark.parametrize("kind, compression, widen", [("ros1", None, 1), ("ros1", "BZ2", 1), ("ros1", "LZ4", 1),
                                                      ("mcap", None, 120), ("mcap", "zstd", 120)])
def test_runs_are_rosbags_messages(tmp_path, carmen_scans, kind, compression, widen):
    """Read by chunks (the kernel lists each chunk's records), a bag gives what rosbags' reader
    gives message by message: topics, record times and bytes, in its order; for all topics and
    for one, over several chunks."""
    path = write(tmp_path / "b", kind, carmen_scans, compression, widen)
    with open_bag(path) as bag:
        for topics in (["/scan", "/tf"], ["/scan"], ["/tf"]):
            runs = list(bag.runs(topics))
            assert len(runs) > 2  # chunks
            assert bag._source._reader is None  # rosbags' reader is not opened for the runs
            want = [(m.topic, m.time_ns, m.raw) for m in bag.messages(topics)]
            assert flattened(runs) == want and len(want) == len(carmen_scans) * len(topics)
            bag._source._reader.close()
            bag._source._reader = None


@pytest.mark.parametrize("kind", ("ros1", "mcap"))
def test_chunks_that_overlap_in_time_are_read_as_rosbags_merges_them(tmp_path, carmen_scans, kind):
    path = write(tmp_path / "b", kind, carmen_scans, widen=1 if kind == "ros1" else 120, back=30.0)
    with open_bag(path) as bag:
        got = flattened(bag.runs(["/scan", "/tf"]))
        assert bag._source._reader is not None  # rosbags' reader merged them
        want = [(m.topic, m.time_ns, m.raw) for m in bag.messages()]
        assert got == want
        assert [t for _, t, _ in want] == sorted(t for _, t, _ in want)  # rosbags' merge, not the chunks' order


@pytest.mark.parametrize("compression, back", [(None, 0.0), ("zstd", 0.0), (None, 30.0)])
def test_an_mcap_files_summary_read_by_occmap_is_what_rosbags_reads(tmp_path, carmen_scans, compression, back):
    """A lone MCAP file is opened from its summary section by occmap (rosbags' reader not opened):
    the same topics, counts, time span and type definitions as rosbags' reader gives. A file
    whose footer points to no summary is left to rosbags (which scans it), with the same result."""
    from occmap.io.bags.bag import _Mcap, _Rosbags

    folder = write(tmp_path / "b", "mcap", carmen_scans, compression, widen=120, back=back)
    file = next(folder.glob("*.mcap"))
    theirs = _Rosbags(file, "ROS 2 MCAP")
    with open_bag(folder) as bag:
        assert isinstance(bag._source, _Mcap) and bag._source._reader is None
        assert sorted(bag.topics.values()) == sorted(theirs.topics())
        assert (bag.start, bag.end) == theirs.span() and bag.start is not None
        topics = {"/scan", "/tf"}
        assert list(bag._source.definitions(topics)) == list(theirs.definitions(topics))
        assert len(bag._source._chunk_index) > 2
    theirs.close()
    data = bytearray(file.read_bytes())
    data[-37 + 9: -37 + 17] = bytes(8)  # the footer's summary start: none
    (tmp_path / "bare.mcap").write_bytes(bytes(data))
    with open_bag(tmp_path / "bare.mcap") as bare, open_bag(folder) as bag:
        assert isinstance(bare._source, _Rosbags)
        assert bare.topics == bag.topics and (bare.start, bare.end) == (bag.start, bag.end)
        if not back:  # rosbags reads an unindexed file only in time order
            assert flattened(bare.runs(["/scan", "/tf"])) == flattened(bag.runs(["/scan", "/tf"]))


def ros1_record(fields: dict, data: bytes) -> bytes:
    header = b"".join(struct.pack("<I", len(k) + 1 + len(v)) + k + b"=" + v for k, v in fields.items())
    return struct.pack("<I", len(header)) + header + struct.pack("<I", len(data)) + data


def ros1_message(conn: int, sec: int, nsec: int, data: bytes) -> bytes:
    return ros1_record({b"op": b"\x02", b"conn": struct.pack("<I", conn), b"time": struct.pack("<II", sec, nsec)},
                       data)


def mcap_message(channel: int, time_ns: int, data: bytes) -> bytes:
    body = struct.pack("<HIQQ", channel, 7, time_ns, time_ns + 5) + data
    return b"\x05" + struct.pack("<Q", len(body)) + body


def test_records_of_hand_made_chunks():
    connection = ros1_record({b"op": b"\x07", b"conn": struct.pack("<I", 3), b"topic": b"/a=b"}, b"definition")
    first, second = ros1_message(3, 10, 20, b"hello"), ros1_message(9, 11, 0, b"")
    ros1 = connection + first + second
    r = chunk_records(ros1, "ros1", "x.bag", "chunk")
    assert r.conn.tolist() == [3, 9] and r.time_ns.tolist() == [10_000_000_020, 11_000_000_000]
    assert ros1[r.start[0]: r.start[0] + r.size[0]] == b"hello" and r.size[1] == 0
    assert r.start[1] == len(ros1)  # an empty message at the very end
    schema = b"\x03" + struct.pack("<Q", 4) + b"abcd"
    mcap = schema + mcap_message(2, 5, b"xyz") + mcap_message(1, 4, b"")
    r = chunk_records(mcap, "mcap", "x.mcap", "chunk")
    assert r.conn.tolist() == [2, 1] and r.time_ns.tolist() == [5, 4] and r.size.tolist() == [3, 0]
    assert mcap[r.start[0]: r.start[0] + 3] == b"xyz"
    assert chunk_records(b"", "mcap", "x.mcap", "chunk").conn.shape == (0,)


GOOD = ros1_message(1, 1, 0, b"ab")  # 48 bytes


@pytest.mark.parametrize("kind, chunk, problem, byte", [
    ("ros1", GOOD + ros1_message(1, 2, 0, b"cd")[:-1], "cut short", 48),
    ("ros1", GOOD[:10], "cut short", 0),
    ("ros1", GOOD + ros1_record({b"op": b"\x02", b"time": bytes(8)}, b""), "lacks", 48),
    ("ros1", GOOD + ros1_record({b"op": b"\x05"}, b""), "neither message data", 48),
    ("ros1", struct.pack("<II", 6, 2) + b"op" + struct.pack("<I", 0), "no '='", 0),
    ("mcap", mcap_message(1, 1, b"abc") + b"\x05" + struct.pack("<Q", 10) + bytes(10), "shorter than", 34),
    ("mcap", mcap_message(1, 1, b"abc")[:-2], "cut short", 0),
    ("mcap", mcap_message(1, 1, b"") + b"\x05\xff\xff\xff\xff\xff\xff\xff\xff", "cut short", 31),
])
def test_corrupt_chunks_name_the_file_the_chunk_and_the_byte(kind, chunk, problem, byte):
    with pytest.raises(FormatError, match=f"f.bag: chunk at byte 99: .*{problem}.* at byte {byte} of its "):
        chunk_records(chunk, kind, "f.bag", "chunk at byte 99")


@pytest.mark.parametrize("kind", ("ros1", "mcap"))
def test_a_corrupt_record_in_a_bag_raises_naming_the_file_and_its_chunk(tmp_path, carmen_scans, kind):
    path = write(tmp_path / "b", kind, carmen_scans[:5])
    file = path if kind == "ros1" else next(path.glob("*.mcap"))
    raw = bytearray(file.read_bytes())
    with open_bag(path) as bag:
        message = next(bag.messages("/scan")).raw
    at = bytes(raw).index(message)  # the first scan's bytes; its record's length field before them
    if kind == "ros1":
        raw[at - 4: at] = struct.pack("<I", 1 << 30)
    else:
        raw[at - 30: at - 22] = struct.pack("<Q", 1 << 40)
    file.write_bytes(bytes(raw))
    with open_bag(path) as bag:
        with pytest.raises(FormatError, match=rf"{file}: chunk at byte \d+: a record is cut short .* at byte \d+ of its"):
            list(bag.runs(["/scan"]))


def test_raws_take_join_and_concat():
    raws = Raws.of([b"ab", b"", b"cde", b"f"])
    assert [raws[i].tobytes() for i in range(len(raws))] == [b"ab", b"", b"cde", b"f"]
    picked = raws.take(np.array([3, 0, 2]))
    assert picked.joined().tobytes() == b"fabcde"
    assert raws.take(slice(1, 3)).joined().base is not None  # in a row already: a view
    both = Raws.concat([picked, raws.take(slice(0, 1))])
    assert [both[i].tobytes() for i in range(len(both))] == [b"f", b"ab", b"cde", b"ab"]
    own = raws.take(slice(2, 4)).compact()  # in a buffer of its own: the chunk's can go
    assert [own[i].tobytes() for i in range(2)] == [b"cde", b"f"] and len(own.buf) == 4
    assert not np.shares_memory(own.buf, raws.buf)


def test_read_span_maps_long_spans_and_reads_short_ones(tmp_path):
    """A span of a file from MAP_BYTES on is a read-only view of a map of its pages (from any
    byte, not only a page's first), a shorter one is read; both are the file's bytes and stay so
    once the file is closed, and a span past the file's end gives the bytes it has."""
    data = np.random.default_rng(1).integers(0, 256, 3 * MAP_BYTES, np.uint8).tobytes()
    path = tmp_path / "f"
    path.write_bytes(data)
    with open(path, "rb") as f:
        long, short, tail = read_span(f, 5000, 2 * MAP_BYTES), read_span(f, 7, 100), read_span(f, len(data) - 10, MAP_BYTES)
    assert isinstance(long, memoryview) and long.readonly and isinstance(short, bytes)
    assert bytes(long) == data[5000: 5000 + 2 * MAP_BYTES] and short == data[7:107] and tail == data[-10:]


@pytest.mark.parametrize("kind, widen", [("ros1", 1), ("mcap", 120)])
def test_what_a_stream_hands_out_stays_as_it_was_while_it_reads_on(tmp_path, carmen_scans, kind, widen):
    """Runs (views of their chunk) and the scan stacks a source decodes from them keep their
    contents while the next chunks are read and after the bag is closed: no buffer is reused or
    let go under what was handed out."""
    from occmap.scan import stack_scans
    from occmap.sources import BagScans

    path = write(tmp_path / "b", kind, carmen_scans, widen=widen)
    with open_bag(path) as bag:
        runs = [(run, flattened([run])) for run in bag.runs(["/scan", "/tf"])]
    assert len(runs) > 2 and all(flattened([run]) == seen for run, seen in runs)
    stacks = [(s, s.ranges.copy(), s.poses.copy()) for s in BagScans(path).stacks()]
    assert len(stacks) > 1
    for s, ranges, poses in stacks:
        np.testing.assert_array_equal(s.ranges, ranges)
        np.testing.assert_array_equal(s.poses, poses)
    whole = np.concatenate([s.ranges for s, _, _ in stacks])
    np.testing.assert_array_equal(whole, np.tile(stack_scans(carmen_scans).ranges.astype(np.float32), widen))
