"""Level of detail for drawing octrees: which depth to draw so that at most a given number of
voxels go to the browser, and the voxels of that depth as flat arrays.

An inner node of an OctoMap tree holds the maximum log-odds of its children, so the nodes at a
depth ``d < 16`` are a conservative coarse view: a node is occupied when any voxel inside it is.
Drawing the occupied nodes of depth ``d`` instead of the leaves hides no obstacle; each is a
box ``2**(16 - d)`` voxels wide. Free nodes at depth ``d`` are those whose every known voxel is
free.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np

from ..octree.keys import DEPTH
from ..octree.views import height_colors

#: The depth drawn first, before the refined one: a few thousand boxes at most on OctoMap's samples.
COARSE_DEPTH = 12


class Voxels(NamedTuple):
    """Boxes to draw: centres (N, 3) float32 metres, edge lengths (N,) float32 metres, log-odds
    (N,) float32."""

    centers: np.ndarray
    sizes: np.ndarray
    log_odds: np.ndarray

    @property
    def count(self) -> int:
        return len(self.sizes)

    def subset(self, mask) -> Voxels:
        return Voxels(self.centers[mask], self.sizes[mask], self.log_odds[mask])

    @classmethod
    def of_leaves(cls, leaves, shift=(0.0, 0.0, 0.0)) -> Voxels:
        """From :class:`occmap.octree.tree.Leaves`, centres moved by ``shift`` metres."""
        return cls((leaves.centers + np.asarray(shift, np.float64)).astype(np.float32),
                   leaves.sizes.astype(np.float32), leaves.log_odds.astype(np.float32))

    @classmethod
    def concatenate(cls, parts) -> Voxels:
        parts = list(parts)
        if not parts:
            return cls(np.empty((0, 3), np.float32), np.empty(0, np.float32), np.empty(0, np.float32))
        return cls(*(np.concatenate(a) for a in zip(*parts)))


class Level(NamedTuple):
    """The boxes drawn for one class of space (occupied or free): the depth they come from, and how
    many leaves the tree holds of that class (what a viewer drawing every leaf would draw)."""

    depth: int
    voxels: Voxels
    leaves: int


def pick_level(nodes_at: Callable[[int], Voxels], keep: Callable[[Voxels], np.ndarray], cap: int,
               count: Callable[[int], int] | None = None) -> Level:
    """The deepest level whose boxes of one class number at most ``cap``.

    ``nodes_at(d)`` gives the known nodes down to depth ``d`` (leaves above it included);
    ``keep(voxels)`` the mask of the class drawn (occupied, or free). Tries depth 16, then
    coarser, each step costing a fraction of the one before (a depth holds about a quarter of the
    nodes of the next on surfaces). ``count(d)``, where given, tells how many boxes of the class
    depth ``d`` holds without building them: only the level chosen is then built (a tile store's
    full depth need not fit in memory)."""
    if count is not None:
        depth = next((d for d in range(DEPTH, -1, -1) if count(d) <= cap), 0)
        v = nodes_at(depth)
        return Level(depth, v.subset(keep(v)), count(DEPTH))
    leaves = None
    for depth in range(DEPTH, -1, -1):
        v = nodes_at(depth)
        mask = keep(v)
        n = int(np.count_nonzero(mask))
        if leaves is None:
            leaves = n
        if n <= cap:
            return Level(depth, v.subset(mask), leaves)
    raise AssertionError("the root level holds one node")  # pragma: no cover


def ramp(values, value_range) -> np.ndarray:
    """RGB (N, 3) uint8 of ``values`` on occmap's height ramp (dark blue → yellow) over
    ``value_range`` (lo, hi): heights in metres, or probabilities over (0, 1)."""
    lo, hi = value_range
    return height_colors((np.asarray(values, np.float64) - lo) / max(hi - lo, 1e-9))


def cut(voxels: Voxels, mode: str, z: float) -> np.ndarray:
    """Mask of the boxes kept by a slice: ``"off"`` all, ``"below"`` those whose bottom lies at
    or below ``z`` (the rest cut away, as a ceiling is), ``"at"`` those the plane ``z`` crosses."""
    bottom = voxels.centers[:, 2] - voxels.sizes / 2
    if mode == "below":
        return bottom <= z
    if mode == "at":
        return (bottom <= z) & (z < bottom + voxels.sizes)
    return np.ones(voxels.count, bool)
