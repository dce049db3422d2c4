"""Inverse sensor models: how much one reading moves a cell's log-odds.

Log-odds ``l = log(p / (1 − p))``; a reading adds ``l_sensor − l_prior`` to every cell it
speaks about (the static-state binary Bayes filter, Thrun et al., *Probabilistic Robotics* §4.2).
Defaults are OctoMap's: hit 0.7, miss 0.4.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .. import checks
from ..errors import InvalidArgumentError, NonFiniteError, ShapeError
from ..geometry.so2 import wrap_angle
from ..logodds import logit, probability


class _HitMiss:
    """What a model's ``prob_hit`` / ``prob_miss`` add to a cell: their log-odds."""

    @property
    def l_hit(self) -> float:
        return logit(self.prob_hit)

    @property
    def l_miss(self) -> float:
        return logit(self.prob_miss)


@dataclass(frozen=True)
class LidarModel(_HitMiss):
    """Beam-end model of a laser: the end cell of a return is hit, the cells before it are free.

    ``prob_hit`` is P(occupied | return ends in the cell), ``prob_miss`` is P(occupied | beam
    passes through the cell); both must lie on their side of 0.5 (names: ``docs/architecture.md``).
    """

    prob_hit: float = 0.7
    prob_miss: float = 0.4

    def __post_init__(self):
        object.__setattr__(self, "prob_hit", checks.probability_on_side("prob_hit", self.prob_hit, True))
        object.__setattr__(self, "prob_miss", checks.probability_on_side("prob_miss", self.prob_miss, False))


