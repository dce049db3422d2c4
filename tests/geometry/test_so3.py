"""SO(3): hat/vee, elementary rotations, Rodrigues exp/log, axis-angle, nearest_rotation,
is_rotation, random_rotations; group laws, the hard angles, and scipy cross-checks."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from scipy.linalg import expm
from scipy.spatial.transform import Rotation
from scipy.stats import kstest

from occmap.geometry import (
    SO3,
    axis_angle_to_matrix,
    euler_zyx_to_matrix,
    exp_so3,
    hat,
    is_rotation,
    log_so3,
    matrix_to_axis_angle,
    nearest_rotation,
    quat_to_matrix,
    random_rotations,
    rot_x,
    rot_y,
    rot_z,
    vee,
)

EPS = np.finfo(np.float64).eps
PROP = settings(deadline=None)  # max_examples from the profile (100 by default)

directions = (
    hnp.arrays(np.float64, 3, elements=st.floats(-1.0, 1.0, allow_subnormal=False))
    .filter(lambda v: np.linalg.norm(v) > 0.1)
    .map(lambda v: v / np.linalg.norm(v))
)
#: rotation vectors with |w| < π (away from the ±axis ambiguity at π)
# angles 0 or in the normal range: a subnormal angle (< 2e-308 rad) underflows when halved inside exp
small_rotvecs = st.builds(lambda n, a: n * a, directions, st.just(0.0) | st.floats(1e-300, np.pi - 1e-6))
any_rotvecs = hnp.arrays(np.float64, 3, elements=st.floats(-20.0, 20.0))
unit_quats = (
    hnp.arrays(np.float64, 4, elements=st.floats(-1.0, 1.0, allow_subnormal=False))
    .filter(lambda v: np.linalg.norm(v) > 0.1)
    .map(lambda v: v / np.linalg.norm(v))
)


def K(n):
    n = np.asarray(n, float)
    return np.array([[0, -n[2], n[1]], [n[2], 0, -n[0]], [-n[1], n[0], 0]])


def rodrigues(axis, angle):
    """Reference: I + sin θ K + (1 − cos θ) K², 1 − cos θ written 2 sin²(θ/2) (exact near 0)."""
    k = K(np.asarray(axis, float) / np.linalg.norm(axis))
    return np.eye(3) + np.sin(angle) * k + 2.0 * np.sin(angle / 2) ** 2 * (k @ k)


def assert_rotation(R, atol=8 * EPS):
    R = np.asarray(R)
    I = np.broadcast_to(np.eye(3), R.shape)
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), I, rtol=0, atol=atol)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, rtol=0, atol=atol)


# ---------------------------------------------------------------- every constructor gives a rotation


@PROP
@given(hnp.arrays(np.float64, 4, elements=st.floats(-50.0, 50.0)))
def test_every_constructor_output_is_a_rotation(v):
    assert_rotation(exp_so3(v[:3]))
    assert_rotation(rot_x(v[0]))
    assert_rotation(rot_y(v[1]))
    assert_rotation(rot_z(v[2]))
    assert_rotation(euler_zyx_to_matrix(v[0], v[1], v[2]))
    if np.linalg.norm(v[:3]) > 1e-100:
        assert_rotation(axis_angle_to_matrix(v[:3], v[3]))
    if np.linalg.norm(v) > 1e-3:
        assert_rotation(quat_to_matrix(v / np.linalg.norm(v)))


@PROP
@given(hnp.arrays(np.float64, (3, 3), elements=st.floats(-10.0, 10.0)).filter(lambda m: np.linalg.svd(m, compute_uv=False)[-1] > 1e-3))
def test_nearest_rotation_output_is_a_rotation(M):
    assert_rotation(nearest_rotation(M), atol=32 * EPS)


def test_random_rotations_are_rotations():
    R = random_rotations(1000, rng=1)
    assert R.shape == (1000, 3, 3)
    assert_rotation(R)
    assert random_rotations(rng=1).shape == (3, 3)
    np.testing.assert_array_equal(random_rotations(5, rng=7), random_rotations(5, rng=np.random.default_rng(7)))


# ---------------------------------------------------------------- hat / vee / elementary rotations


@PROP
@given(any_rotvecs, any_rotvecs)
def test_hat_is_cross_product_and_vee_inverts(w, v):
    W = hat(w)
    np.testing.assert_array_equal(W, -W.T)
    np.testing.assert_allclose(W @ v, np.cross(w, v), rtol=0, atol=8 * EPS * np.abs(w).max() * np.abs(v).max())
    np.testing.assert_array_equal(vee(W), w)
    # vee takes the skew part of any matrix
    S = np.outer(v, v)
    np.testing.assert_allclose(vee(W + S), w, rtol=0, atol=1e-13)


def test_elementary_rotations_right_handed():
    x, y, z = np.eye(3)
    np.testing.assert_allclose(rot_z(np.pi / 2) @ x, y, atol=EPS)
    np.testing.assert_allclose(rot_x(np.pi / 2) @ y, z, atol=EPS)
    np.testing.assert_allclose(rot_y(np.pi / 2) @ z, x, atol=EPS)
    c, s = np.cos(0.3), np.sin(0.3)
    np.testing.assert_array_equal(rot_x(0.3), [[1, 0, 0], [0, c, -s], [0, s, c]])
    np.testing.assert_array_equal(rot_y(0.3), [[c, 0, s], [0, 1, 0], [-s, 0, c]])
    np.testing.assert_array_equal(rot_z(0.3), [[c, -s, 0], [s, c, 0], [0, 0, 1]])


def test_elementary_rotations_vs_scipy(rng):
    a = rng.uniform(-7, 7, 1000)
    for f, ax in [(rot_x, "x"), (rot_y, "y"), (rot_z, "z")]:
        np.testing.assert_allclose(f(a), Rotation.from_euler(ax, a[:, None]).as_matrix(), rtol=0, atol=4 * EPS)


# ---------------------------------------------------------------- exp / log


@PROP
@given(any_rotvecs)
def test_exp_matches_rodrigues_and_expm(w):
    R = exp_so3(w)
    theta = np.linalg.norm(w)
    ref = np.eye(3) if theta == 0 else rodrigues(w, theta)
    # ‖w‖ itself is rounded (relative EPS), so the angle is only defined to about θ·EPS
    np.testing.assert_allclose(R, ref, rtol=0, atol=4 * EPS * (1 + theta))
    np.testing.assert_allclose(R, expm(hat(w)), rtol=0, atol=1e-12)  # expm's own error ~1e-13 at |w| = 16
    np.testing.assert_allclose(R @ w, w, rtol=0, atol=1e-14 * (1 + theta))  # the axis is fixed


@PROP
@given(small_rotvecs)
def test_log_exp_round_trip(w):
    """log(exp(w)) = w for |w| < π. Measured over 10⁶ samples: ≤ 8.4e-16·|w|; asserted 1e-14·|w|."""
    np.testing.assert_allclose(log_so3(exp_so3(w)), w, rtol=0, atol=1e-14 * np.abs(w).max())


@PROP
@given(unit_quats)
def test_exp_log_round_trip(q):
    R = quat_to_matrix(q)
    w = log_so3(R)
    assert np.linalg.norm(w) <= np.pi + 4 * EPS
    np.testing.assert_allclose(exp_so3(w), R, rtol=0, atol=8 * EPS)


@PROP
@given(directions, st.floats(-5, 5), st.floats(-5, 5))
def test_exp_one_parameter_subgroup(n, a, b):
    np.testing.assert_allclose(exp_so3(a * n) @ exp_so3(b * n), exp_so3((a + b) * n), rtol=0, atol=1e-14)


@PROP
@given(unit_quats, any_rotvecs)
def test_exp_conjugation(q, w):
    """R exp(w) Rᵀ = exp(R w): the adjoint of SO(3) is R itself."""
    R = quat_to_matrix(q)
    np.testing.assert_allclose(R @ exp_so3(w) @ R.T, exp_so3(R @ w), rtol=0, atol=1e-13)


@PROP
@given(unit_quats, unit_quats, unit_quats)
def test_composition_associative_and_inverse(q1, q2, q3):
    A, B, C = quat_to_matrix(q1), quat_to_matrix(q2), quat_to_matrix(q3)
    np.testing.assert_allclose((A @ B) @ C, A @ (B @ C), rtol=0, atol=8 * EPS)
    # the inverse rotation's log is −log (away from π)
    w = log_so3(A)
    if np.linalg.norm(w) < np.pi - 1e-6:
        np.testing.assert_allclose(log_so3(A.T), -w, rtol=0, atol=1e-14)


@PROP
@given(directions, st.one_of(st.just(0.0), st.floats(1e-300, np.pi - 1e-6)))  # not subnormal angles
def test_axis_angle_round_trip(n, angle):
    R = axis_angle_to_matrix(n, angle)
    np.testing.assert_allclose(R, rodrigues(n, angle), rtol=0, atol=8 * EPS)
    axis, a = matrix_to_axis_angle(R)
    assert 0 <= a <= np.pi
    assert a == pytest.approx(angle, rel=1e-14, abs=0)
    if angle > 0:
        np.testing.assert_allclose(axis, n, rtol=0, atol=1e-14)


# ---------------------------------------------------------------- the hard angles

EDGE_ANGLES = [1e-12, 1e-8, 1e-4, np.pi - 1e-9, np.pi]
EDGE_AXES = {
    "x": np.array([1.0, 0, 0]),
    "xy": np.array([1.0, 1.0, 0]) / np.sqrt(2),
    "generic": np.array([0.2, -0.6, 0.7746]) / np.linalg.norm([0.2, -0.6, 0.7746]),
    "generic2": np.array([-0.9, 0.1, 0.3]) / np.linalg.norm([-0.9, 0.1, 0.3]),
}


@pytest.mark.parametrize("angle", EDGE_ANGLES)
@pytest.mark.parametrize("axis", list(EDGE_AXES.values()), ids=list(EDGE_AXES))
def test_edge_angles(axis, angle):
    """Measured here: elementwise error of exp vs Rodrigues (≤ 2 ulp of 1), and the relative error
    of the recovered rotation vector |log(R) − w|/|w| (≤ 4e-16 measured; asserted ≤ 4e-15);
    at exactly π either sign of the axis is accepted."""
    w = angle * axis
    ref = rodrigues(axis, angle)
    R = exp_so3(w)
    np.testing.assert_allclose(R, ref, rtol=0, atol=4 * EPS)
    if angle < 1:  # the skew part carries the small angle: check it relatively, not just to 1e-16
        np.testing.assert_allclose(vee(R), np.sin(angle) * axis, rtol=4 * EPS, atol=4 * EPS * angle)

    for got in (log_so3(ref), log_so3(R)):
        if angle == np.pi and got @ axis < 0:
            got = -got
        assert np.linalg.norm(got - w) <= 4e-15 * angle

    n, a = matrix_to_axis_angle(ref)
    assert abs(a - angle) <= 4 * EPS * angle
    if angle == np.pi and n @ axis < 0:
        n = -n
    np.testing.assert_allclose(n, axis, rtol=0, atol=4 * EPS)


def test_axis_angle_of_tiny_angles():
    """Regression (found by this suite, fixed in 17003c6): ‖v‖ = sqrt(x² + y² + z²) underflowed
    below θ ≈ 1e-154, giving angle 0 and axis (1, 0, 0)."""
    R = axis_angle_to_matrix([0.0, 0.0, 1.0], 1e-200)
    np.testing.assert_allclose(log_so3(R), [0.0, 0.0, 1e-200], rtol=4 * EPS, atol=0)
    axis, angle = matrix_to_axis_angle(R)
    assert angle == pytest.approx(1e-200, rel=4 * EPS, abs=0)
    np.testing.assert_allclose(axis, [0.0, 0.0, 1.0], rtol=0, atol=EPS)
    from occmap.geometry import quat_to_axis_angle

    axis, angle = quat_to_axis_angle([1.0, 0.0, 3e-200, 0.0])
    assert angle == pytest.approx(6e-200, rel=4 * EPS, abs=0)
    np.testing.assert_allclose(axis, [0.0, 1.0, 0.0], rtol=0, atol=EPS)


def test_zero_angle():
    np.testing.assert_array_equal(exp_so3([0.0, 0.0, 0.0]), np.eye(3))
    np.testing.assert_array_equal(log_so3(np.eye(3)), [0.0, 0.0, 0.0])
    axis, angle = matrix_to_axis_angle(np.eye(3))
    assert angle == 0.0
    np.testing.assert_array_equal(axis, [1.0, 0.0, 0.0])


def test_textbook_log_loses_small_angles():
    """acos((tr R − 1)/2) returns 0 for θ = 1e-8 (100 % relative error: (tr R − 1)/2 = 1 − 5e-17
    rounds to 1), while log_so3 recovers θ to a relative 4e-16. Documents why we use atan2."""
    theta = 1e-8
    R = rodrigues([0.0, 0.0, 1.0], theta)
    textbook = np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))
    assert abs(textbook - theta) / theta > 0.5
    assert abs(np.linalg.norm(log_so3(R)) - theta) / theta < 4 * EPS


# ---------------------------------------------------------------- nearest_rotation / is_rotation


@PROP
@given(unit_quats, hnp.arrays(np.float64, 3, elements=st.floats(0.2, 5.0)), unit_quats)
def test_nearest_rotation_polar_factor(q, s, p):
    """M = R · P with P symmetric positive definite has polar factor R."""
    R, V = quat_to_matrix(q), quat_to_matrix(p)
    M = R @ (V @ np.diag(s) @ V.T)
    np.testing.assert_allclose(nearest_rotation(M), R, rtol=0, atol=1e-13)


def test_nearest_rotation_is_optimal_and_fixes_reflections(rng):
    M = rng.standard_normal((200, 3, 3))
    N = nearest_rotation(M)
    assert_rotation(N, atol=32 * EPS)
    best = np.linalg.norm(M - N, axis=(-2, -1))
    for _ in range(5):  # no nearby rotation is closer
        other = N @ exp_so3(rng.normal(0, 0.05, (200, 3)))
        assert (np.linalg.norm(M - other, axis=(-2, -1)) >= best - 1e-12).all()
    Rf = nearest_rotation(np.diag([3.0, 2.0, -1.0]))  # the smallest singular direction flips
    np.testing.assert_allclose(Rf, np.eye(3), rtol=0, atol=EPS)
    # 2-D
    np.testing.assert_allclose(nearest_rotation(2.0 * rot_z(0.4)[:2, :2]), rot_z(0.4)[:2, :2], rtol=0, atol=4 * EPS)


def test_nearest_rotation_vs_scipy(scipy_rotations, rng):
    """scipy's from_matrix also solves the orthogonal Procrustes problem for noisy input."""
    M = scipy_rotations.as_matrix() + rng.normal(0, 1e-2, (10_000, 3, 3))
    np.testing.assert_allclose(nearest_rotation(M), Rotation.from_matrix(M).as_matrix(), rtol=0, atol=1e-13)


