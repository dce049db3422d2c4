"""Incremental 2D scan matching: LiDAR odometry from the ranges alone, as Hector mapping does it.

Each scan is matched against the map built from the scans before it (scan-to-map), never
against the previous scan alone, so the error grows with the distance travelled, not with the
number of scans. There is no loop closure: a long run drifts, slowly.

The map is an :class:`~occmap.grid2d.OccupancyGrid2D` (log-odds, beams clear the cells they
cross, so objects that leave are forgotten). Matching does not read the whole map but a local
submap: the square of side ``2 · field_radius`` around the last inserted pose, turned into
distance fields (distance to the nearest occupied cell, :mod:`occmap.raster.edt`) at
``levels`` resolutions, ``resolution · 2^k``, the coarser ones from the finer occupied cells
by any-of-block. A scan is matched by Gauss–Newton coarse to fine from the prior (2 below); when
that fails or keeps fewer than :data:`SEARCH_BELOW` (:data:`SEARCH_BELOW_ODOMETRY` from an odometry
prior) of the end points within the fine cutoff, again from the best pose of a correlative search
(1), and the match with more such inliers wins:

1. A correlative search (Olson, "Real-time correlative scan matching", ICRA 2009; Cartographer's
   real-time matcher) over poses within ``search_window`` of the prior on the coarsest field:
   every candidate scores the sum of ``exp(−d² / 2σ²)`` over (up to :data:`SEARCH_BEAMS`) end
   points, σ the coarse cell, times a Gaussian of its distance from the prior (half the window
   as σ) that breaks ties toward the prior. Steps: half a coarse cell in x and y, and the angle
   that moves the 90th-percentile end point by one coarse cell. This turns a start that is off by
   a turn the prior did not foresee into one off by less than a coarse cell, which is what
   Gauss–Newton needs.
2. Gauss–Newton coarse to fine on the bilinearly interpolated fields
   (:func:`occmap.localize.scan_match.match`): the fine field places the pose to a fraction of a
   cell. End points farther than ``cutoff · 2^k`` from every obstacle of level k (unmapped or
   moving objects) are left out of that level.

The pose a match starts from (the prior) is the last pose moved by the odometry between the two
scans when both carry one (:attr:`~occmap.scan.LaserScan.odom`, the robot's; the sensor is taken
to sit at the robot's origin), else by the last step's motion (constant velocity per scan;
scaling it by the ratio of the time steps predicted worse on Intel's log, whose scans are
irregular). The first scan defines the frame: its pose is ``initial_pose`` (default the origin).

A match *fails* when the finest level keeps fewer than :data:`~occmap.localize.scan_match.MIN_INLIERS`
end points or its system is singular; it is *rejected* when it moves the pose farther than
``max_correction`` from the prior. Both leave the scan at its prior and are counted, never raised.
A match is *degenerate* when the scan's surfaces pin the position in one direction only (a
straight corridor): the unit normals of the surfaces, taken between end points two beams apart
and less than :data:`SURFACE_GAP` apart, have a scatter matrix whose smaller eigenvalue is below
:data:`DEGENERATE_RATIO` times the larger. The map cannot say either (the distance field of a wall
mapped with gaps would pin the pose to the gaps' pattern), so the match moves the position only
along the constrained direction and keeps the prior's along the other (Zhang, Kaess and Singh,
"On degeneracy of optimization-based state estimation problems", ICRA 2016). It is kept, and
counted.

A scan is inserted into the map when its match succeeded (or the map has no obstacle yet) and
the sensor moved at least ``insert_min_d`` metres or turned ``insert_min_a`` radians since the
last insertion; readings beyond ``insert_range`` clear space up to it and mark nothing.

References: S. Kohlbrecher et al., "A flexible and scalable SLAM system with full 3D motion
estimation", SSRR 2011 (Hector mapping: scan-to-map Gauss–Newton on a multi-resolution grid).
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from .. import checks
from .._jit import kernel
from ..errors import InvalidArgumentError
from ..geometry.se2 import compose_poses, relative_poses
from ..geometry.so2 import rot2, wrap_angle_one
from ..grid2d import LidarModel, OccupancyGrid2D
from ..localize import _kernels as K
from ..localize.likelihood_field import beam_end_points
from ..localize.params import LocalizationParams
from ..localize.scan_match import match
from ..raster.edt import bounded_distance
from ..scan import LaserScan

__all__ = ["DEGENERATE_RATIO", "FAILED", "FIRST", "MATCHED", "MatchQuality", "REJECTED", "ScanMatchParams", "ScanMatchTrack",
           "ScanMatcher", "distance_fields", "keep_prior_where_unconstrained", "match_scans", "refine"]

#: Below this ratio of the smaller to the larger eigenvalue of the scatter of a scan's surface
#: normals, the scan constrains the position along one direction only.
DEGENERATE_RATIO = 0.02

#: End points farther apart (m) than this are not taken to lie on one surface.
SURFACE_GAP = 0.5

#: End points scored per candidate of the correlative search, at most (evenly spread).
SEARCH_BEAMS = 120

#: The correlative search runs when Gauss–Newton from a constant-velocity prior keeps fewer than
#: this share of the end points within the fine cutoff (on Intel's run from the ranges alone, 0.3
#: let 27 wrong matches through, 0.8 none) ...
SEARCH_BELOW = 0.8

#: ... and from an odometry prior, which is seldom far off: on Intel's sparse scans (0.67 m apart)
#: 0.8 sent 46 to a search pose with more inliers in a half-mapped room that was a wrong one, 0.3
#: none.
SEARCH_BELOW_ODOMETRY = 0.3

#: Status of a scan in :attr:`ScanMatchTrack.status`.
FIRST, MATCHED, FAILED, REJECTED = 0, 1, 2, 3
STATUS_NAMES = ("first", "matched", "failed", "rejected")


@dataclass(frozen=True, kw_only=True)
class ScanMatchParams:
    """Settings of a :class:`ScanMatcher`, checked when made (a bad value raises
    :class:`~occmap.errors.InvalidArgumentError` naming the field).

    Attributes
    ----------
    resolution : float, default 0.05
        Cell side (m) of the map and of the finest distance field.
    levels : int, default 3
        Distance fields from coarse to fine, at ``resolution · 2^k`` for ``k = levels − 1 … 0``.
    cutoff : float, default 0.15
        End points farther than ``cutoff · 2^k`` (m) from every obstacle are left out at level k.
    field_radius : float, default 20.0
        Half side (m) of the local submap the fields cover, around the last inserted pose.
    insert_range : float, default 30.0
        Readings beyond it (m) clear space up to it and mark nothing when a scan is inserted.
    insert_min_d, insert_min_a : float, default 0.1, 0.1
        Motion (m, rad) since the last insertion that makes a matched scan join the map.
    search_window : (float, float), default (0.4, 0.5)
        Half widths (m in x and y, rad) of the correlative search around the prior; (0, 0)
        leaves it out (Gauss–Newton from the prior alone).
    max_correction : (float, float), default (0.6, 0.7)
        A match moving the pose farther (m, rad) from the prior is rejected.
    max_beams : int, default 400
        End points matched per scan, spread evenly over its valid readings.
    min_range : float, default 0.0
        Readings (m) at or below it are invalid.
    iterations : int, default 10
        Gauss–Newton steps per level at most.
    initial_pose : (float, float, float), default (0, 0, 0)
        The first scan's pose: it defines the frame.
    model : LidarModel, default OctoMap's (0.7, 0.4)
        The inverse sensor model scans are inserted with.
    """

    resolution: float = 0.05
    levels: int = 3
    cutoff: float = 0.15
    field_radius: float = 20.0
    insert_range: float = 30.0
    insert_min_d: float = 0.1
    insert_min_a: float = 0.1
    search_window: tuple = (0.4, 0.5)
    max_correction: tuple = (0.6, 0.7)
    max_beams: int = 400
    min_range: float = 0.0
    iterations: int = 10
    initial_pose: tuple = (0.0, 0.0, 0.0)
    model: LidarModel = field(default_factory=LidarModel)

    def __post_init__(self):
        checks.resolution(self.resolution)
        checks.count("levels", self.levels)
        for name in ("cutoff", "field_radius", "insert_range"):
            checks.positive(name, getattr(self, name), "metres")
        for name in ("insert_min_d", "insert_min_a", "min_range"):
            checks.non_negative(name, getattr(self, name))
        for name, check in (("search_window", checks.non_negative), ("max_correction", checks.positive)):
            value = getattr(self, name)
            if len(value) != 2:
                raise InvalidArgumentError(f"{name} must be (metres, radians), got {value!r}")
            check(f"{name}[0]", value[0], "metres")
            check(f"{name}[1]", value[1], "radians")
        checks.count("max_beams", self.max_beams, 3)
        checks.count("iterations", self.iterations)
        if len(self.initial_pose) != 3:
            raise InvalidArgumentError(f"initial_pose must be (x, y, theta), got {self.initial_pose!r}")
        for k, v in enumerate(self.initial_pose):
            checks.finite(f"initial_pose[{k}]", v)
        if not isinstance(self.model, LidarModel):
            raise InvalidArgumentError(f"model must be a LidarModel, got {type(self.model).__name__}")


class _Field(NamedTuple):
    """A distance field as :func:`~occmap.localize.scan_match.match` reads one, and the per-cell
    score ``exp(−d² / 2·resolution²)`` of the correlative search."""

    distance: np.ndarray  # (H, W) float64, m, clamped at max_dist
    origin: np.ndarray  # (2,) outer corner of cell (0, 0)
    resolution: float
    max_dist: float
    score: np.ndarray | None  # (H, W) float32, the coarsest field's only


class MatchQuality(NamedTuple):
    """How one scan matched: ``status`` (``FIRST``, ``MATCHED``, ``FAILED``, ``REJECTED``), end
    points ``beams`` matched and ``inliers`` within the fine cutoff at the final pose, their
    ``rms`` distance to the map (m, NaN without inliers) and whether the match was ``degenerate``."""

    status: int
    beams: int
    inliers: int
    rms: float
    degenerate: bool


@dataclass
class ScanMatchTrack:
    """The result of :func:`match_scans`, one row per scan.

    Attributes
    ----------
    poses : ndarray (N, 3)
        Scan-matched sensor poses ``(x, y, theta)`` in the frame of the first scan.
    priors : ndarray (N, 3)
        The poses each match started from.
    status : ndarray (N,) int8
        0 first, 1 matched, 2 failed (left at the prior), 3 rejected (left at the prior).
    inliers, beams : ndarray (N,) int64
        End points within the fine cutoff at the final pose, of those matched.
    rms : ndarray (N,)
        RMS distance (m) of the inliers to the map's obstacles.
    degenerate : ndarray (N,) bool
        Matches constrained along one direction only.
    stats : dict
        Counts: ``scans``, ``matched``, ``failed``, ``rejected``, ``degenerate``, ``inserted``.
    grid : OccupancyGrid2D
        The map the scans were matched against.
    """

    poses: np.ndarray
    priors: np.ndarray
    status: np.ndarray
    inliers: np.ndarray
    beams: np.ndarray
    rms: np.ndarray
    degenerate: np.ndarray
    stats: dict
    grid: OccupancyGrid2D

    def __len__(self) -> int:
        return len(self.poses)

    def summary(self) -> str:
        return describe(self.stats)


def describe(stats: dict) -> str:
    """One line on how a matching went, from a :class:`ScanMatcher`'s ``stats``."""
    s = stats
    return (f"scan matching: {s['scans']:,} scans, {s['matched']:,} matched, {s['failed']:,} failed and "
            f"{s['rejected']:,} rejected (left at the prior), {s['degenerate']:,} degenerate, "
            f"{s['inserted']:,} inserted into the map")


