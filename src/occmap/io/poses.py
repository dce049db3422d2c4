"""Pose files: one sensor pose per scan, read into a :class:`PoseTrack`.

Formats, told apart by the number of fields on a line (``format=`` overrides):

* ``kitti`` — 12 numbers, the top 3×4 rows of ``T_world_camera`` row-major (KITTI odometry
  ``poses.txt``: the left camera's pose in the first camera frame, no stamps). With a KITTI
  ``calib.txt`` (:func:`read_kitti_calibration`: its ``Tr:`` line, velodyne → camera) the poses
  become the velodyne's, ``Tr⁻¹ · P · Tr``, so that ``.bin`` clouds map with them;
* ``tum`` — 8 numbers, ``timestamp tx ty tz qx qy qz qw`` (TUM RGB-D benchmark; quaternion in
  ROS order, normalised as tf2 does);
* ``matrix`` — 16 numbers, a whole 4×4 ``T_world_sensor`` row-major on one line (the last row
  must read ``0 0 0 1``).

Units are the file's (metres for all three in practice); ``#`` starts a comment and blank lines
are skipped. Rotation blocks printed with few digits (KITTI's six) are replaced by the nearest
rotation; one that is not close to a rotation at all is an error naming the line.

A track without stamps pairs with scans by index (pose ``k`` for scan ``k``, :meth:`PoseTrack.by_index`);
a TUM track pairs by stamp (:meth:`PoseTrack.at`): interpolated between the two samples around the
stamp as tf2 does, the nearest end within ``tolerance`` seconds outside them, no pose beyond.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import FormatError, InvalidArgumentError
from ..geometry.se3 import SE3
from ._compression import read_bytes
from ._text import Table

__all__ = ["FORMATS", "PoseTrack", "read_kitti_calibration", "read_poses"]

#: Fields per line of each format.
FORMATS = {"kitti": 12, "tum": 8, "matrix": 16}
# A printed rotation block this far from orthonormal (Frobenius norm of RᵀR - I) is not a rotation.
_ROTATION_SLACK = 1e-3


@dataclass(frozen=True, eq=False)
class PoseTrack:
    """The poses of a pose file, in file order.

    Attributes
    ----------
    path : str
    format : str
        ``"kitti"``, ``"tum"`` or ``"matrix"``.
    poses : SE3 (N,)
        ``T_world_sensor`` of each line.
    stamps : ndarray (N,) or None
        Seconds, for a TUM file (sorted); None for the formats without stamps.
    """

    path: str
    format: str
    poses: SE3
    stamps: np.ndarray | None

    def __len__(self) -> int:
        return len(self.poses)

    def by_index(self, count: int, what: str = "scans") -> SE3:
        """The first ``count`` poses, one per scan in order. Raises :class:`InvalidArgumentError`
        naming the file and both counts when the file holds fewer."""
        if len(self) < count:
            raise InvalidArgumentError(f"{self.path}: {len(self):,} poses for {count:,} {what}; "
                                       f"give a pose per {what[:-1] if what.endswith('s') else what}")
        return self.poses[:count]

    def at(self, stamps, tolerance: float = 0.05) -> tuple[SE3, np.ndarray]:
        """Poses at ``stamps`` (seconds, (M,)) and a mask of the stamps that have one: between two
        samples, interpolated (translation linearly, rotation by slerp); before the first or after
        the last, that sample if it is within ``tolerance`` seconds, else none (identity in the
        result, False in the mask). Only for tracks with stamps."""
        if self.stamps is None:
            raise InvalidArgumentError(f"{self.path}: {self.format} poses have no stamps; they pair with scans "
                                       "by index")
        t = np.asarray(stamps, dtype=np.float64).reshape(-1)
        s = self.stamps
        i = np.clip(np.searchsorted(s, t, side="right") - 1, 0, len(s) - 1)
        j = np.minimum(i + 1, len(s) - 1)
        gap = s[j] - s[i]
        frac = np.where(gap > 0, (t - s[i]) / np.where(gap > 0, gap, 1.0), 0.0)
        frac = np.clip(frac, 0.0, 1.0)
        ok = ((t >= s[0]) & (t <= s[-1])) | (np.abs(t - s[0]) <= tolerance) | (np.abs(t - s[-1]) <= tolerance)
        poses = self.poses[i].interpolate(self.poses[j], frac)
        matrices = np.where(ok[:, None, None], poses.matrix, np.eye(4))
        return SE3(matrices), ok


def read_poses(path, format: str | None = None, calibration: SE3 | None = None) -> PoseTrack:
    """Read a pose file (see :mod:`occmap.io.poses`); ``format`` is ``"kitti"``, ``"tum"``,
    ``"matrix"`` or None to tell it by the fields on the first line. ``calibration``
    (``T_camera_sensor``, e.g. from :func:`read_kitti_calibration`) turns camera poses into the
    sensor's: ``calibration⁻¹ · P · calibration``.

    Raises :class:`FormatError` naming the file, and the line and field where there is one, for a
    field that is not a number, a line with another number of fields, a rotation that is not one,
    a non-finite value, unsorted TUM stamps or a file with no poses.
    """
    if format is not None and format not in FORMATS:
        raise InvalidArgumentError(f"pose format {format!r}: expected one of {', '.join(FORMATS)}")
    table = Table(path, read_bytes(path), 1, comments=True)
    if not len(table):
        raise FormatError(path, "no poses in the file")
    if format is None:
        width = int(table.counts[0])
        format = next((name for name, n in FORMATS.items() if n == width), None)
        if format is None:
            raise FormatError(path, f"{width} fields on the first line: expected 12 (KITTI 3×4), 8 (TUM "
                              "timestamp tx ty tz qx qy qz qw) or 16 (a 4×4 matrix)", line=int(table.lines[0]))
    width = FORMATS[format]
    table.require(path, exactly=width, what=f"a {format} pose")
    values = table.columns(range(width))
    bad = ~np.isfinite(values)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise FormatError(path, f"field {col + 1} is {float(values[row, col])!r}, not a finite number",
                          line=int(table.lines[row]))
    stamps = None
    if format == "tum":
        stamps = values[:, 0]
        back = np.flatnonzero(np.diff(stamps) < 0)
        if back.size:
            k = int(back[0]) + 1
            raise FormatError(path, f"timestamp {float(stamps[k])!r} is before the previous line's "
                              f"{float(stamps[k - 1])!r}; TUM poses must be in time order", line=int(table.lines[k]))
        q = values[:, [7, 4, 5, 6]]  # (w, x, y, z)
        norms = np.linalg.norm(q, axis=1)
        if (norms == 0).any():
            k = int(np.argmax(norms == 0))
            raise FormatError(path, "quaternion qx qy qz qw is zero, not a rotation", line=int(table.lines[k]))
        poses = SE3.from_quat(q / norms[:, None], values[:, 1:4])
    else:
        matrices = np.zeros((len(table), 4, 4))
        matrices[:, :3, :] = values[:, :12].reshape(-1, 3, 4)
        matrices[:, 3, 3] = 1.0
        if format == "matrix":
            last = values[:, 12:]
            off = np.flatnonzero((last != (0.0, 0.0, 0.0, 1.0)).any(axis=1))
            if off.size:
                k = int(off[0])
                raise FormatError(path, f"last row {last[k].tolist()} is not 0 0 0 1: not a rigid transform",
                                  line=int(table.lines[k]))
        poses = _rigid(path, matrices, table.lines)
    if calibration is not None:
        poses = calibration.inv() @ poses @ calibration
    return PoseTrack(str(path), format, poses, stamps)


def read_kitti_calibration(path) -> SE3:
    """``T_camera_velodyne`` from a KITTI ``calib.txt``: the ``Tr:`` line (odometry benchmark) or
    ``Tr_velo_to_cam:`` (12 numbers, row-major 3×4). Raises :class:`FormatError` when the file
    has neither or the line does not hold a rigid transform."""
    for number, line in enumerate(read_bytes(path).decode("latin-1").splitlines(), 1):
        key, _, rest = line.partition(":")
        if key.strip() not in ("Tr", "Tr_velo_to_cam"):
            continue
        fields = rest.split()
        if len(fields) != 12:
            raise FormatError(path, f"{key.strip()} holds {len(fields)} numbers, expected 12 (a 3×4 matrix)",
                              line=number)
        try:
            values = np.array([float(f) for f in fields])
        except ValueError:
            bad = next(k for k, f in enumerate(fields) if not _is_number(f))
            raise FormatError(path, f"field {bad + 2} {fields[bad][:40]!r} is not a number", line=number) from None
        m = np.eye(4)
        m[:3, :] = values.reshape(3, 4)
        return _rigid(path, m[None], np.array([number]))[0]
    raise FormatError(path, "no 'Tr:' (velodyne to camera) line: not a KITTI calib.txt")


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _rigid(path, matrices: np.ndarray, lines: np.ndarray) -> SE3:
    """Rigid transforms from printed (N, 4, 4) matrices: rotation blocks replaced by the nearest
    rotation, an error naming the line for one that is far from any."""
    r = matrices[:, :3, :3]
    bad = ~np.isfinite(matrices).all(axis=(1, 2))
    off = np.linalg.norm(np.swapaxes(r, 1, 2) @ r - np.eye(3), axis=(1, 2))
    bad |= ~(off <= _ROTATION_SLACK) | (np.linalg.det(r) <= 0)
    if bad.any():
        k = int(np.argmax(bad))
        raise FormatError(path, f"rotation block {r[k].tolist()} is not a rotation (not orthonormal with "
                          "determinant +1)", line=int(lines[k]))
    return SE3.from_matrix(matrices, project=True)
