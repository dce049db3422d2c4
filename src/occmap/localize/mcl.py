"""Monte Carlo localization (particle filter) of a planar range sensor in a known occupancy grid.

The filter is ROS AMCL's (Thrun, Burgard & Fox, *Probabilistic Robotics*, ch. 4, 5, 6 and 8):

* **motion** — the odometry model of :mod:`occmap.geometry.motion` (rot1–trans–rot2 with the four
  ``alpha`` noise terms), applied to every particle with its own noise draw. A large step between
  two scans (scans dropped, a slow sensor, a fast turn) is integrated like any other, its noise
  growing with its size, as AMCL's ``sample_motion_model_odometry`` does: nothing is refused or
  replaced by an ad-hoc spread. As in AMCL the filter runs only once the odometry has moved
  ``update_min_d`` metres or turned ``update_min_a`` radians since its last run; between runs the
  estimate follows the odometry.
* **measurement** — the likelihood field (:mod:`~occmap.localize.likelihood_field`): each beam
  scores by the distance from its end point to the nearest obstacle of the map. Readings that are
  not finite, at or below ``laser_min_range`` or at/beyond the scan's ``max_range`` (no return)
  carry no information and are skipped; at most ``max_beams`` of the rest are used, evenly spread
  over the scan.
* **resampling** (:mod:`~occmap.localize.resample`) — low-variance (systematic) resampling when the
  effective sample size ``1 / Σ w²`` falls below ``resample_ess · N``; optional KLD-adaptive
  particle count (Fox 2003, AMCL's ``kld_err``/``kld_z`` and its 0.5 m × 0.5 m × 10° bins); random
  particles drawn uniformly over free space are injected with probability ``max(0, 1 − w_fast /
  w_slow)`` (``recovery_alpha_slow``/``recovery_alpha_fast``), AMCL's way of finding a kidnapped
  robot again (on the real runs it does not: see *finding the robot again*). Unlike AMCL the
  averages are not reset after an injection (the book's version: injection continues for as long
  as the short-term likelihood stays below the long-term one),
  injection starts only once ``w_fast / w_slow`` falls below ``recovery_threshold`` (on the Intel
  log, stretches where the scans fit the map poorly drop the ratio below 1 while tracking is fine,
  and a few random particles then win), and the averaged likelihood is the per-beam geometric mean,
  so it does not depend on how many beams a scan had. Injection is off by default, as in AMCL
  (``recovery_alpha_slow = recovery_alpha_fast = 0``).
* **tempering** — with ``min_ess`` a scan that would leave fewer effective particles than that
  share of N is applied with its likelihood raised to a power below 1 (adaptive tempering).
* **coasting** — with ``coast_fit`` a scan the map does not explain where the odometry says the
  robot is (after a local scan match from there: less than ``coast_fit`` of the usual ``fit``) is
  left out: the odometry alone carries the estimate and moves the cloud rigidly (without motion
  noise: with AMCL's noise terms a cloud coasting 4 m spreads 4 m × 2 m × 160°, and the first scan
  weighed afterwards picks any pose in it that fits). Where the map shows a place poorly (Freiburg
  079: a room visited once, where the robot turns on the spot and the corrected poses fit their own
  map 0.3–0.45 m off) such scans fit better at wrong poses a metre and 50–90° away, and weighing
  them drags the cloud there a few degrees per scan. After ``coast_max_d`` metres or ``coast_max_a``
  radians of coasting the filter keeps **two hypotheses**: the scans weigh the cloud again (a filter
  that is really lost, or an odometry gone wrong, is found by it), while the estimate stays the
  odometry's. The held pose is **dead reckoning**: it carries a covariance grown from the cloud's by
  the odometry's noise (``coast_motion``, the extended Kalman filter's prediction), and its best
  pose is the local scan match, from it and from its 1- and 2-sigma points, that scores highest (the
  scan's log-likelihood plus the log of that Gaussian prior). Where that pose and the cloud's
  estimate agree, the cloud's estimate is taken once it is not ``lost`` (its fit at least
  ``lost_fit`` of the usual) on ``coast_confirm`` filter runs in a row. Where they differ, a
  sequential likelihood ratio decides: the scans' log-likelihood at the cloud's estimate minus that
  at the held pose's best, summed over the runs since the cap on which they differ, plus the two
  priors, must reach ``coast_evidence`` for the cloud, ``−coast_evidence`` for the held pose's best
  (each must also have fitted on ``coast_confirm`` runs in a row; taking the held pose's best moves
  the cloud to it). If the odometry's pose itself fits a scan (``coast_fit``) first, the cloud is
  moved back to it. (Freiburg 079, refs 1090–1240: the reference's own scans fit the map 0.2–1.1 m
  off for 13 m of travel; weighed, those scans pulled the cloud 2–4 m away and it never came back.
  The cloud's wrong poses there fit at ``coast_fit`` for 10 runs in a row while the robot turned on
  the spot, hence the stricter ``lost_fit``; and at ref 1,238 a cloud 1.07 m off fitted five runs in
  a row, while the held pose's neighbourhood had explained the scans since the cap by hundreds of
  nats more: taken on fits alone it was confirmed and the filter coasted from there, 1.08 m off;
  weighed by the ratio (−480 nats), the held pose's best, 0.08–0.34 m from the reference on refs
  1,227–1,238 while the held pose drifted to 0.49 m, is taken at ref 1,239, 0.04 m off.)
* **estimate** — the weighted mean of the dominant mode of the cloud (circular mean for the
  heading), its covariance and the effective sample size. A multi-modal cloud (global
  localization before it converges) reports its heaviest mode and the share of weight in it.
  ``fit`` is the share of the scan the map explains at the estimate and ``lost`` says it fell well
  below its usual value (``lost_fit``): the signal a caller acts on. Measured on the real runs
  (``lost_fit = 0.85``): raised for 4.4 % of Intel's scans while the track is right, and for the
  first scans after a simulated kidnapping until the filter is found again.
* **finding the robot again** — with ``relocalize_after`` a ``lost`` estimate on that many filter
  runs in a row starts a global localization as a **second hypothesis** (a copy of the filter that
  shares its map and draws from its own random stream, with the schedule of *global localization*
  below) which runs on the same scans beside the tracking filter; the published estimate stays the
  tracking filter's, coasting on odometry as above. The search replaces the cloud only once it has
  converged and, on every one of its runs over ``coast_confirm`` runs and ``relocalize_confirm_d``
  metres of odometry travel, its estimate was not lost (against its own usual fit, which starts at
  its first converged scan: the robot may now be where the map explains less than where it was),
  fitted the scan at least as well as the tracking estimate, its cloud was compact (position
  standard deviation along its longest axis at most half ``refine_cutoff``), and the tracking
  estimate was lost or the scan favoured the search's estimate over it by ``coast_evidence`` (the
  difference of the scan's log-likelihoods at the two under the filter's beam model). It is dropped once the tracking estimate has not been lost over as many runs
  and metres, and starts over when its own estimate is lost on ``relocalize_after`` runs in a row. A
  restart must not throw away a right track: the ``lost`` flag is raised for 4.4 % of Intel's scans
  while the track is right, and for stretches of Freiburg 079 where the map is wrong, and there a
  hypothesis elsewhere can fit better. Measured: 3 m of confirmation let a wrong hypothesis (up to
  30 m off) replace a right track on Freiburg 079 (seed 7), and without the condition that the
  tracking estimate be lost a right but poorly fitting track was replaced (refs 304–422, seed 1);
  with 5 m and the condition, tracking on both runs is as without the search (no replacement on
  seeds 7, 1, 2, 3). In a corridor a wrong hypothesis can slide along it while fitting every scan,
  its cloud spread 0.2–0.35 m along the axis where a right one's is 0.04 m (Freiburg 079, kidnapped
  from ref 2,579: before the cloud had to be compact, such a hypothesis replaced the kidnapped
  track). A wrong track can fit most of a scan, though: on Freiburg 079 kidnapped from refs 0,
  2,210 and 2,579 the tracks left 5–28 m off fitted 0.80–0.97 of the scans (from ref 0 its usual fit
  drifted from 1.00 to 0.88) and were not lost on every run, and each such run reset the
  confirmation of a search that fitted 0.98–1.00 on the robot (replaced after 20.4–21.5 m, or
  never); hence a run also counts when the scan favours the search by ``coast_evidence``. Kidnapped
  from 10 places of each run (``BENCHMARKS.md``), the robot is back within 0.2 m for good after
  6.4–12.7 m of travel on Intel and 7.2–13.6 m on Freiburg 079, all 20. Global localization in a search costs more than tracking
  (``global_particles``), but runs only every ``global_update_min_d`` / ``global_update_min_a``.
  Random-particle injection (above) is the cheaper textbook answer, but did not bring the robot back
  on the real runs.
* **global localization** — :meth:`MonteCarloLocalizer.initialize_global` spreads
  ``global_particles`` over the free space and runs the filter coarse to fine: until the dominant
  mode holds ``converged_weight`` of the weight, beams score with the wider ``global_sigma_hit``
  (a particle a few decimetres and degrees off the true pose still scores well, so the few that
  land near it survive until the robot's motion and more scans sharpen the cloud), the filter
  runs only every ``global_update_min_d`` / ``global_update_min_a`` (AMCL's spacing: scans taken
  a few centimetres apart repeat each other, and counting them as independent evidence locks
  the cloud onto a wrong mode within a few updates while the robot turns on the spot), the
  particle count stays, and there is no scan-match refinement (a correction fed back to a
  multi-modal cloud would drag every other mode with it). Once converged, the filter tracks
  with its own settings and resamples down to ``n_particles`` (or the KLD count).

Two additions beat plain AMCL's accuracy on real logs (measured in ``BENCHMARKS.md``):

* ``roughening`` (Gordon, Salmond & Smith 1993): after resampling each particle is jittered by a
  Gaussian whose standard deviation per dimension is ``K · E · N^(−1/3)`` (``E`` the cloud's
  spread, its 2nd–98th percentile range), so the cloud cannot collapse onto a few copies of one
  particle and can follow a pose between the samples it held;
* ``refine``: a local scan match of the estimate (:mod:`~occmap.localize.scan_match`: Gauss–Newton
  on the distance field, all valid beams, end points farther than ``refine_cutoff`` from any
  obstacle ignored, then finished on those within ``refine_finish``), which places the pose
  between the particles and below the grid's resolution; with ``refine_feedback`` the whole cloud
  is shifted by the correction.

Poses are ``(x, y, theta)`` of the *sensor* in the map frame unless ``sensor_offset`` (the
sensor's pose in the robot frame) is given; then particles and estimates are robot poses.

The settings, with units and defaults, are one :class:`~occmap.localize.params.LocalizationParams`.
"""

