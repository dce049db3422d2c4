"""The local map: a robot-centred rolling window of log-odds cells that forgets, and its costmap.

Layout: world-aligned cells of side ``resolution`` on the world lattice (the grid conventions of
:mod:`occmap.raster` with the origin at (0, 0)); the window is ``H × W`` of them, ``origin`` the
world position of the outer corner of its cell (0, 0), always a multiple of the resolution, so
cells never resample when the window moves.

Storage is a circular buffer (after ANYbotics' grid_map; index maths in :mod:`occmap.raster.ring`):
window cell ``(wy, wx)`` lives at ``((wy + sr) mod H, (wx + sc) mod W)``. :meth:`LocalMap.move_to`
shifts ``(sr, sc)`` and clears only the rows and columns that left the window (they come back in
as the entering cells, unknown): a move by k cells writes about ``k · width`` cells and copies
nothing.

Sensing follows :class:`~occmap.OccupancyGrid2D` (:mod:`occmap.raster.update`): log-odds
``l ← clamp(l + l_sensor − l_prior)``, every cell updated at most once per scan, a hit winning over
a miss. One ray is cast per distinct end cell of a scan, from the sensor position to the centre of
that cell (OctoMap's ``discretize``), which costs the same cells as any ray into that cell and
makes dense 3D clouds cheap.

Forgetting: with ``half_life`` (seconds) every cell relaxes toward the prior,
``l − l_prior ← (l − l_prior) · 2^(−Δt / half_life)``, exactly and at no cost per update: cells
store ``u = (l − l_prior) / g`` with one global factor ``g`` that the clock multiplies by
``2^(−Δt / half_life)`` (sensor evidence and clamping bounds are divided by ``g`` as they are
applied; ``g`` is folded back into the cells, one pass, when it falls below 2⁻³⁰). A cell is
lethal while ``p ≥ occupied_threshold`` (default 0.65) and free while ``p < free_threshold`` (default 0.196); so a
cell at the upper clamp ``l_max`` that is no longer seen leaves lethal after exactly
``half_life · log2((l_max − l_prior) / (l_occupied − l_prior))`` seconds
(:meth:`LocalMap.time_to_clear`), and re-observed free space clears faster than that.

Method and parameter names follow the vocabulary the three maps share (``docs/architecture.md``).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .. import checks
from .._threads import OneCallAtATime
from ..errors import InvalidArgumentError, NonFiniteError, ShapeError
from ..geometry.se2 import SE2, compose_poses, relative_poses
from ..geometry.so2 import wrap_angle_one
from ..grid2d.sensor_models import LidarModel, RadarModel, radar_sweeps
from ..logodds import logit, occupancy_classes, occupancy_values
from ..raster.ring import slot
from ..raster.update import UNSEEN, ScanCodes
from ..localize.scan_match import MIN_INLIERS
from ..slam.scan_matching import distance_fields, keep_prior_where_unconstrained, refine
from . import _kernels as K
from .costmap import InflationParams, as_footprint, circumscribed_radius, inscribed_radius as _inscribed_radius
from .tracking.detection import elevation_layers
from .tracking.layer import ObjectLayer
from .tracking.tracker import TrackerParams

__all__ = ["LocalMap", "PathCheck"]

#: The global decay factor is folded into the cells when it falls below this.
_RESCALE_BELOW = 2.0 ** -30

#: Farthest a window's centre may lie from the world origin, in cells (2⁴⁰: 55 000 km at 5 cm).
#: Beyond it float64 coordinates lose sub-cell precision and the kernels' int64 cell arithmetic
#: would overflow, so :meth:`LocalMap.move_to` (and ``center``) refuse such positions.
MAX_CELL_INDEX = 2.0 ** 40

#: Registration of a tracking map's planar scans to its static layer (:meth:`LocalMap._registered`):
#: Gauss–Newton over this many distance fields, the finest at the map's resolution, end points
#: farther than this many cells (of each level) from every occupied cell left out, ...
REGISTER_LEVELS = 3
REGISTER_CUTOFF_CELLS = 3.0
#: ... at most this many Gauss–Newton steps a level, ...
REGISTER_ITERATIONS = 10
#: ... kept when at least this share of the scan's returns fit (the rest: objects, and space not
#: mapped yet) and the pose moved no more than this (m, rad).
REGISTER_MIN_SHARE = 0.3
REGISTER_MAX_CORRECTION = (0.6, 0.35)
#: A registering map (``register=True``) takes a fit that moves this share of the returns (a
#: percentile: the far ones, which a heading error moves most) by this many cells or more; a map
#: that only judges what moves takes one by JUDGE_TAKE: half its returns (the median) a cell or more.
REGISTER_TAKE = (90.0, 0.5)
JUDGE_TAKE = (50.0, 1.0)


class PathCheck(NamedTuple):
    """Result of :meth:`LocalMap.check_path`.

    ``max_cost`` (N,) uint8: highest cost under the footprint at each pose (255 for a
    non-finite pose); ``first_collision``: index of the first pose in collision, −1 if none;
    ``dropped``: how many poses were non-finite (skipped, never a collision)."""

    max_cost: np.ndarray
    first_collision: int
    dropped: int


class LocalMap(OneCallAtATime):
    """A rolling, forgetting occupancy window centred on the robot, with a Nav2 costmap.

    Parameters
    ----------
    size : (width, height) in metres
        Extent of the window (rounded up to whole cells).
    resolution : float
        Cell side in metres.
    half_life : float or None
        Seconds for a cell's log-odds (relative to the prior) to halve when nothing updates it;
        ``None``: no forgetting.
    occupied_threshold, free_threshold : float
        Probability thresholds: lethal when ``p ≥ occupied_threshold``, free when
        ``p < free_threshold``; between them, and where never observed, unknown (map_server's
        trinary rule). :meth:`occupancy_at` uses ``occupied_threshold`` alone.
    model : LidarModel
        ``prob_hit`` / ``prob_miss`` of the beam-end model (OctoMap's 0.7 / 0.4).
    prior, clamp : as :class:`~occmap.OccupancyGrid2D`.
    inflation_radius, cost_scaling_factor : float
        Nav2's inflation parameters (defaults 0.55 m, 10).
    footprint : (M, 2) polygon or float radius
        The robot's footprint in the body frame (x forward), used by :meth:`check_path` when none
        is given and for the inscribed radius; default a 0.1 m radius (Nav2's ``robot_radius``).
    center : (x, y)
        Where the window starts, centred (default the world origin). Like :meth:`move_to`, at
        most :data:`MAX_CELL_INDEX` cells from the world origin.
    tracking : bool
        Track moving objects (:mod:`occmap.local.tracking.layer`): returns where the map has seen
        free space, or on a tracked object, go to tracks instead of the static layer; the costmap
        and path checks see where the objects are and will be (:meth:`tracks`,
        :meth:`predicted_occupancy`, ``costmap(at=t)``, ``check_path(..., stamps=...)``).
    tracker : TrackerParams or None
        The tracker's settings.
    register : bool
        Insert each planar scan where it fits the map, not at the pose given (a lidar odometry on
        top of the caller's): the map keeps a running :attr:`correction` from the caller's pose
        frame to its own (ROS's ``map → odom``, as AMCL or slam_toolbox publish it); each scan is
        registered to the static layer from the correction applied to its pose
        (:meth:`_registered`), a fit a cell or more away updates the correction, and the scan goes
        in at the registered pose (:attr:`pose`). For poses that drift (odometry): their walls,
        inserted where they were, would smear over the map's memory and look like objects
        moving. Off by default: the map's frame then is the caller's, as it was.

    Frames: the poses and points given to :meth:`move_to`, :meth:`insert_scan`,
    :meth:`insert_point_cloud` and :meth:`insert_radar` are in the caller's frame; everything the
    map reads out or is asked about — :attr:`origin`, :attr:`center`, :attr:`pose`, cells and
    :meth:`world_to_cell`, :meth:`costmap`, :meth:`tracks`, :meth:`predicted_occupancy`,
    :meth:`occupancy_at`, :meth:`cost_at`, :meth:`check_path` — is in the map's frame, the
    caller's carried by :attr:`correction` (a planner plans in it, from :attr:`pose`). Without
    ``register`` the two are one.
    """

    def __init__(self, size=(40.0, 40.0), resolution: float = 0.1, half_life: float | None = None, *,
                 occupied_threshold: float = 0.65, free_threshold: float = 0.196, model: LidarModel | None = None, prior: float = 0.5,
                 clamp=(0.1192, 0.971), inflation_radius: float = 0.55, cost_scaling_factor: float = 10.0,
                 footprint=0.1, center=(0.0, 0.0), tracking: bool = False, tracker: TrackerParams | None = None,
                 register: bool = False):
        self.resolution = checks.resolution(resolution)
        self.half_life = None if half_life is None else checks.positive("half_life", half_life, "seconds")
        try:
            w, h = size
        except (TypeError, ValueError):
            raise InvalidArgumentError(f"size must be (width, height) in metres, got {size!r}") from None
        w, h = checks.positive("size[0] (width)", w, "metres"), checks.positive("size[1] (height)", h, "metres")
        W = int(math.ceil(w / self.resolution - 1e-9))
        H = int(math.ceil(h / self.resolution - 1e-9))
        self.model = LidarModel() if model is None else model
        self.l_prior = logit(prior)
        self.l_min, self.l_max = logit(clamp[0]), logit(clamp[1])
        if not self.l_min < self.l_prior < self.l_max:
            raise InvalidArgumentError(f"prior {prior!r} must lie strictly between the clamping bounds {clamp!r}")
        self.occupied_threshold = checks.probability("occupied_threshold", occupied_threshold)
        self.free_threshold = checks.probability("free_threshold", free_threshold)
        self.l_occupied, self.l_free = logit(self.occupied_threshold), logit(self.free_threshold)
        if not self.l_free <= self.l_prior < self.l_occupied:
            raise InvalidArgumentError(f"thresholds must satisfy free_threshold ({free_threshold}) ≤ prior ({prior}) "
                                       f"< occupied_threshold ({occupied_threshold})")
        if not self.l_occupied <= self.l_max:
            raise InvalidArgumentError(f"occupied_threshold {occupied_threshold} lies above the upper clamp {clamp[1]}: "
                                       "nothing could be lethal")
        self.footprint = footprint
        self._footprint = as_footprint(footprint)
        self.inflation = InflationParams(self.resolution, inflation_radius, cost_scaling_factor,
                                         _inscribed_radius(footprint))
        self._objects = ObjectLayer(tracker) if tracking else None
        self.register = bool(register)
        self._correction = np.zeros(3)  # (x, y, θ): the caller's pose frame in the map's frame
        self._pose = None
        self._no_objects = np.zeros((H, W), dtype=bool)
        self._cells = np.zeros((H, W, 2), dtype=np.float32)
        self._stamps = self._cells.view(np.int32)
        self._rmark = np.zeros((H, W), dtype=np.int32)
        self._memo = np.zeros((H, W) if tracking else (0, 0), dtype=np.uint8)  # classify_returns' scratch
        # column distances of the inflation pass, capped at R + 1: one byte each when that fits
        self._g_scratch = np.empty((H, W), dtype=np.uint8 if self.inflation.radius_cells < 254 else np.int32)
        #: Two threads for big scans (None: decided per scan, see ``occmap.local._kernels.integrate``);
        #: True / False force it. The cells come out the same either way.
        self.parallel = None
        self._sr = 0
        self._sc = 0
        self._g = 1.0
        self._codes = ScanCodes(np.int32)
        self._time = None
        self._version = 0
        self._cost_cache = None
        self.stats = {"scans": 0, "points": 0, "dropped": 0, "dropped_poses": 0, "beyond_max_range": 0,
                      "rays": 0, "cells_updated": 0, "cells_cleared_by_moves": 0}
        if self._objects is not None:
            self.stats.update(self._objects.counts())
        cx, cy = (checks.finite("center", v) for v in center)
        self._gx0, self._gy0 = self._corner_for(cx, cy)

    # ------------------------------------------------------------------ geometry

    @property
    def shape(self) -> tuple[int, int]:
        """(height, width) in cells."""
        return self._rmark.shape

    @property
    def origin(self) -> np.ndarray:
        """World position (x, y) of the outer corner of window cell (0, 0)."""
        return np.array([self._gx0 * self.resolution, self._gy0 * self.resolution])

    @property
    def center(self) -> np.ndarray:
        """World position of the window's centre."""
        H, W = self.shape
        return self.origin + 0.5 * self.resolution * np.array([W, H])

    @property
    def correction(self) -> np.ndarray:
        """The running correction ``(x, y, θ)`` (m, m, rad): the caller's pose frame seen in the
        map's frame (ROS's ``map → odom``), so that a pose ``p`` the caller gives lies at
        ``compose_poses(correction, p)`` (:func:`occmap.geometry.se2.compose_poses`) in the map.
        Zero without ``register`` (the two frames are one)."""
        return self._correction.copy()

    @property
    def pose(self) -> np.ndarray | None:
        """The sensor pose ``(x, y, θ)`` of the last planar scan (:meth:`insert_scan`) in the map's
        frame, where it was inserted (with ``register``: registered, or the caller's pose carried by
        :attr:`correction` when the scan did not fit); ``None`` before the first."""
        return None if self._pose is None else self._pose.copy()

    def _to_map(self, points: np.ndarray, heading: bool = False) -> np.ndarray:
        """Points (..., k ≥ 2) of the caller's frame in the map's frame (:attr:`correction` applied
        to their x and y; with ``heading``, poses ``(x, y, θ)`` whose θ turns too); the array
        itself while the correction is zero."""
        if not self._correction.any():
            return points
        if heading:
            return compose_poses(self._correction, points)
        out = np.array(points, dtype=np.float64)
        out[..., :2] = SE2(self._correction).apply(points[..., :2])
        return out

    @property
    def time(self) -> float | None:
        """Stamp of the latest update (seconds), ``None`` before the first."""
        return self._time

    def _corner_for(self, x: float, y: float) -> tuple[int, int]:
        """Lattice cell of the window's corner when centred on (x, y); a centre more than
        :data:`MAX_CELL_INDEX` cells from the world origin is refused (InvalidArgumentError)."""
        H, W = self.shape
        inv = 1.0 / self.resolution
        cx, cy = x * inv, y * inv
        if not (abs(cx) <= MAX_CELL_INDEX and abs(cy) <= MAX_CELL_INDEX):
            raise InvalidArgumentError(
                f"position ({x!r}, {y!r}) is {max(abs(cx), abs(cy)):.3g} cells of {self.resolution} m from the world "
                f"origin, beyond the {MAX_CELL_INDEX:.3g} a local map can index")
        return int(math.floor(cx)) - W // 2, int(math.floor(cy)) - H // 2

    def world_to_cell(self, points) -> np.ndarray:
        """Window cells ``(wy, wx)`` (..., 2) of world points (..., 2); not clipped."""
        p = np.asarray(points, dtype=np.float64)
        if p.shape[-1:] != (2,):
            raise ShapeError(f"points must have shape (..., 2), got {p.shape}")
        c = np.floor(p * (1.0 / self.resolution)).astype(np.int64) - np.array([self._gx0, self._gy0])
        return c[..., ::-1]

    def cell_to_world(self, cells) -> np.ndarray:
        """World centres (..., 2) of window cells ``(wy, wx)`` (..., 2)."""
        c = np.asarray(cells)
        if c.shape[-1:] != (2,):
            raise ShapeError(f"cells must have shape (..., 2), got {c.shape}")
        return self.origin + (c[..., ::-1] + 0.5) * self.resolution

    # ------------------------------------------------------------------ moving

    def move_to(self, x: float, y: float) -> int:
        """Centre the window on (x, y) (the caller's frame: with ``register``, carried into the map's
        by :attr:`correction`): the window moves by whole cells, the storage start shifts,
        and only the rows and columns that left are cleared (they re-enter as unknown cells on
        the other side). Returns the number of cells cleared (0 when the window stays).
        A position more than :data:`MAX_CELL_INDEX` cells from the world origin raises
        :class:`~occmap.errors.InvalidArgumentError` and leaves the map as it was."""
        if not (math.isfinite(x) and math.isfinite(y)):
            raise NonFiniteError(f"move_to needs a finite position, got ({x!r}, {y!r})")
        x, y = self._to_map(np.array([x, y], dtype=np.float64))
        gx0, gy0 = self._corner_for(float(x), float(y))
        dx, dy = gx0 - self._gx0, gy0 - self._gy0
        if dx == 0 and dy == 0:
            return 0
        H, W = self.shape
        touched = 0
        if abs(dx) >= W or abs(dy) >= H:
            self._cells[...] = 0.0  # nothing stays: every cell left
            touched = H * W
            self._sr = self._sc = 0
        else:
            if dx:
                # leaving: window columns [0, dx) when moving +x, [W + dx, W) when moving −x;
                # they are the storage columns that the entering ones take over
                c0 = self._sc if dx > 0 else slot(dx, self._sc, W)
                touched += K.clear_columns(self._cells, c0, abs(dx))
                self._sc = slot(dx, self._sc, W)
            if dy:
                r0 = self._sr if dy > 0 else slot(dy, self._sr, H)
                touched += K.clear_rows(self._cells, r0, abs(dy))
                self._sr = slot(dy, self._sr, H)
        self._gx0, self._gy0 = gx0, gy0
        self.stats["cells_cleared_by_moves"] += touched
        self._changed()
        return touched

    # ------------------------------------------------------------------ time

    def _advance(self, stamp) -> None:
        """Move the clock to ``stamp``: check it, and decay by the time passed."""
        stamp = checks.finite("stamp", stamp)
        if self._time is not None:
            dt = stamp - self._time
            if dt < 0:
                raise InvalidArgumentError(
                    f"stamp {stamp!r} goes backwards: the local map is at {self._time!r} s "
                    f"({-dt:.6g} s later); updates must come in time order")
            if self.half_life is not None and dt > 0:
                self._g *= 2.0 ** (-dt / self.half_life)
                if self._g < _RESCALE_BELOW:
                    K.rescale(self._cells, np.float32(self._g))
                    self._g = 1.0
        self._time = stamp
        self._changed()

    def advance_time(self, stamp) -> None:
        """Let time pass to ``stamp`` without an observation (cells decay)."""
        self._advance(stamp)

    def _next_scan(self) -> int:
        code, _ = self._codes.take(1, self._stamps[..., 1])
        if code == 1:  # the codes start (again): the ray marks of earlier scans must not match
            self._rmark[...] = 0
        return code

    def _changed(self) -> None:
        self._version += 1
        self._cost_cache = None

    # ------------------------------------------------------------------ sensing

    def _insert(self, px, py, ends, kinds, dropped: int, maxed: int, max_range: float | None = None,
                model=None, layers=None, judged=None) -> dict:
        """Insert one scan's ray ends from the sensor at (px, py) with ``model``'s evidence (the
        map's by default); record and return its counts (the keys of :attr:`stats`,
        ``docs/architecture.md``). With tracking and the map's own model (a lidar), the returns of
        moving objects clear only and go to the tracks (``layers``: a 3D scanner's elevation
        layers of the ends, for the occlusion test; ``judged``: the ends (and sensor) of the scan
        registered to the static layer, which say what moves and where, or False for a scan that
        does not fit the static layer, in which nothing is taken as moving: see :meth:`_registered`)."""
        model = self.model if model is None else model
        if self._objects is not None and model is self.model and judged is False:
            self._objects.pass_over(self._time, (px, py))
        elif self._objects is not None and model is self.model:
            at, sensor = (ends, (px, py)) if judged is None else judged
            open_, occupied, unseen, walled = self._classify_returns(at, kinds)
            recent = self._objects.recent_hits(self._time)
            vacated = recent[self._classify_returns(recent, np.ones(len(recent), np.int8), vacated=True)[0]]
            self._objects.sort_returns(at, kinds, open_, occupied, sensor, self._time, max_range,
                                       (self.origin, self.resolution, self.shape), vacated, unseen, walled,
                                       layers)
            self.stats.update(self._objects.counts())
        g = self._g
        lp = self.l_prior
        hits, rays, updated, visited = K.integrate(
            self._cells, self._stamps, self._rmark, self._sr, self._sc, self._gx0, self._gy0,
            1.0 / self.resolution, float(px), float(py), ends, kinds, self._next_scan(),
            (model.l_hit - lp) / g, (model.l_miss - lp) / g, (self.l_min - lp) / g, (self.l_max - lp) / g,
            self.parallel)
        counts = {"scans": 1, "points": int(np.count_nonzero(kinds)), "dropped": int(dropped), "beyond_max_range": int(maxed),
                  "rays": int(rays)}
        for key, value in counts.items():
            self.stats[key] += value
        self.stats["cells_updated"] += hits + updated
        self._changed()
        return {**counts, "hits": int(hits), "free_updates": int(updated), "cells_visited": int(visited)}

    def _classify_returns(self, ends: np.ndarray, kinds: np.ndarray, vacated: bool = False):
        """``(open, occupied, unseen)`` per ray end (bool (N,), false but for returns): the return
        in open free space — its cell and neighbours known free and no cell within the layer's
        ``open_margin`` known occupied (not the edge of a wall that grazing rays have cleared or that
        a small pose error shifts); its cell known occupied; its cell never observed. With
        ``vacated``, ``open`` is looser, for cells an earlier scan hit: the cell and its neighbours
        seen with more free evidence than occupied (below the prior) — the hit has been
        contradicted — and nothing occupied within the margin."""
        open_, occupied, unseen, walled = (np.empty(len(kinds), dtype=np.bool_) for _ in range(4))
        reach = int(math.ceil(self._objects.open_margin / self.resolution - 1e-9))
        g = self._g
        free = 0.0 if vacated else (self.l_free - self.l_prior) / g
        K.classify_returns(self._cells, self._stamps, self._sr, self._sc, self._gx0, self._gy0, 1.0 / self.resolution,
                           free, (self.l_occupied - self.l_prior) / g, reach, np.ascontiguousarray(ends), kinds,
                           open_, occupied, unseen, walled, self._memo)
        return open_, occupied, unseen, walled

    def _dropped_pose(self, n: int) -> dict:
        """A scan or cloud whose sensor pose is not finite: counted, nothing inserted."""
        self.stats["dropped_poses"] += 1
        return {"scans": 0, "points": 0, "dropped": n, "beyond_max_range": 0, "dropped_pose": True}

    def insert_scan(self, pose, ranges, angles, stamp, max_range: float | None = None) -> dict:
        """Insert one planar scan from sensor pose ``(x, y, theta)`` taken at ``stamp`` seconds.

        ``ranges`` (n,) metres; ``angles`` (n,) relative to the sensor heading. Readings at or
        beyond ``max_range`` (or infinite) clear up to it and mark nothing; NaN, zero and negative
        readings, and readings whose angle is NaN or infinite, are dropped and counted. Without ``max_range`` every finite reading is a return
        and infinite ones are dropped. A pose with NaN drops the whole scan (counted in
        ``stats["dropped_poses"]``; time still advances). Stamps must not go backwards
        (:class:`~occmap.errors.InvalidArgumentError`). With tracking, what moves is judged in
        the scan registered to the static layer, and nothing in a scan that does not fit it
        (:meth:`_registered`). With ``register`` the pose is the caller's: the scan is
        registered from it carried by :attr:`correction`, and inserted where it fits (where the
        correction carries it when it does not fit); :attr:`pose` says where. Returns this
        scan's counts.
        """
        P = np.asarray(pose, dtype=np.float64)
        if P.shape != (3,):
            raise ShapeError(f"pose must be (x, y, theta), got shape {P.shape}")
        R = np.ascontiguousarray(ranges, dtype=np.float64)
        A = np.ascontiguousarray(angles, dtype=np.float64)
        if R.ndim != 1 or A.shape != R.shape:
            raise ShapeError(f"ranges and angles must both have shape (n,), got {R.shape} and {A.shape}")
        self._advance(stamp)
        if not np.isfinite(P).all():
            return self._dropped_pose(int(R.size))
        bad_angle = ~np.isfinite(A)
        if bad_angle.any():  # a beam without a direction is a dropped reading
            R = np.where(bad_angle, np.nan, R)
        if max_range is None:
            finite = R[np.isfinite(R) & (R > 0)]
            mr = float(np.nextafter(finite.max(), np.inf)) if finite.size else 1.0
            if np.isinf(R).any():
                R = np.where(np.isinf(R), np.nan, R)
        else:
            mr = checks.positive("max_range", max_range, "metres")
        given = P
        if self.register:
            P = self._to_map(P, heading=True)  # where the running correction puts the scan
        ends = np.empty((R.size, 2))
        kinds = np.empty(R.size, dtype=np.int8)
        dropped, maxed = K.scan_ends(P, R, A, mr, ends, kinds)
        judged = None
        if self.register or self._objects is not None:
            Q = self._registered(P, R, A, kinds, ends)
            if Q is None:
                judged = False  # nothing in it judged to move (with register: inserted where the correction puts it)
            elif Q is not P and self.register:  # inserted, and judged, where it fits
                self._correct(given, Q)
                K.scan_ends(Q, R, A, mr, ends, kinds)
                P = Q
            elif Q is not P:  # inserted at the caller's pose, judged where it fits
                judged = (np.empty_like(ends), Q[:2])
                K.scan_ends(Q, R, A, mr, judged[0], np.empty_like(kinds))
        self._pose = P
        return self._insert(P[0], P[1], ends, kinds, dropped, maxed, mr, judged=judged)

    def _correct(self, P: np.ndarray, Q: np.ndarray) -> None:
        """Take the registration of a scan given at ``P`` (the caller's frame) to ``Q`` (the map's)
        as the running :attr:`correction`: ``Q ⊕ P⁻¹``, the transform that carries ``P`` onto ``Q``."""
        self._correction = compose_poses(Q, relative_poses(P, np.zeros(3)))

    def _registered(self, P: np.ndarray, R: np.ndarray, A: np.ndarray, kinds: np.ndarray, ends: np.ndarray):
        """The sensor pose at which a planar scan's static returns (``kinds == 1``, at ``ends``
        from ``P``, off the tracks' footprints) lie on the static layer's occupied cells; None when
        the scan does not fit the static layer.

        The poses a local map is given drift (odometry): a wall seen again from a pose a few
        centimetres or a degree off lands beside the cells that hold it, in cells earlier rays
        saw free, and looks like an object moving; from a pose far off (a heading error of
        odometry while turning), the whole scan does. Whether a return moves is a question about
        the world only once the scan's own pose error is taken out: before the returns are judged
        (what moves, and where: the detections), the scan is registered to the static layer by
        Gauss–Newton on the distance fields of its lethal cells from ``P``
        (:func:`occmap.slam.scan_matching.refine`, cutoff :data:`REGISTER_CUTOFF_CELLS` cells):
        at the finest level first, and coarse to fine over :data:`REGISTER_LEVELS` levels only
        when that does not fit (on a young map the coarse levels pull a scan moved along a street
        back toward the last one by a cell or more); the position is moved only along the
        directions the scan's surfaces constrain (a corridor pins it across, not along). Returns
        on a track's footprint (they move: they say nothing of the pose) and returns in cells the
        map has never seen (surfaces it has not mapped yet, beyond the last scan's range or
        behind what hid them: they pull the scan back onto the map's edge) are left out. The scan
        fits when at least :data:`REGISTER_MIN_SHARE` of those returns lie within the finest
        cutoff and the correction is within :data:`REGISTER_MAX_CORRECTION`; otherwise (or while
        the layer has no occupied cell) nothing in it can be told to move. A correction that
        moves the returns by less than a cell (their median) is within the map's own precision
        and ``P`` is kept (on the simulated street, whose poses are exact, registration is off by
        3 cm at the median, at 0.1 m cells; taken, such corrections move a registering map 0.1 –
        0.2 m off the exact poses in 20 s). Without ``register`` the scan is still inserted at the
        caller's pose (the map stays in the caller's frame and follows the poses' drift as it
        forgets) and only the judgement of what moves is made in the scan's fit to the map; with
        it, the scan is inserted where it fits (:meth:`insert_scan`)."""
        ret = np.flatnonzero(kinds == 1)
        tracker = None if self._objects is None else self._objects.tracker
        if tracker is not None and len(tracker) and len(ret):  # what the tracks explain moves: it says nothing of the pose
            ret = ret[~tracker.covers(ends[ret], self._time, self._objects.cover_margin)]
        if len(ret):
            ret = ret[~np.isnan(self.log_odds_at(ends[ret]))]
        if len(ret) < MIN_INLIERS:
            return None
        occupied = self.lethal()
        if not occupied.any():
            return None
        cutoff = REGISTER_CUTOFF_CELLS * self.resolution
        fields = distance_fields(occupied, self.origin, self.resolution, REGISTER_LEVELS, cutoff, score=False)
        bx = np.ascontiguousarray(R[ret] * np.cos(A[ret]))
        by = np.ascontiguousarray(R[ret] * np.sin(A[ret]))
        enough = REGISTER_MIN_SHARE * len(ret)
        x, inliers = refine(fields[-1:], P, bx, by, cutoff, REGISTER_ITERATIONS)
        if x is None or inliers < enough:
            x, inliers = refine(fields, P, bx, by, cutoff, REGISTER_ITERATIONS)
            if x is None or inliers < enough:
                return None
        x, _ = keep_prior_where_unconstrained(x, P, bx, by)
        if (math.hypot(x[0] - P[0], x[1] - P[1]) > REGISTER_MAX_CORRECTION[0]
                or abs(wrap_angle_one(float(x[2] - P[2]))) > REGISTER_MAX_CORRECTION[1]):
            return None
        # a correction that moves the returns by less than a cell (the median of them) is within the
        # map's own precision (the grid holds a surface to a cell): the scan fits as it is. A
        # registering map is told its poses drift, and odometry's do scan by scan (raw Freiburg 079:
        # the log's corrected poses differ from the raw ones by 0.66° from one scan to the next at
        # the median, 2.7° at the 90th percentile; the fits follow them to 0.28°): a scan left at the
        # running correction because its returns moved under a cell at the median (close walls) put
        # its far walls 0.1 - 0.2 m into cells the map held free. It takes a fit that moves the far
        # returns (the 90th percentile) by half a cell or more (REGISTER_TAKE)
        c, s = math.cos(x[2]) - math.cos(P[2]), math.sin(x[2]) - math.sin(P[2])
        moved = np.hypot(x[0] - P[0] + c * bx - s * by, x[1] - P[1] + s * bx + c * by)
        share, cells = REGISTER_TAKE if self.register else JUDGE_TAKE
        return x if np.percentile(moved, share) >= cells * self.resolution else P

    def insert_point_cloud(self, points, origin, stamp, z_min: float, z_max: float) -> dict:
        """Insert a 3D cloud: ``points`` (N, 3) in the world frame, seen from the sensor at
        ``origin`` (2 or 3 numbers) at ``stamp`` seconds (the caller's frame: with ``register``
        both are carried into the map's by :attr:`correction`, as the scans are; clouds are not
        registered themselves). With tracking, a 3D origin gives each
        return its elevation seen from the sensor, so that only returns of about the same elevation
        hide an object's ends (:func:`~occmap.local.tracking.detection.elevation_layers`); with a 2D
        one, every in-band return can.

        Points with ``z_min ≤ z ≤ z_max`` mark their cell as an obstacle and clear the cells
        before it; the others (ground below the band, overhangs above it) mark nothing and clear
        the cells along their ray projected on the plane, end cell excluded. Points with NaN or
        inf are dropped and counted; a non-finite sensor origin drops the cloud (counted as a
        dropped pose). Returns this cloud's counts.
        """
        pts = np.ascontiguousarray(points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise ShapeError(f"points must have shape (N, 3), got {pts.shape}")
        o = np.asarray(origin, dtype=np.float64).reshape(-1)
        if o.shape not in ((2,), (3,)):
            raise ShapeError(f"origin must have 2 or 3 coordinates, got shape {o.shape}")
        z_min = checks.finite("z_min", z_min)
        z_max = checks.finite("z_max", z_max)
        if not z_min <= z_max:
            raise InvalidArgumentError(f"z_min ({z_min}) must not exceed z_max ({z_max})")
        self._advance(stamp)
        if not np.isfinite(o[:2]).all():
            return self._dropped_pose(len(pts))
        pts, o = self._to_map(pts), self._to_map(o)
        ends = np.empty((len(pts), 2))
        kinds = np.empty(len(pts), dtype=np.int8)
        dropped = K.cloud_ends(pts, z_min, z_max, ends, kinds)
        layers = elevation_layers(pts, o) if self._objects is not None and len(o) == 3 else None
        return self._insert(o[0], o[1], ends, kinds, dropped, 0, layers=layers)

    def insert_radar(self, pose, ranges, azimuths, stamp, max_range: float, radial_velocity=None, ego_velocity=None,
                     model: RadarModel | None = None) -> dict:
        """Insert one radar sweep from sensor pose ``(x, y, theta)`` taken at ``stamp`` seconds (the
        caller's frame: with ``register`` the pose and ``ego_velocity`` are carried into the map's
        by :attr:`correction`, as the scans are; sweeps are not registered themselves).

        ``ranges``, ``azimuths`` (M,) the detections (metres; radians from the heading); with
        ``radial_velocity`` (M,) (m/s, positive away, the sensor's motion included) and
        ``ego_velocity`` (2,) (the sensor's world velocity, m/s) the Doppler says which reflectors
        move. Each detection is a ray to its point with :class:`~occmap.grid2d.RadarModel`'s
        evidence (``model``; the local map's one-ray-per-end-cell rule, no range band): moving
        reflectors only clear; one whose ray meets a cell known at least
        ``model.obstacle_probability`` occupied more than ``ghost_margin`` before its uncertain
        range is a ghost and does nothing. With tracking, detections on a confirmed track's
        footprint only clear too, and the moving ones update the tracks' speed and heading
        (:meth:`~occmap.local.tracking.tracker.Tracker.update_radar`). Detections with NaN or
        infinite values or a range ≤ 0 are dropped and counted; those at or beyond ``max_range``
        are counted and say nothing. Returns this sweep's counts, with ``moving`` and ``ghosts``.
        """
        model = RadarModel() if model is None else model
        P = np.asarray(pose, dtype=np.float64)
        if P.shape != (3,):
            raise ShapeError(f"pose must be (x, y, theta), got shape {P.shape}")
        self._advance(stamp)
        if not np.isfinite(P).all():
            return self._dropped_pose(int(np.size(ranges)))
        P = self._to_map(P, heading=True)
        if ego_velocity is not None and self._correction[2] != 0.0:  # a world velocity turns with the frame
            E = np.asarray(ego_velocity, dtype=np.float64)
            if E.shape[-1:] == (2,):
                c, s = math.cos(self._correction[2]), math.sin(self._correction[2])
                ego_velocity = np.stack([c * E[..., 0] - s * E[..., 1], s * E[..., 0] + c * E[..., 1]], -1)
        d = radar_sweeps(P, ranges, azimuths, max_range, model, None, radial_velocity, ego_velocity)
        ends = np.empty((d.range.size, 2))
        kinds = np.empty(d.range.size, dtype=np.int8)
        g = self._g
        ghosts = K.radar_ends(self._cells, self._stamps, self._sr, self._sc, self._gx0, self._gy0, 1.0 / self.resolution,
                              (logit(model.obstacle_probability) - self.l_prior) / g, P, d.range, d.azimuth, d.moving,
                              model.extent * max(model.sigma_range, 0.5 * self.resolution) + model.ghost_margin,
                              ends, kinds)
        if self._objects is not None:
            tracker = self._objects.tracker
            if len(tracker):  # what falls on a tracked object is the object's, however it moves
                kinds[(kinds == 1) & tracker.covers(ends, self._time, self._objects.cover_margin)] = 2
            on = d.moving & (kinds == 2)
            tracker.update_radar(self._time, ends[on], P[2] + d.azimuth[on], d.radial_speed[on])
            self.stats.update(self._objects.counts())
        counts = self._insert(P[0], P[1], ends, kinds, d.dropped, d.beyond_max_range, model=model)
        return {**counts, "moving": int(d.moving.sum()), "ghosts": int(ghosts)}

    # ------------------------------------------------------------------ read-outs

    def log_odds(self) -> np.ndarray:
        """Log-odds per window cell now (float32 (H, W), row 0 at the origin), NaN where unknown."""
        out = np.empty(self.shape, dtype=np.float32)
        K.log_odds(self._cells, self._stamps, self._sr, self._sc, self._g, self.l_prior, out)
        return out

    @property
    def observed(self) -> np.ndarray:
        """True for window cells observed since they entered the window (window order)."""
        return ~np.isnan(self.log_odds())

    def occupancy(self) -> np.ndarray:
        """nav_msgs/OccupancyGrid values (int8 (H, W), row 0 at :attr:`origin`): −1 unknown, else
        round(100·p)."""
        return occupancy_values(self.log_odds())

    def log_odds_at(self, points) -> np.ndarray:
        """Log-odds (float64, shape (...)) of the cells under world points (..., 2), the value
        :meth:`log_odds` holds there; NaN outside the window or where unknown (NaN points too)."""
        p = np.asarray(points, dtype=np.float64)
        if p.shape[-1:] != (2,):
            raise ShapeError(f"points must have shape (..., 2), got {p.shape}")
        H, W = self.shape
        out = np.full(p.shape[:-1], np.nan)
        good = np.isfinite(p).all(axis=-1)
        cells = self.world_to_cell(np.where(good[..., None], p, 0.0))
        wy, wx = cells[..., 0], cells[..., 1]
        inside = good & (wy >= 0) & (wy < H) & (wx >= 0) & (wx < W)
        r = (wy[inside] + self._sr) % H
        c = (wx[inside] + self._sc) % W
        seen = self._stamps[r, c, 1] != UNSEEN
        l = (self.l_prior + self._g * self._cells[r, c, 0].astype(np.float64)).astype(np.float32)
        out[inside] = np.where(seen, l, np.nan)
        return out

    def occupancy_at(self, points) -> np.ndarray:
        """Per world point (..., 2), int8: −1 unknown or outside the window, 1 occupied
        (``p ≥ occupied_threshold``), else 0 free."""
        return occupancy_classes(self.log_odds_at(points), self.l_occupied)

    def costmap(self, at: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``(cost, origin)``: Nav2 costs (uint8 (H, W), row 0 at the origin; see
        :mod:`occmap.local.costmap`) and the window origin (x, y).

        ``at``: the time (seconds, at or after the last update) the costs are for; ``None`` is
        now. With tracking, moving objects are obstacles where they are predicted to be then (see
        :class:`~occmap.local.tracking.layer.ObjectLayer`); without it nothing moves and every
        time gives today's costs. The costs of now are computed once per change of the map (the
        array is shared with later calls until then: copy it to keep it)."""
        now = at is None or (self._time is not None and checks.finite("at", at) == self._time)
        if not now and self._time is not None and at < self._time:
            raise InvalidArgumentError(f"at = {at!r} lies before the map's time {self._time!r}: costs go forward only")
        if now and self._cost_cache is not None:
            return self._cost_cache, self.origin
        if self._objects is None:
            out = self._costs(self._no_objects)
        else:
            extra, graded = self._objects.lethal(self._time if now else at, self.origin, self.resolution, self.shape)
            out = self._costs(extra)
            if graded.any():  # free and inflated cells an object may cover cost more
                out = np.where((out < 253) & (graded > out), graded, out)
                out.flags.writeable = False
        if now:
            self._cost_cache = out
        return out, self.origin

    def _costs(self, extra: np.ndarray) -> np.ndarray:
        """The inflated costmap of the static layer with the cells of ``extra`` lethal too."""
        H, W = self.shape
        out = np.empty((H, W), dtype=np.uint8)
        g = self._g
        p = self.inflation
        K.costmap(self._cells, self._stamps, self._sr, self._sc, (self.l_occupied - self.l_prior) / g,
                  (self.l_free - self.l_prior) / g, p.radius_cells, p.table, p.inscribed_d2, self._g_scratch, extra,
                  out)
        out.flags.writeable = False
        return out

    def tracks(self):
        """The moving objects tracked at the last update (:class:`~occmap.local.tracking.Tracks`:
        arrays ``id``, ``x``, ``y``, ``vx``, ``vy``, ``heading``, ``length``, ``width``,
        ``confirmed``, ``lost``, ``covariance``); needs ``tracking=True``."""
        return self._layer().tracker.tracks()

    def predicted_occupancy(self, at: float) -> np.ndarray:
        """Probability (float32 (H, W), row 0 at the origin) that a tracked object covers each
        cell's centre at time ``at`` (seconds, at or after the last update); needs ``tracking=True``."""
        return self._layer().occupancy(checks.finite("at", at), self.origin, self.resolution, self.shape)

    @property
    def objects(self) -> ObjectLayer | None:
        """The moving-object layer (its ``tracker`` predicts tracks to any later time), ``None``
        without tracking."""
        return self._objects

    def _layer(self) -> ObjectLayer:
        if self._objects is None:
            raise InvalidArgumentError("this local map does not track moving objects: create it with tracking=True")
        return self._objects

    def lethal(self) -> np.ndarray:
        """Bool (H, W), window order: cells at or above the occupied threshold."""
        out = np.empty(self.shape, dtype=bool)
        K.lethal(self._cells, self._stamps, self._sr, self._sc, self._g, self.l_prior, self.l_occupied, out)
        return out

    def time_to_clear(self, l_start: float | None = None) -> float:
        """Seconds after which a cell at log-odds ``l_start`` (default the upper clamp) that
        nothing updates drops below the occupied threshold: ``half_life · log2(Δl_start / Δl_occ)``
        (Δ relative to the prior); inf without forgetting."""
        if self.half_life is None:
            return math.inf
        l0 = self.l_max if l_start is None else float(l_start)
        return self.half_life * math.log2((l0 - self.l_prior) / (self.l_occupied - self.l_prior))

    # ------------------------------------------------------------------ queries

    def cost_at(self, points, frame: str = "world", robot_pose=None) -> np.ndarray:
        """Costs (uint8, shape (...)) of the cells under points (..., 2): world coordinates, or
        ``frame="body"`` coordinates in the frame of ``robot_pose`` (x, y, θ). Points outside
        the window or with NaN get 255 (the NaN ones are counted in ``stats["dropped"]``)."""
        p = np.asarray(points, dtype=np.float64)
        if p.shape[-1:] != (2,):
            raise ShapeError(f"points must have shape (..., 2), got {p.shape}")
        if frame == "body":
            if robot_pose is None:
                raise InvalidArgumentError('frame="body" needs robot_pose=(x, y, theta)')
            rp = np.asarray(robot_pose, dtype=np.float64)
            if rp.shape != (3,):
                raise ShapeError(f"robot_pose must be (x, y, theta), got shape {rp.shape}")
            c, s = math.cos(rp[2]), math.sin(rp[2])
            p = np.stack([rp[0] + c * p[..., 0] - s * p[..., 1], rp[1] + s * p[..., 0] + c * p[..., 1]], -1)
        elif frame != "world":
            raise InvalidArgumentError(f'frame must be "world" or "body", got {frame!r}')
        cost, _ = self.costmap()
        flat = np.ascontiguousarray(p.reshape(-1, 2))
        out = np.empty(len(flat), dtype=np.uint8)
        bad = K.cost_at(cost, self._gx0, self._gy0, 1.0 / self.resolution, flat, out)
        self.stats["dropped"] += int(bad)
        return out.reshape(p.shape[:-1])

    def check_path(self, poses, footprint=None, unknown_is_collision: bool = False, stamps=None) -> PathCheck:
        """Check poses (N, 3) ``(x, y, θ)`` against the costmap with a footprint (a polygon (M, 2)
        in the body frame, or a radius; default the map's).

        For a polygon the cells under it are those its edges cross and those whose centre lies
        inside; for a radius, the cell under the pose and those whose centre lies within the
        radius. Returns :class:`PathCheck`: the maximum cost per pose, the index of the first
        pose touching a lethal cell (or an unknown one, with ``unknown_is_collision``), −1 if
        none, and the count of non-finite poses (dropped: cost 255, never a collision).

        ``stamps`` (N,): the time of each pose (seconds, at or after the last update). With
        tracking, each pose is then checked against the moving objects predicted to its own time:
        a pose whose footprint (its circumscribed disc) meets a tracked object with probability at
        least the layer's threshold is lethal (254), a lesser probability ``p`` costs
        ``252 · p / threshold`` (from ``p`` = 0.05); the static layer and the moving returns no
        track explains are checked as without stamps. Without tracking the stamps change nothing."""
        P = np.ascontiguousarray(poses, dtype=np.float64)
        if P.ndim != 2 or P.shape[1] != 3:
            raise ShapeError(f"poses must have shape (N, 3), got {P.shape}")
        fp, radius = self._footprint if footprint is None else as_footprint(footprint)
        timed = stamps is not None and self._objects is not None
        if stamps is not None:
            T = np.asarray(stamps, dtype=np.float64)
            if T.shape != (len(P),):
                raise ShapeError(f"stamps must have shape ({len(P)},), one per pose, got {T.shape}")
            if not np.isfinite(T).all():
                raise NonFiniteError("stamps hold NaN or infinity")
            if self._time is not None and (T < self._time).any():
                raise InvalidArgumentError(f"stamp {float(T.min())!r} lies before the map's time {self._time!r}: "
                                           "paths are checked forward in time")
        if timed:
            cost = self._costs(self._objects.lethal(None, self.origin, self.resolution, self.shape)[0])
        else:
            cost, _ = self.costmap()
        out = np.empty(len(P), dtype=np.uint8)
        first, bad = K.check_path(cost, self._gx0, self._gy0, 1.0 / self.resolution, P,
                                  np.ascontiguousarray(fp), radius, bool(unknown_is_collision), out)
        if timed:
            good = np.isfinite(P).all(axis=1)
            reach = radius if radius >= 0.0 else circumscribed_radius(fp)
            p = np.zeros(len(P))
            p[good] = self._objects.path_probability(P[good, :2], T[good], reach)
            thr = self._objects.threshold
            hit = p >= thr
            graded = np.where(hit, 254, np.where(p >= 0.05, np.minimum(252.0 * p / thr, 252.0), 0)).astype(np.uint8)
            out = np.where(good & (out < 253), np.maximum(out, graded), np.where(hit, np.maximum(out, 254), out))
            if hit.any():
                k = int(np.flatnonzero(hit)[0])
                first = k if first < 0 else min(int(first), k)
        self.stats["dropped_poses"] += int(bad)
        return PathCheck(out, int(first), int(bad))

    def _repr_png_(self) -> bytes:
        """Jupyter shows a local map as a labelled frame of its costmap, the window's centre marked
        as the robot, with tracking its confirmed tracks and their footprints 1 s ahead."""
        from ..viz.animation import CostmapAnimation
        from .replay import tracked_objects

        frame = CostmapAnimation(self.shape, self.resolution, 2, repr(self), tracking=self._objects is not None)
        robot = self.world_to_cell(self.center)
        frame.add(self.costmap()[0], (int(robot[0]), int(robot[1])),
                  None if self._objects is None else tracked_objects(self, 1.0),
                  "" if self.time is None else f"t = {self.time:g} s")
        return frame.png_bytes()

    def __repr__(self) -> str:
        H, W = self.shape
        o = self.origin
        hl = "no forgetting" if self.half_life is None else f"half-life {self.half_life} s"
        return (f"LocalMap({W}×{H} cells at {self.resolution} m, origin ({o[0]:.3f}, {o[1]:.3f}), {hl}, "
                f"{self.stats['scans']} scans)")
