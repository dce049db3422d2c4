"""Figures of a localization run: the track over the map, and the errors against distance travelled."""

from __future__ import annotations

import textwrap

import numpy as np

from .figure import figure
from .maps import plan_figure

__all__ = ["error_figure", "track_figure"]

ESTIMATE = "#1f4fe0"
ODOMETRY = "#d62728"
REFERENCE = "#2ca02c"


def track_figure(occupied, free, origin, resolution: float, estimate, odometry=None, reference=None,
                 title: str = "localization"):
    """The map (occupied dark, free white, unknown light blue) under the estimated track (blue),
    the odometry track anchored at the first estimate (red) and reference poses (green dots).

    ``occupied``, ``free``: (H, W) bool, row 0 at the lowest y; ``origin`` the world (x, y) of
    cell (0, 0)'s corner; tracks (N, ≥2) in metres. The view holds the map and the estimate; an
    odometry track that drifts off is cut half the map's size past it."""
    occ = np.where(np.asarray(occupied, bool), 1, np.where(np.asarray(free, bool), 0, -1))
    x0, y0 = float(origin[0]), float(origin[1])
    est = np.asarray(estimate, dtype=np.float64)
    lo = np.minimum([x0, y0], est[:, :2].min(axis=0))
    hi = np.maximum([x0 + occ.shape[1] * resolution, y0 + occ.shape[0] * resolution], est[:, :2].max(axis=0))
    tracks = []
    if odometry is not None:
        span = hi - lo
        odo = np.asarray(odometry, dtype=np.float64)
        lo = np.minimum(lo, np.maximum(odo[:, :2].min(axis=0), lo - 0.5 * span))
        hi = np.maximum(hi, np.minimum(odo[:, :2].max(axis=0), hi + 0.5 * span))
        tracks.append(("odometry (from the first estimate)", odo, dict(color=ODOMETRY, lw=0.8)))
    if reference is not None:
        tracks.append(("reference poses", reference, dict(ls="none", marker=".", color=REFERENCE, ms=2.5)))
    tracks += [("estimate", est, dict(color=ESTIMATE, lw=0.9)),
               ("start", est[:1], dict(ls="none", marker="o", color=ESTIMATE, ms=6, mfc="none"))]
    return plan_figure(occ, (x0, y0), resolution, f"{title}\nmap: {resolution:g} m cells", tracks,
                       (lo[0], hi[0], lo[1], hi[1]))


def error_figure(distance, curves, title: str = "localization error"):
    """Position error (metres, upper panel) and heading error (degrees, lower panel) against the
    distance travelled (metres): ``curves`` is a list of ``(label, position_error, heading_error)``
    (radians), each drawn over ``distance``. The y axes stop at the 99.5th percentile × 1.1 so
    that one spike does not flatten the rest."""
    d = np.asarray(distance, dtype=np.float64)
    fig = figure(900, 560)
    top, bottom = fig.subplots(2, 1, sharex=True)
    for panel, column, scale, label in ((top, 1, 1.0, "position error [m]"),
                                        (bottom, 2, 180.0 / np.pi, "heading error [°]")):
        values = [np.asarray(c[column], dtype=np.float64) * scale for c in curves]
        for (name, *_), v in zip(curves, values):
            panel.plot(d, v, lw=0.8, label=name or None)
        finite = np.concatenate([v[np.isfinite(v)] for v in values]) if values else np.zeros(0)
        ymax = 1.1 * float(np.percentile(finite, 99.5)) if finite.size else 1.0
        panel.set_ylim(0.0, ymax if ymax > 0 else 1.0)
        panel.set_ylabel(label)
        panel.grid(True, color="0.9")
    bottom.set_xlabel("distance travelled [m]")
    top.set_title(textwrap.fill(title, 90))
    if any(c[0] for c in curves):
        top.legend(loc="upper left", fontsize="small")
    return fig
