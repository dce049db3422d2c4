"""Quaternions (w, x, y, z), Hamilton product: algebra, round trips, slerp, the hard angles, and
cross-checks against scipy.spatial.transform on 10,000 random rotations."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from scipy.spatial.transform import Rotation, Slerp

from occmap.geometry import (
    axis_angle_to_quat,
    matrix_to_quat,
    quat_conjugate,
    quat_from_xyzw,
    quat_inverse,
    quat_multiply,
    quat_normalize,
    quat_rotate,
    quat_slerp,
    quat_to_axis_angle,
    quat_to_matrix,
    quat_to_xyzw,
)

# ---------------------------------------------------------------- strategies and references

# subnormal components are covered by dedicated tests (see test_axis_of_subnormal_vector_part)
coords = st.floats(-1.0, 1.0, allow_nan=False, allow_infinity=False, allow_subnormal=False)
raw_quats = hnp.arrays(np.float64, 4, elements=coords).filter(lambda v: np.linalg.norm(v) > 0.1)
unit_quats = raw_quats.map(lambda v: v / np.linalg.norm(v))
vectors = hnp.arrays(np.float64, 3, elements=st.floats(-100.0, 100.0))
PROP = settings(deadline=None)  # max_examples from the profile (100 by default)
EPS = np.finfo(np.float64).eps  # 2.2e-16


def hamilton(p, q):
    """Reference Hamilton product written out from i² = j² = k² = ijk = −1 (plain NumPy)."""
    p, q = np.asarray(p, float), np.asarray(q, float)
    pw, pv = p[..., 0], p[..., 1:]
    qw, qv = q[..., 0], q[..., 1:]
    w = pw * qw - np.sum(pv * qv, -1)
    v = pw[..., None] * qv + qw[..., None] * pv + np.cross(pv, qv)
    return np.concatenate([w[..., None], v], -1)


def rodrigues(axis, angle):
    """Reference rotation matrix, I + sin θ K + (1 − cos θ) K², with 1 − cos θ = 2 sin²(θ/2)."""
    n = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -n[2], n[1]], [n[2], 0, -n[0]], [-n[1], n[0], 0]])
    return np.eye(3) + np.sin(angle) * K + 2.0 * np.sin(angle / 2) ** 2 * (K @ K)


def rotation_angle_between(q0, q1):
    """Rotation angle (radians) of q0⁻¹ q1 for unit quaternions, accurate at 0 and π:
    4·atan2(|a − b|, |a + b|) with b sign-aligned to a (plain NumPy)."""
    q0, q1 = np.asarray(q0), np.asarray(q1)
    s = np.where(np.sum(q0 * q1, -1) < 0, -1.0, 1.0)[..., None]
    return 4.0 * np.arctan2(np.linalg.norm(q0 - s * q1, axis=-1), np.linalg.norm(q0 + s * q1, axis=-1))


def assert_same_rotation_quat(a, b, atol):
    """a == ±b elementwise-signwise per quaternion."""
    a, b = np.asarray(a), np.asarray(b)
    s = np.where(np.sum(a * b, -1) < 0, -1.0, 1.0)[..., None]
    np.testing.assert_allclose(a, s * b, rtol=0, atol=atol)


# ---------------------------------------------------------------- algebra


def test_hamilton_basis_products():
    """i j = k, j k = i, k i = j, i² = −1: Hamilton, not the JPL (left-handed) convention."""
    one, i, j, k = np.eye(4)
    np.testing.assert_array_equal(quat_multiply(i, j), k)
    np.testing.assert_array_equal(quat_multiply(j, k), i)
    np.testing.assert_array_equal(quat_multiply(k, i), j)
    np.testing.assert_array_equal(quat_multiply(j, i), -k)
    for e in (i, j, k):
        np.testing.assert_array_equal(quat_multiply(e, e), -one)
    np.testing.assert_array_equal(quat_multiply(one, [0.3, -1.0, 2.0, 5.0]), [0.3, -1.0, 2.0, 5.0])


@PROP
@given(raw_quats, raw_quats)
def test_multiply_matches_reference_product(p, q):
    np.testing.assert_allclose(quat_multiply(p, q), hamilton(p, q), rtol=0, atol=1e-15)


@PROP
@given(unit_quats, unit_quats)
def test_multiply_matches_matrix_product(q1, q2):
    """quat_to_matrix(q1 ⊗ q2) = R1 R2: q1 ⊗ q2 applies q2 first."""
    R12 = quat_to_matrix(quat_multiply(q1, q2) / np.linalg.norm(quat_multiply(q1, q2)))
    np.testing.assert_allclose(R12, quat_to_matrix(q1) @ quat_to_matrix(q2), rtol=0, atol=2e-15)


@PROP
@given(unit_quats, unit_quats, unit_quats)
def test_multiply_associative(a, b, c):
    np.testing.assert_allclose(
        quat_multiply(quat_multiply(a, b), c), quat_multiply(a, quat_multiply(b, c)), rtol=0, atol=2e-15
    )


@PROP
@given(unit_quats, vectors)
def test_rotate_matches_matrix_and_sandwich(q, v):
    """quat_rotate(q, v) = R(q) v = vector part of q ⊗ (0, v) ⊗ q*."""
    expected = hamilton(hamilton(q, np.r_[0.0, v]), q * [1, -1, -1, -1])[1:]
    scale = 1e-15 * (1 + np.linalg.norm(v))
    np.testing.assert_allclose(quat_rotate(q, v), expected, rtol=0, atol=4 * scale)
    np.testing.assert_allclose(quat_rotate(q, v), quat_to_matrix(q) @ v, rtol=0, atol=4 * scale)


@PROP
@given(unit_quats)
def test_to_matrix_is_rotation(q):
    R = quat_to_matrix(q)
    np.testing.assert_allclose(R @ R.T, np.eye(3), rtol=0, atol=1e-15 * 4)
    assert abs(np.linalg.det(R) - 1.0) < 1e-14


@PROP
@given(unit_quats)
def test_q_and_minus_q_same_matrix(q):
    np.testing.assert_allclose(quat_to_matrix(-q), quat_to_matrix(q), rtol=0, atol=1e-16)


@PROP
@given(unit_quats)
def test_matrix_quat_round_trip(q):
    """matrix_to_quat(quat_to_matrix(q)) = ±q with w ≥ 0, and back to the same matrix."""
    R = quat_to_matrix(q)
    q2 = matrix_to_quat(R)
    assert q2[0] >= 0.0
    assert abs(np.linalg.norm(q2) - 1) < 1e-15
    assert_same_rotation_quat(q2, q, atol=1e-15 * 2)
    np.testing.assert_allclose(quat_to_matrix(q2), R, rtol=0, atol=1e-15 * 2)


@PROP
@given(raw_quats)
def test_inverse_conjugate_normalize(q):
    one = np.array([1.0, 0, 0, 0])
    np.testing.assert_allclose(quat_multiply(q, quat_inverse(q)), one, rtol=0, atol=1e-15 * 4)
    np.testing.assert_allclose(quat_multiply(quat_inverse(q), q), one, rtol=0, atol=1e-15 * 4)
    np.testing.assert_array_equal(quat_conjugate(q), q * [1, -1, -1, -1])
    n = quat_normalize(q)
    assert abs(np.linalg.norm(n) - 1) < 1e-15
    np.testing.assert_allclose(n * np.linalg.norm(q), q, rtol=0, atol=1e-15 * 2)
    # for unit quaternions the inverse is the conjugate
    np.testing.assert_allclose(quat_inverse(n), quat_conjugate(n), rtol=0, atol=1e-15 * 2)


def test_xyzw_reorder():
    np.testing.assert_array_equal(quat_from_xyzw([1.0, 2.0, 3.0, 4.0]), [4.0, 1.0, 2.0, 3.0])
    np.testing.assert_array_equal(quat_to_xyzw([4.0, 1.0, 2.0, 3.0]), [1.0, 2.0, 3.0, 4.0])
    q = np.arange(24.0).reshape(2, 3, 4)
    np.testing.assert_array_equal(quat_from_xyzw(quat_to_xyzw(q)), q)


def test_axis_angle_right_handed_and_axis_length_free():
    q = axis_angle_to_quat([0.0, 0.0, 5.0], np.pi / 2)  # axis of any length
    np.testing.assert_allclose(q, [np.sqrt(0.5), 0, 0, np.sqrt(0.5)], rtol=0, atol=EPS)
    np.testing.assert_allclose(quat_rotate(q, [1.0, 0, 0]), [0, 1.0, 0], rtol=0, atol=1e-15)


@PROP
@given(vectors.filter(lambda a: np.linalg.norm(a) > 1e-3), st.floats(-10, 10))
def test_axis_angle_matches_rodrigues(axis, angle):
    q = axis_angle_to_quat(axis, angle)
    assert abs(np.linalg.norm(q) - 1) < 1e-15
    np.testing.assert_allclose(quat_to_matrix(q), rodrigues(axis, angle), rtol=0, atol=1e-14)


@PROP
@given(unit_quats)
def test_quat_to_axis_angle_round_trip(q):
    axis, angle = quat_to_axis_angle(q)
    assert 0.0 <= angle <= np.pi
    assert abs(np.linalg.norm(axis) - 1) < 1e-15
    assert_same_rotation_quat(axis_angle_to_quat(axis, angle), q, atol=1e-15 * 4)
    axis2, angle2 = quat_to_axis_angle(-q)  # −q is the same rotation
    assert angle2 == pytest.approx(angle, abs=1e-15)
    if 1e-6 < angle < np.pi - 1e-6:  # at 0 the axis is arbitrary, at π it may flip
        np.testing.assert_allclose(axis2, axis, rtol=0, atol=1e-15 * 4)


def test_axis_of_subnormal_vector_part():
    t = 2.2250738585e-313
    axis, angle = quat_to_axis_angle([1.0, t, t, t])
    np.testing.assert_allclose(axis, np.full(3, 1 / np.sqrt(3)), rtol=0, atol=2 * EPS)
    assert angle == pytest.approx(2 * np.sqrt(3) * t, rel=1e-10)


def test_identity_axis_angle_convention():
    axis, angle = quat_to_axis_angle([1.0, 0, 0, 0])
    assert angle == 0.0
    np.testing.assert_array_equal(axis, [1.0, 0, 0])


# ---------------------------------------------------------------- hard angles


EDGE_ANGLES = [1e-12, 1e-8, 1e-4, np.pi - 1e-9, np.pi]
EDGE_AXES = [np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), np.array([0, 0, 1.0]),
             np.array([1.0, 1.0, 0]) / np.sqrt(2), np.array([0.2, -0.6, 0.7746]) / np.linalg.norm([0.2, -0.6, 0.7746])]


@pytest.mark.parametrize("angle", EDGE_ANGLES)
@pytest.mark.parametrize("axis", EDGE_AXES, ids=["x", "y", "z", "xy", "generic"])
def test_edge_angles_axis_angle_and_matrix_to_quat(axis, angle):
    """Measured: relative error of the recovered angle, and the error of the recovered axis
    (± at exactly π), from the exact quaternion (cos θ/2, sin θ/2 n) and from its matrix."""
    q_true = np.r_[np.cos(angle / 2), np.sin(angle / 2) * axis]
    # quaternion → axis-angle
    n, a = quat_to_axis_angle(q_true)
    assert abs(a - angle) <= 4 * EPS * angle
    sign = -1.0 if angle == np.pi and n @ axis < 0 else 1.0  # ±axis only at exactly π
    np.testing.assert_allclose(sign * n, axis, rtol=0, atol=2 * EPS)
    # matrix → quaternion: matches the exact quaternion, up to sign only at π (w = 0 there)
    R = rodrigues(axis, angle)
    q = matrix_to_quat(R)
    if angle < np.pi - 1e-3:
        np.testing.assert_allclose(q, q_true, rtol=0, atol=2 * EPS)
        # the vector part carries the small angle: relative accuracy, not just absolute
        np.testing.assert_allclose(q[1:], q_true[1:], rtol=4e-15, atol=1e-300)
    else:
        assert_same_rotation_quat(q, q_true, atol=2 * EPS)


ROOT_HALF = np.sqrt(0.5)


@pytest.mark.parametrize(
    "R, q",
    [
        (np.diag([1.0, -1.0, -1.0]), [0.0, 1.0, 0.0, 0.0]),
        (np.diag([-1.0, 1.0, -1.0]), [0.0, 0.0, 1.0, 0.0]),
        (np.diag([-1.0, -1.0, 1.0]), [0.0, 0.0, 0.0, 1.0]),
        (np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]), [0.0, ROOT_HALF, ROOT_HALF, 0.0]),
        (np.array([[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]]), [0.0, ROOT_HALF, 0.0, ROOT_HALF]),
        (np.eye(3), [1.0, 0.0, 0.0, 0.0]),
    ],
    ids=["x180", "y180", "z180", "xy180", "xz180", "identity"],
)
def test_half_turns_exact(R, q):
    """180° turns (trace −1, where the trace-based formula divides by 0): within 1 ulp, ± at w = 0."""
    out = matrix_to_quat(R)
    assert_same_rotation_quat(out, q, atol=EPS / 2)
    assert out[0] == 0.0 or np.array_equal(R, np.eye(3))
    n, a = quat_to_axis_angle(out)
    if not np.array_equal(R, np.eye(3)):
        assert a == pytest.approx(np.pi, abs=2 * EPS)


def test_textbook_half_turn_formula_fails_where_shepperd_does_not():
    """w = √(1 + tr R)/2, x = (R21 − R12)/(4w) divides 0 by 0 at 180°: documents why we pivot."""
    R = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    w = np.sqrt(1 + np.trace(R)) / 2
    with np.errstate(invalid="ignore", divide="ignore"):
        x = (R[2, 1] - R[1, 2]) / (4 * w)
    assert not np.isfinite(x)
    assert np.isfinite(matrix_to_quat(R)).all()


# ---------------------------------------------------------------- slerp


@PROP
@given(unit_quats, unit_quats)
def test_slerp_endpoints_and_norm(q0, q1):
    np.testing.assert_allclose(quat_slerp(q0, q1, 0.0), q0, rtol=0, atol=1e-15 * 2)
    assert_same_rotation_quat(quat_slerp(q0, q1, 1.0), q1, atol=1e-15 * 4)
    t = np.linspace(-0.5, 1.5, 21)
    out = quat_slerp(q0, q1, t)
    np.testing.assert_allclose(np.linalg.norm(out, axis=-1), 1.0, rtol=0, atol=1e-15 * 2)


@PROP
@given(unit_quats, unit_quats, st.floats(0.0, 1.0))
def test_slerp_constant_angular_speed(q0, q1, t):
    """The rotation angle from q0 to slerp(t) is t·Ω, and from slerp(t) to q1 is (1 − t)·Ω."""
    omega = rotation_angle_between(q0, q1)  # in [0, π]: the shorter way round
    qt = quat_slerp(q0, q1, t)
    assert rotation_angle_between(q0, qt) == pytest.approx(t * omega, abs=1e-14)
    assert rotation_angle_between(qt, q1) == pytest.approx((1 - t) * omega, abs=1e-14)


@PROP
@given(unit_quats, unit_quats, st.floats(-0.5, 1.5))
def test_slerp_shortest_path(q, p, t):
    """Slerp between q and −p is slerp between q and p (both start at q, so equal as quaternions).
    At q·p = 0 exactly (rotations 180° apart) both arcs are equally short and the sign of p picks
    one: that tie is left out."""
    assume(abs(float(np.dot(q, p))) > 1e-12)
    np.testing.assert_allclose(quat_slerp(q, -p, t), quat_slerp(q, p, t), rtol=0, atol=1e-15 * 4)


def test_slerp_nearly_equal_and_opposite():
    q0 = np.array([1.0, 0, 0, 0])
    q1 = axis_angle_to_quat([0, 0, 1.0], 1e-9)
    mid = quat_slerp(q0, q1, 0.5)
    _, a = quat_to_axis_angle(mid)
    assert a == pytest.approx(0.5e-9, rel=1e-6)
    # q and −q: zero rotation between them, so slerp stays at q
    np.testing.assert_allclose(quat_slerp(q1, -q1, 0.3), q1, rtol=0, atol=1e-15 * 2)


# ---------------------------------------------------------------- scipy cross-checks (10,000 rotations)


def test_scipy_quat_to_matrix(scipy_rotations):
    q = scipy_rotations.as_quat(scalar_first=True)
    np.testing.assert_allclose(quat_to_matrix(q), scipy_rotations.as_matrix(), rtol=0, atol=1e-15 * 2)
    # scalar_first really is (w, x, y, z): compare with the explicit reordering too
    np.testing.assert_allclose(
        quat_to_matrix(quat_from_xyzw(scipy_rotations.as_quat())), scipy_rotations.as_matrix(), rtol=0, atol=2e-15
    )


def test_scipy_matrix_to_quat(scipy_rotations):
    q = matrix_to_quat(scipy_rotations.as_matrix())
    assert (q[:, 0] >= 0).all()
    assert_same_rotation_quat(q, scipy_rotations.as_quat(scalar_first=True), atol=1e-15 * 2)


def test_scipy_multiply(scipy_rotations):
    a, b = scipy_rotations[:5000], scipy_rotations[5000:]
    out = quat_multiply(a.as_quat(scalar_first=True), b.as_quat(scalar_first=True))
    assert_same_rotation_quat(out, (a * b).as_quat(scalar_first=True), atol=1e-15 * 2)


def test_scipy_rotate(scipy_rotations, rng):
    v = rng.uniform(-10, 10, (10_000, 3))
    out = quat_rotate(scipy_rotations.as_quat(scalar_first=True), v)
    np.testing.assert_allclose(out, scipy_rotations.apply(v), rtol=0, atol=1e-14 * 2)


def test_scipy_axis_angle(scipy_rotations):
    axis, angle = quat_to_axis_angle(scipy_rotations.as_quat(scalar_first=True))
    rv = scipy_rotations.as_rotvec()
    np.testing.assert_allclose(angle, np.linalg.norm(rv, axis=-1), rtol=0, atol=1e-15 * 2)
    np.testing.assert_allclose(axis * angle[:, None], rv, rtol=0, atol=1e-15 * 4)
    q = axis_angle_to_quat(axis, angle)
    assert_same_rotation_quat(q, Rotation.from_rotvec(rv).as_quat(scalar_first=True), atol=1e-15 * 2)


def test_scipy_slerp(scipy_rotations):
    """Against Slerp for 200 key pairs × 7 times, and against the closed form
    r0 · exp(t · log(r0⁻¹ r1)) (what Slerp computes) for all 5,000 pairs."""
    r0, r1 = scipy_rotations[:5000], scipy_rotations[5000:]
    q0, q1 = r0.as_quat(scalar_first=True), r1.as_quat(scalar_first=True)
    t = np.linspace(0, 1, 7)
    for k in range(200):
        ref = Slerp([0.0, 1.0], Rotation.concatenate([r0[k], r1[k]]))(t).as_quat(scalar_first=True)
        assert_same_rotation_quat(quat_slerp(q0[k], q1[k], t), ref, atol=1e-14)
    u = np.random.default_rng(3).uniform(0, 1, 5000)
    ref = (r0 * Rotation.from_rotvec(u[:, None] * (r0.inv() * r1).as_rotvec())).as_quat(scalar_first=True)
    assert_same_rotation_quat(quat_slerp(q0, q1, u), ref, atol=1e-14)


# ---------------------------------------------------------------- shapes and broadcasting


def test_single_in_single_out():
    assert quat_to_matrix([1, 0, 0, 0]).shape == (3, 3)  # a list of ints
    assert matrix_to_quat(np.eye(3).tolist()).shape == (4,)
    assert quat_multiply([1, 0, 0, 0], [0, 1, 0, 0]).shape == (4,)
    assert quat_rotate([1, 0, 0, 0], [1, 2, 3]).shape == (3,)
    axis, angle = quat_to_axis_angle([1, 0, 0, 0])
    assert axis.shape == (3,) and np.ndim(angle) == 0
    assert quat_slerp([1, 0, 0, 0], [0, 1, 0, 0], 0.5).shape == (4,)
    assert axis_angle_to_quat([0, 0, 1], 1).shape == (4,)


def test_batch_shapes(rng):
    q = quat_normalize(rng.standard_normal((5, 7, 4)))
    R = quat_to_matrix(q)
    assert R.shape == (5, 7, 3, 3)
    for i, j in [(0, 0), (4, 6), (2, 3)]:
        np.testing.assert_array_equal(R[i, j], quat_to_matrix(q[i, j]))
    assert matrix_to_quat(R).shape == (5, 7, 4)
    v = rng.standard_normal((5, 7, 3))
    out = quat_rotate(q, v)
    np.testing.assert_allclose(out[3, 2], quat_to_matrix(q[3, 2]) @ v[3, 2], rtol=0, atol=1e-15 * 4)
    a, g = quat_to_axis_angle(q)
    assert a.shape == (5, 7, 3) and g.shape == (5, 7)


def test_broadcasting(rng):
    q = quat_normalize(rng.standard_normal((6, 4)))
    v = rng.standard_normal((1000, 3))
    # many vectors, one quaternion; many quaternions, one vector
    np.testing.assert_allclose(quat_rotate(q[0], v), v @ quat_to_matrix(q[0]).T, rtol=0, atol=1e-14)
    np.testing.assert_allclose(quat_rotate(q, v[0]), quat_to_matrix(q) @ v[0], rtol=0, atol=1e-14)
    # partial broadcasting (3, 1) × (1, 4) → (3, 4)
    a, b = q[:3].reshape(3, 1, 4), quat_normalize(rng.standard_normal((1, 4, 4)))
    out = quat_multiply(a, b)
    assert out.shape == (3, 4, 4)
    np.testing.assert_allclose(out[2, 1], hamilton(a[2, 0], b[0, 1]), rtol=0, atol=1e-15)
    s = quat_slerp(a, b, np.array([0.25, 0.5, 0.75, 1.0]))
    assert s.shape == (3, 4, 4)
    np.testing.assert_allclose(s[1, 2], quat_slerp(a[1, 0], b[0, 2], 0.75), rtol=0, atol=1e-15)
    rv = quat_rotate(a, rng.standard_normal((1, 4, 3)))
    assert rv.shape == (3, 4, 3)


def test_single_elements_equal_batch_elements(rng):
    """Single calls run kernels of their own (``quat_multiply_one``, ``quat_slerp_one``): each gives
    the bits of that element in a batch, whatever form ``t`` takes."""
    a, b = quat_normalize(rng.standard_normal((2, 64, 4)))
    b[0], b[1] = a[0], -a[1]  # equal quaternions (normalised lerp), and q against −q
    t = rng.uniform(-0.5, 1.5, 64)
    products, slerps = quat_multiply(a, b), quat_slerp(a, b, t)
    for i in range(64):
        np.testing.assert_array_equal(quat_multiply(a[i], b[i]), products[i])
        for ti in (float(t[i]), t[i], np.array(t[i])):  # float, NumPy float64, 0-d array
            np.testing.assert_array_equal(quat_slerp(a[i], b[i], ti), slerps[i])
    np.testing.assert_array_equal(quat_slerp(a[2], b[2], 1), quat_slerp(a[2:3], b[2:3], 1.0)[0])


def test_empty_batch():
    assert quat_to_matrix(np.zeros((0, 4))).shape == (0, 3, 3)
    assert matrix_to_quat(np.zeros((0, 3, 3))).shape == (0, 4)
    assert quat_multiply(np.zeros((0, 4)), [1, 0, 0, 0]).shape == (0, 4)
    assert quat_rotate([1, 0, 0, 0], np.zeros((0, 3))).shape == (0, 3)
    assert quat_slerp(np.zeros((0, 4)), [1.0, 0, 0, 0], 0.5).shape == (0, 4)
    assert quat_normalize(np.zeros((0, 4))).shape == (0, 4)


def test_empty_quaternion_batch_in_rotate():
    """Regression (found by this suite, fixed in 17003c6): an empty quaternion batch was taken for
    one broadcast quaternion and q[0] was read out of bounds. The empty views below point at NaN
    memory, so reading past their end fails deterministically instead of by chance."""
    nan_q = np.full((1, 4), np.nan)[:0]
    assert nan_q.shape == (0, 4) and nan_q.flags.c_contiguous
    assert quat_rotate(nan_q, np.zeros((0, 3))).shape == (0, 3)
    assert quat_rotate(nan_q, [1.0, 2.0, 3.0]).shape == (0, 3)
    assert quat_rotate(np.zeros((0, 4)), np.zeros((0, 3))).shape == (0, 3)


def test_non_contiguous_input(rng):
    base = quat_normalize(rng.standard_normal((8, 4)))
    wide = np.zeros((8, 8))
    wide[:, ::2] = base
    view = wide[:, ::2]  # strided view, not C-contiguous
    assert not view.flags.c_contiguous
    np.testing.assert_array_equal(quat_to_matrix(view), quat_to_matrix(base))
    fortran = np.asfortranarray(base)
    np.testing.assert_array_equal(quat_multiply(fortran, base[::-1]), quat_multiply(base, base[::-1].copy()))
    R = quat_to_matrix(base)
    np.testing.assert_array_equal(matrix_to_quat(np.swapaxes(np.swapaxes(R, 1, 2).copy(), 1, 2)), matrix_to_quat(R))
