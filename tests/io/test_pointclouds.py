"""Point cloud readers and writers: the real files in ../shared/data (counts, units, poses, the
UOS overlap), writer → reader round trips, foreign layouts built by hand (PCD field orders,
big-endian PLY, elements before the vertices), and broken files for every reader."""

from __future__ import annotations

import bz2
import gzip
import lzma
import re

import numpy as np
import pytest

from occmap.cloud import PointCloud
from occmap.errors import FormatError, InvalidArgumentError, MissingFileError, ShapeError
from occmap.geometry import SE3
from occmap.io import (
    read_cloud,
    read_kitti_bin,
    read_pcd,
    read_ply,
    read_uos,
    read_xyz,
    write_pcd,
    write_ply,
    write_xyz,
)
from occmap.io.pointclouds import uos_euler_to_matrix, uos_matrix_to_se3, uos_points_to_rh

HDL = {"251370668.pcd": 69_088, "251371071.pcd": 69_792}


def f32(a):
    return np.asarray(a, dtype=np.float32).astype(np.float64)


# ---------------------------------------------------------------------------------------------
# real data


def test_octomap_scan_dat(data_dir):
    c = read_xyz(data_dir / "octomap" / "scan.dat.bz2")
    assert len(c) == 88_206 and c.dropped == 0
    r = np.linalg.norm(c.points, axis=1)
    assert 0.46 < r.min() < 0.48 and 28.9 < r.max() < 29.1  # README: ranges 0.47–29 m
    np.testing.assert_array_equal(c.origin, 0)
    assert read_cloud(data_dir / "octomap" / "scan.dat.bz2").points.shape == (88_206, 3)


@pytest.mark.parametrize("name", sorted(HDL))
def test_hdl32_pcd(data_dir, name):
    path = data_dir / "scans3d" / "hdl32_pair" / name
    c = read_pcd(path)
    assert len(c) + c.dropped == HDL[name]
    assert 4_500 < c.dropped < 5_500  # README: about 5,000 exact zeros (no return)
    assert not (c.points == 0).all(axis=1).any()
    np.testing.assert_array_equal(c.pose.matrix, np.eye(4))  # VIEWPOINT 0 0 0 1 0 0 0
    raw = read_pcd(path, drop_origin=False)
    assert len(raw) == HDL[name] and raw.dropped == 0
    assert (raw.points == 0).all(axis=1).sum() == c.dropped
    r = np.linalg.norm(c.points, axis=1)
    assert r.max() < 120  # HDL-32E: up to ~100 m


def _pcd_body(path):
    """x y z intensity float32 records of a real binary PCD, read with NumPy alone."""
    data = path.read_bytes()
    start = data.index(b"DATA binary\n") + len(b"DATA binary\n")
    return np.frombuffer(data, "<f4", offset=start).reshape(-1, 4)


def test_pcd_ascii_equals_binary(data_dir, tmp_path):
    src = data_dir / "scans3d" / "hdl32_pair" / "251370668.pcd"
    rec = _pcd_body(src)
    assert rec.shape == (HDL["251370668.pcd"], 4)
    n = len(rec)
    body = "".join(f"{a!r} {b!r} {c!r} {d!r}\n" for a, b, c, d in rec[:2000].astype(float).tolist())
    header = (
        "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\n"
        f"WIDTH {2000}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {2000}\nDATA ascii\n"
    )
    (tmp_path / "a.pcd").write_text(header + body)
    a = read_pcd(tmp_path / "a.pcd", drop_origin=False)
    np.testing.assert_array_equal(a.points, rec[:2000, :3].astype(np.float64))
    # the whole real file, rewritten by our writer as ascii and as binary
    b = read_pcd(src, drop_origin=False)
    write_pcd(tmp_path / "asc.pcd", b.points, binary=False)
    write_pcd(tmp_path / "bin.pcd", b.points)
    for p in ("asc.pcd", "bin.pcd"):
        c = read_pcd(tmp_path / p, drop_origin=False)
        assert len(c) == n
        np.testing.assert_array_equal(c.points, b.points)


# ---------------------------------------------------------------------------------------------
# UOS / 3DTK


@pytest.fixture(scope="module")
def uos(data_dir):
    d = data_dir / "scans3d" / "uos_3dtk"
    return {mode: [read_uos(d / f"scan{i:03d}.3d", pose=mode, no_return=None) for i in range(3)] for mode in ("frames", "pose", None)}


def _cm_rows(path):
    return np.loadtxt(path, usecols=(0, 1, 2))


