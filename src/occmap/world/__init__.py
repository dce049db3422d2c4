"""World-scale maps: the world cut into fixed, axis-aligned tiles in a global integer key space,
kept in a folder others can read, built out of core and in parallel on Dask, equal to the map one
process builds (issue 17).

:class:`TiledOcTree` (:mod:`.octree_tiles`) is the tiled octree; :mod:`.store` the folder;
:mod:`.build` the parallel build; :mod:`.sources` the scan sources a build reads.
"""

from .octree_tiles import TiledOcTree

__all__ = ["TiledOcTree"]