@dataclass(frozen=True)
class SonarModel(_HitMiss):
    """Cone model of a sonar transducer (after Moravec & Elfes, "High resolution maps from wide
    angle sonar", ICRA 1985, as taught in Thrun et al. §9.2).

    An echo at range ``r`` says: some obstacle lies on the arc of the cone at ``r`` (cells within
    ``arc`` metres of it, i.e. ``|d − r| ≤ arc/2``, get occupied evidence), and the cone before
    the arc is free. ``φ`` is the angle of a cell centre from the transducer's axis.

    Parameters
    ----------
    beam_width : float
        Full opening angle of the cone in radians, in (0, π). With ``sectors="nearest"`` it may be
        up to ``math.inf`` (no limit beyond the transducer's sector).
    prob_hit, prob_miss : float
        P(occupied) for a cell on the arc / inside the cone before it (names:
        ``docs/architecture.md``).
    arc : float or None
        Thickness of the occupied arc in metres (Thrun's α); ``None``: one cell.
    weighting : ``"quadratic"`` (default) or ``"uniform"``
        ``"quadratic"`` weights both updates by ``w = 1 − (φ / (beam_width/2))²``, so the axis
        speaks loudest and the rim not at all; ``"uniform"`` gives every cell of the cone the full
        ``l_hit`` / ``l_miss``, as in Thrun's Table 9.2.
    sectors : ``"cone"`` (default) or ``"nearest"``
        ``"cone"``: each reading updates every cell of its own cone; overlapping cones of one ring
        each contribute. ``"nearest"``: a cell is updated only by the transducer whose bearing is
        nearest to the cell's direction (Table 9.2's ``k = argmin_j |φ − θ_j,sens|``), and only
        within ``beam_width/2`` of that bearing.
    wrap_angles : bool
        True (default): angles are compared modulo 2π. False compares the raw
        ``atan2(y_i − y, x_i − x) − θ`` with the bearings, unwrapped — what the Udacity exercise
        behind the shared ``sonar/`` data set does. It matters for ``sectors="nearest"``: with the
        heading away from 0, some cells go to a transducer on the wrong side of the robot. Only
        for reproducing that exercise's picture.
    min_range : float
        Readings shorter than this (metres) are dropped and counted as dropped (Table 9.2's Zmin).
    ignore_max_range : bool
        False (default): a reading at or beyond the ``max_range`` given to
        :meth:`~occmap.grid2d.OccupancyGrid2D.insert_sonar` had no echo and clears its cone up
        to ``max_range``. True: readings *beyond* ``max_range`` are not integrated at all (only
        counted under ``max_range``); one exactly at ``max_range`` still clears its cone. That is
        the Udacity exercise's rule (``Z_k > Z_max`` returns ``l0``; ``Z_k = Z_max`` is free space).

    :meth:`udacity_exercise` gives the settings of that exercise.
    """

    beam_width: float = math.radians(15.0)
    prob_hit: float = 0.7
    prob_miss: float = 0.4
    arc: float | None = None
    weighting: str = "quadratic"
    sectors: str = "cone"
    wrap_angles: bool = True
    min_range: float = 0.0
    ignore_max_range: bool = False

    def __post_init__(self):
        if self.sectors not in ("cone", "nearest"):
            raise InvalidArgumentError(f"sectors must be 'cone' or 'nearest', got {self.sectors!r}")
        if self.weighting not in ("quadratic", "uniform"):
            raise InvalidArgumentError(f"weighting must be 'quadratic' or 'uniform', got {self.weighting!r}")
        widest = math.inf if self.sectors == "nearest" else math.pi
        what = "in (0, π) radians (up to inf with sectors='nearest')"
        width = math.inf if self.beam_width == widest == math.inf else checks.positive("beam_width", self.beam_width)
        if not (width < widest or width == widest == math.inf):
            raise InvalidArgumentError(f"beam_width must be {what}, got {self.beam_width!r}")
        object.__setattr__(self, "beam_width", width)
        object.__setattr__(self, "prob_hit", checks.probability_on_side("prob_hit", self.prob_hit, True))
        object.__setattr__(self, "prob_miss", checks.probability_on_side("prob_miss", self.prob_miss, False))
        if self.arc is not None:
            object.__setattr__(self, "arc", checks.positive("arc", self.arc, "metres"))
        object.__setattr__(self, "min_range", checks.non_negative("min_range", self.min_range, "metres"))

    @classmethod
    def udacity_exercise(cls) -> "SonarModel":
        """The inverse sensor model of Udacity's occupancy-grid-mapping exercise (Robotics
        Software Engineer nanodegree), which produced the shared ``sonar/Map_reference.png``:
        log-odds ``l_occ = 0.4``, ``l_free = −0.4`` (prior 0) on every cell alike, α = 0.2 m,
        Z_min = 0.17 m, readings > Z_max not integrated, each cell given to the transducer of
        nearest (unwrapped) bearing. Its β = 20 is compared with angles in radians, so the beam
        width never limits anything: ``beam_width=inf``. Integrate with ``max_range=5.0`` (its
        Z_max) on a grid whose clamping does not bind (the exercise clamps nothing)."""
        return cls(beam_width=math.inf, prob_hit=probability(0.4), prob_miss=probability(-0.4),
                   arc=0.2, weighting="uniform", sectors="nearest", wrap_angles=False, min_range=0.17,
                   ignore_max_range=True)

    def sector_bounds(self, bearings):
        """Per transducer, the angles ``(lo, hi)`` relative to its bearing between which a cell's
        direction must lie for that transducer to update it (``lo ≤ φ < hi``; ±inf: no limit).

        ``sectors="cone"``: no limit. ``sectors="nearest"``: half-way to the neighbouring bearings
        (so each direction belongs to the transducer of nearest bearing), around the circle when
        ``wrap_angles``, else on the open line (the outermost transducers reach out to ±inf). Of
        transducers sharing a bearing the first takes the sector and the others get none; a lone
        bearing takes the whole circle (no limit).
        """
        B = np.asarray(bearings, dtype=np.float64)
        k = B.size
        lo = np.full(k, -np.inf)
        hi = np.full(k, np.inf)
        if self.sectors == "cone" or k == 0:
            return lo, hi
        two_pi = 2.0 * math.pi
        b = wrap_angle(B) if self.wrap_angles else B.copy()
        # order by angle, then by index, and keep the first of each run of equal angles
        order = np.lexsort((np.arange(k), b))
        first = np.ones(k, dtype=bool)
        first[1:] = b[order[1:]] != b[order[:-1]]
        lead = order[first]
        lo[:] = 0.0
        hi[:] = 0.0
        angles = b[lead]
        n = lead.size
        if n == 1:
            lo[lead], hi[lead] = -np.inf, np.inf
            return lo, hi
        for j, i in enumerate(lead):
            if self.wrap_angles:
                prev = angles[j - 1] - (two_pi if j == 0 else 0.0)
                nxt = angles[(j + 1) % n] + (two_pi if j == n - 1 else 0.0)
            else:
                prev = angles[j - 1] if j > 0 else -np.inf
                nxt = angles[j + 1] if j < n - 1 else np.inf
            lo[i] = 0.5 * (prev - angles[j])
            hi[i] = 0.5 * (nxt - angles[j])
        return lo, hi


