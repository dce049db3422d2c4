"""occmap: probabilistic occupancy maps from range sensors, on a fast rigid-body geometry core.

Units are metres, radians and seconds throughout; see ``occmap.geometry`` for the conventions.

The names below load on first use (PEP 562), so ``import occmap`` stays light: Numba and the
compiled kernels load only with the first map or kernel a program touches.
"""

from __future__ import annotations

import importlib

from . import errors
from .errors import OccmapError

__version__ = "0.1.0"

#: Public name → the module that defines it, imported when the name is first used.
_LAZY = {
    "LaserScan": ".scan",
    "LidarModel": ".grid2d",
    "LocalMap": ".local",
    "MonteCarloLocalizer": ".localize",
    "OcTree": ".octree",
    "OccupancyGrid2D": ".grid2d",
    "PointCloud": ".cloud",
}
_SUBPACKAGES = ("geometry", "io")

__all__ = sorted([*_LAZY, *_SUBPACKAGES, "OccmapError", "errors", "__version__"])


def __getattr__(name: str):
    if name in _SUBPACKAGES:
        value = importlib.import_module(f".{name}", __name__)
    elif name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name], __name__), name)
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