from __future__ import annotations

import copy
import math
import os
import warnings
from dataclasses import dataclass, field

import numpy as np

from .. import checks
from .._threads import OneCallAtATime
from ..errors import InvalidArgumentError, NonFiniteError, ShapeError
from ..geometry.motion import apply_odometry, odometry_delta
from ..geometry.so2 import wrap_angle, wrap_angle_one
from ..grid2d import OccupancyGrid2D
from . import _kernels as K
from .likelihood_field import LikelihoodField, beam_end_points
from .params import LocalizationParams
from .resample import kld_count, roughen, systematic
from .scan_match import match

#: Rate of the long-term average of the estimates' ``fit`` (about the last 100 filter runs) that
#: ``lost`` compares each fit with: what "usual" is depends on the sensor, the map and the place.
FIT_AVERAGE_RATE = 0.01

#: Largest |x| or |y| (metres) of a pose, odometry pose or map corner the filter accepts: beyond
#: it the particle arithmetic (binning, differences, weights) overflows or loses all precision.
MAX_COORDINATE = 1e9


def _within_reach(name: str, xy) -> None:
    """InvalidArgumentError naming ``name`` when a coordinate exceeds :data:`MAX_COORDINATE`."""
    if not np.all(np.abs(np.asarray(xy, dtype=np.float64)) <= MAX_COORDINATE):
        raise InvalidArgumentError(f"{name} {np.asarray(xy).tolist()} lies beyond ±{MAX_COORDINATE:g} m, farther "
                                   "than the localizer's arithmetic can follow")


