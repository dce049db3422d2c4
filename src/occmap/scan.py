"""Planar range scans: the one record that readers and simulators produce and maps consume."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class LaserScan:
    """One planar range scan: where the sensor was and what it measured.

    Attributes
    ----------
    pose : ndarray (3,)
        Sensor pose ``(x, y, theta)`` in the world frame, metres and radians.
    ranges : ndarray (n,)
        Measured ranges in metres. Readings at or beyond ``max_range`` mean "no return"; NaN,
        infinite, zero and negative readings are left as they are for the consumer to drop and count.
    angles : ndarray (n,)
        Beam angles relative to the sensor heading, radians, counter-clockwise.
    max_range : float
        The sensor's maximum range in metres.
    stamp : float
        Time of the scan in seconds (the logger's timestamp for recorded logs).
    odom : ndarray (3,) or None
        Raw odometry pose of the robot at the scan, when the source has one.
    """

    pose: np.ndarray
    ranges: np.ndarray
    angles: np.ndarray
    max_range: float
    stamp: float = 0.0
    odom: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.ranges.shape[0])