def test_is_rotation():
    R = rot_z(0.3) @ rot_x(1.1)
    assert is_rotation(R)
    assert not is_rotation(np.diag([1.0, 1.0, -1.0]))  # reflection
    assert not is_rotation(-np.eye(3))
    assert not is_rotation(1.001 * R)
    assert is_rotation(1.001 * R, tol=1e-2)
    assert not is_rotation(np.full((3, 3), np.nan))
    assert not is_rotation(np.zeros((3, 3)))
    batch = np.stack([R, np.diag([1.0, 1.0, -1.0]), np.full((3, 3), np.inf)])
    np.testing.assert_array_equal(is_rotation(batch), [True, False, False])
    # tolerance is ‖RᵀR − I‖_F ≤ 1e-6 by default
    M = R.copy()
    M[0, 0] += 4e-7
    assert is_rotation(M)
    M[0, 0] += 1e-6
    assert not is_rotation(M)


# ---------------------------------------------------------------- random_rotations is uniform


def test_random_rotations_uniform():
    """Haar measure: E[R] = 0, and the angle θ has CDF (θ − sin θ)/π on [0, π] (KS test)."""
    R = random_rotations(20_000, rng=2024)
    assert np.abs(R.mean(axis=0)).max() < 0.02  # each entry has std 1/√3: s.e. of the mean ≈ 0.004
    # second moments: E[R_ij²] = 1/3
    np.testing.assert_allclose((R**2).mean(axis=0), 1 / 3, atol=0.02)
    _, theta = matrix_to_axis_angle(R)
    assert kstest(theta, lambda t: (t - np.sin(t)) / np.pi).pvalue > 1e-3
    # a non-uniform sampler (uniform rotation vectors in the ball) fails the same test
    v = np.random.default_rng(1).standard_normal((20_000, 3))
    v *= (np.pi * np.random.default_rng(2).uniform(0, 1, 20_000) ** (1 / 3) / np.linalg.norm(v, axis=1))[:, None]
    _, bad = matrix_to_axis_angle(exp_so3(v))
    assert kstest(bad, lambda t: (t - np.sin(t)) / np.pi).pvalue < 1e-3


