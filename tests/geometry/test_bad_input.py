"""Bad input to the geometry core: every deliberate error is an occmap error (OccmapError) and a
ValueError, of the right subclass, with a message naming the argument, the element index and
what is wrong. Garbage in must raise, never return NaN."""

from __future__ import annotations

import re

import numpy as np
import pytest

from occmap.errors import (
    InvalidArgumentError,
    NonFiniteError,
    NotARotationError,
    NotUnitQuaternionError,
    OccmapError,
    ShapeError,
)
from occmap.geometry import (
    SE2,
    SE3,
    SO2,
    SO3,
    axis_angle_to_matrix,
    axis_angle_to_quat,
    compose_transforms,
    euler_zyx_to_matrix,
    exp_se3,
    exp_so3,
    hat,
    invert_transform,
    is_rotation,
    log_se3,
    log_so3,
    make_transform,
    matrix_to_axis_angle,
    matrix_to_euler_zyx,
    matrix_to_quat,
    nearest_rotation,
    quat_conjugate,
    quat_from_xyzw,
    quat_inverse,
    quat_multiply,
    quat_normalize,
    quat_rotate,
    quat_slerp,
    quat_to_axis_angle,
    quat_to_matrix,
    rot_x,
    se2_from_matrix,
    se2_matrix,
    so2_angle,
    transform_points,
    vee,
)

NAN, INF = np.nan, np.inf
Q1 = np.array([1.0, 0.0, 0.0, 0.0])
I3, I4 = np.eye(3), np.eye(4)
REFLECT = np.diag([1.0, 1.0, -1.0])
SCALED = 1.01 * np.eye(3)


def with_bad(good, index, value):
    """A batch of copies of ``good`` with element ``index`` (of the leading shape) set to ``value``."""
    shape = (2, 3) if len(index) == 2 else (4,)
    out = np.array(np.broadcast_to(good, shape + np.shape(good)))
    out[index] = value
    return out


def rigid(last_row=(0.0, 0.0, 0.0, 1.0), R=I3, t=(1.0, 2.0, 3.0)):
    T = np.eye(4)
    T[:3, :3], T[:3, 3], T[3] = R, t, last_row
    return T