def test_uos_counts_units_and_axes(uos, data_dir):
    for c in uos[None]:
        assert len(c) == 81_360 and c.dropped == 0
        p = c.points
        assert np.linalg.norm(p, axis=1).max() < 60  # metres, not centimetres
        assert p[:, 0].min() > -1e-9  # the scanner saw the half space in front: x is forward
        # z is up: the floor is a dense plane about half a metre below the sensor
        hist, edges = np.histogram(p[:, 2], bins=np.arange(-1.0, 1.0, 0.05))
        assert -0.65 < edges[np.argmax(hist)] < -0.35
    first = _cm_rows(data_dir / "scans3d" / "uos_3dtk" / "scan000.3d")[:3]
    np.testing.assert_allclose(uos[None][0].points[:3], np.stack((first[:, 2], -first[:, 0], first[:, 1]), 1) / 100)


def test_uos_frames_pose_is_last_line_converted(uos, data_dir):
    d = data_dir / "scans3d" / "uos_3dtk"
    for i in range(3):
        last = np.loadtxt(d / f"scan{i:03d}.frames_slam6d_2009")[-1]
        m = last[:16].reshape(4, 4).T  # column-major (OpenGL)
        c = uos["frames"][i]
        np.testing.assert_allclose(c.origin, np.array([m[2, 3], -m[0, 3], m[1, 3]]) / 100, atol=1e-12)
        # the conversion commutes with 3DTK's own transform: world points = axis map of M p
        p_cm = _cm_rows(d / f"scan{i:03d}.3d")[::997]
        w_3dtk = p_cm @ m[:3, :3].T + m[:3, 3]
        np.testing.assert_allclose(c.world_points()[::997], uos_points_to_rh(w_3dtk), atol=1e-4)
    np.testing.assert_allclose(uos["frames"][1].origin, [1.56796, 0.036331, -0.0908315], atol=1e-9)


def test_uos_pose_file_euler_convention(uos, data_dir):
    """3DTK's EulerToMatrix4 is R = Rx Ry Rz (scipy's intrinsic 'XYZ') of the angles in degrees;
    so read, the odometry .pose rotation lies within 1° of the registered frames rotation. (The
    angles are about 1°, so the data cannot tell Rx Ry Rz from Rz Ry Rx; the formula is 3DTK's.)"""
    from scipy.spatial.transform import Rotation

    d = data_dir / "scans3d" / "uos_3dtk"
    for i in (1, 2):
        t, ang = np.loadtxt(d / f"scan{i:03d}.pose")
        m = uos_euler_to_matrix(t, ang)
        np.testing.assert_allclose(m[:3, :3], Rotation.from_euler("XYZ", ang, degrees=True).as_matrix(), atol=1e-12)
        np.testing.assert_array_equal(m[:3, 3], t)
        frames = np.loadtxt(d / f"scan{i:03d}.frames_slam6d_2009")[-1][:16].reshape(4, 4).T[:3, :3]

        def angle(R):
            return np.degrees(np.linalg.norm(Rotation.from_matrix(R.T @ frames).as_rotvec()))

        # 3DTK's reading lies within 1° of the registration; plausible misreadings do not
        assert angle(m[:3, :3]) < 1.0
        assert angle(m[:3, :3].T) > 1.0  # angles negated (the inverse rotation)
        assert angle(Rotation.from_euler("XYZ", ang[::-1], degrees=True).as_matrix()) > 1.0  # x, z swapped
        assert angle(Rotation.from_euler("XYZ", np.degrees(ang), degrees=True).as_matrix()) > 1.0  # radians
        # and read_uos(pose="pose") is that matrix through the axis map
        np.testing.assert_allclose(uos["pose"][i].pose.matrix, uos_matrix_to_se3(m).matrix, atol=1e-12)
        assert np.linalg.norm(uos["pose"][i].origin - uos["frames"][i].origin) < 0.03


def _median_nn(tree, pts):
    d, _ = tree.query(pts)
    return float(np.median(d))


def test_uos_registered_scans_overlap(uos):
    """scan001 placed by its registered (frames) pose lies on scan000: median nearest-neighbour
    distance of its above-floor points a few cm; without poses, or shifted by 10 cm, far worse."""
    from scipy.spatial import cKDTree

    s0, s1 = uos["frames"][0], uos["frames"][1]
    tree = cKDTree(s0.world_points())
    p = s1.points
    keep = (p[:, 2] > -0.3) & (np.linalg.norm(p, axis=1) < 8)  # above the floor, within 8 m
    keep &= np.arange(len(p)) % 3 == 0  # every third point is plenty for a median
    w = s1.world_points()[keep]
    registered = _median_nn(tree, w)
    assert registered < 0.04
    for shift in ([0.1, 0, 0], [-0.1, 0, 0], [0, 0.1, 0], [0, -0.1, 0]):
        assert _median_nn(tree, w + shift) > 1.25 * registered
    unplaced = _median_nn(cKDTree(uos[None][0].points), p[keep])
    assert unplaced > 3 * registered
    # the odometry .pose of this small run is nearly as good as the registration
    odo = uos["pose"][1].world_points()[keep]
    assert _median_nn(cKDTree(uos["pose"][0].world_points()), odo) < 0.05