@dataclass(frozen=True)
class RadarModel(_HitMiss):
    """Inverse model of a detection radar: an automotive radar's list of detections, each a range,
    an azimuth and (optionally) a Doppler radial velocity.

    A detection says an obstacle lies at its point, give or take ``sigma_range`` (1σ, metres)
    along the beam: cells within ``extent`` σ of it get occupied evidence weighted by the
    Gaussian of their offset (across the beam by that of a half cell), and the cells of its ray
    nearer than ``range − extent·σ`` get free evidence. The azimuth error (a degree or so) is
    larger than the cells: a wedge as wide would clear the walls a beam grazes, and the error moves
    the point mostly along the surface it lies on, so it is left to the many detections to
    average out. Missing returns say nothing (a radar misses most of what is there), so
    readings beyond ``max_range`` clear nothing.

    What a radar adds to a lidar's troubles is handled so:

    * **moving reflectors**: with the radial velocity and the sensor's own velocity, a detection
      whose ego-compensated radial speed exceeds ``static_speed`` (m/s) is on a moving object: it
      clears its ray and marks nothing;
    * **multipath ghosts and clutter beyond walls**: a detection whose ray meets a cell already at
      least ``obstacle_probability`` likely occupied, more than ``ghost_margin`` metres before
      its uncertain range, cannot have been seen directly; it updates nothing (counted as
      ``ghosts``). The margin spares walls seen at grazing angles, where a degree of azimuth
      error moves the ray's entry into the wall by metres;
    * **clutter in the open**: false alarms land in random cells; ``prob_hit`` is low enough that
      one detection leaves a cell below the occupied threshold of a saved map (map_server's
      0.65), and the free evidence of later sweeps wins.

    Defaults fit a 77 GHz automotive radar (range σ 0.15 m). ``prob_hit`` / ``prob_miss`` are the
    evidence at the centre of a detection / on its ray (names: ``docs/architecture.md``); the free
    evidence is weak because a ray's azimuth is uncertain by more than a cell. They were chosen on
    :class:`occmap.sim.street.Street` (``benchmarks/bench_radar.py``).
    """

    sigma_range: float = 0.15
    extent: float = 2.0
    prob_hit: float = 0.64
    prob_miss: float = 0.47
    static_speed: float = 0.5
    obstacle_probability: float = 0.8
    ghost_margin: float = 1.0

    def __post_init__(self):
        object.__setattr__(self, "sigma_range", checks.positive("sigma_range", self.sigma_range, "metres"))
        object.__setattr__(self, "extent", checks.positive("extent", self.extent, "standard deviations"))
        object.__setattr__(self, "prob_hit", checks.probability_on_side("prob_hit", self.prob_hit, True))
        object.__setattr__(self, "prob_miss", checks.probability_on_side("prob_miss", self.prob_miss, False))
        object.__setattr__(self, "static_speed", checks.positive("static_speed", self.static_speed, "m/s"))
        object.__setattr__(self, "obstacle_probability",
                           checks.probability_on_side("obstacle_probability", self.obstacle_probability, True))
        object.__setattr__(self, "ghost_margin", checks.non_negative("ghost_margin", self.ghost_margin, "metres"))


class RadarSweeps(NamedTuple):
    """Radar detections checked and sorted for integration (:func:`radar_sweeps`): the kept
    detections' ``sweep`` (pose index), ``range``, ``azimuth``, ``moving`` flag and
    ``radial_speed`` (the reflector's own, ego motion removed; NaN without Doppler), the
    ``poses`` (N, 3), and the counts of the ``dropped`` (unreadable) and ``beyond_max_range`` ones."""

    poses: np.ndarray
    sweep: np.ndarray
    range: np.ndarray
    azimuth: np.ndarray
    moving: np.ndarray
    radial_speed: np.ndarray
    dropped: int
    beyond_max_range: int


