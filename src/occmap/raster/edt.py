"""Exact Euclidean distance transform of a 2D boolean mask.

Felzenszwalb & Huttenlocher, "Distance Transforms of Sampled Functions" (Theory of Computing 8,
2012): the squared distance separates into two 1D passes. First, per column, the distance along
the column to the nearest obstacle (two sweeps); then, per row, the lower envelope of the
parabolas ``(x − q)² + g(q)²``. Both passes are linear in the number of cells, so the whole
transform is O(H·W) whatever the obstacles look like, and every value is exact: squared
distances are sums of squared integers (exact in float64 up to 2⁵³).

Cells are ``(row, col)`` = ``(iy, ix)`` (grid conventions: :mod:`occmap.raster`); the distance
between cells is measured between their centres, in cells (:func:`squared_distance_cells`) or in metres
(:func:`distance_transform`). An obstacle cell is at distance 0; where the mask holds no
obstacle at all, the distance is ``inf``.

The same values as ``scipy.ndimage.distance_transform_edt(~mask)`` (which measures to the
nearest zero), squared or scaled, without its int32 index arrays.
"""

from __future__ import annotations

import numpy as np
from numba import get_num_threads, prange

from .. import checks
from .._jit import kernel, kernel_parallel
from .._threads import ThreadChoice
from ..errors import ShapeError

__all__ = ["bounded_distance", "squared_distance_cells", "distance_transform", "row_envelope"]

#: Masks with fewer cells than this run on one thread (thread start-up costs more than it saves);
#: larger ones on as many as :data:`THREADS` finds cheaper.
PARALLEL_MIN_CELLS = 40_000
THREADS = ThreadChoice(min_work=PARALLEL_MIN_CELLS)

#: Columns per block of the column pass (one block per task; a block's row slice is a few cache lines).
_COL_BLOCK = 64


@kernel
def _columns(mask, out, x0, x1):
    """Column pass for columns ``[x0, x1)``: ``out[y, x]`` = distance along column x from row y to
    the nearest obstacle (inf if the column has none). Sweeps row after row so memory is read in
    order."""
    H = mask.shape[0]
    inf = np.inf
    for x in range(x0, x1):
        out[0, x] = 0.0 if mask[0, x] else inf
    for y in range(1, H):
        for x in range(x0, x1):
            out[y, x] = 0.0 if mask[y, x] else out[y - 1, x] + 1.0
    for y in range(H - 2, -1, -1):
        for x in range(x0, x1):
            b = out[y + 1, x] + 1.0
            if b < out[y, x]:
                out[y, x] = b


@kernel
def row_envelope(row, f, v, z):
    """The row pass, a kernel for other kernels (the costmap's inflation uses it). In place: ``row[q]`` ← min over p of ``(q − p)² + row[p]²`` (``row`` holds the column
    distances; inf entries are no parabola). ``f``, ``v``, ``z`` are scratch of length ≥ n, n, n + 1."""
    n = row.shape[0]
    k = -1
    for q in range(n):
        g = row[q]
        if g == np.inf:
            f[q] = np.inf
            continue
        fq = g * g
        f[q] = fq
        if k < 0:
            k = 0
            v[0] = q
            z[0] = -np.inf
            z[1] = np.inf
            continue
        while True:
            p = v[k]
            s = ((fq + q * q) - (f[p] + p * p)) / (2.0 * (q - p))
            if s <= z[k]:
                k -= 1  # z[0] = −inf, so k stays ≥ 0
            else:
                break
        k += 1
        v[k] = q
        z[k] = s
        z[k + 1] = np.inf
    if k < 0:
        return  # no obstacle within reach of this row: the row stays inf
    k = 0
    for q in range(n):
        while z[k + 1] < q:
            k += 1
        p = v[k]
        d = q - p
        row[q] = d * d + f[p]


@kernel
def _rows(out, y0, y1):
    W = out.shape[1]
    f = np.empty(W)
    v = np.empty(W, dtype=np.int64)
    z = np.empty(W + 1)
    for y in range(y0, y1):
        row_envelope(out[y], f, v, z)


@kernel
def _edt_serial(mask, out):
    H, W = mask.shape
    _columns(mask, out, 0, W)
    _rows(out, 0, H)