# (callable, exception type, regex the message must match)
CASES = [
    # ---- wrong shapes: the message names the argument and the shape it got
    pytest.param(lambda: quat_to_matrix(np.zeros(3)), ShapeError, r"q must have shape \(\.\.\., 4\), got \(3,\)", id="quat_to_matrix-(3,)"),
    pytest.param(lambda: quat_multiply(np.zeros((2, 3)), Q1), ShapeError, r"q1 .*got \(2, 3\)", id="quat_multiply-(2,3)"),
    pytest.param(lambda: quat_rotate(Q1, [1.0, 2.0]), ShapeError, r"v .*got \(2,\)", id="quat_rotate-v(2,)"),
    pytest.param(lambda: matrix_to_quat(np.zeros((3, 4))), ShapeError, r"R .*\(\.\.\., 3, 3\), got \(3, 4\)", id="matrix_to_quat-(3,4)"),
    pytest.param(lambda: exp_so3(np.zeros(4)), ShapeError, r"rotvec .*got \(4,\)", id="exp_so3-(4,)"),
    pytest.param(lambda: log_so3(np.eye(4)), ShapeError, r"got \(4, 4\)", id="log_so3-(4,4)"),
    pytest.param(lambda: hat([1.0, 2.0]), ShapeError, r"w .*got \(2,\)", id="hat-(2,)"),
    pytest.param(lambda: vee(np.zeros(3)), ShapeError, r"W .*got \(3,\)", id="vee-(3,)"),
    pytest.param(lambda: matrix_to_euler_zyx(np.eye(2)), ShapeError, r"got \(2, 2\)", id="m2euler-(2,2)"),
    pytest.param(lambda: exp_se3(np.zeros(5)), ShapeError, r"twist .*got \(5,\)", id="exp_se3-(5,)"),
    pytest.param(lambda: log_se3(np.eye(3)), ShapeError, r"T .*\(\.\.\., 4, 4\), got \(3, 3\)", id="log_se3-(3,3)"),
    pytest.param(lambda: make_transform(I3, [1.0, 2.0]), ShapeError, r"t .*got \(2,\)", id="make_transform-t(2,)"),
    pytest.param(lambda: transform_points(I4, [1.0, 2.0]), ShapeError, r"points .*got \(2,\)", id="transform_points-(2,)"),
    pytest.param(lambda: compose_transforms(I4, I3), ShapeError, r"B .*got \(3, 3\)", id="compose-(3,3)"),
    pytest.param(lambda: se2_from_matrix(I4), ShapeError, r"got \(4, 4\)", id="se2_from_matrix-(4,4)"),
    pytest.param(lambda: nearest_rotation(np.zeros((4, 4))), ShapeError, r"M .*got \(4, 4\)", id="nearest-(4,4)"),
    pytest.param(lambda: is_rotation(np.zeros((2, 2))), ShapeError, r"got \(2, 2\)", id="is_rotation-(2,2)"),
    pytest.param(lambda: axis_angle_to_quat([1.0, 0.0], 1.0), ShapeError, r"axis .*got \(2,\)", id="axis_angle-(2,)"),
    pytest.param(lambda: so2_angle(I3), ShapeError, r"got \(3, 3\)", id="so2_angle-(3,3)"),
    pytest.param(lambda: SO3.from_matrix(np.zeros((2, 3, 4))), ShapeError, r"got \(2, 3, 4\)", id="SO3-(2,3,4)"),
    pytest.param(lambda: SE3.from_matrix(I3), ShapeError, r"got \(3, 3\)", id="SE3-(3,3)"),
    pytest.param(lambda: SE3.from_matrix(I3, project=True), ShapeError, r"got \(3, 3\)", id="SE3-project-(3,3)"),
    pytest.param(lambda: SE2(np.zeros(2)), ShapeError, r"got \(2,\)", id="SE2-(2,)"),
    pytest.param(lambda: SO3.identity().apply(np.zeros(2)), ShapeError, r"got \(2,\)", id="SO3.apply-(2,)"),
    pytest.param(lambda: SO2.identity().apply(np.zeros(3)), ShapeError, r"got \(3,\)", id="SO2.apply-(3,)"),
    # ---- leading shapes that do not broadcast: both shapes named
    pytest.param(lambda: quat_slerp(np.tile(Q1, (2, 1)), np.tile(Q1, (3, 1)), 0.5), ShapeError, r"q0 \(2,\).*q1 \(3,\)", id="slerp-broadcast"),
    pytest.param(lambda: transform_points(np.tile(I4, (3, 1, 1)), np.zeros((5, 3))), ShapeError, r"T \(3,\).*points \(5,\)", id="points-broadcast"),
    pytest.param(lambda: euler_zyx_to_matrix(np.zeros(2), np.zeros(3), 0.0), ShapeError, r"yaw \(2,\).*pitch \(3,\)", id="euler-broadcast"),
    pytest.param(lambda: se2_matrix([1.0, 2.0], [1.0, 2.0, 3.0], 0.0), ShapeError, r"x \(2,\).*y \(3,\)", id="se2-broadcast"),
    # ---- NaN / inf: NonFiniteError naming the argument and the element
    pytest.param(lambda: quat_multiply(with_bad(Q1, (1,), NAN), Q1), NonFiniteError, r"q1\[1\] = .* is not finite", id="quat_multiply-nan"),
    pytest.param(lambda: quat_multiply(Q1, with_bad(Q1, (0, 2), INF)), NonFiniteError, r"q2\[0, 2\] = .* is not finite", id="quat_multiply-inf-2d"),
    pytest.param(lambda: quat_multiply(with_bad(Q1, (2,), NAN), with_bad(Q1, (1,), INF)), NonFiniteError, r"q2\[1\] = .* is not finite", id="quat_multiply-first-bad-row"),
    pytest.param(lambda: quat_multiply(Q1, [0.0, NAN, 0.0, 0.0]), NonFiniteError, r"q2 = .* is not finite", id="quat_multiply-single-nan"),
    pytest.param(lambda: quat_to_matrix(with_bad(Q1, (2,), NAN)), NonFiniteError, r"q\[2\] = .* is not finite", id="quat_to_matrix-nan"),
    pytest.param(lambda: quat_conjugate([NAN, 0, 0, 0]), NonFiniteError, r"q = .* is not finite", id="quat_conjugate-nan"),
    pytest.param(lambda: quat_normalize(with_bad(Q1, (3,), INF)), NonFiniteError, r"q\[3\]", id="quat_normalize-inf"),
    pytest.param(lambda: quat_rotate(Q1, with_bad([1.0, 2.0, 3.0], (3,), NAN)), NonFiniteError, r"v\[3\] = .* is not finite", id="quat_rotate-v-nan"),
    pytest.param(lambda: quat_slerp(Q1, Q1, [0.0, NAN]), NonFiniteError, r"t\[1\] = nan is not finite", id="slerp-t-nan"),
    pytest.param(lambda: axis_angle_to_quat([1.0, 0, 0], [0.0, 1.0, INF]), NonFiniteError, r"angle\[2\]", id="axis_angle-angle-inf"),
    pytest.param(lambda: exp_so3(with_bad([0.1, 0.2, 0.3], (1,), NAN)), NonFiniteError, r"rotvec\[1\] = .* is not finite", id="exp_so3-nan"),
    pytest.param(lambda: log_so3(with_bad(I3, (0, 1), INF)), NonFiniteError, r"R\[0, 1\] = .* is not finite", id="log_so3-inf"),
    pytest.param(lambda: matrix_to_quat(np.full((3, 3), NAN)), NonFiniteError, r"R = .* is not finite", id="matrix_to_quat-nan"),
    pytest.param(lambda: hat([0.0, NAN, 0.0]), NonFiniteError, r"w = ", id="hat-nan"),
    pytest.param(lambda: rot_x([0.0, NAN]), NonFiniteError, r"angle\[1\] = nan is not finite", id="rot_x-nan"),
    pytest.param(lambda: euler_zyx_to_matrix(0.0, float("nan"), 0.0), NonFiniteError, r"pitch = nan is not finite", id="euler-float-nan"),
    pytest.param(lambda: euler_zyx_to_matrix([0.0, 0.0], [0.0, INF], 0.0), NonFiniteError, r"pitch\[1\] = inf", id="euler-array-inf"),
    pytest.param(lambda: matrix_to_euler_zyx(with_bad(I3, (1,), NAN)), NonFiniteError, r"R\[1\]", id="m2euler-nan"),
    pytest.param(lambda: exp_se3(with_bad(np.zeros(6), (1, 0), NAN)), NonFiniteError, r"twist\[1, 0\] = .* is not finite", id="exp_se3-nan"),
    pytest.param(lambda: log_se3(with_bad(rigid(t=(0, 0, 0)), (2,), rigid(t=(0, NAN, 0)))), NonFiniteError, r"T\[2\]", id="log_se3-nan-t"),
    pytest.param(lambda: make_transform(I3, [0.0, NAN, 0.0]), NonFiniteError, r"t = .* is not finite", id="make_transform-t-nan"),
    pytest.param(lambda: transform_points(I4, with_bad([1.0, 2.0, 3.0], (0,), NAN)), NonFiniteError, r"points\[0\] = \[.*\] is not finite", id="transform_points-nan"),
    pytest.param(lambda: transform_points(rigid(t=(INF, 0, 0)), [1.0, 2.0, 3.0]), NonFiniteError, r"T = .* is not finite", id="transform_points-T-inf"),
    pytest.param(lambda: invert_transform(with_bad(I4, (3,), np.full((4, 4), NAN))), NonFiniteError, r"T\[3\]", id="invert-nan"),
    pytest.param(lambda: nearest_rotation(with_bad(I3, (1,), NAN)), NonFiniteError, r"M\[1\]", id="nearest-nan"),
    pytest.param(lambda: se2_matrix(NAN, 0.0, 0.0), NonFiniteError, r"x = nan is not finite", id="se2_matrix-nan"),
    pytest.param(lambda: se2_matrix(0.0, 0.0, [0.0, 0.0, INF]), NonFiniteError, r"theta\[2\]", id="se2_matrix-theta-inf"),
    pytest.param(lambda: SE2([[0.0, 0.0, 0.0], [NAN, 0.0, 0.0]]), NonFiniteError, r"xytheta\[1\]", id="SE2-nan"),
    pytest.param(lambda: SE2.identity(3).apply(with_bad([1.0, 2.0], (1,), INF)[:3]), NonFiniteError, r"points\[1\]", id="SE2.apply-inf"),
    pytest.param(lambda: SO2.from_angle([0.0, NAN]), NonFiniteError, r"theta\[1\] = nan is not finite", id="SO2-nan"),
    pytest.param(lambda: SO3.from_matrix(with_bad(I3, (2,), NAN)), NonFiniteError, r"matrix\[2\]", id="SO3-nan"),
    pytest.param(lambda: SE3.from_matrix(with_bad(I4, (1,), rigid(t=(0, 0, INF)))), NonFiniteError, r"matrix\[1\]", id="SE3-inf"),
    pytest.param(lambda: SE3.identity().apply([[0.0, 0.0, 0.0], [0.0, NAN, 0.0]]), NonFiniteError, r"points\[1\]", id="SE3.apply-nan"),
    # ---- quaternions that are not unit / zero
    pytest.param(lambda: quat_to_matrix([[1.0, 0, 0, 0], [2.0, 0, 0, 0]]), NotUnitQuaternionError, r"q\[1\] = .* has norm 2\b.*quat_normalize", id="quat_to_matrix-norm2"),
    pytest.param(lambda: quat_rotate([0.5, 0, 0, 0], [1.0, 0, 0]), NotUnitQuaternionError, r"q = .* has norm 0\.5.*quat_normalize", id="quat_rotate-norm"),
    pytest.param(lambda: quat_to_axis_angle([1.0, 1.0, 0, 0]), NotUnitQuaternionError, r"norm 1\.414", id="quat_to_axis_angle-norm"),
    pytest.param(lambda: quat_slerp(Q1, [0.0, 3.0, 0, 0], 0.5), NotUnitQuaternionError, r"q1 = .* has norm 3", id="slerp-q1-norm"),
    pytest.param(lambda: quat_to_matrix([1.0 + 6e-7, 0, 0, 0]), NotUnitQuaternionError, r"quat_normalize", id="quat_to_matrix-just-outside-tol"),
    pytest.param(lambda: SO3.from_quat([2.0, 0, 0, 0]), NotUnitQuaternionError, r"norm 2", id="SO3.from_quat-norm"),
    pytest.param(lambda: SE3.from_quat([0.0, 0, 0, 2.0], [0, 0, 0]), NotUnitQuaternionError, r"norm 2", id="SE3.from_quat-norm"),
    pytest.param(lambda: quat_normalize([[1.0, 0, 0, 0], [0, 0, 0, 0]]), NotUnitQuaternionError, r"q\[1\] is the zero quaternion", id="quat_normalize-zero"),
    pytest.param(lambda: quat_inverse([0.0, 0, 0, 0]), NotUnitQuaternionError, r"zero quaternion", id="quat_inverse-zero"),
    pytest.param(lambda: quat_to_matrix([0.0, 0, 0, 0]), NotUnitQuaternionError, r"zero quaternion", id="quat_to_matrix-zero"),
    # ---- matrices that are not rotations
    pytest.param(lambda: matrix_to_quat(REFLECT), NotARotationError, r"R has determinant -1\b.*reflection", id="matrix_to_quat-reflection"),
    pytest.param(lambda: matrix_to_quat(with_bad(I3, (1, 0), REFLECT)), NotARotationError, r"R\[1, 0\] has determinant -1", id="matrix_to_quat-reflection-2d"),
    pytest.param(lambda: matrix_to_quat(np.zeros((3, 3))), NotARotationError, r"determinant 0", id="matrix_to_quat-singular"),
    pytest.param(lambda: log_so3(SCALED), NotARotationError, r"R is not orthonormal.*nearest_rotation", id="log_so3-scaled"),
    pytest.param(lambda: matrix_to_axis_angle(with_bad(I3, (2,), SCALED)), NotARotationError, r"R\[2\] is not orthonormal", id="axis_angle-scaled"),
    pytest.param(lambda: matrix_to_euler_zyx(REFLECT), NotARotationError, r"determinant", id="m2euler-reflection"),
    pytest.param(lambda: matrix_to_quat((1 + 1e-6) * np.eye(3)), NotARotationError, r"not orthonormal", id="just-outside-tol"),
    pytest.param(lambda: make_transform(REFLECT, [0, 0, 0]), NotARotationError, r"R has determinant", id="make_transform-reflection"),
    pytest.param(lambda: SO3.from_matrix(REFLECT), NotARotationError, r"matrix has determinant", id="SO3-reflection"),
    pytest.param(lambda: SO3.from_matrix(SCALED), NotARotationError, r"project", id="SO3-scaled"),
    pytest.param(lambda: so2_angle(np.diag([1.0, -1.0])), NotARotationError, r"R ", id="so2_angle-reflection"),
    pytest.param(lambda: SO2.from_matrix(2 * np.eye(2)), NotARotationError, r"not orthonormal", id="SO2-scaled"),
    # ---- transforms that are not rigid
    pytest.param(lambda: invert_transform(rigid(last_row=(0, 0, 0, 2.0))), NotARotationError, r"T has last row \[0\.0, 0\.0, 0\.0, 2\.0\]", id="invert-last-row"),
    pytest.param(lambda: log_se3(with_bad(I4, (1,), rigid(last_row=(0, 0, 1.0, 1.0)))), NotARotationError, r"T\[1\] has last row", id="log_se3-last-row"),
    pytest.param(lambda: transform_points(rigid(last_row=(0.5, 0, 0, 1.0)), [1.0, 2, 3]), NotARotationError, r"last row", id="transform_points-last-row"),
    pytest.param(lambda: SE3.from_matrix(rigid(last_row=(0, 0, 0, 0.0))), NotARotationError, r"matrix has last row", id="SE3-last-row"),
    pytest.param(lambda: invert_transform(rigid(R=REFLECT)), NotARotationError, r"determinant -1", id="invert-reflection-block"),
    pytest.param(lambda: log_se3(rigid(R=SCALED)), NotARotationError, r"not orthonormal", id="log_se3-scaled-block"),
    pytest.param(lambda: SE3.from_matrix(rigid(R=SCALED)), NotARotationError, r"project", id="SE3-scaled-block"),
    pytest.param(lambda: invert_transform(np.diag([1.0, 1.0, 2.0])), NotARotationError, r"T has last row \[0\.0, 0\.0, 2\.0\]", id="invert2d-last-row"),
    pytest.param(lambda: se2_from_matrix(np.array([[1.0, 0, 0], [0, 1, 0], [1, 0, 1]])), NotARotationError, r"last row", id="se2_from_matrix-last-row"),
    pytest.param(lambda: transform_points(np.diag([1.0, -1.0, 1.0]), [1.0, 2.0]), NotARotationError, r"T ", id="transform_points2d-reflection"),
    pytest.param(lambda: SE2.from_matrix(np.diag([2.0, 2.0, 1.0])), NotARotationError, r"not orthonormal", id="SE2-scaled"),
    # ---- zero axis
    pytest.param(lambda: axis_angle_to_quat([0.0, 0.0, 0.0], 1.0), InvalidArgumentError, r"axis is the zero vector", id="axis_angle-zero"),
    pytest.param(lambda: axis_angle_to_quat([[1.0, 0, 0], [0, 0, 0]], 1.0), InvalidArgumentError, r"axis\[1\] is the zero vector", id="axis_angle-zero-batch"),
    pytest.param(lambda: axis_angle_to_matrix([0, 0, 0], 0.5), InvalidArgumentError, r"zero vector", id="axis_angle_to_matrix-zero"),
    pytest.param(lambda: SO3.from_axis_angle([0.0, 0.0, 0.0], 0.0), InvalidArgumentError, r"zero vector", id="SO3.from_axis_angle-zero"),
]


