"""Figures of maps: a 2D occupancy grid (cropped to its walls), an octree's height map (an indoor
one cut under its ceiling) and horizontal slices, any raster of heights, and a three-colour plan
with tracks over it. Each has axes in metres, a scale bar, a colour key and a title.

Each function returns a ``matplotlib.figure.Figure``; :func:`occmap.viz.figure.save` writes it.
"""

from __future__ import annotations

import numpy as np

from ..errors import InvalidArgumentError, ShapeError
from .figure import FREE, UNKNOWN, figure, known_box, legend, map_axes, raster_size

__all__ = ["grid_figure", "height_figure", "heights_figure", "plan_figure", "slice_figure"]

#: The occupied colour of categorical pictures (slices).
OCCUPIED = (0.1, 0.1, 0.1)


def _extent(origin, resolution: float, shape) -> tuple[float, float, float, float]:
    x0, y0 = float(origin[0]), float(origin[1])
    return x0, x0 + shape[1] * resolution, y0, y0 + shape[0] * resolution


def _panel(shape, key_px: int = 160):
    """A figure sized for a raster of ``shape`` with room for labels and a colour key, and its axes."""
    w, h = raster_size(shape)
    fig = figure(w + key_px + 110, h + 140)
    return fig, fig.add_subplot()


def _legend(ax, entries) -> None:
    """Colour patches ``(label, rgb)``, then the labelled lines of ``ax``, in rows under the map."""
    from matplotlib.patches import Patch

    legend(ax, [Patch(facecolor=c, edgecolor="0.4", label=t) for t, c in entries])


def grid_figure(probability, known, origin, resolution: float, title: str = "occupancy grid", crop=True):
    """An occupancy grid: probability from white (free, 0) to black (occupied, 1) with its colour
    bar, never-observed cells light blue.

    Args:
        probability: (H, W) occupancy probability in [0, 1], row 0 at the lowest y.
        known: (H, W) bool, the observed cells (NaN probabilities count as unobserved).
        origin: world (x, y) of cell (0, 0)'s outer corner, metres.
        resolution: cell side, metres.
        title: the figure's title.
        crop: True: draw only the mapped part, the box of the occupied cells (p ≥ 0.65,
            map_server's threshold) grown by 20 cells, within the observed ones
            (:func:`~occmap.viz.figure.known_box`); False: every cell; ``(xmin, ymin, xmax, ymax)``
            metres: the cells of that box (two maps of one place drawn alike).
    """
    from matplotlib.colors import PowerNorm

    p = np.asarray(probability, dtype=np.float64)
    seen = np.asarray(known, dtype=bool)
    if p.ndim != 2 or p.shape != seen.shape or p.size == 0:
        raise ShapeError(f"probability {p.shape} and known {seen.shape} must be the same non-empty (H, W)")
    seen = seen & ~np.isnan(p)
    bad = seen & ~((p >= 0.0) & (p <= 1.0))
    if bad.any():
        r, c = np.argwhere(bad)[0]
        raise InvalidArgumentError(f"probability[{r}, {c}] = {float(p[r, c])!r} is not in [0, 1]")
    if isinstance(crop, (bool, np.bool_)):
        rows, cols = known_box(seen, seen & (p >= 0.65)) if crop else (slice(0, p.shape[0]), slice(0, p.shape[1]))
    else:
        rows, cols = _box_cells(crop, np.asarray(origin, np.float64), resolution, p.shape)
    p, seen = p[rows, cols], seen[rows, cols]
    corner = (origin[0] + cols.start * resolution, origin[1] + rows.start * resolution)
    extent = _extent(corner, resolution, p.shape)
    cmap = _cmap("gray_r")
    fig, ax = _panel(p.shape)
    # squared: free cells (p ≈ 0.1) draw white, the unknown colour stands out beside them
    image = ax.imshow(np.ma.masked_array(p, ~seen), cmap=cmap, norm=PowerNorm(2.0, 0.0, 1.0), origin="lower",
                      extent=extent, interpolation="nearest")
    fig.colorbar(image, ax=ax, shrink=0.8, label="occupancy probability (0 free, 1 occupied)")
    map_axes(ax, extent, f"{title}\n{resolution:g} m cells")
    _legend(ax, [("never observed", UNKNOWN)])
    return fig


def mapped_box(probability, known, origin, resolution: float) -> tuple[float, float, float, float]:
    """The world box ``(xmin, ymin, xmax, ymax)`` metres :func:`grid_figure` draws by default (the
    mapped part): to draw another map of the same place alike, give it as that map's ``crop``."""
    p, seen = np.asarray(probability, np.float64), np.asarray(known, bool)
    seen = seen & ~np.isnan(p)
    rows, cols = known_box(seen, seen & (p >= 0.65))
    x0, y0 = float(origin[0]), float(origin[1])
    return (x0 + cols.start * resolution, y0 + rows.start * resolution,
            x0 + cols.stop * resolution, y0 + rows.stop * resolution)