def test_uos_scan002_data_quirk(uos):
    """Documents a quirk of the sample data, not of the reader: scan002.3d agrees with scan000
    in the sensor frame (it was recorded from about the same place), while its .pose and .frames
    put it 3.4 m ahead. So only scan000 + scan001 make a consistent registered pair."""
    from scipy.spatial import cKDTree

    p = uos[None][2].points
    keep = (p[:, 2] > -0.3) & (np.linalg.norm(p, axis=1) < 8)
    assert _median_nn(cKDTree(uos[None][0].points), p[keep]) < 0.02
    assert uos["frames"][2].origin[0] > 3.3


def test_uos_synthetic_header_sidecars_and_errors(tmp_path):
    d = tmp_path
    (d / "scan007.3d").write_text("2 x 3\n100 0 0 17\n0 200 300 4\n")
    (d / "scan007.pose").write_text("0 0 100\n0 90 0\n")
    ident = "1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1 2\n"
    (d / "scan007.frames_slam6d_2009").write_text(ident + "1 0 0 0 0 1 0 0 0 0 1 0 50 0 0 1 1\n")
    c = read_uos(d / "scan007.3d", pose=None)
    np.testing.assert_allclose(c.points, [[0, -1, 0], [3, 0, 2]])
    c = read_uos(d / "scan007.3d")  # frames: translation x = 50 cm (right) -> y = -0.5 m
    np.testing.assert_allclose(c.origin, [0, -0.5, 0])
    (d / "scan007.frames").write_text(ident)  # the plain .frames file wins
    np.testing.assert_allclose(read_uos(d / "scan007.3d").origin, 0)
    c = read_uos(d / "scan007.3d", pose="pose")
    # 90° about 3DTK's y (up) turns forward (z) to x (right)...; in our frame that is about z
    np.testing.assert_allclose(c.origin, [1, 0, 0])
    np.testing.assert_allclose(c.pose.rotation.matrix @ [1, 0, 0], [0, -1, 0], atol=1e-12)
    assert read_cloud(d / "scan007.3d", pose=None).points.shape == (2, 3)
    T = SE3.from_rotvec([0, 0, 0.3], [1, 2, 3])
    assert read_uos(d / "scan007.3d", pose=T).pose is T
    with pytest.raises(InvalidArgumentError):
        read_uos(d / "scan007.3d", pose="odometry")
    with pytest.raises(MissingFileError, match=r"scan008\.3d: no pose file beside the scan: tried .*scan008\.frames"):
        (d / "scan008.3d").write_text("1 2 3\n")
        read_uos(d / "scan008.3d")
    (d / "scan007.frames").write_text(ident + "1 0 0 0 0 1 0\n")
    with pytest.raises(FormatError, match="line 2"):
        read_uos(d / "scan007.3d")
    (d / "scan007.frames").write_text("1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 2 2\n")
    with pytest.raises(FormatError, match="rigid"):
        read_uos(d / "scan007.3d")
    (d / "scan007.pose").write_text("0 0 100\n0 90\n")
    with pytest.raises(FormatError, match="line 2"):
        read_uos(d / "scan007.3d", pose="pose")
    (d / "scan007.3d").write_text("2 x 3\n100 0 0\n0 2OO 300\n")
    with pytest.raises(FormatError, match=r"line 3.*'2OO'"):
        read_uos(d / "scan007.3d", pose=None)


# ---------------------------------------------------------------------------------------------
# XYZ


def test_xyz_round_trip_exact(tmp_path, rng):
    pts = rng.normal(size=(1000, 3)) * 100
    write_xyz(tmp_path / "a.xyz", pts)
    c = read_xyz(tmp_path / "a.xyz")
    np.testing.assert_array_equal(c.points, pts)
    T = SE3.from_rotvec([0, 0, 1], [1, 2, 3])
    cloud = PointCloud(pts, T)
    write_xyz(tmp_path / "b.xyz", cloud)  # no pose in the format: world points
    np.testing.assert_array_equal(read_xyz(tmp_path / "b.xyz").points, cloud.world_points())
    assert read_xyz(tmp_path / "a.xyz", pose=T).pose is T


