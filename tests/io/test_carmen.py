"""CARMEN log reader: real logs (counts, first line, angles, wrapping, compression) and synthetic
files (malformed lines, lenient mode, empty file, ROBOTLASER1, PARAM max range, stack_scans)."""

from __future__ import annotations

import bz2
import gzip
import itertools
import lzma
import math
import shutil

import numpy as np
import pytest

from occmap.errors import FormatError, InvalidArgumentError, OccmapError
from occmap.io.carmen import (
    DEFAULT_MAX_RANGE,
    TYPICAL_NO_RETURN,
    CarmenStats,
    flaser_angles,
    iter_carmen,
    laser_offset,
    read_carmen,
)
from occmap.scan import LaserScan, stack_scans

PI = np.pi

REAL = {
    # file: (scans, beams, max range inferred)
    "intel-corrected.log.gz": (910, 180, DEFAULT_MAX_RANGE),
    "freiburg-079-corrected.log.gz": (4791, 360, 80.99),  # PARAM robot_front_laser_max 80.99
    "csail-corrected.log.gz": (406, 361, 50.0),  # PARAM robot_front_laser_max 50
    "intel-raw.clf.bz2": (13631, 180, DEFAULT_MAX_RANGE),
}


@pytest.fixture(scope="module")
def logs(data_dir):
    return {name: read_carmen(data_dir / "carmen" / name) for name in REAL}


def _first_line(path, kind="FLASER"):
    opener = bz2.open if str(path).endswith(".bz2") else gzip.open
    with opener(path, "rt") as f:
        for line in f:
            if line.startswith(kind + " "):
                return line.split()
    raise AssertionError("no scan line")


# ---------------------------------------------------------------------------------------- real data


@pytest.mark.parametrize("name", list(REAL))
def test_real_log_counts_and_shapes(logs, name):
    count, beams, max_range = REAL[name]
    log = logs[name]
    assert len(log.scans) == count
    assert log.skipped_malformed == 0 and log.skipped_unknown == 0
    assert log.skipped_other > 0  # ODOM / PARAM / comments
    assert all(len(s) == beams and s.angles.shape == (beams,) for s in log.scans)
    assert all(s.max_range == max_range for s in log.scans)
    # the no-return codes in these logs (81.83 / 81.91) lie at or beyond the inferred max range,
    # and the real readings below it
    r = np.concatenate([s.ranges for s in log.scans])
    codes = np.isin(r, [81.83, 81.91])
    assert codes.any() and bool(np.all(r[codes] >= max_range))
    assert float(r[~codes].max()) < max_range


@pytest.mark.parametrize("name", list(REAL))
def test_first_scan_equals_first_flaser_line(logs, data_dir, name):
    tok = _first_line(data_dir / "carmen" / name)
    n = int(tok[1])
    s = logs[name].scans[0]
    np.testing.assert_array_equal(s.ranges, np.array(tok[2 : 2 + n], dtype=float))
    x, y, th, ox, oy, oth = (float(v) for v in tok[2 + n : 8 + n])
    assert s.pose[0] == x and s.pose[1] == y
    assert math.isclose(math.remainder(s.pose[2] - th, 2 * PI), 0.0, abs_tol=1e-12)
    np.testing.assert_allclose(s.odom, [ox, oy, math.remainder(oth, 2 * PI)], atol=1e-12)
    assert s.stamp == float(tok[-1])  # the logger timestamp


@pytest.mark.parametrize("name", list(REAL))
def test_beam_angles(logs, name):
    n = REAL[name][1]
    a = logs[name].scans[0].angles
    assert a[0] == -PI / 2
    if n in (180, 360):  # half-open fan [-pi/2, pi/2)
        np.testing.assert_allclose(np.diff(a), PI / n, rtol=1e-12)
        assert a[-1] < PI / 2 and math.isclose(a[-1], PI / 2 - PI / n)
    else:  # closed fan [-pi/2, pi/2]
        np.testing.assert_allclose(np.diff(a), PI / (n - 1), rtol=1e-12)
        assert math.isclose(a[-1], PI / 2)
    # one shared, read-only angle array per log
    assert all(s.angles is a for s in logs[name].scans)
    assert not a.flags.writeable


