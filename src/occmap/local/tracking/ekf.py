"""Extended Kalman filter for moving objects on the constant turn rate and velocity (CTRV) model,
batched over tracks: states ``(N, 5)``, covariances ``(N, 5, 5)``, no Python loop over tracks.

State ``s = (x, y, θ, v, ω)``: centre (m, world frame), heading (rad), speed along the heading
(m/s) and yaw rate (rad/s). Over ``dt`` the object follows the arc of constant ``v`` and ``ω``,
written as its chord (length ``v·dt·sinc(ω·dt/2)`` along ``θ + ω·dt/2``) exactly as
:func:`occmap.geometry.motion.unicycle_step` moves poses, so ``ω → 0`` needs no special case.
Process noise is white longitudinal acceleration (std ``accel`` m/s²) and yaw acceleration (std
``yaw_accel`` rad/s²) held over the step (Schubert, Richter and Wanielik, "Comparison and evaluation
of advanced motion models for vehicle tracking", FUSION 2008). With a finite ``yaw_rate_time`` τ the
yaw rate reverts to zero between measurements, ``ω ← ω·e^(−dt/τ)`` after the step (a first-order
Gauss–Markov turn rate): vehicles turn for a while, not for ever, so a yaw rate picked up from the
noise of one heading measurement dies out instead of turning a track seen only from behind.

Measurements (each returns the innovation ``y``, its Jacobian ``H`` and the caller gives ``R``):

- :func:`pose_innovation`: a point of a detected footprint ``(x, y)`` — its centre, or a point at a
  fixed offset in the object's frame (an edge or a corner seen) — and, for L-shaped views (two faces
  seen), its heading. A box's heading is known only modulo π, so the heading innovation is wrapped
  to ``(−π/2, π/2]``.
- :func:`radial_velocity_innovation`: a Doppler radar's radial velocity of the object, ego motion
  removed, along a world bearing ``φ``: ``h(s) = v·cos(θ − φ)``.

:func:`update` applies them in Joseph form (keeps ``P`` symmetric and positive semi-definite).
"""

from __future__ import annotations

import numpy as np

from ..._jit import kernel
from ...geometry._kernels import wrap_angle_one

__all__ = ["STATE", "pose_innovation", "predict", "radial_velocity_innovation", "update"]

#: Names of the state's components, in order.
STATE = ("x", "y", "heading", "speed", "yaw_rate")

_SERIES_BELOW = 1e-2


@kernel
def _sinc_and_derivative(h):
    """``sin(h)/h`` and its derivative, by their Taylor series near zero."""
    h2 = h * h
    if abs(h) < _SERIES_BELOW:
        return 1.0 - h2 / 6.0 + h2 * h2 / 120.0, -h / 3.0 + h * h2 / 30.0
    return np.sin(h) / h, (h * np.cos(h) - np.sin(h)) / h2


@kernel
def _predict(states, covs, dt, accel, yaw_accel, yaw_rate_time, out, out_covs):
    """:func:`predict` per track into ``out`` (N, 5) and, when ``covs`` has rows, ``out_covs``
    (N, 5, 5): ``P ← F P Fᵀ + G q Gᵀ`` with the motion's Jacobian ``F`` and the noise's ``G``,
    symmetrised."""
    F = np.empty((5, 5))
    FP = np.empty((5, 5))
    G = np.empty((5, 2))
    for n in range(states.shape[0]):
        x, y, th, v, w = states[n, 0], states[n, 1], states[n, 2], states[n, 3], states[n, 4]
        t = dt[n]
        h = 0.5 * w * t
        sinc, dsinc = _sinc_and_derivative(h)
        ca, sa = np.cos(th + h), np.sin(th + h)
        chord = v * t * sinc
        decay = np.exp(-t / yaw_rate_time)
        out[n, 0] = x + chord * ca
        out[n, 1] = y + chord * sa
        out[n, 2] = wrap_angle_one(th + 2.0 * h)
        out[n, 3] = v
        out[n, 4] = w * decay
        if covs.shape[0] == 0:
            continue
        half = 0.5 * t
        F[:, :] = 0.0
        for i in range(5):
            F[i, i] = 1.0
        F[0, 2] = -chord * sa
        F[1, 2] = chord * ca
        F[0, 3] = t * sinc * ca
        F[1, 3] = t * sinc * sa
        F[0, 4] = v * t * (dsinc * half * ca - sinc * sa * half)
        F[1, 4] = v * t * (dsinc * half * sa + sinc * ca * half)
        F[2, 4] = t
        F[4, 4] = decay
        G[:, :] = 0.0
        G[0, 0] = half * t * np.cos(th)
        G[1, 0] = half * t * np.sin(th)
        G[3, 0] = t
        G[2, 1] = half * t
        G[4, 1] = t
        qa = accel[n] * accel[n]
        qw = yaw_accel[n] * yaw_accel[n]
        for i in range(5):
            for j in range(5):
                acc = 0.0
                for k in range(5):
                    acc += F[i, k] * covs[n, k, j]
                FP[i, j] = acc
        for i in range(5):
            for j in range(i, 5):
                acc = G[i, 0] * qa * G[j, 0] + G[i, 1] * qw * G[j, 1]
                for k in range(5):
                    acc += FP[i, k] * F[j, k]
                out_covs[n, i, j] = acc
        for i in range(5):
            for j in range(i):
                out_covs[n, i, j] = out_covs[n, j, i]
    return out


