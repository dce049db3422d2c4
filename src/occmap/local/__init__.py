"""The local map: a robot-centred rolling costmap that forgets moving objects and checks paths.

:class:`LocalMap` holds a circular buffer of log-odds cells around the robot (moving clears only
the strips that left), integrates planar scans and 3D clouds (a height band marks obstacles),
forgets with a half-life, and serves Nav2 costmaps, point costs and batched footprint checks.
:mod:`occmap.local.costmap` has the cost values, the inflation and the footprint helpers.
"""

from .costmap import (
    FREE_SPACE, INSCRIBED, LETHAL, NO_INFORMATION, InflationParams, circumscribed_radius, inflate,
    inscribed_radius, validate_footprint,
)
from .local_map import LocalMap, PathCheck

__all__ = [
    "FREE_SPACE", "INSCRIBED", "LETHAL", "LocalMap", "NO_INFORMATION", "InflationParams", "PathCheck",
    "circumscribed_radius", "inflate", "inscribed_radius", "validate_footprint",
]
