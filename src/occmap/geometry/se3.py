"""SE(3): rigid transforms as homogeneous 4×4 matrices, their exp/log, and the :class:`SE3` wrapper.

``T_a_b`` maps coordinates in frame b to frame a: ``p_a = T_a_b @ p_b``, and
``T_a_c = T_a_b @ T_b_c``. Twists are ``ξ = (ρ, φ)``, translation part first (as Sophus and
Barfoot's *State Estimation for Robotics*): ``exp_se3(ξ) = [[exp(φ^), V ρ], [0, 1]]``.
Functions that take a transform check that its top-left block is a rotation and its last row is
(0, 0, 0, 1), and raise :class:`~occmap.errors.NotARotationError` naming the element. The
functions here also accept 2D transforms (..., 3, 3) with (..., 2) points where noted.
"""

from __future__ import annotations

import numpy as np

from ..errors import ShapeError
from . import _kernels as K
from ._arrays import entry, public, run
from ._batch import Batch
from .euler import euler_zyx_to_matrix
from .se2 import se2_matrix
from .so2 import so2_angle
from .quaternion import quat_slerp, quat_to_matrix
from .so3 import SO3, nearest_rotation

_T, _T2 = ((4, 4), "T", "rigid"), ((3, 3), "T", "rigid2")
_P, _P2 = ((3,), "points", "finite"), ((2,), "points", "finite")


def _invert_any(T):
    """Batches, 2D transforms and bad input; a single 3D transform goes straight to its kernel."""
    if _planar(T):
        return _invert2(T)
    return run(K.invert_transform, (4, 4), (T, *_T))


def _transform_any(T, points):
    """Batches, 2D transforms and bad input; a single 3D transform and point go straight to the kernel."""
    if _planar(T):
        return _transform2(T, points)
    return run(K.transform_points, (3,), (T, *_T), (points, *_P))


def _planar(T) -> bool:
    m = np.asarray(T)
    return m.ndim >= 2 and m.shape[-1] == 3


_make = entry(K.make_transform, (4, 4), ((3, 3), "R", "rotation"), ((3,), "t", "finite"))
_invert = entry(K.invert_transform, (4, 4), _T, otherwise=_invert_any)
_invert2 = entry(K.invert_transform2, (3, 3), _T2)
_transform = entry(K.transform_points, (3,), _T, _P, otherwise=_transform_any)
_transform2 = entry(K.transform_points2, (2,), _T2, _P2)
_compose = entry(K.compose_transforms, (4, 4), ((4, 4), "A", "finite"), ((4, 4), "B", "finite"))
_compose_rigid = entry(K.compose_rigid, (4, 4), ((4, 4), "A", "finite"), ((4, 4), "B", "finite"))
_exp = entry(K.exp_se3, (4, 4), ((6,), "twist", "finite"))
_log = entry(K.log_se3, (6,), ((4, 4), "T", "rigid"))


def make_transform(R, t):
    """Homogeneous transforms (..., 4, 4) from rotations (..., 3, 3) and translations (..., 3);
    2D: rotations (..., 2, 2) and translations (..., 2) give (..., 3, 3)."""
    r = np.asarray(R, dtype=np.float64)
    if r.shape[-2:] == (2, 2):
        tt = np.asarray(t, dtype=np.float64)
        if tt.shape[-1:] != (2,):
            raise ShapeError(f"t must have shape (..., 2) to go with 2×2 rotations, got {tt.shape}")
        return se2_matrix(tt[..., 0], tt[..., 1], so2_angle(r))
    return _make(r, t)


@public(_invert)
def invert_transform(T):
    """Inverses ``[[Rᵀ, −Rᵀt], [0, 1]]`` of rigid transforms (..., 4, 4) or 2D (..., 3, 3)."""
    return _invert(T)


@public(_transform)
def transform_points(T, points):
    """Apply rigid transforms to points: (..., 4, 4) with (..., 3), or 2D (..., 3, 3) with (..., 2).

    Leading shapes broadcast; one transform applied to N points is validated once and not copied.
    """
    return _transform(T, points)


@public(_compose)
def compose_transforms(A, B):
    """``A @ B`` for rigid transforms (..., 4, 4), broadcasting; faster than ``np.matmul`` on batches.
    The inputs are assumed rigid (only their top three rows are read)."""
    return _compose(A, B)


@public(_exp)
def exp_se3(twist):
    """Transforms (..., 4, 4) of twists ``(ρ, φ)`` (..., 6): rotation ``exp(φ^)``, translation ``V ρ``."""
    return _exp(twist)


