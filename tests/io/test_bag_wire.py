"""occmap's own decoders of LaserScan, TFMessage and Odometry (occmap.io.bags.wire and the decoders
on it) against rosbags' deserialisation of the very bytes rosbags serialised: ROS 1, little- and
big-endian CDR, frame names of every length modulo 8 (so every CDR alignment case occurs), empty
and non-empty sequences; and every truncation of a message, which must raise an OccmapError."""

from __future__ import annotations

import math

import numpy as np
import pytest

from occmap.errors import FormatError, OccmapError
from occmap.io.bags import decode_laser_scan, decode_odometry, decode_tf_message, ros_poses
from occmap.io.bags.laserscan import decode_laser_scans
from occmap.io.bags.records import Raws
from occmap.io.bags.wire import Wire, column, stamps

rosbags = pytest.importorskip("rosbags")
from rosbags.typesys import Stores, get_types_from_msg, get_typestore  # noqa: E402

from bag_writing import ODOM, SCAN, TF, Msgs  # noqa: E402

# (encoding, little-endian): ROS 1, and CDR in both byte orders
ENCODINGS = [("ros1", True), ("cdr", True), ("cdr", False)]
FRAMES = ["", "/l", "ab", "odo", "base", "laser", "/laser", "sensor7", "velodyne"]  # lengths 0..8


def store(encoding):
    if encoding == "ros1":
        ts = get_typestore(Stores.ROS1_NOETIC)
        ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", TF))
        return Msgs(ts)
    return Msgs(get_typestore(Stores.LATEST))


def serialise(m, msg, msgtype, encoding, little):
    if encoding == "ros1":
        return bytes(m.ts.serialize_ros1(msg, msgtype))
    raw = bytes(m.ts.serialize_cdr(msg, msgtype, little_endian=little))
    assert raw[1] == little  # the encapsulation header says the byte order
    return raw


def theirs(m, raw, msgtype, encoding):
    return (m.ts.deserialize_ros1 if encoding == "ros1" else m.ts.deserialize_cdr)(raw, msgtype)


def stamp_of(header):
    return header.stamp.sec + header.stamp.nanosec * 1e-9


def scan_message(m, frame, n, intensities):
    rng = np.random.default_rng(n)
    msg = m.laser_scan(1_283_000_000.123456789, frame, rng.uniform(0.1, 30.0, n), -2.35, 0.0061, 0.02, 30.0)
    if intensities:
        msg.intensities = rng.uniform(0, 1000, n).astype(np.float32)
    return msg


@pytest.mark.parametrize("encoding,little", ENCODINGS)
def test_laser_scan_equals_rosbags(encoding, little):
    m = store(encoding)
    for frame in FRAMES:
        for n, intensities in ((0, False), (1, True), (5, False), (181, True)):
            raw = serialise(m, scan_message(m, frame, n, intensities), SCAN, encoding, little)
            ref = theirs(m, raw, SCAN, encoding)
            d = decode_laser_scan(raw, encoding)
            assert d.frame_id == frame.lstrip("/")
            assert d.scan.stamp == stamp_of(ref.header)
            np.testing.assert_array_equal(d.scan.ranges, ref.ranges.astype(np.float64))
            np.testing.assert_array_equal(d.scan.angles, ref.angle_min + ref.angle_increment * np.arange(n))
            assert d.scan.max_range == ref.range_max and d.scan.ranges.dtype == np.float64

            # the cursor reads every field where rosbags does, and ends at the message's end
            w = Wire(raw, encoding, "scan")
            assert w.header() == (stamp_of(ref.header), frame.lstrip("/"))
            assert w.values("7f", "scalars") == (ref.angle_min, ref.angle_max, ref.angle_increment,
                                                 ref.time_increment, ref.scan_time, ref.range_min, ref.range_max)
            np.testing.assert_array_equal(w.array("f4", "ranges"), ref.ranges)
            np.testing.assert_array_equal(w.array("f4", "intensities"), ref.intensities)
            assert w.pos == len(raw)


