"""What every occmap figure shares: a matplotlib figure made without pyplot (no global state, no
display, safe from threads), map axes in metres with a scale bar, the crop to the known area, and
an atomic PNG write.

Conventions: world x to the right, y up (north up); a raster ``(H, W)`` has row 0 at the lowest y
(as every occmap grid) and is drawn with ``origin="lower"`` over its metric ``extent``.
"""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np

from .._files import write_atomic

__all__ = ["figure", "legend", "map_axes", "png_bytes", "save", "known_box", "nice_length", "raster_size"]

#: Colours shared by the figures (RGB in 0 … 1): never-observed cells, free cells.
UNKNOWN = (0.72, 0.82, 0.95)
FREE = (1.0, 1.0, 1.0)

#: Longest side of a map's axes in pixels: small maps are enlarged to it, large ones keep a
#: pixel per cell up to it (at 100 dpi).
MAX_AXES_PX = 1400
MIN_AXES_PX = 640


def figure(width_px: int, height_px: int, dpi: int = 100):
    """A new ``matplotlib.figure.Figure`` of about ``width_px × height_px`` pixels."""
    from matplotlib.figure import Figure

    return Figure(figsize=(width_px / dpi, height_px / dpi), dpi=dpi, layout="compressed")


def raster_size(shape, max_px: int = MAX_AXES_PX, min_px: int = MIN_AXES_PX) -> tuple[int, int]:
    """Pixels ``(width, height)`` for the axes of a ``(H, W)`` raster: a pixel per cell when that
    fits between ``min_px`` and ``max_px`` on the longer side, scaled to fit otherwise."""
    h, w = shape[:2]
    longer = max(h, w, 1)
    f = min(max(1.0, min_px / longer), max_px / longer)
    return max(int(round(w * f)), 60), max(int(round(h * f)), 60)


def nice_length(span: float) -> float:
    """A round length (1, 2 or 5 × 10ⁿ metres) about a fifth of ``span`` metres: the scale bar's."""
    target = max(float(span), 1e-9) / 5.0
    power = 10.0 ** math.floor(math.log10(target))
    for step in (5.0, 2.0, 1.0):
        if step * power <= target:
            return step * power
    return power


def _metres(length: float) -> str:
    return f"{length:g} m" if length >= 1 else f"{length * 100:g} cm"


def map_axes(ax, extent, title: str, xlabel: str = "x [m]", ylabel: str = "y [m]") -> None:
    """Dress ``ax`` as a map: equal aspect over ``extent`` (xmin, xmax, ymin, ymax) in metres, the
    axis labels, ``title``, and a scale bar in the lower right."""
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    x0, x1, y0, y1 = map(float, extent)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    length = nice_length(x1 - x0)
    bar = AnchoredSizeBar(ax.transData, length, _metres(length), "lower right", pad=0.4, sep=3,
                          frameon=True, size_vertical=(y1 - y0) / 400.0, color="black")
    bar.patch.set_alpha(0.8)
    ax.add_artist(bar)


def legend(ax, handles=()) -> None:
    """A legend of ``handles`` and the labelled artists of ``ax`` in rows under the axes, below
    their x label (inside the figure: the layout makes room for it)."""
    from matplotlib.transforms import ScaledTranslation

    handles = list(handles) + ax.get_legend_handles_labels()[0]
    below = ax.transAxes + ScaledTranslation(0.0, -0.5, ax.figure.dpi_scale_trans)  # half an inch down
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, 0.0), bbox_transform=below,
              ncols=min(len(handles), 4), fontsize="small", frameon=False)


def known_box(known: np.ndarray, occupied: np.ndarray | None = None, margin: int = 20, keep: float = 0.995):
    """Row and column slices of the part of a map worth drawing: the box holding the ``keep``
    central fraction of the ``occupied`` cells along each axis (the walls, not a stray speck far
    out; beams that returned nothing reach far past the walls through doors and windows) or, when
    none is occupied or none is given, every ``known`` cell; grown by ``margin`` cells and cut to
    the known cells' box. The whole array when nothing is known."""
    r, c = np.nonzero(known)
    if r.size == 0:
        return slice(0, known.shape[0]), slice(0, known.shape[1])
    outer = r.min(), r.max() + 1, c.min(), c.max() + 1
    if occupied is not None and occupied.any():
        r, c = np.nonzero(occupied)
        tail = (1.0 - keep) / 2.0
        (r0, r1), (c0, c1) = (np.quantile(a, [tail, 1.0 - tail], method="nearest") for a in (r, c))
        inner = int(r0), int(r1) + 1, int(c0), int(c1) + 1
    else:
        inner = outer
    return (slice(max(inner[0] - margin, outer[0]), min(inner[1] + margin, outer[1])),
            slice(max(inner[2] - margin, outer[2]), min(inner[3] + margin, outer[3])))


def png_bytes(fig) -> bytes:
    """The figure as PNG bytes (what a notebook's ``_repr_png_`` returns)."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    return buffer.getvalue()


def save(fig, path) -> Path:
    """Write ``fig`` as a PNG file at ``path`` atomically (the old file or the new one, never half
    of one); returns the path."""
    return write_atomic(path, png_bytes(fig))
