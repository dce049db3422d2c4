"""Pictures and exports of an octree: a top-down height map, a horizontal slice, occupied voxels
as a PLY point cloud.

Images are north-up: image row 0 is the largest y, column 0 the smallest x; one pixel is one
voxel (``tree.resolution``) unless a coarser ``pixel`` size is asked for.
"""

from __future__ import annotations

import numpy as np
from PIL import Image

from .. import checks
from ..errors import InvalidArgumentError
from ..io.pointclouds import write_ply

#: Colours of the height ramp (low → high), interpolated linearly: blue, teal, green, yellow.
_RAMP = np.array([[48, 18, 59], [40, 120, 190], [30, 180, 140], [150, 210, 60], [250, 230, 40]], np.float64)
UNKNOWN = (205, 205, 205)
FREE = (255, 255, 255)
OCCUPIED = (20, 20, 20)


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


def height_map(tree, pixel: float | None = None):
    """Top of the occupied space per column, seen from above: ``(top, known, origin, pixel)`` with
    ``top`` (rows, cols) float64 (the highest occupied z, NaN where a column holds none), ``known``
    (rows, cols) bool (any known voxel in the column), ``origin`` the world (x, y) of the image's
    lower-left corner. Row 0 is the southern edge (y = origin y)."""
    if tree.num_nodes() == 0:
        raise InvalidArgumentError("the octree is empty: nothing to draw")
    pixel, x0, y0, w, h = _frame(tree, pixel)
    lv = tree.leaves()
    occupied = lv.log_odds >= tree.occupied_log_odds
    top = np.full(h * w, -np.inf)
    known = np.zeros(h * w, bool)
    # a leaf covers a square of columns: rasterise each leaf over the pixels its footprint spans
    half = lv.sizes / 2
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
    np.maximum.at(top, cell[occ], (lv.centers[:, 2] + half)[leaf][occ])
    top[np.isinf(top)] = np.nan
    return top.reshape(h, w), known.reshape(h, w), np.array([x0, y0]), pixel


def height_image(tree, pixel: float | None = None, z_range=None) -> Image.Image:
    """The height map as a picture: occupied columns coloured by height (``z_range`` (lo, hi), by
    default the map's), known empty columns white, unknown grey."""
    top, known, _, _ = height_map(tree, pixel)
    rgb = np.empty(top.shape + (3,), np.uint8)
    rgb[:] = UNKNOWN
    rgb[known] = FREE
    has = ~np.isnan(top)
    if has.any():
        lo, hi = (np.nanmin(top), np.nanmax(top)) if z_range is None else map(float, z_range)
        rgb[has] = height_colors((top[has] - lo) / max(hi - lo, 1e-9))
    return Image.fromarray(rgb[::-1])


def slice_image(tree, z: float, pixel: float | None = None) -> Image.Image:
    """The horizontal slice at height ``z``: occupied black, free white, unknown grey."""
    if tree.num_nodes() == 0:
        raise InvalidArgumentError("the octree is empty: nothing to draw")
    pixel, x0, y0, w, h = _frame(tree, pixel)
    xs = x0 + (np.arange(w) + 0.5) * pixel
    ys = y0 + (np.arange(h) + 0.5) * pixel
    X, Y = np.meshgrid(xs, ys)
    occ = tree.occupancy_at(np.stack([X.ravel(), Y.ravel(), np.full(X.size, float(z))], -1)).reshape(h, w)
    rgb = np.empty((h, w, 3), np.uint8)
    rgb[occ == -1] = UNKNOWN
    rgb[occ == 0] = FREE
    rgb[occ == 1] = OCCUPIED
    return Image.fromarray(rgb[::-1])


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