@pytest.mark.parametrize("call, exc, pattern", CASES)
def test_bad_input_raises(call, exc, pattern):
    with pytest.raises(exc) as info:
        call()
    err = info.value
    assert isinstance(err, OccmapError), type(err).__mro__
    assert isinstance(err, ValueError), type(err).__mro__
    assert re.search(pattern, str(err), re.DOTALL), f"message {str(err)!r} does not match {pattern!r}"


def test_error_hierarchy():
    for cls in (ShapeError, NonFiniteError, NotARotationError, NotUnitQuaternionError, InvalidArgumentError):
        assert issubclass(cls, OccmapError) and issubclass(cls, ValueError)
    with pytest.raises(ValueError):  # NumPy / scipy habits keep working
        quat_to_matrix([2.0, 0, 0, 0])
    with pytest.raises(OccmapError):
        exp_so3([NAN, 0, 0])


def test_tolerances_accept_float32_round_off():
    """Within |‖q‖² − 1| ≤ 1e-6 a quaternion is accepted, and the matrix is still orthonormal
    (quat_to_matrix scales by 2/‖q‖²); within ‖RᵀR − I‖ ≤ 1e-6 a matrix is accepted."""
    q = np.array([1.0, 2.0, 3.0, 4.0], dtype=np.float32)
    q = (q / np.linalg.norm(q)).astype(np.float32) * np.float32(1 + 3e-7)
    R = quat_to_matrix(q)
    np.testing.assert_allclose(R @ R.T, np.eye(3), rtol=0, atol=1e-15)
    assert matrix_to_quat((1 + 1e-7) * np.eye(3)).shape == (4,)
    assert SO3.from_matrix((1 + 1e-7) * np.eye(3)).shape == ()


