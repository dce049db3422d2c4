"""Euler Z-Y-X (yaw, pitch, roll), R = Rz(yaw) Ry(pitch) Rx(roll): convention, round trips,
gimbal lock (roll = 0 where cos pitch ≤ 4ε), and scipy's intrinsic 'ZYX' as the reference."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from scipy.spatial.transform import Rotation

from occmap.errors import NonFiniteError
from occmap.geometry import euler_zyx_to_matrix, matrix_to_euler_zyx, quat_to_matrix, rot_x, rot_y, rot_z

EPS = np.finfo(np.float64).eps
PROP = settings(deadline=None)
HALF_PI = np.pi / 2

angles = st.floats(-np.pi, np.pi)
unit_quats = (
    hnp.arrays(np.float64, 4, elements=st.floats(-1.0, 1.0, allow_subnormal=False))
    .filter(lambda v: np.linalg.norm(v) > 0.1)
    .map(lambda v: v / np.linalg.norm(v))
)


def angle_diff(a, b):
    d = np.subtract(a, b)
    return np.arctan2(np.sin(d), np.cos(d))


def reference_matrix(yaw, pitch, roll):
    """Rz(yaw) Ry(pitch) Rx(roll) written out in NumPy."""
    cy, sy, cp, sp, cr, sr = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch), np.cos(roll), np.sin(roll)
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return Rz @ Ry @ Rx


# ---------------------------------------------------------------- convention


@PROP
@given(angles, angles, angles)
def test_convention_rz_ry_rx(yaw, pitch, roll):
    R = euler_zyx_to_matrix(yaw, pitch, roll)
    np.testing.assert_allclose(R, reference_matrix(yaw, pitch, roll), rtol=0, atol=4 * EPS)
    np.testing.assert_allclose(R, rot_z(yaw) @ rot_y(pitch) @ rot_x(roll), rtol=0, atol=4 * EPS)


def test_convention_is_ros_rpy():
    """Roll about x first, then pitch about y, then yaw about z, all about fixed axes:
    scipy's intrinsic 'ZYX' with (yaw, pitch, roll) and extrinsic 'xyz' with (roll, pitch, yaw)."""
    y, p, r = 0.7, -0.4, 2.1
    R = euler_zyx_to_matrix(y, p, r)
    np.testing.assert_allclose(R, Rotation.from_euler("ZYX", [y, p, r]).as_matrix(), rtol=0, atol=4 * EPS)
    np.testing.assert_allclose(R, Rotation.from_euler("xyz", [r, p, y]).as_matrix(), rtol=0, atol=4 * EPS)
    # pure yaw turns x towards y; pure pitch turns z towards x; pure roll turns y towards z
    np.testing.assert_allclose(euler_zyx_to_matrix(HALF_PI, 0.0, 0.0) @ [1, 0, 0], [0, 1, 0], atol=EPS)
    np.testing.assert_allclose(euler_zyx_to_matrix(0.0, HALF_PI, 0.0) @ [0, 0, 1], [1, 0, 0], atol=EPS)
    np.testing.assert_allclose(euler_zyx_to_matrix(0.0, 0.0, HALF_PI) @ [0, 1, 0], [0, 0, 1], atol=EPS)


# ---------------------------------------------------------------- round trips


@PROP
@given(unit_quats)
def test_matrix_euler_matrix_round_trip(q):
    R = quat_to_matrix(q)
    y, p, r = matrix_to_euler_zyx(R)
    assert -np.pi < y <= np.pi and -np.pi < r <= np.pi and -HALF_PI <= p <= HALF_PI
    # the gimbal rule (roll = 0 where cos p < 1e-12) drops terms of size cos p: allow 2·cos p there
    # (hypothesis found q = (0, 0.7071, 1.7e-15, 0.7071): cos p = 2.4e-15, error 2.4e-15)
    cp = np.hypot(R[0, 0], R[1, 0])
    atol = 8 * EPS + (2.1 * cp if cp < 1e-12 else 0.0)
    np.testing.assert_allclose(euler_zyx_to_matrix(y, p, r), R, rtol=0, atol=atol)