def _pose(name: str, value) -> np.ndarray:
    """``value`` as a finite pose ``(x, y, theta)`` within reach, or an error naming ``name``."""
    p = np.asarray(value, dtype=np.float64)
    if p.shape != (3,):
        raise ShapeError(f"{name} must be (x, y, theta), got shape {p.shape}")
    if not np.isfinite(p).all():
        raise NonFiniteError(f"{name} {p.tolist()} is not finite")
    _within_reach(name, p[:2])
    return p


__all__ = ["LocalizationWarning", "MonteCarloLocalizer", "PoseEstimate"]


class LocalizationWarning(UserWarning):
    """Something in the input the filter could not use as given (a scan with no valid reading); the
    message says what and how it was handled."""


@dataclass(frozen=True)
class PoseEstimate:
    """What :meth:`MonteCarloLocalizer.update` returns.

    Attributes
    ----------
    pose : ndarray (3,)
        ``(x, y, theta)``: weighted mean of the dominant mode, heading by circular mean, wrapped;
        refined by the scan match when that is on and succeeded.
    covariance : ndarray (3, 3)
        Weighted covariance of the dominant mode (heading residuals wrapped about the mean).
    ess : float
        Effective sample size ``1 / Σ w²`` of the weights after the last measurement update
        (before any resampling).
    n_particles : int
        Particles in the filter now.
    mode_weight : float
        Share of the total weight in the dominant mode (1 for a single compact cloud).
    converged : bool
        False while a global localization has not converged (the pose is the heaviest mode's).
    updated : bool
        Whether the filter ran on this call (else the pose followed the odometry only).
    beams : int
        Beams used by the measurement update (0 when it did not run or had none).
    fit : float
        Share of the scan's valid beams whose end points, seen from ``pose``, lie within
        ``refine_cutoff`` of an obstacle of the map (the last filter run's when the filter did not
        run; NaN when the scan had no valid reading): how much of what the sensor sees the map
        explains at the estimate.
    lost : bool
        ``fit`` below ``lost_fit`` times its usual value (its average over about the last 100 filter
        runs that were not lost): much of the scan is unexplained where the filter believes the robot
        is (kidnapped, a wrong initial pose, or a place the map does not show as it is now).
        A caller can act on it (stop, re-initialize, call :meth:`MonteCarloLocalizer.initialize_global`);
        with ``relocalize_after`` the filter acts on it itself (a global search beside the track).
        With ``covariance`` and ``ess`` it is the filter's confidence.
    """

    pose: np.ndarray
    covariance: np.ndarray
    ess: float
    n_particles: int
    mode_weight: float = 1.0
    updated: bool = False
    beams: int = 0
    converged: bool = True
    fit: float = math.nan
    lost: bool = False


@dataclass
class _Stats:
    updates: int = 0
    resamples: int = 0
    injected: int = 0
    empty_scans: int = 0
    refined: int = 0
    refine_rejected: int = 0
    tempered: int = 0
    coasted: int = 0
    scan_triggered: int = 0  # filter runs the scan asked for, not the odometry (``_scan_moved``)
    searches: int = 0  # global searches started because the estimate stayed lost
    relocalized: int = 0  # searches whose hypothesis replaced the cloud
    converged_after: int | None = None  # filter runs of a global localization until it converged
    extra: dict = field(default_factory=dict)


