"""KISS-ICP through occmap.slam.lidar_odometry (the optional extra ``lidar-odometry``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from occmap.errors import InvalidArgumentError
from occmap.slam import lidar_odometry


def test_the_hdl32_pair_registers_to_its_recorded_relative_transform(data_dir):
    pytest.importorskip("kiss_icp", reason="KISS-ICP is the optional extra occmap[lidar-odometry]")
    from occmap.io.pointclouds import read_pcd

    folder = data_dir / "scans3d" / "hdl32_pair"
    clouds = [read_pcd(p) for p in sorted(folder.glob("*.pcd"))]
    poses = lidar_odometry(clouds)
    np.testing.assert_allclose(poses.matrix[0], np.eye(4), atol=1e-12)
    relative = np.loadtxt(folder / "relative.txt")  # from scan registration, not ground truth
    off = np.linalg.inv(relative) @ poses.matrix[1]
    angle = math.degrees(math.acos(min(1.0, (np.trace(off[:3, :3]) - 1.0) / 2.0)))
    assert np.linalg.norm(off[:3, 3]) < 0.02 and angle < 0.5


def test_without_clouds_it_says_so():
    pytest.importorskip("kiss_icp", reason="KISS-ICP is the optional extra occmap[lidar-odometry]")
    with pytest.raises(InvalidArgumentError, match="at least one cloud"):
        lidar_odometry([])
