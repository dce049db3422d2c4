"""Multi-object tracking: one CTRV extended Kalman filter per object (:mod:`.ekf`), Mahalanobis
gating, global nearest-neighbour assignment (:mod:`.assignment`) and track management.

A scan's detections (:class:`~.detection.Detections`) update the tracks in four steps:

1. **Predict** every track to the scan's stamp.
2. **Measure against each track**: a box seen from the sensor shows only its near faces, so its
   centre lies nearer to the sensor than the object's. For each track–detection pair the box's
   corners are projected on the track's axes; along an axis where the seen extent is shorter than
   the track's size, the edge nearer to the sensor is kept and the centre put half the size behind
   it; in a view cut at one end, a moving vehicle's centre lies half its size from the bare
   end. That centre is the pair's measurement; a moving vehicle seen without a direction of its
   own (its box measured in the track's axes) is measured at the edge or corner that placed it,
   through the heading (:func:`.ekf.pose_innovation`'s offset).
3. **Gate and assign**: pairs with squared Mahalanobis distance of the centres above ``gate`` are
   not allowed; among the rest the assignment of least total ``d² + ln det S`` that matches the
   most pairs is taken (the cost of a Gaussian likelihood), first for the confirmed tracks, then
   for the others with the detections left.
4. **Manage**: a matched track is updated (its heading too when the box is L-shaped, choosing the
   box axis nearer to the track's heading); its size grows to the largest extent seen (capped). A
   detection left over starts a *tentative* track; once it has moved ``init_distance`` or been seen
   for ``init_span`` seconds its velocity is set from the displacement of its centre between whole
   views, or of a bare end when a vehicle comes out from behind something (see
   :meth:`Tracker._correct`). A tentative track is *confirmed* once it has been detected in
   ``confirm_hits`` of its last ``confirm_window`` scans (a scan in which a confirmed track's box,
   nearer to the sensor, hid its centre counts: see :meth:`Tracker._shadowed`), has moved at least ``min_travel`` from
   where it started (walls and parked cars that leak into the detections do not move), knows its
   speed to ``confirm_speed_sigma`` and moves at ``confirm_speed`` at least. The speed is known
   when the filter's covariance says so, or, for a round object (a person), when its own whole
   views say so (see :meth:`Tracker._measured_speed_known`): the filter's centre noise is set for
   the worst views, so its covariance lags the measurements. A track not detected
   for ``max_coast`` seconds (``tentative_coast`` while tentative) is dropped, as is one whose
   position standard deviation passes ``max_position_sigma``.

Speeds are kept non-negative: a state with ``v < 0`` is turned around (``θ + π``, ``−v``), so the
heading is the direction of travel.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ... import checks
from ...errors import InvalidArgumentError
from ...geometry.so2 import wrap_angle
from . import _kernels as K
from . import ekf
from .assignment import assign
from .detection import Detections, box_corners

__all__ = ["TrackerParams", "Tracker", "Tracks"]

TENTATIVE, CONFIRMED = 0, 1
#: Tracks shorter than this (m) are taken as round objects (people), longer ones as vehicles.
MIN_VEHICLE_LENGTH = 1.0
#: A line of returns at least this long (m) gives a direction.
MIN_FACE_LENGTH = 1.0
#: Durations (s) closer than this are equal: stamps of ROS time (about 1.7·10⁹ s) are float64s
#: 2.4·10⁻⁷ s apart, and a gap of three 0.1 s scans comes out as 0.3 ± 10⁻⁷ s.
STAMP_TOLERANCE = 1e-6


@dataclass(frozen=True)
class TrackerParams:
    """Tracker settings (SI units; see the module's description for their role)."""

    accel: float = 2.0
    person_accel: float = 1.0
    yaw_accel: float = 0.7
    position_sigma: float = 0.15
    heading_sigma: float = math.radians(8.0)
    gate: float = 13.8  # χ² with 2 degrees of freedom at 99.9 %
    confirm_hits: int = 3
    confirm_window: int = 5
    min_travel: float = 0.5
    confirm_speed_sigma: float = 0.4
    centre_sigma_floor: float = 0.05
    walking_speed: float = 0.8
    confirm_speed: float = 0.3
    lost_after: float = 0.3
    max_coast: float = 1.0
    tentative_coast: float = 0.3
    max_position_sigma: float = 3.0
    max_size: tuple = (8.0, 3.0)
    vehicle_size: tuple = (4.4, 1.8)
    min_moving_speed: float = 3.0
    max_speed: float = 20.0
    footprint_margin: float = 0.5
    settled_heading_sigma: float = math.radians(10.0)
    initial_speed_sigma: float = 10.0
    init_span: float = 0.2
    init_distance: float = 1.0
    initial_yaw_rate_sigma: float = 0.5
    yaw_rate_time: float = 1.5
    doppler_sigma: float = 0.2
    doppler_gate: float = 10.8  # χ² with 1 degree of freedom at 99.9 %

    def __post_init__(self):
        for name in ("accel", "person_accel", "yaw_accel", "position_sigma", "heading_sigma", "gate", "lost_after",
                     "max_coast", "tentative_coast", "max_position_sigma", "max_speed",
                     "footprint_margin", "settled_heading_sigma", "confirm_speed_sigma", "centre_sigma_floor",
                     "walking_speed", "confirm_speed", "init_span", "init_distance", "initial_speed_sigma",
                     "initial_yaw_rate_sigma", "doppler_sigma", "doppler_gate"):
            checks.positive(name, getattr(self, name))
        if not (isinstance(self.yaw_rate_time, (int, float)) and self.yaw_rate_time > 0):  # inf: constant turn rate
            raise InvalidArgumentError(f"yaw_rate_time must be a positive number of seconds (or inf), "
                                       f"got {self.yaw_rate_time!r}")
        checks.non_negative("min_travel", self.min_travel, "metres")
        if not 1 <= self.confirm_hits <= self.confirm_window <= 8:
            raise InvalidArgumentError(f"need 1 ≤ confirm_hits ({self.confirm_hits}) ≤ confirm_window "
                                       f"({self.confirm_window}) ≤ 8")


class Tracks(NamedTuple):
    """Tracks at one time, one entry each: ``id``, centre ``x``, ``y`` (m), velocity ``vx``, ``vy``
    (m/s), ``heading`` (rad, direction of travel), ``length``, ``width`` (m), ``confirmed`` (a
    confirmed track detected within ``lost_after`` seconds), ``lost`` (a confirmed track not
    detected for longer: predicted only, until ``max_coast``) and the state covariance
    ``covariance`` ``(N, 5, 5)`` over ``(x, y, heading, speed, yaw_rate)``."""

    id: np.ndarray
    x: np.ndarray
    y: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    heading: np.ndarray
    length: np.ndarray
    width: np.ndarray
    confirmed: np.ndarray
    lost: np.ndarray
    covariance: np.ndarray

    def __len__(self) -> int:
        return int(self.id.shape[0])


def _corners(det: Detections) -> np.ndarray:
    """Corners ``(M, 4, 2)`` of detected boxes."""
    return box_corners(det.x, det.y, det.heading, det.length, det.width)


def _directed(det: Detections) -> np.ndarray:
    """Detections whose box has a direction: L-shaped, or a face at least
    :data:`MIN_FACE_LENGTH` long (its direction is the object's side or its end)."""
    return det.oriented | (det.length >= MIN_FACE_LENGTH)


def _turn_around(states: np.ndarray, covs: np.ndarray) -> None:
    """In place: states with negative speed get ``θ + π`` and ``−v`` (the same motion)."""
    back = states[:, 3] < 0.0
    if back.any():
        states[back, 2] = wrap_angle(states[back, 2] + math.pi)
        states[back, 3] = -states[back, 3]
        flip = np.diag([1.0, 1.0, 1.0, -1.0, 1.0])
        covs[back] = flip @ covs[back] @ flip


def _nearest_axis(box_heading, heading):
    """The direction among ``box_heading + k·π/2`` nearest to ``heading`` (radians)."""
    return box_heading + 0.5 * math.pi * np.round((heading - box_heading) / (0.5 * math.pi))


def _frames(heading, size, centre, sensor, box_heading, directed):
    """Axes ``(..., 2, 2)`` (rows) in which a detection centred at ``centre`` (..., 2) is measured
    for a track of ``heading`` (...) and ``size`` (..., 2), and the size along them. A vehicle
    (length ≥ :data:`MIN_VEHICLE_LENGTH`) is measured along its length and its side: the axes of a
    ``directed`` detection's box (``box_heading``, the one of its axes nearest to the track's
    heading), else the track's own (a track's heading must not place the centre that corrects the
    heading); a smaller object, taken as round, along the line of sight and across it, its size the
    largest seen."""
    along = np.where(directed, _nearest_axis(box_heading, heading), heading)
    c, s = np.cos(along), np.sin(along)
    track = np.stack([np.stack([c, s], -1), np.stack([-s, c], -1)], -2)
    d = centre - sensor
    u = d / np.maximum(np.hypot(d[..., 0], d[..., 1]), 1e-9)[..., None]
    sight = np.stack([u, np.stack([-u[..., 1], u[..., 0]], -1)], -2)
    small = size[..., 0] < MIN_VEHICLE_LENGTH
    axes = np.where(small[..., None, None], sight, track)
    return axes, np.where(small[..., None], size.max(axis=-1, keepdims=True), size)


class _Measured(NamedTuple):
    """What one detected box says of one track (see :meth:`Tracker._measure`), arrays ``(..., k)``:
    the ``centre`` (2) and its ``covariance`` (2, 2) (m, world), the extent ``seen`` (2) and the
    ``side`` (2) along the measuring axes, and the ``lever`` (2): from the centre to the point of
    the box that placed it (an edge, a corner; zero where only bounded), in world axes (m)."""

    centre: np.ndarray
    covariance: np.ndarray
    seen: np.ndarray
    side: np.ndarray
    lever: np.ndarray


class Tracker:
    """Tracks of moving objects, updated scan by scan (see the module's description).

    >>> tracker = Tracker()
    >>> tracker.update(0.1, detect_objects(points), sensor=(x, y))  # doctest: +SKIP
    >>> tracker.tracks().confirmed  # doctest: +SKIP
    """

    def __init__(self, params: TrackerParams | None = None):
        self.params = TrackerParams() if params is None else params
        self.time: float | None = None
        self._next_id = 0
        self.id = np.empty(0, np.int64)
        self.state = np.empty((0, 5))
        self.cov = np.empty((0, 5, 5))
        self.status = np.empty(0, np.int8)
        self.size = np.empty((0, 2))
        self.birth = np.empty((0, 2))
        self.born = np.empty(0)
        self.travel = np.empty(0)
        self.last_hit = np.empty(0)
        self.updates = np.empty(0, np.int64)
        self.hit_bits = np.empty(0, np.uint8)
        # (x, y, stamp) of the centres of whole views (no end cut) in the last confirm_window
        # scans, newest first (NaN: no whole view in that scan), for the confirmation test
        self.centres = np.empty((0, self.params.confirm_window, 3))
        # the view the wait for a velocity started from (see _correct): its ends, which were bare,
        # whether it was whole (no end cut)
        self.birth_ends = np.empty((0, 2, 2))
        self.birth_bare = np.empty((0, 2), bool)
        self.birth_whole = np.empty(0, bool)
        self.stats = {"updates": 0, "detections": 0, "tracks_started": 0, "tracks_confirmed": 0, "tracks_dropped": 0,
                      "doppler_updates": 0}

    def __len__(self) -> int:
        return int(self.id.shape[0])

    # ------------------------------------------------------------------ time

    def _noise(self, size):
        """Process noise ``(accel, yaw_accel)`` per track: people (round tracks) change their
        speed less than vehicles."""
        small = size[:, 0] < MIN_VEHICLE_LENGTH
        p = self.params
        return np.where(small, p.person_accel, p.accel), np.full(len(size), p.yaw_accel)

    def _advance(self, stamp: float) -> None:
        stamp = checks.finite("stamp", stamp)
        if self.time is not None:
            dt = stamp - self.time
            if dt < 0.0:
                raise InvalidArgumentError(f"stamp {stamp!r} goes backwards: the tracker is at {self.time!r} s")
            if dt > 0.0 and len(self):
                p = self.params
                self.state, self.cov = ekf.predict(self.state, self.cov, dt, *self._noise(self.size), p.yaw_rate_time)
        self.time = stamp

    def predicted(self, t, confirmed_only: bool = True, covariances: bool = True):
        """``(ids (T,), states, covariances, sizes (T, 2))`` of the tracks predicted to time ``t``
        (seconds, at or after the last update), without changing them: states ``(T, 5)`` and
        covariances ``(T, 5, 5)`` for one time, ``(K, T, 5)`` and ``(K, T, 5, 5)`` for times
        ``(K,)``. ``confirmed_only``: the confirmed tracks (lost ones included), else all.
        ``covariances`` False: None for them (the states alone cost less)."""
        times = np.asarray(t, dtype=np.float64)
        if not np.isfinite(times).all():
            raise InvalidArgumentError(f"prediction times must be finite, got {t!r}")
        now = self.time if self.time is not None else float(times.min(initial=0.0))
        if (times < now).any():
            raise InvalidArgumentError(f"t = {float(times.min())!r} lies before the tracker's time {now!r}: "
                                       "predictions go forward only")
        keep = self.status == CONFIRMED if confirmed_only else np.ones(len(self), bool)
        s, size = self.state[keep], self.size[keep]
        k, n = times.size, len(s)
        flat_s = np.broadcast_to(s, (k, n, 5)).reshape(-1, 5)
        flat_c = np.broadcast_to(self.cov[keep], (k, n, 5, 5)).reshape(-1, 5, 5) if covariances else None
        dt = np.repeat(times.reshape(-1) - now, n)
        if n and (dt > 0.0).any():  # to the tracker's own time they are as they are
            accel, yaw = self._noise(np.broadcast_to(size, (k, n, 2)).reshape(-1, 2))
            flat_s, flat_c = ekf.predict(flat_s, flat_c, dt, accel, yaw, self.params.yaw_rate_time)
        shape = times.shape + (n,)
        return self.id[keep], flat_s.reshape(shape + (5,)), None if flat_c is None else flat_c.reshape(shape + (5, 5)), size

    def covers(self, points, t: float, margin: float, confirmed_only: bool = False) -> np.ndarray:
        """Whether each world point ``(N, 2)`` lies within a track's footprint (predicted to
        ``t``) grown by ``margin`` metres."""
        return self._owners(points, t, margin, confirmed_only) >= 0

    def _owners(self, points, t: float, margin: float, confirmed_only: bool) -> np.ndarray:
        """Per world point ``(N, 2)``: the index (among the confirmed tracks, or all) of the track
        whose footprint predicted to ``t``, grown by ``margin``, holds it — the nearest centre of
        those that do — or −1."""
        _, s, _, size = self.predicted(t, confirmed_only=confirmed_only, covariances=False)
        p = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
        out = np.empty(len(p), dtype=np.int64)
        half = 0.5 * size + margin
        K.box_owners(p, np.ascontiguousarray(s[:, 0]), np.ascontiguousarray(s[:, 1]), np.ascontiguousarray(s[:, 2]),
                     np.ascontiguousarray(half[:, 0]), np.ascontiguousarray(half[:, 1]), out)
        return out

    def update_radar(self, stamp: float, points, bearings, radial_speeds) -> int:
        """Doppler updates from one radar sweep at ``stamp`` (s, not before the last update):
        detections at world ``points`` (M, 2) whose reflectors move at ``radial_speeds`` (M,)
        (m/s, ego motion removed, positive away from the sensor) along world ``bearings`` (M,)
        (rad). A confirmed track, or a tentative person (a round track) that has its velocity from
        its displacement, takes the detections on its footprint (predicted, grown by
        ``footprint_margin``; a detection on several goes to the nearest centre) as one
        measurement ``h(s) = v·cos(θ − φ)`` at their mean bearing and speed, noise
        ``doppler_sigma² / n``, when its squared innovation is within ``doppler_gate`` (a ghost
        or clutter on the footprint is not): its speed known sooner, the person is confirmed
        sooner. Other tentative tracks are left to the lidar: a Doppler that narrows their speed
        before their motion is known would confirm them with a wrong one (a young vehicle's heading
        may still be the wrong axis of its box; on the simulated street such cars were confirmed up
        to 5 m/s off). Returns the number of tracks updated."""
        p = self.params
        self._advance(stamp)
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        phi = np.asarray(bearings, dtype=np.float64).reshape(-1)
        vr = np.asarray(radial_speeds, dtype=np.float64).reshape(-1)
        if not (pts.shape[0] == phi.size == vr.size):
            raise InvalidArgumentError(f"points {pts.shape}, bearings {phi.shape} and radial_speeds {vr.shape} "
                                       "must describe the same detections")
        if not len(self) or not pts.shape[0]:
            return 0
        owner = self._owners(pts, self.time, p.footprint_margin, confirmed_only=False)
        mine = owner >= 0
        k = owner[mine]
        mine[mine] = (self.status[k] == CONFIRMED) | ((self.updates[k] >= 1) & (self.size[k, 0] < MIN_VEHICLE_LENGTH))
        if not mine.any():
            return 0
        tracks, n = np.unique(owner[mine], return_counts=True)
        index = np.searchsorted(tracks, owner[mine])
        # mean bearing (as a direction) and mean radial speed per track
        cs = np.zeros((len(tracks), 2))
        np.add.at(cs, index, np.stack([np.cos(phi[mine]), np.sin(phi[mine])], -1))
        bearing = np.arctan2(cs[:, 1], cs[:, 0])
        speed = np.bincount(index, weights=vr[mine], minlength=len(tracks)) / n
        y, H = ekf.radial_velocity_innovation(self.state[tracks], bearing, speed)
        R = (p.doppler_sigma ** 2 / n)[:, None, None]
        S = ekf.innovation_covariance(self.cov[tracks], H, R)[:, 0, 0]
        ok = y[:, 0] ** 2 <= p.doppler_gate * S
        if ok.any():
            t = tracks[ok]
            self.state[t], self.cov[t] = ekf.update(self.state[t], self.cov[t], y[ok], H[ok], R[ok])
            _turn_around(self.state, self.cov)
        self.stats["doppler_updates"] += int(ok.sum())
        return int(ok.sum())

    # ------------------------------------------------------------------ measurement

    def _measure(self, corners: np.ndarray, axes: np.ndarray, size: np.ndarray, sensor: np.ndarray, occluded=False,
                 track=None, bare_end=None):
        """What a detected box says of an object of size ``size`` (``(..., 2)`` along ``axes``
        ``(..., 2, 2)``), from its corners ``(..., 4, 2)`` seen from ``sensor``: a :class:`_Measured`.

        Along an axis where the sensor lies beyond the extent seen, the near edge is the object's
        (``side`` +1: the object lies toward +axis from its lower edge, −1 from its upper edge)
        and the centre half the size behind it. Elsewhere — the sensor within the extent
        (``side`` 0), or the axis of an ``occluded`` box (``(...)``) more across the line of sight
        (where the occluder may cut it) — the box only bounds the centre: it lies where an object of that size
        still covers all that is seen. Given the ``track``'s centre (..., 2) the measurement is the
        point of that interval nearest to it (none of a bias a part seen for many scans would
        build up); without it the interval's middle, uncertain by its length (uniform). An
        occluded box's ``bare_end`` (..., 2; NaN: none) is the object's own edge along that axis:
        the centre lies half the size from it toward the cut end. :meth:`update` gives it for
        tracks moving at ``min_moving_speed`` or faster (slower ones may be walls that pose errors
        shift: on the raw Intel run they confirmed more tracks). On the simulated street a car
        driving away 25 – 30 m off, the northern part of its rear seen past a nearer object, drifted
        1.2 m sideways in 1.5 s while only bounded there."""
        shape = np.broadcast_shapes(corners.shape[:-2], axes.shape[:-2], size.shape[:-1], np.shape(occluded),
                                    () if track is None else track.shape[:-1],
                                    () if bare_end is None else bare_end.shape[:-1])
        n = math.prod(shape)

        def flat(a, tail=(), dtype=np.float64):
            return np.ascontiguousarray(np.broadcast_to(a, shape + tail).reshape((n,) + tail), dtype=dtype)

        none = np.empty((0, 2))
        centre, seen, side, lever = (np.empty((n, 2)) for _ in range(4))
        covariance = np.empty((n, 2, 2))
        K.measure_boxes(flat(corners, (4, 2)), flat(axes, (2, 2)), flat(size, (2,)), float(sensor[0]), float(sensor[1]),
                        flat(occluded, dtype=np.bool_),
                        none if track is None else flat(track, (2,)), none if bare_end is None else flat(bare_end, (2,)),
                        self.params.position_sigma ** 2, centre, covariance, seen, side, lever)
        return _Measured(centre.reshape(shape + (2,)), covariance.reshape(shape + (2, 2)), seen.reshape(shape + (2,)),
                         side.reshape(shape + (2,)), lever.reshape(shape + (2,)))

    def update(self, stamp: float, detections: Detections, sensor) -> None:
        """Bring the tracks to ``stamp`` (s, not before the last) with one scan's detections seen
        from ``sensor`` (x, y) in the world frame."""
        p = self.params
        sensor = np.asarray(sensor, dtype=np.float64).reshape(-1)[:2]
        self._advance(stamp)
        self.stats["updates"] += 1
        self.stats["detections"] += len(detections)
        n, m = len(self), len(detections)
        self.hit_bits = (self.hit_bits << 1).astype(np.uint8)
        self.centres = np.roll(self.centres, 1, axis=1)
        self.centres[:, 0] = np.nan
        rows = cols = np.empty(0, np.int64)
        if n and m:
            centres = np.stack([detections.x, detections.y], -1)
            directed = _directed(detections)
            fast = self.state[:, 3] >= p.min_moving_speed  # a vehicle's bare end: see _measure
            axes, size = _frames(self.state[:, None, 2], self.size[:, None], centres[None], sensor,
                                 detections.heading[None], directed[None])
            bare = np.where(fast[:, None, None], detections.bare_end[None], np.nan)
            measured = self._measure(_corners(detections)[None], axes, size, sensor, detections.occluded[None],
                                     self.state[:, None, :2], bare)
            z, R = measured.centre, measured.covariance
            # a track seen once has no velocity yet: it may have gone anywhere within max_speed
            reach = np.where(self.updates == 0, (p.max_speed * (self.time - self.last_hit) / 3.0) ** 2, 0.0)
            cost = K.gate_costs(np.ascontiguousarray(self.state[:, :2]), self.cov, reach, z, R, p.gate, np.empty((n, m)))
            rows, cols = self._assign(cost)
            if len(rows):
                self._resize(*self._correct(rows, cols, z[rows, cols], R[rows, cols], measured.lever[rows, cols],
                                            detections), detections, sensor)
        self._shadowed(np.setdiff1d(np.arange(n), rows), sensor)
        self._manage(rows)
        spawn = np.setdiff1d(np.arange(m), cols)
        if len(spawn) and len(self):
            # a part of an object that a nearer one splits off from the rest starts no track
            spawn = spawn[~self.covers(np.stack([detections.x[spawn], detections.y[spawn]], -1), self.time,
                                       p.footprint_margin)]
        if len(spawn):
            self._spawn(detections, spawn)
        _turn_around(self.state, self.cov)

    def _shadowed(self, missed, sensor) -> None:
        """Tracks ``missed`` by this scan (indices) whose centre lies behind a confirmed track's
        box (predicted to this scan; its corners span the centre's bearing, within a half-turn of
        it, and its centre is nearer), seen from ``sensor`` (x, y), count the scan as a hit: a car
        hidden by another passing nearer is no evidence that it is not there. On the simulated
        street a car waited, its speed known, for new hits after three scans behind a nearer car.
        Tentative tracks hide nothing: wall fragments hiding each other confirmed more tracks
        (the raw Intel run at 0.05 m: 63 instead of 61)."""
        if not len(missed) or len(self) < 2:
            return
        d = self.state[missed, None, :2] - sensor  # (k, 1, 2) to each missed centre
        r = np.hypot(d[..., 0], d[..., 1])
        corners = box_corners(self.state[:, 0], self.state[:, 1], self.state[:, 2], self.size[:, 0],
                              self.size[:, 1]) - sensor  # (n, 4, 2)
        # bearings of each box's corners relative to the direction of each missed centre
        rel = np.arctan2(d[..., None, 1] * corners[None, ..., 0] - d[..., None, 0] * corners[None, ..., 1],
                         d[..., None, 0] * corners[None, ..., 0] + d[..., None, 1] * corners[None, ..., 1])
        spans = (rel.min(axis=-1) < 0.0) & (rel.max(axis=-1) > 0.0) & (np.abs(rel).max(axis=-1) < 0.5 * math.pi)
        nearer = np.hypot(self.state[None, :, 0] - sensor[0], self.state[None, :, 1] - sensor[1]) < r
        behind = spans & nearer & (self.status == CONFIRMED)[None, :]
        behind[np.arange(len(missed)), missed] = False
        hidden = missed[behind.any(axis=1)]
        self.hit_bits[hidden] |= 1

    def _assign(self, cost: np.ndarray):
        """Confirmed tracks choose first; the others share the detections left."""
        first = np.flatnonzero(self.status == CONFIRMED)
        r1, c1 = assign(cost[first])
        r1 = first[r1]
        rest = np.flatnonzero(self.status != CONFIRMED)
        free = np.setdiff1d(np.arange(cost.shape[1]), c1)
        r2, c2 = assign(cost[np.ix_(rest, free)])
        rows = np.concatenate([r1, rest[r2]])
        cols = np.concatenate([c1, free[c2]])
        return rows, cols

    def _correct(self, rows, cols, centres, R_centre, levers, det: Detections):
        """Update matched tracks; returns ``(rows, cols)`` of those that have a velocity now.

        A track without a velocity yet (seen once, or only since its last restart) waits for
        ``init_span`` seconds or ``init_distance`` metres of motion from the view it started from
        and takes its velocity from that displacement: of the box's centre between whole views
        (not cut: a cut box's centre moves with the occluder, not with the object); when a view is
        cut, of an end bare in both views (a point of the object, whatever hides the other) if it
        moved at ``min_moving_speed`` or faster — a vehicle coming out from behind something; a
        slower one may be a wall that pose errors shift. Any other view restarts the wait there."""
        p = self.params
        young = self.updates[rows] == 0
        here = np.stack([det.x[cols], det.y[cols]], -1)
        whole = ~det.occluded[cols] & self.birth_whole[rows]
        kept = det.bare[cols] & self.birth_bare[rows]  # ends bare in both views
        end = np.argmax(kept, axis=1)
        d = np.where(whole[:, None], here - self.birth[rows], det.ends[cols, end] - self.birth_ends[rows, end])
        elapsed = self.time - self.born[rows]
        dist = np.hypot(d[:, 0], d[:, 1])
        fast = dist >= p.min_moving_speed * np.maximum(elapsed, 1e-9)
        restart = young & ~(whole | (kept.any(axis=1) & fast))
        # no velocity from views of one stamp (a log's stamps held where they went backwards)
        ready = young & ~restart & (elapsed > STAMP_TOLERANCE) & ((elapsed >= p.init_span) | (dist >= p.init_distance))
        waiting = young & ~ready
        if waiting.any():
            r, c = rows[waiting], cols[waiting]
            self.state[r, :2] = here[waiting]
            self.state[r, 2] = det.heading[c]
            self.state[r, 3:] = 0.0
            self.size[r] = np.minimum(np.stack([det.length[c], det.width[c]], -1), p.max_size)
        if restart.any():
            r, c = rows[restart], cols[restart]
            self.birth[r] = here[restart]
            self.born[r] = self.time
            self.birth_ends[r] = det.ends[c]
            self.birth_bare[r] = det.bare[c]
            self.birth_whole[r] = ~det.occluded[c]
        if ready.any():
            r, c = rows[ready], cols[ready]
            dt, dd = elapsed[ready], dist[ready]
            heading = np.arctan2(d[ready, 1], d[ready, 0])
            # an L-shaped box knows the heading better than two noisy centres: its axis nearest
            aligned = _nearest_axis(det.heading[c], heading)
            self.state[r, 2] = np.where(det.oriented[c], wrap_angle(aligned), heading)
            self.state[r, :2] = here[ready]
            self.state[r, 3] = dd / dt
            self.state[r, 4] = 0.0
            var_p = p.position_sigma ** 2
            cov = np.zeros((len(r), 5, 5))
            cov[:, 0, 0] = cov[:, 1, 1] = var_p
            cov[:, 2, 2] = np.where(det.oriented[c], p.heading_sigma ** 2,
                                    np.minimum(2.0 * var_p / np.maximum(dd, 1e-9) ** 2, (math.pi / 2) ** 2))
            cov[:, 3, 3] = 2.0 * var_p / dt ** 2 + (p.accel * dt) ** 2
            cov[:, 4, 4] = p.initial_yaw_rate_sigma ** 2
            self.cov[r] = cov
        rest = ~young
        if rest.any():
            r, c = rows[rest], cols[rest]
            # a vehicle seen without a direction of its own is measured in the track's axes: at the point of
            # its box that placed the centre (an edge, a corner), so that the track's heading does not place
            # the centre that corrects it (a directed box places it in its own axes; a round object's
            # lever follows the line of sight, not its heading)
            vehicle = self.size[r, 0] >= MIN_VEHICLE_LENGTH
            fast = self.state[r, 3] >= p.min_moving_speed
            lever = np.where((vehicle & fast & ~_directed(det)[c])[:, None], levers[rest], 0.0)
            z = np.concatenate([centres[rest] + lever, np.zeros((len(r), 1))], 1)
            c_th, s_th = np.cos(self.state[r, 2]), np.sin(self.state[r, 2])
            offset = np.stack([c_th * lever[:, 0] + s_th * lever[:, 1], -s_th * lever[:, 0] + c_th * lever[:, 1]], -1)
            oriented = _directed(det)[c] & (self.updates[r] >= 2) & vehicle
            z[:, 2] = _nearest_axis(det.heading[c], self.state[r, 2])
            for with_heading in (False, True):
                k = oriented == with_heading
                if not k.any():
                    continue
                y, H = ekf.pose_innovation(self.state[r[k]], z[k], with_heading, offset[k])
                R = np.zeros((int(k.sum()), 3, 3))
                R[:, :2, :2] = R_centre[rest][k]
                R[:, 2, 2] = p.heading_sigma ** 2
                R = R if with_heading else R[:, :2, :2]
                self.state[r[k]], self.cov[r[k]] = ekf.update(self.state[r[k]], self.cov[r[k]], y, H, R)
        self.updates[rows[~waiting]] += 1
        self.last_hit[rows] = self.time
        self.hit_bits[rows] |= 1
        whole_view = ~det.occluded[cols]
        self.centres[rows[whole_view], 0] = np.stack([det.x[cols[whole_view]], det.y[cols[whole_view]],
                                                      np.full(int(whole_view.sum()), self.time)], -1)
        d = self.state[rows, :2] - self.birth[rows]
        self.travel[rows] = np.maximum(self.travel[rows], np.hypot(d[:, 0], d[:, 1]))
        return rows[~waiting], cols[~waiting]

    def _resize(self, rows, cols, det: Detections, sensor) -> None:
        """After an update: sizes grow to the largest extent seen along the measuring axes of the
        updated heading (capped; a round object stays round; an object moving at
        ``min_moving_speed`` or faster — a vehicle, however little of it shows — is measured in its
        own axes and taken as at least ``vehicle_size`` until seen whole), and the face seen stays where it is:
        along an axis measured from one edge the centre moves away from it by half the growth.
        A track at its second detection has just got its heading: its size is what is seen now
        along it, its centre measured anew (a vehicle's from its bare end when the view is cut at
        the other: measured as a whole view, the cut end nearer to the sensor along that axis
        would be taken for the vehicle's; on the simulated street a car turning in beside parked
        cars, seen from behind, started 2.4 m ahead of itself, lost its speed and was dropped)."""
        p = self.params
        centres = np.stack([det.x[cols], det.y[cols]], -1)
        first = self.updates[rows] == 1
        size = np.where(first[:, None], 0.0, self.size[rows])
        car = self.state[rows, 3] >= p.min_moving_speed  # measured in its own axes, at least a car's size
        size[car] = np.maximum(size[car], p.vehicle_size)
        axes, size = _frames(self.state[rows, 2], size, centres, sensor, det.heading[cols], _directed(det)[cols])
        corners = _corners(det)[cols]
        _, _, seen, side, _ = self._measure(corners, axes, size, sensor)
        small = size[:, 0] < MIN_VEHICLE_LENGTH
        # sizes grow only from whole views (a box an occluder cuts may hold the occluder's returns),
        # a vehicle's only in settled axes (a box measured in a wrong heading looks wider)
        settled = ~det.occluded[cols] & (small | (det.oriented[cols]
                                                  & (self.cov[rows, 2, 2] <= p.settled_heading_sigma ** 2)))
        grown = np.where((settled | first)[:, None], np.maximum(size, seen), size)
        grown[small] = grown[small].max(axis=1, keepdims=True)
        grown[car] = np.where(settled[car, None], np.maximum(grown[car], p.vehicle_size), p.vehicle_size)
        grown = np.minimum(grown, p.max_size)
        self.state[rows, :2] += np.einsum("ka,kaj->kj", side * 0.5 * (grown - size), axes)
        if first.any():
            bare = np.where((first & car)[:, None], det.bare_end[cols], np.nan)[first]
            self.state[rows[first], :2] = self._measure(corners[first], axes[first], grown[first], sensor,
                                                        np.isfinite(bare[:, 0]), bare_end=bare).centre
        self.size[rows] = grown

    def _measured_speed_known(self) -> np.ndarray:
        """Per track: whether a round object's (a person's) own measurements say its velocity is
        known to ``confirm_speed_sigma``. A straight line is fitted to the centres of its whole
        views (no end cut) in each of the last ``confirm_window`` scans; it says so when

        - the fitted velocity's standard error, from the fit's own residuals (m per axis, floored
          at ``centre_sigma_floor``), is within ``confirm_speed_sigma``;
        - the fitted velocity differs from the filter's by no more than that;
        - the motion is significant at the gate's confidence by both estimates (``|v|² ≥ gate ·
          se²`` for the fitted and the filter's speed), and both are at least ``walking_speed``
          (slow walking; on the raw Intel run a wall fragment that pose errors shift drifted at
          0.5 m/s, steadily enough for that test);
        - the filter's speed sigma, scaled by ``centre_sigma_floor / position_sigma`` (what it
          would be had it been fed these views at their own noise), is within it too.

        Measured on the simulated street, whole views' centres are off by 0.055 m (rms per axis,
        cars and people alike), cut views' by up to 0.36 m across: the filter's ``position_sigma``
        (0.15 m) is set for the worst, so its speed sigma reaches ``confirm_speed_sigma`` only
        after 5 – 7 updates however clean the views. Vehicles keep the filter's test: their
        early speed errors (1 – 3 m/s rms in their first 5 updates, a box seen end-on or cut) are
        larger than their covariance says, and the wait hides them."""
        p = self.params
        ok = np.isfinite(self.centres[..., 0])
        n = ok.sum(axis=1)
        xy, t = self.centres[..., :2], np.where(ok, self.centres[..., 2], 0.0)
        tm = t.sum(axis=1) / np.maximum(n, 1)
        dev = np.where(ok, t - tm[:, None], 0.0)
        stt = (dev ** 2).sum(axis=1)
        z = np.where(ok[..., None], xy, 0.0)
        zm = z.sum(axis=1) / np.maximum(n, 1)[:, None]
        dz = np.where(ok[..., None], z - zm[:, None], 0.0)
        fitted = np.einsum("nk,nkj->nj", dev, dz) / np.maximum(stt, 1e-12)[:, None]
        resid = dz - dev[..., None] * fitted[:, None]
        dof = np.maximum(2 * (n - 2), 1)
        var = np.maximum((resid ** 2).sum(axis=(1, 2)) / dof, p.centre_sigma_floor ** 2)
        se = np.sqrt(var / np.maximum(stt, 1e-12))
        mine = self.state[:, 3:4] * np.stack([np.cos(self.state[:, 2]), np.sin(self.state[:, 2])], -1)
        agree = np.hypot(*(mine - fitted).T) <= p.confirm_speed_sigma
        slower = np.minimum((fitted ** 2).sum(axis=1), self.state[:, 3] ** 2)
        moving = (slower >= p.gate * se ** 2) & (slower >= p.walking_speed ** 2)
        person = self.size[:, 0] < MIN_VEHICLE_LENGTH
        # the filter, fed these views at their own noise, would know the speed that much better
        filtered = np.sqrt(self.cov[:, 3, 3]) * p.centre_sigma_floor / p.position_sigma <= p.confirm_speed_sigma
        return person & (n >= p.confirm_window) & (se <= p.confirm_speed_sigma) & agree & moving & filtered

    def _manage(self, matched) -> None:
        p = self.params
        window = (1 << p.confirm_window) - 1
        hits = np.unpackbits((self.hit_bits & window)[:, None], axis=1).sum(axis=1)
        known = (self.cov[:, 3, 3] <= p.confirm_speed_sigma ** 2) | self._measured_speed_known()
        promote = ((self.status == TENTATIVE) & (hits >= p.confirm_hits) & (self.travel >= p.min_travel)
                   & (self.updates >= 2) & known & (self.state[:, 3] >= p.confirm_speed))
        self.status[promote] = CONFIRMED
        self.stats["tracks_confirmed"] += int(promote.sum())
        idle = self.time - self.last_hit
        limit = np.where(self.status == CONFIRMED, p.max_coast, p.tentative_coast)
        lost = (idle > limit + STAMP_TOLERANCE) | (np.sqrt(self.cov[:, 0, 0] + self.cov[:, 1, 1]) > p.max_position_sigma)
        if lost.any():
            self.stats["tracks_dropped"] += int(lost.sum())
            self._keep(~lost)

    def _keep(self, keep) -> None:
        for name in ("id", "state", "cov", "status", "size", "birth", "born", "travel", "last_hit", "updates",
                     "hit_bits", "centres", "birth_ends", "birth_bare", "birth_whole"):
            setattr(self, name, getattr(self, name)[keep])

    def _spawn(self, det: Detections, which) -> None:
        p = self.params
        k = len(which)
        state = np.zeros((k, 5))
        state[:, 0], state[:, 1], state[:, 2] = det.x[which], det.y[which], det.heading[which]
        cov = np.zeros((k, 5, 5))
        cov[:, 0, 0] = cov[:, 1, 1] = p.position_sigma ** 2
        cov[:, 2, 2] = (math.pi / 2.0) ** 2
        cov[:, 3, 3] = p.initial_speed_sigma ** 2
        cov[:, 4, 4] = p.initial_yaw_rate_sigma ** 2
        self.id = np.concatenate([self.id, np.arange(self._next_id, self._next_id + k)])
        self._next_id += k
        self.state = np.concatenate([self.state, state])
        self.cov = np.concatenate([self.cov, cov])
        self.status = np.concatenate([self.status, np.full(k, TENTATIVE, np.int8)])
        self.size = np.concatenate([self.size, np.minimum(np.stack([det.length[which], det.width[which]], -1),
                                                          p.max_size)])
        self.birth = np.concatenate([self.birth, state[:, :2]])
        self.born = np.concatenate([self.born, np.full(k, self.time)])
        self.travel = np.concatenate([self.travel, np.zeros(k)])
        self.last_hit = np.concatenate([self.last_hit, np.full(k, self.time)])
        self.updates = np.concatenate([self.updates, np.zeros(k, np.int64)])
        self.hit_bits = np.concatenate([self.hit_bits, np.ones(k, np.uint8)])
        centres = np.full((k, p.confirm_window, 3), np.nan)
        whole_view = ~det.occluded[which]
        centres[whole_view, 0] = np.stack([det.x[which], det.y[which], np.full(k, self.time)], -1)[whole_view]
        self.centres = np.concatenate([self.centres, centres])
        self.birth_ends = np.concatenate([self.birth_ends, det.ends[which]])
        self.birth_bare = np.concatenate([self.birth_bare, det.bare[which]])
        self.birth_whole = np.concatenate([self.birth_whole, ~det.occluded[which]])
        self.stats["tracks_started"] += k

    # ------------------------------------------------------------------ read-out

    def tracks(self) -> Tracks:
        """The tracks alive at the last update (tentative ones included; see ``confirmed``)."""
        s = self.state
        lost = self.time - self.last_hit > self.params.lost_after + STAMP_TOLERANCE
        return Tracks(self.id.copy(), s[:, 0].copy(), s[:, 1].copy(), s[:, 3] * np.cos(s[:, 2]),
                      s[:, 3] * np.sin(s[:, 2]), s[:, 2].copy(), self.size[:, 0].copy(), self.size[:, 1].copy(),
                      (self.status == CONFIRMED) & ~lost, (self.status == CONFIRMED) & lost, self.cov.copy())
