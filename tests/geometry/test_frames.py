"""FrameTree: tf2 semantics checked against matrix products and scipy's Rotation / Slerp."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation, Slerp

from occmap.errors import (
    ConnectivityError,
    ExtrapolationError,
    FrameLoopError,
    NonFiniteError,
    NotARotationError,
    OccmapError,
    ShapeError,
    InvalidArgumentError,
    TransformError,
    UnknownFrameError,
)
from occmap.geometry.frames import FrameTree
from occmap.geometry.se3 import SE3


def pose(rotation: Rotation | None = None, translation=(0.0, 0.0, 0.0)) -> np.ndarray:
    """A (4, 4) rigid transform (or a batch) from a scipy rotation and a translation."""
    rotation = Rotation.identity() if rotation is None else rotation
    R = rotation.as_matrix()
    T = np.zeros(R.shape[:-2] + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = translation
    T[..., 3, 3] = 1.0
    return T


def yaw(deg: float, translation=(0.0, 0.0, 0.0)) -> np.ndarray:
    return pose(Rotation.from_euler("z", deg, degrees=True), translation)


def random_pose(rng: np.random.Generator, n: int | None = None) -> np.ndarray:
    size = () if n is None else (n,)
    return pose(Rotation.random(n, random_state=rng), rng.normal(size=size + (3,)))


@pytest.fixture
def robot() -> tuple[FrameTree, dict[str, np.ndarray]]:
    """map -> odom (static), odom -> base_link (dynamic, t = 0..4), base_link -> laser / camera."""
    rng = np.random.default_rng(7)
    tree = FrameTree()
    T = {
        "odom": random_pose(rng),
        "base_link": random_pose(rng, 5),
        "laser": random_pose(rng),
        "camera": random_pose(rng),
    }
    tree.set_transform("map", "odom", T["odom"], static=True)
    tree.set_transform("odom", "base_link", T["base_link"], np.arange(5.0))
    tree.set_transform("base_link", "laser", T["laser"], static=True)
    tree.set_transform("base_link", "camera", SE3.from_matrix(T["camera"]), static=True)
    return tree, T


# ---------------------------------------------------------------------------- composition


def test_chain_equals_matrix_product(robot):
    tree, T = robot
    for k in range(5):
        expected = T["odom"] @ T["base_link"][k] @ T["laser"]
        np.testing.assert_allclose(tree.lookup("map", "laser", float(k)).matrix, expected, atol=1e-12)
        np.testing.assert_allclose(tree.lookup("laser", "map", float(k)).matrix, np.linalg.inv(expected), atol=1e-12)


def test_lookup_maps_source_coordinates_into_target(robot):
    tree, T = robot
    p_laser = np.array([[1.0, 2.0, 3.0], [-4.0, 0.5, 0.0]])
    expected = (T["odom"] @ T["base_link"][2] @ T["laser"] @ np.c_[p_laser, np.ones(2)].T).T[:, :3]
    np.testing.assert_allclose(tree.transform_points("map", "laser", p_laser, 2.0), expected, atol=1e-12)


def test_siblings_go_through_common_parent_only(robot):
    tree, T = robot
    expected = np.linalg.inv(T["camera"]) @ T["laser"]
    # The path camera <- base_link -> laser is all static, so any time works, even far outside
    # the odom -> base_link samples.
    for stamp in (None, -1e6, 2.5, 1e6):
        np.testing.assert_allclose(tree.lookup("camera", "laser", stamp).matrix, expected, atol=1e-12)


def test_lookup_is_inverse_of_reverse_lookup(robot):
    tree, _ = robot
    frames = tree.frames
    for a in frames:
        for b in frames:
            ab = tree.lookup(a, b, 1.3).matrix
            ba_inv = tree.lookup(b, a, 1.3).inv().matrix
            np.testing.assert_allclose(ab, ba_inv, atol=1e-12)


def test_same_frame_is_identity(robot):
    tree, _ = robot
    np.testing.assert_array_equal(tree.lookup("laser", "laser").matrix, np.eye(4))
    assert tree.lookup("base_link", "base_link", np.zeros(3)).matrix.shape == (3, 4, 4)


# ---------------------------------------------------------------------------- interpolation


def test_midpoint_interpolation_by_hand():
    tree = FrameTree()
    tree.set_transform("odom", "base_link", np.stack([yaw(0.0), yaw(90.0, (2.0, 4.0, -1.0))]), [10.0, 12.0])
    T = tree.lookup("odom", "base_link", 11.0).matrix
    c = s = np.sqrt(0.5)  # yaw 45°
    np.testing.assert_allclose(T[:3, :3], [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]], atol=1e-12)
    np.testing.assert_allclose(T[:3, 3], [1.0, 2.0, -0.5], atol=1e-12)
    # A quarter of the way: yaw 22.5°, translation a quarter of the way.
    T = tree.lookup("odom", "base_link", 10.5).matrix
    np.testing.assert_allclose(T, yaw(22.5, (0.5, 1.0, -0.25)), atol=1e-12)


def test_interpolation_takes_the_short_way_across_180_degrees():
    tree = FrameTree()
    tree.set_transform("a", "b", np.stack([yaw(179.0), yaw(-179.0)]), [0.0, 1.0])
    # The long way would pass through yaw 0 at t = 0.5.
    np.testing.assert_allclose(tree.lookup("a", "b", 0.5).matrix, yaw(180.0), atol=1e-12)
    np.testing.assert_allclose(tree.lookup("a", "b", 0.25).matrix, yaw(179.5), atol=1e-12)
    np.testing.assert_allclose(tree.lookup("a", "b", 0.75).matrix, yaw(-179.5), atol=1e-12)


def test_interpolation_matches_scipy_slerp():
    rng = np.random.default_rng(3)
    stamps = np.sort(rng.uniform(0.0, 5.0, 8))
    rotations = Rotation.random(8, random_state=rng)
    translations = rng.normal(size=(8, 3))
    tree = FrameTree()
    tree.set_transform("world", "body", pose(rotations, translations), stamps)
    t = rng.uniform(stamps[0], stamps[-1], 200)
    got = tree.lookup("world", "body", t).matrix
    np.testing.assert_allclose(got[:, :3, :3], Slerp(stamps, rotations)(t).as_matrix(), atol=1e-10)
    expected_t = np.stack([np.interp(t, stamps, translations[:, i]) for i in range(3)], axis=-1)
    np.testing.assert_allclose(got[:, :3, 3], expected_t, atol=1e-12)


def test_exact_stamp_returns_the_sample(robot):
    tree, T = robot
    for k in range(5):
        got = tree.lookup("odom", "base_link", float(k)).matrix
        np.testing.assert_allclose(got, T["base_link"][k], rtol=0, atol=1e-15)


def test_batched_stamps_equal_one_by_one_lookups():
    rng = np.random.default_rng(11)
    tree = FrameTree()
    tree.set_transform("map", "odom", random_pose(rng, 6), np.linspace(0.0, 5.0, 6))
    tree.set_transform("odom", "base_link", random_pose(rng, 21), np.linspace(-1.0, 6.0, 21))
    tree.set_transform("base_link", "laser", random_pose(rng), static=True)
    tree.set_transform("map", "beacon", random_pose(rng, 3), [0.0, 2.0, 5.0])
    stamps = rng.uniform(0.0, 5.0, (4, 10))
    stamps[0, :3] = [0.0, 2.0, 5.0]  # exact hits on some links
    batched = tree.lookup("beacon", "laser", stamps)
    assert batched.matrix.shape == (4, 10, 4, 4)
    one_by_one = np.array([[tree.lookup("beacon", "laser", s).matrix for s in row] for row in stamps])
    np.testing.assert_allclose(batched.matrix, one_by_one, atol=1e-12)


# ---------------------------------------------------------------------------- storage


def test_batched_set_transform_equals_one_by_one_in_any_order():
    rng = np.random.default_rng(5)
    stamps = rng.permutation(np.arange(40.0) * 0.25)
    poses = random_pose(rng, 40)
    batch, single = FrameTree(), FrameTree()
    batch.set_transform("odom", "base_link", poses, stamps)
    for T, s in zip(poses, stamps):
        single.set_transform("odom", "base_link", T, s)
    from_se3 = FrameTree()
    from_se3.set_transform("odom", "base_link", SE3.from_matrix(poses), stamps)
    t = np.linspace(0.0, 9.75, 97)
    expected = batch.lookup("odom", "base_link", t).matrix
    np.testing.assert_array_equal(single.lookup("odom", "base_link", t).matrix, expected)
    np.testing.assert_array_equal(from_se3.lookup("odom", "base_link", t).matrix, expected)
    order = np.argsort(stamps)
    np.testing.assert_allclose(batch.lookup("odom", "base_link", stamps[order]).matrix, poses[order], atol=1e-12)


def test_out_of_order_samples_are_merged_in_time_order():
    tree = FrameTree()
    tree.set_transform("a", "b", yaw(0.0, (4.0, 0.0, 0.0)), 4.0)
    tree.set_transform("a", "b", yaw(0.0, (0.0, 0.0, 0.0)), 0.0)  # before everything
    tree.set_transform("a", "b", np.stack([yaw(0.0, (2.0, 0.0, 0.0)), yaw(0.0, (1.0, 0.0, 0.0))]), [2.0, 1.0])
    tree.set_transform("a", "b", yaw(0.0, (6.0, 0.0, 0.0)), 6.0)  # after everything
    tree.set_transform("a", "b", yaw(0.0, (5.0, 0.0, 0.0)), 5.0)  # between the last two
    t = np.array([0.0, 0.5, 1.0, 2.0, 3.0, 4.5, 5.5, 6.0])
    x = tree.lookup("a", "b", t).translation[:, 0]
    np.testing.assert_allclose(x, t, atol=1e-12)


def test_sample_at_stored_stamp_replaces_it():
    tree = FrameTree()
    tree.set_transform("a", "b", np.stack([yaw(0.0), yaw(10.0), yaw(20.0)]), [0.0, 1.0, 2.0])
    tree.set_transform("a", "b", yaw(-10.0), 1.0)
    np.testing.assert_allclose(tree.lookup("a", "b", 1.0).matrix, yaw(-10.0), atol=1e-15)
    # Within one batch, the last of equal stamps wins, as with one-by-one calls.
    tree.set_transform("a", "b", np.stack([yaw(30.0), yaw(40.0), yaw(50.0)]), [3.0, 2.0, 2.0])
    np.testing.assert_allclose(tree.lookup("a", "b", 2.0).matrix, yaw(50.0), atol=1e-15)
    np.testing.assert_allclose(tree.lookup("a", "b", 3.0).matrix, yaw(30.0), atol=1e-15)


def test_long_streams_keep_the_right_window():
    rng = np.random.default_rng(2)
    poses = random_pose(rng, 3000)
    stamps = np.arange(3000) * 0.01
    tree = FrameTree(cache_time=1.0)
    for T, s in zip(poses, stamps):  # one call per sample: the amortised append and compaction path
        tree.set_transform("odom", "base_link", T, s)
    kept = stamps >= stamps[-1] - 1.0
    assert 100 <= kept.sum() <= 101
    got = tree.lookup("odom", "base_link", stamps[kept]).matrix
    np.testing.assert_allclose(got, poses[kept], atol=1e-12)
    with pytest.raises(ExtrapolationError, match="before the first"):
        tree.lookup("odom", "base_link", stamps[~kept][-1])


# ---------------------------------------------------------------------------- history bounds


def test_cache_time_drops_old_samples():
    tree = FrameTree(cache_time=10.0)
    tree.set_transform("odom", "base_link", np.broadcast_to(np.eye(4), (21, 4, 4)), np.arange(21.0))
    tree.lookup("odom", "base_link", 10.0)  # newest 20 − 10 s: still kept
    with pytest.raises(ExtrapolationError, match=r"before the first sample at t=10\.0"):
        tree.lookup("odom", "base_link", 5.0)
    # A late sample older than the cache window is dropped on arrival (tf2 rejects it too).
    tree.set_transform("odom", "base_link", np.eye(4), 3.0)
    assert not tree.can_transform("odom", "base_link", 3.0)


def test_max_history_keeps_newest_samples():
    tree = FrameTree(max_history=3)
    for k in range(6):
        tree.set_transform("odom", "base_link", yaw(10.0 * k), float(k))
    assert tree.can_transform("odom", "base_link", 3.0)
    assert not tree.can_transform("odom", "base_link", 2.5)
    np.testing.assert_allclose(tree.lookup("odom", "base_link", 4.5).matrix, yaw(45.0), atol=1e-12)


def test_static_links_hold_at_any_time():
    tree = FrameTree(cache_time=1.0)
    T = yaw(30.0, (1.0, 2.0, 3.0))
    tree.set_transform("base_link", "laser", T, stamp=123.0, static=True)
    for stamp in (None, -1e9, 0.0, 123.0, 1e9, np.array([-5.0, 5.0])):
        expected = np.broadcast_to(T, np.shape(stamp) + (4, 4))
        np.testing.assert_allclose(tree.lookup("base_link", "laser", stamp).matrix, expected, atol=1e-15)


# ---------------------------------------------------------------------------- latest common time


def test_none_stamp_uses_latest_common_time():
    tree = FrameTree()
    tree.set_transform("map", "odom", np.stack([yaw(0.0), yaw(10.0)]), [0.0, 5.0])
    tree.set_transform("odom", "base_link", np.stack([yaw(0.0, (0, 0, 0)), yaw(0.0, (3, 0, 0))]), [0.0, 3.0])
    tree.set_transform("base_link", "laser", yaw(0.0), static=True)
    assert tree.latest_common_time("map", "laser") == 3.0
    assert tree.latest_common_time("odom", "laser") == 3.0
    assert tree.latest_common_time("map", "odom") == 5.0
    assert tree.latest_common_time("base_link", "laser") is None
    np.testing.assert_allclose(tree.lookup("map", "laser").matrix, tree.lookup("map", "laser", 3.0).matrix, atol=0)
    np.testing.assert_allclose(tree.lookup("map", "odom").matrix, yaw(10.0), atol=1e-15)


# ---------------------------------------------------------------------------- errors


def test_unknown_frame(robot):
    tree, _ = robot
    with pytest.raises(UnknownFrameError, match="'lidar'"):
        tree.lookup("map", "lidar")
    with pytest.raises(UnknownFrameError, match="'gps'"):
        tree.lookup("gps", "map", 1.0)
    with pytest.raises(UnknownFrameError):
        tree.parent("gps")
    assert not tree.can_transform("map", "lidar")


def test_disconnected_trees(robot):
    tree, _ = robot
    tree.set_transform("world", "gps", np.eye(4), static=True)
    with pytest.raises(ConnectivityError, match="'world'.*'map'"):
        tree.lookup("gps", "laser", 1.0)
    assert not tree.can_transform("gps", "laser", 1.0)


def test_extrapolation_messages_name_direction_link_and_time(robot):
    tree, _ = robot
    with pytest.raises(ExtrapolationError) as past:
        tree.lookup("map", "laser", -0.5)
    message = str(past.value)
    assert "before the first sample at t=0.0" in message
    assert "'odom' -> 'base_link'" in message and "t=-0.5" in message
    with pytest.raises(ExtrapolationError) as future:
        tree.lookup("laser", "map", np.array([1.0, 4.25]))
    message = str(future.value)
    assert "after the last sample at t=4.0" in message
    assert "'odom' -> 'base_link'" in message and "t=4.25" in message


def test_single_sample_link_only_at_its_stamp():
    tree = FrameTree()
    tree.set_transform("a", "b", yaw(10.0), 2.0)
    np.testing.assert_allclose(tree.lookup("a", "b", 2.0).matrix, yaw(10.0), atol=1e-15)
    np.testing.assert_allclose(tree.lookup("a", "b").matrix, yaw(10.0), atol=1e-15)
    with pytest.raises(ExtrapolationError, match="after the last"):
        tree.lookup("a", "b", 2.001)
    with pytest.raises(ExtrapolationError, match="before the first"):
        tree.lookup("a", "b", 1.999)


def test_loops_are_rejected_and_leave_the_tree_unchanged(robot):
    tree, _ = robot
    with pytest.raises(FrameLoopError, match="itself"):
        tree.set_transform("laser", "laser", np.eye(4), static=True)
    with pytest.raises(FrameLoopError, match="'laser' -> 'map'"):
        tree.set_transform("laser", "map", np.eye(4), static=True)
    with pytest.raises(FrameLoopError):
        tree.set_transform("base_link", "odom", np.eye(4), 1.0)
    assert tree.parent("map") is None and tree.parent("odom") == "map"


def test_error_hierarchy():
    for error in (UnknownFrameError, ConnectivityError, ExtrapolationError, FrameLoopError):
        assert issubclass(error, TransformError) and issubclass(error, OccmapError)


def test_rejects_bad_transforms_and_stamps():
    tree = FrameTree()
    with pytest.raises(NotARotationError):
        tree.set_transform("a", "b", np.diag([1.0, 1.0, -1.0, 1.0]), static=True)
    with pytest.raises(NotARotationError):
        tree.set_transform("a", "b", 2.0 * np.eye(4), 0.0)
    with pytest.raises(ShapeError):
        tree.set_transform("a", "b", np.eye(3), static=True)
    with pytest.raises(ShapeError):
        tree.set_transform("a", "b", np.stack([np.eye(4)] * 3), [0.0, 1.0])
    with pytest.raises(ShapeError):
        tree.set_transform("a", "b", np.stack([np.eye(4)] * 2), static=True)
    with pytest.raises(NonFiniteError):
        tree.set_transform("a", "b", np.eye(4), float("nan"))
    with pytest.raises(InvalidArgumentError, match="needs a stamp"):
        tree.set_transform("a", "b", np.eye(4))
    with pytest.raises(InvalidArgumentError):
        tree.set_transform("", "b", np.eye(4), static=True)
    assert tree.frames == []


# ---------------------------------------------------------------------------- structure


def test_reparenting_and_static_dynamic_switch_replace_the_link():
    tree = FrameTree()
    tree.set_transform("odom", "base_link", np.stack([yaw(0.0), yaw(10.0)]), [0.0, 1.0])
    tree.set_transform("map", "base_link", yaw(20.0), 5.0)
    assert tree.parent("base_link") == "map"
    assert not tree.can_transform("map", "base_link", 0.5)  # the old history is gone
    assert not tree.can_transform("odom", "base_link", 5.0)
    tree.set_transform("map", "base_link", yaw(30.0), static=True)
    np.testing.assert_allclose(tree.lookup("map", "base_link", -3.0).matrix, yaw(30.0), atol=1e-15)
    tree.set_transform("map", "base_link", yaw(40.0), 7.0)
    assert not tree.can_transform("map", "base_link", 6.0)


def test_frames_parent_and_repr(robot):
    tree, _ = robot
    assert set(tree.frames) == {"map", "odom", "base_link", "laser", "camera"}
    assert "odom" in tree and "gps" not in tree
    assert tree.parent("map") is None
    assert tree.parent("laser") == "base_link"
    assert tree.can_transform("map", "camera", 3.5)
    assert not tree.can_transform("map", "camera", 4.5)
    text = repr(tree)
    assert "map" in text and "[static]" in text and "5 samples" in text
    depth = {}
    for line in text.splitlines()[1:]:
        name = line.lstrip(" │├└─").split()[0]
        depth[name] = len(line) - len(line.lstrip(" │├└─"))
    assert depth["map"] < depth["odom"] < depth["base_link"] < depth["laser"] == depth["camera"]
    assert "no frames" in repr(FrameTree())


# ---------------------------------------------------------------------------- laws


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), a=st.integers(0, 7), b=st.integers(0, 7), c=st.integers(0, 7))
def test_lookups_compose_in_a_random_tree(seed, a, b, c):
    """T_a_c = T_a_b @ T_b_c for any three frames of one tree, at any time the data covers."""
    rng = np.random.default_rng(seed)
    tree = FrameTree()
    for k in range(1, 8):  # frame k hangs below a random earlier frame
        parent, child = f"f{rng.integers(k)}", f"f{k}"
        if rng.random() < 0.4:
            tree.set_transform(parent, child, random_pose(rng), static=True)
        else:
            stamps = rng.permutation(np.linspace(0.0, 2.0, 5) + rng.uniform(-0.2, 0.2, 5))
            tree.set_transform(parent, child, random_pose(rng, 5), stamps)
    stamp = rng.uniform(0.2, 1.8, 3)
    fa, fb, fc = f"f{a}", f"f{b}", f"f{c}"
    composed = tree.lookup(fa, fb, stamp).matrix @ tree.lookup(fb, fc, stamp).matrix
    np.testing.assert_allclose(tree.lookup(fa, fc, stamp).matrix, composed, atol=1e-10)
