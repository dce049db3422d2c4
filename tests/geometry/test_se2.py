"""Planar geometry: wrap_angle, rot2, so2_angle, the SO2 class, se2_matrix / se2_from_matrix, the
2-D forms of make_transform / invert_transform / transform_points, and the SE2 class."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from occmap.errors import NotARotationError, ShapeError
from occmap.geometry import (
    SE2,
    SO2,
    compose_poses,
    invert_transform,
    make_transform,
    nearest_rotation,
    relative_poses,
    rot2,
    se2_from_matrix,
    se2_matrix,
    so2_angle,
    transform_points,
    wrap_angle,
    wrap_angle_one,
)

EPS = np.finfo(np.float64).eps
PROP = settings(deadline=None)
PI = np.pi

angles = st.floats(-50.0, 50.0)
coords = st.floats(-100.0, 100.0)
poses = st.tuples(coords, coords, angles)


def angle_diff(a, b):
    d = np.subtract(a, b)
    return np.arctan2(np.sin(d), np.cos(d))


def pose_matrix(x, y, t):
    """Reference homogeneous matrix, NumPy only."""
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, -s, x], [s, c, y], [0, 0, 1.0]])


# ---------------------------------------------------------------- wrap_angle


@pytest.mark.parametrize(
    "a, expected",
    [(0.0, 0.0), (PI, PI), (-PI, PI), (3 * PI, PI), (-3 * PI, PI), (2 * PI, 0.0), (PI / 2 + 4 * PI, PI / 2),
     (-PI / 2 - 2 * PI, -PI / 2), (1.0, 1.0), (-1.0, -1.0)],
)
def test_wrap_angle_values(a, expected):
    assert wrap_angle(a) == pytest.approx(expected, abs=8 * EPS * max(1, abs(a)))
    assert -PI < wrap_angle(a) <= PI


@PROP
@given(st.floats(-1e4, 1e4))
def test_wrap_angle_is_congruent(a):
    w = wrap_angle(a)
    assert abs(angle_diff(w, a)) <= 4 * EPS * max(1.0, abs(a))
    assert -PI < w <= PI


def test_wrap_angle_leaves_atan2_output_alone(rng):
    """(−π, π] is atan2's range, so wrap(atan2(s, c)) is atan2(s, c) bit for bit."""
    t = np.arctan2(rng.normal(size=100_000), rng.normal(size=100_000))
    t = np.r_[t, PI, np.nextafter(PI, 0), 0.0, 1e-300, -1e-300]
    np.testing.assert_array_equal(wrap_angle(t), t)


def test_wrap_angle_one_is_wrap_angle_bit_for_bit(rng):
    """The scalar twin (for kernels and Python scalars) follows the array rule to the bit, near
    every odd multiple of π too."""
    k = np.arange(-9, 10) * PI
    a = np.r_[rng.uniform(-30, 30, 20_000), k, np.nextafter(k, 100), np.nextafter(k, -100), 0.0, -0.0, 1e300]
    one = np.array([wrap_angle_one(float(v)) for v in a])
    np.testing.assert_array_equal(one.view(np.int64), wrap_angle(a).view(np.int64))
    assert type(wrap_angle_one(7.0)) is float


def test_wrap_angle_shapes():
    assert np.ndim(wrap_angle(1)) == 0
    assert wrap_angle([[1.0, 7.0]]).shape == (1, 2)
    assert wrap_angle(np.zeros(0)).shape == (0,)


def test_wrap_angle_strict_range():
    """Regression (found by this suite, fixed in 17003c6): a − 2π·ceil((a − π)/2π) returned values
    above π for ~19 % of floats within an ulp of (2k+1)π, |k| < 1000, and moved the in-range
    nextafter(−π, 0) above π."""
    a = np.nextafter(-PI, 0.0)  # inside (−π, π]: must come back unchanged
    assert wrap_angle(a) == a
    assert wrap_angle(-34.55751918948772) <= PI  # -11π: returns 3.1415926535897967 > π
    k = np.arange(-1000, 1000)
    y = (2 * k + 1) * PI
    y = np.r_[y, np.nextafter(y, np.inf), np.nextafter(y, -np.inf)]
    w = wrap_angle(y)
    assert ((w > -PI) & (w <= PI)).all()


# ---------------------------------------------------------------- rot2 / so2_angle / SO2


