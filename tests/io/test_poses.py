"""Pose files (occmap.io.poses): KITTI with its calibration, TUM matched by stamp and
interpolated (checked against scipy's Slerp), 4×4 per line; the format told by the field count
or given; bad lines named by file, line, field and value."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from occmap.errors import FormatError, InvalidArgumentError
from occmap.io.poses import read_kitti_calibration, read_poses


def rigid(rotations, translations):
    m = np.tile(np.eye(4), (len(translations), 1, 1))
    m[:, :3, :3] = rotations.as_matrix()
    m[:, :3, 3] = translations
    return m


@pytest.fixture
def track(rng):
    """Ten random rigid transforms."""
    return rigid(Rotation.random(10, rng=rng), rng.uniform(-50, 50, (10, 3)))


def write(path, rows, fmt="%.17g"):
    path.write_text("".join(" ".join(fmt % v for v in row) + "\n" for row in rows))
    return path


def test_kitti_with_and_without_calibration(tmp_path, track, rng):
    poses = write(tmp_path / "poses.txt", track[:, :3, :].reshape(-1, 12))
    got = read_poses(poses)
    assert (got.format, len(got), got.stamps) == ("kitti", 10, None)
    np.testing.assert_allclose(got.poses.matrix, track, atol=1e-12)
    tr = rigid(Rotation.random(1, rng=rng), rng.uniform(-1, 1, (1, 3)))[0]
    (tmp_path / "calib.txt").write_text("P0: " + " ".join(["1"] + ["0"] * 11) + "\nTr: "
                                        + " ".join("%.17g" % v for v in tr[:3].reshape(-1)) + "\n")
    calib = read_kitti_calibration(tmp_path / "calib.txt")
    np.testing.assert_allclose(calib.matrix, tr, atol=1e-12)
    velodyne = read_poses(poses, calibration=calib)
    np.testing.assert_allclose(velodyne.poses.matrix, np.linalg.inv(tr) @ track @ tr, atol=1e-10)


def test_kitti_six_digit_rotations_are_made_rigid(tmp_path, track):
    got = read_poses(write(tmp_path / "p.txt", track[:, :3, :].reshape(-1, 12), "%.6e")).poses.matrix
    r = got[:, :3, :3]
    np.testing.assert_allclose(np.swapaxes(r, 1, 2) @ r, np.broadcast_to(np.eye(3), r.shape), atol=1e-14)
    np.testing.assert_allclose(got, track, atol=1e-4)


def test_matrix_per_line(tmp_path, track):
    got = read_poses(write(tmp_path / "m.txt", track.reshape(-1, 16)))
    assert got.format == "matrix"
    np.testing.assert_allclose(got.poses.matrix, track, atol=1e-12)
    assert len(got.by_index(10)) == 10
    with pytest.raises(InvalidArgumentError, match=r"m\.txt: 10 poses for 11 point clouds"):
        got.by_index(11, "point clouds")
    bad = track.reshape(-1, 16).copy()
    bad[3, 12] = 0.5
    with pytest.raises(FormatError, match=r"m2\.txt, line 4: last row \[0\.5, 0\.0, 0\.0, 1\.0\]"):
        read_poses(write(tmp_path / "m2.txt", bad))


def test_tum_interpolated_by_stamp_as_scipy_slerps(tmp_path, rng):
    stamps = np.cumsum(rng.uniform(0.05, 0.2, 12)) + 1e9  # epoch seconds, as TUM files carry
    rot = Rotation.random(12, rng=rng)
    trans = rng.uniform(-5, 5, (12, 3))
    rows = np.c_[stamps, trans, rot.as_quat() * rng.uniform(0.9, 1.1, (12, 1))]  # scipy: (x, y, z, w)
    track = read_poses(write(tmp_path / "tum.txt", rows))
    assert track.format == "tum"
    np.testing.assert_array_equal(track.stamps, stamps)
    inside = rng.uniform(stamps[0], stamps[-1], 50)
    query = np.r_[inside, stamps[3], stamps[0] - 0.01, stamps[-1] + 0.04, stamps[0] - 0.2, stamps[-1] + 1.0]
    got, ok = track.at(query, tolerance=0.05)
    np.testing.assert_array_equal(ok, [True] * 53 + [False, False])
    want_r = Slerp(stamps, rot)(inside)
    np.testing.assert_allclose(got.rotation.matrix[:50], want_r.as_matrix(), atol=1e-12)
    want_t = np.stack([np.interp(inside, stamps, trans[:, k]) for k in range(3)], axis=1)
    np.testing.assert_allclose(got.translation[:50], want_t, atol=1e-12)
    np.testing.assert_allclose(got.matrix[50], rigid(rot[3:4], trans[3:4])[0], atol=1e-12)  # on a sample
    np.testing.assert_allclose(got.matrix[51], rigid(rot[:1], trans[:1])[0], atol=1e-12)  # nearest end
    np.testing.assert_allclose(got.matrix[52], rigid(rot[-1:], trans[-1:])[0], atol=1e-12)
    with pytest.raises(InvalidArgumentError, match="no stamps"):
        read_poses(write(tmp_path / "k.txt", np.zeros((1, 12)) + np.r_[1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0])).at([0.0])


def test_format_override_and_detection(tmp_path, track):
    path = write(tmp_path / "m.txt", track.reshape(-1, 16))
    with pytest.raises(FormatError, match=r"m\.txt, line 1: expected 12 fields \(a kitti pose\), got 16"):
        read_poses(path, "kitti")
    with pytest.raises(InvalidArgumentError, match="pose format 'euler'"):
        read_poses(path, "euler")
    (tmp_path / "seven.txt").write_text("# t x y z yaw pitch roll\n1 2 3 4 5 6 7\n")
    with pytest.raises(FormatError, match=r"seven\.txt, line 2: 7 fields on the first line"):
        read_poses(tmp_path / "seven.txt")


@pytest.mark.parametrize("text, message", [
    ("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1\n", r"line 2: expected 12 fields \(a kitti pose\), got 11"),
    ("1 0 0 0 0 1 0 0 0 0 1 0\n\n1 0 0 0 0 1 0 x 0 0 1 0\n", r"line 3: field 8 'x' is not a number"),
    ("1 0 0 0 0 1 0 0 0 0 1 nan\n", r"line 1: field 12 is nan, not a finite number"),
    ("1 0 0 0 0 1 0 0 0 0 -1 0\n", r"line 1: rotation block .* is not a rotation"),
    ("2 0 0 0 0 0 0 1\n1 0 0 0 0 0 0 1\n", r"line 2: timestamp 1\.0 is before the previous line's 2\.0"),
    ("1 0 0 0 0 0 0 0\n", r"line 1: quaternion qx qy qz qw is zero"),
    ("# nothing\n", r"no poses in the file"),
])
def test_bad_pose_files(tmp_path, text, message):
    path = tmp_path / "bad.txt"
    path.write_text(text)
    with pytest.raises(FormatError, match=r"bad\.txt(, |: )" + message):
        read_poses(path)


def test_bad_calibration(tmp_path):
    (tmp_path / "c.txt").write_text("P0: 1 0 0 0 0 1 0 0 0 0 1 0\n")
    with pytest.raises(FormatError, match=r"c\.txt: no 'Tr:'"):
        read_kitti_calibration(tmp_path / "c.txt")
    (tmp_path / "c.txt").write_text("Tr: 1 0 0 0 0 1 0 0 0 0 1\n")
    with pytest.raises(FormatError, match=r"c\.txt, line 1: Tr holds 11 numbers"):
        read_kitti_calibration(tmp_path / "c.txt")
    (tmp_path / "c.txt").write_text("Tr: 1 0 0 0 0 1 0 0 0 0 1 z\n")
    with pytest.raises(FormatError, match=r"c\.txt, line 1: field 13 'z' is not a number"):
        read_kitti_calibration(tmp_path / "c.txt")
