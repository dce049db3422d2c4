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
   through the heading (:func:`.ekf.pose_innovation`'s offset; :func:`._steps.measure_pairs`).
3. **Gate and assign**: pairs with squared Mahalanobis distance of the centres above ``gate`` are
   not allowed; among the rest the assignment of least total ``d² + ln det S`` that matches the
   most pairs is taken (the cost of a Gaussian likelihood), first for the confirmed tracks, then
   for the others with the detections left.
4. **Manage**: a matched track is updated (its heading too when the box is L-shaped, choosing the
   box axis nearer to the track's heading); its size grows to the largest extent seen (capped). A
   detection left over starts a *tentative* track; once it has moved ``init_distance`` or been seen
   for ``init_span`` seconds its velocity is set from the displacement of its centre between whole
   views, or of a bare end when a vehicle comes out from behind something (see
   :func:`._steps.correct`). A tentative track is *confirmed* once it has been detected in
   ``confirm_hits`` of its last ``confirm_window`` scans (a scan in which a confirmed track's box,
   nearer to the sensor, hid its centre counts: see :func:`._steps.count_hidden`), has moved at least ``min_travel`` from
   where it started (walls and parked cars that leak into the detections do not move), knows its
   speed to ``confirm_speed_sigma`` and moves at ``confirm_speed`` at least. The speed is known
   when the filter's covariance says so, or, for a round object (a person), when its own whole
   views say so (see :func:`._steps._measured_speed_known`): the filter's centre noise is set for
   the worst views, so its covariance lags the measurements. A track not detected
   for ``max_coast`` seconds (``tentative_coast`` while tentative) is dropped, as is one whose
   position standard deviation passes ``max_position_sigma``.

Speeds are kept non-negative: a state with ``v < 0`` is turned around (``θ + π``, ``−v``), so the
heading is the direction of travel.
"""

from __future__ import annotations

import math
from collections import namedtuple
from dataclasses import astuple, dataclass, fields
from typing import NamedTuple

import numpy as np

from ... import checks
from ...errors import InvalidArgumentError
from ...geometry.so2 import wrap_angle
from . import _kernels as K
from . import _steps as S
from . import ekf
from ._steps import CONFIRMED, MIN_VEHICLE_LENGTH, STAMP_TOLERANCE, TENTATIVE
from .detection import Detections

__all__ = ["TrackerParams", "Tracker", "Tracks"]


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


#: :class:`TrackerParams`'s fields as a named tuple, as the kernels take them (:mod:`._steps`).
_Knobs = namedtuple("TrackerKnobs", [f.name for f in fields(TrackerParams)])


def _knobs(params: TrackerParams):
    """``params`` for the kernels: numbers as floats (counts as ints), pairs as float pairs, so
    that every setting compiles to the same types."""
    def number(v):
        if isinstance(v, tuple | list):
            return tuple(float(x) for x in v)
        return int(v) if isinstance(v, int | np.integer) and not isinstance(v, bool) else float(v)
    return _Knobs(*(number(v) for v in astuple(params)))


class TrackArrays(NamedTuple):
    """The tracker's arrays, one row per track (see :class:`Tracker`), as its kernels take them."""

    id: np.ndarray
    state: np.ndarray
    cov: np.ndarray
    status: np.ndarray
    size: np.ndarray
    birth: np.ndarray
    born: np.ndarray
    travel: np.ndarray
    last_hit: np.ndarray
    updates: np.ndarray
    hit_bits: np.ndarray
    centres: np.ndarray
    birth_ends: np.ndarray
    birth_bare: np.ndarray
    birth_whole: np.ndarray


#: The fields of :class:`Detections` that are not float64 arrays, and their types.
_DETECTION_TYPES = {"points": np.int64, "cut": np.bool_, "oriented": np.bool_, "bare": np.bool_}


def _for_kernels(det: Detections) -> Detections:
    """Detections as the kernels take them: contiguous arrays of one type per field."""
    return Detections(*(np.ascontiguousarray(getattr(det, name), dtype=_DETECTION_TYPES.get(name, np.float64))
                        for name in Detections._fields))


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


def _turn_around(states: np.ndarray, covs: np.ndarray) -> None:
    """In place: states with negative speed get ``θ + π`` and ``−v`` (the same motion)."""
    back = states[:, 3] < 0.0
    if back.any():
        states[back, 2] = wrap_angle(states[back, 2] + math.pi)
        states[back, 3] = -states[back, 3]
        flip = np.diag([1.0, 1.0, 1.0, -1.0, 1.0])
        covs[back] = flip @ covs[back] @ flip


class Tracker:
    """Tracks of moving objects, updated scan by scan (see the module's description).

    >>> tracker = Tracker()
    >>> tracker.update(0.1, detect_objects(points), sensor=(x, y))  # doctest: +SKIP
    >>> tracker.tracks().confirmed  # doctest: +SKIP
    """

    def __init__(self, params: TrackerParams | None = None):
        self.params = TrackerParams() if params is None else params
        self._knobs = _knobs(self.params)
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
        # the view the wait for a velocity started from (see _steps.correct): its ends, which were bare,
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

    # ------------------------------------------------------------------ update

    def _arrays(self) -> TrackArrays:
        return TrackArrays(*(getattr(self, name) for name in TrackArrays._fields))

    def update(self, stamp: float, detections: Detections, sensor) -> None:
        """Bring the tracks to ``stamp`` (s, not before the last) with one scan's detections seen
        from ``sensor`` (x, y) in the world frame (the steps of the module's description; their
        kernels are in :mod:`._steps`)."""
        p = self.params
        sx, sy = (float(v) for v in np.asarray(sensor, dtype=np.float64).reshape(-1)[:2])
        self._advance(stamp)
        self.stats["updates"] += 1
        self.stats["detections"] += len(detections)
        n, m = len(self), len(detections)
        tracks = self._arrays()
        S.next_scan(tracks)
        rows = cols = np.empty(0, np.int64)
        if n and m:
            det = _for_kernels(detections)
            centre, covariance, lever = np.empty((n * m, 2)), np.empty((n * m, 2, 2)), np.empty((n * m, 2))
            cost = S.measure_pairs(tracks, det, sx, sy, self.time, self._knobs, centre, covariance, lever,
                                   np.empty((n, m)))
            pairs = np.empty((2, min(n, m)), np.int64)
            k = S.assign_rounds(cost, self.status == CONFIRMED, pairs[0], pairs[1])
            rows, cols = pairs[0, :k], pairs[1, :k]
            if k:
                moved = S.correct(tracks, det, rows, cols, centre, covariance, lever, self.time, self._knobs,
                                  np.empty(k, np.bool_))
                S.resize(tracks, det, rows[moved], cols[moved], sx, sy, self._knobs)
        missed = np.ones(n, np.bool_)
        missed[rows] = False
        S.count_hidden(tracks, missed, sx, sy)
        lost = np.empty(n, np.bool_)
        self.stats["tracks_confirmed"] += S.confirm_and_drop(tracks, self.time, self._knobs, lost)
        if lost.any():
            self.stats["tracks_dropped"] += int(lost.sum())
            self._keep(~lost)
        spawn = np.ones(m, np.bool_)
        spawn[cols] = False
        spawn = np.flatnonzero(spawn)
        if len(spawn) and len(self):
            # a part of an object that a nearer one splits off from the rest starts no track
            spawn = spawn[~self.covers(np.stack([detections.x[spawn], detections.y[spawn]], -1), self.time,
                                       p.footprint_margin)]
        if len(spawn):
            self._spawn(detections, spawn)
        _turn_around(self.state, self.cov)

    def _keep(self, keep) -> None:
        for name in TrackArrays._fields:
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