@PROP
@given(angles)
def test_rot2_and_angle(t):
    R = rot2(t)
    np.testing.assert_allclose(R, pose_matrix(0, 0, t)[:2, :2], rtol=0, atol=0)
    np.testing.assert_allclose(R @ R.T, np.eye(2), rtol=0, atol=4 * EPS)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=4 * EPS)
    assert abs(angle_diff(so2_angle(R), t)) <= 4 * EPS * max(1, abs(t))


def test_rot2_counter_clockwise():
    np.testing.assert_allclose(rot2(PI / 2) @ [1.0, 0.0], [0.0, 1.0], atol=EPS)
    assert rot2(np.zeros((3, 4))).shape == (3, 4, 2, 2)


@PROP
@given(angles, angles, angles)
def test_so2_group(a, b, c):
    A, B, C = SO2.from_angle(a), SO2.from_angle(b), SO2.from_angle(c)
    np.testing.assert_allclose((A @ B).matrix, A.matrix @ B.matrix, rtol=0, atol=1e-14)
    assert abs(angle_diff(((A @ B) @ C).angle, (A @ (B @ C)).angle)) <= 1e-13
    np.testing.assert_allclose((A @ A.inv()).matrix, np.eye(2), rtol=0, atol=1e-15)
    assert -PI - 1e-13 <= (A @ B).angle <= PI + 1e-13
    p = np.array([[1.0, 2.0], [-3.0, 0.5]])
    np.testing.assert_allclose(A.apply(p), p @ A.matrix.T, rtol=0, atol=1e-14)


def test_so2_class_api():
    r = SO2.from_angle([0.1, 3.0, -3.0])
    assert r.shape == (3,) and len(r) == 3
    assert r[1].angle == 3.0 and r[1].shape == ()
    np.testing.assert_allclose(SO2.identity(4).angle, np.zeros(4))
    with pytest.raises(TypeError):
        len(SO2.identity())
    # wraps on construction
    assert SO2.from_angle(3 * PI).angle == pytest.approx(PI, abs=8 * EPS)
    # interpolate the short way round: from 3.0 to −3.0 passes through π, not 0
    mid = SO2.from_angle(3.0).interpolate(SO2.from_angle(-3.0), 0.5)
    assert abs(angle_diff(mid.angle, PI)) < 1e-14
    assert SO2.from_angle(0.2).interpolate(SO2.from_angle(1.0), 0.0).angle == pytest.approx(0.2, abs=EPS)
    assert SO2.from_angle(0.2).interpolate(SO2.from_angle(1.0), 1.0).angle == pytest.approx(1.0, abs=EPS)
    # one rotation, many points; many rotations, one point
    pts = np.random.default_rng(0).normal(size=(10, 2))
    assert SO2.from_angle(0.3).apply(pts).shape == (10, 2)
    assert r.apply([1.0, 0.0]).shape == (3, 2)
    np.testing.assert_allclose(r.apply([1.0, 0.0]), np.c_[np.cos(r.angle), np.sin(r.angle)], atol=EPS)


def test_so2_from_matrix():
    R = rot2(0.7)
    assert SO2.from_matrix(R).angle == pytest.approx(0.7, abs=2 * EPS)
    with pytest.raises(NotARotationError):
        SO2.from_matrix(1.01 * R)
    with pytest.raises(NotARotationError):
        SO2.from_matrix(np.diag([1.0, -1.0]))
    M = np.random.default_rng(5).normal(size=(100, 2, 2))
    proj = SO2.from_matrix(M, project=True)
    np.testing.assert_allclose(proj.matrix, nearest_rotation(M), rtol=0, atol=1e-14)


def test_so2_immutable():
    a = np.array([0.1, 0.2])
    r = SO2.from_angle(a)
    a[0] = 5.0
    assert r.angle[0] == 0.1
    with pytest.raises(ValueError):
        r.angle[0] = 1.0


# ---------------------------------------------------------------- se2_matrix / se2_from_matrix / 2-D transforms


@PROP
@given(poses)
def test_se2_matrix_round_trip(p):
    x, y, t = p
    T = se2_matrix(x, y, t)
    np.testing.assert_array_equal(T, pose_matrix(x, y, t))
    xx, yy, tt = se2_from_matrix(T)
    assert (xx, yy) == (x, y)
    assert abs(angle_diff(tt, t)) <= 4 * EPS * max(1, abs(t)) and -PI <= tt <= PI


