"""Exact ray traversal of regular grids (Amanatides & Woo, "A Fast Voxel Traversal Algorithm for
Ray Tracing", Eurographics 1987): every cell a segment passes through, in order, each once.

Grid conventions (shared with the maps): cell ``(iy, ix)`` covers
``[ox + ix·res, ox + (ix+1)·res) × [oy + iy·res, oy + (iy+1)·res)`` where ``(ox, oy)`` is the
world position of the outer corner of cell (0, 0); the index of a point is computed as
``floor((x − ox) · (1/res))``, OctoMap's arithmetic, so a point within rounding of a cell boundary
lands where OctoMap puts it. Where a segment passes exactly through a
cell corner, the traversal steps along x first (one of the two side cells is visited, as in
OctoMap's ``computeRayKeys``). Cells are not clipped to any grid: indices may be negative.
"""

from __future__ import annotations

import math

import numpy as np
from ._jit import kernel
from .errors import InvalidArgumentError, NonFiniteError, ShapeError

@kernel
def cell_of(x, y, ox, oy, inv_res):
    """(ix, iy) of the cell containing world point (x, y)."""
    return int(math.floor((x - ox) * inv_res)), int(math.floor((y - oy) * inv_res))


@kernel
def count_2d(x0, y0, x1, y1, ox, oy, inv_res):
    """Number of cells :func:`dda_2d` visits from (x0, y0) to (x1, y1), both end cells included."""
    ix, iy = cell_of(x0, y0, ox, oy, inv_res)
    ex, ey = cell_of(x1, y1, ox, oy, inv_res)
    return abs(ex - ix) + abs(ey - iy) + 1


@kernel
def dda_init(x0, y0, x1, y1, ox, oy, inv_res):
    """Start a walk from (x0, y0) to (x1, y1): returns ``(steps, state)`` where ``steps`` is the
    number of :func:`dda_step` calls that reach the end cell and ``state`` starts in the start cell;
    ``state[0], state[1]`` are the current ``(ix, iy)``."""
    return dda_setup((x0 - ox) * inv_res, (y0 - oy) * inv_res, (x1 - ox) * inv_res, (y1 - oy) * inv_res)


@kernel
def dda_setup(u0, v0, u1, v1):
    """:func:`dda_init` in cell units: cell ``(i, j)`` spans ``[i, i + 1) × [j, j + 1)``."""
    ix, iy = int(math.floor(u0)), int(math.floor(v0))
    ex, ey = int(math.floor(u1)), int(math.floor(v1))
    du, dv = u1 - u0, v1 - v0
    sx = 1 if ex > ix else -1
    sy = 1 if ey > iy else -1
    # parameter t ∈ [0, 1] along the segment at which the next x (y) cell boundary is crossed
    t_max_x, t_dx, t_max_y, t_dy = np.inf, np.inf, np.inf, np.inf
    if du != 0.0:
        t_max_x = ((ix + (1 if du > 0.0 else 0)) - u0) / du
        t_dx = abs(1.0 / du)
    if dv != 0.0:
        t_max_y = ((iy + (1 if dv > 0.0 else 0)) - v0) / dv
        t_dy = abs(1.0 / dv)
    return abs(ex - ix) + abs(ey - iy), (ix, iy, ex, ey, sx, sy, t_max_x, t_max_y, t_dx, t_dy)


@kernel
def dda_step(state):
    """One step to the next cell. Once one axis has reached the end cell's index only the other
    one moves, so rounding can never overshoot or miss the end cell."""
    ix, iy, ex, ey, sx, sy, t_max_x, t_max_y, t_dx, t_dy = state
    if iy == ey or (ix != ex and t_max_x <= t_max_y):
        return (ix + sx, iy, ex, ey, sx, sy, t_max_x + t_dx, t_max_y, t_dx, t_dy)
    return (ix, iy + sy, ex, ey, sx, sy, t_max_x, t_max_y + t_dy, t_dx, t_dy)


@kernel
def dda_2d(x0, y0, x1, y1, ox, oy, inv_res, cells, start):
    """Write the cells crossed from (x0, y0) to (x1, y1) as rows ``(ix, iy)`` of ``cells`` from row
    ``start`` on, start cell first, end cell last; returns the row after the last one written."""
    steps, state = dda_init(x0, y0, x1, y1, ox, oy, inv_res)
    k = start
    cells[k, 0], cells[k, 1] = state[0], state[1]
    for _ in range(steps):
        state = dda_step(state)
        k += 1
        cells[k, 0], cells[k, 1] = state[0], state[1]
    return k + 1


@kernel
def _traverse_many(starts, ends, ox, oy, inv_res):
    n = starts.shape[0]
    offsets = np.empty(n + 1, dtype=np.int64)
    offsets[0] = 0
    for i in range(n):
        offsets[i + 1] = offsets[i] + count_2d(starts[i, 0], starts[i, 1], ends[i, 0], ends[i, 1], ox, oy, inv_res)
    cells = np.empty((offsets[n], 2), dtype=np.int64)
    for i in range(n):
        dda_2d(starts[i, 0], starts[i, 1], ends[i, 0], ends[i, 1], ox, oy, inv_res, cells, offsets[i])
    return cells, offsets


def traverse_2d(starts, ends, resolution: float, origin=(0.0, 0.0)):
    """Cells crossed by segments ``starts[i] → ends[i]`` (points (..., 2), metres).

    Returns ``(iy, ix, offsets)``: the cells of segment ``i`` are ``iy[offsets[i]:offsets[i+1]]``,
    ``ix[...]`` (row, column), start cell first and end cell last. A single segment (shape (2,))
    gives ``offsets`` of length 2.
    """
    a = np.asarray(starts, dtype=np.float64)
    b = np.asarray(ends, dtype=np.float64)
    if a.shape[-1:] != (2,) or b.shape[-1:] != (2,):
        raise ShapeError(f"starts and ends must have shape (..., 2), got {a.shape} and {b.shape}")
    a, b = np.broadcast_arrays(a, b)
    a = np.ascontiguousarray(a.reshape(-1, 2))
    b = np.ascontiguousarray(b.reshape(-1, 2))
    if not (np.isfinite(a).all() and np.isfinite(b).all()):
        raise NonFiniteError("segment end points must be finite")
    if not resolution > 0:
        raise InvalidArgumentError(f"resolution must be > 0, got {resolution!r}")
    ox, oy = (float(v) for v in origin)
    cells, offsets = _traverse_many(a, b, ox, oy, 1.0 / float(resolution))
    return cells[:, 1], cells[:, 0], offsets
