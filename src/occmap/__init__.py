"""occmap: probabilistic occupancy maps from range sensors, on a fast rigid-body geometry core.

Units are metres, radians and seconds throughout; see ``occmap.geometry`` for the conventions.
"""

from . import errors, geometry
from .errors import OccmapError

__version__ = "0.1.0"

__all__ = ["OccmapError", "errors", "geometry", "__version__"]