def predict(states: np.ndarray, covs: np.ndarray | None, dt, accel: float, yaw_accel: float,
            yaw_rate_time: float = np.inf):
    """States and covariances ``dt`` seconds later (``dt``, ``accel`` and ``yaw_accel`` scalars or
    ``(N,)``; ``dt ≥ 0``; the yaw rate's time constant ``yaw_rate_time`` in seconds, inf: constant
    turn rate); returns new arrays. ``covs`` None: the states only (the same), ``(states, None)``."""
    s = np.ascontiguousarray(states, dtype=np.float64)
    n = s.shape[0]
    each = [np.ascontiguousarray(np.broadcast_to(np.asarray(a, dtype=np.float64), (n,))) for a in (dt, accel, yaw_accel)]
    out = np.empty((n, 5))
    if covs is None:
        _predict(s, np.empty((0, 5, 5)), *each, float(yaw_rate_time), out, np.empty((0, 5, 5)))
        return out, None
    out_covs = np.empty((n, 5, 5))
    _predict(s, np.ascontiguousarray(covs, dtype=np.float64), *each, float(yaw_rate_time), out, out_covs)
    return out, out_covs


@kernel
def pose_innovation_one(s, z, ox, oy, y, H):
    """:func:`pose_innovation` of one state ``s`` (5,) and measurement ``z``, into ``y`` (m,) and
    ``H`` (m, 5), ``m`` = 2 (the point) or 3 (and the heading) from ``y``'s length."""
    m = y.shape[0]
    c, sn = np.cos(s[2]), np.sin(s[2])
    H[:, :] = 0.0
    for k in range(m):
        y[k] = z[k] - s[k]
        H[k, k] = 1.0
    y[0] -= c * ox - sn * oy
    y[1] -= sn * ox + c * oy
    H[0, 2] = -sn * ox - c * oy
    H[1, 2] = c * ox - sn * oy
    if m == 3:
        y[2] = wrap_angle_one(2.0 * y[2]) / 2.0  # a box's heading is known modulo π
    return y


@kernel
def _pose_innovations(states, z, offset, y, H):
    for n in range(states.shape[0]):
        pose_innovation_one(states[n], z[n], offset[n, 0], offset[n, 1], y[n], H[n])
    return y


def pose_innovation(states: np.ndarray, z: np.ndarray, with_heading: bool, offset=None):
    """Innovation ``(N, m)`` and Jacobian ``(N, m, 5)`` of measurements ``z`` ``(N, 2)`` of the point
    at ``offset`` ``(N, 2)`` (m, in the object's frame: along its heading and to its left; None:
    the centre), or of that point and the heading ``(N, 3)`` when ``with_heading`` (``m`` = 2 or
    3): ``h(s) = (x, y) + Rot(θ)·offset``. A point off the centre ties the heading to where it is
    seen: a heading error swings it about the centre."""
    s = np.ascontiguousarray(states, dtype=np.float64)
    n, m = s.shape[0], 3 if with_heading else 2
    off = np.zeros((n, 2)) if offset is None else np.ascontiguousarray(offset, dtype=np.float64)
    y, H = np.empty((n, m)), np.empty((n, m, 5))
    _pose_innovations(s, np.ascontiguousarray(z, dtype=np.float64), off, y, H)
    return y, H


def radial_velocity_innovation(states: np.ndarray, bearing: np.ndarray, radial_velocity: np.ndarray):
    """Innovation ``(N, 1)`` and Jacobian ``(N, 1, 5)`` of radial velocities (m/s, ego motion
    removed, positive away from the sensor) seen along world bearings ``bearing`` (rad)."""
    d = states[:, 2] - bearing
    v = states[:, 3]
    y = (radial_velocity - v * np.cos(d))[:, None]
    H = np.zeros((states.shape[0], 1, 5))
    H[:, 0, 2] = -v * np.sin(d)
    H[:, 0, 3] = np.cos(d)
    return y, H


