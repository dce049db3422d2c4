"""Objects from the returns a static map does not explain: clusters of points, each with an
oriented box (its footprint as seen).

A box seen from one side covers only the faces that face the sensor; ``length`` and ``width`` are
the extent of the points, and the tracker (:mod:`.tracker`) grows them to the object's size.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ... import checks
from ...errors import ShapeError
from . import _kernels as K

__all__ = ["Detections", "box_corners", "detect_objects", "elevation_layers"]

#: Largest gap (m) between the returns of one object.
DETECTION_GAP = 0.5
#: Bearing sectors over the full circle in which the occlusion test looks for nearer returns (0.25°).
BEARING_SECTORS = 1440
#: Directions tried by the L-shape fit over 90° (one per degree).
FIT_STEPS = 90
#: Floor of the closeness criterion's distance (m): points this close to an edge count alike.
FIT_MIN_DISTANCE = 0.01
#: Points of a cluster over which the L-shape fit searches its direction, at most: a larger
#: cluster (a car beside a 3D scanner: 22,000 returns) gives every k-th point, weighed k; the box
#: is then drawn around all its points.
FIT_SAMPLE = 512
#: Elevation layers (rad) of a 3D scanner's returns in the occlusion test: a return hides an end
#: only from its own layer or the next (one laser: a ring's returns share an elevation).
ELEVATION_LAYER = math.radians(0.5)


def elevation_layers(points, origin) -> np.ndarray:
    """Elevation layer (int64 (N,), from 0) of 3D ``points`` (N, 3) seen from ``origin`` (3,):
    their elevation angle above the sensor's horizontal plane in steps of :data:`ELEVATION_LAYER`,
    counted from the lowest (non-finite points: the step of elevation 0)."""
    p = np.ascontiguousarray(points, dtype=np.float64)
    o = np.asarray(origin, dtype=np.float64)
    layer = K.elevation_steps(p, o[0], o[1], o[2], ELEVATION_LAYER, np.empty(len(p), np.int64))
    return layer - layer.min() if len(layer) else layer


class Detections(NamedTuple):
    """Per detected object: box centre ``x``, ``y`` (m, world), ``heading`` of its longer side
    (rad, in [−π/2, π/2): a box's heading is known modulo π), ``length`` ≥ ``width`` (m, extent of
    the points), ``points`` (how many), ``cut`` ``(M, 2)`` (its clockwise and its counter-clockwise
    end as seen from the sensor may not be the object's: something nearer hides what lies beyond,
    or the end lies at the range limit), ``oriented``: an L-shaped cluster (two faces seen, both
    sides at least ``min_width``) whose box heading is the object's, up to π — a single face seen
    (a line of points) gives a box whose heading may be the object's side or its end —, ``ends``
    ``(M, 2, 2)``: the returns at those two ends (world, m; NaN when the sensor is not known), and
    ``bare`` ``(M, 2)``: that end is not cut and nothing lies just beyond it but farther than it
    by ``depth`` or more (the surface does not go on into returns not taken as moving, as a wall's
    does). A bare end is a point of the object: it moves with it, whatever hides the other."""

    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    length: np.ndarray
    width: np.ndarray
    points: np.ndarray
    cut: np.ndarray
    oriented: np.ndarray
    ends: np.ndarray
    bare: np.ndarray

    def __len__(self) -> int:
        return int(self.x.shape[0])

    @property
    def occluded(self) -> np.ndarray:
        """Per detection: an end of it is cut, so its extent may be cut short."""
        return self.cut.any(axis=1)

    @staticmethod
    def empty() -> Detections:
        f = np.empty(0)
        return Detections(f, f, f, f, f, np.empty(0, np.int64), np.empty((0, 2), bool), np.empty(0, bool),
                          np.empty((0, 2, 2)), np.empty((0, 2), bool))


def box_corners(x, y, heading, length, width) -> np.ndarray:
    """Corners ``(N, 4, 2)`` of boxes centred at ``(x, y)`` (N,) with ``heading`` (rad) along
    their ``length`` and ``width`` across (m): counter-clockwise from the rear right."""
    x, y, heading, length, width = (np.ascontiguousarray(a, dtype=np.float64)
                                    for a in np.broadcast_arrays(x, y, heading, length, width))
    return K.box_corners(x, y, heading, length, width, np.empty(x.shape + (4, 2)))


def _fit_sample(starts):
    """For clusters ``points[starts[k]:starts[k + 1]]``: ``(index (M,), sample_starts, weights
    (M,))`` of every k-th point of each, k the least step leaving at most :data:`FIT_SAMPLE`,
    each standing for the points up to the next."""
    counts = np.diff(starts)
    step = np.maximum(-(-counts // FIT_SAMPLE), 1)
    per = -(-counts // step)  # points taken from each cluster
    sample_starts = np.concatenate([[0], np.cumsum(per)]).astype(np.int64)
    cluster = np.repeat(np.arange(len(counts)), per)
    rank = np.arange(sample_starts[-1]) - sample_starts[cluster]
    index = starts[cluster] + rank * step[cluster]
    weights = np.minimum(step[cluster], starts[cluster + 1] - index).astype(np.float64)
    return index, sample_starts, weights


def detect_objects(points, gap: float = DETECTION_GAP, min_points: int = 3, min_width: float = 0.3, *, sensor=None,
                   scene=None, max_range: float | None = None, angle: float = math.radians(1.0),
                   depth: float = 0.3, layers=None, scene_layers=None) -> Detections:
    """Cluster world points ``(N, 2)`` (single linkage at ``gap`` m) and fit a box to each cluster
    of at least ``min_points``; a box is ``oriented`` when its width is at least ``min_width`` m.

    With the ``sensor`` position (x, y) and the ``scene`` (all returns of the scan, ``(K, 2)``), a
    detection's angular end is ``cut`` when a return within ``angle`` (rad, about two beams; in
    sectors of 0.25°) beyond it is at least ``depth`` m nearer, or (given the sensor's
    ``max_range``) when it lies within ``depth`` of the range limit, beyond which the rest may lie
    (both ends when only other points of it do); without the sensor none is, and ``ends`` are NaN.
    An end is ``bare`` when it is not cut and no return within ``angle`` beyond it lies less than
    ``depth`` m farther. The returns of a 3D scanner (``layers`` of ``points`` and ``scene_layers``
    of ``scene``: :func:`elevation_layers`) count beyond an end only from its elevation layer or
    the next: a lower ring's ground returns, nearer at every bearing, hide nothing of an object its
    own ring sees whole (a planar scan: one layer)."""
    p = np.ascontiguousarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ShapeError(f"points must have shape (N, 2), got {p.shape}")
    lay = np.zeros(len(p), np.int64) if layers is None else np.asarray(layers, dtype=np.int64)
    if lay.shape != (len(p),):
        raise ShapeError(f"layers must have shape ({len(p)},), got {lay.shape}")
    finite = np.isfinite(p[:, 0]) & np.isfinite(p[:, 1])
    p, lay = p.compress(finite, axis=0), lay.compress(finite)
    gap = checks.positive("gap", gap, "metres")
    min_points = checks.count("min_points", min_points)
    if not len(p):
        return Detections.empty()
    labels = np.empty(len(p), np.int64)
    n = K.cluster_points(p, gap, labels)
    sizes = np.bincount(labels, minlength=n)
    keep = sizes >= min_points
    remap = np.cumsum(keep) - 1
    chosen = keep[labels]
    lab = remap[labels[chosen]]
    order = np.argsort(lab, kind="stable")
    pts = p.compress(chosen, axis=0).take(order, axis=0)
    pts_layers = lay.compress(chosen).take(order)
    counts = sizes[keep]
    starts = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    index, sample_starts, weights = _fit_sample(starts)
    box = K.fit_boxes(pts, starts, pts.take(index, axis=0), sample_starts, weights, FIT_STEPS, FIT_MIN_DISTANCE,
                      np.empty((len(counts), 5)))
    oriented = box[:, 4] >= checks.non_negative("min_width", min_width, "metres")
    cut = np.zeros((len(counts), 2), bool)
    bare = np.zeros((len(counts), 2), bool)
    ends = np.full((len(counts), 2, 2), np.nan)
    if sensor is not None:
        sx, sy = (checks.finite("sensor", v) for v in np.asarray(sensor, dtype=np.float64).reshape(-1)[:2])
        sc = np.empty((0, 2)) if scene is None else np.ascontiguousarray(scene, dtype=np.float64)
        if sc.ndim != 2 or sc.shape[1] != 2:
            raise ShapeError(f"scene must have shape (K, 2), got {sc.shape}")
        sc_layers = np.zeros(len(sc), np.int64) if scene_layers is None else \
            np.ascontiguousarray(scene_layers, dtype=np.int64)
        if sc_layers.shape != (len(sc),):
            raise ShapeError(f"scene_layers must have shape ({len(sc)},), got {sc_layers.shape}")
        n_layers = int(max(pts_layers.max(initial=0), sc_layers.max(initial=0))) + 1
        depth = checks.non_negative("depth", depth, "metres")
        index = np.empty((len(counts), 2), np.int64)
        beyond = np.empty((len(counts), 2))
        K.beyond_ends(pts, pts_layers, starts, sc, sc_layers, n_layers, sx, sy, BEARING_SECTORS,
                      checks.positive("angle", angle), depth, index, beyond)
        ends = pts[index]
        r_end = np.hypot(ends[..., 0] - sx, ends[..., 1] - sy)
        cut = beyond < r_end - depth
        if max_range is not None and len(counts):
            far = np.hypot(pts[:, 0] - sx, pts[:, 1] - sy) >= checks.positive("max_range", max_range) - depth
            # an end at the range limit is cut there; a cluster reaching it elsewhere, both
            elsewhere = (np.add.reduceat(far, starts[:-1]) > 0) & ~far[index].any(axis=1)
            cut |= far[index] | elsewhere[:, None]
        bare = ~cut & np.isinf(beyond)
    return Detections(box[:, 0], box[:, 1], box[:, 2], box[:, 3], box[:, 4], counts.astype(np.int64), cut,
                      oriented, ends, bare)
