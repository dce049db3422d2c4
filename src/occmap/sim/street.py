"""A street with moving cars and people, its truth at every instant, and the sensors that see it:
a planar lidar (cast exactly through :class:`~occmap.sim.world2d.World2D`) and an automotive radar.

The default scene (:meth:`Street.default`, 20 s) is a main street along x (road ``|y| ≤ 5`` m, a
parking lane at ``|y| ≈ 4``, lanes centred at ``y = ±1.5``, pavements to the building fronts at
``|y| = 8``) crossed at ``x ∈ [65, 75]`` by a side street along y. In it: parked cars (static), cars
at 6–14 m/s passing each other (1.2 m apart), one turning from the side street into the main
street (easing in and out of the bend), one crossing it, pedestrians at 1.2–1.8 m/s along and
across the street, and a delivery
robot on the southern pavement at 1.5 m/s that carries the sensors.

Objects move on piecewise constant ``(speed, yaw rate)`` legs integrated exactly
(:func:`~occmap.geometry.motion.unicycle_step`: the constant turn rate and velocity model), so the
truth a tracker is scored against is its own motion model's. Every object has an id, a kind
(:data:`CAR`, :data:`PEDESTRIAN`, :data:`PARKED`), a footprint (cars are boxes, pedestrians discs of
diameter ``width``) and exists from its start time to the end of its last leg.

>>> street = Street.default()
>>> scan = street.lidar(5.0, rng=0)
>>> truth = street.objects(5.0)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .. import checks
from ..geometry.motion import unicycle_step
from ..local.tracking.detection import box_corners
from ..scan import LaserScan
from .world2d import World2D, simulate_lidar

__all__ = ["CAR", "PARKED", "PEDESTRIAN", "Mover", "Objects", "RadarScan", "Street", "CLUTTER", "GHOST", "STATIC"]

#: Object kinds.
CAR, PEDESTRIAN, PARKED = 0, 1, 2
#: Truth labels of radar detections and lidar returns that are not an object's.
STATIC, CLUTTER, GHOST = -1, -2, -3


@dataclass(frozen=True)
class Mover:
    """One object: ``start`` pose ``(x, y, heading)`` at time ``t0`` (s), then ``legs`` of
    ``(duration s, speed m/s, yaw rate rad/s)`` driven in turn; a parked object has one leg of speed 0.
    ``length`` and ``width`` in metres (a pedestrian's disc has diameter ``width``)."""

    ident: int
    kind: int
    length: float
    width: float
    t0: float
    start: tuple
    legs: tuple

    @property
    def t_end(self) -> float:
        return self.t0 + sum(leg[0] for leg in self.legs)

    def state(self, t: float):
        """``(pose (3,), speed, yaw rate)`` at time ``t`` (``t0 ≤ t ≤ t_end``)."""
        pose = np.array(self.start, dtype=np.float64)
        left = t - self.t0
        speed = rate = 0.0
        for duration, speed, rate in self.legs:
            step = min(left, duration)
            pose = unicycle_step(pose, speed, rate, step)
            left -= step
            if left <= 0.0:
                break
        return pose, float(speed), float(rate)


class Objects(NamedTuple):
    """The objects present at one instant, one entry each: ``id``, ``kind``, centre ``x``, ``y``
    (m), ``heading`` (rad), ``speed`` (m/s along the heading), ``yaw_rate`` (rad/s), velocity ``vx``,
    ``vy`` (m/s, world frame), ``length``, ``width`` (m)."""

    id: np.ndarray
    kind: np.ndarray
    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    speed: np.ndarray
    yaw_rate: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    length: np.ndarray
    width: np.ndarray

    def __len__(self) -> int:
        return int(self.id.shape[0])

    def corners(self) -> np.ndarray:
        """Footprint corners ``(N, 4, 2)``, counter-clockwise from rear right."""
        return box_corners(self.x, self.y, self.heading, self.length, self.width)


class RadarScan(NamedTuple):
    """One radar sweep: the sensor ``pose`` (x, y, heading) and its world velocity ``ego_velocity``
    (vx, vy) at ``stamp``; per detection the ``range`` (m), ``azimuth`` (rad, from the sensor's
    heading, counter-clockwise), ``radial_velocity`` (m/s, of the reflector relative to the sensor
    along the line of sight, positive moving away: what a Doppler radar measures, ego motion *not*
    removed), ``rcs`` (radar cross-section, dBsm) and, as truth for tests, ``truth``: the object id,
    or :data:`STATIC`, :data:`CLUTTER` (false alarm), :data:`GHOST` (multipath)."""

    pose: np.ndarray
    ego_velocity: np.ndarray
    stamp: float
    range: np.ndarray
    azimuth: np.ndarray
    radial_velocity: np.ndarray
    rcs: np.ndarray
    truth: np.ndarray


# ------------------------------------------------------------------ the default scene

_X_END = 140.0
_FRONT = 8.0  # building fronts at |y| = 8
_SIDE = (62.0, 78.0)  # the side street's building fronts in x
_SIDE_END = 50.0
_CAR = (4.5, 1.8)
_PERSON = 0.6


def _inside(corners: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Whether the points (x, y) lie in the convex quadrilateral ``corners`` (4, 2), counter-clockwise."""
    inside = np.ones(x.shape, dtype=bool)
    for k in range(4):
        (ax, ay), (bx, by) = corners[k], corners[(k + 1) % 4]
        inside &= (bx - ax) * (y - ay) - (by - ay) * (x - ax) >= 0.0
    return inside


def _grown(mask: np.ndarray) -> np.ndarray:
    """``mask`` dilated by one cell (8-neighbourhood)."""
    out = mask.copy()
    H, W = mask.shape
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            out[max(dy, 0):H + min(dy, 0), max(dx, 0):W + min(dx, 0)] |= \
                mask[max(-dy, 0):H + min(-dy, 0), max(-dx, 0):W + min(-dx, 0)]
    return out


def _walls() -> np.ndarray:
    x0, x1 = _SIDE
    return np.array([
        [0.0, _FRONT, x0, _FRONT], [x1, _FRONT, _X_END, _FRONT],
        [0.0, -_FRONT, x0, -_FRONT], [x1, -_FRONT, _X_END, -_FRONT],
        [x0, _FRONT, x0, _SIDE_END], [x1, _FRONT, x1, _SIDE_END],
        [x0, -_FRONT, x0, -_SIDE_END], [x1, -_FRONT, x1, -_SIDE_END],
        # shop recesses and steps along the fronts
        [20.0, -_FRONT, 20.0, -7.6], [20.0, -7.6, 23.0, -7.6], [23.0, -7.6, 23.0, -_FRONT],
        [40.0, _FRONT, 40.0, 7.5], [40.0, 7.5, 44.0, 7.5], [44.0, 7.5, 44.0, _FRONT],
    ])


def _trees() -> np.ndarray:
    xs = np.array([10.0, 25.0, 35.0, 50.0, 85.0, 100.0, 115.0, 130.0])
    return np.concatenate([np.stack([xs, np.full(8, 5.6), np.full(8, 0.15)], -1),
                           np.stack([xs + 7.0, np.full(8, -5.6), np.full(8, 0.15)], -1)])


def _turn_legs(speed: float, radius: float, angle: float, ramp: float = 1.0, steps: int = 10) -> tuple:
    """Legs that turn by ``angle`` (rad, negative clockwise) at ``speed`` on an arc of ``radius``,
    the yaw rate raised and lowered over ``ramp`` seconds in ``steps`` stairs (as a driver eases
    into a bend: yaw acceleration about ``speed / radius / ramp``)."""
    rate = math.copysign(speed / radius, angle)
    dt = ramp / steps
    up = [(dt, speed, rate * (k + 0.5) / steps) for k in range(steps)]
    hold = abs(angle / rate) - ramp  # each ramp turns by rate · ramp / 2
    return (*up, (hold, speed, rate), *reversed(up))


def _displacement(legs: tuple, heading: float) -> np.ndarray:
    """Where ``legs`` driven from the origin at ``heading`` end."""
    return Mover(0, CAR, 1.0, 1.0, 0.0, (0.0, 0.0, heading), legs).state(sum(leg[0] for leg in legs))[0][:2]


def _default_movers() -> tuple:
    car, person = _CAR, _PERSON
    turn_v = 6.0
    turn = _turn_legs(turn_v, 8.0, -math.pi / 2.0)
    # where the turn must begin for the car to come out of it on the eastbound lane's centre line
    _, dy = _displacement(turn, math.pi / 2.0)
    approach = (-1.5 - dy) - (-45.0)
    parked = [(18.0, 4.0), (24.0, 4.0), (47.0, 4.0), (95.0, 4.0), (101.0, 4.0), (88.0, -4.0), (110.0, -4.0)]
    movers = [Mover(i, PARKED, *car, 0.0, (x, y, 0.0), ((1e9, 0.0, 0.0),)) for i, (x, y) in enumerate(parked)]
    k = len(movers)
    movers += [
        Mover(k, CAR, *car, 0.0, (10.0, -1.5, 0.0), ((12.0, 10.0, 0.0),)),  # eastbound
        Mover(k + 1, CAR, *car, 2.0, (135.0, 1.5, math.pi), ((12.0, 11.0, 0.0),)),  # westbound, passes k
        Mover(k + 2, CAR, *car, 3.0, (71.5, -45.0, math.pi / 2.0),  # turns right into the main street
              ((approach / turn_v, turn_v, 0.0), *turn, (10.0, turn_v, 0.0))),
        Mover(k + 3, CAR, *car, 4.0, (68.5, 45.0, -math.pi / 2.0), ((90.0 / 13.0, 13.0, 0.0),)),  # crosses
        Mover(k + 4, CAR, *car, 9.5, (0.0, -1.5, 0.0), ((10.5, 12.0, 0.0),)),  # overtakes the robot
        Mover(k + 5, PEDESTRIAN, person, person, 0.0, (100.0, 6.3, math.pi), ((20.0, 1.4, 0.0),)),
        Mover(k + 6, PEDESTRIAN, person, person, 0.0, (52.0, -7.3, 0.0), ((20.0, 1.6, 0.0),)),
        Mover(k + 7, PEDESTRIAN, person, person, 5.0, (85.0, 7.0, -math.pi / 2.0), ((14.5 / 1.2, 1.2, 0.0),)),
        Mover(k + 8, PEDESTRIAN, person, person, 0.0, (40.0, 7.3, 0.0), ((20.0, 1.8, 0.0),)),
    ]
    return tuple(movers)


@dataclass(frozen=True)
class Street:
    """A street scene: static ``walls`` (M, 4) and ``poles`` (K, 3) discs, the ``movers`` (parked
    ones included) and the ``robot`` that carries the sensors (a :class:`Mover` too). ``duration``
    is the length of the scene in seconds."""

    walls: np.ndarray
    poles: np.ndarray
    movers: tuple
    robot: Mover
    duration: float
    bounds: tuple

    @classmethod
    def default(cls) -> Street:
        robot = Mover(-1, CAR, 0.6, 0.5, 0.0, (45.0, -6.8, 0.0), ((20.0, 1.5, 0.0),))
        return cls(_walls(), _trees(), _default_movers(), robot, 20.0,
                   (0.0, -_SIDE_END, _X_END, _SIDE_END))

    def objects(self, t: float) -> Objects:
        """Truth: the objects present at time ``t`` (s)."""
        t = checks.finite("t", t)
        rows = []
        for m in self.movers:
            if m.t0 <= t <= m.t_end:
                pose, speed, rate = m.state(t)
                rows.append((m.ident, m.kind, *pose, speed, rate, m.length, m.width))
        a = np.array(rows, dtype=np.float64).reshape(-1, 9)
        heading, speed = a[:, 4], a[:, 5]
        return Objects(a[:, 0].astype(np.int64), a[:, 1].astype(np.int64), a[:, 2], a[:, 3], heading, speed,
                       a[:, 6], speed * np.cos(heading), speed * np.sin(heading), a[:, 7], a[:, 8])

    def robot_pose(self, t: float) -> np.ndarray:
        """The robot's pose ``(x, y, heading)`` at ``t``."""
        return self.robot.state(checks.finite("t", t))[0]

    def robot_velocity(self, t: float) -> np.ndarray:
        """The robot's world velocity ``(vx, vy)`` at ``t`` (m/s)."""
        pose, speed, _ = self.robot.state(checks.finite("t", t))
        return speed * np.array([math.cos(pose[2]), math.sin(pose[2])])

    def world(self, t: float) -> World2D:
        """The scene frozen at ``t``: walls, poles, car outlines as segments, pedestrians as discs."""
        obj = self.objects(t)
        box = obj.kind != PEDESTRIAN
        c = obj.corners()[box]
        edges = np.concatenate([c, np.roll(c, -1, axis=1)], axis=-1).reshape(-1, 4)
        people = np.stack([obj.x, obj.y, obj.width / 2.0], -1)[~box]
        return World2D(np.concatenate([self.walls, edges]), np.concatenate([self.poles, people]), self.bounds)

    def label(self, points, t: float, margin: float = 0.05) -> np.ndarray:
        """Truth label of world points ``(N, 2)`` at ``t``: the id of the object whose footprint,
        grown by ``margin`` (m), holds the point, else :data:`STATIC`."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        obj = self.objects(t)
        dx = p[:, None, 0] - obj.x[None]
        dy = p[:, None, 1] - obj.y[None]
        c, s = np.cos(obj.heading), np.sin(obj.heading)
        along, across = c * dx + s * dy, -s * dx + c * dy
        in_box = (np.abs(along) <= obj.length / 2.0 + margin) & (np.abs(across) <= obj.width / 2.0 + margin)
        in_disc = np.hypot(dx, dy) <= obj.width / 2.0 + margin
        inside = np.where(obj.kind == PEDESTRIAN, in_disc, in_box)
        out = np.full(p.shape[0], STATIC, dtype=np.int64)
        hit = inside.any(axis=1)
        out[hit] = obj.id[inside.argmax(axis=1)[hit]]
        return out

    def lidar(self, t: float, n_beams: int = 720, max_range: float = 30.0, sigma: float = 0.02,
              rng=None) -> LaserScan:
        """The robot's planar lidar at ``t``: a full circle of ``n_beams`` (see
        :func:`~occmap.sim.world2d.simulate_lidar` for the noise model), pose and stamp set."""
        return simulate_lidar(self.world(t), self.robot_pose(t), n_beams=n_beams, max_range=max_range,
                              sigma=sigma, rng=rng, stamp=float(t))

    def lidar_scans(self, rate: float = 10.0, rng=None, **options) -> list[LaserScan]:
        """Lidar scans at ``rate`` Hz over the whole scene (``options`` as :meth:`lidar`)."""
        rng = np.random.default_rng(rng)
        stamps = np.arange(0.0, self.duration + 1e-9, 1.0 / checks.positive("rate", rate, "Hz"))
        return [self.lidar(float(t), rng=rng, **options) for t in stamps]

    def radar(self, t: float, rng=None, *, fov: float = 2.0 * math.pi, max_range: float = 60.0,
              azimuth_step: float = math.radians(1.0), sigma_range: float = 0.15,
              sigma_azimuth: float = math.radians(0.5), sigma_velocity: float = 0.1,
              p_detect: tuple = (0.5, 0.35, 0.15), clutter_rate: float = 4.0, p_ghost: float = 0.05) -> RadarScan:
        """An automotive radar sweep from the robot at ``t``.

        Rays every ``azimuth_step`` across ``fov`` (centred on the heading) find the reflectors;
        each reflector point becomes a detection with probability ``p_detect`` = (object, pedestrian,
        static structure) per ray, with Gaussian noise on range, azimuth and radial velocity. Then
        ``clutter_rate`` false alarms on average (Poisson; uniform in range and azimuth, half at the
        Doppler of the static ground, half at random velocities within ±15 m/s) and, for each
        object detection between two building fronts of the main street with probability
        ``p_ghost``, a multipath ghost: the reflector mirrored across the front beyond it, with its
        mirrored velocity. Cross-sections (dBsm): cars 10 ± 3, pedestrians −5 ± 3, structure
        15 ± 5, false alarms −10 ± 5. The default noise is a 77 GHz radar's (range 0.15 m, azimuth
        0.5°: such sensors state 0.1–0.3° at boresight and about 1° at ±45°).
        """
        rng = np.random.default_rng(rng)
        pose = self.robot_pose(t)
        ego = self.robot_velocity(t)
        n = max(1, int(round(checks.positive("fov", fov) / checks.positive("azimuth_step", azimuth_step))))
        rel = (np.arange(n) + 0.5) * (fov / n) - fov / 2.0
        true = self.world(t).cast(pose[:2], pose[2] + rel, max_range)
        seen = np.isfinite(true) & (true > 0.0)
        rel, true = rel[seen], true[seen]
        world_pts = pose[:2] + true[:, None] * np.stack([np.cos(pose[2] + rel), np.sin(pose[2] + rel)], -1)
        truth = self.label(world_pts, t, margin=1e-3)
        obj = self.objects(t)
        kind = np.full(truth.shape, -1)
        vel = np.zeros((truth.shape[0], 2))
        row = {int(i): k for k, i in enumerate(obj.id)}
        for j in np.flatnonzero(truth >= 0):  # one lookup per detection of an object, a few dozen
            k = row[int(truth[j])]
            kind[j] = obj.kind[k]
            vel[j] = (obj.vx[k], obj.vy[k])
        pd = np.where(kind == PEDESTRIAN, p_detect[1], np.where(kind >= 0, p_detect[0], p_detect[2]))
        keep = rng.random(truth.shape[0]) < pd
        pts, vel, truth, kind = world_pts[keep], vel[keep], truth[keep], kind[keep]
        rcs = np.where(kind == PEDESTRIAN, -5.0, np.where(kind >= 0, 10.0, 15.0))
        rcs = rcs + rng.normal(0.0, np.where(kind < 0, 5.0, 3.0))
        fronted = (np.abs(pts[:, 1]) < _FRONT) & ((pts[:, 0] < _SIDE[0]) | (pts[:, 0] > _SIDE[1]))
        ghost = (truth >= 0) & fronted & (rng.random(truth.shape[0]) < p_ghost)
        g_pts = pts[ghost].copy()
        front = np.where(g_pts[:, 1] > pose[1], _FRONT, -_FRONT)
        g_pts[:, 1] = 2.0 * front - g_pts[:, 1]
        g_vel = vel[ghost] * np.array([1.0, -1.0])
        m = rng.poisson(checks.non_negative("clutter_rate", clutter_rate))
        c_rel = rng.uniform(-fov / 2.0, fov / 2.0, m)
        c_rng = rng.uniform(1.0, max_range, m)
        c_pts = pose[:2] + c_rng[:, None] * np.stack([np.cos(pose[2] + c_rel), np.sin(pose[2] + c_rel)], -1)
        c_vel = np.where(rng.random(m)[:, None] < 0.5, 0.0, rng.uniform(-15.0, 15.0, (m, 2)))
        pts = np.concatenate([pts, g_pts, c_pts])
        vel = np.concatenate([vel, g_vel, c_vel])
        truth = np.concatenate([truth, np.full(g_pts.shape[0], GHOST), np.full(m, CLUTTER)])
        rcs = np.concatenate([rcs, rcs[ghost] - 6.0, rng.normal(-10.0, 5.0, m)])
        d = pts - pose[:2]
        r = np.hypot(d[:, 0], d[:, 1])
        u = d / r[:, None]
        vr = np.einsum("ij,ij->i", vel - ego, u)
        az = np.arctan2(d[:, 1], d[:, 0]) - pose[2]
        k = r.shape[0]
        return RadarScan(pose, ego, float(t), r + rng.normal(0.0, sigma_range, k),
                         np.angle(np.exp(1j * (az + rng.normal(0.0, sigma_azimuth, k)))),
                         vr + rng.normal(0.0, sigma_velocity, k), rcs, truth)

    def visible_static(self, stamps, resolution: float, origin, shape, max_range: float,
                       azimuth_step: float = math.radians(1.0)) -> np.ndarray:
        """Truth for recall: the cells (bool (H, W) on the grid ``origin``/``shape``) of static
        structure and parked cars that a noise-free ray every ``azimuth_step`` from the robot
        reaches first, within ``max_range``, at any of ``stamps``."""
        out = np.zeros(shape, dtype=bool)
        res = checks.resolution(resolution)
        o = np.asarray(origin, dtype=np.float64)
        parked = [m.ident for m in self.movers if m.kind == PARKED]
        n = max(1, int(round(2.0 * math.pi / checks.positive("azimuth_step", azimuth_step))))
        rel = (np.arange(n) + 0.5) * (2.0 * math.pi / n) - math.pi
        for t in stamps:
            pose = self.robot_pose(float(t))
            r = self.world(float(t)).cast(pose[:2], pose[2] + rel, max_range)
            seen = np.isfinite(r) & (r < max_range)
            a = pose[2] + rel[seen]
            # a millimetre past the surface: the point inside what it hit
            pts = pose[:2] + (r[seen] + 1e-3)[:, None] * np.stack([np.cos(a), np.sin(a)], -1)
            label = self.label(pts, float(t), margin=1e-3)
            pts = pts[(label == STATIC) | np.isin(label, parked)]
            ij = np.floor((pts - o) / res).astype(np.int64)
            inside = (ij >= 0).all(axis=1) & (ij[:, 0] < shape[1]) & (ij[:, 1] < shape[0])
            out[ij[inside, 1], ij[inside, 0]] = True
        return out

    def map_scores(self, occupied, resolution: float, origin, stamps, max_range: float = 30.0) -> tuple[float, float]:
        """How well a map of the street's static structure, ``occupied`` (bool (H, W) on the grid
        ``origin``), matches the truth: ``(precision, recall)``. Precision: the share of occupied
        cells within one cell (8-neighbourhood) of a truly occupied one (:meth:`occupancy` at the
        end, static only); recall: the share of the cells a sensor at the robot could see first
        within ``max_range`` at ``stamps`` (:meth:`visible_static`) that lie within one cell of
        an occupied one. Either is NaN when there is nothing to count."""
        occupied = np.asarray(occupied, dtype=bool)
        end = max(float(t) for t in stamps)
        truth = self.occupancy(end, resolution, origin, occupied.shape, static_only=True)
        seen = self.visible_static(stamps, resolution, origin, occupied.shape, max_range)
        n_occ, n_seen = int(occupied.sum()), int(seen.sum())
        precision = (occupied & _grown(truth)).sum() / n_occ if n_occ else math.nan
        recall = (seen & _grown(occupied)).sum() / n_seen if n_seen else math.nan
        return float(precision), float(recall)

    def occupancy(self, t: float, resolution: float, origin, shape, static_only: bool = False):
        """True occupancy raster ``(H, W)`` at ``t`` on the grid ``origin``/``shape``: the cells
        that walls, poles and people touch (see :meth:`World2D.occupancy`) and the cells whose
        centre lies in a car, cars being solid. ``static_only`` leaves out the moving objects
        (parked cars stay)."""
        scene = self
        if static_only:
            scene = Street(self.walls, self.poles, tuple(m for m in self.movers if m.kind == PARKED),
                           self.robot, self.duration, self.bounds)
        out = scene.world(t).occupancy(resolution, origin, shape)[0]
        obj = scene.objects(t)
        res = checks.resolution(resolution)
        o = np.asarray(origin, dtype=np.float64)
        H, W = shape
        for corners in obj.corners()[obj.kind != PEDESTRIAN]:  # one box per car, a few dozen
            lo = np.maximum(np.floor((corners.min(0) - o) / res).astype(int), 0)
            hi = np.minimum(np.floor((corners.max(0) - o) / res).astype(int), (W - 1, H - 1))
            if (lo > hi).any():
                continue
            cx, cy = np.meshgrid(o[0] + (np.arange(lo[0], hi[0] + 1) + 0.5) * res,
                                 o[1] + (np.arange(lo[1], hi[1] + 1) + 0.5) * res)
            out[lo[1]:hi[1] + 1, lo[0]:hi[0] + 1] |= _inside(corners, cx, cy)
        return out