def test_thetas_wrapped(logs, data_dir):
    for log in logs.values():
        th = np.array([s.pose[2] for s in log.scans])
        assert np.all(th > -PI) and np.all(th <= PI)
    # csail's raw thetas go well past pi; the wrapped ones agree modulo 2 pi
    with gzip.open(data_dir / "carmen" / "csail-corrected.log.gz", "rt") as f:
        raw = [float(t[4 + int(t[1])]) for t in (ln.split() for ln in f) if t and t[0] == "FLASER"]
    raw = np.array(raw)
    assert raw.max() > 10.0
    th = np.array([s.pose[2] for s in logs["csail-corrected.log.gz"].scans])
    np.testing.assert_allclose(np.remainder(th - raw + PI, 2 * PI) - PI, 0.0, atol=1e-9)


def test_params_collected(logs):
    assert logs["freiburg-079-corrected.log.gz"].params["robot_front_laser_max"] == "80.99"
    assert logs["intel-corrected.log.gz"].params["robot_frontlaser_offset"] == "0.0"


def test_stack_real_log(logs):
    log = logs["intel-corrected.log.gz"]
    poses, ranges, angles, max_ranges, stamps = stack_scans(log.scans)
    assert poses.shape == (910, 3) and ranges.shape == (910, 180) and angles.shape == (180,)
    assert max_ranges.shape == (910,) and stamps.shape == (910,)
    np.testing.assert_array_equal(ranges[17], log.scans[17].ranges)
    np.testing.assert_array_equal(poses[17], log.scans[17].pose)
    assert stamps[17] == log.scans[17].stamp


def test_compressions_read_identically(data_dir, tmp_path):
    """The same 40 lines as plain, gzip, bzip2 and xz, under misleading names: same scans."""
    with gzip.open(data_dir / "carmen" / "freiburg-079-corrected.log.gz", "rb") as f:
        head = b"".join(f.readline() for _ in range(400))
    files = {
        "plain.gz": head,  # plain text with a .gz name: detected by content, not by name
        "a.log": gzip.compress(head),
        "b.txt": bz2.compress(head),
        "c.log": lzma.compress(head),
    }
    results = []
    for name, data in files.items():
        (tmp_path / name).write_bytes(data)
        results.append(read_carmen(tmp_path / name))
    ref = results[0]
    assert len(ref.scans) > 5
    for other in results[1:]:
        assert len(other.scans) == len(ref.scans)
        assert other.skipped_other == ref.skipped_other
        for a, b in zip(ref.scans, other.scans):
            np.testing.assert_array_equal(a.ranges, b.ranges)
            np.testing.assert_array_equal(a.pose, b.pose)
            assert a.stamp == b.stamp and a.max_range == b.max_range


