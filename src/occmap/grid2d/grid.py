"""The 2D occupancy grid: per-cell log-odds under the static-state binary Bayes filter.

Grid conventions (cells ``(iy, ix)``, the origin at the outer corner of cell (0, 0), the index
rule): :mod:`occmap.raster`. Each cell holds ``l = log(p / (1 − p))``, updated
``l ← clamp(l + l_sensor − l_prior)`` at most once per scan (:mod:`occmap.raster.update`); a cell
no reading ever touched is *unknown*.

Method and parameter names follow the vocabulary the three maps share (``docs/architecture.md``).
"""

from __future__ import annotations

import math

import numpy as np

from .. import checks
from .._threads import OneCallAtATime
from ..errors import InvalidArgumentError, NonFiniteError, ShapeError
from ..logodds import logit, occupancy_classes, occupancy_values, probability
from ..raster.update import SEEN, UNSEEN, ScanCodes
from . import _kernels as K
from .sensor_models import LidarModel, RadarModel, SonarModel, radar_sweeps

#: Default largest side of a growing map, metres (``max_extent``).
DEFAULT_MAX_EXTENT = 10_000.0

#: Cells added on each side when a growing map must grow, at least (amortises the copies).
_GROW_MARGIN_CELLS = 64
_FIRST_MARGIN_CELLS = 4096


def _new_cells(shape, l_prior: float) -> tuple[np.ndarray, np.ndarray]:
    """Cell storage: float32 log-odds at the prior and uint16 stamps, UNSEEN (0), both (H, W).
    Zeroed buffers come from the OS and are only paged in where rays go."""
    L = np.zeros(shape, dtype=np.float32) if l_prior == 0.0 else np.full(shape, l_prior, dtype=np.float32)
    return L, np.zeros(shape, dtype=np.uint16)


def beam_points(P: np.ndarray, R: np.ndarray, A: np.ndarray, max_range: float) -> tuple[np.ndarray, np.ndarray]:
    """World x and y (N, 1 + n) of each scan's sensor position (column 0) and of the beam ends
    that will be used (columns 1..n: ranges capped at ``max_range``; NaN for dropped readings)."""
    r = np.where(R > 0, np.minimum(R, max_range), np.nan)  # NaN stays NaN: dropped beams
    a = P[:, 2:3] + A
    x = np.concatenate([P[:, 0:1], P[:, 0:1] + r * np.cos(a)], axis=1)
    y = np.concatenate([P[:, 1:2], P[:, 1:2] + r * np.sin(a)], axis=1)
    return x, y


def _farthest(x: np.ndarray, y: np.ndarray, centre: np.ndarray | None) -> tuple[int, ...]:
    """Index into ``x``/``y`` of the point farthest (Chebyshev) from ``centre`` (``None``: the
    first point), NaN left out."""
    if centre is None:
        centre = (x.flat[0], y.flat[0])
    d = np.fmax(np.abs(x - centre[0]), np.abs(y - centre[1]))
    return np.unravel_index(int(np.nanargmax(d)), d.shape)