class MonteCarloLocalizer(OneCallAtATime):
    """A particle filter that localizes a range sensor in a fixed occupancy grid (ROS AMCL).

    Parameters
    ----------
    grid : OccupancyGrid2D or str or os.PathLike
        The map; a path is read as a map_server YAML (:meth:`OccupancyGrid2D.load`).
    n_particles : int, optional
        Shorthand for the ``n_particles`` setting.
    params : LocalizationParams, optional
        The settings (default: :class:`LocalizationParams`'s defaults).
    seed : int or numpy.random.Generator, optional
        Source of randomness (reproducible runs).
    **settings
        Fields of :class:`LocalizationParams` that replace those of ``params``, e.g.
        ``MonteCarloLocalizer(grid, 1000, refine=True, seed=0)``.

    Attributes
    ----------
    params : LocalizationParams
    field : LikelihoodField
        The map's distance field and beam scores.
    particles : ndarray (N, 3), weights : ndarray (N,)
    stats
        Counts of filter runs, resamplings, injected particles, refinements, global searches started
        (``searches``) and those that replaced the cloud (``relocalized``), ...
    """

    def __init__(self, grid, n_particles: int | None = None, *, params: LocalizationParams | None = None, seed=None,
                 **settings):
        if isinstance(grid, (str, os.PathLike)):
            grid = OccupancyGrid2D.load(grid)
        if not isinstance(grid, OccupancyGrid2D):
            raise InvalidArgumentError(f"grid must be an OccupancyGrid2D or a map_server YAML path, got {type(grid).__name__}")
        if params is None:
            params = LocalizationParams()
        elif not isinstance(params, LocalizationParams):
            raise InvalidArgumentError(f"params must be a LocalizationParams, got {type(params).__name__}")
        if n_particles is not None:
            settings["n_particles"] = n_particles
        self.params = params.replace(**settings) if settings else params
        self.rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
        if grid.origin is not None:
            H, W = grid.shape
            _within_reach("the map's corners", [grid.origin, grid.origin + grid.resolution * np.array([W, H])])
        self.field = LikelihoodField(grid, self.params)
        self.grid = grid
        self.particles = np.zeros((0, 3))
        self.weights = np.zeros(0)
        self.w_slow = 0.0
        self.w_fast = 0.0
        self.stats = _Stats()
        self._filter_odom = None  # odometry pose at the last filter run
        # odometry travel (m) and summed turns (rad) since the last applied scan; None once past the cap
        self._coasted: tuple[float, float] | None = (0.0, 0.0)
        self._held = None  # coasting: the pose the odometry alone carried from the last scan that fitted
        self._held_cov = None  # covariance (3×3) of the held pose: dead reckoning since the hold began
        self._dr_best = None  # past the cap: the dead-reckoning hypothesis's best pose (moved by the odometry)
        self._confirm = 0  # past the cap: consecutive filter runs whose (cloud's) estimate the scan fits
        self._evidence = 0.0  # past the cap: summed log-likelihood ratio, cloud's estimate over the held pose's best
        self._dr_confirm = 0  # past the cap: consecutive filter runs whose scan fits the held pose's best
        self._usual_fit = None  # long-term average of the estimates' fit while not lost
        self._lost_runs = 0  # consecutive filter runs whose estimate was lost (or, searching, was not)
        self._right_travel = 0.0  # searching: odometry travel (m) over those runs that were not lost
        self._search: MonteCarloLocalizer | None = None  # the second hypothesis: a global localization
        # its consecutive filter runs that fit and fit better than the estimate, their odometry travel (m),
        # and its consecutive runs that do not fit
        self._search_confirm = (0, 0.0, 0)
        self._estimate: PoseEstimate | None = None
        self._force = True
        self._global = False  # a global localization that has not converged yet
        self._count = self.params.n_particles  # particles drawn at each resampling (without KLD)

    # ------------------------------------------------------------------ initialization

    def initialize(self, pose, cov=None, n: int | None = None) -> None:
        """Start tracking: ``n`` (default ``n_particles``) particles drawn from a Gaussian around
        ``pose`` ``(x, y, theta)`` with covariance ``cov`` (3×3, or 3 variances; default AMCL's
        0.5² m², 0.5² m², (π/12)² rad²)."""
        p = _pose("pose", pose)
        c = np.diag([0.25, 0.25, (np.pi / 12) ** 2]) if cov is None else np.asarray(cov, dtype=np.float64)
        if c.shape == (3,):
            c = np.diag(c)
        if c.shape != (3, 3):
            raise ShapeError(f"cov must be (3, 3) or three variances, got shape {c.shape}")
        if not np.isfinite(c).all():
            raise NonFiniteError("cov is not finite")
        c = 0.5 * (c + c.T)
        vals, vecs = np.linalg.eigh(c)
        if vals.min() < -1e-12 * max(1.0, vals.max()):
            raise InvalidArgumentError(f"cov must be positive semi-definite, has eigenvalue {vals.min()!r}")
        n = self.params.n_particles if n is None else checks.count("n", n)
        z = self.rng.standard_normal((n, 3))
        parts = p + (z * np.sqrt(np.maximum(vals, 0.0))) @ vecs.T
        parts[:, 2] = wrap_angle(parts[:, 2])
        self._reset(parts, global_phase=False)

    def initialize_global(self, n: int | None = None) -> None:
        """Global localization: ``n`` particles (default ``global_particles``) uniformly over the
        free cells, headings uniform; the filter runs coarse to fine until it converges (see the
        module's notes)."""
        n = self.params.global_particles if n is None else checks.count("n", n)
        self._reset(self.field.uniform_free(n, self.rng), global_phase=True)

    def _reset(self, particles: np.ndarray, global_phase: bool) -> None:
        self.particles = np.ascontiguousarray(particles)
        self.weights = np.full(len(particles), 1.0 / len(particles))
        self._global = global_phase
        self._count = len(particles)
        self.w_slow = self.w_fast = 0.0
        self._filter_odom = None
        self._coasted = (0.0, 0.0)
        self._release()
        self._lost_runs = 0
        self._search = None
        self._search_confirm = (0, 0.0, 0)
        self._estimate = None
        self._force = True

    # ------------------------------------------------------------------ the filter step

    def update(self, odometry_pose, ranges, angles, max_range: float) -> PoseEstimate:
        """One step: move by the odometry since the last filter run, weigh by the scan, resample.

        Parameters
        ----------
        odometry_pose : (x, y, theta)
            The raw odometry pose at the time of the scan (any frame: only its changes are used).
        ranges : array_like (n,)
            Readings in metres; non-finite ones, those at or below ``laser_min_range`` and those at or
            beyond ``max_range`` are not used.
        angles : array_like (n,)
            Beam angles relative to the sensor's heading.
        max_range : float
            The sensor's maximum range.

        Returns
        -------
        PoseEstimate
        """
        if self.particles.shape[0] == 0:
            raise InvalidArgumentError("initialize() or initialize_global() the filter before update()")
        odom = _pose("odometry_pose", odometry_pose)
        r = np.asarray(ranges, dtype=np.float64).reshape(-1)
        a = np.asarray(angles, dtype=np.float64).reshape(-1)
        if r.shape != a.shape:
            raise ShapeError(f"ranges {r.shape} and angles {a.shape} must have the same shape")
        mr = checks.positive("max_range", max_range)

        if self._filter_odom is None:
            self._filter_odom = odom.copy()

        prm = self.params
        rot1, trans, rot2 = odometry_delta(self._filter_odom, odom, min_trans=prm.motion.min_trans)
        min_d, min_a = ((prm.global_update_min_d, prm.global_update_min_a) if self._global
                        else (prm.update_min_d, prm.update_min_a))
        moved = float(trans) >= min_d and min_d > 0
        turned = abs(wrap_angle_one(float(rot1 + rot2))) >= min_a and min_a > 0
        run = self._force or moved or turned or (min_d == 0 and min_a == 0)
        bx, by, bx_all, by_all = beam_end_points(r, a, mr, prm)
        if not run:
            est = self._estimate
            pose = apply_odometry(est.pose, (rot1, trans, rot2))
            if not self._scan_moved(pose, bx_all, by_all, min_d, min_a):
                return PoseEstimate(pose, est.covariance, est.ess, len(self.particles), est.mode_weight, False, 0,
                                    est.converged, est.fit, est.lost)
            self.stats.scan_triggered += 1

        coast = bx.size > 0 and self._coast((rot1, trans, rot2), bx_all, by_all)
        # motion (rigid while coasting)
        if float(trans) > 0 or float(rot1) != 0 or float(rot2) != 0:
            self.particles = apply_odometry(self.particles, (rot1, trans, rot2), None if coast else prm.motion.alphas,
                                            self.rng)
        self._filter_odom = odom.copy()
        self._force = False

        # measurement
        ess = 1.0 / float(np.sum(self.weights ** 2))
        if coast:
            self.stats.coasted += 1
        elif bx.size:
            self._weigh(bx, by, mr)
            ess = 1.0 / float(np.sum(self.weights ** 2))
            if ess < prm.resample_ess * len(self.particles) or self._inject_probability() > 0:
                self._resample()
        else:
            self.stats.empty_scans += 1
            warnings.warn("scan has no valid reading: the filter moved by odometry only", LocalizationWarning,
                          stacklevel=2)
        self.stats.updates += 1
        pose, cov, mode_w = self._mean()
        if self._global and mode_w >= prm.converged_weight:
            # one mode left: track from here on, and shrink the cloud at the next resampling
            self._global = False
            self._count = prm.n_particles
            self.stats.converged_after = self.stats.updates
        if prm.refine and not self._global and bx_all.size and not coast:
            pose = self._refine(pose, bx_all, by_all)
        if self._held is not None:
            pose = self._choose(pose, coast, bx, by, mr, bx_all, by_all)
        fit, lost = math.nan, False
        if bx_all.size:
            fit = self._fit(pose, bx_all, by_all)
            if self._usual_fit is None and not self._global:
                self._usual_fit = fit  # the first tracked scan sets what is usual
            lost = self._usual_fit is not None and fit < prm.lost_fit * self._usual_fit
            if not lost and not self._global:
                self._usual_fit += FIT_AVERAGE_RATE * (fit - self._usual_fit)
        self._estimate = PoseEstimate(pose, cov, ess, len(self.particles), mode_w, True, int(bx.size),
                                      not self._global, fit, lost)
        if bx.size and not self._global and self._usual_fit is not None and prm.relocalize_after > 0:
            self._relocalize(odom, r, a, mr, bx, by, fit, lost, float(trans))
        return self._estimate

    def _relocalize(self, odom, r, a, mr, bx, by, fit: float, lost: bool, trans: float) -> None:
        """The second hypothesis. After ``relocalize_after`` lost filter runs in a row a global
        localization starts beside the tracking filter (a copy of this localizer sharing its map,
        with its own random stream and no search of its own) and runs on the same scans, while the
        estimate stays the tracking filter's. The search is dropped once the estimate has not been
        lost on ``coast_confirm`` runs in a row over ``relocalize_confirm_d`` metres of odometry
        travel. Once converged, the search's estimate has its own ``lost`` flag (its usual fit
        starts at its first converged scan: the robot may be where the map explains less than
        where it was); lost on ``relocalize_after`` of its runs in a row, the search starts over
        from the whole free space. It replaces the cloud once, on every one of its runs over the
        last ``coast_confirm`` runs and ``relocalize_confirm_d`` metres of odometry travel, its
        estimate was not lost, fitted the scan at least as well as the tracking filter's and its
        cloud was compact (position standard deviation at most ``refine_cutoff / 2`` along its
        longest axis), and the tracking filter's estimate was lost or the scan's log-likelihood
        (``bx``, ``by``: the beams the filter weighed) at the search's estimate exceeded that at the
        tracking filter's by ``coast_evidence``: a wrong track that fits most of the scan is not
        lost on every run, and each run it was not reset the confirmation (Freiburg 079)."""
        prm = self.params
        if self._search is None:
            self._lost_runs = self._lost_runs + 1 if lost else 0
            if self._lost_runs >= prm.relocalize_after:
                self._search = copy.copy(self)
                self._search.params = prm.replace(relocalize_after=0)
                self._search.stats = _Stats()
                self._search.rng = self.rng.spawn(1)[0]  # the tracking filter's draws stay as without a search
                self._start_search()
                self.stats.searches += 1
            return
        self._lost_runs = 0 if lost else self._lost_runs + 1
        self._right_travel = 0.0 if lost else self._right_travel + trans
        if self._lost_runs >= prm.coast_confirm and self._right_travel >= prm.relocalize_confirm_d:
            self._search = None
            self._lost_runs = 0
            return
        before = self._search._filter_odom
        found = self._search.update(odom, r, a, mr)
        if not found.updated or not found.converged:
            return
        runs, travel, misfits = self._search_confirm
        spread = math.sqrt(max(float(np.linalg.eigvalsh(found.covariance[:2, :2])[-1]), 0.0))
        rejected = found.lost or found.fit < fit or spread > 0.5 * prm.refine_cutoff
        if not (rejected or lost):  # a track not lost gives way only where the scan favours the search
            both = self.field.score(np.stack([found.pose, self._estimate.pose]), bx, by, mr, prm.sigma_hit)
            rejected = both[0] - both[1] < prm.coast_evidence
        if rejected:
            self._search_confirm = (0, 0.0, misfits + 1 if found.lost else 0)
            if misfits + 1 >= prm.relocalize_after:
                self._start_search()
            return
        travel += 0.0 if before is None else math.hypot(odom[0] - before[0], odom[1] - before[1])
        self._search_confirm = (runs + 1, travel, 0)
        if runs + 1 < prm.coast_confirm or travel < prm.relocalize_confirm_d:
            return
        s = self._search
        self.particles, self.weights, self._filter_odom = s.particles, s.weights, s._filter_odom
        self.w_slow, self.w_fast, self._count = s.w_slow, s.w_fast, s._count
        self._release()
        self._lost_runs = 0
        self._search = None
        self.stats.relocalized += 1
        e = self._estimate
        self._estimate = PoseEstimate(found.pose, found.covariance, found.ess, len(self.particles), found.mode_weight,
                                      True, e.beams, True, found.fit, False)

    def _start_search(self) -> None:
        """(Re)start the second hypothesis: a global localization with no usual fit yet."""
        self._search.initialize_global()
        self._search._usual_fit = None
        self._lost_runs = 0
        self._right_travel = 0.0
        self._search_confirm = (0, 0.0, 0)

    def _scan_moved(self, pose: np.ndarray, bx_all: np.ndarray, by_all: np.ndarray, min_d: float,
                    min_a: float) -> bool:
        """Whether the scan says the robot turned on the spot by the filter's spacing though the
        odometry says it did not: the scan match from ``pose`` (the last estimate moved by the
        odometry since) turns it by at least ``update_min_a`` while moving it less than
        ``update_min_d``. Wheels slip when a robot turns on the spot: on Freiburg 079 the raw
        odometry turned 5° while the corrected poses (which their map places within 1°) turned
        15-25° (refs 4,513-4,528, 811-819), and with filter runs asked for by the odometry alone
        the estimate stayed 10-19° off. Looked at between filter runs, while tracking with the
        refinement fed back to the cloud (the run's motion is the odometry's, with no noise to
        turn the particles: the refinement turns them), the last estimate not lost and not coasting. A displacement is not taken: on
        Freiburg 079 a scan matched 0.4 m away (ref 4,088, where the corrected heading jumps 7.5°
        and back) then ran the filter onto it, 0.63 m off."""
        est = self._estimate
        if not (self.params.refine and self.params.refine_feedback) or self._global or est is None or est.lost or self._held is not None \
                or not bx_all.size or min_a <= 0:
            return False
        x = self._local_match(pose, bx_all, by_all)
        return x is not None and math.hypot(x[0] - pose[0], x[1] - pose[1]) < min_d \
            and abs(wrap_angle_one(float(x[2] - pose[2]))) >= min_a

    def _fit(self, pose, bx_all: np.ndarray, by_all: np.ndarray) -> float:
        """Share of the end points within ``refine_cutoff`` of an obstacle, seen from ``pose``."""
        return float(np.mean(self.field.distances(pose, bx_all, by_all) <= self.params.refine_cutoff))

    def _coast(self, delta, bx_all: np.ndarray, by_all: np.ndarray) -> bool:
        """Whether this scan is left out (the cloud moves by odometry alone): the map explains less
        than ``coast_fit`` times the usual fit of it at the pose the odometry predicts (after a local
        scan match from there, so that odometry drift alone does not count), and the odometry has
        carried the cloud at most ``coast_max_d`` metres and ``coast_max_a`` radians (summed heading
        changes) since the last scan that fitted. The odometry's pose is kept (``_held``) for as
        long as no scan fits, also past the cap; when a scan fits it again after the cap, the cloud
        (which the scans weighed meanwhile) is moved back to it."""
        prm = self.params
        if prm.coast_fit <= 0 or self._global or self._usual_fit is None or self._estimate is None:
            return False
        base, cov = (self._estimate.pose, self._estimate.covariance) if self._held is None else \
            (self._held, self._held_cov)
        prior = apply_odometry(base, delta)
        x = self._local_match(prior, bx_all, by_all)
        at = prior if x is None else x
        fit = self._fit(at, bx_all, by_all)
        if fit >= prm.coast_fit * self._usual_fit:
            if self._held is not None and self._coasted is None:
                self._move_cloud(self._mean()[0], at)
            self._release()
            return False
        self._held = prior
        self._held_cov = prm.coast_motion.covariance(base, cov, delta)
        if self._dr_best is not None:
            self._dr_best = apply_odometry(self._dr_best, delta)
        if self._coasted is None:
            return False  # coasted as far as allowed: the scans weigh the cloud again (see _choose)
        rot1, trans, rot2 = delta
        d = self._coasted[0] + float(trans)
        a = self._coasted[1] + abs(wrap_angle_one(float(rot1 + rot2)))
        self._coasted = (d, a) if d <= prm.coast_max_d and a <= prm.coast_max_a else None
        return self._coasted is not None

    def _release(self) -> None:
        """Drop the held pose: the cloud carries the estimate again."""
        self._held = self._held_cov = self._dr_best = None
        self._coasted = (0.0, 0.0)
        self._confirm = self._dr_confirm = 0
        self._evidence = 0.0

    def _choose(self, pose: np.ndarray, coast: bool, bx, by, mr: float, bx_all: np.ndarray,
                by_all: np.ndarray) -> np.ndarray:
        """The estimate while the odometry's pose is held: that pose while coasting. Past the cap two
        hypotheses are weighed, the cloud's estimate ``pose`` and dead reckoning, the held pose with
        its covariance ``Σ`` (:meth:`_dead_reckoning` gives its best pose ``d``); each scores a pose
        by the scan's log-likelihood (the filter's beam model) plus the prior ``−½ mᵀ Σ⁻¹ m``
        (``m`` the pose's offset from the held one). Where ``pose`` and ``d`` agree (within half
        ``refine_cutoff`` and 0.1 rad) the scans cannot tell them apart and ``pose`` is taken once it
        has not been lost (fit at least ``lost_fit`` of the usual) on ``coast_confirm`` filter runs
        in a row. Where they differ, a sequential (generalized) likelihood ratio decides: the scans'
        log-likelihood differences summed over the filter runs since the cap on which they
        differ, plus the two priors, must reach ``coast_evidence`` for ``pose`` or
        ``−coast_evidence`` for ``d`` (the cloud is then moved to it), each having fitted on
        ``coast_confirm`` runs in a row. Until then the
        estimate is the held pose. A cloud the scans of a place the map shows wrongly dragged a
        metre off, but as far from the odometry as its drift allows, is no longer confirmed by the
        first scans that fit it: the place it fits must also beat the held pose's neighbourhood."""
        if coast or not bx_all.size:
            return self._held
        prm = self.params
        need = prm.lost_fit * self._usual_fit
        fits = self._fit(pose, bx_all, by_all) >= need
        self._confirm = self._confirm + 1 if fits else 0
        d, d_fit, d_score, info = self._dead_reckoning(bx, by, mr, bx_all, by_all)
        c_score = self._score(pose, bx, by, mr)
        c_prior = self._prior_at(pose, info)
        if math.hypot(d[0] - pose[0], d[1] - pose[1]) <= 0.5 * prm.refine_cutoff and \
                abs(wrap_angle_one(float(d[2] - pose[2]))) <= 0.1:
            if self._confirm < prm.coast_confirm:
                return self._held
            self._release()
            return pose
        self._evidence += c_score - d_score
        ratio = self._evidence + c_prior - self._prior_at(d, info)
        if ratio >= prm.coast_evidence and self._confirm >= prm.coast_confirm:
            self._release()
            return pose
        self._dr_confirm = self._dr_confirm + 1 if d_fit >= need else 0
        if ratio <= -prm.coast_evidence and self._dr_confirm >= prm.coast_confirm:
            self._move_cloud(self._mean()[0], d)
            self._release()
            return d
        return self._held

    def _prior_at(self, x: np.ndarray, info: np.ndarray) -> float:
        """Log of the dead-reckoning prior at ``x`` (up to a constant): ``−½ mᵀ Σ⁻¹ m``."""
        m = np.array([x[0] - self._held[0], x[1] - self._held[1], wrap_angle_one(float(x[2] - self._held[2]))])
        return -0.5 * float(m @ info @ m)

    def _score(self, x: np.ndarray, bx, by, mr: float) -> float:
        """The scan's log-likelihood at ``x`` under the filter's beam model."""
        return float(self.field.score(np.asarray(x, dtype=np.float64)[None], bx, by, mr, self.params.sigma_hit)[0])

    def _dead_reckoning(self, bx, by, mr: float, bx_all: np.ndarray, by_all: np.ndarray):
        """The dead-reckoning hypothesis's best pose: local scan matches from the held pose and
        from the points 1 and 2 standard deviations from it along each axis of its covariance,
        the one with the highest score (log-likelihood plus the log prior). Returns the pose, its
        fit, its score (log-likelihood only) and the prior's information matrix ``Σ⁻¹``. These
        matches are not finished (``refine_finish``): they only pick the place that the ratio
        weighs against the cloud's; finished, the coast through Freiburg 079's refs 1,141-1,277
        (5 cm map) ended 1.03-1.05 m off on 5 of 8 seeds, as before the ratio."""
        cov = self._held_cov + np.diag([1e-6, 1e-6, 1e-8])
        info = np.linalg.inv(cov)
        vals, vecs = np.linalg.eigh(cov)
        steps = (vecs * np.sqrt(np.maximum(vals, 0.0))).T
        starts = [self._held] + [self._held + k * s for s in steps for k in (-2.0, -1.0, 1.0, 2.0)]
        if self._dr_best is not None:
            starts.append(self._dr_best)
        best, best_total, best_score = self._held, -math.inf, -math.inf
        for x0 in starts:
            x0 = np.array([x0[0], x0[1], wrap_angle_one(float(x0[2]))])
            x = self._local_match(x0, bx_all, by_all, finish=False)
            x = x0 if x is None else x
            score = self._score(x, bx, by, mr)
            total = score + self._prior_at(x, info)
            if total > best_total:
                best, best_total, best_score = x, total, score
        self._dr_best = best
        return best, self._fit(best, bx_all, by_all), best_score, info

    def _move_cloud(self, pose: np.ndarray, x: np.ndarray) -> None:
        """Move the cloud rigidly so that ``pose`` lands on ``x``: rotate about ``pose`` by the
        heading difference, then shift."""
        dt = wrap_angle_one(float(x[2] - pose[2]))
        c, s = math.cos(dt), math.sin(dt)
        rel = self.particles[:, :2] - pose[:2]
        self.particles[:, 0] = x[0] + c * rel[:, 0] - s * rel[:, 1]
        self.particles[:, 1] = x[1] + s * rel[:, 0] + c * rel[:, 1]
        self.particles[:, 2] = wrap_angle(self.particles[:, 2] + dt)

    @property
    def estimate(self) -> PoseEstimate | None:
        """The estimate of the last filter run (None before the first)."""
        return self._estimate

    def _weigh(self, bx, by, mr) -> None:
        prm = self.params
        loglik = self.field.score(self.particles, bx, by, mr, prm.global_sigma_hit if self._global else prm.sigma_hit)
        logprior = np.log(np.maximum(self.weights, 1e-300))
        logw = logprior + loglik
        top = logw.max()
        w = np.exp(logw - top)
        total = w.sum()
        # per-beam geometric mean of the likelihood averaged over the prior weights
        w_avg = math.exp((top + math.log(total)) / bx.size)
        self.weights = w / total
        if prm.min_ess > 0 and 1.0 / np.sum(self.weights ** 2) < prm.min_ess * len(w):
            self.weights = self._temper(logprior, loglik)
        if self.w_slow == 0.0:
            self.w_slow = self.w_fast = w_avg
        else:
            self.w_slow += prm.recovery_alpha_slow * (w_avg - self.w_slow)
            self.w_fast += prm.recovery_alpha_fast * (w_avg - self.w_fast)

    def _temper(self, logprior: np.ndarray, loglik: np.ndarray) -> np.ndarray:
        """Weights ``∝ prior · likelihood^β`` with the largest ``β`` in (0, 1] whose effective
        sample size is at least ``min_ess · N`` (bisection): adaptive tempering, so one scan
        cannot put all the weight on a handful of particles."""
        target = self.params.min_ess * len(loglik)
        lo, hi = 0.0, 1.0
        best = None
        for _ in range(20):
            beta = 0.5 * (lo + hi)
            lw = logprior + beta * loglik
            w = np.exp(lw - lw.max())
            w /= w.sum()
            if 1.0 / np.sum(w * w) >= target:
                lo, best = beta, w
            else:
                hi = beta
        if best is None:
            best = np.exp(logprior - logprior.max())
            best /= best.sum()
        self.stats.tempered += 1
        return best

    def _inject_probability(self) -> float:
        prm = self.params
        if prm.recovery_alpha_slow <= 0 or prm.recovery_alpha_fast <= 0 or self.w_slow <= 0:
            return 0.0
        ratio = self.w_fast / self.w_slow
        return 1.0 - ratio if ratio < prm.recovery_threshold else 0.0

    # ------------------------------------------------------------------ resampling

    def _resample(self) -> None:
        prm = self.params
        if prm.kld and not self._global:
            idx = systematic(self.weights, prm.max_particles, self.rng)
            self.rng.shuffle(idx)
            n = kld_count(self.particles[idx], prm.kld_err, prm.kld_z, prm.min_particles, prm.max_particles)
            idx = idx[:n]
        else:
            idx = systematic(self.weights, self._count, self.rng)
        parts = self.particles[idx]
        p_inject = self._inject_probability()
        if p_inject > 0:
            fresh = self.rng.random(len(parts)) < p_inject
            k = int(fresh.sum())
            if k:
                parts[fresh] = self.field.uniform_free(k, self.rng)
                self.stats.injected += k
            if prm.reset_averages:
                self.w_slow = self.w_fast = 0.0
        if prm.roughening > 0:
            roughen(parts, prm.roughening, self.rng)
        self.particles = np.ascontiguousarray(parts)
        self.weights = np.full(len(parts), 1.0 / len(parts))
        self.stats.resamples += 1

    # ------------------------------------------------------------------ the estimate

    def _mean(self):
        p, w = self.particles, self.weights
        mode_w = 1.0
        sel = None
        if p.shape[0] > 1 and (np.ptp(p[:, 0]) > 2.0 or np.ptp(p[:, 1]) > 2.0):
            # several modes possible: the heaviest 1 m × 1 m × 45° bin seeds the dominant mode
            keys = (np.floor(p[:, 0]).astype(np.int64) * 100_003 + np.floor(p[:, 1]).astype(np.int64)) * 11
            keys += np.floor((p[:, 2] + np.pi) / (np.pi / 4)).astype(np.int64)
            uk, inv = np.unique(keys, return_inverse=True)
            best = int(np.argmax(np.bincount(inv, weights=w)))
            seed = self._weighted(p[inv == best], w[inv == best])[0]
            sel = (np.hypot(p[:, 0] - seed[0], p[:, 1] - seed[1]) < 1.0) & (np.abs(wrap_angle(p[:, 2] - seed[2])) < 0.5)
            mode_w = float(w[sel].sum())
            p, w = p[sel], w[sel]
        mean, cov = self._weighted(p, w)
        return mean, cov, mode_w

    @staticmethod
    def _weighted(p: np.ndarray, w: np.ndarray):
        s = w.sum()
        w = w / s if s > 0 else np.full(len(w), 1.0 / len(w))
        mean = np.empty(3)
        cov = np.empty((3, 3))
        K.weighted_moments(np.ascontiguousarray(p), w, mean, cov)
        return mean, cov

    # ------------------------------------------------------------------ scan-match refinement

    def match(self, pose, bx, by, iterations: int = 10, finish: bool = True):
        """Scan match (:func:`occmap.localize.scan_match.match`) of end points ``(bx, by)``
        (sensor/robot frame) from ``pose`` against the map, finished within ``refine_finish``
        unless ``finish`` is False; returns ``(pose, inliers)`` (``None`` pose when it failed)."""
        return match(self.field, pose, bx, by, self.params.refine_cutoff, iterations,
                     self.params.refine_finish if finish else None)

    def _local_match(self, pose: np.ndarray, bx: np.ndarray, by: np.ndarray, finish: bool = True) -> np.ndarray | None:
        """The scan match from ``pose`` (finished unless ``finish`` is False), or None when it
        failed, used under 30 % of the end points or moved more than 0.5 m or 0.3 rad (then it
        found another place, not a correction)."""
        x, used = self.match(pose, bx, by, finish=finish)
        if x is None or not np.isfinite(x).all() or used < 0.3 * bx.size or \
                math.hypot(x[0] - pose[0], x[1] - pose[1]) > 0.5 or abs(wrap_angle_one(float(x[2] - pose[2]))) > 0.3:
            return None
        return x

    def _refine(self, pose: np.ndarray, bx: np.ndarray, by: np.ndarray) -> np.ndarray:
        x = self._local_match(pose, bx, by)
        if x is None:
            self.stats.refine_rejected += 1
            return pose
        self.stats.refined += 1
        if self.params.refine_feedback:
            self._move_cloud(pose, x)
        return x