@PROP
@given(angles, st.floats(-HALF_PI + 1e-6, HALF_PI - 1e-6), angles)
def test_euler_matrix_euler_round_trip(yaw, pitch, roll):
    """Away from the lock the angles come back; the error grows like 1/cos(pitch)."""
    y, p, r = matrix_to_euler_zyx(euler_zyx_to_matrix(yaw, pitch, roll))
    tol = 8 * EPS / np.cos(pitch)
    assert abs(p - pitch) <= tol
    assert abs(angle_diff(y, yaw)) <= tol
    assert abs(angle_diff(r, roll)) <= tol


@pytest.mark.parametrize("sign", [1.0, -1.0], ids=["+90", "-90"])
def test_gimbal_lock_exact(sign, rng):
    """pitch = ±π/2 exactly: roll == 0, pitch = ±π/2, yaw = yaw ∓ roll, and R reproduced to 1e-15."""
    yaw, roll = rng.uniform(-np.pi, np.pi, (2, 500))
    for R in (euler_zyx_to_matrix(yaw, sign * HALF_PI, roll), Rotation.from_euler("ZYX", np.c_[yaw, np.full(500, sign * HALF_PI), roll]).as_matrix()):
        y, p, r = matrix_to_euler_zyx(R)
        np.testing.assert_array_equal(r, 0.0)
        np.testing.assert_allclose(p, sign * HALF_PI, rtol=0, atol=2 * EPS)
        np.testing.assert_allclose(angle_diff(y, yaw - sign * roll), 0.0, rtol=0, atol=8 * EPS)
        assert ((y > -np.pi) & (y <= np.pi)).all()
        np.testing.assert_allclose(euler_zyx_to_matrix(y, p, r), R, rtol=0, atol=8 * EPS)


def test_gimbal_lock_matches_scipy():
    """scipy also sets the third intrinsic angle (roll) to 0 at the lock."""
    for pitch in (HALF_PI, -HALF_PI):
        R = Rotation.from_euler("ZYX", [0.3, pitch, 0.2])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # scipy warns about the lock
            ref = R.as_euler("ZYX")
        np.testing.assert_allclose(matrix_to_euler_zyx(R.as_matrix()), ref, rtol=0, atol=8 * EPS)


@pytest.mark.parametrize("pitch", [HALF_PI - 1e-9, HALF_PI + 1e-9, -HALF_PI + 1e-9, -HALF_PI - 1e-9])
def test_near_gimbal_lock_reproduces_matrix(pitch, rng):
    """cos(pitch) ≈ 1e-9: yaw and roll are separately ill-conditioned, but the returned angles
    reproduce R. Measured ≤ 1.1e-15 elementwise over 10⁵ samples; asserted ≤ 1e-14 (brief: 1e-12)."""
    yaw, roll = rng.uniform(-np.pi, np.pi, (2, 2000))
    R = Rotation.from_euler("ZYX", np.c_[yaw, np.full(2000, pitch), roll]).as_matrix()
    y, p, r = matrix_to_euler_zyx(R)
    assert (np.abs(p) <= HALF_PI).all()
    assert (r != 0).all()  # not treated as locked
    np.testing.assert_allclose(euler_zyx_to_matrix(y, p, r), R, rtol=0, atol=1e-14)
    # and the pitch itself is accurate: folded into [−π/2, π/2]
    np.testing.assert_allclose(np.abs(p), HALF_PI - 1e-9, rtol=0, atol=1e-15)


def test_gimbal_threshold_error_bound():
    """Only matrices at the lock up to rounding (cos p ≤ 4ε) get roll = 0, which then changes R by
    at most ~2·cos p; a pitch 1e-12 away from the lock is resolved without the convention and
    reproduces R to rounding (with a 1e-12 threshold the error there was 1e-12)."""
    inside = HALF_PI - 5e-16  # cos p ≈ 5e-16 (after rounding of π/2 − 5e-16 and of the matrix)
    R = Rotation.from_euler("ZYX", [0.4, inside, 1.3]).as_matrix()
    y, p, r = matrix_to_euler_zyx(R)
    assert r == 0.0
    np.testing.assert_allclose(euler_zyx_to_matrix(y, p, r), R, rtol=0, atol=2.5e-15)
    outside = HALF_PI - 1e-12
    R = Rotation.from_euler("ZYX", [0.4, outside, 1.3]).as_matrix()
    y, p, r = matrix_to_euler_zyx(R)
    assert r != 0.0
    np.testing.assert_allclose(euler_zyx_to_matrix(y, p, r), R, rtol=0, atol=8 * EPS)


