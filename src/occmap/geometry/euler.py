"""Euler angles, Z-Y-X (yaw, pitch, roll): ``R = Rz(yaw) · Ry(pitch) · Rx(roll)``.

This is the ROS RPY convention: roll about x is applied first, then pitch about y, then yaw
about z, all about the fixed axes (equivalently z, y', x'' about the moving ones).
Extracted angles are yaw, roll ∈ (−π, π] and pitch ∈ [−π/2, π/2].

Gimbal lock: at pitch = ±π/2 only yaw − roll (pitch = +π/2) or yaw + roll (pitch = −π/2) is
defined. There (cos pitch < 1e-12) :func:`matrix_to_euler_zyx` returns roll = 0 and puts the
whole angle in yaw. Near the lock the split between yaw and roll is ill-conditioned, but the
returned angles always reproduce the matrix to rounding error.
"""

from __future__ import annotations

import numpy as np

from . import _kernels as K
from ._arrays import Rejected, batch, broadcast, reject, unstack


def euler_zyx_to_matrix(yaw, pitch, roll):
    """Rotation matrices (..., 3, 3) from yaw, pitch, roll (radians; broadcast against each other)."""
    if type(yaw) is float and type(pitch) is float and type(roll) is float:
        out = np.empty((3, 3))
        try:
            K.euler_zyx_to_matrix_one(yaw, pitch, roll, out)
        except Rejected:
            pass  # fall through to the array path, which names the bad argument
        else:
            return out
    (y, p, r), lead = broadcast((yaw, (), "yaw"), (pitch, (), "pitch"), (roll, (), "roll"))
    out = np.empty(lead + (3, 3))
    try:
        K.euler_zyx_to_matrix(y, p, r, out)
    except Rejected as e:
        reject(e.args[0], lead, (y, (), "yaw", "finite"), (p, (), "pitch", "finite"), (r, (), "roll", "finite"))
    return out


def matrix_to_euler_zyx(R):
    """``(yaw, pitch, roll)`` arrays (...) of rotation matrices (..., 3, 3); see the module notes."""
    a, lead = batch(R, (3, 3), "R")
    out = np.empty(lead + (3,))
    try:
        K.matrix_to_euler_zyx(a, out)
    except Rejected as e:
        reject(e.args[0], lead, (a, (3, 3), "R", "rotation"))
    return unstack(out)
