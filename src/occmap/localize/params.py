"""The parameters of Monte Carlo localization, in one validated object.

Names follow ROS AMCL (nav2's ``amcl`` node and ROS 1's) where a parameter means the same thing:
``z_hit``, ``z_rand``, ``sigma_hit``, ``laser_likelihood_max_dist``, ``max_beams``,
``laser_min_range``, ``min_particles``, ``max_particles``, ``kld_err``, ``kld_z``,
``update_min_d``, ``update_min_a``, ``recovery_alpha_slow``, ``recovery_alpha_fast``; the map
thresholds are map_server's. The rest are occmap's additions, described in
:mod:`occmap.localize.mcl`. Units: metres, radians; probabilities and shares in [0, 1].
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

from .. import checks
from ..errors import InvalidArgumentError
from ..geometry.motion import OdometryMotionModel

__all__ = ["LocalizationParams"]


@dataclass(frozen=True, kw_only=True)
class LocalizationParams:
    """Settings of a :class:`~occmap.localize.MonteCarloLocalizer`, checked when made.

    Fields are keyword-only. Numbers follow :mod:`occmap.checks` (``np.float32`` and NumPy integers accepted; bools, NaN and
    inf rejected); a bad value raises :class:`~occmap.errors.InvalidArgumentError` naming the field.
    :meth:`replace` gives a copy with some fields changed (and checked).

    Attributes
    ----------
    n_particles : int, default 2000
        Particles while tracking (and at each resampling unless ``kld``).
    min_particles, max_particles : int, default 500, 5000
        The range of the KLD particle count.
    kld : bool, default False
        Adapt the particle count at each resampling (Fox's KLD-sampling) within
        ``[min_particles, max_particles]``, with ``kld_err`` (default 0.01) and ``kld_z`` (0.99).
    motion : OdometryMotionModel, default AMCL's (0.2, 0.2, 0.2, 0.2)
        Odometry noise; four floats ``(alpha1 .. alpha4)`` are made into one.
    update_min_d, update_min_a : float, default 0.0, 0.0
        Odometry translation (m) / rotation (rad) since the last filter run that triggers the next
        (0 and 0: every scan). With ``refine`` and ``refine_feedback`` a scan whose match from the
        estimate turns it by ``update_min_a`` on the spot triggers one too (wheels slip in a turn on
        the spot: the odometry misses it).
    sensor_offset : (float, float, float), default (0, 0, 0)
        Pose ``(x, y, theta)`` of the sensor in the robot frame.
    laser_min_range : float, default 0.0
        Readings (m) at or below it are invalid.
    max_beams : int, default 60
        Beams per measurement update, evenly spread over a scan's valid readings.
    z_hit, z_rand : float, default 0.95, 0.05
        Likelihood-field mixture: weight of the Gaussian hit term and of the uniform random term;
        not both zero.
    z_rand_span : {"field", "range"}, default "field"
        What the random term is spread over: the distance field's range (``z_rand /
        laser_likelihood_max_dist`` per metre: the share of beams that end away from every mapped
        obstacle, whatever the sensor) or, as AMCL, the sensor's range (``z_rand / max_range``: with
        an 80 m laser the term all but vanishes, and one unmapped object or smeared wall outweighs
        the rest of the scan).
    sigma_hit : float, default 0.2
        Standard deviation (m) of the hit term while tracking.
    laser_likelihood_max_dist : float, default 2.0
        Distance (m) at which the distance field is clamped.
    model : {"product", "amcl"}, default "product"
        How beams combine: the product of ``pz`` (to the power ``beam_exponent``), or AMCL's
        ``1 + Σ pz³``.
    beam_exponent : float, default 1.0
        Exponent on the product model's likelihood (< 1 tempers over-confident beams).
    occupied_thresh, free_thresh : float, default 0.65, 0.196
        Occupancy probabilities above which a cell is an obstacle, below which it is free
        (map_server's); ``0 ≤ free_thresh ≤ occupied_thresh ≤ 1``.
    resample_ess : float, default 0.5
        Resample when the effective sample size falls below this share of the particles.
    min_ess : float, default 0.1
        Adaptive tempering keeps at least this share of effective particles per scan (0: off).
    roughening : float, default 0.0
        Gordon's roughening constant ``K`` (0: off).
    recovery_alpha_slow, recovery_alpha_fast : float, default 0.0, 0.0
        Rates of the long- and short-term likelihood averages that drive random-particle
        injection; 0 and 0 turn injection off.
    recovery_threshold : float, default 0.5
        Inject random particles only while ``w_fast / w_slow`` is below this.
    reset_averages : bool, default False
        Reset ``w_slow`` and ``w_fast`` after each injection, as AMCL's code does.
    refine, refine_feedback : bool, default False, False
        Refine the estimate by a scan match against the distance field; also shift the particles
        by its correction.
    refine_cutoff : float, default 0.3
        End points farther (m) than this from any obstacle are left out of the scan match, and
        count as unexplained in an estimate's ``fit``.
    refine_finish : float, default 0.15
        Once a scan match of the filter (refinement, coasting) has converged with
        ``refine_cutoff``, it is finished on the end points within this distance (m) of an obstacle
        (:func:`~occmap.localize.scan_match.match`); at least ``refine_cutoff``: no finishing pass.
        The dead-reckoning hypothesis's local matches (past ``coast_max_d``) are not finished.
    lost_fit : float, default 0.85
        An estimate whose ``fit`` (share of the scan's beams the map explains there) is below this
        share of its usual value is reported ``lost``.
    coast_fit : float, default 0.0
        Leave a scan out (the cloud moves by odometry alone; no weighting, resampling or refinement)
        when the map explains less than this share of its usual ``fit`` of it at the pose the
        odometry predicts, after a local scan match from there (0: off).
    coast_max_d, coast_max_a : float, default 3.0, 2π
        The most odometry travel (m) and heading change (rad, summed) the filter coasts through
        since the last scan that fitted; beyond either, scans weigh the cloud again, while the
        estimate stays the odometry's until ``coast_confirm`` runs confirm the cloud's.
    coast_confirm : int, default 5
        Past the coasting cap, consecutive filter runs whose scan fits the cloud's estimate (at
        least ``lost_fit`` of the usual fit) before that estimate replaces the odometry's.
    coast_motion : OdometryMotionModel, default (0.05, 0.05, 0.05, 0.05)
        Odometry noise of the held (dead-reckoning) pose: its covariance grows by the extended Kalman
        filter's prediction (:meth:`OdometryMotionModel.covariance`) from the cloud's covariance when
        the hold began. Measured: over 10 m of travel the raw odometry's error against the corrected
        poses has a median normalized squared error (3 degrees of freedom: 3 when consistent) of 7.0 on
        Intel and 0.49 on Freiburg 079 with 0.05 (0.01: 35 and 2.5); the filter's own ``motion`` (AMCL's
        0.2) is a particle-diffusion setting, 1-2 m after 10 m on Freiburg 079, where the odometry drifted 0.5 m
        (there 0.2 makes the filter diverge, 0.02 no longer reaches the place that fits; 0.1 is as 0.05).
    coast_evidence : float, default 4.6
        Past the coasting cap, the log-likelihood ratio (nats, ``log 99``) by which the scans must
        favour the cloud's estimate over the best pose of the held pose's neighbourhood (or that pose
        over the cloud's), with the dead-reckoning prior, before one is taken (:mod:`occmap.localize.mcl`).
    relocalize_after : int, default 0
        Consecutive filter runs with a ``lost`` estimate after which a global localization starts
        as a second hypothesis beside the tracking filter, and replaces it once confirmed (0: off).
    relocalize_confirm_d : float, default 5.0
        Odometry travel (m) over which that hypothesis must fit the scans at least as well as the
        tracking filter's estimate (which stays lost, or which the scan's log-likelihood puts
        ``coast_evidence`` below it), with a compact cloud, on every filter run before it replaces
        the cloud (:mod:`occmap.localize.mcl`).
    global_particles : int, default 20000
        Particles a global localization spreads over the free space.
    global_sigma_hit : float, default 1.0
        ``sigma_hit`` (m) until a global localization converges.
    global_update_min_d, global_update_min_a : float, default 0.2, π/6
        ``update_min_d`` / ``update_min_a`` until a global localization converges.
    converged_weight : float, default 0.98
        A global localization has converged once its dominant mode holds this share of the weight.
    """

    # particles
    n_particles: int = 2000
    min_particles: int = 500
    max_particles: int = 5000
    # KLD-sampling
    kld: bool = False
    kld_err: float = 0.01
    kld_z: float = 0.99
    # motion, and when the filter runs
    motion: OdometryMotionModel = field(default_factory=OdometryMotionModel)
    update_min_d: float = 0.0
    update_min_a: float = 0.0
    # the sensor
    sensor_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    laser_min_range: float = 0.0
    max_beams: int = 60
    # the likelihood field
    z_hit: float = 0.95
    z_rand: float = 0.05
    z_rand_span: str = "field"
    sigma_hit: float = 0.2
    laser_likelihood_max_dist: float = 2.0
    # how beams combine
    model: str = "product"
    beam_exponent: float = 1.0
    # the map (map_server's thresholds)
    occupied_thresh: float = 0.65
    free_thresh: float = 0.196
    # resampling
    resample_ess: float = 0.5
    min_ess: float = 0.1
    roughening: float = 0.0
    # recovery by random particles
    recovery_alpha_slow: float = 0.0
    recovery_alpha_fast: float = 0.0
    recovery_threshold: float = 0.5
    reset_averages: bool = False
    # scan-match refinement
    refine: bool = False
    refine_feedback: bool = False
    refine_cutoff: float = 0.3
    refine_finish: float = 0.15
    lost_fit: float = 0.85
    # coasting through what the map does not explain
    coast_fit: float = 0.0
    coast_max_d: float = 3.0
    coast_max_a: float = 2 * math.pi
    coast_confirm: int = 5
    coast_motion: OdometryMotionModel = field(default_factory=lambda: OdometryMotionModel(0.05, 0.05, 0.05, 0.05))
    coast_evidence: float = 4.6
    # finding the robot again
    relocalize_after: int = 0
    relocalize_confirm_d: float = 5.0
    # global localization
    global_particles: int = 20_000
    global_sigma_hit: float = 1.0
    global_update_min_d: float = 0.2
    global_update_min_a: float = math.pi / 6
    converged_weight: float = 0.98

    def __post_init__(self):
        def put(name, value):
            object.__setattr__(self, name, value)

        for name in ("n_particles", "max_beams", "global_particles", "coast_confirm"):
            put(name, checks.count(name, getattr(self, name)))
        for name in ("motion", "coast_motion"):
            if not isinstance(getattr(self, name), OdometryMotionModel):
                put(name, OdometryMotionModel(*getattr(self, name)))
        for name in ("z_hit", "z_rand", "laser_min_range", "recovery_alpha_slow", "recovery_alpha_fast",
                     "update_min_d", "update_min_a", "roughening", "global_update_min_d", "global_update_min_a",
                     "coast_max_d", "coast_max_a", "relocalize_confirm_d", "coast_evidence"):
            put(name, checks.non_negative(name, getattr(self, name)))
        if self.z_hit + self.z_rand <= 0:
            raise InvalidArgumentError("z_hit + z_rand must be positive")
        for name in ("sigma_hit", "laser_likelihood_max_dist", "beam_exponent", "kld_err", "kld_z",
                     "refine_cutoff", "refine_finish", "global_sigma_hit"):
            put(name, checks.positive(name, getattr(self, name)))
        if self.z_rand_span not in ("field", "range"):
            raise InvalidArgumentError(f"z_rand_span must be 'field' or 'range', got {self.z_rand_span!r}")
        if self.model not in ("product", "amcl"):
            raise InvalidArgumentError(f"model must be 'product' or 'amcl', got {self.model!r}")
        free_t = checks.fraction("free_thresh", self.free_thresh)
        occ_t = checks.fraction("occupied_thresh", self.occupied_thresh)
        if not free_t <= occ_t:
            raise InvalidArgumentError(f"need 0 <= free_thresh <= occupied_thresh <= 1, got {free_t!r}, {occ_t!r}")
        put("free_thresh", free_t)
        put("occupied_thresh", occ_t)
        for name in ("resample_ess", "min_ess", "recovery_threshold", "lost_fit", "coast_fit"):
            put(name, checks.fraction(name, getattr(self, name)))
        put("converged_weight", checks.fraction("converged_weight", self.converged_weight, zero=False))
        lo = checks.count("min_particles", self.min_particles)
        hi = checks.count("max_particles", self.max_particles)
        if lo > hi:
            raise InvalidArgumentError(f"need 1 <= min_particles <= max_particles, got {lo!r}, {hi!r}")
        put("min_particles", lo)
        put("max_particles", hi)
        put("relocalize_after", checks.count("relocalize_after", self.relocalize_after, minimum=0))
        for name in ("kld", "refine", "refine_feedback", "reset_averages"):
            put(name, bool(getattr(self, name)))
        off = tuple(self.sensor_offset)
        if len(off) != 3:
            raise InvalidArgumentError(f"sensor_offset must be three finite numbers (x, y, theta), got {off!r}")
        put("sensor_offset", tuple(checks.finite(f"sensor_offset[{k}]", v) for k, v in enumerate(off)))

    def replace(self, **changes) -> LocalizationParams:
        """A copy with ``changes`` (field names) applied, checked like a new one."""
        return dataclasses.replace(self, **changes)