def keep_prior_where_unconstrained(pose: np.ndarray, prior: np.ndarray, bx: np.ndarray, by: np.ndarray):
    """``(pose, degenerate)``: when the surfaces of end points ``(bx, by)`` (sensor frame)
    constrain the position along one direction only, ``pose`` with its position moved from the
    prior's along that direction only."""
    tx, ty = bx[2:] - bx[:-2], by[2:] - by[:-2]
    length = np.hypot(tx, ty)
    keep = (length > 0.0) & (length < SURFACE_GAP)
    if np.count_nonzero(keep) < 3:
        return pose, False
    tx, ty = tx[keep] / length[keep], ty[keep] / length[keep]
    # Σ n nᵀ of the normals n = (−t_y, t_x)
    scatter = np.array([[np.dot(ty, ty), -np.dot(tx, ty)], [-np.dot(tx, ty), np.dot(tx, tx)]])
    ev, vec = np.linalg.eigh(scatter)
    if ev[0] >= DEGENERATE_RATIO * ev[1]:
        return pose, False
    v = rot2(pose[2]) @ vec[:, 1]  # the constrained direction, in the world frame
    out = pose.copy()
    out[:2] = prior[:2] + v * np.dot(v, pose[:2] - prior[:2])
    return out, True


class ScanMatcher:
    """Streaming scan-to-map matching: :meth:`add` one scan at a time, get its pose.

    See the module's description for the method; ``params`` is a :class:`ScanMatchParams`.
    ``stats`` counts ``scans``, ``matched``, ``failed``, ``rejected``, ``degenerate``, ``inserted``;
    ``quality`` is the :class:`MatchQuality` of the last scan; ``grid`` the map so far.

    Examples
    --------
    >>> matcher = ScanMatcher()                              # doctest: +SKIP
    >>> for scan in scans:                                   # doctest: +SKIP
    ...     pose = matcher.add(scan)
    """

    def __init__(self, params: ScanMatchParams | None = None):
        self.params = ScanMatchParams() if params is None else params
        if not isinstance(self.params, ScanMatchParams):
            raise InvalidArgumentError(f"params must be ScanMatchParams, got {type(self.params).__name__}")
        p = self.params
        self.grid = OccupancyGrid2D(p.resolution)
        self.stats = {"scans": 0, "matched": 0, "failed": 0, "rejected": 0, "degenerate": 0, "inserted": 0}
        self.quality: MatchQuality | None = None
        self.prior: np.ndarray | None = None
        self._beams = LocalizationParams(max_beams=p.max_beams, laser_min_range=p.min_range)
        self._fields: list[_Field] = []  # coarse to fine; empty until the map has an obstacle
        self._pose: np.ndarray | None = None
        self._step = np.zeros(3)  # the last step's motion, in the frame of the pose before it
        self._odom: np.ndarray | None = None
        self._inserted: np.ndarray | None = None

    @property
    def pose(self) -> np.ndarray | None:
        """The last scan's pose (a copy), None before the first."""
        return None if self._pose is None else self._pose.copy()

    def add(self, scan: LaserScan) -> np.ndarray:
        """Match ``scan`` against the map so far (inserting it when due); returns its sensor
        pose ``(x, y, theta)`` (3,) in the frame of the first scan. Its pose field is not read."""
        p = self.params
        odom = None if scan.odom is None else np.asarray(scan.odom, dtype=np.float64)
        bx, by, _, _ = beam_end_points(np.asarray(scan.ranges, dtype=np.float64),
                                       np.asarray(scan.angles, dtype=np.float64), float(scan.max_range), self._beams)
        degenerate = False
        if self._pose is None:
            pose = np.array(p.initial_pose, dtype=np.float64)
            prior, status = pose.copy(), FIRST
        else:
            prior, by_odometry = self._predict(odom)
            pose, status = self._match(prior, bx, by, SEARCH_BELOW_ODOMETRY if by_odometry else SEARCH_BELOW)
            if status == MATCHED:
                pose, degenerate = keep_prior_where_unconstrained(pose, prior, bx, by)
        self.quality = self._quality(status, pose, bx, by, degenerate)
        self._count(self.quality)
        if self._pose is not None:
            self._step = relative_poses(self._pose, pose)
        self._pose, self._odom, self.prior = pose, odom, prior
        if not self._fields or (status == MATCHED and self._moved_enough(pose)):
            self._insert(scan, pose)
        return pose.copy()

    def _predict(self, odom) -> tuple[np.ndarray, bool]:
        """The prior and whether odometry gave it."""
        if odom is not None and self._odom is not None and np.isfinite(odom).all() and np.isfinite(self._odom).all():
            return compose_poses(self._pose, relative_poses(self._odom, odom)), True
        return compose_poses(self._pose, self._step), False

    def _match(self, prior: np.ndarray, bx: np.ndarray, by: np.ndarray, search_below: float) -> tuple[np.ndarray, int]:
        p = self.params
        if not self._fields:
            return prior, FAILED
        x, inliers = self._refine(prior, bx, by)
        if x is None or inliers < search_below * bx.size:
            y, more = self._refine(self._search(prior, bx, by), bx, by)
            if y is not None and more > inliers:
                x = y
        if x is None:
            return prior, FAILED
        dx = x - prior
        if math.hypot(dx[0], dx[1]) > p.max_correction[0] or abs(wrap_angle_one(dx[2])) > p.max_correction[1]:
            return prior, REJECTED
        return x, MATCHED

    def _refine(self, start: np.ndarray, bx: np.ndarray, by: np.ndarray) -> tuple[np.ndarray | None, int]:
        return refine(self._fields, start, bx, by, self.params.cutoff, self.params.iterations)

    def _search(self, prior: np.ndarray, bx: np.ndarray, by: np.ndarray) -> np.ndarray:
        """The best pose of the correlative search around ``prior`` on the coarsest field."""
        wt, wa = self.params.search_window
        if bx.size == 0 or (wt == 0.0 and wa == 0.0):
            return prior
        f = self._fields[0]
        if bx.size > SEARCH_BEAMS:
            pick = np.rint(np.linspace(0, bx.size - 1, SEARCH_BEAMS)).astype(np.int64)
            bx, by = bx[pick], by[pick]
        reach = max(float(np.percentile(np.hypot(bx, by), 90)), f.resolution)
        dt = 0.5 * f.resolution
        da = f.resolution / reach
        ts = dt * np.arange(-math.floor(wt / dt), math.floor(wt / dt) + 1)
        angles = da * np.arange(-math.floor(wa / da), math.floor(wa / da) + 1)
        gx, gy, ga = (a.ravel() for a in np.meshgrid(ts, ts, angles, indexing="ij"))
        candidates = np.column_stack([prior[0] + gx, prior[1] + gy, prior[2] + ga])
        out = np.empty(len(candidates))
        K.score_particles(candidates, np.ascontiguousarray(bx), np.ascontiguousarray(by), f.score, 0.0,
                          f.origin[0], f.origin[1], 1.0 / f.resolution, out)
        penalty = (gx * gx + gy * gy) / (0.5 * max(wt, dt)) ** 2 + (ga / (0.5 * max(wa, da))) ** 2
        best = int(np.argmax(out * np.exp(-0.5 * penalty)))
        x = candidates[best]
        x[2] = wrap_angle_one(float(x[2]))
        return x

    def _quality(self, status: int, pose: np.ndarray, bx: np.ndarray, by: np.ndarray, degenerate: bool) -> MatchQuality:
        if not self._fields:
            return MatchQuality(status, bx.size, 0, math.nan, degenerate)
        f = self._fields[-1]
        Hm, g = np.empty((3, 3)), np.empty(3)
        cost, used = K.match_normal_equations(pose, bx, by, f.distance, f.max_dist, self.params.cutoff,
                                              f.origin[0], f.origin[1], 1.0 / f.resolution, Hm, g)
        rms = math.sqrt(cost / used) if used else math.nan
        return MatchQuality(status, bx.size, used, rms, degenerate)

    def _count(self, q: MatchQuality) -> None:
        s = self.stats
        s["scans"] += 1
        if q.status != FIRST:
            s[STATUS_NAMES[q.status]] += 1
        s["degenerate"] += q.degenerate

    def _moved_enough(self, pose: np.ndarray) -> bool:
        d = relative_poses(self._inserted, pose)
        return math.hypot(d[0], d[1]) >= self.params.insert_min_d or abs(d[2]) >= self.params.insert_min_a

    def _insert(self, scan: LaserScan, pose: np.ndarray) -> None:
        p = self.params
        ranges = np.asarray(scan.ranges, dtype=np.float64)
        with np.errstate(invalid="ignore"):
            ranges = np.where(ranges >= scan.max_range, np.inf, ranges)  # no return
        reach = min(float(scan.max_range), p.insert_range)
        self.grid.insert_scan(pose, ranges, scan.angles, max_range=reach, model=p.model)
        self._inserted = pose.copy()
        self.stats["inserted"] += 1
        self._fields = self._build_fields(pose)

    def _build_fields(self, centre: np.ndarray) -> list[_Field]:
        """Distance fields of the submap around ``centre``, coarse to fine (empty: no obstacle)."""
        p = self.params
        r = p.field_radius
        L, corner = self.grid.log_odds_in((centre[0] - r, centre[1] - r), (centre[0] + r, centre[1] + r))
        with np.errstate(invalid="ignore"):
            occupied = L > 0  # NaN (unobserved) is not an obstacle
        if not occupied.any():
            return []
        return distance_fields(occupied, corner, p.resolution, p.levels, p.cutoff)


