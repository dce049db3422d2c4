"""2D occupancy grids: the log-odds Bayes filter per cell, lidar and sonar inverse sensor models."""

from .grid import OccupancyGrid2D
from .sensor_models import LidarModel, RadarModel, SonarModel

__all__ = ["LidarModel", "OccupancyGrid2D", "RadarModel", "SonarModel"]
