"""PointCloud: construction, validation, origin and world points against scipy."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from occmap.cloud import PointCloud
from occmap.errors import InvalidArgumentError, NonFiniteError, NotARotationError, OccmapError, ShapeError
from occmap.geometry import SE3


def test_defaults_identity_pose(rng):
    pts = rng.normal(size=(50, 3))
    c = PointCloud(pts)
    assert len(c) == 50
    assert c.points.dtype == np.float64 and c.points.shape == (50, 3)
    np.testing.assert_array_equal(c.origin, np.zeros(3))
    np.testing.assert_array_equal(c.world_points(), pts)
    assert c.stamp is None and c.dropped == 0
    assert c.pose.shape == ()


def test_world_points_match_scipy(rng):
    rot = Rotation.from_rotvec([0.3, -0.2, 1.1])
    t = np.array([1.0, -2.0, 0.5])
    m = np.eye(4)
    m[:3, :3] = rot.as_matrix()
    m[:3, 3] = t
    pts = rng.normal(size=(200, 3)) * 10
    for pose in (SE3(m), m):  # an SE3 or a plain 4x4 array
        c = PointCloud(pts, pose, stamp=12, dropped=3)
        np.testing.assert_allclose(c.world_points(), rot.apply(pts) + t, atol=1e-12)
        np.testing.assert_allclose(c.origin, t)
        assert isinstance(c.pose, SE3)
        assert c.stamp == 12.0 and isinstance(c.stamp, float)
        assert c.dropped == 3
    # origin is a copy: changing it does not move the cloud
    o = c.origin
    o[0] = 99
    assert c.origin[0] == 1.0


def test_lists_and_float32_are_converted():
    c = PointCloud([[1, 2, 3]])
    assert c.points.dtype == np.float64
    c32 = PointCloud(np.ones((4, 3), dtype=np.float32))
    assert c32.points.dtype == np.float64


def test_empty_cloud():
    c = PointCloud(np.zeros((0, 3)), SE3.from_rotvec([0, 0, 1], [1, 2, 3]))
    assert len(c) == 0
    assert c.world_points().shape == (0, 3)


@pytest.mark.parametrize("shape", [(3,), (5, 2), (5, 4), (2, 5, 3), (0,)])
def test_bad_point_shapes(shape):
    with pytest.raises(ShapeError, match="points"):
        PointCloud(np.zeros(shape))


def test_bad_pose():
    with pytest.raises(ShapeError, match="pose"):
        PointCloud(np.zeros((1, 3)), SE3.identity(2))
    with pytest.raises(NotARotationError):
        PointCloud(np.zeros((1, 3)), np.ones((4, 4)))
    with pytest.raises(ShapeError):
        PointCloud(np.zeros((1, 3)), np.eye(3))


@pytest.mark.parametrize("dropped", [-1, 1.5])
def test_bad_dropped(dropped):
    with pytest.raises(InvalidArgumentError, match="dropped"):
        PointCloud(np.zeros((1, 3)), dropped=dropped)


def test_frozen():
    c = PointCloud(np.zeros((1, 3)))
    with pytest.raises(AttributeError):
        c.stamp = 3.0


def test_non_finite_points_fail_in_world_points():
    c = PointCloud([[0.0, np.nan, 1.0]])
    assert len(c) == 1  # the record itself is faithful
    with pytest.raises(NonFiniteError):
        c.world_points()
    assert issubclass(NonFiniteError, OccmapError)
