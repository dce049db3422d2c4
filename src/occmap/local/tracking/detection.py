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

__all__ = ["Detections", "box_corners", "detect_objects"]

#: Largest gap (m) between the returns of one object.
DETECTION_GAP = 0.5
#: Bearing sectors over the full circle in which the occlusion test looks for nearer returns (0.25°).
BEARING_SECTORS = 1440
#: Directions tried by the L-shape fit over 90° (one per degree).
FIT_STEPS = 90
#: Floor of the closeness criterion's distance (m): points this close to an edge count alike.
FIT_MIN_DISTANCE = 0.01


class Detections(NamedTuple):
    """Per detected object: box centre ``x``, ``y`` (m, world), ``heading`` of its longer side
    (rad, in [−π/2, π/2): a box's heading is known modulo π), ``length`` ≥ ``width`` (m, extent of
    the points), ``points`` (how many), ``occluded`` (something nearer hides one of its ends from
    the sensor, so its extent may be cut short) and ``oriented``: an L-shaped cluster (two faces seen, both
    sides at least ``min_width``) whose box heading is the object's, up to π. A single face seen
    (a line of points) gives a box whose heading may be the object's side or its end."""

    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    length: np.ndarray
    width: np.ndarray
    points: np.ndarray
    occluded: np.ndarray
    oriented: np.ndarray

    def __len__(self) -> int:
        return int(self.x.shape[0])

    @staticmethod
    def empty() -> Detections:
        f = np.empty(0)
        return Detections(f, f, f, f, f, np.empty(0, np.int64), np.empty(0, bool), np.empty(0, bool))


def box_corners(x, y, heading, length, width) -> np.ndarray:
    """Corners ``(N, 4, 2)`` of boxes centred at ``(x, y)`` (N,) with ``heading`` (rad) along
    their ``length`` and ``width`` across (m): counter-clockwise from the rear right."""
    c, s = np.cos(heading)[:, None], np.sin(heading)[:, None]
    u = np.array([-0.5, 0.5, 0.5, -0.5])[None] * np.asarray(length)[:, None]
    v = np.array([-0.5, -0.5, 0.5, 0.5])[None] * np.asarray(width)[:, None]
    return np.stack([np.asarray(x)[:, None] + c * u - s * v, np.asarray(y)[:, None] + s * u + c * v], -1)


def detect_objects(points, gap: float = DETECTION_GAP, min_points: int = 3, min_width: float = 0.3, *, sensor=None,
                   scene=None, max_range: float | None = None, angle: float = math.radians(1.0),
                   depth: float = 0.3) -> Detections:
    """Cluster world points ``(N, 2)`` (single linkage at ``gap`` m) and fit a box to each cluster
    of at least ``min_points``; a box is ``oriented`` when its width is at least ``min_width`` m.

    With the ``sensor`` position (x, y) and the ``scene`` (all returns of the scan, ``(K, 2)``), a
    detection is ``occluded`` when a return within ``angle`` (rad, about two beams; in sectors of
    0.25°) beyond either of its angular ends is at least ``depth`` m nearer, or (given the sensor's
    ``max_range``) when a point of it lies within ``depth`` of the range limit, beyond which the
    rest may lie; without the sensor none is."""
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
    occluded = np.zeros(len(counts), bool)
    if sensor is not None:
        sx, sy = (checks.finite("sensor", v) for v in np.asarray(sensor, dtype=np.float64).reshape(-1)[:2])
    if sensor is not None and scene is not None:
        sc = np.ascontiguousarray(scene, dtype=np.float64)
        if sc.ndim != 2 or sc.shape[1] != 2:
            raise ShapeError(f"scene must have shape (K, 2), got {sc.shape}")
        depth = checks.non_negative("depth", depth, "metres")
        K.occluded_ends(pts, starts, sc, sx, sy, BEARING_SECTORS, checks.positive("angle", angle), depth, occluded)
    if sensor is not None and max_range is not None:
        far = np.hypot(pts[:, 0] - sx, pts[:, 1] - sy) >= checks.positive("max_range", max_range) - depth
        occluded |= np.add.reduceat(far, starts[:-1]) > 0 if len(counts) else occluded
    return Detections(box[:, 0], box[:, 1], box[:, 2], box[:, 3], box[:, 4], counts.astype(np.int64), occluded,
                      oriented)