def _box_cells(box, origin, resolution: float, shape) -> tuple[slice, slice]:
    """Row and column slices of the cells a world box ``(xmin, ymin, xmax, ymax)`` metres touches,
    within the map."""
    b = np.asarray(box, dtype=np.float64)
    if b.shape != (4,) or not np.isfinite(b).all() or not (b[0] < b[2] and b[1] < b[3]):
        raise InvalidArgumentError(f"crop must be True, False or (xmin, ymin, xmax, ymax) in metres with min < max, "
                                   f"got {box!r}")
    (c0, r0), (c1, r1) = (np.floor((b[:2] - origin) / resolution).astype(int),
                          np.ceil((b[2:] - origin) / resolution).astype(int))
    rows = slice(int(np.clip(r0, 0, shape[0])), int(np.clip(r1, 0, shape[0])))
    cols = slice(int(np.clip(c0, 0, shape[1])), int(np.clip(c1, 0, shape[1])))
    if rows.start == rows.stop or cols.start == cols.stop:
        raise InvalidArgumentError(f"crop {b.tolist()} holds no cell of the map")
    return rows, cols


def _cmap(name: str):
    """A copy of a named colour map whose masked cells draw as :data:`UNKNOWN`."""
    from matplotlib import colormaps

    return colormaps[name].with_extremes(bad=UNKNOWN)


def height_figure(tree, pixel: float | None = None, z_max: float | str | None = "ceiling", title: str = "height map"):
    """An octree seen from above: each column coloured by its highest occupied voxel (colour bar in
    metres), known columns with nothing occupied white, unknown light blue.

    ``z_max``: leave out what is occupied from this height up; ``"ceiling"`` (default) cuts an
    indoor map just under its ceiling (:func:`occmap.octree.views.ceiling`; outdoor maps are not
    cut), None never cuts."""
    from ..octree import views

    if isinstance(z_max, str):
        z_max = views.ceiling(tree)
    top, known, origin, px = views.height_map(tree, pixel, z_max=z_max)
    cut = "" if z_max is None else f", below z = {z_max:.2f} m"
    return heights_figure(top, known, origin, px, f"{title}\n{px:g} m pixels{cut}",
                          "height of the highest occupied voxel [m]")


def heights_figure(top, known, origin, pixel: float, title: str, key: str, tracks=(), cmap: str = "viridis"):
    """A raster of heights seen from above: ``top`` (H, W) metres (NaN: nothing there) coloured
    with a colour bar labelled ``key``, cells ``known`` with no height white, the rest light blue;
    ``tracks`` drawn over it (see :func:`plan_figure`). Row 0 at ``origin``'s y."""
    from matplotlib import colormaps

    top = np.asarray(top, dtype=np.float64)
    extent = _extent(origin, pixel, top.shape)
    fig, ax = _panel(top.shape)
    ax.imshow(np.where(known, 1.0, np.nan), cmap=_cmap("gray"), vmin=0.0, vmax=1.0, origin="lower",
              extent=extent, interpolation="nearest")
    image = ax.imshow(np.ma.masked_invalid(top), cmap=colormaps[cmap].with_extremes(bad=(0, 0, 0, 0)),
                      origin="lower", extent=extent, interpolation="nearest")
    fig.colorbar(image, ax=ax, shrink=0.8, label=key)
    _tracks(ax, tracks)
    map_axes(ax, extent, title)
    _legend(ax, [("known, nothing occupied", FREE), ("unknown", UNKNOWN)])
    return fig


def slice_figure(tree, z: float, pixel: float | None = None, title: str = "horizontal slice"):
    """The octree's horizontal slice at height ``z`` metres: occupied dark, free white, unknown
    light blue."""
    from ..octree import views

    occ, origin, px = views.slice_map(tree, z, pixel)
    return plan_figure(occ, origin, px, f"{title} at z = {float(z):g} m\n{px:g} m pixels")


def plan_figure(occupancy, origin, resolution: float, title: str, tracks=(), view=None):
    """A map in three colours — ``occupancy`` (H, W) int: 1 occupied (dark), 0 free (white),
    −1 unknown (light blue), row 0 at ``origin``'s y — under ``tracks``: ``(label, xy (N, ≥2),
    style)`` each, drawn with ``Axes.plot(x, y, **style)`` and named in the legend. ``view``
    (xmin, xmax, ymin, ymax) metres: the part shown (default: the raster)."""
    occ = np.asarray(occupancy)
    rgb = np.empty(occ.shape + (3,))
    rgb[:] = UNKNOWN
    rgb[occ == 0] = FREE
    rgb[occ == 1] = OCCUPIED
    extent = _extent(origin, resolution, occ.shape)
    view = extent if view is None else tuple(map(float, view))
    shape = (round((view[3] - view[2]) / resolution), round((view[1] - view[0]) / resolution))
    fig, ax = _panel(shape, key_px=0)
    ax.set_facecolor(UNKNOWN)
    ax.imshow(rgb, origin="lower", extent=extent, interpolation="nearest")
    _tracks(ax, tracks)
    map_axes(ax, view, title)
    _legend(ax, [("occupied", OCCUPIED), ("free", FREE), ("unknown", UNKNOWN)])
    return fig


def _tracks(ax, tracks) -> None:
    for label, xy, style in tracks:
        xy = np.asarray(xy, dtype=np.float64)
        ax.plot(xy[:, 0], xy[:, 1], label=label, **style)