def radar_sweeps(poses, ranges, azimuths, max_range: float, model: RadarModel, sweeps=None, radial_velocity=None,
                 ego_velocity=None) -> RadarSweeps:
    """Check a call's radar detections and sort them (:class:`RadarModel`'s rules).

    ``poses`` (3,) or (N, 3) sensor poses (x, y, heading); ``ranges``, ``azimuths`` (M,) metres
    and radians from the heading; ``sweeps`` (M,) the pose index of each detection (needed when
    N > 1). ``radial_velocity`` (M,) m/s, positive moving away, as the sensor measures it (its own
    motion included) and ``ego_velocity`` (2,) or (N, 2), the sensor's world velocity: together they
    flag moving reflectors. Detections with a NaN or infinite value (range, azimuth, radial
    velocity) or a range ≤ 0 are dropped; those at or beyond ``max_range`` are counted and kept
    out. Bad shapes, non-finite poses and sweep indices outside the poses raise."""
    P = np.atleast_2d(np.asarray(poses, dtype=np.float64))
    R = np.asarray(ranges, dtype=np.float64)
    A = np.asarray(azimuths, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3 or R.ndim != 1 or A.shape != R.shape:
        raise ShapeError(f"expected poses (N, 3), ranges (M,), azimuths (M,); got {P.shape}, {R.shape}, {A.shape}")
    if not np.isfinite(P).all():
        raise NonFiniteError("radar poses must be finite")
    if sweeps is None:
        if P.shape[0] != 1:
            raise ShapeError(f"{P.shape[0]} poses need sweeps (M,): the pose index of each detection")
        S = np.zeros(R.shape, dtype=np.int64)
    else:
        S = np.asarray(sweeps)
        if S.shape != R.shape or not np.issubdtype(S.dtype, np.integer):
            raise ShapeError(f"sweeps must be integers of shape {R.shape}, got {S.dtype} {S.shape}")
        bad = np.flatnonzero((S < 0) | (S >= P.shape[0]))
        if bad.size:
            raise InvalidArgumentError(f"sweeps[{bad[0]}] = {S[bad[0]]} is not a pose index (0..{P.shape[0] - 1})")
        S = S.astype(np.int64)
    max_range = checks.positive("max_range", max_range, "metres")
    ok = np.isfinite(R) & np.isfinite(A) & (R > 0.0)
    moving = np.zeros(R.shape, dtype=np.bool_)
    along = np.full(R.shape, np.nan)
    if radial_velocity is not None:
        if ego_velocity is None:
            raise InvalidArgumentError("radial_velocity needs ego_velocity (the sensor's world velocity, m/s)")
        V = np.asarray(radial_velocity, dtype=np.float64)
        E = np.atleast_2d(np.asarray(ego_velocity, dtype=np.float64))
        if V.shape != R.shape or E.shape not in ((1, 2), (P.shape[0], 2)):
            raise ShapeError(f"expected radial_velocity {R.shape} and ego_velocity (2,) or ({P.shape[0]}, 2); "
                             f"got {V.shape}, {E.shape}")
        if not np.isfinite(E).all():
            raise NonFiniteError("ego_velocity must be finite")
        ok &= np.isfinite(V)
        heading = P[S, 2] + np.where(ok, A, 0.0)
        e = E[S if E.shape[0] > 1 else np.zeros_like(S)]
        along = V + e[:, 0] * np.cos(heading) + e[:, 1] * np.sin(heading)  # the reflector's own radial speed
        moving = np.abs(along) > model.static_speed
    beyond = ok & (R >= max_range)
    keep = ok & ~beyond
    return RadarSweeps(P, np.ascontiguousarray(S[keep]), np.ascontiguousarray(R[keep]),
                       np.ascontiguousarray(A[keep]), np.ascontiguousarray(moving[keep]), along[keep],
                       int((~ok).sum()), int(beyond.sum()))
