"""The solids of a :class:`~occmap.sim.world3d.World3D` binned on a uniform grid over the xy plane,
so that a ray or a point is tested against the solids near it only.

A world of thousands of solids (a town) would otherwise cost every ray a test of every solid.
Cell ``(cx, cy)`` spans ``[x0 + cx·cell, x0 + (cx+1)·cell] × [y0 + cy·cell, y0 + (cy+1)·cell]``
and lists each box and cylinder whose footprint (its xy rectangle, or the square around its disc),
grown by :data:`MARGIN`, meets it. Ray casts through the grid give the very ranges the test of
every solid gives (the argument is in :mod:`occmap.sim._kernels3d`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from . import _kernels3d

__all__ = ["MARGIN", "SolidGrid", "build_grid"]

#: Metres by which footprints are grown before binning: far more than the rounding of the ray walk
#: (~1e-12 m), so that a hit on a cell border or corner is found in every cell that touches it.
MARGIN = 0.01


class SolidGrid(NamedTuple):
    """Cells over the solids' footprints and the solids each one lists (CSR arrays, cell
    ``c = cy·nx + cx``: boxes ``box_items[box_start[c]:box_start[c+1]]``, likewise cylinders)."""

    x0: float
    y0: float
    cell: float
    nx: int
    ny: int
    box_start: np.ndarray
    box_items: np.ndarray
    cyl_start: np.ndarray
    cyl_items: np.ndarray


def footprints(boxes, cylinders) -> np.ndarray:
    """The xy rectangles ``[xmin, ymin, xmax, ymax]`` (B + C, 4) of the boxes, then of the
    cylinders (the squares around their discs)."""
    c = cylinders
    discs = np.stack([c[:, 0] - c[:, 2], c[:, 1] - c[:, 2], c[:, 0] + c[:, 2], c[:, 1] + c[:, 2]],
                     axis=1)
    return np.concatenate([boxes[:, [0, 1, 3, 4]], discs])


def build_grid(boxes, cylinders, cell: float | None = None) -> SolidGrid:
    """Bin ``boxes`` (B, 6) and ``cylinders`` (C, 5) (the rows of
    :class:`~occmap.sim.world3d.World3D`) on a grid covering their grown footprints. ``cell``
    (metres) defaults to the side of the mean area per solid, at least 1 m: for the default town
    (35,000 solids on 2 km × 2 km, 11 m cells) a 14,400-beam scan then takes ~1 ms, a third less
    than with cells twice as large."""
    rects = footprints(boxes, cylinders)
    rects[:, :2] -= MARGIN
    rects[:, 2:] += MARGIN
    lo = rects[:, :2].min(axis=0)
    hi = rects[:, 2:].max(axis=0)
    if cell is None:
        cell = max(1.0, math.sqrt(float(np.prod(hi - lo)) / len(rects)))
    nx, ny = (max(1, int(math.ceil(float(v)))) for v in (hi - lo) / cell)
    x0, y0 = float(lo[0]), float(lo[1])
    nb = boxes.shape[0]
    box_start, box_items = _kernels3d.bin_rects(np.ascontiguousarray(rects[:nb]), x0, y0, cell, nx, ny)
    cyl_start, cyl_items = _kernels3d.bin_rects(np.ascontiguousarray(rects[nb:]), x0, y0, cell, nx, ny)
    return SolidGrid(x0, y0, float(cell), nx, ny, box_start, box_items, cyl_start, cyl_items)
