"""The likelihood field of a map: AMCL's measurement model (Thrun et al., *Probabilistic Robotics* §6.4).

The distance ``d`` from a beam's end point to the nearest occupied cell is precomputed once for
the whole map with the exact Euclidean distance transform (:mod:`occmap.raster.edt`) and clamped
at ``laser_likelihood_max_dist``; each beam scores ``pz = z_hit · exp(−d² / 2σ²) + z_rand / D`` with
``D`` the clamp (``z_rand_span="field"``: the random term is a share of beams spread over the distances
the field tells apart) or, as AMCL, the sensor's ``max_range`` (``z_rand_span="range"``).
Only occupied cells (occupancy above ``occupied_thresh``) are obstacles; an end point in an
unknown cell scores by its distance like any other, one off the map as if ``max_dist`` away.
Beams combine as a product (the sum of ``beam_exponent · log pz``) or by AMCL's ``1 + Σ pz³``
(``model="amcl"``, scored as ``log(1 + Σ pz³)``). Per-cell scores are tabulated once per
``(max_range, σ)``, so the kernel's work per beam is a table look-up.

The field is cropped to the obstacles' bounding box grown by ``max_dist`` (+ 1 cell): every end
point outside it is at least ``max_dist`` from any obstacle and scores like one off the map.
Cells are ``(row, col) = (iy, ix)`` from ``origin``, the outer corner of cell (0, 0), as every grid.
"""

from __future__ import annotations

import math

import numpy as np

from .._threads import ThreadChoice
from ..errors import InvalidArgumentError
from ..geometry.so2 import wrap_angle
from ..raster.edt import distance_transform
from . import _kernels as K
from .params import LocalizationParams

__all__ = ["LikelihoodField", "beam_end_points"]

#: Tables of (max range, σ) kept before the cache starts again.
_TABLES = 8