@pytest.mark.parametrize("encoding,little", ENCODINGS)
def test_many_laser_scans_decode_as_each_alone(encoding, little):
    """Scans decoded together, interleaving layouts (two frames, three beam counts, ranges below
    range_min, a changed angle_min), are each message decoded alone, in message order."""
    m = store(encoding)
    rng = np.random.default_rng(3)
    raws = []
    for k in range(23):
        frame, n = ("laser", 181) if k % 3 else ("/front_laser", 5 + 2 * (k % 2))
        ranges = rng.uniform(0.1, 30.0, n)
        ranges[3] = 0.015 if k % 4 == 2 else ranges[3]  # below range_min: NaN
        msg = m.laser_scan(1_283_000_000.25 + 0.025 * k, frame, ranges,
                           -2.35 + (0.01 if k == 7 else 0.0), 0.0061, 0.02, 30.0 + (k == 4))
        raws.append(serialise(m, msg, SCAN, encoding, little))
    stack, beams, frames = decode_laser_scans(raws, encoding)
    for k, raw in enumerate(raws):
        alone = decode_laser_scan(raw, encoding)
        n = len(alone.scan.ranges)
        assert beams[k] == n and frames[k] == alone.frame_id and stack.stamps[k] == alone.scan.stamp
        assert stack.max_ranges[k] == alone.scan.max_range
        np.testing.assert_array_equal(stack.ranges[k, :n], alone.scan.ranges)
        assert np.isnan(stack.ranges[k, n:]).all()
        np.testing.assert_array_equal(stack.angles[k, :n], alone.scan.angles)
    assert np.isnan(stack.ranges[2::4, 3]).all() and not np.isnan(stack.ranges[1::4, 3]).any()
    with pytest.raises(FormatError, match="scan 5: .*range_max"):
        bad = raws[:5] + [serialise(m, m.laser_scan(1.0, "laser", np.ones(181), -2.35, 0.0061, 0.02, -1.0), SCAN,
                                    encoding, little)]
        decode_laser_scans(bad, encoding, lambda i: f"scan {i}")


def tf_message(m, frames):
    transforms = []
    for k, (parent, child) in enumerate(frames):
        yaw = 0.3 * k - 1.0
        q = (0.1 * k, -0.2, math.sin(yaw / 2), math.cos(yaw / 2))  # not of unit norm, as recorded
        transforms.append(m.transform(1_700_000_000.5 + k * 0.25, parent, child, (1.5 * k, -2.0, 0.125 * k), q))
    return m.tf(transforms)


@pytest.mark.parametrize("encoding,little", ENCODINGS)
def test_tf_message_equals_rosbags(encoding, little):
    m = store(encoding)
    for shift in range(8):  # child frames of every length modulo 8 after parents of every length
        frames = [(FRAMES[(k + shift) % 9], FRAMES[(3 * k + shift + 1) % 9] + "_c") for k in range(6)]
        raw = serialise(m, tf_message(m, frames), TF, encoding, little)
        ref = theirs(m, raw, TF, encoding).transforms
        d = decode_tf_message(raw, encoding)
        assert d.parents == [t.header.frame_id.lstrip("/") for t in ref]
        assert d.children == [t.child_frame_id.lstrip("/") for t in ref]
        np.testing.assert_array_equal(d.stamps, [stamp_of(t.header) for t in ref])
        tr = [(t.transform.translation.x, t.transform.translation.y, t.transform.translation.z) for t in ref]
        q = [(t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z, t.transform.rotation.w)
             for t in ref]
        np.testing.assert_array_equal(d.translations, tr)
        np.testing.assert_array_equal(d.quaternions_xyzw, q)
    empty = decode_tf_message(serialise(m, m.tf([]), TF, encoding, little), encoding)
    assert empty.parents == [] and empty.translations.shape == (0, 3) and empty.quaternions_xyzw.shape == (0, 4)


@pytest.mark.parametrize("encoding,little", ENCODINGS)
def test_odometry_equals_rosbags(encoding, little):
    m = store(encoding)
    for parent, child in zip(FRAMES, reversed(FRAMES)):
        msg = m.odometry(1_600_000_000.75, parent, child or "c", (3.0, -4.5, 0.25), (0.0, 0.0, 0.6, 0.8))
        raw = serialise(m, msg, ODOM, encoding, little)
        ref = theirs(m, raw, ODOM, encoding)
        stamp, pose = decode_odometry(raw, encoding)
        p, o = ref.pose.pose.position, ref.pose.pose.orientation
        assert stamp == stamp_of(ref.header)
        np.testing.assert_array_equal(pose.matrix, ros_poses([p.x, p.y, p.z], [o.x, o.y, o.z, o.w]).matrix[0])


