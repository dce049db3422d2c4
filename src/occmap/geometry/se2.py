"""SE(2): planar poses ``(x, y, theta)``, their 3×3 homogeneous matrices, and the :class:`SE2` wrapper.

``T = [[cos θ, −sin θ, x], [sin θ, cos θ, y], [0, 0, 1]]`` maps body coordinates to world
coordinates; θ in radians, counter-clockwise, returned in (−π, π].
"""

from __future__ import annotations

import numpy as np

from ..errors import ShapeError
from . import _kernels as K
from ._arrays import entry, public, reject, unstack
from ._batch import Batch
from .so2 import SO2, wrap_angle

_matrix = entry(
    K.matrix_of_three, (3, 3), ((), "x", "finite"), ((), "y", "finite"), ((), "theta", "finite"),
    args=(K.SE2_POSE,), one=K.se2_matrix_one,
)
_from_matrix = entry(K.se2_from_matrix, (3,), ((3, 3), "T", "rigid2"))
_apply = entry(K.transform_points2, (2,), ((3, 3), "pose", "rigid2"), ((2,), "points", "finite"))


@public(_matrix)
def se2_matrix(x, y, theta):
    """Homogeneous matrices (..., 3, 3) of poses; ``x``, ``y``, ``theta`` broadcast."""
    return _matrix(x, y, theta)


def se2_from_matrix(T):
    """``(x, y, theta)`` arrays (...) of planar rigid transforms (..., 3, 3), θ ∈ (−π, π]."""
    return unstack(_from_matrix(T))


def compose_poses(a, b) -> np.ndarray:
    """Poses ``a ⊕ b`` (..., 3): pose or motion ``b`` ``(x, y, θ)`` taken in the frame of pose ``a``,
    θ wrapped; the ``xytheta`` of ``SE2(a) @ SE2(b)`` without its checks, for a loop that
    moves one pose at a time. ``a`` and ``b`` broadcast."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    return np.stack([a[..., 0] + c * b[..., 0] - s * b[..., 1], a[..., 1] + s * b[..., 0] + c * b[..., 1],
                     wrap_angle(a[..., 2] + b[..., 2])], -1)


def relative_poses(a, b) -> np.ndarray:
    """Motions ``a⁻¹ ⊕ b`` (..., 3) from poses ``a`` to poses ``b``, in ``a``'s frame, θ wrapped; the
    ``xytheta`` of ``SE2(a).inv() @ SE2(b)`` without its checks. ``a`` and ``b`` broadcast."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    dx, dy = b[..., 0] - a[..., 0], b[..., 1] - a[..., 1]
    return np.stack([c * dx + s * dy, -s * dx + c * dy, wrap_angle(b[..., 2] - a[..., 2])], -1)


class SE2(Batch):
    """Batched planar poses of shape ``self.shape``, held as a read-only (..., 3) ``(x, y, θ)`` array.

    Immutable. ``a @ b`` composes (``T_a_c = T_a_b @ T_b_c``), ``.inv()`` inverts,
    ``.apply(points)`` maps (..., 2) points from the body frame to the world frame.
    """

    __slots__ = ()
    _ELEMENT = (3,)

    def _checked(self, xytheta) -> np.ndarray:
        p = np.array(xytheta, dtype=np.float64)
        if p.shape[-1:] != (3,):
            raise ShapeError(f"xytheta must have shape (..., 3), got {p.shape}")
        row = K.first_nonfinite(p.reshape(-1, 3))
        if row >= 0:
            reject(row, p.shape[:-1], (p, (3,), "xytheta", "finite"))
        p[..., 2] = wrap_angle(p[..., 2])
        return p

    @classmethod
    def from_xytheta(cls, x, y, theta) -> SE2:
        x, y, theta = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (x, y, theta)))
        return cls(np.stack([x, y, theta], -1))

    @classmethod
    def from_matrix(cls, matrix, project: bool = False) -> SE2:
        """From (..., 3, 3) planar rigid transforms; raises NotARotationError for a bad rotation
        block unless ``project`` is true (then θ = atan2 of the nearest rotation)."""
        m = np.asarray(matrix, dtype=np.float64)
        if project:
            if m.shape[-2:] != (3, 3):
                raise ShapeError(f"matrix must have shape (..., 3, 3), got {m.shape}")
            theta = SO2.from_matrix(m[..., :2, :2], project=True).angle
            return cls.from_xytheta(m[..., 0, 2], m[..., 1, 2], theta)
        x, y, theta = se2_from_matrix(m)
        return cls(np.stack([x, y, theta], -1))

    @classmethod
    def identity(cls, shape: tuple[int, ...] | int = ()) -> SE2:
        shape = (shape,) if isinstance(shape, int) else tuple(shape)
        return cls(np.zeros(shape + (3,)))

    @property
    def xytheta(self) -> np.ndarray:
        return self._a

    @property
    def translation(self) -> np.ndarray:
        return self._a[..., :2]

    @property
    def rotation(self) -> SO2:
        return SO2(self._a[..., 2])

    @property
    def matrix(self) -> np.ndarray:
        return se2_matrix(self._a[..., 0], self._a[..., 1], self._a[..., 2])

    def __matmul__(self, other: SE2) -> SE2:
        if not isinstance(other, SE2):
            return NotImplemented
        a, b = self._a, other._a
        c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
        x = a[..., 0] + c * b[..., 0] - s * b[..., 1]
        y = a[..., 1] + s * b[..., 0] + c * b[..., 1]
        return SE2(np.stack(np.broadcast_arrays(x, y, a[..., 2] + b[..., 2]), -1))

    def inv(self) -> SE2:
        p = self._a
        c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
        return SE2(np.stack([-c * p[..., 0] - s * p[..., 1], s * p[..., 0] - c * p[..., 1], -p[..., 2]], -1))

    def apply(self, points) -> np.ndarray:
        """Map (..., 2) body-frame points to the world frame (leading shapes broadcast)."""
        return _apply(self.matrix, points)

    def interpolate(self, other: SE2, t) -> SE2:
        """Translation linearly, heading the short way round (``t = 0`` gives ``self``)."""
        t = np.asarray(t, dtype=np.float64)[..., None]
        d = other._a - self._a
        d[..., 2] = wrap_angle(d[..., 2])
        return SE2(self._a + t * d)

    def __repr__(self) -> str:
        if not self.shape:
            x, y, th = self._a
            return f"SE2(x={x:.6g}, y={y:.6g}, theta={th:.6g})"
        return f"SE2(shape={self.shape})"