def test_errors_not_nan_for_zero_quaternions():
    for f in (quat_normalize, quat_inverse, quat_to_matrix, quat_to_axis_angle):
        with pytest.raises(NotUnitQuaternionError):
            f(np.zeros(4))


def test_compose_transforms_does_not_validate():
    """Documented: compose_transforms trusts its input (reads only the top three rows)."""
    out = compose_transforms(rigid(last_row=(1.0, 2.0, 3.0, 4.0)), I4)
    np.testing.assert_array_equal(out[3], [0, 0, 0, 1])


def test_quat_from_xyzw_shape_error():
    with pytest.raises(ShapeError, match=r"\(3,\)"):
        quat_from_xyzw([1.0, 2.0, 3.0])


@pytest.mark.parametrize("cls, point", [(SO3, [0.0, NAN, 0.0]), (SO2, [INF, 0.0])], ids=["SO3", "SO2"])
def test_rotation_apply_rejects_non_finite(cls, point):
    """Regression (found by this suite, fixed in 17003c6): SO3.apply / SO2.apply let NaN/inf
    through silently while SE3.apply / SE2.apply raised."""
    with pytest.raises(NonFiniteError, match=r"points"):
        cls.identity().apply(point)
    with pytest.raises(NonFiniteError, match=r"points\[2\]"):
        cls.identity(4).apply(np.r_[np.zeros((2, len(point))), [point], np.zeros((1, len(point)))])


@pytest.mark.parametrize("scale", [1e-170, 1e200, 5e-324, 1.7e308])
def test_quat_normalize_extreme_scales(scale):
    """Regression (found by this suite, fixed in 17003c6): ‖q‖² under/overflowed, and finite
    non-zero quaternions were rejected with 'element  of q was rejected'."""
    np.testing.assert_allclose(quat_normalize([scale, 0.0, 0.0, 0.0]), [1.0, 0.0, 0.0, 0.0])
