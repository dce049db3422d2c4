"""Costmap values, inflation and robot footprints, as in ROS Nav2's ``costmap_2d``.

Cost values (``nav2_costmap_2d/cost_values.hpp``): 0 free, 1–252 graded by distance to the
nearest obstacle, 253 inscribed (the robot's centre here puts an obstacle inside its inscribed
circle), 254 lethal (an obstacle in the cell), 255 unknown.

Inflation (Nav2's ``InflationLayer::computeCost``): with ``d`` the Euclidean distance in metres
between the cell's centre and the nearest lethal cell's centre,

* ``d = 0`` → 254, ``d ≤ r_inscribed`` → 253,
* ``r_inscribed < d ≤ inflation_radius`` → ``int(252 · exp(−k · (d − r_inscribed)))`` (k the
  cost scaling factor; the float is truncated as Nav2's cast to ``unsigned char`` does),
* beyond the inflation radius → 0 (free cells keep 0).

Unknown cells stay 255 unless within the inscribed radius of an obstacle, where they become 253
(Nav2's default ``inflate_unknown: false``). Defaults as Nav2: inflation radius 0.55 m, cost
scaling factor 10. Unlike Nav2, whose cell inflation radius is ``ceil(radius / resolution)``
cells, the radius here is exact in metres: a cell is inflated when ``d ≤ inflation_radius``.
Distances are exact (:mod:`occmap.raster.edt`): every cell gets the cost of its true nearest obstacle,
where Nav2's wavefront can be off by a cell at some angles.

Footprints follow Nav2: a polygon of (x, y) vertices in the robot's body frame (x forward),
or a radius. The polygon must be simple (no two edges cross or touch except neighbours at their
shared vertex) with non-zero area; :func:`validate_footprint` says which edges break the rule.
"""

from __future__ import annotations

import math

import numpy as np

from .. import checks
from ..errors import InvalidArgumentError, NonFiniteError, ShapeError
from . import _kernels as K

__all__ = [
    "FREE_SPACE", "INSCRIBED", "LETHAL", "NO_INFORMATION",
    "InflationParams", "cost_table", "inflate", "inscribed_radius", "circumscribed_radius",
    "validate_footprint",
]

FREE_SPACE = 0
INSCRIBED = 253
LETHAL = 254
NO_INFORMATION = 255


class InflationParams:
    """Inflation settings at one resolution, and the table of costs by squared cell distance.

    ``radius_cells`` (R) is the largest offset in cells along one axis that can receive a
    non-zero cost (or 253); ``table[d²]`` for ``d² = 0 … D + 1`` (D the largest squared cell
    distance within the radius) the cost of a free cell at squared distance d² (cells) from the
    nearest obstacle, the last entry 0 standing for everything beyond; ``inscribed_d2`` the
    largest d² within the inscribed radius.
    """

    def __init__(self, resolution: float, inflation_radius: float = 0.55, cost_scaling_factor: float = 10.0,
                 inscribed_radius: float = 0.0):
        self.resolution = checks.resolution(resolution)
        self.inflation_radius = checks.non_negative("inflation_radius", inflation_radius, "metres")
        self.cost_scaling_factor = checks.non_negative("cost_scaling_factor", cost_scaling_factor)
        self.inscribed_radius = checks.non_negative("inscribed_radius", inscribed_radius, "metres")
        reach = max(self.inflation_radius, self.inscribed_radius)
        R = int(math.floor(reach / self.resolution + 1e-9))
        self.radius_cells = R
        D = int(math.floor((reach / self.resolution) ** 2 + 1e-9))  # e.g. 30 for 0.55 m at 0.1 m, R = 5
        table = np.zeros(D + 2, dtype=np.uint8)
        inscribed_d2 = -1
        for d2 in range(D + 1):
            table[d2] = self.cost(math.sqrt(d2) * self.resolution)
            if d2 > 0 and math.sqrt(d2) * self.resolution <= self.inscribed_radius + 1e-9:
                inscribed_d2 = d2
        self.table = table
        self.inscribed_d2 = max(inscribed_d2, 0)

    def cost(self, distance: float) -> int:
        """Cost of a free cell ``distance`` metres (centre to centre) from the nearest obstacle."""
        if distance == 0.0:
            return LETHAL
        if distance <= self.inscribed_radius + 1e-9:
            return INSCRIBED
        if distance > self.inflation_radius + 1e-9:
            return FREE_SPACE
        return int((INSCRIBED - 1) * math.exp(-self.cost_scaling_factor * (distance - self.inscribed_radius)))


