"""Unit quaternions, scalar first: ``q = (w, x, y, z)``, Hamilton product, ``q ⊗ p`` applies ``p`` first.

A rotation quaternion must have unit norm: functions that treat ``q`` as a rotation accept
``|‖q‖² − 1| ≤ 1e-6`` (float32 round-off) and raise :class:`~occmap.errors.NotUnitQuaternionError`
otherwise, naming the element; call :func:`quat_normalize` first for raw data. ``q`` and ``−q``
are the same rotation; functions returning quaternions from matrices pick ``w ≥ 0``.
ROS messages store ``(x, y, z, w)``: convert with :func:`quat_from_xyzw` / :func:`quat_to_xyzw`.
"""

from __future__ import annotations

from . import _kernels as K
from ._arrays import batch, entry, public

_Q = (4,)
_multiply = entry(K.quat_multiply, _Q, (_Q, "q1", "finite"), (_Q, "q2", "finite"), one=K.quat_multiply_one)
_conjugate = entry(K.quat_scale, _Q, (_Q, "q", "finite"), args=(0,))
_inverse = entry(K.quat_scale, _Q, (_Q, "q", "nonzero"), args=(1,))
_normalize = entry(K.quat_scale, _Q, (_Q, "q", "nonzero"), args=(2,))
_rotate = entry(K.quat_rotate, (3,), (_Q, "q", "unit"), ((3,), "v", "finite"))
_to_matrix = entry(K.quat_to_matrix, (3, 3), (_Q, "q", "unit"))
_from_matrix = entry(K.matrix_to_quat, _Q, ((3, 3), "R", "rotation"))
_from_axis_angle = entry(K.axis_angle_to_quat, _Q, ((3,), "axis", "nonzero"), ((), "angle", "finite"))
_to_axis_angle = entry(K.quat_to_axis_angle, _Q, (_Q, "q", "unit"))
_slerp = entry(K.quat_slerp, _Q, (_Q, "q0", "unit"), (_Q, "q1", "unit"), ((), "t", "finite"), one=K.quat_slerp_one)


@public(_multiply)
def quat_multiply(q1, q2):
    """Hamilton product ``q1 ⊗ q2`` (rotation by ``q2`` then ``q1``) of any finite quaternions."""
    return _multiply(q1, q2)


@public(_conjugate)
def quat_conjugate(q):
    """``(w, −x, −y, −z)``: the inverse rotation of a unit quaternion."""
    return _conjugate(q)


@public(_inverse)
def quat_inverse(q):
    """Multiplicative inverse ``q* / ‖q‖²`` of any non-zero finite quaternion."""
    return _inverse(q)


@public(_normalize)
def quat_normalize(q):
    """``q / ‖q‖`` for any non-zero finite quaternion (exact also for tiny or huge ones);
    raises NotUnitQuaternionError for a zero quaternion, NonFiniteError for NaN/inf."""
    return _normalize(q)


@public(_rotate)
def quat_rotate(q, v):
    """Rotate vectors ``v`` (..., 3) by unit quaternions ``q`` (..., 4): ``q ⊗ (0, v) ⊗ q*``."""
    return _rotate(q, v)


@public(_to_matrix)
def quat_to_matrix(q):
    """Rotation matrices (..., 3, 3) of unit quaternions (..., 4)."""
    return _to_matrix(q)


@public(_from_matrix)
def matrix_to_quat(R):
    """Unit quaternions (..., 4) with ``w ≥ 0`` of rotation matrices (..., 3, 3).

    Shepperd's pivoted method: exact for every rotation, 180° turns included. Matrices must be
    rotations to within ‖RᵀR − I‖ ≤ 1e-6 (else NotARotationError); project noisy ones first with
    :func:`~occmap.geometry.so3.nearest_rotation`.
    """
    return _from_matrix(R)


@public(_from_axis_angle)
def axis_angle_to_quat(axis, angle):
    """Quaternions of rotations by ``angle`` (radians, right-handed) about ``axis`` (non-zero, any length)."""
    return _from_axis_angle(axis, angle)


def quat_to_axis_angle(q):
    """``(axis, angle)`` of unit quaternions: unit axes (..., 3) and angles (...) in [0, π].

    The angle is ``2·atan2(‖v‖, |w|)``, accurate near 0 and π; the identity gets axis (1, 0, 0).
    """
    out = _to_axis_angle(q)
    return out[..., :3], out[..., 3]


@public(_slerp)
def quat_slerp(q0, q1, t):
    """Spherical linear interpolation from ``q0`` (t = 0) to ``q1`` (t = 1) along the shorter arc.

    ``q0``, ``q1`` (..., 4) and ``t`` (...) broadcast; ``t`` outside [0, 1] extrapolates along the
    same great circle. The result has unit norm.
    """
    return _slerp(q0, q1, t)


def quat_from_xyzw(q):
    """Reorder ROS / Eigen-storage ``(x, y, z, w)`` quaternions to ``(w, x, y, z)``."""
    a, _ = batch(q, _Q, "q")
    return a[..., [3, 0, 1, 2]]


def quat_to_xyzw(q):
    """Reorder ``(w, x, y, z)`` quaternions to ROS's ``(x, y, z, w)``."""
    a, _ = batch(q, _Q, "q")
    return a[..., [1, 2, 3, 0]]
