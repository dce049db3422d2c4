"""The exact 2D ray walk, written once (Amanatides & Woo, "A Fast Voxel Traversal Algorithm for
Ray Tracing", Eurographics 1987): every cell a segment passes through, in order, each once.

Grid conventions (cells, origin, the index rule, ties at corners): :mod:`occmap.raster`. A walk
is a state and a step (:func:`dda_init` / :func:`dda_setup`, :func:`dda_step`); where it is in a
rectangle of cells can be computed without walking (:func:`dda_span`); :func:`miss_walk` walks the
part of it in a rectangle of a map's flat arrays and applies the miss update
(:mod:`occmap.raster.update`) to each cell, the hot loop of every 2D map.

The crossing parameters are rounded down to multiples of 2⁻⁵⁰ (a shift of the crossings by
less than 10⁻¹⁵ of the segment), which makes a walk's additions exact: where a walk is after any
number of steps can then be computed without walking (:func:`dda_span`).
"""

from __future__ import annotations

import math

import numpy as np

from .. import checks
from .._jit import inline_kernel, kernel
from ..errors import NonFiniteError, ShapeError
from .update import clamp_add, miss_stamp


@kernel
def cell_of(x, y, ox, oy, inv_res):
    """(ix, iy) of the cell containing world point (x, y): the index rule of :mod:`occmap.raster`
    (``inv_res`` = 1/res; a world-lattice map passes origin (0, 0))."""
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


#: Crossing parameters are multiples of this (2⁻⁵⁰): sums of such numbers below 8 are exact in
#: float64, so a walk that adds ``t_dx`` crossing after crossing is at ``t_max_x + j·t_dx``
#: exactly, and where a walk is after any number of steps can be computed (:func:`dda_span`).
_T_QUANTUM = 2.0 ** -50


@kernel
def _quantize(t):
    """``t`` rounded down to a multiple of :data:`_T_QUANTUM` (inf stays inf)."""
    return math.floor(t / _T_QUANTUM) * _T_QUANTUM if t < 8.0 else t


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
        t_max_x = _quantize(((ix + (1 if du > 0.0 else 0)) - u0) / du)
        t_dx = _quantize(abs(1.0 / du))
    if dv != 0.0:
        t_max_y = _quantize(((iy + (1 if dv > 0.0 else 0)) - v0) / dv)
        t_dy = _quantize(abs(1.0 / dv))
    return abs(ex - ix) + abs(ey - iy), (ix, iy, ex, ey, sx, sy, t_max_x, t_max_y, t_dx, t_dy)


@kernel
def crossings_before(t0, td, n, t, inclusive):
    """How many of an axis's first ``n`` crossings (at ``t0 + k·td``, k = 0..n−1) come before
    parameter ``t``, counting one at ``t`` itself when ``inclusive``: the count a walk's own
    comparisons give, found from an estimate and checked against them."""
    if n <= 0:
        return 0
    q = (t - t0) / td
    c = 0
    if q >= 0.0:  # false for NaN too
        c = n if q >= n else int(q) + 1
    while c > 0 and not (t0 + (c - 1) * td <= t if inclusive else t0 + (c - 1) * td < t):
        c -= 1
    while c < n and (t0 + c * td <= t if inclusive else t0 + c * td < t):
        c += 1
    return c


@kernel
def _axis_window(i0, s, n, lo, hi):
    """Range ``[a, b]`` of step counts ``j`` ∈ [0, n] along one axis (index ``i0 + s·j``) that
    keep the index in ``[lo, hi)``; empty when a > b."""
    if s > 0:
        return max(lo - i0, 0), min(hi - 1 - i0, n)
    return max(i0 - (hi - 1), 0), min(i0 - lo, n)


@kernel
def dda_span(state, x_lo, x_hi, y_lo, y_hi):
    """Where a walk (``state`` from :func:`dda_init`, not yet stepped) is in the rectangle
    ``[x_lo, x_hi) × [y_lo, y_hi)``.

    A walk is monotone in both axes, so its cells in a rectangle are one run. Returns
    ``(s_in, s_out, jx, jy)``: the run is steps ``s_in ≤ s < s_out`` (step 0 is the start cell,
    step ``steps`` the end cell; empty when ``s_out ≤ s_in``), and before cell ``s_in`` the walk
    has made ``jx`` x steps and ``jy`` y steps, so its state there is ``t_max_x + jx·t_dx``,
    ``t_max_y + jy·t_dy`` (exact, see :data:`_T_QUANTUM`)."""
    ix, iy, ex, ey, sx, sy, t_max_x, t_max_y, t_dx, t_dy = state
    rx, ry = abs(ex - ix), abs(ey - iy)
    ax, bx = _axis_window(ix, sx, rx, x_lo, x_hi)
    ay, by = _axis_window(iy, sy, ry, y_lo, y_hi)
    if ax > bx or ay > by:
        return 0, 0, 0, 0
    # x step J (its crossing at t_max_x + (J−1)·t_dx) comes after the y crossings strictly before
    # it (x first on ties), y step K after the x crossings at or before its own
    in_x = 0 if ax == 0 else ax + crossings_before(t_max_y, t_dy, ry, t_max_x + (ax - 1) * t_dx, False)
    in_y = 0 if ay == 0 else ay + crossings_before(t_max_x, t_dx, rx, t_max_y + (ay - 1) * t_dy, True)
    s_out = rx + ry + 1
    if bx < rx:
        s_out = min(s_out, bx + 1 + crossings_before(t_max_y, t_dy, ry, t_max_x + bx * t_dx, False))
    if by < ry:
        s_out = min(s_out, by + 1 + crossings_before(t_max_x, t_dx, rx, t_max_y + by * t_dy, True))
    if in_x >= in_y:
        return in_x, s_out, ax, in_x - ax
    return in_y, s_out, in_y - ay, ay


