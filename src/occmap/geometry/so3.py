"""SO(3): rotation matrices, the hat/vee maps, Rodrigues' exp/log, and the :class:`SO3` wrapper.

Rotation matrices act on column vectors (``p' = R @ p``) and are right-handed. Rotation vectors
(axis · angle, radians) are the so(3) coordinates: ``exp_so3(w) = exp(hat(w))``. Functions that
take a rotation check it (‖RᵀR − I‖_F ≤ 1e-6 and det R > 0) and raise
:class:`~occmap.errors.NotARotationError` naming the element; :func:`nearest_rotation` projects
noisy matrices. All functions broadcast over leading dimensions and return float64.
"""

from __future__ import annotations

import numpy as np

from ..errors import ShapeError
from . import _kernels as K
from ._arrays import batch, entry, public, reject
from ._batch import Batch
from .euler import euler_zyx_to_matrix, matrix_to_euler_zyx
from .quaternion import axis_angle_to_quat, matrix_to_quat, quat_slerp, quat_to_matrix

_hat = entry(K.hat, (3, 3), ((3,), "w", "finite"))
_vee = entry(K.vee, (3,), ((3, 3), "W", "finite"))
_rot = [entry(K.rot_axis, (3, 3), ((), "angle", "finite"), args=(axis,)) for axis in range(3)]
_exp = entry(K.exp_so3, (3, 3), ((3,), "rotvec", "finite"))
_axis_angle = entry(K.matrix_to_axis_angle, (4,), ((3, 3), "R", "rotation"), args=(False,))
_log = entry(K.matrix_to_axis_angle, (3,), ((3, 3), "R", "rotation"), args=(True,))
_rotate = entry(K.rotate_points, (3,), ((3, 3), "rotation", "rotation"), ((3,), "points", "finite"))
_compose = entry(K.compose_rotations, (3, 3), ((3, 3), "A", "finite"), ((3, 3), "B", "finite"))


@public(_hat)
def hat(w):
    """Skew-symmetric matrices (..., 3, 3) with ``hat(w) @ v == cross(w, v)``."""
    return _hat(w)


@public(_vee)
def vee(W):
    """Inverse of :func:`hat`; takes the skew-symmetric part ``(W − Wᵀ)/2`` of any 3×3 matrix."""
    return _vee(W)


@public(_rot[0])
def rot_x(angle):
    """Rotations (..., 3, 3) by ``angle`` radians about x (counter-clockwise seen from +x)."""
    return _rot[0](angle)


@public(_rot[1])
def rot_y(angle):
    """Rotations (..., 3, 3) by ``angle`` radians about y."""
    return _rot[1](angle)


@public(_rot[2])
def rot_z(angle):
    """Rotations (..., 3, 3) by ``angle`` radians about z."""
    return _rot[2](angle)


@public(_exp)
def exp_so3(rotvec):
    """Rodrigues' formula: rotation matrices of rotation vectors (..., 3), any angle.

    Computed through the unit quaternion ``(cos θ/2, sin(θ/2)/θ · w)`` with a series for
    sin(θ/2)/θ at small θ, so it is accurate to rounding from θ = 0 upward.
    """
    return _exp(rotvec)


def matrix_to_axis_angle(R):
    """``(axis, angle)``: unit axes (..., 3) and angles (...) in [0, π] of rotation matrices.

    Goes through Shepperd's quaternion and ``angle = 2·atan2(‖v‖, w)``, which stays accurate to
    ~1e-15 at angles near 0 and near π, where ``acos((tr R − 1)/2)`` loses half the digits.
    The identity gets axis (1, 0, 0); at exactly π, ``axis`` and ``−axis`` are equally valid.
    """
    out = _axis_angle(R)
    return out[..., :3], out[..., 3]


@public(_log)
def log_so3(R):
    """Rotation vectors (..., 3) (axis · angle, angle ∈ [0, π]) of rotation matrices; accurate to
    rounding relative to the angle from 0 up to π (see :func:`matrix_to_axis_angle`)."""
    return _log(R)


def axis_angle_to_matrix(axis, angle):
    """Rotation matrices of rotations by ``angle`` radians about ``axis`` (non-zero, any length)."""
    return quat_to_matrix(axis_angle_to_quat(axis, angle))


def nearest_rotation(M):
    """The rotation closest to each (..., 3, 3) or (..., 2, 2) matrix in the Frobenius norm.

    ``U · diag(1, …, 1, det(U Vᵀ)) · Vᵀ`` from the SVD ``M = U S Vᵀ``; raises
    NonFiniteError for NaN/inf entries.
    """
    a = np.asarray(M, dtype=np.float64)
    if a.ndim < 2 or a.shape[-1] != a.shape[-2] or a.shape[-1] not in (2, 3):
        raise ShapeError(f"M must have shape (..., 3, 3) or (..., 2, 2), got {a.shape}")
    d = a.shape[-1]
    a, lead = batch(a, (d, d), "M")
    row = K.first_nonfinite(a.reshape(-1, d * d))
    if row >= 0:
        reject(row, lead, (a, (d, d), "M", "finite"))
    u, _, vt = np.linalg.svd(a)
    # flip the last singular direction where U Vᵀ is a reflection
    u[..., :, -1] *= np.where(np.linalg.det(u @ vt) < 0, -1.0, 1.0)[..., None]
    return u @ vt


