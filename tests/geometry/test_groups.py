"""The SO3 and SE3 classes: constructors (checked against scipy), composition order, inverse,
apply, interpolation, indexing, immutability, and from_matrix's validation / projection."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from scipy.spatial.transform import Rotation, Slerp

from occmap.errors import NotARotationError, ShapeError
from occmap.geometry import SE3, SO3, is_rotation

EPS = np.finfo(np.float64).eps
PROP = settings(deadline=None)

unit_quats = (
    hnp.arrays(np.float64, 4, elements=st.floats(-1.0, 1.0, allow_subnormal=False))
    .filter(lambda v: np.linalg.norm(v) > 0.1)
    .map(lambda v: v / np.linalg.norm(v))
)
translations = hnp.arrays(np.float64, 3, elements=st.floats(-100.0, 100.0))


def homogeneous(R, t):
    T = np.zeros(np.shape(R)[:-2] + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return T


@pytest.fixture
def rots(rng):
    return Rotation.random(8, rng=rng)


# ---------------------------------------------------------------- SO3 constructors vs scipy


def test_so3_constructors_match_scipy(rots, rng):
    q = rots.as_quat(scalar_first=True)
    M = rots.as_matrix()
    np.testing.assert_allclose(SO3.from_quat(q).matrix, M, rtol=0, atol=4 * EPS)
    np.testing.assert_allclose(SO3.from_rotvec(rots.as_rotvec()).matrix, M, rtol=0, atol=8 * EPS)
    ypr = rots.as_euler("ZYX")
    np.testing.assert_allclose(SO3.from_euler_zyx(ypr[:, 0], ypr[:, 1], ypr[:, 2]).matrix, M, rtol=0, atol=8 * EPS)
    rv = rots.as_rotvec()
    angle = np.linalg.norm(rv, axis=1)
    np.testing.assert_allclose(SO3.from_axis_angle(3.0 * rv, angle).matrix, M, rtol=0, atol=8 * EPS)
    np.testing.assert_array_equal(SO3.from_matrix(M).matrix, M)
    np.testing.assert_array_equal(SO3.identity().matrix, np.eye(3))
    assert SO3.identity((2, 3)).shape == (2, 3)
    assert SO3.identity(5).matrix.shape == (5, 3, 3)
    r = SO3.random(100, rng=1)
    assert r.shape == (100,) and is_rotation(r.matrix).all()
    assert SO3.random(rng=1).shape == ()


def test_so3_conversions_match_scipy(rots):
    r = SO3.from_matrix(rots.as_matrix())
    q = r.as_quat()
    assert (q[:, 0] >= 0).all()
    s = np.where(np.sum(q * rots.as_quat(scalar_first=True), 1) < 0, -1.0, 1.0)[:, None]
    np.testing.assert_allclose(q, s * rots.as_quat(scalar_first=True), rtol=0, atol=4 * EPS)
    np.testing.assert_allclose(r.as_rotvec(), rots.as_rotvec(), rtol=0, atol=1e-14)
    np.testing.assert_allclose(np.stack(r.as_euler_zyx(), -1), rots.as_euler("ZYX"), rtol=0, atol=1e-13)
    np.testing.assert_allclose(r.magnitude(), rots.magnitude(), rtol=0, atol=4 * EPS)


# ---------------------------------------------------------------- SO3 group operations


@PROP
@given(unit_quats, unit_quats, translations)
def test_so3_composition_order_and_inverse(qa, qb, p):
    A, B = SO3.from_quat(qa), SO3.from_quat(qb)
    # the product, renormalised onto SO(3): the step moves an entry by about the product's own
    # distance from SO(3), a few ulp (4.5 found by hypothesis)
    np.testing.assert_allclose((A @ B).matrix, A.matrix @ B.matrix, rtol=0, atol=8 * EPS)
    # A @ B applies B first
    e = 16 * EPS * (1 + np.abs(p).max())
    np.testing.assert_allclose((A @ B).apply(p), A.apply(B.apply(p)), rtol=0, atol=e)
    np.testing.assert_allclose((A @ A.inv()).matrix, np.eye(3), rtol=0, atol=8 * EPS)
    np.testing.assert_allclose(A.inv().matrix, np.linalg.inv(A.matrix), rtol=0, atol=8 * EPS)
    ref = Rotation.from_quat(qa, scalar_first=True) * Rotation.from_quat(qb, scalar_first=True)
    np.testing.assert_allclose((A @ B).matrix, ref.as_matrix(), rtol=0, atol=8 * EPS)
    np.testing.assert_allclose(A.apply(p), Rotation.from_quat(qa, scalar_first=True).apply(p), rtol=0, atol=e)


def test_so3_apply_broadcasting(rots, rng):
    r = SO3.from_matrix(rots.as_matrix())
    p = rng.normal(size=(100, 3))
    np.testing.assert_allclose(r[0].apply(p), rots[0].apply(p), rtol=0, atol=1e-14)  # one rotation, many points
    np.testing.assert_allclose(r.apply(p[0]), rots.apply(p[0]), rtol=0, atol=1e-14)  # many rotations, one point
    np.testing.assert_allclose(r.apply(p[:8]), rots.apply(p[:8]), rtol=0, atol=1e-14)  # pairwise
    assert r.apply([1, 2, 3]).shape == (8, 3)  # a list of ints
    out = SO3.from_matrix(rots.as_matrix().reshape(8, 1, 3, 3)).apply(p[:5].reshape(1, 5, 3))
    assert out.shape == (8, 5, 3)
    np.testing.assert_allclose(out[6, 4], rots[6].apply(p[4]), rtol=0, atol=1e-14)
    with pytest.raises(ShapeError):
        r.apply(np.zeros((8, 2)))


def test_so3_interpolate(rots):
    a, b = SO3.from_matrix(rots[0].as_matrix()), SO3.from_matrix(rots[1].as_matrix())
    np.testing.assert_allclose(a.interpolate(b, 0.0).matrix, a.matrix, rtol=0, atol=8 * EPS)
    np.testing.assert_allclose(a.interpolate(b, 1.0).matrix, b.matrix, rtol=0, atol=8 * EPS)
    t = np.linspace(0, 1, 9)
    ref = Slerp([0, 1], Rotation.concatenate([rots[0], rots[1]]))(t).as_matrix()
    out = a.interpolate(b, t)
    assert out.shape == (9,)
    np.testing.assert_allclose(out.matrix, ref, rtol=0, atol=1e-14)
    half = (a.inv() @ a.interpolate(b, 0.5)).magnitude()
    assert half == pytest.approx((a.inv() @ b).magnitude() / 2, abs=1e-14)


def test_so3_indexing_and_len(rots):
    r = SO3.from_matrix(rots.as_matrix().reshape(2, 4, 3, 3))
    assert len(r) == 2 and r.shape == (2, 4)
    np.testing.assert_array_equal(r[1, 2].matrix, rots[6].as_matrix())
    assert r[1].shape == (4,)
    assert r[:, 1:3].shape == (2, 2)
    assert r[np.array([1, 0])].shape == (2, 4)
    assert r[-1, -1].shape == ()
    with pytest.raises(TypeError):
        len(SO3.identity())
    with pytest.raises(IndexError):
        SO3.identity()[0]
    with pytest.raises(IndexError):
        r[1, 2, 0]
    assert "SO3" in repr(r) and "SO3" in repr(r[0, 0])


def test_indexing_into_matrices_is_rejected():
    """Regression (found by this suite, fixed in 17003c6): with a batch of 3 (SO3) or 4 (SE3),
    r[:, 0] reached into the matrices and returned an 'SO3' holding rows, not a rotation."""
    with pytest.raises(IndexError):
        SO3.random(3, rng=0)[:, 0]
    with pytest.raises(IndexError):
        SE3.identity(4)[:, 0]


def test_so3_immutability(rots):
    M = rots.as_matrix()
    r = SO3.from_matrix(M)
    M[0] = np.eye(3)  # modifying the input after construction
    np.testing.assert_array_equal(r.matrix[0], rots[0].as_matrix())
    assert not r.matrix.flags.writeable
    with pytest.raises(ValueError):
        r.matrix[0, 0, 0] = 2.0
    assert not r[0].matrix.flags.writeable
    assert not r.inv().matrix.flags.writeable
    assert not (r @ r).matrix.flags.writeable
    assert not SO3.identity().matrix.flags.writeable
    M2 = rots.as_matrix() * 1.001
    p = SO3.from_matrix(M2, project=True)
    M2[:] = 0.0
    assert is_rotation(p.matrix).all()
    assert not p.matrix.flags.writeable
    with pytest.raises(AttributeError):
        r.foo = 1  # __slots__: no new attributes


def test_so3_from_matrix_validation_and_projection(rots, rng):
    with pytest.raises(NotARotationError):
        SO3.from_matrix(np.diag([1.0, 1.0, -1.0]))
    M = rots.as_matrix() + rng.normal(0, 1e-3, (8, 3, 3))
    with pytest.raises(NotARotationError, match=r"matrix\[0\]"):
        SO3.from_matrix(M)
    P = SO3.from_matrix(M, project=True)
    np.testing.assert_allclose(P.matrix, Rotation.from_matrix(M).as_matrix(), rtol=0, atol=1e-14)
    # a reflection is projected onto a proper rotation
    assert is_rotation(SO3.from_matrix(np.diag([1.0, 1.0, -1.0]), project=True).matrix)
    # within the 1e-6 tolerance the matrix is kept as given
    almost = rots[0].as_matrix() * (1 + 1e-8)
    np.testing.assert_array_equal(SO3.from_matrix(almost).matrix, almost)


def test_so3_project_rejects_2x2():
    """Regression (found by this suite, fixed in 17003c6): project=True returned an 'SO3' holding
    a 2×2 matrix (nearest_rotation accepts 2-D matrices)."""
    with pytest.raises(ShapeError):
        SO3.from_matrix(np.eye(2), project=True)


# ---------------------------------------------------------------- SE3


def test_se3_constructors(rots, rng):
    t = rng.uniform(-5, 5, (8, 3))
    M = rots.as_matrix()
    ref = homogeneous(M, t)
    np.testing.assert_allclose(SE3.from_rt(M, t).matrix, ref, rtol=0, atol=0)
    np.testing.assert_allclose(SE3.from_rt(SO3.from_matrix(M), t).matrix, ref, rtol=0, atol=0)
    np.testing.assert_allclose(SE3.from_quat(rots.as_quat(scalar_first=True), t).matrix, ref, rtol=0, atol=4 * EPS)
    ypr = rots.as_euler("ZYX")
    np.testing.assert_allclose(SE3.from_euler_zyx(ypr[:, 0], ypr[:, 1], ypr[:, 2], t).matrix, ref, rtol=0, atol=8 * EPS)
    np.testing.assert_allclose(SE3.from_rotvec(rots.as_rotvec(), t).matrix, ref, rtol=0, atol=8 * EPS)
    np.testing.assert_array_equal(SE3.from_matrix(ref).matrix, ref)
    np.testing.assert_array_equal(SE3.identity().matrix, np.eye(4))
    assert SE3.identity(3).shape == (3,)
    # default translation is zero
    np.testing.assert_array_equal(SE3.from_quat([1.0, 0, 0, 0]).matrix, np.eye(4))
    T = SE3.from_rt(M, t)
    np.testing.assert_array_equal(T.rotation.matrix, M)
    np.testing.assert_array_equal(T.translation, t)
    assert isinstance(T.rotation, SO3)
    # exp / log
    xi = T.log()
    assert xi.shape == (8, 6)
    np.testing.assert_allclose(SE3.exp(xi).matrix, ref, rtol=0, atol=1e-13)


@PROP
@given(unit_quats, translations, unit_quats, translations, translations)
def test_se3_composition_order(qa, ta, qb, tb, p_c):
    """T_a_c = T_a_b @ T_b_c, and T_a_c.apply(p_c) = T_a_b.apply(T_b_c.apply(p_c))."""
    T_a_b, T_b_c = SE3.from_quat(qa, ta), SE3.from_quat(qb, tb)
    T_a_c = T_a_b @ T_b_c
    e = 32 * EPS * (1 + np.abs(ta).max() + np.abs(tb).max() + np.abs(p_c).max())  # a few ulp of the magnitudes
    np.testing.assert_allclose(T_a_c.matrix, T_a_b.matrix @ T_b_c.matrix, rtol=0, atol=e)
    np.testing.assert_allclose(T_a_c.apply(p_c), T_a_b.apply(T_b_c.apply(p_c)), rtol=0, atol=e)
    Ra = Rotation.from_quat(qa, scalar_first=True)
    np.testing.assert_allclose(T_a_b.apply(p_c), Ra.apply(p_c) + ta, rtol=0, atol=e)
    np.testing.assert_allclose((T_a_b @ T_a_b.inv()).matrix, np.eye(4), rtol=0, atol=e)
    np.testing.assert_allclose((T_a_b.inv() @ T_a_b).matrix, np.eye(4), rtol=0, atol=e)
    np.testing.assert_allclose(T_a_b.inv().apply(T_a_b.apply(p_c)), p_c, rtol=0, atol=e)


def test_se3_apply_broadcasting(rots, rng):
    T = SE3.from_rt(rots.as_matrix(), rng.normal(size=(8, 3)))
    p = rng.normal(size=(1000, 3))
    assert T[0].apply(p).shape == (1000, 3)
    assert T.apply(p[0]).shape == (8, 3)
    assert T.apply(p[:8]).shape == (8, 3)
    np.testing.assert_allclose(T.apply(p[:8])[5], T[5].matrix[:3, :3] @ p[5] + T[5].translation, rtol=0, atol=1e-14)
    assert SE3.from_rt(rots.as_matrix().reshape(8, 1, 3, 3), np.zeros(3)).apply(p[:4].reshape(1, 4, 3)).shape == (8, 4, 3)


def test_se3_interpolate(rots, rng):
    a = SE3.from_rt(rots[0].as_matrix(), [0.0, 0.0, 0.0])
    b = SE3.from_rt(rots[1].as_matrix(), [2.0, -4.0, 6.0])
    np.testing.assert_allclose(a.interpolate(b, 0.0).matrix, a.matrix, rtol=0, atol=8 * EPS)
    np.testing.assert_allclose(a.interpolate(b, 1.0).matrix, b.matrix, rtol=0, atol=8 * EPS)
    t = np.linspace(0, 1, 5)
    m = a.interpolate(b, t)
    assert m.shape == (5,)
    np.testing.assert_allclose(m.translation, np.outer(t, [2.0, -4.0, 6.0]), rtol=0, atol=8 * EPS)
    ref = Slerp([0, 1], Rotation.concatenate([rots[0], rots[1]]))(t).as_matrix()
    np.testing.assert_allclose(m.rotation.matrix, ref, rtol=0, atol=1e-14)


def test_se3_indexing_and_immutability(rots, rng):
    t = rng.normal(size=(8, 3))
    M = homogeneous(rots.as_matrix(), t)
    T = SE3.from_matrix(M.reshape(2, 4, 4, 4))
    assert len(T) == 2 and T.shape == (2, 4)
    np.testing.assert_array_equal(T[1, 3].matrix, M[7])
    assert T[:, ::2].shape == (2, 2)
    with pytest.raises(IndexError):
        SE3.identity()[0]
    with pytest.raises(TypeError):
        len(SE3.identity())
    M[:] = 0.0  # after construction
    np.testing.assert_array_equal(T[0, 0].translation, t[0])
    for arr in (T.matrix, T.translation, T.rotation.matrix, T.inv().matrix, (T @ T).matrix, T[0, 0].matrix):
        assert not arr.flags.writeable
    with pytest.raises(ValueError):
        T.translation[0, 0, 0] = 1.0
    assert "SE3" in repr(T) and "SE3" in repr(T[0, 0])


def test_se3_from_matrix_validation_and_projection(rots, rng):
    good = homogeneous(rots[0].as_matrix(), [1.0, 2.0, 3.0])
    noisy = good.copy()
    noisy[:3, :3] += rng.normal(0, 1e-3, (3, 3))
    with pytest.raises(NotARotationError):
        SE3.from_matrix(noisy)
    fixed = SE3.from_matrix(noisy, project=True)
    np.testing.assert_allclose(fixed.rotation.matrix, Rotation.from_matrix(noisy[:3, :3]).as_matrix(), rtol=0, atol=1e-14)
    np.testing.assert_array_equal(fixed.translation, [1.0, 2.0, 3.0])
    before = noisy.copy()
    SE3.from_matrix(noisy, project=True)
    np.testing.assert_array_equal(noisy, before)  # the input is not projected in place
    # a bad last row cannot be projected away
    shear = good.copy()
    shear[3] = [0.0, 0.0, 1.0, 1.0]
    with pytest.raises(NotARotationError, match="last row"):
        SE3.from_matrix(shear)
    with pytest.raises(NotARotationError, match="last row"):
        SE3.from_matrix(shear, project=True)
    with pytest.raises(ShapeError):
        SE3.from_matrix(np.eye(3), project=True)