def innovation_covariance(covs: np.ndarray, H: np.ndarray, R: np.ndarray) -> np.ndarray:
    """``S = H P Hᵀ + R`` per track."""
    return H @ covs @ H.transpose(0, 2, 1) + R


@kernel
def _solve(A, B):
    """``B ← A⁻¹ B`` for a small square ``A`` (m, m) (overwritten) and ``B`` (m, k): Gaussian
    elimination with partial pivoting (LAPACK's ``gesv``)."""
    m = A.shape[0]
    for col in range(m):
        pivot = col
        for r in range(col + 1, m):
            if abs(A[r, col]) > abs(A[pivot, col]):
                pivot = r
        if pivot != col:
            for j in range(m):
                A[col, j], A[pivot, j] = A[pivot, j], A[col, j]
            for j in range(B.shape[1]):
                B[col, j], B[pivot, j] = B[pivot, j], B[col, j]
        for r in range(col + 1, m):
            f = A[r, col] / A[col, col]
            for j in range(col, m):
                A[r, j] -= f * A[col, j]
            for j in range(B.shape[1]):
                B[r, j] -= f * B[col, j]
    for col in range(m - 1, -1, -1):
        for j in range(B.shape[1]):
            acc = B[col, j]
            for k in range(col + 1, m):
                acc -= A[col, k] * B[k, j]
            B[col, j] = acc / A[col, col]
    return B


@kernel
def update_one(s, P, y, H, R):
    """One state ``s`` (5,) and covariance ``P`` (5, 5), in place, after a measurement with
    innovation ``y`` (m,), Jacobian ``H`` (m, 5) and noise ``R`` (m, m): Joseph form, the heading
    wrapped, ``P`` symmetrised. The gain ``K = P Hᵀ S⁻¹`` is taken as ``(S⁻¹ H P)ᵀ`` (``S``, ``P``
    symmetric)."""
    m = y.shape[0]
    X = np.zeros((m, 5))  # H P, then S⁻¹ H P = Kᵀ
    for i in range(m):
        for j in range(5):
            acc = 0.0
            for k in range(5):
                acc += H[i, k] * P[k, j]
            X[i, j] = acc
    S = np.empty((m, m))
    for i in range(m):
        for j in range(m):
            acc = R[i, j]
            for k in range(5):
                acc += X[i, k] * H[j, k]
            S[i, j] = acc
    _solve(S, X)
    A = np.empty((5, 5))  # I − K H
    for i in range(5):
        acc = 0.0
        for a in range(m):
            acc += X[a, i] * y[a]
        s[i] += acc
        for j in range(5):
            acc = 1.0 if i == j else 0.0
            for a in range(m):
                acc -= X[a, i] * H[a, j]
            A[i, j] = acc
    s[2] = wrap_angle_one(s[2])
    AP = np.empty((5, 5))
    for i in range(5):
        for j in range(5):
            acc = 0.0
            for k in range(5):
                acc += A[i, k] * P[k, j]
            AP[i, j] = acc
    KR = np.empty((5, m))
    for i in range(5):
        for b in range(m):
            acc = 0.0
            for a in range(m):
                acc += X[a, i] * R[a, b]
            KR[i, b] = acc
    for i in range(5):
        for j in range(i, 5):
            acc = 0.0
            for k in range(5):
                acc += AP[i, k] * A[j, k]
            for b in range(m):
                acc += KR[i, b] * X[b, j]
            P[i, j] = acc
    for i in range(5):
        for j in range(i):
            P[i, j] = P[j, i]
    return s


@kernel
def _updates(states, covs, y, H, R):
    for n in range(states.shape[0]):
        update_one(states[n], covs[n], y[n], H[n], R[n])
    return states


def update(states: np.ndarray, covs: np.ndarray, y: np.ndarray, H: np.ndarray, R: np.ndarray):
    """States and covariances after measurements with innovations ``y`` ``(N, m)``, Jacobians ``H``
    ``(N, m, 5)`` and noise ``R`` ``(N, m, m)``; returns new arrays."""
    out = np.array(states, dtype=np.float64, order="C")
    out_covs = np.array(covs, dtype=np.float64, order="C")
    _updates(out, out_covs, *(np.ascontiguousarray(a, dtype=np.float64) for a in (y, H, R)))
    return out, out_covs