# ---------------------------------------------------------------- scipy cross-checks


def test_scipy_euler(scipy_rotations):
    R = scipy_rotations.as_matrix()
    ypr = scipy_rotations.as_euler("ZYX")
    y, p, r = matrix_to_euler_zyx(R)
    np.testing.assert_allclose(p, ypr[:, 1], rtol=0, atol=1e-13)
    np.testing.assert_allclose(angle_diff(y, ypr[:, 0]), 0, rtol=0, atol=1e-13)
    np.testing.assert_allclose(angle_diff(r, ypr[:, 2]), 0, rtol=0, atol=1e-13)
    np.testing.assert_allclose(euler_zyx_to_matrix(ypr[:, 0], ypr[:, 1], ypr[:, 2]), R, rtol=0, atol=8 * EPS)


# ---------------------------------------------------------------- shapes


def test_shapes_and_broadcasting(rng):
    assert euler_zyx_to_matrix(0.1, 0.2, 0.3).shape == (3, 3)  # Python floats (fast path)
    assert euler_zyx_to_matrix(1, 0, 0).shape == (3, 3)  # ints
    np.testing.assert_array_equal(euler_zyx_to_matrix(0.1, 0.2, 0.3), euler_zyx_to_matrix(np.float64(0.1), [0.2][0], np.array(0.3)))
    y = rng.uniform(-3, 3, (3, 1))
    r = rng.uniform(-3, 3, (1, 4))
    R = euler_zyx_to_matrix(y, 0.5, r)
    assert R.shape == (3, 4, 3, 3)
    np.testing.assert_allclose(R[2, 1], reference_matrix(y[2, 0], 0.5, r[0, 1]), rtol=0, atol=4 * EPS)
    yy, pp, rr = matrix_to_euler_zyx(R)
    assert yy.shape == pp.shape == rr.shape == (3, 4)
    one = matrix_to_euler_zyx(np.eye(3).tolist())
    assert all(np.ndim(a) == 0 for a in one)
    assert euler_zyx_to_matrix(np.zeros(0), 0.0, 0.0).shape == (0, 3, 3)
    assert matrix_to_euler_zyx(np.zeros((0, 3, 3)))[0].shape == (0,)
    # non-contiguous
    Rt = np.swapaxes(np.swapaxes(R, -1, -2).copy(), -1, -2)
    np.testing.assert_array_equal(matrix_to_euler_zyx(Rt)[2], rr)
    # columns of an (N, 3) array are read in place (strided), with the same result and the same errors
    ypr = rng.uniform(-3, 3, (100, 3))
    np.testing.assert_array_equal(euler_zyx_to_matrix(ypr[:, 0], ypr[:, 1], ypr[:, 2]),
                                  euler_zyx_to_matrix(*ypr.T.copy()))
    np.testing.assert_array_equal(euler_zyx_to_matrix(ypr[::-2, 0], 0.5, ypr[::-2, 2]),
                                  euler_zyx_to_matrix(ypr[::-2, 0].copy(), 0.5, ypr[::-2, 2].copy()))
    ypr[7, 1] = np.nan
    with pytest.raises(NonFiniteError, match=r"pitch\[7\]"):
        euler_zyx_to_matrix(ypr[:, 0], ypr[:, 1], ypr[:, 2])


def test_yaw_roll_range_excludes_minus_pi():
    """Regression (found by this suite, fixed in 17003c6): atan2(−0.0, −1) = −π leaked out."""
    R = np.array([[-1.0, 0.0, 0.0], [-0.0, -1.0, 0.0], [0.0, 0.0, 1.0]])  # Rz(π) with r10 = −0.0
    y, _, _ = matrix_to_euler_zyx(R)
    assert -np.pi < y <= np.pi
    # found by hypothesis: a half turn about x with 1e-250 perturbations gives roll = −π
    t = -2.96700939e-250
    _, _, r = matrix_to_euler_zyx(quat_to_matrix([t, 1.0, t, t]))
    assert -np.pi < r <= np.pi