class LikelihoodField:
    """The distance field of an :class:`~occmap.grid2d.OccupancyGrid2D` and the beam scores on it.

    Attributes
    ----------
    resolution : float
        Cell size (m).
    origin : ndarray (2,)
        World position (m) of the outer corner of cell (0, 0) of the cropped field.
    occupied, free : ndarray (H, W) bool
        Obstacle cells and free cells (where particles may be placed) of the cropped field.
    free_cells : ndarray (k,) int64
        Flat indices of the free cells.
    distance : ndarray (H, W) float64
        Distance (m) from each cell's centre to the nearest obstacle, clamped at ``max_dist``.
    max_dist : float
        The clamp (``params.laser_likelihood_max_dist``).
    """

    #: One thread or all, per call, by their measured cost per particle × beam (calls with fewer
    #: than ``THREADS.min_work`` take one thread).
    THREADS = ThreadChoice(min_work=500_000)

    def __init__(self, grid, params: LocalizationParams):
        H, W = grid.shape
        if H == 0 or W == 0 or grid.origin is None:
            raise InvalidArgumentError("the map is empty (no cells): build or load a map before localizing in it")
        self.params = params
        occ = grid.occupancy()
        known = occ >= 0
        occupied = known & (occ > 100.0 * params.occupied_thresh)
        free = known & (occ < 100.0 * params.free_thresh)
        if not occupied.any():
            raise InvalidArgumentError("the map has no occupied cell: there is nothing to localize against")
        if not free.any():
            raise InvalidArgumentError("the map has no free cell: there is nowhere to place particles")
        self.max_dist = params.laser_likelihood_max_dist
        self.resolution = float(grid.resolution)
        ys, xs = np.nonzero(occupied)
        m = int(math.ceil(self.max_dist / self.resolution)) + 1
        y0, y1 = max(0, ys.min() - m), min(H, ys.max() + m + 1)
        x0, x1 = max(0, xs.min() - m), min(W, xs.max() + m + 1)
        occupied = np.ascontiguousarray(occupied[y0:y1, x0:x1])
        free = np.ascontiguousarray(free[y0:y1, x0:x1])
        if not free.any():
            raise InvalidArgumentError("the map has no free cell near its obstacles: there is nowhere to place particles")
        self.origin = np.array(grid.origin, dtype=np.float64) + np.array([x0, y0]) * self.resolution
        self.occupied = occupied
        self.free = free
        self.free_cells = np.flatnonzero(free.ravel())
        dist = distance_transform(occupied, self.resolution)
        np.minimum(dist, self.max_dist, out=dist)
        self.distance = dist
        self._tables: dict[tuple[float, float], tuple[np.ndarray, float]] = {}

    def table(self, max_range: float, sigma: float) -> tuple[np.ndarray, float]:
        """Per-cell beam score (float32 (H, W)) for scans of this max range with a hit term of
        this standard deviation, and the score off the map."""
        hit = self._tables.get((max_range, sigma))
        if hit is not None:
            return hit
        if len(self._tables) > _TABLES:
            self._tables.clear()
        p = self.params
        rand = p.z_rand / (self.max_dist if p.z_rand_span == "field" else max_range)
        d = np.concatenate([self.distance.ravel(), [self.max_dist]])
        pz = p.z_hit * np.exp(-(d * d) / (2.0 * sigma ** 2)) + rand
        if p.model == "product":
            score = p.beam_exponent * np.log(np.maximum(pz, 1e-300))
        else:
            score = pz ** 3
        table = score[:-1].reshape(self.distance.shape).astype(np.float32)
        out = (table, float(score[-1]))
        self._tables[(max_range, sigma)] = out
        return out

    def score(self, particles: np.ndarray, bx: np.ndarray, by: np.ndarray, max_range: float,
              sigma: float) -> np.ndarray:
        """Log-likelihood (N,) of end points ``(bx, by)`` (particle frame, m) seen from each of
        ``particles`` (N, 3)."""
        table, outside = self.table(max_range, sigma)
        out = np.empty(len(particles))
        with self.THREADS.choose(len(particles) * bx.size) as parallel:
            fn = K.score_particles_parallel if parallel else K.score_particles
            fn(particles, bx, by, table, outside, self.origin[0], self.origin[1], 1.0 / self.resolution, out)
        if self.params.model == "amcl":
            out = np.log1p(out)
        return out

    def distances(self, pose, bx: np.ndarray, by: np.ndarray) -> np.ndarray:
        """Distance (m) from each end point ``(bx, by)`` (pose frame) seen from ``pose``
        ``(x, y, theta)`` to the nearest obstacle, ``max_dist`` off the map."""
        x, y, t = (float(v) for v in pose)
        c, s = math.cos(t), math.sin(t)
        inv = 1.0 / self.resolution
        ix = np.floor((x + c * bx - s * by - self.origin[0]) * inv).astype(np.int64)
        iy = np.floor((y + s * bx + c * by - self.origin[1]) * inv).astype(np.int64)
        H, W = self.distance.shape
        inside = (ix >= 0) & (iy >= 0) & (ix < W) & (iy < H)
        d = np.full(np.shape(bx), self.max_dist)
        d[inside] = self.distance[iy[inside], ix[inside]]
        return d

    def uniform_free(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` poses (n, 3) uniform over the free cells, headings uniform in (−π, π]."""
        cells = self.free_cells[rng.integers(0, self.free_cells.size, n)]
        W = self.free.shape[1]
        iy, ix = np.divmod(cells, W)
        out = np.empty((n, 3))
        u = rng.random((n, 3))
        out[:, 0] = self.origin[0] + (ix + u[:, 0]) * self.resolution
        out[:, 1] = self.origin[1] + (iy + u[:, 1]) * self.resolution
        out[:, 2] = wrap_angle(-np.pi + 2.0 * np.pi * u[:, 2])
        return out


def beam_end_points(ranges: np.ndarray, angles: np.ndarray, max_range: float, params: LocalizationParams):
    """End points ``(bx, by, bx_all, by_all)`` in the particle frame: of at most ``max_beams`` beams
    evenly spread over the valid readings, and of all valid readings. Valid: finite, above
    ``laser_min_range``, below ``max_range`` (a reading at or beyond it had no return)."""
    r, a = ranges, angles
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(r) & np.isfinite(a) & (r > params.laser_min_range) & (r < max_range)
    idx = np.flatnonzero(ok)
    ox, oy, ot = params.sensor_offset
    rr, aa = r[idx], a[idx] + ot
    x_all = ox + rr * np.cos(aa)
    y_all = oy + rr * np.sin(aa)
    if idx.size > params.max_beams:
        pick = np.rint(np.linspace(0, idx.size - 1, params.max_beams)).astype(np.int64)
        return (np.ascontiguousarray(x_all[pick]), np.ascontiguousarray(y_all[pick]), x_all, y_all)
    return x_all, y_all, x_all, y_all