def scan_arrays(poses, ranges, angles, max_range):
    """The checked arrays of :meth:`OccupancyGrid2D.insert_scans` (its conventions), for every map
    that takes planar scans: ``(P, R, A, max_range)``, poses (N, 3), ranges (N, n) and angles
    (N, n) C-contiguous float64, a reading with a NaN or infinite angle turned into a NaN (dropped)
    reading, and ``max_range`` a positive float (without one: just above the largest finite
    reading, infinite readings dropped)."""
    P = np.ascontiguousarray(poses, dtype=np.float64)
    R = np.ascontiguousarray(ranges, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise ShapeError(f"poses must have shape (N, 3), got {P.shape}")
    if R.ndim != 2 or R.shape[0] != P.shape[0]:
        raise ShapeError(f"ranges must have shape (N, n) with N = {P.shape[0]} poses, got {R.shape}")
    A = np.asarray(angles, dtype=np.float64)
    if A.shape == (R.shape[1],):
        A = np.broadcast_to(A, R.shape)
    if A.shape != R.shape:
        raise ShapeError(f"angles must have shape (n,) or (N, n) matching ranges {R.shape}, got {A.shape}")
    A = np.ascontiguousarray(A)
    bad_angle = ~np.isfinite(A)
    if bad_angle.any():  # a beam without a direction is a dropped reading
        R, A = np.where(bad_angle, np.nan, R), np.where(bad_angle, 0.0, A)
    good_pose = np.isfinite(P).all(axis=1)
    if not good_pose.all():
        raise NonFiniteError(f"poses[{int(np.argmin(good_pose))}] = {P[np.argmin(good_pose)].tolist()} is not finite")
    if max_range is None:
        # no sensor limit given: every finite reading is a return, an infinite one says
        # nothing definite and is dropped like NaN
        finite = R[np.isfinite(R) & (R > 0)]
        max_range = float(np.nextafter(finite.max(), np.inf)) if finite.size else 1.0
        if np.isinf(R).any():
            R = np.where(np.isinf(R), np.nan, R)
    return P, R, A, checks.positive("max_range", max_range, "metres")


class OccupancyGrid2D(OneCallAtATime):
    """A 2D occupancy grid in log-odds.

    Parameters
    ----------
    resolution : float
        Cell side in metres.
    size : (width, height) in metres, optional
        Fixed extent. ``None`` (default) makes a map that grows to fit what it is given; a fixed
        map ignores the parts of rays outside it.
    origin : (x, y), optional
        World position of the outer corner of cell (0, 0) of a fixed map (default (0, 0)). A
        growing map's cells are those of the *world lattice*: cell ``(i, j)`` covers
        ``[ox + i·res, ox + (i+1)·res) × [oy + j·res, oy + (j+1)·res)`` with ``(ox, oy)`` this
        ``origin`` (default (0, 0)), found as ``floor((x − ox) · (1/res))``; the map is the box
        of lattice cells holding every sensor position and beam end it was given (:attr:`origin`
        reports that box's corner). Its cells and extent therefore do not depend on how the
        scans were split into calls, and equal a tiled map's (:mod:`occmap.world`).
    prior : float
        Prior occupancy probability of every cell (0.5: no prior knowledge).
    clamp : (p_min, p_max)
        Clamping bounds in probability (OctoMap's defaults), keeping cells able to change.
    occupied_threshold : float
        Probability at or above which an observed cell counts as occupied in :meth:`occupancy_at`
        (OctoMap's 0.5).
    max_extent : float or None
        Largest side, in metres, a growing map may reach (default 10 km: 40 M cells at 5 cm
        already take 200 MB). An insertion that would grow it further raises
        :class:`~occmap.errors.InvalidArgumentError` naming the pose or beam that asked, and
        changes nothing. ``None``: no limit. Ignored by a fixed map.
    """

    def __init__(self, resolution: float, size=None, origin=None, prior: float = 0.5, clamp=(0.1192, 0.971),
                 occupied_threshold: float = 0.5, max_extent: float | None = DEFAULT_MAX_EXTENT):
        self.resolution = checks.resolution(resolution)
        self.max_extent = None if max_extent is None else checks.positive("max_extent", max_extent, "metres")
        if origin is not None:
            o = np.asarray(origin, dtype=np.float64)
            if o.shape != (2,):
                raise ShapeError(f"origin must be (x, y), got shape {o.shape}")
            origin = (checks.finite("origin[0]", o[0]), checks.finite("origin[1]", o[1]))
        self.l_prior = logit(prior, "prior")
        self.l_min, self.l_max = logit(clamp[0], "clamp[0]"), logit(clamp[1], "clamp[1]")
        if not self.l_min < self.l_prior < self.l_max:
            raise InvalidArgumentError(f"prior {prior!r} must lie strictly between the clamping bounds {clamp!r}")
        self.occupied_threshold = checks.probability("occupied_threshold", occupied_threshold)
        self._l_occ = logit(self.occupied_threshold)
        self.growing = size is None
        self._codes = ScanCodes(np.uint16)
        self.stats = {"scans": 0, "points": 0, "dropped": 0, "beyond_max_range": 0}
        # the lattice: cell (i, j) is floor((p − anchor) · (1/res)); storage cell [r, c] is the
        # lattice cell offset + (c, r); the map is the lattice box window = (x0, y0, x1, y1),
        # half-open (None: an empty growing map). A fixed map's storage is its window.
        self._anchor = np.zeros(2) if origin is None else np.array(origin, dtype=np.float64)
        self._offset = (0, 0)
        if size is None:
            self._window = None
            shape = (0, 0)
        else:
            w, h = size
            w, h = checks.positive("size[0] (width)", w, "metres"), checks.positive("size[1] (height)", h, "metres")
            shape = (int(math.ceil(h / self.resolution - 1e-9)), int(math.ceil(w / self.resolution - 1e-9)))
            self._window = (0, 0, shape[1], shape[0])
        self._L, self._stamp = _new_cells(shape, self.l_prior)

    # ------------------------------------------------------------------ geometry

    @property
    def shape(self) -> tuple[int, int]:
        """(height, width) in cells."""
        if self._window is None:
            return (0, 0)
        x0, y0, x1, y1 = self._window
        return (y1 - y0, x1 - x0)

    @property
    def origin(self) -> np.ndarray | None:
        """World position (x, y) of the outer corner of cell (0, 0); ``None`` for an empty growing
        map."""
        if self._window is None:
            return None
        return self._anchor + np.array(self._window[:2]) * self.resolution

    def _corner(self) -> np.ndarray:
        """Lattice cell (x, y) of the map's cell (0, 0)."""
        return np.array((0, 0) if self._window is None else self._window[:2], dtype=np.int64)

    def _cells(self) -> tuple[np.ndarray, np.ndarray]:
        """Views (log-odds, stamps) (H, W) of the map's cells in the storage."""
        if self._window is None:
            return self._L, self._stamp
        x0, y0, x1, y1 = self._window
        gx0, gy0 = self._offset
        rows, cols = slice(y0 - gy0, y1 - gy0), slice(x0 - gx0, x1 - gx0)
        return self._L[rows, cols], self._stamp[rows, cols]

    def world_to_cell(self, points) -> np.ndarray:
        """Integer cells ``(iy, ix)`` (..., 2) of world points (..., 2); not clipped to the map."""
        p = np.asarray(points, dtype=np.float64)
        if p.shape[-1:] != (2,):
            raise ShapeError(f"points must have shape (..., 2), got {p.shape}")
        cell = np.floor((p - self._anchor) * (1.0 / self.resolution)).astype(np.int64) - self._corner()
        return cell[..., ::-1]

    def cell_to_world(self, cells) -> np.ndarray:
        """World centres (..., 2) of cells ``(iy, ix)`` (..., 2)."""
        c = np.asarray(cells)
        if c.shape[-1:] != (2,):
            raise ShapeError(f"cells must have shape (..., 2), got {c.shape}")
        return self._anchor + (c[..., ::-1] + self._corner() + 0.5) * self.resolution

    # ------------------------------------------------------------------ read-outs

    def log_odds(self) -> np.ndarray:
        """Log-odds per cell (a copy, float32, (H, W), row 0 at the origin), NaN where unobserved."""
        L, stamp = self._cells()
        return np.where(stamp != UNSEEN, L, np.float32(np.nan))

    @property
    def observed(self) -> np.ndarray:
        """True for cells some reading has touched."""
        return self._cells()[1] != UNSEEN

    def probability(self) -> np.ndarray:
        """Occupancy probability per cell (float64); unobserved cells hold the prior."""
        return probability(self._cells()[0])

    def occupancy(self) -> np.ndarray:
        """nav_msgs/OccupancyGrid values (int8, (H, W), row 0 at the origin): −1 unknown, else
        round(100·p)."""
        return occupancy_values(self.log_odds())

    def maximum_likelihood(self) -> np.ndarray:
        """int8 map: 1 occupied (l > 0), 0 free (observed, l ≤ 0), −1 never observed."""
        ml = np.where(self._cells()[0] > 0, 1, 0).astype(np.int8)
        ml[~self.observed] = -1
        return ml

    def log_odds_at(self, points) -> np.ndarray:
        """Log-odds (float64, shape (...)) at world points (..., 2); NaN outside the map or where
        unobserved (NaN points too)."""
        p = np.asarray(points, dtype=np.float64)
        good = np.isfinite(p).all(axis=-1)
        cells = self.world_to_cell(np.where(good[..., None], p, 0.0))
        iy, ix = cells[..., 0], cells[..., 1]
        H, W = self.shape
        inside = good & (iy >= 0) & (iy < H) & (ix >= 0) & (ix < W)
        out = np.full(iy.shape, np.nan)
        jy, jx = iy[inside], ix[inside]
        L, stamp = self._cells()
        out[inside] = np.where(stamp[jy, jx] != UNSEEN, L[jy, jx], np.nan)
        return out

    def log_odds_in(self, lo, hi) -> tuple[np.ndarray, np.ndarray]:
        """Log-odds (a copy, float32, NaN where unobserved) of the map's cells that overlap the world
        box from ``lo = (xmin, ymin)`` to ``hi = (xmax, ymax)``, clipped to the map (possibly
        empty), and the world position of the outer corner of its cell (0, 0). Costs the box, not
        the map: what a local submap reads of a growing map."""
        H, W = self.shape
        (iy0, ix0), (iy1, ix1) = self.world_to_cell(np.array([lo, hi], dtype=np.float64))
        ix0, iy0 = min(max(ix0, 0), W), min(max(iy0, 0), H)
        ix1, iy1 = min(max(ix1 + 1, ix0), W), min(max(iy1 + 1, iy0), H)
        L, stamp = self._cells()
        window = np.where(stamp[iy0:iy1, ix0:ix1] != UNSEEN, L[iy0:iy1, ix0:ix1], np.float32(np.nan))
        corner = self._anchor + (np.array([ix0, iy0]) + self._corner()) * self.resolution
        return window, corner

    def occupancy_at(self, points) -> np.ndarray:
        """Per world point (..., 2), int8: −1 unknown or outside the map, 1 occupied
        (``p ≥ occupied_threshold``), else 0 free."""
        return occupancy_classes(self.log_odds_at(points), self._l_occ)

    # ------------------------------------------------------------------ insertion

    def insert_scan(self, pose, ranges, angles, max_range: float | None = None, model: LidarModel | None = None) -> dict:
        """Insert one scan from sensor pose ``(x, y, theta)``; see :meth:`insert_scans`."""
        r = np.asarray(ranges, dtype=np.float64)
        return self.insert_scans(np.asarray(pose, dtype=np.float64)[None], r[None], angles, max_range, model)

    def insert_scans(self, poses, ranges, angles, max_range: float | None = None, model: LidarModel | None = None) -> dict:
        """Insert N scans in one call.

        ``poses`` (N, 3) are sensor poses ``(x, y, theta)``; ``ranges`` (N, n) in metres;
        ``angles`` (n,) or (N, n) beam angles relative to the sensor heading. A reading at or
        beyond ``max_range``, or infinite, frees the cells up to ``max_range`` and marks nothing;
        NaN, zero and negative readings, and readings whose angle is NaN or infinite, are dropped
        and counted. Without ``max_range`` every
        finite reading is a return and infinite ones are dropped too. Within one scan a cell is
        updated at most once and a hit wins over a miss. Returns the counts of this call:
        ``scans``, ``points`` (readings used), ``dropped``, ``beyond_max_range``.
        """
        model = LidarModel() if model is None else model
        P, R, A, max_range = scan_arrays(poses, ranges, angles, max_range)
        fresh = False  # new storage: this call touches its pages first
        if self.growing and len(P):
            def culprit(centre):
                x, y = beam_points(P, R, A, max_range)
                i, j = _farthest(x, y, centre)
                if j == 0:
                    return f"poses[{i}] = {P[i].tolist()}"
                return (f"beam {j - 1} of scan {i} (poses[{i}] = {P[i].tolist()}, ranges[{i}, {j - 1}] = "
                        f"{float(R[i, j - 1])!r}) ending at ({float(x[i, j])!r}, {float(y[i, j])!r})")

            fresh = self._grow_to(*K.beam_extent(P, R, A, float(max_range)), culprit)
        (ox, oy), (gx0, gy0) = self._anchor, self._offset
        used, dropped, maxed = self._in_runs(len(P), lambda i, j, code: K.integrate_lidar(
            self._L, self._stamp, code, P[i:j], R[i:j], A[i:j], float(max_range), float(ox), float(oy), gx0, gy0,
            1.0 / self.resolution, model.l_hit - self.l_prior, model.l_miss - self.l_prior, self.l_min, self.l_max,
            fresh=fresh,
        ))
        return self._record(len(P), used, dropped, maxed)

    def insert_sonar(self, poses, ranges, bearings, max_range: float, model: SonarModel | None = None) -> dict:
        """Insert rings of sonar readings with the cone model of :class:`SonarModel`.

        ``poses`` (3,) or (N, 3) are robot poses; ``ranges`` (k,) or (N, k) in metres, one per
        transducer; ``bearings`` (k,) the transducers' directions relative to the heading. Each
        reading updates each cell of its cone once; overlapping cones of one ring each contribute
        (the readings are independent measurements). NaN, zero and negative readings, and those
        below ``model.min_range``, are dropped and counted; readings at or beyond ``max_range``
        clear their cone up to it (with ``model.ignore_max_range``, those beyond it are only
        counted). Nothing beyond ``max_range`` is touched.
        ``model.sectors``, ``weighting`` and ``wrap_angles`` choose which cells a reading speaks
        about and how loudly (see :class:`SonarModel`).
        """
        model = SonarModel() if model is None else model
        P = np.atleast_2d(np.asarray(poses, dtype=np.float64))
        R = np.atleast_2d(np.asarray(ranges, dtype=np.float64))
        B = np.ascontiguousarray(bearings, dtype=np.float64)
        if P.shape[1:] != (3,) or R.shape[0] != P.shape[0] or B.shape != (R.shape[1],):
            raise ShapeError(f"expected poses (N, 3), ranges (N, k), bearings (k,); got {P.shape}, {R.shape}, {B.shape}")
        if not np.isfinite(P).all():
            raise NonFiniteError("sonar poses must be finite")
        max_range = checks.positive("max_range", max_range, "metres")
        arc = self.resolution if model.arc is None else model.arc
        if self.growing and len(P):
            reach = max_range + arc

            def culprit(centre):
                i = _farthest(P[:, 0], P[:, 1], centre)[0]
                return f"poses[{i}] = {P[i].tolist()} (with its cones reaching {reach!r} m)"

            self._grow_to(P[:, 0].min() - reach, P[:, 1].min() - reach, P[:, 0].max() + reach, P[:, 1].max() + reach,
                          culprit)
        lo, hi = model.sector_bounds(B)
        P, R = np.ascontiguousarray(P), np.ascontiguousarray(R)
        (ox, oy), (gx0, gy0) = self._anchor, self._offset
        used, dropped, maxed = self._in_runs(len(P), lambda i, j, code: K.integrate_sonar(
            self._L, self._stamp, code, P[i:j], R[i:j], B, lo, hi,
            0.5 * model.beam_width, bool(model.wrap_angles), model.weighting == "uniform", float(model.min_range),
            float(max_range), bool(model.ignore_max_range), float(arc), float(ox), float(oy), gx0, gy0,
            self.resolution, model.l_hit - self.l_prior, model.l_miss - self.l_prior, self.l_min, self.l_max,
        ))
        return self._record(len(P), used, dropped, maxed)

    def insert_radar(self, poses, ranges, azimuths, max_range: float, *, sweeps=None, radial_velocity=None,
                     ego_velocity=None, model: RadarModel | None = None) -> dict:
        """Insert radar detections with the wedge model of :class:`RadarModel`.

        ``poses`` (3,) or (N, 3) sensor poses (x, y, heading) of N sweeps; ``ranges`` and
        ``azimuths`` (M,) the detections (metres; radians from the heading, counter-clockwise);
        ``sweeps`` (M,) each detection's pose index (needed when N > 1). With
        ``radial_velocity`` (M,) (m/s, positive moving away, the sensor's own motion included)
        and ``ego_velocity`` (2,) or (N, 2) (the sensor's world velocity), detections on moving
        objects only clear. Detections with NaN or infinite values or a range ≤ 0 are dropped and
        counted; those at or beyond ``max_range`` are counted and say nothing. Sweeps are applied
        in order, each detection of a sweep on its own. Returns the counts of this call:
        ``scans`` (sweeps), ``points`` (detections used), ``dropped``, ``beyond_max_range``,
        ``moving`` (detections the Doppler says move: they only clear) and ``ghosts`` (behind a
        known obstacle: not used).
        """
        model = RadarModel() if model is None else model
        d = radar_sweeps(poses, ranges, azimuths, max_range, model, sweeps, radial_velocity, ego_velocity)
        order = np.lexsort((d.range, d.azimuth, d.sweep))  # any order in: the same map out
        S, R, A, M = d.sweep[order], d.range[order], d.azimuth[order], d.moving[order]
        reach = R + model.extent * max(model.sigma_range, self.resolution)
        if self.growing and len(R):
            heading = d.poses[S, 2] + A
            x = d.poses[S, 0] + reach * np.cos(heading)
            y = d.poses[S, 1] + reach * np.sin(heading)
            spread = model.extent * self.resolution

            def culprit(centre):
                i = _farthest(x, y, centre)[0]
                return f"the detection at range {float(R[i])!r} of sweep {int(S[i])} (poses[{int(S[i])}] = " \
                       f"{d.poses[S[i]].tolist()})"

            self._grow_to(min(x.min(), d.poses[:, 0].min()) - spread, min(y.min(), d.poses[:, 1].min()) - spread,
                          max(x.max(), d.poses[:, 0].max()) + spread, max(y.max(), d.poses[:, 1].max()) + spread,
                          culprit)
        bounds = np.searchsorted(S, np.arange(len(d.poses) + 1))
        (ox, oy), (gx0, gy0) = self._anchor, self._offset
        l_obstacle = logit(model.obstacle_probability)
        ghosts = 0

        def integrate(i, j, code):
            nonlocal ghosts
            a = bounds[i]
            used, g = K.integrate_radar(
                self._L, self._stamp, code, d.poses[i:j], bounds[i:j + 1] - a, R[a:], A[a:], M[a:], model.sigma_range,
                model.extent, model.ghost_margin, float(ox), float(oy), gx0, gy0, self.resolution,
                model.l_hit - self.l_prior, model.l_miss - self.l_prior, l_obstacle, self.l_min, self.l_max)
            ghosts += g
            return used, 0, 0

        used, _, _ = self._in_runs(len(d.poses), integrate)
        counts = self._record(len(d.poses), used, d.dropped, d.beyond_max_range)
        return {**counts, "moving": int(M.sum()), "ghosts": int(ghosts)}

    def _in_runs(self, n: int, integrate) -> tuple[int, int, int]:
        """Integrate a call's ``n`` scans as ``integrate(i, j, code)`` over runs ``[i, j)`` whose
        stamp codes ``code .. code + j − i − 1`` fit the uint16 stamps (:class:`ScanCodes`);
        returns the summed counts."""
        totals = np.zeros(3, dtype=np.int64)
        i = 0
        while i < n:
            code, k = self._codes.take(n - i, self._cells()[1])  # cells outside the window are all UNSEEN
            totals += integrate(i, i + k, code)
            i += k
        return tuple(totals)

    def _record(self, scans: int, points, dropped, maxed) -> dict:
        """Add one call's counts to :attr:`stats`; returns them."""
        counts = {"scans": scans, "points": int(points), "dropped": int(dropped), "beyond_max_range": int(maxed)}
        for key, value in counts.items():
            self.stats[key] += value
        return counts

    def _grow_to(self, xmin: float, ymin: float, xmax: float, ymax: float, culprit) -> bool:
        """Extend the map to the lattice cells holding the world box (never shrink it), so that
        its extent is the union of the boxes it was given, whatever the calls. The storage grows
        with a margin proportional to its size (amortising the copies), never past
        ``max_extent``. Beyond it, raise naming ``culprit(centre)``: the point farthest from the
        map's centre (``None`` for an empty map: from the call's first sensor position). Returns
        whether the storage is new."""
        res = self.resolution
        if not math.isfinite(xmin + ymin + xmax + ymax):  # readings so long their ends overflow
            raise InvalidArgumentError(f"{culprit(None)} lies beyond any map (its coordinates overflow)")
        inv = 1.0 / res  # the index rule of the kernels (occmap.raster), in the same float64 steps
        (ax, ay), box = self._anchor, self._window
        x0, y0 = math.floor((xmin - ax) * inv), math.floor((ymin - ay) * inv)
        x1, y1 = math.floor((xmax - ax) * inv) + 1, math.floor((ymax - ay) * inv) + 1
        if box is not None:
            x0, y0, x1, y1 = min(x0, box[0]), min(y0, box[1]), max(x1, box[2]), max(y1, box[3])
        need_w, need_h = x1 - x0, y1 - y0
        limit = math.inf if self.max_extent is None else math.floor(self.max_extent / res + 1e-9)
        if max(need_w, need_h) > limit:
            centre = None if box is None else self._anchor + 0.5 * res * np.array([box[0] + box[2], box[1] + box[3]])
            raise InvalidArgumentError(
                f"{culprit(centre)} would grow the map to {need_w * res:.6g} m × {need_h * res:.6g} m, beyond "
                f"max_extent = {self.max_extent!r} m per side (an outlier? drop it, or raise max_extent; None: "
                f"no limit)")
        self._window = (x0, y0, x1, y1)
        (gx0, gy0), (H, W) = self._offset, self._L.shape
        if H and gx0 <= x0 and gy0 <= y0 and x1 <= gx0 + W and y1 <= gy0 + H:
            return False
        # half the storage's size on a growing side, and half the box's size (at most
        # _FIRST_MARGIN_CELLS) round the first storage: a robot's first scans show much of the
        # place, so the map then grows rarely (each growth copies the map)
        first_x, first_y = (min(need_w // 2, _FIRST_MARGIN_CELLS), min(need_h // 2, _FIRST_MARGIN_CELLS)) \
            if not H else (0, 0)
        margin_x = min(max(_GROW_MARGIN_CELLS, W // 2, first_x), min(limit - need_w, 2**62) // 2)
        margin_y = min(max(_GROW_MARGIN_CELLS, H // 2, first_y), min(limit - need_h, 2**62) // 2)
        sx0 = x0 - margin_x if not H or x0 < gx0 else gx0
        sy0 = y0 - margin_y if not H or y0 < gy0 else gy0
        sx1 = x1 + margin_x if not H or x1 > gx0 + W else gx0 + W
        sy1 = y1 + margin_y if not H or y1 > gy0 + H else gy0 + H
        L, stamp = _new_cells((sy1 - sy0, sx1 - sx0), self.l_prior)
        if box is not None:  # only the old window: the margins around it were never written
            rows, cols = slice(box[1] - gy0, box[3] - gy0), slice(box[0] - gx0, box[2] - gx0)
            L[box[1] - sy0:box[3] - sy0, box[0] - sx0:box[2] - sx0] = self._L[rows, cols]
            stamp[box[1] - sy0:box[3] - sy0, box[0] - sx0:box[2] - sx0] = self._stamp[rows, cols]
        self._L, self._stamp, self._offset = L, stamp, (sx0, sy0)
        return True

    # ------------------------------------------------------------------ files

    def save(self, path_yaml, **kwargs):
        """Write a ROS map_server pair (``.yaml`` + trinary ``.pgm``) exactly as map_saver does;
        keyword arguments go to :func:`occmap.io.mapserver.save_map`. Returns the image path."""
        from ..io.mapserver import save_map

        if self.origin is None:
            raise InvalidArgumentError("an empty growing map has no extent to save yet")
        return save_map(path_yaml, self.occupancy(), self.resolution, self.origin, **kwargs)

    def figure(self, title: str = "occupancy grid", crop=True):
        """A labelled figure of the occupancy probability (free white, occupied black, never
        observed light blue; axes in metres, scale bar, colour bar), cropped to the mapped part, or
        to ``crop = (xmin, ymin, xmax, ymax)`` metres, or not (False)
        (:func:`occmap.viz.maps.grid_figure`)."""
        from ..viz import maps

        return maps.grid_figure(self.probability(), self.observed, self.origin, self.resolution, title, crop)

    def save_png(self, path, title: str = "occupancy grid", crop=True):
        """Write :meth:`figure` as a PNG file; returns the path. (The map_server image a ROS node
        loads is :meth:`save`'s, cell for pixel.)"""
        from ..viz import figure

        return figure.save(self.figure(title, crop), path)

    def _repr_png_(self) -> bytes:
        """Jupyter shows a grid as its figure."""
        from ..viz import figure

        return figure.png_bytes(self.figure())

    @classmethod
    def load(cls, path_yaml, prior: float = 0.5, clamp=(0.1192, 0.971)) -> OccupancyGrid2D:
        """A fixed-size grid from a map_server YAML (trinary, scale or raw image).

        Occupied cells (100) start at the upper clamp, free ones (0) at the lower clamp, values in
        between at ``logit(value / 100)`` clamped; unknown (−1) cells are unobserved. Maps with a
        non-zero origin yaw are rejected: grids here are world-aligned.
        """
        from ..io.mapserver import load_map

        m = load_map(path_yaml)
        if m.origin[2] != 0.0:
            raise InvalidArgumentError(f"{m.yaml_path}: origin yaw {m.origin[2]!r} is not supported (grids are world-aligned)")
        H, W = m.occupancy.shape
        grid = cls(m.resolution, size=(W * m.resolution, H * m.resolution), origin=m.origin[:2], prior=prior, clamp=clamp)
        occ = m.occupancy.astype(np.float64)
        known = occ >= 0
        p = np.clip(occ / 100.0, 1e-9, 1 - 1e-9)
        grid._L[known] = np.clip(logit(p), grid.l_min, grid.l_max)[known]
        grid._stamp[known] = SEEN  # known from a file: before every scan
        return grid

    def __repr__(self) -> str:
        H, W = self.shape
        o = "unset" if self.origin is None else f"({self.origin[0]:.3f}, {self.origin[1]:.3f})"
        return f"OccupancyGrid2D({W}×{H} cells at {self.resolution} m, origin {o}, {self.stats['scans']} scans)"
