"""Unit quaternions, scalar first: ``q = (w, x, y, z)``, Hamilton product, ``q ⊗ p`` applies ``p`` first.

A rotation quaternion must have unit norm: functions that treat ``q`` as a rotation accept
``|‖q‖² − 1| ≤ 1e-6`` (float32 round-off) and raise :class:`~occmap.errors.NotUnitQuaternionError`
otherwise, naming the element; call :func:`quat_normalize` first for raw data. ``q`` and ``−q``
are the same rotation; functions returning quaternions from matrices pick ``w ≥ 0``.
ROS messages store ``(x, y, z, w)``: convert with :func:`quat_from_xyzw` / :func:`quat_to_xyzw`.
"""

from __future__ import annotations

import numpy as np

from . import _kernels as K
from ._arrays import Rejected, batch, broadcast, reject

_Q = (4,)


def quat_multiply(q1, q2):
    """Hamilton product ``q1 ⊗ q2`` (rotation by ``q2`` then ``q1``) of any finite quaternions."""
    (a, b), lead = broadcast((q1, _Q, "q1"), (q2, _Q, "q2"))
    out = np.empty(lead + _Q)
    try:
        K.quat_multiply(a, b, out)
    except Rejected as e:
        reject(e.args[0], lead, (a, _Q, "q1", "finite"), (b, _Q, "q2", "finite"))
    return out


def _scaled(q, mode: int, kind: str):
    a, lead = batch(q, _Q, "q")
    out = np.empty(a.shape)
    try:
        K.quat_scale(a, mode, out)
    except Rejected as e:
        reject(e.args[0], lead, (a, _Q, "q", kind))
    return out


def quat_conjugate(q):
    """``(w, −x, −y, −z)``: the inverse rotation of a unit quaternion."""
    return _scaled(q, 0, "finite")


def quat_inverse(q):
    """Multiplicative inverse ``q* / ‖q‖²`` of any non-zero quaternion."""
    return _scaled(q, 1, "nonzero")


def quat_normalize(q):
    """``q / ‖q‖``; raises NotUnitQuaternionError for a zero quaternion, NonFiniteError for NaN."""
    return _scaled(q, 2, "nonzero")


def quat_rotate(q, v):
    """Rotate vectors ``v`` (..., 3) by unit quaternions ``q`` (..., 4): ``q ⊗ (0, v) ⊗ q*``."""
    (a, b), lead = broadcast((q, _Q, "q"), (v, (3,), "v"))
    out = np.empty(lead + (3,))
    try:
        K.quat_rotate(a, b, out)
    except Rejected as e:
        reject(e.args[0], lead, (a, _Q, "q", "unit"), (b, (3,), "v", "finite"))
    return out


def quat_to_matrix(q):
    """Rotation matrices (..., 3, 3) of unit quaternions (..., 4)."""
    a, lead = batch(q, _Q, "q")
    out = np.empty(lead + (3, 3))
    try:
        K.quat_to_matrix(a, out)
    except Rejected as e:
        reject(e.args[0], lead, (a, _Q, "q", "unit"))
    return out


def matrix_to_quat(R):
    """Unit quaternions (..., 4) with ``w ≥ 0`` of rotation matrices (..., 3, 3).

    Shepperd's pivoted method: exact for every rotation, 180° turns included. Matrices must be
    rotations to within ‖RᵀR − I‖ ≤ 1e-6 (else NotARotationError); project noisy ones first with
    :func:`~occmap.geometry.so3.nearest_rotation`.
    """
    a, lead = batch(R, (3, 3), "R")
    out = np.empty(lead + _Q)
    try:
        K.matrix_to_quat(a, out)
    except Rejected as e:
        reject(e.args[0], lead, (a, (3, 3), "R", "rotation"))
    return out


def axis_angle_to_quat(axis, angle):
    """Quaternions of rotations by ``angle`` (radians, right-handed) about ``axis`` (non-zero, any length)."""
    (a, g), lead = broadcast((axis, (3,), "axis"), (angle, (), "angle"))
    out = np.empty(lead + _Q)
    try:
        K.axis_angle_to_quat(a, g, out)
    except Rejected as e:
        reject(e.args[0], lead, (g, (), "angle", "finite"), (a, (3,), "axis", "nonzero"))
    return out


def quat_to_axis_angle(q):
    """``(axis, angle)`` of unit quaternions: unit axes (..., 3) and angles (...) in [0, π].

    The angle is ``2·atan2(‖v‖, |w|)``, accurate near 0 and π; the identity gets axis (1, 0, 0).
    """
    a, lead = batch(q, _Q, "q")
    out = np.empty(lead + _Q)
    try:
        K.quat_to_axis_angle(a, out)
    except Rejected as e:
        reject(e.args[0], lead, (a, _Q, "q", "unit"))
    return out[..., :3], out[..., 3]


def quat_slerp(q0, q1, t):
    """Spherical linear interpolation from ``q0`` (t = 0) to ``q1`` (t = 1) along the shorter arc.

    ``q0``, ``q1`` (..., 4) and ``t`` (...) broadcast; ``t`` outside [0, 1] extrapolates along the
    same great circle. The result has unit norm.
    """
    (a, b, u), lead = broadcast((q0, _Q, "q0"), (q1, _Q, "q1"), (t, (), "t"))
    out = np.empty(lead + _Q)
    try:
        K.quat_slerp(a, b, u, out)
    except Rejected as e:
        reject(e.args[0], lead, (a, _Q, "q0", "unit"), (b, _Q, "q1", "unit"), (u, (), "t", "finite"))
    return out


def quat_from_xyzw(q):
    """Reorder ROS / Eigen-storage ``(x, y, z, w)`` quaternions to ``(w, x, y, z)``."""
    a, _ = batch(q, _Q, "q")
    return a[..., [3, 0, 1, 2]]


def quat_to_xyzw(q):
    """Reorder ``(w, x, y, z)`` quaternions to ROS's ``(x, y, z, w)``."""
    a, _ = batch(q, _Q, "q")
    return a[..., [1, 2, 3, 0]]
