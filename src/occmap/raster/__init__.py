"""The algorithms every 2D grid of occmap shares, each written once.

Modules: :mod:`~occmap.raster.walk2d` (the exact 2D ray walk), :mod:`~occmap.raster.ring`
(circular-buffer index maths), :mod:`~occmap.raster.update` (the clamped log-odds update and the
per-scan stamps), :mod:`~occmap.raster.edt` (the exact Euclidean distance transform). Importing
this package loads none of them.

Grid conventions (the modules and the maps built on them refer here):

* Cells are indexed ``(row, col)`` = ``(iy, ix)``; arrays are (H, W), row-major.
* A grid's ``origin`` ``(ox, oy)`` is the world position of the *outer corner* of cell (0, 0):
  cell ``(iy, ix)`` covers ``[ox + ix·res, ox + (ix+1)·res) × [oy + iy·res, oy + (iy+1)·res)``
  and its centre is ``(ox + (ix + 0.5)·res, oy + (iy + 0.5)·res)``. A world-lattice map (the
  local map, a growing 2D grid, the tiled map) computes cells with origin (0, 0) and holds a
  window of them at an integer cell offset; its reported origin is that offset times ``res``.
* The cell of a point is ``ix = floor((x − ox) · (1/res))`` (and ``iy`` alike): multiplied by the
  reciprocal, OctoMap's arithmetic, so a point within rounding of a boundary lands where OctoMap
  puts it. Cells are half-open: a point on a boundary belongs to the cell above it (larger index).
* Ties in a walk: where a segment passes exactly through a cell corner, the walk steps along x
  first (one of the two side cells is visited, as OctoMap's ``computeRayKeys`` does).
* Indices are not clipped to a grid: a walk may go through negative indices; the callers keep to
  their own cells.
"""