def is_rotation(M, tol: float = 1e-6):
    """Boolean array (...): ``‖RᵀR − I‖_F ≤ tol`` and ``det R > 0``; False for NaN/inf, never raises
    for values (only for a shape other than (..., 3, 3))."""
    a, lead = batch(M, (3, 3), "M")
    err = np.empty(lead)
    K.rotation_errors(a, err)
    return err <= tol


def random_rotations(n: int | None = None, rng=None):
    """Rotations drawn uniformly (Haar measure) from SO(3): ``(n, 3, 3)``, or ``(3, 3)`` for n None.

    Normalised 4-D Gaussian samples are uniform unit quaternions (Shoemake / Muller).
    ``rng`` is a ``numpy.random.Generator`` or anything ``numpy.random.default_rng`` accepts.
    """
    g = np.random.default_rng(rng)
    q = g.standard_normal((1 if n is None else int(n), 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    R = quat_to_matrix(q)
    return R[0] if n is None else R


class SO3(Batch):
    """Batched 3D rotations of shape ``self.shape``, held as read-only (..., 3, 3) matrices.

    Immutable. ``a @ b`` composes (apply ``b`` first) and renormalises the product (one
    cheap step, ``_kernels._renormalize``: a long chain of products stays on SO(3), as scipy's
    renormalised quaternion products do); ``.apply(points)`` rotates (..., 3)
    points; construct with ``from_matrix``, ``from_quat`` (w, x, y, z), ``from_rotvec``,
    ``from_euler_zyx`` or ``identity``. Indexing and ``len`` act on the batch.
    """

    __slots__ = ()
    _ELEMENT, _CHECK, _KIND = (3, 3), staticmethod(K.check_rotation), "rotation"
    _COMPOSE = staticmethod(_compose)

    @classmethod
    def from_matrix(cls, matrix, project: bool = False) -> SO3:
        """From (..., 3, 3) rotation matrices; a non-rotation raises NotARotationError unless
        ``project`` is true, which replaces each matrix by its nearest rotation."""
        if project:
            m, _ = batch(matrix, (3, 3), "matrix")
            return cls(nearest_rotation(m), _trusted=True)
        return cls(matrix)

    @classmethod
    def from_quat(cls, q) -> SO3:
        """From unit quaternions (..., 4), scalar first (w, x, y, z)."""
        return cls(quat_to_matrix(q), _trusted=True)

    @classmethod
    def from_rotvec(cls, rotvec) -> SO3:
        """From rotation vectors (..., 3): axis times angle in radians."""
        return cls(exp_so3(rotvec), _trusted=True)

    @classmethod
    def from_axis_angle(cls, axis, angle) -> SO3:
        return cls(axis_angle_to_matrix(axis, angle), _trusted=True)

    @classmethod
    def from_euler_zyx(cls, yaw, pitch, roll) -> SO3:
        """From Z-Y-X Euler angles: ``Rz(yaw) Ry(pitch) Rx(roll)`` (see :mod:`occmap.geometry.euler`)."""
        return cls(euler_zyx_to_matrix(yaw, pitch, roll), _trusted=True)

    @classmethod
    def identity(cls, shape: tuple[int, ...] | int = ()) -> SO3:
        shape = (shape,) if isinstance(shape, int) else tuple(shape)
        return cls(np.broadcast_to(np.eye(3), shape + (3, 3)), _trusted=True)

    @classmethod
    def random(cls, n: int | None = None, rng=None) -> SO3:
        """Uniformly distributed rotations (see :func:`random_rotations`)."""
        return cls(random_rotations(n, rng), _trusted=True)

    @property
    def matrix(self) -> np.ndarray:
        return self._a

    def as_quat(self) -> np.ndarray:
        """Unit quaternions (..., 4), (w, x, y, z) with w ≥ 0."""
        return matrix_to_quat(self._a)

    def as_rotvec(self) -> np.ndarray:
        return log_so3(self._a)

    def as_euler_zyx(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(yaw, pitch, roll); roll = 0 at gimbal lock."""
        return matrix_to_euler_zyx(self._a)

    def inv(self) -> SO3:
        return SO3(np.swapaxes(self._a, -1, -2), _trusted=True)

    def apply(self, points) -> np.ndarray:
        """Rotate (..., 3) points; their leading shape broadcasts with ``self.shape``."""
        return _rotate(self._a, points)

    def magnitude(self) -> np.ndarray:
        """Rotation angles in [0, π] (radians)."""
        return matrix_to_axis_angle(self._a)[1]

    def interpolate(self, other: SO3, t) -> SO3:
        """Geodesic (slerp) interpolation: ``t = 0`` gives ``self``, ``t = 1`` gives ``other``."""
        q = quat_slerp(self.as_quat(), other.as_quat(), t)
        return SO3(quat_to_matrix(q), _trusted=True)

    def __repr__(self) -> str:
        if not self.shape:
            return f"SO3(rotvec={np.array2string(self.as_rotvec(), precision=6)})"
        return f"SO3(shape={self.shape})"


__all__ = [
    "SO3",
    "axis_angle_to_matrix",
    "exp_so3",
    "hat",
    "is_rotation",
    "log_so3",
    "matrix_to_axis_angle",
    "nearest_rotation",
    "random_rotations",
    "rot_x",
    "rot_y",
    "rot_z",
    "vee",
]