@kernel
def dda_step(state):
    """One step to the next cell. Once one axis has reached the end cell's index only the other
    one moves, so rounding can never overshoot or miss the end cell."""
    ix, iy, ex, ey, sx, sy, t_max_x, t_max_y, t_dx, t_dy = state
    if iy == ey or (ix != ex and t_max_x <= t_max_y):
        return (ix + sx, iy, ex, ey, sx, sy, t_max_x + t_dx, t_max_y, t_dx, t_dy)
    return (ix, iy + sy, ex, ey, sx, sy, t_max_x, t_max_y + t_dy, t_dx, t_dy)


@inline_kernel
def miss_walk(L, S, base, cs, rs, steps, state, x_lo, x_hi, y_lo, y_hi, s, d, lo, hi):
    """The miss update of scan ``s`` (:mod:`occmap.raster.update`) on the cells of a walk
    (``steps, state`` from :func:`dda_init` or :func:`dda_setup`, not yet stepped) before its end
    cell that lie in the rectangle ``[x_lo, x_hi) × [y_lo, y_hi)`` of cells, whose cell
    ``(ix, iy)`` is at index ``base + iy·rs + ix·cs`` of the flat arrays ``L`` and ``S``.
    Returns the number of cells updated.

    The walk is monotone in both axes, so its cells in a rectangle are one run: it starts at its
    first cell there (:func:`dda_span`) and stops where it leaves. It goes in two phases: while
    both axes can still step in the rectangle, :func:`dda_step`'s rule (along the axis whose next
    boundary comes first, x on ties); then a straight run along the other axis, as long as the
    walk takes it, with no comparison per cell. Inlined into each caller: the grid, which ignores
    the count, then does not pay for it (about 13 % on one thread otherwise, noisy)."""
    ix, iy, ex, ey, sx, sy, tmx, tmy, tdx, tdy = state
    if max(ix, ex) < x_lo or min(ix, ex) >= x_hi or max(iy, ey) < y_lo or min(iy, ey) >= y_hi:
        return 0
    rx = abs(ex - ix)  # steps left to the end cell (which is not updated), per axis
    ry = abs(ey - iy)
    if not (x_lo <= ix < x_hi and y_lo <= iy < y_hi):  # the walk enters the rectangle later
        s_in, s_out, jx, jy = dda_span(state, x_lo, x_hi, y_lo, y_hi)
        if s_out <= s_in or s_in == steps:  # no cell in the rectangle, or only the end cell
            return 0
        rx -= jx
        ry -= jy
        if jx > 0:  # (an axis that never steps has infinite t_dx)
            tmx += jx * tdx
            ix += sx * jx
        if jy > 0:
            tmy += jy * tdy
            iy += sy * jy
    cx = min(rx, x_hi - 1 - ix if sx > 0 else ix - x_lo)  # the steps that stay in the rectangle
    cy = min(ry, y_hi - 1 - iy if sy > 0 else iy - y_lo)
    idx = base + iy * rs + ix * cs
    stx = sx * cs
    sty = sy * rs
    code = miss_stamp(s)
    updated = 0
    while cx > 0 and cy > 0:
        i = np.uint64(idx)  # unsigned: no wrap-around test for negative indices
        if S[i] < code:
            S[i] = code
            L[i] = clamp_add(L[i], d, lo, hi)
            updated += 1
        if tmx <= tmy:
            idx += stx
            tmx += tdx
            rx -= 1
            cx -= 1
        else:
            idx += sty
            tmy += tdy
            ry -= 1
            cy -= 1
    # one axis can no longer step in the rectangle (cx or cy is 0): a straight run along the
    # other, of all its steps in the rectangle where the first axis has reached the end cell,
    # else of those before the first one's next crossing (the step that leaves the rectangle)
    if cx == 0:
        st, m, more = sty, cy, ry > cy
        if rx > 0:
            m, t = 0, tmy
            while m < cy and t < tmx:
                t += tdy
                m += 1
            more = True
    else:
        st, m, more = stx, cx, rx > cx
        if ry > 0:
            m, t = 0, tmx
            while m < cx and t <= tmy:
                t += tdx
                m += 1
            more = True
    cells = m + (1 if more else 0)  # the walk goes on after the run: its last cell is no end cell
    for _ in range(cells):
        i = np.uint64(idx)
        if S[i] < code:
            S[i] = code
            L[i] = clamp_add(L[i], d, lo, hi)
            updated += 1
        idx += st
    return updated


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
    resolution = checks.resolution(resolution)
    ox, oy = (checks.finite("origin", v) for v in origin)
    cells, offsets = _traverse_many(a, b, ox, oy, 1.0 / resolution)
    return cells[:, 1], cells[:, 0], offsets