def cost_table(resolution: float, inflation_radius: float = 0.55, cost_scaling_factor: float = 10.0,
               inscribed_radius: float = 0.0) -> np.ndarray:
    """Costs (uint8) of free cells by squared distance in cells (see :class:`InflationParams`)."""
    return InflationParams(resolution, inflation_radius, cost_scaling_factor, inscribed_radius).table


def inflate(lethal, unknown=None, resolution: float = 0.05, inflation_radius: float = 0.55,
            cost_scaling_factor: float = 10.0, inscribed_radius: float = 0.0) -> np.ndarray:
    """The Nav2 costmap (uint8 (H, W)) of a grid given as masks: ``lethal`` (bool (H, W)) the
    obstacle cells, ``unknown`` (bool (H, W), optional) the unobserved ones; every other cell
    is free. The same kernel :meth:`LocalMap.costmap` runs."""
    lethal = np.asarray(lethal, dtype=bool)
    if lethal.ndim != 2:
        raise ShapeError(f"lethal must be a 2D mask, got shape {lethal.shape}")
    unknown = np.zeros_like(lethal) if unknown is None else np.asarray(unknown, dtype=bool)
    if unknown.shape != lethal.shape:
        raise ShapeError(f"unknown must have the shape of lethal {lethal.shape}, got {unknown.shape}")
    p = InflationParams(resolution, inflation_radius, cost_scaling_factor, inscribed_radius)
    H, W = lethal.shape
    cells = np.zeros((H, W, 2), dtype=np.float32)
    stamps = cells.view(np.int32)
    cells[..., 0] = np.where(lethal, 1.0, -1.0)
    stamps[..., 1] = np.where(unknown & ~lethal, 0, 1)
    out = np.empty((H, W), dtype=np.uint8)
    if H and W:
        K.costmap(cells, stamps, 0, 0, 0.5, -0.5, p.radius_cells, p.table, p.inscribed_d2,
                  np.empty((H, W), dtype=np.uint8 if p.radius_cells < 254 else np.int32), np.zeros((H, W), bool), out)
    return out


# ---------------------------------------------------------------------------------------------
# footprints


def _segments_cross(p1, p2, q1, q2) -> bool:
    """Whether closed segments p1p2 and q1q2 share a point (exact orientation tests)."""
    def orient(a, b, c):
        v = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
        return (v > 0) - (v < 0)

    def on(a, b, c):  # c on segment ab, given collinear
        return min(a[0], b[0]) <= c[0] <= max(a[0], b[0]) and min(a[1], b[1]) <= c[1] <= max(a[1], b[1])

    o1, o2, o3, o4 = orient(p1, p2, q1), orient(p1, p2, q2), orient(q1, q2, p1), orient(q1, q2, p2)
    if o1 != o2 and o3 != o4 and 0 not in (o1, o2, o3, o4):
        return True
    return ((o1 == 0 and on(p1, p2, q1)) or (o2 == 0 and on(p1, p2, q2))
            or (o3 == 0 and on(q1, q2, p1)) or (o4 == 0 and on(q1, q2, p2)))