# ---------------------------------------------------------------- scipy cross-checks


def test_scipy_exp_log(scipy_rotations):
    rv = scipy_rotations.as_rotvec()
    np.testing.assert_allclose(exp_so3(rv), scipy_rotations.as_matrix(), rtol=0, atol=8 * EPS)
    np.testing.assert_allclose(log_so3(scipy_rotations.as_matrix()), rv, rtol=0, atol=1e-14)
    axis, angle = matrix_to_axis_angle(scipy_rotations.as_matrix())
    np.testing.assert_allclose(angle, scipy_rotations.magnitude(), rtol=0, atol=4 * EPS)
    np.testing.assert_allclose(axis, rv / np.linalg.norm(rv, axis=1, keepdims=True), rtol=0, atol=1e-14)
    np.testing.assert_allclose(axis_angle_to_matrix(axis, angle), scipy_rotations.as_matrix(), rtol=0, atol=8 * EPS)
    # large rotation vectors (|w| > π) too
    big = rv * 3.0
    np.testing.assert_allclose(exp_so3(big), Rotation.from_rotvec(big).as_matrix(), rtol=0, atol=1e-14)


# ---------------------------------------------------------------- shapes and broadcasting


def test_shapes(rng):
    assert exp_so3([0, 0, 1]).shape == (3, 3)  # list of ints
    assert log_so3(np.eye(3).tolist()).shape == (3,)
    assert rot_x(1).shape == (3, 3)
    assert hat([1, 2, 3]).shape == (3, 3)
    assert vee(np.eye(3)).shape == (3,)
    w = rng.normal(size=(4, 5, 3))
    R = exp_so3(w)
    assert R.shape == (4, 5, 3, 3)
    np.testing.assert_array_equal(R[3, 1], exp_so3(w[3, 1]))
    assert log_so3(R).shape == (4, 5, 3)
    axis, angle = matrix_to_axis_angle(R)
    assert axis.shape == (4, 5, 3) and angle.shape == (4, 5)
    assert rot_z(np.zeros((2, 3))).shape == (2, 3, 3, 3)
    assert hat(w).shape == (4, 5, 3, 3) and vee(hat(w)).shape == (4, 5, 3)
    assert nearest_rotation(R).shape == (4, 5, 3, 3)
    assert is_rotation(R).shape == (4, 5)
    # partial broadcasting: axis (3, 1, 3) with angle (1, 4)
    M = axis_angle_to_matrix(rng.normal(size=(3, 1, 3)), rng.normal(size=(1, 4)))
    assert M.shape == (3, 4, 3, 3)