@pytest.mark.parametrize("opener,suffix", [(gzip.open, ".gz"), (bz2.open, ".bz2"), (lzma.open, ".xz"), (open, "")])
def test_xyz_compressed_comments_extra_columns(tmp_path, opener, suffix):
    text = "# a comment\n1 2 3 9 9\n\n  4.5\t5 6 # trailing comment\n7 8 9 10\r\n"
    path = tmp_path / f"p.txt{suffix}"
    with opener(path, "wb") as f:
        f.write(text.encode())
    c = read_cloud(path)
    np.testing.assert_array_equal(c.points, [[1, 2, 3], [4.5, 5, 6], [7, 8, 9]])


def test_xyz_non_finite_dropped_and_counted(tmp_path):
    (tmp_path / "n.xyz").write_text("1 2 3\nnan 0 0\n0 inf 0\n4 5 6\n0 0 -inf\n")
    c = read_xyz(tmp_path / "n.xyz")
    np.testing.assert_array_equal(c.points, [[1, 2, 3], [4, 5, 6]])
    assert c.dropped == 3


def test_xyz_empty(tmp_path):
    (tmp_path / "e.xyz").write_text("")
    (tmp_path / "c.xyz").write_text("# nothing\n\n")
    for name in ("e.xyz", "c.xyz"):
        c = read_xyz(tmp_path / name)
        assert c.points.shape == (0, 3)


@pytest.mark.parametrize(
    "text,line,what",
    [
        ("1 2 3\n4 5\n", 2, "at least 3"),
        ("1 2 3\n\n4 5 x\n", 3, "'x'"),
        ("1 2 3\n4,5,6\n", 2, "'4,5,6'"),
        ("1 2 3\n4 5 6abc\n", 2, "'6abc'"),
        ("# c\n1 2 3 4\n7 8 9 0x\n", 3, "field 4"),
    ],
)
def test_xyz_errors_name_the_line(tmp_path, text, line, what):
    (tmp_path / "bad.xyz").write_text(text)
    with pytest.raises(FormatError, match=re.escape(what)) as e:
        read_xyz(tmp_path / "bad.xyz")
    assert e.value.line == line and f"line {line}" in str(e.value) and "bad.xyz" in str(e.value)


