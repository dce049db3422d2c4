"""SE(3) functions: make_transform, invert_transform, compose_transforms, transform_points,
exp_se3 / log_se3 with twists (ρ, φ) translation first; the series switch at θ = 0.1; checks
against scipy.linalg.expm and scipy's RigidTransform (which orders exp coords rotation first)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from scipy.linalg import expm
from scipy.spatial.transform import RigidTransform, Rotation

from occmap.errors import NonFiniteError
from occmap.geometry import (
    SE3,
    SO3,
    compose_transforms,
    exp_se3,
    exp_so3,
    invert_transform,
    log_se3,
    make_transform,
    quat_rotate,
    quat_to_matrix,
    transform_points,
)

EPS = np.finfo(np.float64).eps
PROP = settings(deadline=None)

unit_quats = (
    hnp.arrays(np.float64, 4, elements=st.floats(-1.0, 1.0, allow_subnormal=False))
    .filter(lambda v: np.linalg.norm(v) > 0.1)
    .map(lambda v: v / np.linalg.norm(v))
)
translations = hnp.arrays(np.float64, 3, elements=st.floats(-100.0, 100.0))
transforms = st.builds(lambda q, t: make_transform(quat_to_matrix(q), t), unit_quats, translations)
directions = (
    hnp.arrays(np.float64, 3, elements=st.floats(-1.0, 1.0, allow_subnormal=False))
    .filter(lambda v: np.linalg.norm(v) > 0.1)
    .map(lambda v: v / np.linalg.norm(v))
)
#: twists (ρ, φ) with |φ| < π
twists = st.builds(
    lambda rho, n, a: np.r_[rho, n * a], hnp.arrays(np.float64, 3, elements=st.floats(-10.0, 10.0)), directions,
    st.floats(0.0, np.pi - 1e-6),
)


def twist_matrix(xi):
    """The 4×4 se(3) matrix [[φ^, ρ], [0, 0]] of a twist (ρ, φ)."""
    rho, phi = xi[:3], xi[3:]
    A = np.zeros((4, 4))
    A[:3, :3] = [[0, -phi[2], phi[1]], [phi[2], 0, -phi[0]], [-phi[1], phi[0], 0]]
    A[:3, 3] = rho
    return A


def to_scipy_exp_coords(xi):
    """scipy's RigidTransform orders exponential coordinates (φ, ρ)."""
    return np.concatenate([xi[..., 3:], xi[..., :3]], -1)


def tol(*arrays):
    """Rounding allowance for transform arithmetic: a few ulp of the largest magnitude involved
    (translations up to 100 m make 1e-13 too tight: hypothesis found 1.1e-13 at |t| = 160)."""
    return 16 * EPS * (1 + sum(np.abs(a).max() for a in arrays))


