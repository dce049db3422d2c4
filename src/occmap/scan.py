"""Planar range scans: the one record that readers and simulators produce and maps consume."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from .errors import ShapeError


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


class ScanStack(NamedTuple):
    """A run of scans as plain arrays, for batched processing (see :func:`stack_scans`).

    Attributes
    ----------
    poses : ndarray (N, 3)
        Sensor poses ``(x, y, theta)``.
    ranges : ndarray (N, m)
        Ranges, ``m`` = the largest beam count; shorter scans are padded with NaN at the end.
    angles : ndarray (m,) or (N, m)
        Beam angles relative to each sensor heading: one shared row ``(m,)`` when every scan has
        the very same angles (the usual case for one log), else one NaN-padded row per scan.
    max_ranges : ndarray (N,)
        Each scan's maximum range.
    stamps : ndarray (N,)
        Each scan's time stamp.
    """

    poses: np.ndarray
    ranges: np.ndarray
    angles: np.ndarray
    max_ranges: np.ndarray
    stamps: np.ndarray

    def take(self, rows) -> ScanStack:
        """The scans ``rows`` (indices, a mask or a slice) as a stack."""
        return ScanStack(self.poses[rows], self.ranges[rows], self.angles if self.angles.ndim == 1 else self.angles[rows],
                         self.max_ranges[rows], self.stamps[rows])


def stack_scans(scans) -> ScanStack:
    """Stack an iterable of :class:`LaserScan` into arrays (a :class:`ScanStack`, which unpacks as
    ``poses, ranges, angles, max_ranges, stamps``).

    Scans with different beam counts are allowed: ``ranges`` (and ``angles``, when they differ)
    are padded with NaN to the largest count, and consumers drop NaN beams as they already do for
    invalid readings. ``angles`` is a single ``(m,)`` row when every scan's angles are identical,
    otherwise ``(N, m)``; check ``angles.ndim`` (or use ``np.broadcast_to(angles, ranges.shape)``).
    An empty input gives ``(0, 3)``, ``(0, 0)``, ``(0,)``, ``(0,)``, ``(0,)``. Arrays are float64.
    """
    scans = list(scans)
    count = len(scans)
    if count == 0:
        z = np.zeros((0,), dtype=np.float64)
        return ScanStack(np.zeros((0, 3)), np.zeros((0, 0)), z, z.copy(), z.copy())
    poses = np.empty((count, 3), dtype=np.float64)
    max_ranges = np.empty(count, dtype=np.float64)
    stamps = np.empty(count, dtype=np.float64)
    widths = np.empty(count, dtype=np.intp)
    first = np.asarray(scans[0].angles, dtype=np.float64)
    shared = True
    for k, s in enumerate(scans):
        poses[k] = s.pose
        max_ranges[k] = s.max_range
        stamps[k] = s.stamp
        widths[k] = np.shape(s.ranges)[0]
        if shared and s.angles is not first:
            a = np.asarray(s.angles)
            shared = a.shape == first.shape and np.array_equal(a, first)
    m = int(widths.max())
    if (widths == m).all():
        ranges = np.array([s.ranges for s in scans], dtype=np.float64).reshape(count, m)
    else:
        ranges = np.full((count, m), np.nan)
        for k, s in enumerate(scans):
            ranges[k, : widths[k]] = s.ranges
    if shared:
        angles = first.copy()
    else:
        angles = np.full((count, m), np.nan)
        for k, s in enumerate(scans):
            angles[k, : np.shape(s.angles)[0]] = s.angles
    return ScanStack(poses, ranges, angles, max_ranges, stamps)


def concat_stacks(stacks) -> ScanStack:
    """One :class:`ScanStack` of the scans of ``stacks`` in order, as :func:`stack_scans` would
    stack their scans: padded with NaN to the widest, one shared angle row when all share it."""
    stacks = [s for s in stacks if len(s.poses)]
    if len(stacks) == 1:
        return stacks[0]
    if not stacks:
        return stack_scans([])
    m = max(s.ranges.shape[1] for s in stacks)
    first = stacks[0].angles
    if first.ndim == 1 and all(s.angles is first or (s.angles.shape == first.shape and np.array_equal(s.angles, first))
                               for s in stacks):
        angles = first
    else:
        angles = np.concatenate([_padded(np.broadcast_to(s.angles, s.ranges.shape), m) for s in stacks])
    return ScanStack(np.concatenate([s.poses for s in stacks]), np.concatenate([_padded(s.ranges, m) for s in stacks]),
                     angles, np.concatenate([s.max_ranges for s in stacks]),
                     np.concatenate([s.stamps for s in stacks]))


def _padded(rows: np.ndarray, m: int) -> np.ndarray:
    """``rows`` (N, k ≤ m) padded with NaN columns to (N, m)."""
    if rows.shape[1] == m:
        return rows
    return np.concatenate([rows, np.full((rows.shape[0], m - rows.shape[1]), np.nan)], axis=1)


def with_poses(scans, poses) -> list[LaserScan]:
    """The scans with their sensor poses replaced by ``poses`` (N, 3) (scan-matched ones, say);
    ranges, angles, stamps and odometry are shared, not copied."""
    scans = list(scans)
    p = np.asarray(poses, dtype=np.float64)
    if p.shape != (len(scans), 3):
        raise ShapeError(f"poses must have shape ({len(scans)}, 3) for {len(scans)} scans, got {p.shape}")
    return [replace(s, pose=p[k].copy()) for k, s in enumerate(scans)]
