"""Synthetic worlds and sensors with known truth, for the demo and for accuracy tests."""

from .world2d import World2D, default_path, simulate_lidar, simulate_scans, simulate_sonar

__all__ = ["World2D", "default_path", "simulate_lidar", "simulate_scans", "simulate_sonar"]
