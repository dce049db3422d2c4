"""occmap: probabilistic occupancy maps from range sensors, on a fast rigid-body geometry core.

Units are metres, radians and seconds throughout; see ``occmap.geometry`` for the conventions.
"""

from . import errors, geometry, io
from .cloud import PointCloud
from .errors import OccmapError
from .grid2d import LidarModel, OccupancyGrid2D
from .local import LocalMap
from .localize import MonteCarloLocalizer
from .scan import LaserScan

__version__ = "0.1.0"

__all__ = [
    "LaserScan", "LidarModel", "LocalMap", "MonteCarloLocalizer", "OccmapError", "OccupancyGrid2D", "PointCloud", "errors", "geometry", "io",
    "__version__",
]