def test_xyz_truncated_compression(tmp_path):
    blob = bz2.compress(b"1 2 3\n" * 5000)
    (tmp_path / "t.xyz.bz2").write_bytes(blob[: len(blob) // 2])
    with pytest.raises(FormatError, match="truncated or corrupt"):
        read_xyz(tmp_path / "t.xyz.bz2")


# ---------------------------------------------------------------------------------------------
# PCD


def test_pcd_round_trip_with_viewpoint(tmp_path, rng):
    pts = f32(rng.normal(size=(500, 3)) * 20)
    T = SE3.from_rotvec([0.2, -0.4, 1.0], [3.0, -1.0, 0.5])
    for binary in (True, False):
        write_pcd(tmp_path / "v.pcd", PointCloud(pts, T), binary=binary)
        c = read_pcd(tmp_path / "v.pcd")
        np.testing.assert_array_equal(c.points, pts)
        np.testing.assert_allclose(c.pose.matrix, T.matrix, atol=1e-12)
        np.testing.assert_allclose(c.world_points(), T.apply(pts), atol=1e-9)
    text = (tmp_path / "v.pcd").read_bytes().split(b"DATA")[0].decode()
    assert "VIEWPOINT 3.0 -1.0 0.5 " in text and "FIELDS x y z\n" in text


def _pcd(fields, sizes, types, counts, n, data_kind, body: bytes, viewpoint="0 0 0 1 0 0 0"):
    return (
        "# .PCD v0.7\nVERSION 0.7\n"
        f"FIELDS {fields}\nSIZE {sizes}\nTYPE {types}\nCOUNT {counts}\nWIDTH {n}\nHEIGHT 1\n"
        f"VIEWPOINT {viewpoint}\nPOINTS {n}\nDATA {data_kind}\n"
    ).encode() + body


def _mixed_records(rng, n):
    dt = np.dtype([("intensity", "<f4"), ("y", "<f8"), ("pad", "u1", (3,)), ("ring", "<u2"), ("z", "<i4"), ("x", "<f4")])
    rec = np.zeros(n, dt)
    rec["intensity"] = rng.uniform(0, 255, n)
    rec["x"] = rng.normal(size=n)
    rec["y"] = rng.normal(size=n)
    rec["z"] = rng.integers(-1000, 1000, n)
    rec["ring"] = rng.integers(0, 32, n)
    return rec


def test_pcd_any_field_layout_binary_and_ascii(tmp_path, rng):
    n = 300
    rec = _mixed_records(rng, n)
    args = ("intensity y _ ring z x", "4 8 1 2 4 4", "F F U U I F", "1 1 3 1 1 1", n)
    (tmp_path / "b.pcd").write_bytes(_pcd(*args, "binary", rec.tobytes()))
    rows = [f"{i!r} {y!r} 0 0 0 {ring} {z} {x!r}" for i, y, _pad, ring, z, x in rec.tolist()]
    (tmp_path / "a.pcd").write_bytes(_pcd(*args, "ascii", ("\n".join(rows) + "\n").encode()))
    want = np.stack((rec["x"].astype(float), rec["y"], rec["z"].astype(float)), axis=1)
    for name in ("b.pcd", "a.pcd"):
        c = read_pcd(tmp_path / name)
        np.testing.assert_array_equal(c.points, want)
        assert c.dropped == 0


def test_pcd_non_finite_dropped_and_counted(tmp_path):
    pts = np.array([[1, 2, 3], [np.nan, np.nan, np.nan], [0, 0, 0], [4, np.inf, 6], [7, 8, 9]], np.float32)
    (tmp_path / "n.pcd").write_bytes(_pcd("x y z", "4 4 4", "F F F", "1 1 1", 5, "binary", pts.tobytes()))
    c = read_pcd(tmp_path / "n.pcd")
    np.testing.assert_array_equal(c.points, [[1, 2, 3], [7, 8, 9]])
    assert c.dropped == 3
    c = read_pcd(tmp_path / "n.pcd", drop_origin=False)
    assert len(c) == 3 and c.dropped == 2


@pytest.mark.parametrize(
    "edit,match,line",
    [
        (lambda s: s.replace("FIELDS x y z", "FIELDS x y w"), "no field 'z'", 3),
        (lambda s: s.replace("SIZE 4 4 4", "SIZE 4 4"), "SIZE has 2 values", 4),
        (lambda s: s.replace("TYPE F F F", "TYPE F F Q"), "unsupported TYPE", 5),
        (lambda s: s.replace("POINTS 3", "POINTS 4"), "WIDTH", 10),
        (lambda s: s.replace("VIEWPOINT 0 0 0 1 0 0 0", "VIEWPOINT 0 0 0 2 0 0 0"), "norm", 9),
        (lambda s: s.replace("VIEWPOINT 0 0 0 1 0 0 0", "VIEWPOINT 0 0 0 1 0 0"), "7 finite", 9),
        (lambda s: s.replace("DATA ascii", "DATA binary_compressed"), "binary_compressed", 11),
        (lambda s: s.replace("DATA ascii", "DATA text"), "DATA must be", 11),
        (lambda s: s.replace("DATA ascii\n", ""), "unknown PCD header keyword '1'", 11),
        (lambda s: s.split("DATA")[0], "no DATA line", 10),
        (lambda s: s.replace("WIDTH 3", "WIDTH three"), "integers", 7),
        (lambda s: s.replace("HEIGHT 1", "HIGHT 1"), "unknown PCD header keyword", 8),
        (lambda s: s.replace("4 5 6\n", "4 5 six\n"), "'six'", 13),
        (lambda s: s.replace("4 5 6\n", "4 5\n"), "expected 3 fields", 13),
        (lambda s: s.replace("7 8 9\n", ""), "expected 3 points", 14),
        (lambda s: s + "1 1 1\n", "expected 3 points", 15),
    ],
)
def test_pcd_header_and_ascii_errors(tmp_path, edit, match, line):
    good = _pcd("x y z", "4 4 4", "F F F", "1 1 1", 3, "ascii", b"1 2 3\n4 5 6\n7 8 9\n").decode()
    (tmp_path / "g.pcd").write_text(good)
    assert len(read_pcd(tmp_path / "g.pcd")) == 3
    (tmp_path / "bad.pcd").write_text(edit(good))
    with pytest.raises(FormatError, match=match) as e:
        read_pcd(tmp_path / "bad.pcd")
    assert e.value.line == line


def test_pcd_truncated_binary_names_offset(data_dir, tmp_path):
    src = (data_dir / "scans3d" / "hdl32_pair" / "251370668.pcd").read_bytes()
    start = src.index(b"DATA binary\n") + len(b"DATA binary\n")
    for cut in (start, start + 5, start + 16 * 1000 + 7, len(src) - 1):
        (tmp_path / "t.pcd").write_bytes(src[:cut])
        with pytest.raises(FormatError, match="truncated") as e:
            read_pcd(tmp_path / "t.pcd")
        assert e.value.offset == start + (cut - start) // 16 * 16
        assert f"byte {e.value.offset}" in str(e.value)
    (tmp_path / "t.pcd").write_bytes(src[:100])  # cut inside the header
    with pytest.raises(FormatError):
        read_pcd(tmp_path / "t.pcd")
    (tmp_path / "t.pcd").write_bytes(b"\x00\x01garbage" * 1000)
    with pytest.raises(FormatError):
        read_pcd(tmp_path / "t.pcd")


# ---------------------------------------------------------------------------------------------
# PLY


def test_ply_round_trip_binary_and_ascii(tmp_path, rng):
    pts = rng.normal(size=(400, 3)) * 50
    colors = rng.integers(0, 256, (400, 3))
    for binary in (True, False):
        for col in (None, colors):
            write_ply(tmp_path / "o.ply", pts, colors=col, binary=binary)
            c = read_ply(tmp_path / "o.ply")
            np.testing.assert_array_equal(c.points, f32(pts))
    a = read_ply(tmp_path / "o.ply").points
    write_ply(tmp_path / "b.ply", pts, colors=colors)
    np.testing.assert_array_equal(read_ply(tmp_path / "b.ply").points, a)


def test_ply_written_header_and_colors(tmp_path):
    pts = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    write_ply(tmp_path / "c.ply", pts, colors=np.array([[1.0, 0.5, 0.0], [0.0, 0.0, 1.0]]))
    data = (tmp_path / "c.ply").read_bytes()
    header, body = data.split(b"end_header\n")
    assert header.decode().splitlines() == [
        "ply", "format binary_little_endian 1.0", "comment written by occmap", "element vertex 2",
        "property float x", "property float y", "property float z",
        "property uchar red", "property uchar green", "property uchar blue",
    ]  # fmt: skip
    rec = np.frombuffer(body, [("xyz", "<f4", 3), ("rgb", "u1", 3)])
    np.testing.assert_array_equal(rec["rgb"], [[255, 128, 0], [0, 0, 255]])
    np.testing.assert_array_equal(rec["xyz"], pts)
    write_ply(tmp_path / "d.ply", pts, colors=(10, 20, 30), binary=False)
    assert (tmp_path / "d.ply").read_text().endswith("1 2 3 10 20 30\n4 5 6 10 20 30\n")
    cloud = PointCloud(pts, SE3.from_rotvec([0, 0, 0], [10, 0, 0]))
    write_ply(tmp_path / "w.ply", cloud)  # a PointCloud is written in the world frame
    np.testing.assert_array_equal(read_ply(tmp_path / "w.ply").points, pts + [10, 0, 0])
    with pytest.raises(InvalidArgumentError):
        write_ply(tmp_path / "x.ply", pts, colors=[[0, 0, 256], [0, 0, 0]])
    with pytest.raises(InvalidArgumentError):
        write_ply(tmp_path / "x.ply", pts, colors=np.full((2, 3), 1.5))
    with pytest.raises(ShapeError):
        write_ply(tmp_path / "x.ply", pts, colors=np.zeros((3, 3), np.uint8))
    with pytest.raises(ShapeError):
        write_ply(tmp_path / "x.ply", np.zeros((2, 2)))
    assert not (tmp_path / "x.ply").exists()


def _foreign_ply(fmt, order, n, rng):
    """A PLY as other tools write it: a fixed-size element before the vertices, doubles and
    extra vertex properties, and a face list element after them."""
    vdt = np.dtype([("nx", order + "f4"), ("x", order + "f8"), ("y", order + "f8"), ("z", order + "f8"),
                    ("red", "u1"), ("quality", order + "i2")])  # fmt: skip
    v = np.zeros(n, vdt)
    v["x"], v["y"], v["z"] = rng.normal(size=(3, n))
    v["red"] = rng.integers(0, 255, n)
    v["quality"] = rng.integers(-100, 100, n)
    cam = np.array([(1.5, 2.5)], dtype=[("a", order + "f4"), ("b", order + "f4")])
    header = (
        f"ply\nformat {fmt} 1.0\ncomment made by hand\nobj_info nothing\nelement camera 1\n"
        "property float a\nproperty float b\n"
        f"element vertex {n}\nproperty float nx\nproperty double x\nproperty double y\n"
        "property double z\nproperty uchar red\nproperty short quality\n"
        "element face 2\nproperty list uchar int vertex_indices\nend_header\n"
    ).encode()
    if fmt == "ascii":
        lines = ["1.5 2.5"] + [f"{r[0]!r} {r[1]!r} {r[2]!r} {r[3]!r} {r[4]} {r[5]}" for r in v.tolist()]
        body = ("\n".join(lines) + "\n3 0 1 2\n3 1 2 0\n").encode()
    else:
        faces = np.array([3, 0, 0, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0], np.uint8).tobytes() * 2
        body = cam.tobytes() + v.tobytes() + faces
    want = np.stack((v["x"], v["y"], v["z"]), axis=1).astype(np.float64)
    return header + body, want


@pytest.mark.parametrize("fmt,order", [("ascii", "<"), ("binary_little_endian", "<"), ("binary_big_endian", ">")])
def test_ply_foreign_layouts(tmp_path, rng, fmt, order):
    data, want = _foreign_ply(fmt, order, 250, rng)
    (tmp_path / "f.ply").write_bytes(data)
    c = read_ply(tmp_path / "f.ply")
    np.testing.assert_array_equal(c.points, want)
    assert read_cloud(tmp_path / "f.ply").points.shape == (250, 3)


def test_ply_ascii_list_element_before_vertex_is_skipped(tmp_path):
    text = (
        "ply\nformat ascii 1.0\nelement face 2\nproperty list uchar int vertex_indices\n"
        "element vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
        "3 0 1 2\n4 0 1 2 3\n1 2 3\nnan 5 6\n"
    )
    (tmp_path / "l.ply").write_text(text)
    c = read_ply(tmp_path / "l.ply")
    np.testing.assert_array_equal(c.points, [[1, 2, 3]])
    assert c.dropped == 1
    (tmp_path / "l.ply").write_text(text.replace("1 2 3\n", "1 2 x\n"))
    with pytest.raises(FormatError, match="'x'") as e:
        read_ply(tmp_path / "l.ply")
    assert e.value.line == 12


def test_ply_errors(tmp_path, rng):
    data, _ = _foreign_ply("binary_little_endian", "<", 100, rng)
    header_end = data.index(b"end_header\n") + len(b"end_header\n")
    vstart = header_end + 8  # after the camera element
    for cut in (header_end, vstart + 30, vstart + 31 * 99 + 1):
        (tmp_path / "t.ply").write_bytes(data[:cut])
        with pytest.raises(FormatError, match="truncated") as e:
            read_ply(tmp_path / "t.ply")
        assert e.value.offset == vstart + max(cut - vstart, 0) // 31 * 31
    bad_list = data.replace(b"element camera 1\nproperty float a\nproperty float b\n",
                            b"element face 1\nproperty list uchar int vertex_indices\n")  # fmt: skip
    (tmp_path / "l.ply").write_bytes(bad_list)
    with pytest.raises(FormatError, match="list property") as e:
        read_ply(tmp_path / "l.ply")
    assert e.value.line == 5
    for old, new, match in [
        (b"ply\n", b"plz\n", "not a PLY"),
        (b"format binary_little_endian 1.0", b"format binary_middle_endian 1.0", "format"),
        (b"property double y", b"property quad y", "bad property"),
        (b"property double y", b"property double w", "no property 'y'"),
        (b"element vertex 100", b"element vertex many", "element vertex count must be a whole number"),
        (b"end_header\n", b"end_headr\n", "unknown PLY header keyword"),
    ]:
        (tmp_path / "b.ply").write_bytes(data.replace(old, new, 1))
        with pytest.raises(FormatError, match=match):
            read_ply(tmp_path / "b.ply")
    text, _ = _foreign_ply("ascii", "<", 5, rng)
    lines = text.split(b"\n")
    (tmp_path / "a.ply").write_bytes(b"\n".join(lines[:-6]) + b"\n")  # drop the last vertices
    with pytest.raises(FormatError, match="expected 5 vertex lines"):
        read_ply(tmp_path / "a.ply")
    lines[18] = b"1 2"  # the first vertex line (17 header lines, then the camera)
    (tmp_path / "a.ply").write_bytes(b"\n".join(lines))
    with pytest.raises(FormatError, match="expected 6 fields") as e:
        read_ply(tmp_path / "a.ply")
    assert e.value.line == 19


# ---------------------------------------------------------------------------------------------
# KITTI


def test_kitti_bin(tmp_path, rng):
    rec = rng.normal(size=(1000, 4)).astype("<f4")
    rec[5, 1] = np.nan
    rec[7, 2] = np.inf
    (tmp_path / "000000.bin").write_bytes(rec.tobytes())
    c = read_kitti_bin(tmp_path / "000000.bin")
    keep = np.ones(1000, bool)
    keep[[5, 7]] = False
    np.testing.assert_array_equal(c.points, rec[keep, :3].astype(np.float64))
    assert c.dropped == 2
    T = SE3.from_rotvec([0, 0, 0.1], [1, 0, 0])
    assert read_cloud(tmp_path / "000000.bin", pose=T).pose is T
    for cut in (1, 17, 16 * 999 + 15):
        (tmp_path / "t.bin").write_bytes(rec.tobytes()[:cut])
        with pytest.raises(FormatError, match="multiple of 16") as e:
            read_kitti_bin(tmp_path / "t.bin")
        assert e.value.offset == cut // 16 * 16
    (tmp_path / "e.bin").write_bytes(b"")
    assert len(read_kitti_bin(tmp_path / "e.bin")) == 0


def test_read_cloud_unknown_extension(tmp_path):
    (tmp_path / "x.las").write_bytes(b"")
    with pytest.raises(InvalidArgumentError, match="extension"):
        read_cloud(tmp_path / "x.las")


def test_xyz_comment_edge_cases(tmp_path):
    (tmp_path / "c.xyz").write_bytes(b"#1 2 3\n1 2 3 # 4 # 5\n# x y z\n\t4 5 6#7\n7 8 9 # no newline at the end")
    c = read_xyz(tmp_path / "c.xyz")
    np.testing.assert_array_equal(c.points, [[1, 2, 3], [4, 5, 6], [7, 8, 9]])
    (tmp_path / "d.xyz").write_bytes(b"1 2 3\n4 5 6")  # no final newline, no comments
    assert len(read_xyz(tmp_path / "d.xyz")) == 2
    (tmp_path / "e.xyz").write_bytes(b"1 2 3\n4 5 \x006\n")
    with pytest.raises(FormatError) as e:
        read_xyz(tmp_path / "e.xyz")
    assert e.value.line == 2


def test_binary_that_looks_compressed_is_read_as_is(tmp_path):
    rec = np.zeros((2, 4), "<f4")
    raw = bytearray(rec.tobytes())
    raw[:3] = b"BZh"  # a float that happens to start like a bzip2 stream
    (tmp_path / "0.bin").write_bytes(bytes(raw))
    c = read_kitti_bin(tmp_path / "0.bin")
    assert len(c) == 2
    assert c.points[0, 0] == np.frombuffer(bytes(raw[:4]), "<f4")[0]


def test_pcd_integer_field_must_hold_integers(tmp_path):
    body = b"1 2 3\n4 5 6.5\n"
    (tmp_path / "i.pcd").write_bytes(_pcd("x y z", "4 4 2", "F F I", "1 1 1", 2, "ascii", body))
    with pytest.raises(FormatError, match="'z' = 6.5 does not fit the declared type int16") as e:
        read_pcd(tmp_path / "i.pcd")
    assert e.value.line == 13
    (tmp_path / "i.pcd").write_bytes(_pcd("x y z", "4 4 2", "F F I", "1 1 1", 2, "ascii", b"1 2 3\n4 5 6\n"))
    np.testing.assert_array_equal(read_pcd(tmp_path / "i.pcd").points, [[1, 2, 3], [4, 5, 6]])


def test_uos_no_return_readings_are_dropped_and_counted(data_dir):
    """The UOS scanner writes a beam that saw nothing at 32.767 m (its 16-bit millimetre maximum):
    those points are no hits (15 % of map3d's occupied voxels were such phantom arcs)."""
    path = data_dir / "scans3d" / "uos_3dtk" / "scan000.3d"
    kept = read_uos(path, pose=None, no_return=None)
    cloud = read_uos(path, pose=None)
    r_all = np.linalg.norm(kept.points, axis=1)
    saturated = int(np.count_nonzero(r_all >= 32.747))
    assert saturated > 1000  # 1,481 in this scan, at 32.755-32.770 m; no real return beyond 32.4 m
    assert len(cloud) == len(kept) - saturated and cloud.dropped == kept.dropped + saturated
    assert np.linalg.norm(cloud.points, axis=1).max() < 32.5
    with pytest.raises(InvalidArgumentError, match="no_return"):
        read_uos(path, pose=None, no_return=-1.0)


def test_has_pose_says_whether_the_file_gave_one(tmp_path):
    pts = np.random.default_rng(3).normal(size=(50, 3))
    placed = SE3.from_euler_zyx(0.2, 0.0, 0.0, translation=[1.0, 2.0, 0.5])
    write_pcd(tmp_path / "a.pcd", pts, viewpoint=placed)
    write_pcd(tmp_path / "b.pcd", pts)  # PCL's default VIEWPOINT: the pose was not known
    write_ply(tmp_path / "c.ply", pts)
    assert read_pcd(tmp_path / "a.pcd").has_pose
    assert not read_pcd(tmp_path / "b.pcd").has_pose and not read_ply(tmp_path / "c.ply").has_pose
    assert PointCloud(pts, SE3.identity()).has_pose and not PointCloud(pts).has_pose