@PROP
@given(poses, poses, poses)
def test_se2_composition_matches_matrix_product(a, b, c):
    A, B, C = SE2.from_xytheta(*a), SE2.from_xytheta(*b), SE2.from_xytheta(*c)
    # a few ulp of the magnitudes involved (translations up to 100, angles up to 50 rad)
    e = 32 * EPS * (1 + sum(np.abs(v).max() for v in (a, b, c)))
    np.testing.assert_allclose((A @ B).matrix, pose_matrix(*a) @ pose_matrix(*b), rtol=0, atol=e)
    np.testing.assert_allclose(((A @ B) @ C).matrix, (A @ (B @ C)).matrix, rtol=0, atol=e)
    np.testing.assert_allclose((A @ A.inv()).matrix, np.eye(3), rtol=0, atol=e)
    np.testing.assert_allclose((A.inv() @ A).matrix, np.eye(3), rtol=0, atol=e)
    np.testing.assert_allclose(A.inv().matrix, np.linalg.inv(pose_matrix(*a)), rtol=0, atol=e)
    # the functional 2-D forms agree with the class
    np.testing.assert_allclose(invert_transform(A.matrix), A.inv().matrix, rtol=0, atol=e)
    p = np.array([[1.0, -2.0], [0.0, 3.0]])
    np.testing.assert_allclose(A.apply(p), transform_points(pose_matrix(*a), p), rtol=0, atol=e)
    np.testing.assert_allclose(A.apply(p), p @ pose_matrix(*a)[:2, :2].T + a[:2], rtol=0, atol=e)


def test_make_transform_2d():
    T = make_transform(rot2(0.4), [1.0, 2.0])
    np.testing.assert_allclose(T, pose_matrix(1.0, 2.0, 0.4), rtol=0, atol=2 * EPS)
    T = make_transform(rot2(np.array([0.1, 0.2])), np.zeros((2, 2)))
    assert T.shape == (2, 3, 3)
    with pytest.raises(ShapeError):
        make_transform(rot2(0.4), [1.0, 2.0, 3.0])


def test_se2_body_to_world():
    """A robot at (1, 2) heading 90°: a point 1 m ahead is at (1, 3) in the world."""
    T_world_robot = SE2.from_xytheta(1.0, 2.0, PI / 2)
    np.testing.assert_allclose(T_world_robot.apply([1.0, 0.0]), [1.0, 3.0], atol=4 * EPS)
    T_robot_laser = SE2.from_xytheta(0.5, 0.0, 0.0)
    np.testing.assert_allclose((T_world_robot @ T_robot_laser).translation, [1.0, 2.5], atol=4 * EPS)


# ---------------------------------------------------------------- SE2 class


def test_se2_class_api(rng):
    p = np.c_[rng.uniform(-5, 5, (6, 2)), rng.uniform(-3, 3, 6)]
    T = SE2(p)
    assert T.shape == (6,) and len(T) == 6
    np.testing.assert_array_equal(T[2].xytheta, p[2])
    assert T[1:3].shape == (2,)
    np.testing.assert_array_equal(T.translation, p[:, :2])
    np.testing.assert_array_equal(T.rotation.angle, p[:, 2])
    assert T.matrix.shape == (6, 3, 3)
    np.testing.assert_array_equal(SE2.identity().xytheta, [0.0, 0.0, 0.0])
    assert SE2.identity((2, 3)).shape == (2, 3)
    with pytest.raises(TypeError):
        len(SE2.identity())
    # θ is wrapped on construction
    assert SE2([0.0, 0.0, 3 * PI]).xytheta[2] == pytest.approx(PI, abs=8 * EPS)
    # from_matrix, project
    M = se2_matrix(1.0, 2.0, 0.3)
    np.testing.assert_allclose(SE2.from_matrix(M).xytheta, [1.0, 2.0, 0.3], atol=2 * EPS)
    bad = M.copy()
    bad[:2, :2] *= 1.1
    with pytest.raises(NotARotationError):
        SE2.from_matrix(bad)
    np.testing.assert_allclose(SE2.from_matrix(bad, project=True).xytheta, [1.0, 2.0, 0.3], atol=4 * EPS)
    # broadcasting: (3, 1) poses @ (1, 4) poses
    A, B = SE2(p[:3].reshape(3, 1, 3)), SE2(p[2:].reshape(1, 4, 3))
    C = A @ B
    assert C.shape == (3, 4)
    np.testing.assert_allclose(C[2, 1].matrix, pose_matrix(*p[2]) @ pose_matrix(*p[3]), rtol=0, atol=1e-13)
    # one pose, many points; many poses, one point
    pts = rng.normal(size=(50, 2))
    assert T[0].apply(pts).shape == (50, 2)
    assert T.apply([1.0, 1.0]).shape == (6, 2)