def messages(encoding, little):
    m = store(encoding)
    return [(SCAN, decode_laser_scan, serialise(m, scan_message(m, "laser", 3, True), SCAN, encoding, little)),
            (TF, decode_tf_message, serialise(m, tf_message(m, [("odom", "base_link"), ("base_link", "laser")]), TF,
                                              encoding, little)),
            (ODOM, decode_odometry, serialise(m, m.odometry(5.0, "odom", "base", (1, 2, 3), (0, 0, 0, 1)), ODOM,
                                              encoding, little))]


@pytest.mark.parametrize("encoding,little", ENCODINGS)
def test_every_truncation_raises_format_error(encoding, little):
    for msgtype, decode, raw in messages(encoding, little):
        decode(raw, encoding, "whole")
        for cut in range(len(raw)):
            with pytest.raises(FormatError, match=f"{msgtype} cut at {cut}: ") as e:
                decode(raw[:cut], encoding, f"{msgtype} cut at {cut}")
            assert ("field " in str(e.value)) or ("CDR encapsulation" in str(e.value) and cut < 4), str(e.value)


@pytest.mark.parametrize("encoding,little", ENCODINGS)
def test_corrupt_lengths_and_text(encoding, little):
    """A length or count of 2³² - 1, or one byte too many, and a frame that is not UTF-8: an
    OccmapError naming the field, and nothing allocated for the count."""
    order = "little" if little else "big"
    for msgtype, decode, raw in messages(encoding, little):
        # a TFMessage starts with its count of transforms; the others with a Header, whose
        # frame's length follows ROS 1's seq and stamp, or CDR's encapsulation and the stamp
        at, field = (0 if encoding == "ros1" else 4, "transforms") if msgtype == TF else (12, "header.frame_id")
        for length in (2**32 - 1, len(raw)):
            with pytest.raises(FormatError, match=f"field {field}"):
                decode(raw[:at] + length.to_bytes(4, order) + raw[at + 4:], encoding, "msg")
        if msgtype == TF:
            continue
        bad = bytearray(raw)
        bad[at + 4] = 0xFF  # the frame's first byte
        with pytest.raises(FormatError, match="header.frame_id: .* is not UTF-8"):
            decode(bytes(bad), encoding, "msg")


def test_encapsulation_and_encoding_names():
    m = store("cdr")
    raw = serialise(m, scan_message(m, "laser", 3, False), SCAN, "cdr", True)
    for head in (b"\x00\x02", b"\x01\x01", b"\x00\x07"):  # PL_CDR, nonsense, XCDR2: not read
        with pytest.raises(FormatError, match="CDR encapsulation"):
            decode_laser_scan(head + raw[2:], "cdr", "scan")
    with pytest.raises(OccmapError, match="encoding 'json'"):
        decode_laser_scan(raw, "json", "scan")


def test_column_reads_messages_where_they_lie_as_numpy_does():
    """column() and stamps() read a field of messages scattered in one buffer (a chunk's, with
    other records between them) as NumPy reads each message alone, in both byte orders; a message
    too short for the bytes read is refused rather than read past."""
    rng = np.random.default_rng(5)
    size, count = 48, 37
    gaps = rng.integers(0, 23, count)  # odd offsets too: nothing is aligned
    starts = np.cumsum(gaps + size) - size
    buf = rng.integers(0, 256, int(starts[-1]) + size + 7, dtype=np.uint8)
    buf.setflags(write=False)
    raws = Raws(buf, starts.astype(np.int64), np.full(count, size, np.int64))
    for order in "<>":
        for kind, n in (("f4", 5), ("f8", 3), ("i4", 4), ("u4", 2)):
            at = 7
            got = column(raws, at, order + kind, n)
            want = np.array([np.frombuffer(raws[i], order + kind, n, at) for i in range(count)], np.float64)
            assert got.dtype == np.float64 and got.shape == (count, n)
            np.testing.assert_array_equal(got, want)  # NaN bit patterns compare equal as NaN
        sec = np.array([np.frombuffer(raws[i], order + "i4", 1, 11)[0] for i in range(count)])
        nsec = np.array([np.frombuffer(raws[i], order + "u4", 1, 15)[0] for i in range(count)])
        np.testing.assert_array_equal(stamps(raws, 11, order), sec + nsec * 1e-9)
    short = Raws(buf, starts.astype(np.int64), np.where(np.arange(count) == 9, 20, size))
    with pytest.raises(OccmapError, match="message 9 is 20 bytes; 16 are read from byte 7"):
        column(short, 7, "<f4", 4)
