"""3D point clouds: the one record that 3D readers produce and 3D maps (the octree) consume.

A :class:`PointCloud` holds the points in the frame of the sensor that measured them and the
sensor's pose in the world, ``T_world_sensor`` (``p_world = T_world_sensor @ p_sensor``, see
:mod:`occmap.geometry.se3`). Keeping the two apart is what a ray-casting map needs: every ray
starts at :attr:`PointCloud.origin` and ends at one of :meth:`PointCloud.world_points`.
Units are metres; arrays are float64.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import checks
from .errors import ShapeError
from .geometry.se3 import SE3

__all__ = ["PointCloud"]


@dataclass(frozen=True, eq=False)
class PointCloud:
    """One 3D scan: points in the sensor frame and where the sensor was.

    Attributes
    ----------
    points : ndarray (N, 3) float64
        Measured points in the **sensor** frame, metres. Anything array-like of shape (N, 3) is
        accepted and converted (not copied when it already is a float64 array). Readers drop
        non-finite points before building a cloud; the class itself does not forbid them, but
        :meth:`world_points` raises :class:`~occmap.errors.NonFiniteError` on them.
    pose : SE3
        ``T_world_sensor``, a single transform (shape ``()``); a (4, 4) array is accepted and
        checked. ``None`` (the default) means identity: the sensor frame is the world frame.
    has_pose : bool
        Whether a pose was given (read from the file, or passed); False when ``pose`` is the
        identity only because none was known.
    stamp : float or None
        Time of the scan in seconds when the source has one.
    dropped : int
        Points the reader removed (non-finite coordinates, and for PCD by default the exact
        ``(0, 0, 0)`` no-return points); ``len(cloud) + cloud.dropped`` is what the file held.
    """

    points: np.ndarray
    pose: SE3 | None = None
    stamp: float | None = None
    dropped: int = 0
    has_pose: bool = field(init=False)

    def __post_init__(self):
        pts = np.asarray(self.points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise ShapeError(f"points must have shape (N, 3), got {pts.shape}")
        object.__setattr__(self, "points", pts)
        pose = self.pose
        object.__setattr__(self, "has_pose", pose is not None)
        if pose is None:
            pose = SE3.identity()
        elif not isinstance(pose, SE3):
            pose = SE3(pose)
        if pose.shape != ():
            raise ShapeError(f"pose must be a single SE3 (shape ()), got shape {pose.shape}")
        object.__setattr__(self, "pose", pose)
        if self.stamp is not None:
            object.__setattr__(self, "stamp", float(self.stamp))
        object.__setattr__(self, "dropped", checks.count("dropped", self.dropped, 0))

    @property
    def origin(self) -> np.ndarray:
        """World position of the sensor, shape (3,) (a new array: the pose's translation)."""
        return np.array(self.pose.translation, dtype=np.float64)

    def world_points(self) -> np.ndarray:
        """The points in the world frame, ``pose.apply(points)``: a new (N, 3) float64 array."""
        if self.points.shape[0] == 0:
            return np.zeros((0, 3), dtype=np.float64)
        return np.asarray(self.pose.apply(self.points), dtype=np.float64)

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def __repr__(self) -> str:
        o = np.array2string(self.origin, precision=4)
        return f"PointCloud({len(self)} points, origin={o}, stamp={self.stamp}, dropped={self.dropped})"