def test_truncated_compressed_stream(data_dir, tmp_path):
    src = data_dir / "carmen" / "intel-corrected.log.gz"
    data = src.read_bytes()
    p = tmp_path / "cut.log.gz"
    p.write_bytes(data[: len(data) // 3])
    with pytest.raises(FormatError, match="cut.log.gz"):
        read_carmen(p)


# ------------------------------------------------------------------------------------- synthetic


def _flaser(n=4, ranges=None, pose=(1.0, 2.0, 0.5), odom=(0.1, 0.2, 0.3), ipc=100.5, logger=7.25, kind="FLASER"):
    r = ranges if ranges is not None else [1.0 + i for i in range(n)]
    fields = [kind, str(n), *map(str, r), *map(str, pose), *map(str, odom), str(ipc), "host", str(logger)]
    return " ".join(fields)


def _write(tmp_path, lines, name="t.log"):
    p = tmp_path / name
    p.write_text("\n".join(lines) + "\n")
    return p


def test_synthetic_flaser_fields(tmp_path):
    p = _write(tmp_path, ["# a comment", "PARAM x 1 0 h 0", "", _flaser(), "ODOM 1 2 3 0 0 0 1 h 1", "WEIRD 1 2"])
    log = read_carmen(p)
    (s,) = log.scans
    assert isinstance(s, LaserScan)
    np.testing.assert_array_equal(s.ranges, [1, 2, 3, 4])
    np.testing.assert_array_equal(s.pose, [1.0, 2.0, 0.5])
    np.testing.assert_array_equal(s.odom, [0.1, 0.2, 0.3])
    np.testing.assert_allclose(s.angles, -PI / 2 + np.arange(4) * PI / 3)  # other n: closed 180° fan
    assert s.stamp == 7.25 and s.max_range == DEFAULT_MAX_RANGE
    assert log.skipped_other == 3 and log.skipped_unknown == 1
    assert log.stats.unknown_types == {"WEIRD": 1} and log.params == {"x": "1"}


def test_laser_offset_from_params(tmp_path, data_dir):
    """The laser's pose on the robot: CARMEN's PARAMs; the raw Freiburg 079 log's FLASER poses sit
    0.04 m behind its odometry poses, as its PARAM says."""
    log = read_carmen(_write(tmp_path, ["PARAM robot_frontlaser_offset 0.1 0 h 0",
                                        "PARAM robot_rearlaser_angular_offset 3.14 0 h 0", _flaser()]))
    assert log.laser_offset() == (0.1, 0.0, 0.0)
    assert log.laser_offset("rear") == (0.0, 0.0, 3.14)
    with pytest.raises(InvalidArgumentError, match="'front' or 'rear'"):
        log.laser_offset("side")
    bad = read_carmen(_write(tmp_path, ["PARAM robot_frontlaser_side_offset nan 0 h 0", _flaser()], "bad.log"))
    with pytest.raises(FormatError, match=r"bad\.log: PARAM robot_frontlaser_side_offset is 'nan'"):
        bad.laser_offset()
    stats = CarmenStats()
    scans = list(itertools.islice(iter_carmen(data_dir / "carmen" / "fr079-raw.clf.bz2", stats=stats), 200))
    off = laser_offset(stats.params)  # the PARAMs come first
    assert off == (-0.04, 0.0, 0.0)
    for s in scans:
        c, sn = math.cos(s.odom[2]), math.sin(s.odom[2])
        np.testing.assert_allclose(s.pose[:2], s.odom[:2] + off[0] * np.array([c, sn]), atol=2e-3)


def test_missing_logger_timestamp_falls_back_to_ipc(tmp_path):
    line = _flaser().rsplit(None, 1)[0]  # ends at the hostname
    (s,) = read_carmen(_write(tmp_path, [line])).scans
    assert s.stamp == 100.5


def test_theta_wrapped_and_rlaser_keeps_its_pose(tmp_path):
    p = _write(tmp_path, [_flaser(pose=(0, 0, 10.9)), _flaser(kind="RLASER", pose=(0, 0, -PI))])
    f, r = read_carmen(p).scans
    assert math.isclose(f.pose[2], 10.9 - 4 * PI, abs_tol=1e-12)
    assert r.pose[2] == PI  # -pi wraps to +pi; nothing added for the rear laser
    assert read_carmen(p, kinds=("RLASER",)).skipped_other == 1


@pytest.mark.parametrize(
    "bad, expect",
    [
        (_flaser()[:40], "FLASER"),  # truncated inside the ranges
        (_flaser(ranges=[1.0, "x1", 3.0, 4.0]), "'x1'"),  # non-numeric range
        (_flaser(n=6, ranges=[1.0, 2.0, 3.0, 4.0]), "n = 6"),  # n larger than the fields
        (_flaser(n=3, ranges=[1.0, 2.0, 3.0, 4.0]), "n = 3"),  # n smaller than the fields
        (_flaser(n=4).replace("FLASER 4", "FLASER 2.5"), "not a non-negative integer"),
        (_flaser(pose=(0, "nan", 0)), "finite"),
        ("FLASER", "too short"),
    ],
)
def test_malformed_line_raises_with_file_and_line(tmp_path, bad, expect):
    p = _write(tmp_path, ["# header", _flaser(), bad, _flaser()], name="bad.log")
    with pytest.raises(FormatError, match=expect) as info:
        read_carmen(p)
    assert info.value.line == 3 and "bad.log, line 3" in str(info.value)
    assert isinstance(info.value, OccmapError) and isinstance(info.value, ValueError)
    # lenient: skipped and counted, the good lines still read
    log = read_carmen(p, lenient=True)
    assert len(log.scans) == 2 and log.skipped_malformed == 1
    assert log.stats.errors[0].line == 3


def test_lenient_counts_several(tmp_path):
    lines = [_flaser(), _flaser()[:30], _flaser(ranges=[1, 2, "?", 4]), _flaser(n=9, ranges=[1, 2, 3, 4]), _flaser()]
    stats = CarmenStats()
    scans = list(iter_carmen(_write(tmp_path, lines), lenient=True, stats=stats))
    assert len(scans) == 2 and stats.scans == 2 and stats.skipped_malformed == 3
    assert [e.line for e in stats.errors] == [2, 3, 4]


def test_empty_and_comment_only_files(tmp_path):
    empty = tmp_path / "empty.log"
    empty.write_bytes(b"")
    log = read_carmen(empty)
    assert log.scans == [] and log.skipped_other == 0
    gz = tmp_path / "empty.log.gz"
    gz.write_bytes(gzip.compress(b""))
    assert read_carmen(gz).scans == []
    assert read_carmen(_write(tmp_path, ["# only a comment"])).skipped_other == 1
    st = stack_scans([])
    assert st.poses.shape == (0, 3) and st.ranges.shape == (0, 0)


def test_robotlaser1_explicit_geometry(tmp_path):
    n, start, res = 5, -0.6, 0.3
    ranges = [1.0, 2.0, 3.0, 4.0, 5.0]
    rem = [0.5, 0.6]
    line = " ".join(
        map(
            str,
            ["ROBOTLASER1", 0, start, 1.2, res, 30.0, 0.01, 0, n, *ranges, len(rem), *rem,
             3.0, 4.0, 7.0, 2.9, 3.9, 0.1, 0.5, 0.1, 0.3, 0.2, 0.0, 55.5, "host", 66.5],
        )
    )  # fmt: skip
    p = _write(tmp_path, [line])
    (s,) = read_carmen(p).scans
    np.testing.assert_allclose(s.angles, start + np.arange(n) * res, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(s.ranges, ranges)
    np.testing.assert_allclose(s.pose, [3.0, 4.0, 7.0 - 2 * PI], atol=1e-12)  # laser pose, wrapped
    np.testing.assert_array_equal(s.odom, [2.9, 3.9, 0.1])  # robot pose
    assert s.max_range == 30.0 and s.stamp == 66.5
    assert read_carmen(p, max_range=12.0).scans[0].max_range == 12.0
    # a remission count that does not fit the fields
    bad = line.replace(f" {len(rem)} 0.5 0.6 ", " 3 0.5 0.6 ")
    with pytest.raises(FormatError, match="remissions"):
        read_carmen(_write(tmp_path, [bad], name="rl.log"))


def test_max_range_from_param_and_override_and_no_return_values(tmp_path):
    lines = ["PARAM robot_front_laser_max 40 0 h 0", _flaser(ranges=[1.0, 32.767, 50.0, 81.91])]
    p = _write(tmp_path, lines)
    assert read_carmen(p).scans[0].max_range == 40.0
    assert read_carmen(p, max_range=20.0).scans[0].max_range == 20.0
    s = read_carmen(p, no_return_values=TYPICAL_NO_RETURN).scans[0]
    np.testing.assert_array_equal(s.ranges, [1.0, 40.0, 50.0, 81.91])  # codes below max moved to it
    np.testing.assert_array_equal(read_carmen(p).scans[0].ranges, [1.0, 32.767, 50.0, 81.91])


def test_the_log_says_what_the_reader_assumed(tmp_path):
    """Scans that took DEFAULT_MAX_RANGE or a guessed fan are counted, for the CLI to say so."""
    lines = [_flaser(n=180), _flaser(n=4), "PARAM robot_front_laser_max 40 0 h 0", _flaser(n=181), _flaser(n=7),
             _flaser(n=360, kind="RLASER")]
    log = read_carmen(_write(tmp_path, lines))
    assert [s.max_range for s in log] == [DEFAULT_MAX_RANGE, DEFAULT_MAX_RANGE, 40.0, 40.0, DEFAULT_MAX_RANGE]
    assert log.stats.assumed_max_range == 3  # the two before the PARAM and the rear laser's
    assert log.stats.guessed_angles == 2  # n = 4 and n = 7
    given = read_carmen(_write(tmp_path, lines), max_range=30.0)
    assert given.stats.assumed_max_range == 0 and given.stats.guessed_angles == 2


def test_every_and_kinds(tmp_path):
    lines = [_flaser(logger=float(k)) for k in range(10)]
    stats = CarmenStats()
    scans = list(iter_carmen(_write(tmp_path, lines), every=3, stats=stats))
    assert [s.stamp for s in scans] == [0.0, 3.0, 6.0, 9.0] and stats.skipped_decimated == 6
    with pytest.raises(InvalidArgumentError):
        iter_carmen(tmp_path / "t.log", every=0)
    with pytest.raises(InvalidArgumentError):
        iter_carmen(tmp_path / "t.log", kinds=("ODOM",))
    with pytest.raises(InvalidArgumentError):
        iter_carmen(tmp_path / "t.log", max_range=-1.0)


def test_flaser_angle_rules():
    np.testing.assert_allclose(flaser_angles(180), -PI / 2 + np.arange(180) * PI / 180)
    np.testing.assert_allclose(flaser_angles(361)[[0, -1]], [-PI / 2, PI / 2])
    assert flaser_angles(0).shape == (0,) and flaser_angles(1)[0] == -PI / 2


def test_stack_scans_pads_with_nan():
    a = LaserScan(np.zeros(3), np.array([1.0, 2.0]), flaser_angles(2), 10.0, 1.0)
    b = LaserScan(np.ones(3), np.array([3.0, 4.0, 5.0]), flaser_angles(3), 20.0, 2.0)
    poses, ranges, angles, max_ranges, stamps = stack_scans([a, b])
    np.testing.assert_array_equal(ranges, [[1, 2, np.nan], [3, 4, 5]])
    assert angles.shape == (2, 3) and np.isnan(angles[0, 2])
    np.testing.assert_array_equal(max_ranges, [10, 20])
    np.testing.assert_array_equal(stamps, [1, 2])
    np.testing.assert_array_equal(poses, [[0, 0, 0], [1, 1, 1]])


def test_missing_file_is_os_error(tmp_path):
    with pytest.raises(FileNotFoundError):
        read_carmen(tmp_path / "nope.log")


def test_plain_copy_of_real_log(data_dir, tmp_path):
    """A decompressed copy of the intel log reads like the gzip original."""
    src = data_dir / "carmen" / "intel-corrected.log.gz"
    plain = tmp_path / "intel.log"
    with gzip.open(src, "rb") as fi, open(plain, "wb") as fo:
        shutil.copyfileobj(fi, fo)
    a, b = read_carmen(src), read_carmen(plain)
    assert len(a.scans) == len(b.scans) == 910
    np.testing.assert_array_equal(stack_scans(a.scans).ranges, stack_scans(b.scans).ranges)


def _odom(x, y, theta, tv, logger):
    return f"ODOM {x} {y} {theta} {tv} 0 0 {logger} host {logger}"


def test_odometry_that_went_forwards_while_the_speed_was_negative_is_reversed(tmp_path):
    """A robot heading +y (theta = pi/2) drives 1 m forwards, then 0.5 m backwards, then turns;
    the log's odometry advanced forwards all along (the speed unsigned) while its ODOM messages say
    tv < 0: the backwards step is driven backwards, the turn and the later steps kept, composed
    from the corrected pose. Where the odometry already went backwards, or no ODOM message says
    anything, nothing changes."""
    h = math.pi / 2
    lines = [_flaser(odom=(0, 0, h), logger=1.0), _odom(0, 0.5, h, 0.5, 1.5),
             _flaser(odom=(0, 1, h), logger=2.0), _odom(0, 1.25, h, -0.5, 2.5), _odom(0, 1.5, h + 0.1, -0.5, 2.8),
             _flaser(odom=(0, 1.5, h + 0.1), logger=3.0), _odom(0, 1.5, h + 0.3, 0.0, 3.5),
             _flaser(odom=(0, 1.5, h + 0.3), logger=4.0)]
    log = read_carmen(_write(tmp_path, lines))
    got = np.array([s.odom for s in log.scans])
    assert log.stats.reversed_steps == 1
    np.testing.assert_allclose(got[:2], [[0, 0, h], [0, 1, h]])  # untouched before the first reversal
    np.testing.assert_allclose(got[2], [0, 0.5, h + 0.1], atol=1e-12)  # 0.5 m back, the turn kept
    np.testing.assert_allclose(got[3], [0, 0.5, h + 0.3], atol=1e-12)  # the next step from there
    # signed odometry (it went back by itself) and logs without ODOM: as read
    signed = [_flaser(odom=(0, 1, h), logger=2.0), _odom(0, 0.75, h, -0.5, 2.5), _flaser(odom=(0, 0.5, h), logger=3.0)]
    plain = [_flaser(odom=(0, 1, h), logger=2.0), _flaser(odom=(0, 1.5, h), logger=3.0)]
    for name, log_lines, end in (("signed.log", signed, 0.5), ("plain.log", plain, 1.5)):
        log = read_carmen(_write(tmp_path, log_lines, name))
        assert log.stats.reversed_steps == 0 and log.scans[1].odom[1] == end
    # an ODOM line without a readable speed is left out, as other ODOM lines are not validated
    odd = [_flaser(odom=(0, 0, h), logger=1.0), "ODOM 0 0.5 1.57 fast", _flaser(odom=(0, 1, h), logger=2.0)]
    assert read_carmen(_write(tmp_path, odd, "odd.log")).scans[1].odom[1] == 1.0


def test_freiburg_079_reversing_is_read_as_reversing(logs, data_dir):
    """Freiburg 079's raw odometry advances while its ODOM speed is negative (320 messages below
    -0.05 m/s, every one); the corrected log (SLAM, scans matched) has the robot reversing there.
    Read, the raw steps now go the same way as the corrected ones: refs 1386-1400 (the robot backs
    up 2 m), 0.2 m a step back in both; and on the whole run the odometry no longer contradicts the
    reference's direction of travel."""
    from occmap.geometry.se2 import relative_poses
    from occmap.localize.replay import pair_scans

    raw = read_carmen(data_dir / "carmen" / "fr079-raw.clf.bz2")
    ref = logs["freiburg-079-corrected.log.gz"].scans
    assert raw.stats.reversed_steps == 294
    pairs = pair_scans(raw.scans, ref)
    assert (pairs >= 0).mean() > 0.95
    ks = np.flatnonzero((pairs[:-1] >= 0) & (pairs[1:] >= 0))
    odo = relative_poses(np.array([raw.scans[pairs[k]].odom for k in ks]),
                         np.array([raw.scans[pairs[k + 1]].odom for k in ks]))[:, 0]
    cor = relative_poses(np.array([ref[k].pose for k in ks]), np.array([ref[k + 1].pose for k in ks]))[:, 0]
    back = (ks >= 1386) & (ks < 1400)
    assert back.sum() >= 12 and (odo[back] < -0.05).all() and (cor[back] < -0.05).all()
    contradicts = (np.sign(odo) != np.sign(cor)) & (np.abs(odo) > 0.05) & (np.abs(cor) > 0.05)
    assert contradicts.sum() <= 5