def test_se2_interpolate():
    a, b = SE2.from_xytheta(0.0, 0.0, 3.0), SE2.from_xytheta(2.0, 4.0, -3.0)
    mid = a.interpolate(b, 0.5)
    np.testing.assert_allclose(mid.translation, [1.0, 2.0])
    assert abs(angle_diff(mid.xytheta[2], PI)) < 1e-14  # the short way, through π
    np.testing.assert_allclose(a.interpolate(b, 0.0).xytheta, a.xytheta, atol=EPS)
    np.testing.assert_allclose(a.interpolate(b, 1.0).xytheta, b.xytheta, atol=4 * EPS)
    assert a.interpolate(b, np.linspace(0, 1, 5)).shape == (5,)


def test_se2_immutable():
    p = np.array([1.0, 2.0, 0.3])
    T = SE2(p)
    p[0] = 100.0
    assert T.xytheta[0] == 1.0
    with pytest.raises(ValueError):
        T.xytheta[0] = 5.0
    with pytest.raises(ValueError):
        T.translation[0] = 5.0


def test_se2_lists_ints_empty_noncontiguous():
    assert SE2([1, 2, 0]).shape == ()
    assert se2_matrix(1, 2, 0).shape == (3, 3)
    assert se2_matrix(np.zeros(0), 0.0, 0.0).shape == (0, 3, 3)
    assert se2_from_matrix(np.zeros((0, 3, 3)))[0].shape == (0,)
    T = se2_matrix(np.arange(4.0), 1.0, np.linspace(-3, 3, 4))
    Tt = np.swapaxes(np.swapaxes(T, 1, 2).copy(), 1, 2)
    np.testing.assert_array_equal(se2_from_matrix(Tt)[2], se2_from_matrix(T)[2])
    np.testing.assert_array_equal(invert_transform(Tt), invert_transform(T))


def test_se2_apply_empty_batch():
    """Regression (found by this suite, fixed in 17003c6): the 0-row pose matrix was read at
    index 0 out of bounds."""
    assert SE2.identity(0).apply([1.0, 2.0]).shape == (0, 2)


def test_planar_angle_range_with_negative_zero():
    """Regression (found by this suite, fixed in 17003c6): atan2(−0.0, −1) = −π leaked out."""
    R = np.array([[-1.0, 0.0], [-0.0, -1.0]])
    assert -PI < so2_angle(R) <= PI
    T = np.array([[-1.0, 0.0, 0.0], [-0.0, -1.0, 0.0], [0.0, 0.0, 1.0]])
    assert -PI < se2_from_matrix(T)[2] <= PI


def test_compose_and_relative_poses_agree_with_the_se2_products_and_broadcast():
    rng = np.random.default_rng(7)
    a = rng.uniform([-5, -5, -4], [5, 5, 4], (50, 3))
    b = rng.uniform([-5, -5, -4], [5, 5, 4], (50, 3))
    np.testing.assert_allclose(compose_poses(a, b), (SE2(a) @ SE2(b)).xytheta, atol=1e-12)
    np.testing.assert_allclose(relative_poses(a, b), (SE2(a).inv() @ SE2(b)).xytheta, atol=1e-12)
    np.testing.assert_allclose(compose_poses(a, relative_poses(a, b)), SE2(b).xytheta, atol=1e-12)
    one = compose_poses(a[0], b)  # one pose against many
    assert one.shape == (50, 3)
    np.testing.assert_allclose(one[3], compose_poses(a[0], b[3]), atol=1e-15)
    # a quarter turn: one metre ahead of a robot facing +y is one metre up
    np.testing.assert_allclose(compose_poses([1.0, 2.0, np.pi / 2], [1.0, 0.0, 0.0]), [1.0, 3.0, np.pi / 2], atol=1e-15)
