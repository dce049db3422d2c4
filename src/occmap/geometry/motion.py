"""Vehicle motion models for 2D poses: unicycle, differential drive, kinematic bicycle, odometry.

Conventions
-----------
- A pose is ``(x, y, theta)`` in metres and radians, an array of shape ``(..., 3)``; ``theta`` is
  the heading of the vehicle's x axis (forward) measured counter-clockwise from the world x axis.
  Input headings may be any finite angle; output headings and angle differences are wrapped by
  :func:`occmap.geometry.so2.wrap_angle` (to the range of ``atan2``).
- Velocities are in m/s, yaw rates in rad/s, durations in seconds, float64 throughout.
- Every function broadcasts: poses ``(..., 3)`` against controls of shape ``(...)`` by NumPy's
  rules (one control for N particles, N controls for one pose, or N of each), with no Python loop
  over poses.
- Errors: :class:`~occmap.errors.ShapeError` when poses are not ``(..., 3)`` or the arguments do
  not broadcast, :class:`~occmap.errors.NonFiniteError` when an argument holds NaN or infinity,
  :class:`~occmap.errors.InvalidArgumentError` for a value out of its range (each function lists
  those).

Motion over a step is integrated exactly for constant controls: the vehicle follows a circular arc
(a straight line when the yaw rate is zero). The chord of an arc that turns by ``phi`` has length
``d · sin(phi/2) / (phi/2)`` (``d`` the arc length) and points along ``theta + phi/2``; writing the
step this way, with a series for ``sin(h)/h`` near zero, is exact and never divides by a tiny yaw
rate, so ``omega -> 0`` meets the straight line continuously.

The odometry model is the one of Thrun, Burgard and Fox, *Probabilistic Robotics*, Tables 5.5 and
5.6, with the two changes ROS AMCL's ``diff`` model makes (see :func:`odometry_delta` and
:func:`apply_odometry`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InvalidArgumentError, NonFiniteError, ShapeError
from ._arrays import batch, where
from .so2 import wrap_angle

__all__ = [
    "OdometryMotionModel",
    "apply_odometry",
    "bicycle_step",
    "diff_drive_step",
    "odometry_delta",
    "unicycle_step",
]

#: AMCL's threshold: below this translation (metres) the bearing of the motion is taken as 0.
AMCL_MIN_TRANS = 0.01

# sin(h)/h by its Taylor series below this |h|; the first omitted term, h^6/5040, is < 3e-16 there.
_SINC_SERIES_BELOW = 1e-2


def unicycle_step(poses, v, omega, dt) -> np.ndarray:
    """Move poses for ``dt`` seconds at constant linear velocity ``v`` and yaw rate ``omega``.

    Parameters
    ----------
    poses : array_like, shape (..., 3)
        Start poses ``(x, y, theta)`` in metres and radians.
    v : array_like, shape (...)
        Forward velocity along the heading in m/s (negative drives backwards).
    omega : array_like, shape (...)
        Yaw rate in rad/s, positive counter-clockwise.
    dt : array_like, shape (...)
        Duration in seconds, ``>= 0``.

    Returns
    -------
    ndarray, shape (broadcast leading shape, 3)
        End poses, headings wrapped. The integration is exact: the pose moves along
        the circular arc of radius ``v / omega`` (a straight line for ``omega = 0``), so ``k`` steps
        of ``dt`` equal one step of ``k · dt``.

    Raises
    ------
    InvalidArgumentError
        ``dt < 0``.
    """
    p = _poses(poses, "poses")
    v = _values(v, "v")
    omega = _values(omega, "omega")
    dt = _values(dt, "dt")
    _require(dt >= 0, dt, "dt", ">= 0")
    shape = _lead_shape(("poses", p.shape[:-1]), ("v", v.shape), ("omega", omega.shape), ("dt", dt.shape))
    return _arc(p, v * dt, omega * dt, shape)


def diff_drive_step(poses, v_left, v_right, wheel_base, dt) -> np.ndarray:
    """Move differential-drive poses for ``dt`` seconds at constant wheel speeds.

    The reference point is midway between the wheels. The wheel speeds (m/s, the ground speed of
    each wheel's contact point, positive forward) give ``v = (v_right + v_left) / 2`` and
    ``omega = (v_right - v_left) / wheel_base``, then :func:`unicycle_step` integrates exactly.
    Equal speeds drive straight; opposite speeds turn in place.

    Parameters
    ----------
    poses : array_like, shape (..., 3)
        Start poses ``(x, y, theta)``.
    v_left, v_right : array_like, shape (...)
        Wheel speeds in m/s.
    wheel_base : array_like, shape (...)
        Distance between the wheels' contact points in metres, ``> 0``.
    dt : array_like, shape (...)
        Duration in seconds, ``>= 0``.

    Returns
    -------
    ndarray, shape (broadcast leading shape, 3)
        End poses of the point midway between the wheels, headings wrapped.

    Raises
    ------
    InvalidArgumentError
        ``wheel_base <= 0`` or ``dt < 0``.
    """
    p = _poses(poses, "poses")
    vl = _values(v_left, "v_left")
    vr = _values(v_right, "v_right")
    b = _values(wheel_base, "wheel_base")
    dt = _values(dt, "dt")
    _require(b > 0, b, "wheel_base", "> 0")
    _require(dt >= 0, dt, "dt", ">= 0")
    shape = _lead_shape(
        ("poses", p.shape[:-1]), ("v_left", vl.shape), ("v_right", vr.shape), ("wheel_base", b.shape), ("dt", dt.shape)
    )
    return _arc(p, 0.5 * (vr + vl) * dt, (vr - vl) / b * dt, shape)


def bicycle_step(poses, v, steering_angle, wheelbase, dt, *, max_steering=None) -> np.ndarray:
    """Move kinematic-bicycle (car-like) poses for ``dt`` seconds at constant speed and steering.

    The pose is that of the middle of the rear axle, whose velocity always points along the heading:
    the car cannot move sideways (the non-holonomic constraint ``-sin(theta)·dx + cos(theta)·dy = 0``
    holds at every instant). The yaw rate is ``omega = v · tan(delta) / L``, so the rear axle turns
    on a circle of radius ``L / tan(delta)``; the arc is integrated exactly as in
    :func:`unicycle_step`.

    Parameters
    ----------
    poses : array_like, shape (..., 3)
        Start poses ``(x, y, theta)`` of the rear-axle centre.
    v : array_like, shape (...)
        Speed of the rear-axle centre along the heading in m/s (negative reverses).
    steering_angle : array_like, shape (...)
        Front-wheel angle ``delta`` in radians, positive to the left, ``|delta| < pi/2``.
    wheelbase : array_like, shape (...)
        Distance ``L`` from the rear to the front axle in metres, ``> 0``.
    dt : array_like, shape (...)
        Duration in seconds, ``>= 0``.
    max_steering : float, optional
        Steering limit in radians, ``0 <= max_steering < pi/2``. When given, the steering angle
        saturates at ``±max_steering`` (as a real steering rack does) instead of being rejected.

    Returns
    -------
    ndarray, shape (broadcast leading shape, 3)
        End poses of the rear-axle centre, headings wrapped.

    Raises
    ------
    InvalidArgumentError
        ``|steering_angle| >= pi/2`` (the wheel would be sideways or beyond; checked before any
        saturation), ``wheelbase <= 0``, ``dt < 0`` or a ``max_steering`` outside ``[0, pi/2)``.
    """
    p = _poses(poses, "poses")
    v = _values(v, "v")
    delta = _values(steering_angle, "steering_angle")
    length = _values(wheelbase, "wheelbase")
    dt = _values(dt, "dt")
    _require(np.abs(delta) < np.pi / 2, delta, "steering_angle", "in (-pi/2, pi/2)")
    _require(length > 0, length, "wheelbase", "> 0")
    _require(dt >= 0, dt, "dt", ">= 0")
    if max_steering is not None:
        limit = _values(max_steering, "max_steering")
        if limit.ndim != 0:
            raise ShapeError(f"max_steering must be a scalar, got shape {limit.shape}")
        _require((limit >= 0) & (limit < np.pi / 2), limit, "max_steering", "in [0, pi/2)")
        delta = np.clip(delta, -limit, limit)
    shape = _lead_shape(
        ("poses", p.shape[:-1]), ("v", v.shape), ("steering_angle", delta.shape), ("wheelbase", length.shape),
        ("dt", dt.shape),
    )
    d = v * dt
    return _arc(p, d, d * np.tan(delta) / length, shape)


def odometry_delta(pose_prev, pose_curr, *, min_trans=AMCL_MIN_TRANS) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split the motion between two odometry poses into ``(rot1, trans, rot2)`` (Table 5.5).

    ``rot1`` turns from the previous heading to the direction of travel, ``trans`` is the
    straight-line distance, ``rot2`` turns from the direction of travel to the new heading::

        rot1  = wrap(atan2(dy, dx) - theta_prev)
        trans = hypot(dx, dy)
        rot2  = wrap(theta_curr - theta_prev - rot1)

    so that ``theta_curr = theta_prev + rot1 + rot2`` (mod 2 pi), both rotations wrapped.

    When ``trans < min_trans`` (AMCL's 0.01 m by default) ``rot1`` is set to 0 and the whole
    rotation goes to ``rot2``: the bearing of a near-zero translation (e.g. jitter while turning in
    place) is meaningless, and a large spurious ``rot1`` would inflate the rotation noise of
    :func:`apply_odometry`. The price is that re-applying such a delta moves the pose along its
    heading rather than along ``(dx, dy)``, a position error of at most ``2 · trans``; pass
    ``min_trans=0`` for an exact decomposition.

    Parameters
    ----------
    pose_prev, pose_curr : array_like, shape (..., 3)
        Odometry poses ``(x, y, theta)`` at the previous and the current time; broadcast.
    min_trans : float
        Translation (metres, ``>= 0``) below which ``rot1`` is 0.

    Returns
    -------
    rot1, trans, rot2 : ndarray, each of the broadcast leading shape
        Radians, metres (``>= 0``), radians.
    """
    prev = _poses(pose_prev, "pose_prev")
    curr = _poses(pose_curr, "pose_curr")
    _lead_shape(("pose_prev", prev.shape[:-1]), ("pose_curr", curr.shape[:-1]))
    threshold = _values(min_trans, "min_trans")
    if threshold.ndim != 0:
        raise ShapeError(f"min_trans must be a scalar, got shape {threshold.shape}")
    _require(threshold >= 0, threshold, "min_trans", ">= 0")
    dx = curr[..., 0] - prev[..., 0]
    dy = curr[..., 1] - prev[..., 1]
    trans = np.hypot(dx, dy)
    rot1 = np.where(trans < threshold, 0.0, wrap_angle(np.arctan2(dy, dx) - prev[..., 2]))
    rot2 = wrap_angle(wrap_angle(curr[..., 2] - prev[..., 2]) - rot1)
    return np.asarray(rot1), np.asarray(trans), np.asarray(rot2)


def apply_odometry(poses, delta, alphas=None, rng=None) -> np.ndarray:
    """Move poses by an odometry motion ``(rot1, trans, rot2)``, optionally sampling noise (Table 5.6).

    Each pose turns by ``rot1``, drives ``trans`` metres along its new heading and turns by
    ``rot2``::

        x' = x + trans · cos(theta + rot1)
        y' = y + trans · sin(theta + rot1)
        theta' = wrap(theta + rot1 + rot2)

    With ``alphas = (a1, a2, a3, a4)`` the three components are first perturbed by independent
    zero-mean Gaussians, drawn separately for every pose, with the standard deviations of
    *Probabilistic Robotics* Table 5.6::

        std(rot1)  = sqrt(a1 · r1² + a2 · trans²)
        std(trans) = sqrt(a3 · trans² + a4 · (r1² + r2²))
        std(rot2)  = sqrt(a1 · r2² + a2 · trans²)

    ``a1`` is rotation noise from rotation, ``a2`` rotation from translation, ``a3`` translation
    from translation and ``a4`` translation from rotation (ROS AMCL's ``odom_alpha1..4``). As in
    AMCL, ``r1 = min(|rot1|, pi - |rot1|)`` and likewise ``r2`` (the rotations taken as wrapped to
    ``[-pi, pi]``): driving backwards turns ``rot1`` and ``rot2`` by about ``pi``, and this makes
    reversing as certain as driving forwards instead of charging it a half-turn of rotation noise.

    Parameters
    ----------
    poses : array_like, shape (..., 3)
        Poses ``(x, y, theta)`` to move (e.g. the particles of a filter).
    delta : sequence of three array_like
        ``(rot1, trans, rot2)`` as returned by :func:`odometry_delta`, each broadcasting against the
        poses' leading shape.
    alphas : sequence of four floats, optional
        Noise parameters ``(a1, a2, a3, a4)``, each ``>= 0``; each weighs a squared rotation (rad²)
        or translation (m²) into a variance as above.
        ``None`` moves the poses without noise.
    rng : numpy.random.Generator or seed, optional
        Source of the noise, passed to :func:`numpy.random.default_rng` (so ``None`` draws fresh
        entropy). Ignored when ``alphas`` is ``None``.

    Returns
    -------
    ndarray, shape (broadcast leading shape, 3)
        Moved poses, headings wrapped.
    """
    p = _poses(poses, "poses")
    try:
        rot1, trans, rot2 = delta
    except (TypeError, ValueError):
        raise ShapeError(f"delta must be the triple (rot1, trans, rot2), got {delta!r}") from None
    rot1 = _values(rot1, "delta.rot1")
    trans = _values(trans, "delta.trans")
    rot2 = _values(rot2, "delta.rot2")
    shape = _lead_shape(
        ("poses", p.shape[:-1]), ("delta.rot1", rot1.shape), ("delta.trans", trans.shape), ("delta.rot2", rot2.shape)
    )
    if alphas is not None:
        a1, a2, a3, a4 = _alphas(alphas)
        r1 = _rotation_noise_term(rot1)
        r2 = _rotation_noise_term(rot2)
        t2 = trans * trans
        noise = np.random.default_rng(rng).standard_normal((3,) + shape)
        rot1 = rot1 + np.sqrt(a1 * r1 * r1 + a2 * t2) * noise[0]
        trans = trans + np.sqrt(a3 * t2 + a4 * (r1 * r1 + r2 * r2)) * noise[1]
        rot2 = rot2 + np.sqrt(a1 * r2 * r2 + a2 * t2) * noise[2]
    heading = p[..., 2] + rot1
    out = np.empty(shape + (3,))
    out[..., 0] = p[..., 0] + trans * np.cos(heading)
    out[..., 1] = p[..., 1] + trans * np.sin(heading)
    out[..., 2] = wrap_angle(heading + rot2)
    return out


@dataclass(frozen=True)
class OdometryMotionModel:
    """Odometry motion model for a particle filter (*Probabilistic Robotics* Table 5.6, AMCL ``diff``).

    Holds the four noise parameters (see :func:`apply_odometry`; the defaults are ROS AMCL's 0.2)
    and the translation below which the bearing is ignored (see :func:`odometry_delta`).

    Example::

        model = OdometryMotionModel(0.1, 0.05, 0.1, 0.05)
        particles = model.sample(particles, odom_prev, odom_curr, rng)
    """

    alpha1: float = 0.2
    alpha2: float = 0.2
    alpha3: float = 0.2
    alpha4: float = 0.2
    min_trans: float = AMCL_MIN_TRANS

    def __post_init__(self):
        alphas = _alphas(self.alphas)
        for name, value in zip(("alpha1", "alpha2", "alpha3", "alpha4"), alphas):
            object.__setattr__(self, name, float(value))
        threshold = _values(self.min_trans, "min_trans")
        if threshold.ndim != 0:
            raise ShapeError(f"min_trans must be a scalar, got shape {threshold.shape}")
        _require(threshold >= 0, threshold, "min_trans", ">= 0")
        object.__setattr__(self, "min_trans", float(threshold))

    @property
    def alphas(self) -> tuple[float, float, float, float]:
        """``(alpha1, alpha2, alpha3, alpha4)``."""
        return (self.alpha1, self.alpha2, self.alpha3, self.alpha4)

    def delta(self, prev, curr) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(rot1, trans, rot2)`` between two odometry poses; see :func:`odometry_delta`."""
        return odometry_delta(prev, curr, min_trans=self.min_trans)

    def sample(self, poses, prev_odom, curr_odom, rng=None) -> np.ndarray:
        """Move ``poses`` by the odometry motion from ``prev_odom`` to ``curr_odom``, with noise.

        The motion is measured in the odometry frame and applied in each pose's own frame, with an
        independent noise draw per pose; see :func:`apply_odometry`.
        """
        return apply_odometry(poses, self.delta(prev_odom, curr_odom), self.alphas, rng)

    def covariance(self, pose, cov, delta) -> np.ndarray:
        """Covariance (3×3) of the pose after the motion ``delta = (rot1, trans, rot2)`` from
        ``pose`` ``(x, y, theta)`` with covariance ``cov``: the extended Kalman filter's prediction
        (*Probabilistic Robotics* Table 7.3), ``G Σ Gᵀ + V M Vᵀ`` with ``G`` and ``V`` the Jacobians of
        :func:`apply_odometry` with respect to the pose and to ``(rot1, trans, rot2)``, and ``M`` the
        variances of :func:`apply_odometry`'s noise (the same ``alpha`` terms, rotations charged as
        AMCL does, so reversing is not a half-turn). Dead reckoning: the uncertainty the odometry
        alone accumulates, growing with the distance and the turns driven."""
        rot1, trans, rot2 = (float(v) for v in delta)
        h = float(pose[2]) + rot1
        c, s = np.cos(h), np.sin(h)
        g = np.array([[1.0, 0.0, -trans * s], [0.0, 1.0, trans * c], [0.0, 0.0, 1.0]])
        v = np.array([[-trans * s, c, 0.0], [trans * c, s, 0.0], [1.0, 0.0, 1.0]])
        r1 = float(_rotation_noise_term(np.asarray(rot1)))
        r2 = float(_rotation_noise_term(np.asarray(rot2)))
        a1, a2, a3, a4 = self.alphas
        m = np.diag([a1 * r1 * r1 + a2 * trans * trans, a3 * trans * trans + a4 * (r1 * r1 + r2 * r2),
                     a1 * r2 * r2 + a2 * trans * trans])
        return g @ np.asarray(cov, dtype=np.float64) @ g.T + v @ m @ v.T


def _arc(p: np.ndarray, d, phi, shape: tuple[int, ...]) -> np.ndarray:
    """Poses ``p`` moved along an arc of length ``d`` that turns the heading by ``phi``."""
    h = 0.5 * phi
    h2 = h * h
    small = np.abs(h) < _SINC_SERIES_BELOW
    sinc = np.where(small, 1.0 - h2 / 6.0 * (1.0 - h2 / 20.0), np.sin(h) / np.where(small, 1.0, h))
    chord = d * sinc
    bearing = p[..., 2] + h
    out = np.empty(shape + (3,))
    out[..., 0] = p[..., 0] + chord * np.cos(bearing)
    out[..., 1] = p[..., 1] + chord * np.sin(bearing)
    out[..., 2] = wrap_angle(p[..., 2] + phi)
    return out


def _rotation_noise_term(rot: np.ndarray) -> np.ndarray:
    """AMCL's ``min(|angle_diff(rot, 0)|, |angle_diff(rot, pi)|)``."""
    r = np.abs(wrap_angle(rot))
    return np.minimum(r, np.pi - r)