@kernel
def _coarser(mask, out):
    """``out`` ((H + 1) // 2, (W + 1) // 2) ← whether any of the (up to) 2 × 2 cells of ``mask``
    (H, W) that each of its cells covers is True (one pass over ``out``, branch-free)."""
    H, W = mask.shape
    h, w = out.shape
    for Y in range(h):
        y0 = 2 * Y
        y1 = min(y0 + 1, H - 1)  # an odd last row covers one row
        for X in range(W // 2):
            out[Y, X] = mask[y0, 2 * X] | mask[y0, 2 * X + 1] | mask[y1, 2 * X] | mask[y1, 2 * X + 1]
        if W % 2:
            out[Y, w - 1] = mask[y0, W - 1] | mask[y1, W - 1]


def distance_fields(occupied: np.ndarray, corner, resolution: float, levels: int, cutoff: float,
                    score: bool = True) -> list[_Field]:
    """Distance fields (:class:`_Field`, coarse to fine) of the obstacle cells ``occupied``
    (bool (H, W), row 0 at ``corner``, the outer corner (x, y) of cell (0, 0), cells of side
    ``resolution`` m): level k at ``resolution · 2^k`` (a coarse cell is occupied when any of the
    finer cells it covers is), clamped just beyond its cutoff ``cutoff · 2^k`` (m); the coarsest
    with the correlative search's score when ``score`` (:func:`refine` does not read it)."""
    fields = []
    mask = np.ascontiguousarray(occupied, dtype=np.bool_)
    for k in range(levels):
        if k:
            coarse = np.empty(((mask.shape[0] + 1) // 2, (mask.shape[1] + 1) // 2), dtype=np.bool_)
            _coarser(mask, coarse)
            mask = coarse
        res = resolution * 2 ** k
        far = cutoff * 2 ** k + res
        dist = bounded_distance(mask, res, far)
        fields.append(_Field(dist, np.asarray(corner, dtype=np.float64), res, far, None))
    if score:
        coarse = fields[-1]
        fields[-1] = coarse._replace(score=np.exp(-0.5 * (coarse.distance / coarse.resolution) ** 2).astype(np.float32))
    return fields[::-1]


def refine(fields: list[_Field], start: np.ndarray, bx: np.ndarray, by: np.ndarray, cutoff: float,
           iterations: int) -> tuple[np.ndarray | None, int]:
    """Gauss–Newton coarse to fine (:func:`distance_fields`) from pose ``start`` for end points
    ``(bx, by)`` (sensor frame, m), ends farther than ``cutoff · 2^k`` (m) from every obstacle
    left out at level k: ``(pose, inliers at the finest level)``, the pose None when the finest
    level failed (a coarse level that finds too little leaves the finer ones where it began)."""
    x = start
    used = 0
    for level, f in enumerate(fields):
        found, used = match(f, x, bx, by, cutoff * 2 ** (len(fields) - 1 - level), iterations)
        if found is None:
            if level == len(fields) - 1:
                return None, used
            continue
        x = found
    return x, used


def match_scans(scans, params: ScanMatchParams | None = None, progress: bool = False) -> ScanMatchTrack:
    """Scan-match a run of :class:`~occmap.scan.LaserScan` (their poses are not read): the batch
    form of :class:`ScanMatcher`, giving the very same poses. Odometry, where the scans carry
    it, is the prior of each match. ``progress`` draws a counter on stderr."""
    matcher = ScanMatcher(params)
    poses, priors, rows = [], [], []
    for i, scan in enumerate(scans):
        poses.append(matcher.add(scan))
        priors.append(matcher.prior)
        rows.append(matcher.quality)
        if progress and i % 100 == 0:
            print(f"\rscan matching: scan {i + 1:,}", end="", file=sys.stderr, flush=True)
    if progress:
        print(file=sys.stderr)
    n = len(poses)
    q = MatchQuality(*zip(*rows)) if n else MatchQuality((), (), (), (), ())
    return ScanMatchTrack(
        poses=np.array(poses, dtype=np.float64).reshape(n, 3),
        priors=np.array(priors, dtype=np.float64).reshape(n, 3),
        status=np.array(q.status, dtype=np.int8),
        inliers=np.array(q.inliers, dtype=np.int64),
        beams=np.array(q.beams, dtype=np.int64),
        rms=np.array(q.rms, dtype=np.float64),
        degenerate=np.array(q.degenerate, dtype=bool),
        stats=dict(matcher.stats),
        grid=matcher.grid,
    )
