"""Objects from the returns a static map does not explain: clusters of points, each with an
oriented box (its footprint as seen).

A box seen from one side covers only the faces that face the sensor; ``length`` and ``width`` are
the extent of the points, and the tracker (:mod:`.tracker`) grows them to the object's size.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ... import checks
from ...errors import ShapeError
from . import _kernels as K

__all__ = ["Detections", "detect_objects"]

#: Directions tried by the L-shape fit over 90° (one per degree).
FIT_STEPS = 90
#: Floor of the closeness criterion's distance (m): points this close to an edge count alike.
FIT_MIN_DISTANCE = 0.01


class Detections(NamedTuple):
    """Per detected object: box centre ``x``, ``y`` (m, world), ``heading`` of its longer side
    (rad, in [−π/2, π/2): a box's heading is known modulo π), ``length`` ≥ ``width`` (m, extent of
    the points), ``points`` (how many), and ``oriented``: an L-shaped cluster (two faces seen, both
    sides at least ``min_width``) whose box heading is the object's, up to π. A single face seen
    (a line of points) gives a box whose heading may be the object's side or its end."""

    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    length: np.ndarray
    width: np.ndarray
    points: np.ndarray
    oriented: np.ndarray

    def __len__(self) -> int:
        return int(self.x.shape[0])

    @staticmethod
    def empty() -> Detections:
        f = np.empty(0)
        return Detections(f, f, f, f, f, np.empty(0, np.int64), np.empty(0, bool))


def detect_objects(points, gap: float = 0.5, min_points: int = 3, min_width: float = 0.3) -> Detections:
    """Cluster world points ``(N, 2)`` (single linkage at ``gap`` m) and fit a box to each cluster
    of at least ``min_points``; a box is ``oriented`` when its width is at least ``min_width`` m."""
    p = np.ascontiguousarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ShapeError(f"points must have shape (N, 2), got {p.shape}")
    p = p[np.isfinite(p).all(axis=1)]
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
    pts = np.ascontiguousarray(p[chosen][order])
    counts = sizes[keep]
    starts = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    box = K.fit_boxes(pts, starts, FIT_STEPS, FIT_MIN_DISTANCE, np.empty((len(counts), 5)))
    oriented = box[:, 4] >= checks.non_negative("min_width", min_width, "metres")
    return Detections(box[:, 0], box[:, 1], box[:, 2], box[:, 3], box[:, 4], counts.astype(np.int64), oriented)
