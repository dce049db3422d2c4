"""Tests of occmap.geometry.motion: closed forms, limits, composition, the odometry model's
round trip and noise statistics, broadcasting, and the rejection of bad input."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from occmap.errors import InvalidArgumentError, NonFiniteError, ShapeError
from occmap.geometry.motion import (
    OdometryMotionModel,
    apply_odometry,
    bicycle_step,
    diff_drive_step,
    odometry_delta,
    unicycle_step,
)


def angle_diff(a, b):
    return np.arctan2(np.sin(np.subtract(a, b)), np.cos(np.subtract(a, b)))


def assert_poses_close(actual, expected, atol):
    actual, expected = np.asarray(actual), np.asarray(expected)
    assert actual.shape == expected.shape
    np.testing.assert_allclose(actual[..., :2], expected[..., :2], rtol=0, atol=atol)
    np.testing.assert_allclose(angle_diff(actual[..., 2], expected[..., 2]), 0.0, rtol=0, atol=atol)


def arc_reference(poses, v, omega, dt):
    """The textbook arc formula (divides by omega; accurate when omega·dt is not small)."""
    x, y, th = np.moveaxis(np.asarray(poses, dtype=float), -1, 0)
    r = v / omega
    th1 = th + omega * dt
    return np.stack([x + r * (np.sin(th1) - np.sin(th)), y - r * (np.cos(th1) - np.cos(th)), th1], -1)


def relative_pose(a, b):
    """b expressed in the frame of a (a⁻¹ ⊕ b)."""
    dx, dy = b[..., 0] - a[..., 0], b[..., 1] - a[..., 1]
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    return np.stack([c * dx + s * dy, -s * dx + c * dy, b[..., 2] - a[..., 2]], -1)


def compose(a, rel):
    """a ⊕ rel."""
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    return np.stack(
        [a[..., 0] + c * rel[..., 0] - s * rel[..., 1], a[..., 1] + s * rel[..., 0] + c * rel[..., 1],
         a[..., 2] + rel[..., 2]], -1
    )


def random_poses(rng, n):
    return np.column_stack([rng.uniform(-10, 10, (n, 2)), rng.uniform(-np.pi, np.pi, n)])


# --- unicycle --------------------------------------------------------------------------------------


def test_quarter_circle_from_origin():
    out = unicycle_step([0.0, 0.0, 0.0], 1.0, np.pi / 2, 1.0)
    np.testing.assert_allclose(out, [2 / np.pi, 2 / np.pi, np.pi / 2], rtol=0, atol=1e-15)


def test_half_and_full_circle():
    half = unicycle_step([1.0, 2.0, 0.0], 1.0, 1.0, np.pi)
    assert_poses_close(half, [1.0, 4.0, np.pi], 1e-14)
    full = unicycle_step([1.0, 2.0, 0.5], 3.0, -2.0, np.pi)
    assert_poses_close(full, [1.0, 2.0, 0.5], 1e-14)


def test_matches_textbook_arc_formula():
    rng = np.random.default_rng(1)
    poses = random_poses(rng, 500)
    v = rng.uniform(-3, 3, 500)
    omega = rng.choice([-1, 1], 500) * rng.uniform(0.2, 4, 500)
    dt = rng.uniform(0.1, 2, 500)
    assert_poses_close(unicycle_step(poses, v, omega, dt), arc_reference(poses, v, omega, dt), 1e-12)


def test_headings_are_wrapped_and_any_input_heading_accepted():
    out = unicycle_step([0.0, 0.0, 20.0], 0.0, 3.0, 7.0)
    assert -np.pi <= out[2] <= np.pi
    assert angle_diff(out[2], 41.0) == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("omega", [1e-12, -1e-12, 1e-8, 0.0, -0.0])
def test_small_omega_limit(omega):
    pose = np.array([0.3, -1.2, 0.7])
    v, dt = 1.7, 0.9
    out = unicycle_step(pose, v, omega, dt)
    d, h = v * dt, omega * dt / 2
    # exact to second order in h (the next term is d·h⁴/120 < 1e-30 here)
    chord = d * (1 - h * h / 6)
    expected = [pose[0] + chord * np.cos(pose[2] + h), pose[1] + chord * np.sin(pose[2] + h), pose[2] + 2 * h]
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-15)
    straight = [pose[0] + d * np.cos(pose[2]), pose[1] + d * np.sin(pose[2]), pose[2]]
    np.testing.assert_allclose(out, straight, rtol=0, atol=1e-12 if abs(omega) <= 1e-12 else 1e-7)


def test_continuous_in_omega_including_zero_and_series_switch():
    pose = np.array([0.0, 0.0, 0.4])
    omegas = np.concatenate([-np.logspace(-15, -1, 400)[::-1], [0.0], np.logspace(-15, -1, 400)])
    out = unicycle_step(pose, 2.0, omegas, 1.0)
    # |∂pose/∂omega| ≤ v·dt² here, so neighbouring omegas give neighbouring poses
    jumps = np.abs(np.diff(out, axis=0)).max(axis=1)
    assert np.all(jumps <= 2.0 * np.abs(np.diff(omegas)) + 1e-15)
    # both sides of the series threshold (|omega·dt/2| = 1e-2) agree with the textbook formula there
    near = 2e-2 * (1 + np.linspace(-1e-3, 1e-3, 101))
    assert_poses_close(unicycle_step(pose, 2.0, near, 1.0), arc_reference(pose, 2.0, near, 1.0), 1e-13)


def test_many_small_steps_equal_one_big_step():
    rng = np.random.default_rng(2)
    poses = random_poses(rng, 64)
    v = rng.uniform(-2, 2, 64)
    omega = rng.uniform(-3, 3, 64)
    omega[:8] = 0.0
    omega[8:16] = 1e-10
    big = unicycle_step(poses, v, omega, 2.0)
    small = poses
    for _ in range(1000):
        small = unicycle_step(small, v, omega, 2e-3)
    assert_poses_close(small, big, 1e-11)


def test_zero_dt_and_zero_velocity():
    pose = np.array([1.0, 2.0, 0.3])
    np.testing.assert_array_equal(unicycle_step(pose, 5.0, 2.0, 0.0), pose)
    np.testing.assert_allclose(unicycle_step(pose, 0.0, 2.0, 0.5), [1.0, 2.0, 1.3], atol=1e-15)


def test_reverse_undoes_forward():
    rng = np.random.default_rng(3)
    poses = random_poses(rng, 100)
    v, omega = rng.uniform(-2, 2, 100), rng.uniform(-2, 2, 100)
    there = unicycle_step(poses, v, omega, 1.3)
    assert_poses_close(unicycle_step(there, -v, -omega, 1.3), poses, 1e-12)


# --- differential drive ----------------------------------------------------------------------------


def test_diff_drive_equal_speeds_is_straight():
    out = diff_drive_step([1.0, 1.0, np.pi / 4], 0.5, 0.5, 0.3, 2.0)
    np.testing.assert_allclose(out, [1 + np.sqrt(0.5), 1 + np.sqrt(0.5), np.pi / 4], atol=1e-15)


def test_diff_drive_opposite_speeds_turn_in_place():
    out = diff_drive_step([1.0, -2.0, 0.0], -0.25, 0.25, 0.5, 1.0)
    np.testing.assert_allclose(out, [1.0, -2.0, 1.0], atol=1e-15)


def test_diff_drive_matches_unicycle():
    rng = np.random.default_rng(4)
    poses = random_poses(rng, 50)
    vl, vr, b = rng.uniform(-1, 1, 50), rng.uniform(-1, 1, 50), rng.uniform(0.1, 1, 50)
    expected = unicycle_step(poses, (vl + vr) / 2, (vr - vl) / b, 0.7)
    np.testing.assert_allclose(diff_drive_step(poses, vl, vr, b, 0.7), expected, rtol=0, atol=1e-15)


def test_diff_drive_wheels_trace_concentric_arcs():
    # the right wheel, faster, lies on the outer circle: radius (R + b/2) around the centre
    b, vl, vr = 0.4, 0.3, 0.5
    radius = b / 2 * (vr + vl) / (vr - vl)
    out = diff_drive_step(np.zeros(3), vl, vr, b, np.linspace(0, 10, 20))
    np.testing.assert_allclose(np.hypot(out[:, 0], out[:, 1] - radius), radius, atol=1e-14)


# --- bicycle ---------------------------------------------------------------------------------------


def test_bicycle_yaw_rate_is_v_tan_delta_over_l():
    delta = np.array([-0.5, -0.1, 0.0, 0.2, 1.2])
    out = bicycle_step(np.zeros(3), 2.0, delta, 2.5, 0.3)
    np.testing.assert_allclose(out[:, 2], 2.0 * np.tan(delta) / 2.5 * 0.3, rtol=0, atol=1e-15)
    np.testing.assert_allclose(out, unicycle_step(np.zeros(3), 2.0, 2.0 * np.tan(delta) / 2.5, 0.3), atol=1e-15)


def test_bicycle_turning_radius():
    length, delta = 2.7, 0.35
    radius = length / np.tan(delta)
    start = np.array([3.0, -1.0, 0.6])
    centre = start[:2] + radius * np.array([-np.sin(start[2]), np.cos(start[2])])
    out = bicycle_step(start, 1.5, delta, length, np.linspace(0, 20, 50))
    np.testing.assert_allclose(np.hypot(*(out[:, :2] - centre).T), radius, rtol=0, atol=1e-13)
    # steering right puts the centre on the right
    out = bicycle_step(start, 1.5, -delta, length, np.linspace(0, 20, 50))
    centre = start[:2] - radius * np.array([-np.sin(start[2]), np.cos(start[2])])
    np.testing.assert_allclose(np.hypot(*(out[:, :2] - centre).T), radius, rtol=0, atol=1e-13)


def test_bicycle_has_no_lateral_velocity():
    # Along a trajectory, the displacement over a tiny step is along the heading: its sideways part
    # is second order in dt (v²·tan(delta)/L·dt²/2), so sideways / dt → 0.
    rng = np.random.default_rng(5)
    poses = random_poses(rng, 200)
    v, delta = rng.uniform(-3, 3, 200), rng.uniform(-1.3, 1.3, 200)
    traj = bicycle_step(poses, v, delta, 2.0, 1.7)
    for dt in (1e-3, 1e-6):
        step = bicycle_step(traj, v, delta, 2.0, dt) - traj
        c, s = np.cos(traj[:, 2]), np.sin(traj[:, 2])
        forward = c * step[:, 0] + s * step[:, 1]
        lateral = -s * step[:, 0] + c * step[:, 1]
        omega = v * np.tan(delta) / 2.0
        np.testing.assert_allclose(forward, v * dt, rtol=1e-5, atol=1e-14)
        np.testing.assert_allclose(lateral, v * omega * dt**2 / 2, rtol=1e-5, atol=1e-14)
        assert np.all(np.abs(lateral) <= np.abs(v * omega) * dt**2 + 1e-14)


def test_bicycle_straight_and_max_steering():
    np.testing.assert_allclose(bicycle_step([0, 0, 0], 2.0, 0.0, 3.0, 1.5), [3.0, 0, 0], atol=1e-15)
    clipped = bicycle_step(np.zeros(3), 1.0, [1.0, -1.0, 0.2], 2.0, 1.0, max_steering=0.5)
    np.testing.assert_array_equal(clipped, bicycle_step(np.zeros(3), 1.0, [0.5, -0.5, 0.2], 2.0, 1.0))


# --- odometry model --------------------------------------------------------------------------------

pose_st = st.tuples(
    st.floats(-50, 50), st.floats(-50, 50), st.floats(-10, 10)
).map(np.array)


@settings(max_examples=200, deadline=None)
@given(pose_st, pose_st, pose_st)
def test_odometry_round_trip(prev, curr, particle):
    delta = odometry_delta(prev, curr, min_trans=0.0)
    assert_poses_close(apply_odometry(prev, delta), curr, 1e-9)
    # the same delta moves any other pose by the same motion in its own frame
    assert_poses_close(apply_odometry(particle, delta), compose(particle, relative_pose(prev, curr)), 1e-9)
    # with AMCL's threshold the round trip is exact above 1 cm, and off by at most 2·trans below
    rot1, trans, rot2 = odometry_delta(prev, curr)
    out = apply_odometry(prev, (rot1, trans, rot2))
    assert angle_diff(out[2], curr[2]) == pytest.approx(0.0, abs=1e-9)
    if trans >= 0.01:
        assert_poses_close(out, curr, 1e-9)
    else:
        assert rot1 == 0.0
        assert np.hypot(*(out[:2] - curr[:2])) <= 2 * trans + 1e-12


def test_odometry_delta_values():
    rot1, trans, rot2 = odometry_delta([1.0, 1.0, np.pi / 2], [1.0, 3.0, 0.0])
    assert (rot1, trans, rot2) == pytest.approx((0.0, 2.0, -np.pi / 2), abs=1e-15)
    rot1, trans, rot2 = odometry_delta([0.0, 0.0, 0.0], [-1.0, 0.0, 0.0])  # straight backwards
    assert abs(rot1) == pytest.approx(np.pi) and trans == 1.0 and abs(rot2) == pytest.approx(np.pi)
    # turning in place with 5 mm of jitter: the bearing of the jitter is ignored
    rot1, trans, rot2 = odometry_delta([0.0, 0.0, 0.0], [0.0, -0.005, 1.0])
    assert (rot1, trans, rot2) == pytest.approx((0.0, 0.005, 1.0), abs=1e-15)
    rot1, _, rot2 = odometry_delta([0.0, 0.0, 0.0], [0.0, -0.005, 1.0], min_trans=0.0)
    assert (rot1, rot2) == pytest.approx((-np.pi / 2, 1.0 + np.pi / 2))


def test_odometry_delta_broadcasts():
    rng = np.random.default_rng(6)
    prev, curr = random_poses(rng, 7), random_poses(rng, 7)
    rot1, trans, rot2 = odometry_delta(prev, curr)
    assert rot1.shape == trans.shape == rot2.shape == (7,)
    one = odometry_delta(prev[3], curr)
    assert one[0].shape == (7,)
    np.testing.assert_allclose(one[1], np.hypot(*(curr[:, :2] - prev[3, :2]).T))
    grid = odometry_delta(prev[:, None], curr[None, :4])
    assert grid[2].shape == (7, 4)
    np.testing.assert_allclose(grid[2][3, 1], odometry_delta(prev[3], curr[1])[2])


def _drawn_components(out, rot1, rot2):
    """Recover the sampled (rot1, trans, rot2) from poses moved from the origin, unwrapped near the
    nominal values so that draws across ±pi do not jump by 2 pi."""
    drawn_rot1 = rot1 + angle_diff(np.arctan2(out[:, 1], out[:, 0]), rot1)
    drawn_trans = np.hypot(out[:, 0], out[:, 1])
    drawn_rot2 = rot2 + angle_diff(out[:, 2] - drawn_rot1, rot2)
    return drawn_rot1, drawn_trans, drawn_rot2


@pytest.mark.parametrize("rot1,trans,rot2", [(0.3, 1.0, -0.2), (np.pi - 0.1, 0.8, np.pi - 0.25)])
def test_noise_matches_table_5_6(rot1, trans, rot2):
    a1, a2, a3, a4 = 0.05, 0.01, 0.02, 0.01
    n = 200_000
    out = apply_odometry(np.zeros((n, 3)), (rot1, trans, rot2), (a1, a2, a3, a4), rng=7)
    r1, t, r2 = _drawn_components(out, rot1, rot2)
    # AMCL's symmetric rotation terms: driving backwards (rot ≈ pi) costs like driving forwards
    n1, n2 = min(abs(rot1), np.pi - abs(rot1)), min(abs(rot2), np.pi - abs(rot2))
    stds = [np.sqrt(a1 * n1**2 + a2 * trans**2), np.sqrt(a3 * trans**2 + a4 * (n1**2 + n2**2)),
            np.sqrt(a1 * n2**2 + a2 * trans**2)]
    for drawn, mean, std in zip((r1, t, r2), (rot1, trans, rot2), stds):
        assert abs(drawn.mean() - mean) < 4 * std / np.sqrt(n)
        assert drawn.std() == pytest.approx(std, rel=0.01)
    # independent draws per pose and per component
    corr = np.corrcoef([r1, t, r2])
    np.testing.assert_allclose(corr[np.triu_indices(3, 1)], 0.0, atol=0.01)


def test_noise_seeding_and_zero_alphas():
    poses = np.zeros((5, 3))
    delta = (0.2, 1.0, 0.1)
    a = apply_odometry(poses, delta, (0.1, 0.1, 0.1, 0.1), rng=42)
    b = apply_odometry(poses, delta, (0.1, 0.1, 0.1, 0.1), rng=np.random.default_rng(42))
    np.testing.assert_array_equal(a, b)
    assert len(np.unique(a[:, 0])) == 5
    np.testing.assert_array_equal(apply_odometry(poses, delta, (0, 0, 0, 0), rng=1), apply_odometry(poses, delta))


def test_apply_odometry_broadcasts_per_pose_deltas():
    rng = np.random.default_rng(8)
    prev, curr = random_poses(rng, 10), random_poses(rng, 10)
    delta = odometry_delta(prev, curr)
    assert_poses_close(apply_odometry(prev, delta), curr, 1e-12)
    out = apply_odometry(prev[:, None], delta)
    assert out.shape == (10, 10, 3)
    assert_poses_close(out[4, 6], apply_odometry(prev[4], tuple(d[6] for d in delta)), 0.0)
    noisy = apply_odometry(prev[0], delta, (0.1, 0.1, 0.1, 0.1), rng=0)
    assert noisy.shape == (10, 3)


def test_motion_model_class():
    model = OdometryMotionModel(0.1, 0.05, 0.2, 0.01)
    assert model.alphas == (0.1, 0.05, 0.2, 0.01)
    with pytest.raises(dataclasses.FrozenInstanceError):
        model.alpha1 = 0.3
    odom_prev, odom_curr = np.array([1.0, 2.0, 0.3]), np.array([1.5, 2.2, 0.5])
    particles = random_poses(np.random.default_rng(9), 2000)
    for got, want in zip(model.delta(odom_prev, odom_curr), odometry_delta(odom_prev, odom_curr)):
        np.testing.assert_array_equal(got, want)
    moved = model.sample(particles, odom_prev, odom_curr, rng=3)
    assert moved.shape == (2000, 3)
    np.testing.assert_array_equal(
        moved, apply_odometry(particles, odometry_delta(odom_prev, odom_curr), model.alphas, rng=3)
    )
    noise_free = OdometryMotionModel(0, 0, 0, 0).sample(particles, odom_prev, odom_curr, rng=3)
    assert_poses_close(noise_free, compose(particles, relative_pose(odom_prev, odom_curr)), 1e-12)
    with pytest.raises(InvalidArgumentError, match="alphas\\[3\\] = -0.1"):
        OdometryMotionModel(0.1, 0.1, 0.1, -0.1)
    with pytest.raises(NonFiniteError):
        OdometryMotionModel(np.nan, 0.1, 0.1, 0.1)
    with pytest.raises(InvalidArgumentError, match="min_trans"):
        OdometryMotionModel(min_trans=-1.0)


# --- broadcasting ----------------------------------------------------------------------------------


def test_one_control_many_poses_and_many_controls_one_pose():
    rng = np.random.default_rng(10)
    poses = random_poses(rng, 20)
    out = unicycle_step(poses, 1.2, 0.4, 0.5)
    assert out.shape == (20, 3)
    for i in (0, 7, 19):
        np.testing.assert_array_equal(out[i], unicycle_step(poses[i], 1.2, 0.4, 0.5))
    v = rng.uniform(-1, 1, 20)
    out = unicycle_step(poses[0], v, 0.4, 0.5)
    assert out.shape == (20, 3)
    np.testing.assert_array_equal(out[5], unicycle_step(poses[0], v[5], 0.4, 0.5))
    # only v varies: headings must still come out per element
    out = unicycle_step(poses[0], v, 0.0, 0.5)
    np.testing.assert_array_equal(out[:, 2], poses[0, 2])


def test_many_controls_many_poses_and_outer_product():
    rng = np.random.default_rng(11)
    poses = random_poses(rng, 6)
    v, omega, dt = rng.uniform(-1, 1, 6), rng.uniform(-1, 1, 6), rng.uniform(0, 1, 6)
    out = unicycle_step(poses, v, omega, dt)
    for i in range(6):
        np.testing.assert_array_equal(out[i], unicycle_step(poses[i], v[i], omega[i], dt[i]))
    grid = unicycle_step(poses[:, None], v[:4], omega[:4], 0.3)
    assert grid.shape == (6, 4, 3)
    np.testing.assert_array_equal(grid[2, 3], unicycle_step(poses[2], v[3], omega[3], 0.3))
    assert diff_drive_step(poses[:, None, :], v[:4], v[:4] + 0.1, 0.5, 0.3).shape == (6, 4, 3)
    assert bicycle_step(poses[:, None, :], 1.0, omega[:4], [[2.0]] * 6, 0.3).shape == (6, 4, 3)


def test_inputs_as_lists_and_integers():
    out = unicycle_step([[0, 0, 0], [1, 1, 0]], [1, 2], 0, 1)
    assert out.dtype == np.float64
    np.testing.assert_array_equal(out, [[1, 0, 0], [3, 1, 0]])


# --- bad input -------------------------------------------------------------------------------------

P = np.zeros(3)


@pytest.mark.parametrize(
    "call,error,match",
    [
        (lambda: unicycle_step([0.0, 0.0], 1, 1, 1), ShapeError, "poses"),
        (lambda: unicycle_step(np.zeros((3, 4)), 1, 1, 1), ShapeError, "poses"),
        (lambda: unicycle_step(np.zeros((3, 3)), [1, 2], 1, 1), ShapeError, "broadcast"),
        (lambda: unicycle_step([0, np.nan, 0], 1, 1, 1), NonFiniteError, "poses"),
        (lambda: unicycle_step(P, np.inf, 1, 1), NonFiniteError, "v = inf"),
        (lambda: unicycle_step(P, 1, [0, np.nan], 1), NonFiniteError, "omega\\[1\\] = nan"),
        (lambda: unicycle_step(P, 1, 1, np.nan), NonFiniteError, "dt"),
        (lambda: unicycle_step(P, 1, 1, -0.1), InvalidArgumentError, "dt = -0.1"),
        (lambda: unicycle_step(P, 1, 1, [0.1, -0.2]), InvalidArgumentError, "dt\\[1\\] = -0.2"),
        (lambda: diff_drive_step(P, 1, 1, 0.0, 1), InvalidArgumentError, "wheel_base = 0.0"),
        (lambda: diff_drive_step(P, 1, 1, -0.5, 1), InvalidArgumentError, "wheel_base = -0.5"),
        (lambda: diff_drive_step(P, np.nan, 1, 0.5, 1), NonFiniteError, "v_left"),
        (lambda: diff_drive_step(P, 1, 1, np.inf, 1), NonFiniteError, "wheel_base"),
        (lambda: diff_drive_step(P, 1, 1, 0.5, -1), InvalidArgumentError, "dt"),
        (lambda: bicycle_step(P, 1, np.pi / 2, 2, 1), InvalidArgumentError, "steering_angle"),
        (lambda: bicycle_step(P, 1, -2.0, 2, 1), InvalidArgumentError, "steering_angle = -2.0"),
        (lambda: bicycle_step(P, 1, 2.0, 2, 1, max_steering=0.5), InvalidArgumentError, "steering_angle"),
        (lambda: bicycle_step(P, 1, 0.1, 2, 1, max_steering=np.pi / 2), InvalidArgumentError, "max_steering"),
        (lambda: bicycle_step(P, 1, 0.1, 2, 1, max_steering=-0.1), InvalidArgumentError, "max_steering"),
        (lambda: bicycle_step(P, 1, 0.1, 0.0, 1), InvalidArgumentError, "wheelbase = 0.0"),
        (lambda: bicycle_step(P, 1, np.nan, 2, 1), NonFiniteError, "steering_angle"),
        (lambda: bicycle_step(P, 1, 0.1, 2, -1), InvalidArgumentError, "dt"),
        (lambda: odometry_delta(P, [0, 0]), ShapeError, "pose_curr"),
        (lambda: odometry_delta(np.zeros((2, 3)), np.zeros((3, 3))), ShapeError, "broadcast"),
        (lambda: odometry_delta([np.inf, 0, 0], P), NonFiniteError, "pose_prev"),
        (lambda: odometry_delta(P, P, min_trans=-0.01), InvalidArgumentError, "min_trans"),
        (lambda: apply_odometry(P, (0.1, 1.0)), ShapeError, "delta"),
        (lambda: apply_odometry(P, 1.0), ShapeError, "delta"),
        (lambda: apply_odometry(P, (0.1, np.nan, 0.0)), NonFiniteError, "delta.trans"),
        (lambda: apply_odometry(np.zeros((4, 3)), ([1, 2], 1, 0)), ShapeError, "broadcast"),
        (lambda: apply_odometry([0, 0, np.nan], (0, 1, 0)), NonFiniteError, "poses"),
        (lambda: apply_odometry(P, (0, 1, 0), (0.1, 0.1, 0.1)), ShapeError, "alphas"),
        (lambda: apply_odometry(P, (0, 1, 0), (0.1, -0.1, 0.1, 0.1)), InvalidArgumentError, "alphas\\[1\\] = -0.1"),
        (lambda: apply_odometry(P, (0, 1, 0), (0.1, np.inf, 0.1, 0.1)), NonFiniteError, "alphas"),
    ],
)
def test_bad_input_raises(call, error, match):
    with pytest.raises(error, match=match):
        call()


def test_value_errors_are_occmap_errors():
    with pytest.raises(ValueError):
        unicycle_step([0.0, 0.0], 1, 1, 1)
    with pytest.raises(ValueError):
        unicycle_step(P, np.nan, 1, 1)


def test_covariance_matches_the_sampled_spread():
    """The extended Kalman filter's prediction of the odometry model's covariance against the spread
    of 40,000 poses moved by :func:`apply_odometry` with the same noise, over a drive of 20 steps
    that turns (covariance from the heading's uncertainty bending the position's, not only the
    sum of the steps' own noise) and a step driven in reverse (charged as forward, not as a
    half-turn); small noise, so the linearization holds. A covariance that ignored the pose
    Jacobian, or charged the reversal π of rotation, would be several times off."""
    model = OdometryMotionModel(0.002, 0.001, 0.003, 0.001)
    rng = np.random.default_rng(5)
    steps = [(0.05, 0.3, 0.04)] * 19 + [(np.pi - 0.02, 0.2, np.pi + 0.01)]
    pose = np.array([1.0, -2.0, 0.4])
    cov = np.diag([1e-4, 4e-4, 1e-4])
    samples = pose + rng.standard_normal((40_000, 3)) @ np.linalg.cholesky(cov).T
    for delta in steps:
        cov = model.covariance(pose, cov, delta)
        pose = apply_odometry(pose, delta)
        samples = apply_odometry(samples, delta, model.alphas, rng)
    res = samples - pose
    res[:, 2] = np.angle(np.exp(1j * res[:, 2]))
    sampled = np.cov(res.T)
    np.testing.assert_allclose(np.sqrt(np.diag(cov)), np.sqrt(np.diag(sampled)), rtol=0.05)
    corr = cov[0, 1] / np.sqrt(cov[0, 0] * cov[1, 1])
    assert abs(corr - sampled[0, 1] / np.sqrt(sampled[0, 0] * sampled[1, 1])) < 0.05
    assert np.sqrt(cov[0, 0]) > 3 * np.sqrt(1e-4)  # the drive grew it well beyond the start's