def _alphas(alphas) -> np.ndarray:
    a = np.asarray(alphas, dtype=np.float64)
    if a.shape != (4,):
        raise ShapeError(f"alphas must be four numbers (a1, a2, a3, a4), got shape {a.shape}")
    a = _values(a, "alphas")
    _require(a >= 0, a, "alphas", ">= 0")
    return a


def _poses(x, name: str) -> np.ndarray:
    flat, lead = batch(x, (3,), name)
    _finite(flat.reshape(lead + (3,)), name, pose=True)
    return flat.reshape(lead + (3,))


def _values(x, name: str) -> np.ndarray:
    flat, lead = batch(x, (), name)
    _finite(flat.reshape(lead), name)
    return flat.reshape(lead)


def _finite(a: np.ndarray, name: str, pose: bool = False) -> None:
    """Raise :class:`NonFiniteError` naming the first pose (or value) of ``a`` holding NaN or inf."""
    ok = np.isfinite(a)
    if ok.all():
        return
    if pose:
        ok = ok.all(axis=-1)
    index = int(np.argmin(ok.ravel()))
    bad = a.reshape((-1, 3))[index].tolist() if pose else float(a.ravel()[index])
    raise NonFiniteError(f"{name}{where(index, ok.shape)} = {bad!r} is not finite")


def _require(ok: np.ndarray, value: np.ndarray, name: str, what: str) -> None:
    """Raise :class:`InvalidArgumentError` naming the first element of ``value`` where ``ok`` is false."""
    if not np.all(ok):
        index = int(np.argmin(np.ravel(ok)))
        bad = float(np.ravel(value)[index])
        raise InvalidArgumentError(f"{name}{where(index, value.shape)} = {bad!r} must be {what}")


def _lead_shape(*named: tuple[str, tuple[int, ...]]) -> tuple[int, ...]:
    try:
        return np.broadcast_shapes(*(lead for _, lead in named))
    except ValueError:
        shapes = ", ".join(f"{name} {lead}" for name, lead in named)
        raise ShapeError(f"leading shapes do not broadcast: {shapes}") from None
