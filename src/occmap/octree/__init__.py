"""3D occupancy octree with OctoMap's semantics (:class:`OcTree`); its files are read and written
by :mod:`occmap.io.octomap`."""

from .tree import Leaves, Nodes, OcTree

__all__ = ["Leaves", "Nodes", "OcTree"]