@kernel_parallel
def _edt_parallel(mask, out, n_chunks):
    H, W = mask.shape
    n_blocks = (W + _COL_BLOCK - 1) // _COL_BLOCK
    for b in prange(n_blocks):
        _columns(mask, out, b * _COL_BLOCK, min(W, (b + 1) * _COL_BLOCK))
    for c in prange(n_chunks):
        _rows(out, (H * c) // n_chunks, (H * (c + 1)) // n_chunks)


def _check_mask(obstacle_mask) -> np.ndarray:
    m = np.asarray(obstacle_mask)
    if m.ndim != 2:
        raise ShapeError(f"obstacle_mask must be a 2D (H, W) array, got shape {m.shape}")
    if m.dtype != np.bool_:
        m = m != 0
    return np.ascontiguousarray(m)


def _squared(mask: np.ndarray, parallel) -> np.ndarray:
    H, W = mask.shape
    out = np.empty((H, W), dtype=np.float64)
    if H == 0 or W == 0:
        return out
    if parallel is None:
        with THREADS.choose(H * W) as parallel:
            return _fill(mask, out, parallel)
    return _fill(mask, out, parallel)


def _fill(mask, out, parallel: bool) -> np.ndarray:
    if parallel:
        _edt_parallel(mask, out, max(1, min(mask.shape[0], 4 * get_num_threads())))
    else:
        _edt_serial(mask, out)
    return out


def squared_distance_cells(obstacle_mask, parallel: bool | None = None) -> np.ndarray:
    """Squared Euclidean distance, in cells, from each cell's centre to the nearest True cell.

    ``obstacle_mask`` is a boolean (H, W) array (any other dtype: non-zero is an obstacle).
    Returns float64 (H, W): exact integers (0 on obstacles), ``inf`` everywhere when the mask has
    no obstacle. ``parallel`` (default: :data:`THREADS` chooses, for masks of
    :data:`PARALLEL_MIN_CELLS` cells or more) splits both passes over threads; the result is the
    same.
    """
    return _squared(_check_mask(obstacle_mask), parallel)


def distance_transform(obstacle_mask, resolution: float = 1.0, parallel: bool | None = None) -> np.ndarray:
    """Euclidean distance in metres from each cell's centre to the nearest obstacle cell's centre.

    ``resolution`` is the cell side in metres. Returns float64 (H, W): 0 on obstacles, ``inf``
    where the mask has no obstacle at all. Equals
    ``scipy.ndimage.distance_transform_edt(~mask) * resolution`` wherever the mask has an obstacle.
    """
    resolution = checks.resolution(resolution)
    d = _squared(_check_mask(obstacle_mask), parallel)
    np.sqrt(d, out=d)
    if resolution != 1.0:
        d *= float(resolution)
    return d


@kernel
def _stamp(mask, reach, step, limit, out):
    """``out`` (C-contiguous) ← ``min(limit, distance to the nearest True cell of mask)``,
    ``step`` m a cell, for ``limit ≤ reach · step``. Each obstacle on the border of its region (a
    4-neighbour free or off the mask) writes ``step·√(dv² + du²)`` into the cells of its disk
    where that is below ``limit`` (offsets and values from a table; bounds checked only for
    obstacles within ``reach`` of the edge); an obstacle whose four neighbours are obstacles
    only gets 0: the nearest obstacle of any other cell is a border one (a step from an inner
    obstacle towards the cell reaches a nearer one)."""
    H, W = mask.shape
    n = 2 * reach + 1
    dv = np.empty(n * n, dtype=np.int64)
    du = np.empty(n * n, dtype=np.int64)
    value = np.empty(n * n)
    k = 0
    for i in range(-reach, reach + 1):
        for j in range(-reach, reach + 1):
            d = step * np.sqrt(float(i * i + j * j))
            if d < limit:
                dv[k] = i
                du[k] = j
                value[k] = d
                k += 1
    flat = out.reshape(H * W)
    for p in range(H * W):
        flat[p] = limit
    for y in range(H):
        for x in range(W):
            if not mask[y, x]:
                continue
            centre = y * W + x
            if 0 < y < H - 1 and 0 < x < W - 1 and mask[y - 1, x] and mask[y + 1, x] and mask[y, x - 1] and mask[y, x + 1]:
                flat[centre] = 0.0
            elif reach <= y < H - reach and reach <= x < W - reach:
                for q in range(k):
                    p = centre + dv[q] * W + du[q]
                    if value[q] < flat[p]:
                        flat[p] = value[q]
            else:
                for q in range(k):
                    v = y + dv[q]
                    u = x + du[q]
                    if 0 <= v < H and 0 <= u < W and value[q] < out[v, u]:
                        out[v, u] = value[q]


def bounded_distance(obstacle_mask, resolution: float, limit: float) -> np.ndarray:
    """:func:`distance_transform` clamped at ``limit`` metres, ``min(distance, limit)``, exactly
    (the same float64 values): each obstacle writes its distance into the cells within
    ``ceil(limit / resolution)`` cells of it. For sparse masks and short limits, as scan matchers
    read them, a fraction of the whole transform's cost. float64 (H, W); ``limit`` everywhere
    when the mask has no obstacle."""
    resolution = checks.resolution(resolution)
    limit = checks.positive("limit", limit, "metres")
    mask = _check_mask(obstacle_mask)
    out = np.empty(mask.shape, dtype=np.float64)
    _stamp(mask, int(np.ceil(limit / resolution)), float(resolution), float(limit), out)
    return out
