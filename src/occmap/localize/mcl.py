"""Monte Carlo localization (particle filter) of a planar range sensor in a known occupancy grid.

The filter is ROS AMCL's (Thrun, Burgard & Fox, *Probabilistic Robotics*, ch. 4, 5, 6 and 8):

* **motion** — the odometry model of :mod:`occmap.geometry.motion` (rot1–trans–rot2 with the four
  ``alpha`` noise terms), applied to every particle with its own noise draw. As in AMCL the filter
  runs only once the odometry has moved ``update_min_d`` metres or turned ``update_min_a``
  radians since its last run; between runs the estimate follows the odometry.
* **measurement** — the likelihood field: the distance ``d`` from a beam's end point to the
  nearest occupied cell, precomputed once for the whole map with the exact Euclidean distance
  transform (:mod:`occmap.raster.edt`) and clamped at ``max_dist``; each beam scores
  ``pz = z_hit · exp(−d² / 2σ²) + z_rand / max_range``. Unknown cells are handled as AMCL does:
  only occupied cells (occupancy above ``occupied_thresh``) are obstacles, an end point in an
  unknown cell scores by its distance to the nearest obstacle like any other, and an end point
  off the map scores as if ``max_dist`` away. Readings that are not finite, below ``range_min``
  or at/beyond the scan's ``max_range`` (no return) carry no information and are skipped. At most
  ``max_beams`` of the remaining beams are used, evenly spread over the scan. Beams combine as
  a product (``model="product"``: the sum of log ``pz``, scaled by ``beam_exponent`` to temper the
  over-confidence that comes from treating neighbouring beams as independent) or by AMCL's ad-hoc
  ``1 + Σ pz³`` (``model="amcl"``).
* **resampling** — low-variance (systematic) resampling when the effective sample size
  ``1 / Σ w²`` falls below ``resample_ess · N``; optional KLD-adaptive particle count (Fox 2003,
  AMCL's ``kld_err``/``kld_z`` and its 0.5 m × 0.5 m × 10° bins); random particles drawn
  uniformly over free space are injected with probability ``max(0, 1 − w_fast / w_slow)``
  (AMCL's ``recovery_alpha_slow``/``recovery_alpha_fast``), which is how a kidnapped robot is
  found again. Unlike AMCL the averages are not reset after an injection (the book's version:
  injection continues for as long as the short-term likelihood stays below the long-term one),
  injection starts only once ``w_fast / w_slow`` falls below ``recovery_threshold`` (on the
  Intel log, stretches where the scans fit the map poorly drop the ratio below 1 while tracking
  is fine, and a few random particles then win), and the averaged likelihood is the per-beam
  geometric mean, so it does not depend on how many beams a scan had. Injection is off by
  default, as in AMCL (``alpha_slow = alpha_fast = 0``).
* **tempering** — with ``min_ess`` a scan that would leave fewer effective particles than that
  share of N is applied with its likelihood raised to a power below 1 (adaptive tempering).
* **estimate** — the weighted mean of the dominant mode of the cloud (circular mean for the
  heading), its covariance and the effective sample size. A multi-modal cloud (global
  localization before it converges) reports its heaviest mode and the share of weight in it.
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
* ``refine``: a local scan match of the estimate — Gauss–Newton on the bilinearly interpolated
  distance field, all valid beams, end points farther than ``refine_cutoff`` from any obstacle
  ignored — which places the pose between the particles and below the grid's resolution; with
  ``refine_feedback`` the whole cloud is shifted by the correction.

Poses are ``(x, y, theta)`` of the *sensor* in the map frame unless ``sensor_offset`` (the
sensor's pose in the robot frame) is given; then particles and estimates are robot poses.
"""

from __future__ import annotations

import math
import os
import warnings
from dataclasses import dataclass, field

import numpy as np
from numba import get_num_threads

from ..raster.edt import distance_transform
from ..errors import InvalidArgumentError, NonFiniteError, ShapeError
from ..geometry.motion import OdometryMotionModel, apply_odometry, odometry_delta
from ..geometry.so2 import wrap_angle
from ..grid2d import OccupancyGrid2D
from . import _kernels as K

