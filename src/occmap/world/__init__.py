"""World-scale maps: the world cut into fixed, axis-aligned tiles in a global integer key space,
kept in a folder others can read, built out of core and in parallel on Dask, equal to the map one
process builds (issue 17).

:class:`TiledOcTree` (:mod:`.octree_tiles`) is the tiled octree, :class:`TiledGrid2D`
(:mod:`.grid_tiles`) the tiled 2D grid; :mod:`.store` the folder;
:mod:`.build` the parallel build; the scan sources a build reads are :mod:`occmap.sources`.
"""

from .grid_tiles import TiledGrid2D
from .octree_tiles import TiledOcTree

__all__ = ["TiledGrid2D", "TiledOcTree"]
