"""Multi-object tracking: one CTRV extended Kalman filter per object (:mod:`.ekf`), Mahalanobis
gating, global nearest-neighbour assignment (:mod:`.assignment`) and track management.

A scan's detections (:class:`~.detection.Detections`) update the tracks in four steps:

1. **Predict** every track to the scan's stamp.
2. **Measure against each track**: a box seen from the sensor shows only its near faces, so its
   centre lies nearer to the sensor than the object's. For each track–detection pair the box's
   corners are projected on the track's axes; along an axis where the seen extent is shorter than
   the track's size, the edge nearer to the sensor is kept and the centre put half the size behind
   it. That centre is the pair's measurement.
3. **Gate and assign**: pairs with squared Mahalanobis distance of the centres above ``gate`` are
   not allowed; among the rest the assignment of least total ``d² + ln det S`` that matches the
   most pairs is taken (the cost of a Gaussian likelihood).
4. **Manage**: a matched track is updated (its heading too when the box is L-shaped, choosing the
   box axis nearer to the track's heading); its size grows to the largest extent seen (capped).
   A detection left over starts a *tentative* track; at its second detection the velocity is set
   from the displacement (two-point initialisation). A tentative track is *confirmed* once it has
   been detected in ``confirm_hits`` of its last ``confirm_window`` scans and has moved at least
   ``min_travel`` from where it started (walls and parked cars that leak into the detections do
   not move). A track not detected for ``max_coast`` seconds (``tentative_coast`` while tentative)
   is dropped, as is one whose position standard deviation passes ``max_position_sigma``.

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
from . import ekf
from .assignment import assign
from .detection import Detections

__all__ = ["TrackerParams", "Tracker", "Tracks"]

TENTATIVE, CONFIRMED = 0, 1
#: Tracks shorter than this (m) are taken as round objects (people), longer ones as vehicles.
MIN_VEHICLE_LENGTH = 1.0


@dataclass(frozen=True)
class TrackerParams:
    """Tracker settings (SI units; see the module's description for their role)."""

    accel: float = 3.0
    yaw_accel: float = 1.5
    position_sigma: float = 0.15
    heading_sigma: float = math.radians(8.0)
    gate: float = 13.8  # χ² with 2 degrees of freedom at 99.9 %
    confirm_hits: int = 3
    confirm_window: int = 5
    min_travel: float = 0.5
    max_coast: float = 1.0
    tentative_coast: float = 0.3
    max_position_sigma: float = 3.0
    max_size: tuple = (8.0, 3.0)
    vehicle_size: tuple = (4.0, 1.7)
    vehicle_width: float = 1.2
    min_moving_speed: float = 1.0
    max_speed: float = 20.0
    initial_speed_sigma: float = 10.0
    initial_yaw_rate_sigma: float = 0.5
    radial_velocity_sigma: float = 0.2

    def __post_init__(self):
        for name in ("accel", "yaw_accel", "position_sigma", "heading_sigma", "gate", "max_coast",
                     "tentative_coast", "max_position_sigma", "vehicle_width", "max_speed", "initial_speed_sigma", "initial_yaw_rate_sigma",
                     "radial_velocity_sigma"):
            checks.positive(name, getattr(self, name))
        checks.non_negative("min_travel", self.min_travel, "metres")
        if not 1 <= self.confirm_hits <= self.confirm_window <= 8:
            raise InvalidArgumentError(f"need 1 ≤ confirm_hits ({self.confirm_hits}) ≤ confirm_window "
                                       f"({self.confirm_window}) ≤ 8")


class Tracks(NamedTuple):
    """Tracks at one time, one entry each: ``id``, centre ``x``, ``y`` (m), velocity ``vx``, ``vy``
    (m/s), ``heading`` (rad, direction of travel), ``length``, ``width`` (m), ``confirmed`` and the
    state covariance ``covariance`` ``(N, 5, 5)`` over ``(x, y, heading, speed, yaw_rate)``."""

    id: np.ndarray
    x: np.ndarray
    y: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    heading: np.ndarray
    length: np.ndarray
    width: np.ndarray
    confirmed: np.ndarray
    covariance: np.ndarray

    def __len__(self) -> int:
        return int(self.id.shape[0])


def _corners(det: Detections) -> np.ndarray:
    """Corners ``(M, 4, 2)`` of detected boxes."""
    c, s = np.cos(det.heading), np.sin(det.heading)
    hl, hw = det.length / 2.0, det.width / 2.0
    u = np.array([-1.0, 1.0, 1.0, -1.0])
    w = np.array([-1.0, -1.0, 1.0, 1.0])
    ax = u[None] * hl[:, None]
    ay = w[None] * hw[:, None]
    return np.stack([det.x[:, None] + c[:, None] * ax - s[:, None] * ay,
                     det.y[:, None] + s[:, None] * ax + c[:, None] * ay], -1)


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
        self.time: float | None = None
        self._next_id = 0
        self.id = np.empty(0, np.int64)
        self.state = np.empty((0, 5))
        self.cov = np.empty((0, 5, 5))
        self.status = np.empty(0, np.int8)
        self.size = np.empty((0, 2))
        self.birth = np.empty((0, 2))
        self.travel = np.empty(0)
        self.last_hit = np.empty(0)
        self.updates = np.empty(0, np.int64)
        self.hit_bits = np.empty(0, np.uint8)
        self.stats = {"updates": 0, "detections": 0, "tracks_started": 0, "tracks_confirmed": 0, "tracks_dropped": 0}

    def __len__(self) -> int:
        return int(self.id.shape[0])

    # ------------------------------------------------------------------ time

    def _advance(self, stamp: float) -> None:
        stamp = checks.finite("stamp", stamp)
        if self.time is not None:
            dt = stamp - self.time
            if dt < 0.0:
                raise InvalidArgumentError(f"stamp {stamp!r} goes backwards: the tracker is at {self.time!r} s")
            if dt > 0.0 and len(self):
                p = self.params
                self.state, self.cov = ekf.predict(self.state, self.cov, dt, p.accel, p.yaw_accel)
        self.time = stamp

    def predicted(self, t: float, confirmed_only: bool = True):
        """``(ids, states (N, 5), covariances (N, 5, 5), sizes (N, 2))`` of the tracks predicted to
        time ``t`` (at or after the last update), without changing them."""
        t = checks.finite("t", t)
        now = self.time if self.time is not None else t
        if t < now:
            raise InvalidArgumentError(f"t = {t!r} lies before the tracker's time {now!r}: predictions go forward only")
        keep = self.status == CONFIRMED if confirmed_only else np.ones(len(self), bool)
        s, c = self.state[keep], self.cov[keep]
        if t > now and len(s):
            s, c = ekf.predict(s, c, t - now, self.params.accel, self.params.yaw_accel)
        return self.id[keep], s, c, self.size[keep]

    # ------------------------------------------------------------------ measurement

    def _pair_frames(self, det: Detections, sensor: np.ndarray):
        """Per track and detection: the axes ``(N, M, 2, 2)`` (rows) in which the detection is
        measured and the track's size ``(N, 2)`` along them. A vehicle (length ≥
        :data:`MIN_VEHICLE_LENGTH`) is measured along its heading and its side; a smaller object,
        taken as round, along the line of sight and across it, its size the largest seen."""
        th = self.state[:, 2]
        track = np.stack([np.stack([np.cos(th), np.sin(th)], -1), np.stack([-np.sin(th), np.cos(th)], -1)], 1)
        d = np.stack([det.x, det.y], -1) - sensor
        u = d / np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)[:, None]
        sight = np.stack([u, np.stack([-u[:, 1], u[:, 0]], -1)], 1)
        small = self.size[:, 0] < MIN_VEHICLE_LENGTH
        axes = np.where(small[:, None, None, None], sight[None], track[:, None])
        size = np.where(small[:, None], self.size.max(axis=1, keepdims=True), self.size)
        return axes, size

    def _measured_centres(self, corners: np.ndarray, axes: np.ndarray, size: np.ndarray, sensor: np.ndarray):
        """Detection centres corrected for the faces not seen ``(..., 2)``, and the extents seen
        ``(..., 2)``, from box corners ``(..., 4, 2)`` measured along ``axes`` ``(..., 2, 2)``
        with the track sizes ``size`` ``(..., 2)``."""
        proj = np.einsum("...cj,...aj->...ac", corners, axes)
        lo, hi = proj.min(-1), proj.max(-1)
        seen = hi - lo
        s_proj = np.einsum("...aj,j->...a", axes, sensor)
        full = np.maximum(size, seen)
        # the edge nearer to the sensor is the one seen; a sensor within the extent sees both
        centre = np.where(s_proj < lo, lo + 0.5 * full, np.where(s_proj > hi, hi - 0.5 * full, 0.5 * (lo + hi)))
        return np.einsum("...a,...aj->...j", centre, axes), seen

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
        rows = cols = np.empty(0, np.int64)
        if n and m:
            axes, size = self._pair_frames(detections, sensor)
            z, seen = self._measured_centres(_corners(detections)[None], axes, size[:, None], sensor)
            r = z - self.state[:, None, :2]
            S = self.cov[:, None, :2, :2] + p.position_sigma ** 2 * np.eye(2)
            # a track seen once has no velocity yet: it may have gone anywhere within max_speed
            young = self.updates == 0
            reach = (p.max_speed * (self.time - self.last_hit[young]) / 3.0) ** 2
            S[young] = (reach[:, None, None, None] + 2.0 * p.position_sigma ** 2) * np.eye(2)
            d2 = np.einsum("nmi,nmi->nm", r, np.linalg.solve(S, r[..., None])[..., 0])
            cost = np.where(d2 <= p.gate, d2 + np.log(np.linalg.det(S)), np.inf)
            rows, cols = assign(cost)
            if len(rows):
                self._correct(rows, cols, z[rows, cols], detections)
                small = self.size[rows, 0] < MIN_VEHICLE_LENGTH
                grown = np.maximum(self.size[rows], seen[rows, cols])
                grown[small] = grown[small].max(axis=1, keepdims=True)
                # a moving object as wide as a car is taken as at least a car until seen whole
                car = (grown.max(axis=1) >= p.vehicle_width) & (self.state[rows, 3] >= p.min_moving_speed)
                grown[car] = np.maximum(grown[car], p.vehicle_size)
                self.size[rows] = np.minimum(grown, p.max_size)
        self._manage(rows)
        spawn = np.setdiff1d(np.arange(m), cols)
        if len(spawn):
            self._spawn(detections, spawn)
        _turn_around(self.state, self.cov)

    def _correct(self, rows, cols, centres, det: Detections) -> None:
        p = self.params
        first = self.updates[rows] == 0
        if first.any():  # the second detection: velocity from the displacement
            r = rows[first]
            d = centres[first] - self.state[r, :2]
            dt = np.maximum(self.time - self.last_hit[r], 1e-3)
            dist = np.hypot(d[:, 0], d[:, 1])
            self.state[r, :2] = centres[first]
            self.state[r, 2] = np.arctan2(d[:, 1], d[:, 0])
            self.state[r, 3] = dist / dt
            self.state[r, 4] = 0.0
            var_p = p.position_sigma ** 2
            cov = np.zeros((len(r), 5, 5))
            cov[:, 0, 0] = cov[:, 1, 1] = var_p
            cov[:, 2, 2] = np.minimum(2.0 * var_p / np.maximum(dist, 1e-9) ** 2, (math.pi / 2) ** 2)
            cov[:, 3, 3] = 2.0 * var_p / dt ** 2 + (p.accel * dt) ** 2
            cov[:, 4, 4] = p.initial_yaw_rate_sigma ** 2
            self.cov[r] = cov
        rest = ~first
        if rest.any():
            r, c = rows[rest], cols[rest]
            z = np.concatenate([centres[rest], np.zeros((len(r), 1))], 1)
            oriented = det.oriented[c] & (self.updates[r] >= 2)
            # the box axis nearer to the track's heading, modulo π
            h = det.heading[c]
            alt = h + math.pi / 2.0
            near = np.abs(wrap_angle(2.0 * (h - self.state[r, 2]))) <= np.abs(wrap_angle(2.0 * (alt - self.state[r, 2])))
            z[:, 2] = np.where(near, h, alt)
            for with_heading in (False, True):
                k = oriented == with_heading
                if not k.any():
                    continue
                y, H = ekf.pose_innovation(self.state[r[k]], z[k], with_heading)
                sig = [p.position_sigma, p.position_sigma] + ([p.heading_sigma] if with_heading else [])
                R = np.broadcast_to(np.diag(np.square(sig)), (int(k.sum()), len(sig), len(sig)))
                self.state[r[k]], self.cov[r[k]] = ekf.update(self.state[r[k]], self.cov[r[k]], y, H, R)
        self.updates[rows] += 1
        self.last_hit[rows] = self.time
        self.hit_bits[rows] |= 1
        d = self.state[rows, :2] - self.birth[rows]
        self.travel[rows] = np.maximum(self.travel[rows], np.hypot(d[:, 0], d[:, 1]))

    def _manage(self, matched) -> None:
        p = self.params
        window = (1 << p.confirm_window) - 1
        hits = np.unpackbits((self.hit_bits & window)[:, None], axis=1).sum(axis=1)
        promote = (self.status == TENTATIVE) & (hits >= p.confirm_hits) & (self.travel >= p.min_travel)
        self.status[promote] = CONFIRMED
        self.stats["tracks_confirmed"] += int(promote.sum())
        idle = self.time - self.last_hit
        limit = np.where(self.status == CONFIRMED, p.max_coast, p.tentative_coast)
        lost = (idle > limit) | (np.sqrt(self.cov[:, 0, 0] + self.cov[:, 1, 1]) > p.max_position_sigma)
        if lost.any():
            self.stats["tracks_dropped"] += int(lost.sum())
            self._keep(~lost)

    def _keep(self, keep) -> None:
        for name in ("id", "state", "cov", "status", "size", "birth", "travel", "last_hit", "updates", "hit_bits"):
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
        self.travel = np.concatenate([self.travel, np.zeros(k)])
        self.last_hit = np.concatenate([self.last_hit, np.full(k, self.time)])
        self.updates = np.concatenate([self.updates, np.zeros(k, np.int64)])
        self.hit_bits = np.concatenate([self.hit_bits, np.ones(k, np.uint8)])
        self.stats["tracks_started"] += k

    # ------------------------------------------------------------------ read-out

    def tracks(self) -> Tracks:
        """The tracks alive at the last update (tentative ones included; see ``confirmed``)."""
        s = self.state
        return Tracks(self.id.copy(), s[:, 0].copy(), s[:, 1].copy(), s[:, 3] * np.cos(s[:, 2]),
                      s[:, 3] * np.sin(s[:, 2]), s[:, 2].copy(), self.size[:, 0].copy(), self.size[:, 1].copy(),
                      self.status == CONFIRMED, self.cov.copy())
