"""Synthetic worlds and sensors with known truth, for the demo and for accuracy tests."""

from .city import (
    CITY_LIDAR,
    City,
    CityDrive,
    CityPlan,
    city_drive,
    city_laser_drive,
    city_laser_scan,
    city_scan,
)
from .world2d import World2D, default_path, simulate_lidar, simulate_scans, simulate_sonar
from .world3d import (
    VELODYNE_HDL32,
    VELODYNE_HDL64,
    VELODYNE_VLP16,
    LidarModel,
    VoxelTruth,
    World3D,
    simulate_drive,
)
from .world3d import simulate_lidar as simulate_lidar3d

__all__ = [
    "World2D", "default_path", "simulate_lidar", "simulate_scans", "simulate_sonar",
    "World3D", "LidarModel", "VELODYNE_HDL32", "VELODYNE_HDL64", "VELODYNE_VLP16", "VoxelTruth",
    "simulate_drive", "simulate_lidar3d",
    "CityPlan", "CityDrive", "City", "CITY_LIDAR", "city_drive", "city_scan", "city_laser_drive",
    "city_laser_scan",
]
