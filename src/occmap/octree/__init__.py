"""3D occupancy octree with OctoMap's semantics (:class:`OcTree`)."""

from .tree import Leaves, OcTree

__all__ = ["Leaves", "OcTree"]
