"""3D LiDAR odometry for clouds without poses, through KISS-ICP (the optional extra
``occmap[lidar-odometry]``).

KISS-ICP (Vizzo et al., "KISS-ICP: In Defense of Point-to-Point ICP", RA-L 2023) registers each
cloud against a voxel-hashed local map of the clouds before it, with an adaptive correspondence
threshold and a constant-velocity prior. Here it is used as a library, one call per cloud; its
poses are the sensor's, ``T_world_sensor`` with the first cloud's sensor frame as the world.
"""

from __future__ import annotations

import numpy as np

from .. import checks
from ..cloud import PointCloud
from ..errors import InvalidArgumentError, ShapeError
from ..geometry.se3 import SE3

__all__ = ["lidar_odometry"]


def _kiss():
    try:
        from kiss_icp.config import load_config
        from kiss_icp.kiss_icp import KissICP
    except ImportError as e:
        raise InvalidArgumentError(
            "LiDAR odometry needs KISS-ICP: pip install 'occmap[lidar-odometry]' (or kiss-icp)") from e
    return load_config, KissICP


def lidar_odometry(clouds, max_range: float = 100.0, min_range: float = 0.0, voxel_size: float | None = None) -> SE3:
    """Sensor poses (N,) ``T_world_sensor`` of a run of clouds registered one after the other.

    Parameters
    ----------
    clouds : iterable of PointCloud or array_like (n, 3)
        Points in the sensor frame, metres (a cloud's own pose is not read). Non-finite points
        are dropped.
    max_range, min_range : float
        Points farther or nearer (m) than these are left out (KISS-ICP's ``data`` settings).
    voxel_size : float, optional
        Voxel side (m) of KISS-ICP's local map; by default ``max_range / 100`` as KISS-ICP chooses.

    Raises
    ------
    InvalidArgumentError
        When KISS-ICP is not installed, a range is not positive, or there is no cloud.
    ShapeError
        When a cloud's points are not (n, 3).
    """
    load_config, KissICP = _kiss()
    config = load_config(None)
    config.data.max_range = checks.positive("max_range", max_range, "metres")
    config.data.min_range = checks.non_negative("min_range", min_range, "metres")
    config.data.deskew = False  # clouds here carry no per-point times
    config.mapping.voxel_size = (config.data.max_range / 100.0 if voxel_size is None
                                 else checks.positive("voxel_size", voxel_size, "metres"))
    odometry = KissICP(config)
    poses = []
    no_times = np.zeros(0)
    for k, cloud in enumerate(clouds):
        pts = np.asarray(cloud.points if isinstance(cloud, PointCloud) else cloud, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise ShapeError(f"clouds[{k}] must have shape (n, 3), got {pts.shape}")
        pts = np.ascontiguousarray(pts[np.isfinite(pts).all(axis=1)])
        odometry.register_frame(pts, no_times)
        poses.append(np.array(odometry.last_pose, dtype=np.float64))
    if not poses:
        raise InvalidArgumentError("lidar_odometry needs at least one cloud")
    return SE3.from_matrix(np.stack(poses), project=True)
