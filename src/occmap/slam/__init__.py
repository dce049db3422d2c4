"""Poses from the data itself where the log has none: incremental 2D scan matching (a SLAM front
end without loop closure), 3D LiDAR odometry through KISS-ICP, and the relative pose error that
measures both against a reference."""

from .evaluate import RelativePoseError, relative_pose_error
from .lidar_odometry import lidar_odometry
from .scan_matching import MatchQuality, ScanMatcher, ScanMatchParams, ScanMatchTrack, match_scans

__all__ = [
    "MatchQuality", "RelativePoseError", "ScanMatchParams", "ScanMatchTrack", "ScanMatcher", "lidar_odometry",
    "match_scans", "relative_pose_error",
]
