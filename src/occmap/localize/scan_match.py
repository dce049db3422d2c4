"""Scan matching against a likelihood field: Gauss–Newton on the distance to the nearest obstacle.

The residual of an end point is the bilinearly interpolated distance field at it (metres, cell
centres at integer + 0.5); end points farther than ``cutoff`` from every obstacle (outliers,
unmapped objects) are left out. Each step solves ``(JᵀJ + 10⁻⁶·n·I) δ = −Jᵀr`` for the pose
correction ``δ = (dx, dy, dθ)`` and stops when it is below 10⁻⁵ (m and rad). The matcher places
a pose between a particle filter's samples and below the grid's resolution.
"""

from __future__ import annotations

import numpy as np

from ..geometry.so2 import wrap_angle_one
from . import _kernels as K
from .likelihood_field import LikelihoodField

__all__ = ["match"]

#: Fewer inlier end points than this and the match has failed.
MIN_INLIERS = 10


def match(field: LikelihoodField, pose, bx: np.ndarray, by: np.ndarray, cutoff: float, iterations: int = 10):
    """Match end points ``(bx, by)`` (sensor/robot frame, m) from ``pose`` ``(x, y, theta)``
    against ``field``; returns ``(pose, inliers)``, the pose None when the match failed (too few
    inliers or a singular system)."""
    x = np.array(pose, dtype=np.float64)
    Hm = np.empty((3, 3))
    g = np.empty(3)
    inv = 1.0 / field.resolution
    used = 0
    for _ in range(iterations):
        _, used = K.match_normal_equations(x, bx, by, field.distance, field.max_dist, cutoff,
                                           field.origin[0], field.origin[1], inv, Hm, g)
        if used < MIN_INLIERS:
            return None, used
        Hm.flat[::4] += 1e-6 * used  # the diagonal
        try:
            step = np.linalg.solve(Hm, -g)
        except np.linalg.LinAlgError:
            return None, used
        x += step
        x[2] = wrap_angle_one(float(x[2]))
        if abs(step[0]) + abs(step[1]) < 1e-5 and abs(step[2]) < 1e-5:
            break
    return x, used