def random_transforms(rng, n):
    q = rng.standard_normal((n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return make_transform(Rotation.from_quat(q, scalar_first=True).as_matrix(), rng.uniform(-10, 10, (n, 3)))


# ---------------------------------------------------------------- conventions


def test_t_a_b_maps_b_to_a():
    """A robot at (1, 2, 0) in the world, yawed +90°: its x axis points along world y."""
    T_world_robot = make_transform(exp_so3([0, 0, np.pi / 2]), [1.0, 2.0, 0.0])
    np.testing.assert_allclose(transform_points(T_world_robot, [1.0, 0.0, 0.0]), [1.0, 3.0, 0.0], atol=4 * EPS)
    # T_a_c = T_a_b @ T_b_c: a sensor 0.5 m ahead of the robot sits at (1, 2.5, 0) in the world
    T_robot_sensor = make_transform(np.eye(3), [0.5, 0.0, 0.0])
    T_world_sensor = compose_transforms(T_world_robot, T_robot_sensor)
    np.testing.assert_allclose(T_world_sensor[:3, 3], [1.0, 2.5, 0.0], atol=4 * EPS)
    np.testing.assert_allclose(transform_points(T_world_sensor, [0, 0, 0]), [1.0, 2.5, 0.0], atol=4 * EPS)


def test_make_transform_layout():
    R = exp_so3([0.1, -0.2, 0.3])
    T = make_transform(R, [1, 2, 3])
    np.testing.assert_array_equal(T[:3, :3], R)
    np.testing.assert_array_equal(T[:3, 3], [1, 2, 3])
    np.testing.assert_array_equal(T[3], [0, 0, 0, 1])


# ---------------------------------------------------------------- group laws


@PROP
@given(transforms)
def test_inverse_laws(T):
    I = np.eye(4)
    Ti = invert_transform(T)
    e = tol(T)
    np.testing.assert_allclose(T @ Ti, I, rtol=0, atol=e)
    np.testing.assert_allclose(Ti @ T, I, rtol=0, atol=e)
    np.testing.assert_allclose(compose_transforms(T, Ti), I, rtol=0, atol=e)
    np.testing.assert_allclose(Ti, np.linalg.inv(T), rtol=0, atol=e)
    np.testing.assert_allclose(invert_transform(Ti), T, rtol=0, atol=e)


@PROP
@given(transforms, transforms, transforms)
def test_composition_matches_matmul_and_is_associative(A, B, C):
    e = tol(A, B, C)
    np.testing.assert_allclose(compose_transforms(A, B), A @ B, rtol=0, atol=e)
    np.testing.assert_allclose(
        compose_transforms(compose_transforms(A, B), C), compose_transforms(A, compose_transforms(B, C)), rtol=0, atol=2 * e
    )
    # (AB)⁻¹ = B⁻¹A⁻¹
    np.testing.assert_allclose(
        invert_transform(compose_transforms(A, B)), compose_transforms(invert_transform(B), invert_transform(A)), rtol=0, atol=2 * e
    )


@PROP
@given(transforms, transforms, hnp.arrays(np.float64, (5, 3), elements=st.floats(-100, 100)))
def test_transform_points(A, B, p):
    e = tol(A, B, p)
    np.testing.assert_allclose(transform_points(A, p), p @ A[:3, :3].T + A[:3, 3], rtol=0, atol=e)
    np.testing.assert_allclose(
        transform_points(compose_transforms(A, B), p), transform_points(A, transform_points(B, p)), rtol=0, atol=2 * e
    )
    np.testing.assert_allclose(transform_points(invert_transform(A), transform_points(A, p)), p, rtol=0, atol=2 * e)


# ---------------------------------------------------------------- exp / log


@PROP
@given(hnp.arrays(np.float64, 6, elements=st.floats(-10.0, 10.0)))
def test_exp_matches_matrix_exponential(xi):
    T = exp_se3(xi)
    scale = 1 + np.linalg.norm(xi) ** 2
    np.testing.assert_allclose(T, expm(twist_matrix(xi)), rtol=0, atol=1e-13 * scale)
    np.testing.assert_allclose(T[:3, :3], exp_so3(xi[3:]), rtol=0, atol=4 * EPS * (1 + np.linalg.norm(xi[3:])))
    np.testing.assert_array_equal(T[3], [0, 0, 0, 1])


@PROP
@given(twists)
def test_log_exp_round_trip(xi):
    np.testing.assert_allclose(log_se3(exp_se3(xi)), xi, rtol=0, atol=1e-13 * (1 + np.linalg.norm(xi)))


@PROP
@given(transforms)
def test_exp_log_round_trip(T):
    xi = log_se3(T)
    assert np.linalg.norm(xi[3:]) <= np.pi + 4 * EPS
    np.testing.assert_allclose(exp_se3(xi), T, rtol=0, atol=4 * tol(T))


def test_pure_translation_twist():
    np.testing.assert_array_equal(exp_se3([1.0, -2.0, 3.0, 0, 0, 0]), make_transform(np.eye(3), [1.0, -2.0, 3.0]))
    np.testing.assert_array_equal(log_se3(make_transform(np.eye(3), [1.0, -2.0, 3.0])), [1.0, -2.0, 3.0, 0, 0, 0])


def test_screw_motion_closed_form():
    """exp of (ρ, φ) = (v·ẑ, ω·ẑ) about z: rotate by ω and translate v along z (pure screw)."""
    T = exp_se3([0.0, 0.0, 2.0, 0.0, 0.0, 1.2])
    np.testing.assert_allclose(T[:3, :3], exp_so3([0, 0, 1.2]), atol=2 * EPS)
    np.testing.assert_allclose(T[:3, 3], [0, 0, 2.0], atol=2 * EPS)
    # (ρ, φ) = (ẋ, π ẑ): a half turn while moving along x traces a half circle of radius 1/π
    T = exp_se3([1.0, 0.0, 0.0, 0.0, 0.0, np.pi])
    np.testing.assert_allclose(T[:3, 3], [0, 2 / np.pi, 0], atol=4 * EPS)


SWITCH = 0.1  # where the series for (1 − cos θ)/θ², (θ − sin θ)/θ³ and the log's d(θ) hand over


@pytest.mark.parametrize(
    "theta",
    [0.0, 1e-10, 0.05, np.nextafter(SWITCH, 0), SWITCH, np.nextafter(SWITCH, 1), 0.5, np.pi - 1e-9],
    ids=["0", "1e-10", "0.05", "0.1-ulp", "0.1", "0.1+ulp", "0.5", "pi-1e-9"],
)
def test_edge_angles_exp_log(theta, rng):
    """Measured per twist: ‖exp_se3(ξ) − expm(ξ^)‖ elementwise (asserted ≤ 2e-15·(1 + |ρ|)), and
    ‖log(exp(ξ)) − ξ‖: rotation part relative to θ (≤ 4e-15·θ), translation ≤ 1e-14·|ρ|."""
    for _ in range(20):
        n = rng.standard_normal(3)
        n /= np.linalg.norm(n)
        rho = rng.uniform(-5, 5, 3)
        xi = np.r_[rho, theta * n]
        T = exp_se3(xi)
        np.testing.assert_allclose(T, expm(twist_matrix(xi)), rtol=0, atol=2e-15 * (1 + np.linalg.norm(rho)))
        back = log_se3(T)
        assert np.linalg.norm(back[3:] - xi[3:]) <= 4e-15 * theta
        assert np.linalg.norm(back[:3] - rho) <= 1e-14 * np.linalg.norm(rho)


@pytest.mark.parametrize("fn", ["exp", "log"])
def test_series_switch_is_continuous(fn, rng):
    """Across θ = 0.1 the two formulas agree to rounding: a jump bigger than a few ulp of |ρ|
    means one of the coefficient series is wrong."""
    lo, hi = np.nextafter(SWITCH, 0), np.nextafter(SWITCH, 1)
    for _ in range(20):
        n = rng.standard_normal(3)
        n /= np.linalg.norm(n)
        rho = rng.uniform(-5, 5, 3)
        if fn == "exp":
            a, b = exp_se3(np.r_[rho, lo * n])[:3, 3], exp_se3(np.r_[rho, hi * n])[:3, 3]
        else:
            R_lo, R_hi = exp_so3(lo * n), exp_so3(hi * n)
            a = log_se3(make_transform(R_lo, rho))[:3]
            b = log_se3(make_transform(R_hi, rho))[:3]
        np.testing.assert_allclose(a, b, rtol=0, atol=4 * EPS * np.linalg.norm(rho))


def test_log_at_exactly_pi():
    """At θ = π the axis sign is free, and either answer must map back to the same transform."""
    for axis in np.eye(3).tolist() + [[np.sqrt(0.5), np.sqrt(0.5), 0.0]]:
        R = 2 * np.outer(axis, axis) - np.eye(3)
        T = make_transform(R, [0.3, -1.0, 2.0])
        xi = log_se3(T)
        assert np.linalg.norm(xi[3:]) == pytest.approx(np.pi, abs=4 * EPS)
        np.testing.assert_allclose(exp_se3(xi), T, rtol=0, atol=1e-14)


# ---------------------------------------------------------------- scipy cross-checks


def test_scipy_rigid_transform(scipy_rotations, rng):
    n = len(scipy_rotations)
    t = rng.uniform(-10, 10, (n, 3))
    ref = RigidTransform.from_components(t, scipy_rotations)
    T = make_transform(scipy_rotations.as_matrix(), t)
    np.testing.assert_allclose(T, ref.as_matrix(), rtol=0, atol=8 * EPS)
    np.testing.assert_allclose(invert_transform(T), ref.inv().as_matrix(), rtol=0, atol=1e-14)
    T2 = T[::-1].copy()
    np.testing.assert_allclose(compose_transforms(T, T2), (ref * ref[::-1]).as_matrix(), rtol=0, atol=1e-13)
    p = rng.uniform(-10, 10, (n, 3))
    np.testing.assert_allclose(transform_points(T, p), ref.apply(p), rtol=0, atol=1e-13)
    xi = log_se3(T)
    np.testing.assert_allclose(to_scipy_exp_coords(xi), ref.as_exp_coords(), rtol=0, atol=1e-12)
    np.testing.assert_allclose(exp_se3(xi), RigidTransform.from_exp_coords(to_scipy_exp_coords(xi)).as_matrix(), rtol=0, atol=1e-13)


# ---------------------------------------------------------------- shapes and broadcasting


def test_shapes(rng):
    T = random_transforms(rng, 12).reshape(3, 4, 4, 4)
    assert make_transform(np.eye(3).tolist(), [1, 2, 3]).shape == (4, 4)  # lists, ints
    assert invert_transform(T).shape == (3, 4, 4, 4)
    assert log_se3(T).shape == (3, 4, 6)
    assert exp_se3(log_se3(T)).shape == (3, 4, 4, 4)
    assert exp_se3([0, 0, 0, 0, 0, 1]).shape == (4, 4)
    assert transform_points(np.eye(4), [1, 2, 3]).shape == (3,)
    np.testing.assert_array_equal(invert_transform(T)[2, 1], invert_transform(T[2, 1]))


def test_broadcasting(rng):
    T = random_transforms(rng, 5)
    p = rng.uniform(-5, 5, (1000, 3))
    # one transform, many points
    np.testing.assert_allclose(transform_points(T[0], p), p @ T[0, :3, :3].T + T[0, :3, 3], rtol=0, atol=1e-13)
    # many transforms, one point
    out = transform_points(T, p[0])
    assert out.shape == (5, 3)
    np.testing.assert_allclose(out, np.einsum("nij,j->ni", T[:, :3, :3], p[0]) + T[:, :3, 3], rtol=0, atol=1e-13)
    # (5, 1) transforms × (1, 7) points → (5, 7)
    out = transform_points(T[:, None], p[None, :7])
    assert out.shape == (5, 7, 3)
    np.testing.assert_allclose(out[3, 6], T[3, :3, :3] @ p[6] + T[3, :3, 3], rtol=0, atol=1e-13)
    # partial broadcasting in composition and make_transform
    C = compose_transforms(T[:3, None], T[None, :4])
    assert C.shape == (3, 4, 4, 4)
    np.testing.assert_allclose(C[2, 3], T[2] @ T[3], rtol=0, atol=1e-13)
    M = make_transform(T[:, :3, :3], [1.0, 2.0, 3.0])
    assert M.shape == (5, 4, 4)
    np.testing.assert_array_equal(M[:, :3, 3], np.broadcast_to([1.0, 2.0, 3.0], (5, 3)))


def test_empty_and_non_contiguous(rng):
    assert exp_se3(np.zeros((0, 6))).shape == (0, 4, 4)
    assert log_se3(np.zeros((0, 4, 4))).shape == (0, 6)
    assert invert_transform(np.zeros((0, 4, 4))).shape == (0, 4, 4)
    assert transform_points(np.eye(4), np.zeros((0, 3))).shape == (0, 3)
    T = random_transforms(rng, 6)
    Tt = np.swapaxes(np.swapaxes(T, 1, 2).copy(), 1, 2)
    assert not Tt.flags.c_contiguous
    np.testing.assert_array_equal(invert_transform(Tt), invert_transform(T))
    np.testing.assert_array_equal(log_se3(Tt), log_se3(T))
    p = rng.normal(size=(6, 6))[:, ::2]
    np.testing.assert_array_equal(transform_points(T, p), transform_points(T, p.copy()))


def test_empty_transform_batch():
    """Regression (found by this suite, fixed in 17003c6): an empty transform batch was taken for
    one broadcast transform and T[0] was validated out of bounds. The NaN-backed empty views make
    an out-of-bounds read fail every time, not by chance."""
    nan_T = np.full((1, 4, 4), np.nan)[:0]
    nan_T2 = np.full((1, 3, 3), np.nan)[:0]
    assert transform_points(nan_T, np.zeros(3)).shape == (0, 3)
    assert transform_points(nan_T, np.zeros((0, 3))).shape == (0, 3)
    assert transform_points(nan_T2, np.zeros(2)).shape == (0, 2)
    assert transform_points(np.zeros((0, 4, 4)), np.zeros(3)).shape == (0, 3)
    assert transform_points(np.zeros((0, 4, 4)), np.zeros((0, 3))).shape == (0, 3)
    assert transform_points(np.zeros((0, 3, 3)), np.zeros(2)).shape == (0, 2)


def test_large_clouds_take_the_parallel_path_and_still_name_the_bad_point():
    """Clouds of ≥ 65,536 points are mapped on all cores; results must equal NumPy's, and a NaN
    anywhere must still be reported at its own index (the parallel reduction only detects it)."""
    rng = np.random.default_rng(5)
    pts = rng.normal(size=(70_000, 3)) * 10
    q = np.array([0.6, 0.0, 0.8, 0.0])
    R = quat_to_matrix(q)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, [1.0, -2.0, 3.0]
    expected = pts @ R.T
    np.testing.assert_allclose(transform_points(T, pts), expected + T[:3, 3], rtol=0, atol=1e-12)
    np.testing.assert_allclose(quat_rotate(q, pts), expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(SO3.from_matrix(R).apply(pts), expected, rtol=0, atol=1e-12)
    pts[69_123, 2] = np.nan
    for call in (lambda: transform_points(T, pts), lambda: quat_rotate(q, pts), lambda: SO3.from_matrix(R).apply(pts)):
        with pytest.raises(NonFiniteError, match=r"\[69123\]"):
            call()


def test_repeated_se3_composition_stays_rigid():
    """SE3 @ renormalises its rotation block as SO3 @ does; compose_transforms does not."""
    T = SE3.from_rt(SO3.random(rng=4).matrix, [0.1, -0.2, 0.3])
    raw = T.matrix
    for _ in range(50):
        T = T @ T
        raw = compose_transforms(raw, raw)
    R = T.matrix[:3, :3]
    assert np.abs(R.T @ R - np.eye(3)).max() < 1e-14
    assert np.array_equal(T.matrix[3], [0, 0, 0, 1])
    T.rotation.as_quat()  # a rotation still
    Rr = raw[:3, :3]
    assert np.abs(Rr.T @ Rr - np.eye(3)).max() > 1e-6  # the drift the operator removes


def test_se3_composition_still_the_product():
    A = SE3.from_rt(SO3.random(500, rng=5).matrix, np.random.default_rng(6).normal(size=(500, 3)))
    B = SE3.from_rt(SO3.random(500, rng=7).matrix, np.random.default_rng(8).normal(size=(500, 3)))
    np.testing.assert_allclose((A @ B).matrix, A.matrix @ B.matrix, rtol=0, atol=1e-14)
    np.testing.assert_allclose((A[3] @ B).matrix, A.matrix[3] @ B.matrix, rtol=0, atol=1e-14)
