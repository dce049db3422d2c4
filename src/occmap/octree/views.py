"""Rasters and exports of an octree: a top-down height map, the ceiling of an indoor map, a
horizontal slice, occupied voxels as a PLY point cloud. The figures drawn from them are in
:mod:`occmap.viz.maps`.

Rasters have row 0 at the smallest y (the southern edge), column 0 at the smallest x; one pixel is
one voxel (``tree.resolution``) unless a coarser ``pixel`` size is asked for.
"""

from __future__ import annotations

import numpy as np
from .. import checks
from ..errors import InvalidArgumentError
from ..io.pointclouds import write_ply

#: Colours of the height ramp (low → high), interpolated linearly: blue, teal, green, yellow.
_RAMP = np.array([[48, 18, 59], [40, 120, 190], [30, 180, 140], [150, 210, 60], [250, 230, 40]], np.float64)


def height_colors(t) -> np.ndarray:
    """RGB (…, 3) uint8 of the height ramp at ``t`` in [0, 1] (clipped)."""
    t = np.clip(np.asarray(t, dtype=np.float64), 0.0, 1.0) * (len(_RAMP) - 1)
    i = np.minimum(t.astype(np.int64), len(_RAMP) - 2)
    f = (t - i)[..., None]
    return np.rint(_RAMP[i] * (1 - f) + _RAMP[i + 1] * f).astype(np.uint8)


def _frame(tree, pixel):
    """Pixel size and the (xmin, ymin, xmax, ymax) box of the known leaves, snapped to pixels."""
    pixel = tree.resolution if pixel is None else checks.positive("pixel", pixel, "metres")
    lo, hi = tree.metric_bounds()
    x0, y0 = np.floor(lo[:2] / pixel) * pixel
    x1, y1 = np.ceil(hi[:2] / pixel) * pixel
    return pixel, x0, y0, max(1, int(round((x1 - x0) / pixel))), max(1, int(round((y1 - y0) / pixel)))


def height_map(tree, pixel: float | None = None, z_max: float | None = None):
    """Top of the occupied space per column, seen from above: ``(top, known, origin, pixel)`` with
    ``top`` (rows, cols) float64 (the highest occupied z, NaN where a column holds none), ``known``
    (rows, cols) bool (any known voxel in the column), ``origin`` the world (x, y) of the image's
    lower-left corner. Row 0 is the southern edge (y = origin y). With ``z_max``, occupied leaves
    starting at or above it are left out (an indoor map seen from under its ceiling, see
    :func:`ceiling`)."""
    if tree.num_nodes() == 0:
        raise InvalidArgumentError("the octree is empty: nothing to draw")
    pixel, x0, y0, w, h = _frame(tree, pixel)
    lv = tree.leaves()
    half = lv.sizes / 2
    occupied = lv.log_odds >= tree.occupied_log_odds
    if z_max is not None:
        occupied &= lv.centers[:, 2] - half < float(z_max)
    top = np.full(h * w, -np.inf)
    known = np.zeros(h * w, bool)
    # a leaf covers a square of columns: rasterise each leaf over the pixels its footprint spans
    c0 = np.floor((lv.centers[:, 0] - half - x0) / pixel + 1e-9).astype(np.int64)
    c1 = np.ceil((lv.centers[:, 0] + half - x0) / pixel - 1e-9).astype(np.int64)
    r0 = np.floor((lv.centers[:, 1] - half - y0) / pixel + 1e-9).astype(np.int64)
    r1 = np.ceil((lv.centers[:, 1] + half - y0) / pixel - 1e-9).astype(np.int64)
    span = np.maximum(c1 - c0, 1) * np.maximum(r1 - r0, 1)
    leaf = np.repeat(np.arange(len(span)), span)
    offset = np.arange(len(leaf)) - np.repeat(np.cumsum(span) - span, span)
    cols = np.maximum(c1 - c0, 1)[leaf]
    col = np.clip(c0[leaf] + offset % cols, 0, w - 1)
    row = np.clip(r0[leaf] + offset // cols, 0, h - 1)
    cell = row * w + col
    known[cell] = True
    occ = occupied[leaf]
    top_z = lv.centers[:, 2] + half
    if z_max is not None:
        top_z = np.minimum(top_z, float(z_max))
    np.maximum.at(top, cell[occ], top_z[leaf][occ])
    top[np.isinf(top)] = np.nan
    return top.reshape(h, w), known.reshape(h, w), np.array([x0, y0]), pixel


def ceiling(tree, cover: float = 0.2, thickness: float = 0.5) -> float | None:
    """The height of an indoor map's ceiling, or None when the map has none (outdoors).

    A ceiling is a horizontal layer of occupied voxels (one ``resolution`` thick) in the upper half
    of the occupied height range that covers at least ``cover`` of the area over which anything is
    occupied, with (nearly) nothing above it: at least 90 % of what is occupied from that layer up
    lies within ``thickness`` metres of it (a roof over the ceiling, not the upper floors of a
    town's taller buildings). The lowest such layer's bottom is returned. Leaves larger than a
    voxel count with their whole footprint at their centre's layer."""
    lv = tree.leaves()
    occ = lv.log_odds >= tree.occupied_log_odds
    if not occ.any():
        return None
    res = tree.resolution
    layer = np.floor(lv.centers[occ, 2] / res).astype(np.int64)
    lo = layer.min()
    counts = np.bincount(layer - lo, weights=(lv.sizes[occ] / res) ** 2)
    top, _, _, _ = height_map(tree)  # one pixel a voxel: its occupied columns are the footprint
    footprint = np.count_nonzero(~np.isnan(top))
    n = len(counts)
    k = np.arange(n)
    below = np.concatenate([[0.0], np.cumsum(counts)])  # below[k]: what lies under layer k
    band = max(1, int(round(thickness / res)))
    within = below[np.minimum(k + band, n)] - below[k]
    from_here_up = below[n] - below[k]
    upper = k >= n / 2
    flat = np.flatnonzero(upper & (counts >= cover * footprint) & (within >= 0.9 * from_here_up))
    return None if flat.size == 0 else float((lo + flat[0]) * res)


def slice_map(tree, z: float, pixel: float | None = None):
    """The horizontal slice at height ``z``: ``(occupancy, origin, pixel)`` with ``occupancy``
    (rows, cols) int8 (−1 unknown, 0 free, 1 occupied; row 0 the southern edge) over the known
    leaves' box, ``origin`` the world (x, y) of its lower-left corner."""
    if tree.num_nodes() == 0:
        raise InvalidArgumentError("the octree is empty: nothing to draw")
    pixel, x0, y0, w, h = _frame(tree, pixel)
    xs = x0 + (np.arange(w) + 0.5) * pixel
    ys = y0 + (np.arange(h) + 0.5) * pixel
    X, Y = np.meshgrid(xs, ys)
    occ = tree.occupancy_at(np.stack([X.ravel(), Y.ravel(), np.full(X.size, float(z))], -1)).reshape(h, w)
    return occ.astype(np.int8), np.array([x0, y0]), pixel


def export_ply(tree, path, binary: bool = True) -> int:
    """Write the occupied leaves' centres as a PLY point cloud coloured by height (opens in MeshLab
    and CloudCompare). Returns the number of points."""
    pts = tree.occupied_centers()
    colors = None
    if len(pts):
        lo, hi = pts[:, 2].min(), pts[:, 2].max()
        colors = height_colors((pts[:, 2] - lo) / max(hi - lo, 1e-9))
    write_ply(path, pts, colors=colors, binary=binary)
    return len(pts)