def validate_footprint(footprint) -> np.ndarray:
    """The footprint as a float64 (M, 2) array of vertices, checked to be a simple polygon.

    Raises :class:`~occmap.errors.ShapeError` for a wrong shape or fewer than 3 vertices,
    :class:`~occmap.errors.NonFiniteError` for NaN/inf, and
    :class:`~occmap.errors.InvalidArgumentError` naming the offence for repeated vertices, zero
    area, or edges that cross or touch (a bow tie, a figure eight). A closing vertex equal to
    the first is dropped.
    """
    fp = np.array(footprint, dtype=np.float64)
    if fp.ndim != 2 or fp.shape[1] != 2:
        raise ShapeError(f"footprint must be an (M, 2) array of (x, y) vertices, got shape {fp.shape}")
    if not np.isfinite(fp).all():
        raise NonFiniteError("footprint vertices must be finite")
    if len(fp) >= 2 and np.array_equal(fp[0], fp[-1]):
        fp = fp[:-1]
    M = len(fp)
    if M < 3:
        raise ShapeError(f"footprint needs at least 3 distinct vertices, got {M}")
    nxt = np.roll(fp, -1, axis=0)
    zero = np.flatnonzero(np.all(fp == nxt, axis=1))
    if zero.size:
        raise InvalidArgumentError(f"footprint is not a simple polygon: vertices {zero[0]} and {(zero[0] + 1) % M} coincide")
    area = 0.5 * float(np.sum(fp[:, 0] * nxt[:, 1] - nxt[:, 0] * fp[:, 1]))
    if area == 0.0:
        raise InvalidArgumentError("footprint is not a simple polygon: its area is zero")
    pts = [tuple(p) for p in fp.tolist()]
    for i in range(M):
        a1, a2 = pts[i], pts[(i + 1) % M]
        for j in range(i + 1, M):
            b1, b2 = pts[j], pts[(j + 1) % M]
            if j == i + 1 or (i == 0 and j == M - 1):
                # neighbours share one vertex; they must not fold back along each other
                shared = a2 if j == i + 1 else a1
                other_a = a1 if j == i + 1 else a2
                other_b = b2 if j == i + 1 else b1
                if _collinear_overlap(shared, other_a, other_b):
                    raise InvalidArgumentError(
                        f"footprint is not a simple polygon: edges {i} and {j} fold back on each other")
                continue
            if _segments_cross(a1, a2, b1, b2):
                raise InvalidArgumentError(
                    f"footprint is not a simple polygon: edge {i} ({a1} → {a2}) and edge {j} ({b1} → {b2}) cross")
    return fp


def _collinear_overlap(shared, a, b) -> bool:
    """Edges shared→a and shared→b lie on one line on the same side of the shared vertex."""
    ux, uy = a[0] - shared[0], a[1] - shared[1]
    vx, vy = b[0] - shared[0], b[1] - shared[1]
    return ux * vy - uy * vx == 0 and ux * vx + uy * vy > 0


def _point_segment_distance(p, a, b) -> float:
    ab = b - a
    t = float(np.clip(np.dot(p - a, ab) / np.dot(ab, ab), 0.0, 1.0))
    return float(np.hypot(*(a + t * ab - p)))


def inscribed_radius(footprint) -> float:
    """Distance from the body origin to the nearest footprint edge (Nav2's
    ``calculateMinAndMaxDistances``); a radius footprint is its own inscribed radius."""
    if np.ndim(footprint) == 0:
        return float(footprint)
    fp = validate_footprint(footprint)
    o = np.zeros(2)
    return min(_point_segment_distance(o, fp[i], fp[(i + 1) % len(fp)]) for i in range(len(fp)))


def circumscribed_radius(footprint) -> float:
    """Distance from the body origin to the farthest footprint vertex."""
    if np.ndim(footprint) == 0:
        return float(footprint)
    fp = validate_footprint(footprint)
    return float(np.max(np.hypot(fp[:, 0], fp[:, 1])))


def as_footprint(footprint) -> tuple[np.ndarray, float]:
    """``(vertices (M, 2), radius)`` for the kernels: a polygon gives radius −1, a radius gives
    an empty vertex array."""
    if np.ndim(footprint) == 0:
        return np.zeros((0, 2)), checks.non_negative("footprint radius", footprint, "metres")
    return validate_footprint(footprint), -1.0
