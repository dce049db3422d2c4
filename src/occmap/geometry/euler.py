"""Euler angles, Z-Y-X (yaw, pitch, roll): ``R = Rz(yaw) · Ry(pitch) · Rx(roll)``.

This is the ROS RPY convention: roll about x is applied first, then pitch about y, then yaw
about z, all about the fixed axes (equivalently z, y', x'' about the moving ones).
Extracted angles are yaw, roll ∈ (−π, π] and pitch ∈ [−π/2, π/2].

Gimbal lock: at pitch = ±π/2 only yaw − roll (pitch = +π/2) or yaw + roll (pitch = −π/2) is
defined. There (cos pitch ≤ 4ε ≈ 9e-16, i.e. at the lock up to rounding)
:func:`matrix_to_euler_zyx` returns roll = 0 and puts the whole angle in yaw. Near the lock the
split between yaw and roll is ill-conditioned, but the returned angles always reproduce the
matrix to rounding error (≤ 2e-15 per entry).
"""

from __future__ import annotations

from . import _kernels as K
from ._arrays import entry, public, unstack

_to_matrix = entry(
    K.matrix_of_three, (3, 3), ((), "yaw", "finite"), ((), "pitch", "finite"), ((), "roll", "finite"),
    args=(K.EULER_ZYX,), one=K.euler_zyx_to_matrix_one,
)
_to_euler = entry(K.matrix_to_euler_zyx, (3,), ((3, 3), "R", "rotation"))


@public(_to_matrix)
def euler_zyx_to_matrix(yaw, pitch, roll):
    """Rotation matrices (..., 3, 3) from yaw, pitch, roll (radians; broadcast against each other)."""
    return _to_matrix(yaw, pitch, roll)


def matrix_to_euler_zyx(R):
    """``(yaw, pitch, roll)`` arrays (...) of rotation matrices (..., 3, 3); see the module notes."""
    return unstack(_to_euler(R))