def test_empty_and_non_contiguous(rng):
    assert exp_so3(np.zeros((0, 3))).shape == (0, 3, 3)
    assert log_so3(np.zeros((0, 3, 3))).shape == (0, 3)
    assert random_rotations(0).shape == (0, 3, 3)
    R = random_rotations(6, rng=3)
    Rt = np.swapaxes(np.swapaxes(R, 1, 2).copy(), 1, 2)  # same values, transposed strides
    assert not Rt.flags.c_contiguous
    np.testing.assert_array_equal(log_so3(Rt), log_so3(R))
    w = rng.normal(size=(6, 6))[:, ::2]
    np.testing.assert_array_equal(exp_so3(w), exp_so3(w.copy()))


def _orthonormality_error(m):
    m = np.asarray(m)[..., :3, :3]
    return float(np.abs(np.swapaxes(m, -1, -2) @ m - np.eye(3)).max())


def test_repeated_composition_stays_on_so3():
    """x = x @ x fifty times doubles the rounding error each time without renormalisation
    (off SO(3) by about 0.1 and as_quat() refusing it); a long chain of random products too."""
    for seed in range(5):
        x = SO3.random(rng=seed)
        for _ in range(50):
            x = x @ x
        assert _orthonormality_error(x.matrix) < 1e-14
        assert np.isclose(np.linalg.norm(x.as_quat()), 1.0)
    steps = SO3.random(2000, rng=9)
    chain = SO3.identity()
    for k in range(len(steps)):
        chain = chain @ steps[k]
    assert _orthonormality_error(chain.matrix) < 1e-14
    batch = SO3.random(100, rng=3)
    for _ in range(50):
        batch = batch @ batch
    assert _orthonormality_error(batch.matrix) < 1e-14


def test_composition_still_the_product(rng):
    a, b = SO3.random(1000, rng=1), SO3.random(1000, rng=2)
    np.testing.assert_allclose((a @ b).matrix, a.matrix @ b.matrix, rtol=0, atol=1e-15)
    np.testing.assert_allclose((a @ b[0]).matrix, a.matrix @ b.matrix[0], rtol=0, atol=1e-15)
    np.testing.assert_allclose((a[0] @ b[0]).matrix, a.matrix[0] @ b.matrix[0], rtol=0, atol=1e-15)
    assert (a @ a.inv()).shape == (1000,) and _orthonormality_error((a @ a.inv()).matrix) < 1e-15