__all__ = ["LocalizationWarning", "MonteCarloLocalizer", "PoseEstimate"]


class LocalizationWarning(UserWarning):
    """Something in the input the filter could not use as given (an odometry jump, a scan with no
    valid reading); the message says what and how it was handled."""


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
    """

    pose: np.ndarray
    covariance: np.ndarray
    ess: float
    n_particles: int
    mode_weight: float = 1.0
    updated: bool = False
    beams: int = 0
    converged: bool = True


@dataclass
class _Stats:
    updates: int = 0
    resamples: int = 0
    injected: int = 0
    odometry_jumps: int = 0
    empty_scans: int = 0
    refined: int = 0
    refine_rejected: int = 0
    tempered: int = 0
    converged_after: int | None = None  # filter runs of a global localization until it converged
    extra: dict = field(default_factory=dict)


def _wrap(a: float) -> float:
    """A scalar angle wrapped to (−π, π] (the scalar twin of :func:`wrap_angle`)."""
    a = math.fmod(a, 2.0 * math.pi)
    if a > math.pi:
        a -= 2.0 * math.pi
    elif a <= -math.pi:
        a += 2.0 * math.pi
    return a


def _positive(name, value, allow_zero=False):
    v = float(value)
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        raise InvalidArgumentError(f"{name} must be a {'non-negative' if allow_zero else 'positive'} finite number, got {value!r}")
    return v


class MonteCarloLocalizer:
    """A particle filter that localizes a range sensor in a fixed occupancy grid (ROS AMCL).

    Parameters
    ----------
    grid : OccupancyGrid2D or str or os.PathLike
        The map; a path is read as a map_server YAML (:meth:`OccupancyGrid2D.load`).
    n_particles : int
        Particles for tracking (and for global localization unless ``kld``).
    motion : OdometryMotionModel or sequence of four floats, optional
        Odometry noise ``(alpha1..alpha4)``; default AMCL's 0.2 each.
    z_hit, z_rand, sigma_hit, max_dist : float
        Likelihood field mixture: weight of the Gaussian hit term, of the uniform random term
        (``z_rand / max_range`` per metre), the hit term's standard deviation (m) and the distance
        (m) at which the distance field is clamped (AMCL's ``laser_likelihood_max_dist``).
    max_beams : int
        Beams per measurement update, evenly spread over the scan's valid readings.
    model : {"product", "amcl"}
        How beams combine: product of ``pz`` (to the power ``beam_exponent``) or AMCL's
        ``1 + Σ pz³``.
    beam_exponent : float
        Exponent on the product model's likelihood (``1`` independent beams; less tempers it).
    occupied_thresh, free_thresh : float
        Occupancy probabilities above which a cell is an obstacle, below which it is free
        (map_server's 0.65 and 0.196). Free cells are where global initialization and injected
        particles go.
    range_min : float
        Readings at or below it are invalid.
    resample_ess : float
        Resample when the effective sample size falls below this fraction of N.
    kld : bool
        Adapt the particle count at each resampling (Fox's KLD-sampling) between
        ``min_particles`` and ``max_particles`` with ``kld_err`` and ``kld_z``.
    alpha_slow, alpha_fast : float
        Rates of the long- and short-term likelihood averages that drive random-particle
        injection; ``0, 0`` turns injection off.
    update_min_d, update_min_a : float
        Odometry translation (m) / rotation (rad) since the last filter run that triggers the
        next one (AMCL's ``update_min_d`` / ``update_min_a``); ``0`` runs on every scan.
    roughening : float
        Gordon's roughening constant ``K`` (0: off).
    refine : bool
        Refine the estimate by a local scan match against the distance field.
    refine_feedback : bool
        Also shift the particles by the scan match's correction.
    refine_cutoff : float
        End points farther than this (m) from any obstacle are left out of the scan match.
    max_odom_jump : (float, float)
        Odometry motion between two consecutive calls above this translation (m) or rotation
        (rad) is treated as a jump: a :class:`LocalizationWarning`, the motion is not applied,
        the particles are spread by Gaussians of half these sizes instead.
    sensor_offset : (x, y, theta)
        Pose of the sensor in the robot frame (default: the filter tracks the sensor itself).
    min_ess : float
        Adaptive tempering: when a scan would leave fewer than ``min_ess · N`` effective
        particles, its likelihood is raised to the largest power ``β ≤ 1`` that keeps that many
        (0: off, the textbook filter). Keeps several hypotheses alive through global localization
        and recovery instead of betting everything on the best particle of one scan.
    recovery_threshold : float
        Random particles are injected only while ``w_fast / w_slow`` is below this (AMCL: 1);
        the moments a real log fits its map poorly must not scatter a tracking filter.
    reset_averages : bool
        Reset ``w_slow`` and ``w_fast`` after each injection, as AMCL's code does.
    global_particles : int
        Particles :meth:`initialize_global` spreads over the free space; their count stays until
        the cloud converges.
    global_sigma_hit : float
        The hit term's standard deviation (m) until a global localization converges.
    global_update_min_d, global_update_min_a : float
        ``update_min_d`` / ``update_min_a`` until a global localization converges.
    converged_weight : float
        A global localization has converged once its dominant mode holds this share of the weight.
    seed : int or numpy.random.Generator, optional
        Source of randomness (reproducible runs).
    """

    #: particles × beams from which the measurement model runs on all threads
    parallel_min = 500_000

    def __init__(self, grid, n_particles: int = 2000, *, motion=None, z_hit: float = 0.95, z_rand: float = 0.05,
                 sigma_hit: float = 0.2, max_dist: float = 2.0, max_beams: int = 60, model: str = "product",
                 beam_exponent: float = 1.0, occupied_thresh: float = 0.65, free_thresh: float = 0.196,
                 range_min: float = 0.0, resample_ess: float = 0.5, kld: bool = False, kld_err: float = 0.01,
                 kld_z: float = 0.99, min_particles: int = 500, max_particles: int = 5000,
                 alpha_slow: float = 0.0, alpha_fast: float = 0.0, update_min_d: float = 0.0,
                 update_min_a: float = 0.0, roughening: float = 0.0, refine: bool = False,
                 refine_feedback: bool = False, refine_cutoff: float = 0.3, max_odom_jump=(1.0, 1.0),
                 sensor_offset=(0.0, 0.0, 0.0), min_ess: float = 0.1, recovery_threshold: float = 0.5, reset_averages: bool = False,
                 global_particles: int = 20_000, global_sigma_hit: float = 1.0, global_update_min_d: float = 0.2,
                 global_update_min_a: float = math.pi / 6, converged_weight: float = 0.98, seed=None):
        if isinstance(grid, (str, os.PathLike)):
            grid = OccupancyGrid2D.load(grid)
        if not isinstance(grid, OccupancyGrid2D):
            raise InvalidArgumentError(f"grid must be an OccupancyGrid2D or a map_server YAML path, got {type(grid).__name__}")
        self.n_particles = int(n_particles)
        if self.n_particles < 1:
            raise InvalidArgumentError(f"n_particles must be at least 1, got {n_particles!r}")
        if motion is None:
            motion = OdometryMotionModel()
        elif not isinstance(motion, OdometryMotionModel):
            motion = OdometryMotionModel(*motion)
        self.motion = motion
        self.z_hit = _positive("z_hit", z_hit, allow_zero=True)
        self.z_rand = _positive("z_rand", z_rand, allow_zero=True)
        if self.z_hit + self.z_rand <= 0:
            raise InvalidArgumentError("z_hit + z_rand must be positive")
        self.sigma_hit = _positive("sigma_hit", sigma_hit)
        self.max_dist = _positive("max_dist", max_dist)
        self.max_beams = int(max_beams)
        if self.max_beams < 1:
            raise InvalidArgumentError(f"max_beams must be at least 1, got {max_beams!r}")
        if model not in ("product", "amcl"):
            raise InvalidArgumentError(f"model must be 'product' or 'amcl', got {model!r}")
        self.model = model
        self.beam_exponent = _positive("beam_exponent", beam_exponent)
        if not 0.0 <= free_thresh <= occupied_thresh <= 1.0:
            raise InvalidArgumentError(f"need 0 <= free_thresh <= occupied_thresh <= 1, got {free_thresh!r}, {occupied_thresh!r}")
        self.range_min = _positive("range_min", range_min, allow_zero=True)
        self.resample_ess = float(resample_ess)
        if not 0.0 <= self.resample_ess <= 1.0:
            raise InvalidArgumentError(f"resample_ess must lie in [0, 1], got {resample_ess!r}")
        self.kld = bool(kld)
        self.kld_err = _positive("kld_err", kld_err)
        self.kld_z = _positive("kld_z", kld_z)
        self.min_particles = int(min_particles)
        self.max_particles = int(max_particles)
        if not 1 <= self.min_particles <= self.max_particles:
            raise InvalidArgumentError(f"need 1 <= min_particles <= max_particles, got {min_particles!r}, {max_particles!r}")
        self.alpha_slow = _positive("alpha_slow", alpha_slow, allow_zero=True)
        self.alpha_fast = _positive("alpha_fast", alpha_fast, allow_zero=True)
        self.update_min_d = _positive("update_min_d", update_min_d, allow_zero=True)
        self.update_min_a = _positive("update_min_a", update_min_a, allow_zero=True)
        self.roughening = _positive("roughening", roughening, allow_zero=True)
        self.refine = bool(refine)
        self.reset_averages = bool(reset_averages)
        self.min_ess = float(min_ess)
        if not 0.0 <= self.min_ess <= 1.0:
            raise InvalidArgumentError(f"min_ess must lie in [0, 1], got {min_ess!r}")
        self.recovery_threshold = float(recovery_threshold)
        if not 0.0 <= self.recovery_threshold <= 1.0:
            raise InvalidArgumentError(f"recovery_threshold must lie in [0, 1], got {recovery_threshold!r}")
        self.refine_feedback = bool(refine_feedback)
        self.refine_cutoff = _positive("refine_cutoff", refine_cutoff)
        self.global_particles = int(global_particles)
        if self.global_particles < 1:
            raise InvalidArgumentError(f"global_particles must be at least 1, got {global_particles!r}")
        self.global_sigma_hit = _positive("global_sigma_hit", global_sigma_hit)
        self.global_update_min_d = _positive("global_update_min_d", global_update_min_d, allow_zero=True)
        self.global_update_min_a = _positive("global_update_min_a", global_update_min_a, allow_zero=True)
        self.converged_weight = float(converged_weight)
        if not 0.0 < self.converged_weight <= 1.0:
            raise InvalidArgumentError(f"converged_weight must lie in (0, 1], got {converged_weight!r}")
        jd, ja = max_odom_jump
        self.max_odom_jump = (_positive("max_odom_jump[0]", jd), _positive("max_odom_jump[1]", ja))
        off = np.asarray(sensor_offset, dtype=np.float64)
        if off.shape != (3,) or not np.isfinite(off).all():
            raise InvalidArgumentError(f"sensor_offset must be three finite numbers (x, y, theta), got {sensor_offset!r}")
        self.sensor_offset = off
        self.rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)

        self._prepare_map(grid, float(occupied_thresh), float(free_thresh))
        self.particles = np.zeros((0, 3))
        self.weights = np.zeros(0)
        self.w_slow = 0.0
        self.w_fast = 0.0
        self.stats = _Stats()
        self._filter_odom = None  # odometry pose at the last filter run
        self._last_odom = None  # odometry pose at the last call
        self._estimate: PoseEstimate | None = None
        self._force = True
        self._global = False  # a global localization that has not converged yet
        self._count = self.n_particles  # particles drawn at each resampling (without KLD)

    # ------------------------------------------------------------------ the map

    def _prepare_map(self, grid: OccupancyGrid2D, occ_t: float, free_t: float) -> None:
        H, W = grid.shape
        if H == 0 or W == 0 or grid.origin is None:
            raise InvalidArgumentError("the map is empty (no cells): build or load a map before localizing in it")
        occ = grid.occupancy()
        known = occ >= 0
        occupied = known & (occ > 100.0 * occ_t)
        free = known & (occ < 100.0 * free_t)
        if not occupied.any():
            raise InvalidArgumentError("the map has no occupied cell: there is nothing to localize against")
        if not free.any():
            raise InvalidArgumentError("the map has no free cell: there is nowhere to place particles")
        # crop to the obstacles' bounding box grown by max_dist (+1 cell): every end point outside
        # it is at least max_dist from any obstacle and scores like one off the map
        self.grid = grid
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
        self._free_cells = np.flatnonzero(free.ravel())
        dist = distance_transform(occupied, self.resolution)
        np.minimum(dist, self.max_dist, out=dist)
        #: distance (m) from each cell's centre to the nearest obstacle, clamped at ``max_dist``
        self.distance = dist
        self._tables: dict[tuple[float, float], tuple[np.ndarray, float]] = {}

    def _table(self, max_range: float, sigma: float) -> tuple[np.ndarray, float]:
        """Per-cell beam score for scans of this max range with a hit term of this standard
        deviation, and the score off the map."""
        hit = self._tables.get((max_range, sigma))
        if hit is not None:
            return hit
        if len(self._tables) > 8:
            self._tables.clear()
        rand = self.z_rand / max_range
        d = np.concatenate([self.distance.ravel(), [self.max_dist]])
        pz = self.z_hit * np.exp(-(d * d) / (2.0 * sigma ** 2)) + rand
        if self.model == "product":
            score = self.beam_exponent * np.log(np.maximum(pz, 1e-300))
        else:
            score = pz ** 3
        table = score[:-1].reshape(self.distance.shape).astype(np.float32)
        out = (table, float(score[-1]))
        self._tables[(max_range, sigma)] = out
        return out

    # ------------------------------------------------------------------ initialization

    def initialize(self, pose, cov=None, n: int | None = None) -> None:
        """Start tracking: ``n`` (default ``n_particles``) particles drawn from a Gaussian around
        ``pose`` ``(x, y, theta)`` with covariance ``cov`` (3×3, or 3 variances; default AMCL's
        0.5² m², 0.5² m², (π/12)² rad²)."""
        p = np.asarray(pose, dtype=np.float64)
        if p.shape != (3,):
            raise ShapeError(f"pose must be (x, y, theta), got shape {p.shape}")
        if not np.isfinite(p).all():
            raise NonFiniteError(f"pose {p.tolist()} is not finite")
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
        n = self.n_particles if n is None else int(n)
        z = self.rng.standard_normal((n, 3))
        parts = p + (z * np.sqrt(np.maximum(vals, 0.0))) @ vecs.T
        parts[:, 2] = wrap_angle(parts[:, 2])
        self._reset(parts, global_phase=False)

    def initialize_global(self, n: int | None = None) -> None:
        """Global localization: ``n`` particles (default ``global_particles``) uniformly over the
        free cells, headings uniform; the filter runs coarse to fine until it converges (see the
        module's notes)."""
        n = self.global_particles if n is None else int(n)
        if n < 1:
            raise InvalidArgumentError(f"n must be at least 1, got {n!r}")
        self._reset(self._uniform_free(n), global_phase=True)

    def _uniform_free(self, n: int) -> np.ndarray:
        cells = self._free_cells[self.rng.integers(0, self._free_cells.size, n)]
        W = self.free.shape[1]
        iy, ix = np.divmod(cells, W)
        out = np.empty((n, 3))
        u = self.rng.random((n, 3))
        out[:, 0] = self.origin[0] + (ix + u[:, 0]) * self.resolution
        out[:, 1] = self.origin[1] + (iy + u[:, 1]) * self.resolution
        out[:, 2] = wrap_angle(-np.pi + 2.0 * np.pi * u[:, 2])
        return out

    def _reset(self, particles: np.ndarray, global_phase: bool) -> None:
        self.particles = np.ascontiguousarray(particles)
        self.weights = np.full(len(particles), 1.0 / len(particles))
        self._global = global_phase
        self._count = len(particles)
        self.w_slow = self.w_fast = 0.0
        self._filter_odom = None
        self._last_odom = None
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
            Readings in metres; non-finite ones, those at or below ``range_min`` and those at or
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
        odom = np.asarray(odometry_pose, dtype=np.float64)
        if odom.shape != (3,):
            raise ShapeError(f"odometry_pose must be (x, y, theta), got shape {odom.shape}")
        if not np.isfinite(odom).all():
            raise NonFiniteError(f"odometry_pose {odom.tolist()} is not finite")
        r = np.asarray(ranges, dtype=np.float64).reshape(-1)
        a = np.asarray(angles, dtype=np.float64).reshape(-1)
        if r.shape != a.shape:
            raise ShapeError(f"ranges {r.shape} and angles {a.shape} must have the same shape")
        mr = float(max_range)
        if not (math.isfinite(mr) and mr > 0):
            raise InvalidArgumentError(f"max_range must be a positive finite number, got {max_range!r}")

        if self._filter_odom is None:
            self._filter_odom = odom.copy()
            self._last_odom = odom.copy()
        else:
            self._check_jump(odom)
        self._last_odom = odom.copy()

        rot1, trans, rot2 = odometry_delta(self._filter_odom, odom, min_trans=self.motion.min_trans)
        min_d, min_a = ((self.global_update_min_d, self.global_update_min_a) if self._global
                        else (self.update_min_d, self.update_min_a))
        moved = float(trans) >= min_d and min_d > 0
        turned = abs(_wrap(float(rot1 + rot2))) >= min_a and min_a > 0
        run = self._force or moved or turned or (min_d == 0 and min_a == 0)
        if not run:
            est = self._estimate
            pose = apply_odometry(est.pose, (rot1, trans, rot2))
            return PoseEstimate(pose, est.covariance, est.ess, len(self.particles), est.mode_weight, False, 0,
                                est.converged)

        # motion
        if float(trans) > 0 or float(rot1) != 0 or float(rot2) != 0:
            self.particles = apply_odometry(self.particles, (rot1, trans, rot2), self.motion.alphas, self.rng)
        self._filter_odom = odom.copy()
        self._force = False

        # measurement
        bx, by, bx_all, by_all = self._beams(r, a, mr)
        ess = 1.0 / float(np.sum(self.weights ** 2))
        if bx.size:
            self._weigh(bx, by, mr)
            ess = 1.0 / float(np.sum(self.weights ** 2))
            if ess < self.resample_ess * len(self.particles) or self._inject_probability() > 0:
                self._resample()
        else:
            self.stats.empty_scans += 1
            warnings.warn("scan has no valid reading: the filter moved by odometry only", LocalizationWarning,
                          stacklevel=2)
        self.stats.updates += 1
        pose, cov, mode_w = self._mean()
        if self._global and mode_w >= self.converged_weight:
            # one mode left: track from here on, and shrink the cloud at the next resampling
            self._global = False
            self._count = self.n_particles
            self.stats.converged_after = self.stats.updates
        if self.refine and not self._global and bx_all.size:
            pose = self._refine(pose, bx_all, by_all)
        self._estimate = PoseEstimate(pose, cov, ess, len(self.particles), mode_w, True, int(bx.size),
                                      not self._global)
        return self._estimate

    @property
    def estimate(self) -> PoseEstimate | None:
        """The estimate of the last filter run (None before the first)."""
        return self._estimate

    def _check_jump(self, odom: np.ndarray) -> None:
        prev = self._last_odom
        step = math.hypot(odom[0] - prev[0], odom[1] - prev[1])
        turn = abs(_wrap(float(odom[2] - prev[2])))
        jd, ja = self.max_odom_jump
        if step <= jd and turn <= ja:
            return
        self.stats.odometry_jumps += 1
        warnings.warn(
            f"odometry jumped {step:.3f} m and {math.degrees(turn):.1f}° between two scans (limits {jd:g} m, "
            f"{math.degrees(ja):.1f}°): the jump is not applied, the particles are spread instead",
            LocalizationWarning, stacklevel=3)
        # apply the motion pending before the jump, then re-anchor the odometry after it
        d = odometry_delta(self._filter_odom, prev, min_trans=self.motion.min_trans)
        self.particles = apply_odometry(self.particles, d, self.motion.alphas, self.rng)
        n = len(self.particles)
        spread = self.rng.standard_normal((n, 3)) * np.array([0.5 * jd, 0.5 * jd, 0.5 * ja])
        self.particles[:, :2] += spread[:, :2]
        self.particles[:, 2] = wrap_angle(self.particles[:, 2] + spread[:, 2])
        self._filter_odom = odom.copy()
        self._force = True

    def _beams(self, r: np.ndarray, a: np.ndarray, mr: float):
        """End points in the particle frame of the subsampled beams and of all valid beams."""
        with np.errstate(invalid="ignore"):
            ok = np.isfinite(r) & np.isfinite(a) & (r > self.range_min) & (r < mr)
        idx = np.flatnonzero(ok)
        ox, oy, ot = self.sensor_offset
        rr, aa = r[idx], a[idx] + ot
        x_all = ox + rr * np.cos(aa)
        y_all = oy + rr * np.sin(aa)
        if idx.size > self.max_beams:
            pick = np.rint(np.linspace(0, idx.size - 1, self.max_beams)).astype(np.int64)
            return (np.ascontiguousarray(x_all[pick]), np.ascontiguousarray(y_all[pick]), x_all, y_all)
        return x_all, y_all, x_all, y_all

    def _score(self, particles: np.ndarray, bx: np.ndarray, by: np.ndarray, mr: float) -> np.ndarray:
        table, outside = self._table(mr, self.global_sigma_hit if self._global else self.sigma_hit)
        out = np.empty(len(particles))
        big = len(particles) * bx.size >= self.parallel_min and get_num_threads() > 1
        fn = K.score_particles_parallel if big else K.score_particles
        fn(particles, bx, by, table, outside, self.origin[0], self.origin[1], 1.0 / self.resolution, out)
        if self.model == "amcl":
            out = np.log1p(out)
        return out

    def _weigh(self, bx, by, mr) -> None:
        loglik = self._score(self.particles, bx, by, mr)
        logprior = np.log(np.maximum(self.weights, 1e-300))
        logw = logprior + loglik
        top = logw.max()
        w = np.exp(logw - top)
        total = w.sum()
        # per-beam geometric mean of the likelihood averaged over the prior weights
        w_avg = math.exp((top + math.log(total)) / bx.size)
        self.weights = w / total
        if self.min_ess > 0 and 1.0 / np.sum(self.weights ** 2) < self.min_ess * len(w):
            self.weights = self._temper(logprior, loglik)
        if self.w_slow == 0.0:
            self.w_slow = self.w_fast = w_avg
        else:
            self.w_slow += self.alpha_slow * (w_avg - self.w_slow)
            self.w_fast += self.alpha_fast * (w_avg - self.w_fast)

    def _temper(self, logprior: np.ndarray, loglik: np.ndarray) -> np.ndarray:
        """Weights ``∝ prior · likelihood^β`` with the largest ``β`` in (0, 1] whose effective
        sample size is at least ``min_ess · N`` (bisection): adaptive tempering, so one scan
        cannot put all the weight on a handful of particles."""
        target = self.min_ess * len(loglik)
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
        if self.alpha_slow <= 0 or self.alpha_fast <= 0 or self.w_slow <= 0:
            return 0.0
        ratio = self.w_fast / self.w_slow
        return 1.0 - ratio if ratio < self.recovery_threshold else 0.0

    # ------------------------------------------------------------------ resampling

    def _resample(self) -> None:
        cum = np.cumsum(self.weights)
        cum /= cum[-1]
        if self.kld and not self._global:
            m = self.max_particles
            idx = np.empty(m, dtype=np.int64)
            K.systematic_indices(cum, float(self.rng.random()), idx)
            self.rng.shuffle(idx)
            n = self._kld_count(self.particles[idx])
            idx = idx[:n]
        else:
            idx = np.empty(self._count, dtype=np.int64)
            K.systematic_indices(cum, float(self.rng.random()), idx)
        parts = self.particles[idx]
        p_inject = self._inject_probability()
        if p_inject > 0:
            fresh = self.rng.random(len(parts)) < p_inject
            k = int(fresh.sum())
            if k:
                parts[fresh] = self._uniform_free(k)
                self.stats.injected += k
            if self.reset_averages:
                self.w_slow = self.w_fast = 0.0
        if self.roughening > 0:
            self._roughen(parts)
        self.particles = np.ascontiguousarray(parts)
        self.weights = np.full(len(parts), 1.0 / len(parts))
        self.stats.resamples += 1

    def _kld_count(self, samples: np.ndarray) -> int:
        """Fox's KLD bound: the smallest prefix of ``samples`` at least as long as the count its
        own occupied bins call for, clipped to ``[min_particles, max_particles]``."""
        keys = np.floor(samples[:, 0] / 0.5).astype(np.int64) * 1_000_003
        keys = (keys + np.floor(samples[:, 1] / 0.5).astype(np.int64)) * 1_000_033
        keys += np.floor(samples[:, 2] / math.radians(10.0)).astype(np.int64)
        _, first = np.unique(keys, return_index=True)
        new = np.zeros(len(samples), dtype=np.int64)
        new[first] = 1
        k = np.cumsum(new)
        km1 = np.maximum(k - 1, 1).astype(np.float64)
        b = 2.0 / (9.0 * km1)
        need = km1 / (2.0 * self.kld_err) * (1.0 - b + np.sqrt(b) * self.kld_z) ** 3
        need = np.where(k <= 1, 1.0, need)
        enough = np.flatnonzero(np.arange(1, len(samples) + 1) >= need)
        n = int(enough[0]) + 1 if enough.size else len(samples)
        return int(min(max(n, self.min_particles), self.max_particles))

    def _roughen(self, parts: np.ndarray) -> None:
        n = len(parts)
        lo, hi = np.percentile(parts[:, :2], [2.0, 98.0], axis=0)
        mean_t = math.atan2(np.sin(parts[:, 2]).mean(), np.cos(parts[:, 2]).mean())
        dt = wrap_angle(parts[:, 2] - mean_t)
        tlo, thi = np.percentile(dt, [2.0, 98.0])
        spread = np.array([hi[0] - lo[0], hi[1] - lo[1], thi - tlo])
        sigma = self.roughening * spread * n ** (-1.0 / 3.0)
        parts += self.rng.standard_normal((n, 3)) * sigma
        parts[:, 2] = wrap_angle(parts[:, 2])

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

    def match(self, pose, bx, by, iterations: int = 10):
        """Gauss–Newton scan match of end points ``(bx, by)`` (sensor/robot frame) from ``pose``
        against the distance field; returns ``(pose, inliers)`` (``None`` pose when it failed)."""
        x = np.array(pose, dtype=np.float64)
        Hm = np.empty((3, 3))
        g = np.empty(3)
        inv = 1.0 / self.resolution
        used = 0
        for _ in range(iterations):
            _, used = K.match_normal_equations(x, bx, by, self.distance, self.max_dist, self.refine_cutoff,
                                               self.origin[0], self.origin[1], inv, Hm, g)
            if used < 10:
                return None, used
            Hm[np.diag_indices(3)] += 1e-6 * used
            try:
                step = np.linalg.solve(Hm, -g)
            except np.linalg.LinAlgError:
                return None, used
            x += step
            x[2] = _wrap(float(x[2]))
            if abs(step[0]) + abs(step[1]) < 1e-5 and abs(step[2]) < 1e-5:
                break
        return x, used

    def _refine(self, pose: np.ndarray, bx: np.ndarray, by: np.ndarray) -> np.ndarray:
        x, used = self.match(pose, bx, by)
        if x is None or not np.isfinite(x).all() or used < 0.3 * bx.size or \
                math.hypot(x[0] - pose[0], x[1] - pose[1]) > 0.5 or abs(_wrap(float(x[2] - pose[2]))) > 0.3:
            self.stats.refine_rejected += 1
            return pose
        self.stats.refined += 1
        if self.refine_feedback:
            # move the cloud rigidly: rotate about the estimate by the heading correction, then shift
            dt = _wrap(float(x[2] - pose[2]))
            c, s = math.cos(dt), math.sin(dt)
            rel = self.particles[:, :2] - pose[:2]
            self.particles[:, 0] = x[0] + c * rel[:, 0] - s * rel[:, 1]
            self.particles[:, 1] = x[1] + s * rel[:, 0] + c * rel[:, 1]
            self.particles[:, 2] = wrap_angle(self.particles[:, 2] + dt)
        return x