@public(_log)
def log_se3(T):
    """Twists ``(ρ, φ)`` (..., 6) of rigid transforms, with ‖φ‖ ∈ [0, π]; inverse of :func:`exp_se3`."""
    return _log(T)


class SE3(Batch):
    """Batched rigid transforms of shape ``self.shape``, held as read-only (..., 4, 4) matrices.

    Immutable. ``T_a_b @ T_b_c`` composes (rotation block renormalised, as in ``SO3 @``;
    :func:`compose_transforms` leaves it as multiplied), ``.inv()`` inverts, ``.apply(points)`` maps (..., 3)
    points. ``.rotation`` is an :class:`SO3`, ``.translation`` a (..., 3) array.
    """

    __slots__ = ()
    _ELEMENT, _CHECK, _KIND = (4, 4), staticmethod(K.check_rigid), "rigid"
    _COMPOSE = staticmethod(_compose_rigid)

    @classmethod
    def from_matrix(cls, matrix, project: bool = False) -> SE3:
        """From (..., 4, 4) rigid transforms; a bad rotation block raises NotARotationError unless
        ``project`` is true, which replaces it by its nearest rotation."""
        if project:
            m = np.array(matrix, dtype=np.float64)
            if m.shape[-2:] != (4, 4):
                raise ShapeError(f"matrix must have shape (..., 4, 4), got {m.shape}")
            m[..., :3, :3] = nearest_rotation(m[..., :3, :3])
            return cls(m)
        return cls(matrix)

    @classmethod
    def from_rt(cls, rotation, translation) -> SE3:
        """From rotation matrices (..., 3, 3) or an :class:`SO3`, and translations (..., 3)."""
        r = rotation.matrix if isinstance(rotation, SO3) else rotation
        return cls(make_transform(r, translation), _trusted=True)

    @classmethod
    def from_quat(cls, q, translation=(0.0, 0.0, 0.0)) -> SE3:
        """From unit quaternions (w, x, y, z) (..., 4) and translations (..., 3)."""
        return cls(make_transform(quat_to_matrix(q), translation), _trusted=True)

    @classmethod
    def from_euler_zyx(cls, yaw, pitch, roll, translation=(0.0, 0.0, 0.0)) -> SE3:
        return cls(make_transform(euler_zyx_to_matrix(yaw, pitch, roll), translation), _trusted=True)

    @classmethod
    def from_rotvec(cls, rotvec, translation=(0.0, 0.0, 0.0)) -> SE3:
        return cls.from_rt(SO3.from_rotvec(rotvec), translation)

    @classmethod
    def exp(cls, twist) -> SE3:
        """From twists ``(ρ, φ)`` (..., 6), see :func:`exp_se3`."""
        return cls(exp_se3(twist), _trusted=True)

    @classmethod
    def identity(cls, shape: tuple[int, ...] | int = ()) -> SE3:
        shape = (shape,) if isinstance(shape, int) else tuple(shape)
        return cls(np.broadcast_to(np.eye(4), shape + (4, 4)), _trusted=True)

    @property
    def matrix(self) -> np.ndarray:
        return self._a

    @property
    def rotation(self) -> SO3:
        return SO3(self._a[..., :3, :3], _trusted=True)

    @property
    def translation(self) -> np.ndarray:
        return self._a[..., :3, 3]

    def log(self) -> np.ndarray:
        """Twists ``(ρ, φ)`` (..., 6), see :func:`log_se3`."""
        return log_se3(self._a)

    def inv(self) -> SE3:
        return SE3(invert_transform(self._a), _trusted=True)

    def apply(self, points) -> np.ndarray:
        """Map (..., 3) points through the transforms (leading shapes broadcast)."""
        return transform_points(self._a, points)

    def interpolate(self, other: SE3, t) -> SE3:
        """Interpolate as tf2 does: translation linearly, rotation by slerp (``t = 0`` gives ``self``)."""
        t = np.asarray(t, dtype=np.float64)
        q = quat_slerp(self.rotation.as_quat(), other.rotation.as_quat(), t)
        p = self.translation + t[..., None] * (other.translation - self.translation)
        return SE3(make_transform(quat_to_matrix(q), p), _trusted=True)

    def __repr__(self) -> str:
        if not self.shape:
            t = np.array2string(self.translation, precision=6)
            r = np.array2string(self.rotation.as_rotvec(), precision=6)
            return f"SE3(translation={t}, rotvec={r})"
        return f"SE3(shape={self.shape})"
