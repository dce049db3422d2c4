"""SO(2): planar rotations, angle wrapping, and the batched :class:`SO2` wrapper.

Angles are radians, counter-clockwise positive. Wrapped angles lie in (−π, π], the range of
``atan2``, so ``wrap_angle(atan2(s, c)) == atan2(s, c)`` exactly. :func:`wrap_angle` wraps arrays;
:func:`wrap_angle_one` is the same rule, to the bit, for one float: callable from Numba kernels
(where it is inlined) and cheap on a Python scalar.
"""

from __future__ import annotations

import numpy as np

from . import _kernels as K
from ._kernels import wrap_angle_one
from ._arrays import ROTATION_TOL, batch, reject
from ._batch import Batch

_TWO_PI = 2.0 * np.pi


def wrap_angle(angle):
    """Wrap angles (radians) to (−π, π]; angles already in range are returned unchanged."""
    a = np.asarray(angle, dtype=np.float64)
    w = a - _TWO_PI * np.round(a / _TWO_PI)
    # the rounded multiple can land one period off near odd multiples of π; fold back exactly
    w = np.where(w <= -np.pi, w + _TWO_PI, w)
    return np.where(w > np.pi, w - _TWO_PI, w)


def rot2(theta):
    """Rotation matrices ``[[c, −s], [s, c]]`` of shape (..., 2, 2) for angles (...)."""
    t = np.asarray(theta, dtype=np.float64)
    c, s = np.cos(t), np.sin(t)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def so2_angle(R):
    """Angle in (−π, π] of rotation matrices (..., 2, 2), validated like :meth:`SO2.from_matrix`."""
    a, lead = batch(R, (2, 2), "R")
    _check_so2(a, lead, "R")
    return wrap_angle(np.arctan2(a[..., 1, 0], a[..., 0, 0]))


def _check_so2(a: np.ndarray, lead: tuple[int, ...], name: str) -> None:
    c, s = a[..., 0, 0], a[..., 1, 0]
    err = (a[..., 0, 1] + s) ** 2 + (a[..., 1, 1] - c) ** 2 + (c * c + s * s - 1.0) ** 2
    bad = ~(err <= ROTATION_TOL**2)
    if bad.any():
        reject(int(np.argmax(bad.reshape(-1))), lead, (a, (2, 2), name, "rotation2"))


class SO2(Batch):
    """Batched planar rotations, stored as angles in (−π, π] (shape ``self.shape``).

    Immutable; ``a @ b`` composes (apply ``b`` first), ``.apply(points)`` rotates (..., 2) points.
    """

    __slots__ = ()
    _ELEMENT = ()

    def _checked(self, angle) -> np.ndarray:
        return np.array(wrap_angle(angle))

    @classmethod
    def from_angle(cls, theta) -> SO2:
        """Rotations by ``theta`` radians (counter-clockwise)."""
        a = np.asarray(theta, dtype=np.float64)
        if not np.isfinite(a).all():
            reject(int(np.argmin(np.isfinite(a).reshape(-1))), a.shape, (a, (), "theta", "finite"))
        return cls(a)

    @classmethod
    def from_matrix(cls, R, project: bool = False) -> SO2:
        """From (..., 2, 2) matrices; raises NotARotationError unless ``project`` (nearest rotation)."""
        a, lead = batch(R, (2, 2), "R")
        if not project:
            _check_so2(a, lead, "R")
        elif not np.isfinite(a).all():
            reject(int(np.argmin(np.isfinite(a).all((-2, -1)).reshape(-1))), lead, (a, (2, 2), "R", "finite"))
        # atan2 of the averaged first column and rotated second column is the SVD projection in 2D.
        return cls(np.arctan2(a[..., 1, 0] - a[..., 0, 1], a[..., 0, 0] + a[..., 1, 1]))

    @classmethod
    def identity(cls, shape: tuple[int, ...] | int = ()) -> SO2:
        return cls(np.zeros(shape))

    @property
    def angle(self) -> np.ndarray:
        return self._a

    @property
    def matrix(self) -> np.ndarray:
        return rot2(self._a)

    def __matmul__(self, other: SO2) -> SO2:
        if not isinstance(other, SO2):
            return NotImplemented
        return SO2(self._a + other._a)

    def inv(self) -> SO2:
        return SO2(-self._a)

    def apply(self, points) -> np.ndarray:
        """Rotate (..., 2) points; leading shapes broadcast with ``self.shape``."""
        p, lead = batch(points, (2,), "points")
        row = K.first_nonfinite(p.reshape(-1, 2))
        if row >= 0:
            reject(row, lead, (p, (2,), "points", "finite"))
        c, s = np.cos(self._a)[..., None], np.sin(self._a)[..., None]
        x, y = p[..., :1], p[..., 1:]
        return np.concatenate([c * x - s * y, s * x + c * y], -1)

    def interpolate(self, other: SO2, t) -> SO2:
        """Geodesic interpolation: ``t = 0`` gives ``self``, ``t = 1`` gives ``other``, shortest way round."""
        t = np.asarray(t, dtype=np.float64)
        return SO2(self._a + t * wrap_angle(other._a - self._a))

    def __repr__(self) -> str:
        return f"SO2(angle={np.array2string(self._a, precision=6)})"
