"""A procedural town with known truth, far from the origin, and a long LiDAR drive through it: the
test bed for world-scale maps (kilometres of streets, beyond OctoMap's ±3,276.8 m key range at
0.1 m).

The town is a :class:`~occmap.sim.world3d.World3D` (solid axis-aligned boxes, vertical cylinders,
the ground ``z <= 0``), generated from a :class:`CityPlan` alone — the same plan gives the same
solids, route and scans bit for bit, in any process:

- **Streets**: a grid of streets running north–south and east–west, blocks of varied size between
  them; every few streets, and the ring road round the edge, an avenue (wider). A street is
  ``street_width`` between the building lines: a sidewalk of ``sidewalk`` on each side and the
  road between, whose outer ``PARKING_LANE`` on each side holds parked vehicles.
- **Blocks**: most are cut into lots holding buildings (boxes 6–24 m tall, some with an upper
  storey set back; a few towers of 40–120 m on a podium; awnings over some sidewalks); some are
  parks (trees) or squares (a fountain, a statue on its plinth, lamps).
- **Sidewalks**: street lamps (7 m poles) and trees (a trunk and an overhanging crown); parked
  cars (:func:`occmap.sim.world3d._car`'s body and cabin), vans and trucks along the kerbs, none
  within 6 m of a crossing.

The drive (:attr:`City.route`) follows the centre lines of the roads from the town's south-west
corner, turning at crossings on arcs of ``turn_radius``: at each crossing it prefers a street not
yet driven that passes blocks not yet seen, and when none is adjacent it heads for the nearest one
(never turning back on itself), until the route is ``route_length`` long. Nothing stands on the
roads: the sensor, on the centre line, keeps at least 1.5 m from every parked vehicle.

Scans are made one at a time (:func:`city_drive`, :func:`city_laser_drive`) or singly by number
(:func:`city_scan`, :func:`city_laser_scan`), with the same bits either way: scan ``k`` depends on
the :class:`CityDrive` and ``k`` only, so processes that each make some of the scans (Dask workers)
agree without making the others. (Across machines, bits may differ where NumPy's sin, cos and
arctan2 pick other SIMD code for another CPU: the beam directions and the sensor's heading.) Each process builds the town once per plan (a cache; 0.25 s for
the default town, plus its solid grid on the first scan).

Speed: rays are cast through a 2D grid of the solids (:mod:`occmap.sim.solid_grid`), so a scan
costs what the solids near the sensor cost. Measured on one core (``NUMBA_NUM_THREADS=1``, a shared
2-core machine, noisy), 100-scan stretches of the default drive: 600–740 scans/s with
:data:`CITY_LIDAR` (14,400 beams, ~13,000 points per scan), 280–450 scans/s at the VLP-16's own
0.2° step (28,800 beams), ~5,000 planar scans/s of 720 beams.

The default plan: 2 km × 2 km centred at (10 km, 10 km), 15 × 15 blocks (205 of buildings, 15
parks, 5 squares), 18,561 boxes and 16,142 cylinders; a 20 km drive passing 96% of the blocks,
4,001 scans 5 m apart.

>>> drive = CityDrive(CityPlan(size=(400.0, 300.0), route_length=2_000.0))
>>> cloud = city_scan(10, drive)                  # a PointCloud, points in the sensor frame
>>> clouds = city_drive(drive, start=0, stop=20)  # streamed, one at a time
>>> drive.city.occupied(cloud.world_points())     # the truth
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass, field
from functools import cached_property, lru_cache

import numpy as np

from .. import checks
from ..cloud import PointCloud
from ..errors import InvalidArgumentError
from ..geometry.se3 import SE3
from ..scan import LaserScan
from .world2d import _arc_lengths, _beam_angles, _corrupt, _poses_along
from .world3d import VELODYNE_VLP16, LidarModel, World3D, _car, _tree, level_poses, simulate_lidar

__all__ = [
    "CITY_LIDAR",
    "City",
    "CityDrive",
    "CityPlan",
    "city_drive",
    "city_laser_drive",
    "city_laser_scan",
    "city_scan",
]

#: Width (m) of the strip along each kerb where vehicles park.
PARKING_LANE = 2.6

#: The drive's default sensor: a VLP-16's lasers at a 0.4° azimuth step (900 columns, 14,400 beams
#: per revolution), 100 m range.
CITY_LIDAR = VELODYNE_VLP16.with_azimuth_step(math.radians(0.4))

# Half the chord (m) along the route from which a pose's heading is taken: a property of the route,
# so the pose at an arc length does not depend on the spacing of the scans.
_HEADING_CHORD = 1.0


@dataclass(frozen=True)
class CityPlan:
    """Everything that decides a town: small, hashable and picklable (send it, not the town).

    Attributes
    ----------
    seed : int
        The town's random choices (layout, buildings, objects, route).
    size : (float, float)
        Extent along x and y, metres; the town covers ``centre ± size / 2``.
    centre : (float, float)
        World position of the town's centre, metres. The default, 10 km from the origin on both
        axes, lies beyond any 16-bit OctoMap key at 0.1 m (±3,276.8 m).
    block : (float, float)
        Range of block sides between building lines, metres (stretched a little so the streets
        fill ``size`` exactly).
    street_width, avenue_width : float
        Building line to building line, metres.
    avenue_every : int
        Every this many streets is an avenue (counting from the edge; the edges are avenues).
    sidewalk : float
        Sidewalk width, metres.
    park_share, square_share : float
        Fractions of blocks that are parks and open squares.
    route_length : float
        Length of the drive, metres.
    turn_radius : float
        Radius of the arcs on which the drive turns at crossings, metres.
    """

    seed: int = 0
    size: tuple = (2000.0, 2000.0)
    centre: tuple = (10_000.0, 10_000.0)
    block: tuple = (70.0, 160.0)
    street_width: float = 16.0
    avenue_width: float = 26.0
    avenue_every: int = 4
    sidewalk: float = 3.0
    park_share: float = 0.06
    square_share: float = 0.04
    route_length: float = 20_000.0
    turn_radius: float = 6.0

    def __post_init__(self):
        object.__setattr__(self, "seed", checks.count("seed", self.seed, 0))
        for name in ("size", "centre", "block"):
            v = tuple(float(x) for x in np.asarray(getattr(self, name), dtype=np.float64).reshape(-1))
            if len(v) != 2:
                raise InvalidArgumentError(f"{name} must be two numbers, got {getattr(self, name)!r}")
            for x in v:
                checks.finite(name, x)
            object.__setattr__(self, name, v)
        lo, hi = self.block
        checks.positive("block", lo, "metres")
        if hi < lo:
            raise InvalidArgumentError(f"block must be (min, max) with min <= max, got {self.block}")
        for name in ("street_width", "avenue_width", "sidewalk", "route_length", "turn_radius"):
            object.__setattr__(self, name, checks.positive(name, getattr(self, name), "metres"))
        object.__setattr__(self, "avenue_every", checks.count("avenue_every", self.avenue_every))
        for name in ("park_share", "square_share"):
            object.__setattr__(self, name, checks.fraction(name, getattr(self, name)))
        road = min(self.street_width, self.avenue_width) - 2.0 * self.sidewalk
        if road < 2.0 * PARKING_LANE + 3.0:
            raise InvalidArgumentError(
                f"streets need a road of at least {2.0 * PARKING_LANE + 3.0} m between the "
                f"sidewalks (two parking lanes and 3 m), got {road} m")
        if self.turn_radius > road / 2.0 + self.sidewalk:
            raise InvalidArgumentError(f"turn_radius {self.turn_radius} m does not fit a crossing")
        for name, v in zip(("x", "y"), self.size):
            if v < 2.0 * self.avenue_width + lo:
                raise InvalidArgumentError(f"size along {name} ({v} m) holds no block between two "
                                           f"avenues of {self.avenue_width} m")


@dataclass(frozen=True)
class CityDrive:
    """A drive through a town: the plan, the sensors, and where and how often they scan. Small,
    hashable and picklable, like the plan.

    Scan ``k`` is taken at arc length ``k · spacing`` along the route (``n_scans`` of them, the
    last at or before the route's end), stamped ``k · spacing / speed`` seconds, by a level sensor
    ``height`` above the ground heading along the route.

    Attributes
    ----------
    plan : CityPlan
    lidar : LidarModel
        The 3D sensor of :func:`city_scan`; see :func:`occmap.sim.world3d.simulate_lidar`.
    spacing, height : float
        Metres between scans along the route; sensor height above the ground.
    speed : float
        Metres per second, for the stamps.
    noise_std, dropout : float
        The 3D sensor's range noise (metres, std) and dropout probability.
    seed : int
        The sensors' noise: scan ``k`` draws from ``numpy.random.default_rng([seed, sensor, k])``.
    laser_beams, laser_fov, laser_max_range, laser_sigma :
        The planar laser of :func:`city_laser_scan` at the same poses and height: beams over the
        field of view (radians, centred on the heading), its maximum range (metres; no return
        reads exactly this) and range noise (metres, std).
    """

    plan: CityPlan = CityPlan()
    lidar: LidarModel = CITY_LIDAR
    spacing: float = 5.0
    height: float = 1.8
    speed: float = 10.0
    noise_std: float = 0.02
    dropout: float = 0.0
    seed: int = 0
    laser_beams: int = 720
    laser_fov: float = 2.0 * math.pi
    laser_max_range: float = 60.0
    laser_sigma: float = 0.01

    def __post_init__(self):
        if not isinstance(self.plan, CityPlan):
            raise InvalidArgumentError(f"plan must be a CityPlan, got {type(self.plan).__name__}")
        if not isinstance(self.lidar, LidarModel):
            raise InvalidArgumentError(f"lidar must be a LidarModel, got {type(self.lidar).__name__}")
        for name in ("spacing", "height", "speed", "laser_max_range"):
            object.__setattr__(self, name, checks.positive(name, getattr(self, name)))
        for name in ("noise_std", "laser_sigma"):
            object.__setattr__(self, name, checks.non_negative(name, getattr(self, name), "metres"))
        object.__setattr__(self, "dropout", checks.fraction("dropout", self.dropout))
        object.__setattr__(self, "seed", checks.count("seed", self.seed, 0))
        _beam_angles(self.laser_beams, self.laser_fov)  # checks both

    @property
    def city(self) -> City:
        """The town of :attr:`plan` (built once per process and plan)."""
        return City.of(self.plan)

    @property
    def n_scans(self) -> int:
        return int(math.floor(self.plan.route_length / self.spacing)) + 1

    def poses2d(self) -> np.ndarray:
        """The planar sensor poses ``(x, y, theta)`` of all scans, (n_scans, 3)."""
        return _poses2d(self)

    def pose(self, k: int) -> SE3:
        """``T_world_sensor`` of scan ``k``."""
        return SE3(level_poses(self.poses2d()[self._index(k)], self.height)[0])

    def stamp(self, k: int) -> float:
        return self._index(k) * self.spacing / self.speed

    def _index(self, k) -> int:
        k = checks.count("k", k, 0)
        if k >= self.n_scans:
            raise InvalidArgumentError(f"scan {k} is past the drive's end ({self.n_scans} scans)")
        return k

    def _rng(self, sensor: int, k: int) -> np.random.Generator:
        return np.random.default_rng([self.seed, sensor, k])


@lru_cache(maxsize=8)
def _poses2d(drive: CityDrive) -> np.ndarray:
    # computed whole and cached, so that pose k has the same bits however it is asked for
    p = drive.city.route_poses(np.arange(drive.n_scans) * drive.spacing)
    p.flags.writeable = False
    return p


def city_scan(k: int, drive: CityDrive | None = None) -> PointCloud:
    """Scan ``k`` of the drive's 3D LiDAR (default drive: ``CityDrive()``): points in the sensor
    frame, the pose, the stamp; the same bits as the ``k``-th cloud of :func:`city_drive`."""
    drive = CityDrive() if drive is None else drive
    return simulate_lidar(drive.city.world, drive.pose(k), drive.lidar, rng=drive._rng(0, k),
                          noise_std=drive.noise_std, dropout=drive.dropout, stamp=drive.stamp(k))


def city_drive(drive: CityDrive | None = None, start: int = 0, stop: int | None = None
               ) -> Iterator[PointCloud]:
    """The drive's 3D scans ``start .. stop − 1`` (default: all), made one at a time as the
    iterator is advanced (the arguments are checked at once)."""
    drive = CityDrive() if drive is None else drive
    return (city_scan(k, drive) for k in _scan_range(drive, start, stop))


def city_laser_scan(k: int, drive: CityDrive | None = None) -> LaserScan:
    """Scan ``k`` of the drive's planar laser: the horizontal section of the town at the sensor's
    height (walls, tree trunks, poles, tall vehicles), with the conventions of
    :func:`occmap.sim.world2d.simulate_scans` (noise clipped to ``[0, max_range]``, no return
    reads ``max_range``). The same bits as the ``k``-th scan of :func:`city_laser_drive`."""
    drive = CityDrive() if drive is None else drive
    pose = drive.poses2d()[drive._index(k)]
    rel = _beam_angles(drive.laser_beams, drive.laser_fov)
    a = pose[2] + rel
    dirs = np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], axis=1)
    origin = np.array([pose[0], pose[1], drive.height])
    true = drive.city.world.cast(origin, dirs, drive.laser_max_range)
    ranges = _corrupt(true, drive.laser_max_range, drive.laser_sigma, 0.0, 0.0, drive._rng(1, k))
    return LaserScan(pose=pose.copy(), ranges=ranges, angles=rel, max_range=drive.laser_max_range,
                     stamp=drive.stamp(k))


def city_laser_drive(drive: CityDrive | None = None, start: int = 0, stop: int | None = None
                     ) -> Iterator[LaserScan]:
    """The drive's planar scans ``start .. stop − 1`` (default: all), made one at a time."""
    drive = CityDrive() if drive is None else drive
    return (city_laser_scan(k, drive) for k in _scan_range(drive, start, stop))


def _scan_range(drive, start, stop):
    n = drive.n_scans
    start = checks.count("start", start, 0)
    stop = n if stop is None else checks.count("stop", stop, 0)
    if stop > n:
        raise InvalidArgumentError(f"stop {stop} is past the drive's end ({n} scans)")
    return range(start, stop)


# ------------------------------------------------------------------ the town


@dataclass(eq=False)
class City:
    """A generated town (see the module's notes); make one with :meth:`of`.

    Attributes
    ----------
    plan : CityPlan
    world : World3D
        The solids and the ground (z = 0); its ``waypoints`` are the route.
    streets_x, streets_y : ndarray (n, 2)
        The streets running north–south (at x) and east–west (at y): centre line and width.
    blocks : ndarray (B, 4)
        ``[xmin, ymin, xmax, ymax]`` of each block between the building lines.
    block_kinds : ndarray (B,) of str
        ``"buildings"``, ``"park"`` or ``"square"``.
    route : ndarray (P, 2)
        The drive's polyline on the road centre lines, ``route_length`` long.
    blocks_passed : ndarray (B,) bool
        The blocks the route drives along at least one side of.
    """

    plan: CityPlan
    world: World3D
    streets_x: np.ndarray
    streets_y: np.ndarray
    blocks: np.ndarray
    block_kinds: np.ndarray
    route: np.ndarray
    blocks_passed: np.ndarray = field(repr=False)

    @staticmethod
    def of(plan: CityPlan | None = None) -> City:
        """The town of ``plan`` (default ``CityPlan()``), built once per process and plan."""
        return _build(CityPlan() if plan is None else plan)

    @property
    def bounds(self) -> tuple:
        """``(xmin, ymin, xmax, ymax)`` of the town."""
        (cx, cy), (sx, sy) = self.plan.centre, self.plan.size
        return (cx - sx / 2.0, cy - sy / 2.0, cx + sx / 2.0, cy + sy / 2.0)

    @cached_property
    def _route_lengths(self):
        return _arc_lengths(self.route)

    @property
    def route_length(self) -> float:
        return float(self._route_lengths[1][-1])

    def route_poses(self, s) -> np.ndarray:
        """Planar poses ``(x, y, theta)`` (N, 3) at arc lengths ``s`` (N,) along the route (clipped
        to its ends), heading along the route."""
        p, lengths = self._route_lengths
        return _poses_along(p, lengths, np.asarray(s, dtype=np.float64).reshape(-1), _HEADING_CHORD)

    def occupied(self, points) -> np.ndarray:
        """The truth: whether each point (..., 3) lies in or on a solid or the ground."""
        return self.world.occupied(points)

    def occupied_2d(self, points, height: float = 1.8) -> np.ndarray:
        """The truth of the planar view: whether each point (..., 2) lies in or on a solid's
        section at ``height`` above the ground."""
        p = np.asarray(points, dtype=np.float64)
        return self.world.occupied(np.concatenate([p, np.full(p.shape[:-1] + (1,), float(height))],
                                                  axis=-1))

    def render_png(self, path, resolution: float = 1.0):
        """Write a labelled plan of the town seen from above (:func:`occmap.viz.maps.heights_figure`):
        the height of the top surface (colour bar in metres, the ground at its low end), the route
        in red from its start in green. ``resolution`` metres per pixel. Returns the path."""
        from ..viz import figure, maps

        res = checks.resolution(resolution)
        xmin, ymin, xmax, ymax = self.bounds
        xs = np.arange(xmin + res / 2.0, xmax, res)
        ys = np.arange(ymin + res / 2.0, ymax, res)
        X, Y = np.meshgrid(xs, ys)
        top = self.world.bounds[5] + 1.0
        origins = np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, top)])
        down = np.broadcast_to((0.0, 0.0, -1.0), origins.shape)
        height = top - self.world.cast(origins, down).reshape(X.shape)
        route = self.route_poses(np.arange(0.0, self.route_length, res / 2.0))
        tracks = [("route", route, dict(color="#d62728", lw=1.2)),
                  ("start", route[:1], dict(ls="none", marker="o", color="#2ca02c", ms=7))]
        fig = maps.heights_figure(height, np.isfinite(height), (xmin, ymin), res,
                                  f"simulated town from above\n{res:g} m pixels", "height of the top surface [m]",
                                  tracks, cmap="gray_r")
        return figure.save(fig, path)


@lru_cache(maxsize=4)
def _build(plan: CityPlan) -> City:
    rng = np.random.default_rng(plan.seed)
    (cx, cy), (sx, sy) = plan.centre, plan.size
    streets_x = _streets(rng, cx - sx / 2.0, sx, plan)
    streets_y = _streets(rng, cy - sy / 2.0, sy, plan)
    parts = _Parts()
    blocks, kinds = [], []
    for j in range(len(streets_y) - 1):
        for i in range(len(streets_x) - 1):
            rect = (streets_x[i, 0] + streets_x[i, 1] / 2.0, streets_y[j, 0] + streets_y[j, 1] / 2.0,
                    streets_x[i + 1, 0] - streets_x[i + 1, 1] / 2.0,
                    streets_y[j + 1, 0] - streets_y[j + 1, 1] / 2.0)
            u = rng.random()
            kind = ("park" if u < plan.park_share else
                    "square" if u < plan.park_share + plan.square_share else "buildings")
            _BLOCK_MAKERS[kind](rng, rect, parts)
            for side in range(4):
                _kerb_side(rng, rect, side, plan, parts)
            blocks.append(rect)
            kinds.append(kind)
    blocks = np.array(blocks, dtype=np.float64)
    route, passed = _route(rng, streets_x[:, 0], streets_y[:, 0], plan)
    boxes, cylinders = parts.arrays()
    top = max(boxes[:, 5].max(initial=0.0), cylinders[:, 4].max(initial=0.0))
    world = World3D(boxes, cylinders, ground_z=0.0,
                    bounds=(cx - sx / 2.0, cy - sy / 2.0, -1.0, cx + sx / 2.0, cy + sy / 2.0, top),
                    waypoints=route)
    return City(plan, world, streets_x, streets_y, blocks, np.array(kinds), route, passed)


def _streets(rng, lo, length, plan):
    """Streets across one axis (n, 2): centre and width; avenues at both edges and every
    ``avenue_every``-th; blocks drawn from ``plan.block`` and stretched to fill ``length``."""
    b_lo, b_hi = plan.block
    n_blocks = max(1, int(round(length / (0.5 * (b_lo + b_hi) + plan.street_width))))
    while True:
        widths = np.array([plan.avenue_width if (i % plan.avenue_every == 0 or i == n_blocks)
                           else plan.street_width for i in range(n_blocks + 1)])
        room = length - widths.sum()
        if room >= n_blocks * b_lo or n_blocks == 1:
            break
        n_blocks -= 1
    sizes = rng.uniform(b_lo, b_hi, n_blocks)
    sizes *= room / sizes.sum()
    edges = lo + np.concatenate([[0.0], np.cumsum(np.ravel(np.column_stack(
        [widths[:-1], sizes])))])
    return np.column_stack([edges[0::2] + widths / 2.0, widths])


class _Parts:
    """The solids as they are made: lists of box and cylinder rows."""

    def __init__(self):
        self.boxes = []
        self.cylinders = []

    def arrays(self):
        return (np.array(self.boxes, dtype=np.float64).reshape(-1, 6),
                np.array(self.cylinders, dtype=np.float64).reshape(-1, 5))


def _buildings(rng, rect, parts):
    """Lots cut from the block (split across their longer side until at most 45 m), each a
    building set back from its neighbours, or (one in twelve) left empty."""
    lots = [rect]
    out = []
    while lots:
        x0, y0, x1, y1 = lots.pop()
        w, h = x1 - x0, y1 - y0
        if max(w, h) <= 45.0:
            out.append((x0, y0, x1, y1))
        elif w >= h:
            xs = x0 + w * rng.uniform(0.35, 0.65)
            lots += [(x0, y0, xs, y1), (xs, y0, x1, y1)]
        else:
            ys = y0 + h * rng.uniform(0.35, 0.65)
            lots += [(x0, y0, x1, ys), (x0, ys, x1, y1)]
    for lot in out:
        if rng.random() < 1.0 / 12.0:
            continue
        # per side (south, east, north, west): on the block's edge (facing a street), and how
        # far the building stands back from the lot's edge
        on_street = [lot[1] == rect[1], lot[2] == rect[2], lot[3] == rect[3], lot[0] == rect[0]]
        inset = [rng.uniform(0.0, 1.5) if s and rng.random() < 0.4 else
                 (0.0 if s else rng.uniform(0.5, 3.0)) for s in on_street]
        x0, y0 = lot[0] + inset[3], lot[1] + inset[0]
        x1, y1 = lot[2] - inset[1], lot[3] - inset[2]
        if x1 - x0 < 4.0 or y1 - y0 < 4.0:
            continue
        area = (x1 - x0) * (y1 - y0)
        height = rng.uniform(6.0, 24.0)
        if area > 300.0 and rng.random() < 0.05:  # a tower on a podium
            podium = rng.uniform(8.0, 14.0)
            parts.boxes.append((x0, y0, 0.0, x1, y1, podium))
            t = min(rng.uniform(3.0, 6.0), (x1 - x0) / 4.0, (y1 - y0) / 4.0)
            parts.boxes.append((x0 + t, y0 + t, podium, x1 - t, y1 - t, rng.uniform(40.0, 120.0)))
        else:
            parts.boxes.append((x0, y0, 0.0, x1, y1, height))
            if rng.random() < 0.2 and x1 - x0 > 8.0 and y1 - y0 > 8.0:  # an upper storey set back
                parts.boxes.append((x0 + 2.0, y0 + 2.0, height, x1 - 2.0, y1 - 2.0,
                                    height + rng.uniform(3.0, 4.0)))
        for side, s in enumerate(on_street):  # awnings over the sidewalk, 2.6–2.8 m up
            if s and inset[side] == 0.0 and rng.random() < 0.1:
                u0, u1 = (x0, x1) if side in (0, 2) else (y0, y1)
                if u1 - u0 > 4.0:
                    parts.boxes.append(_side_box(rect, side, u0 + 1.0, u1 - 1.0, 0.0, 1.5, 2.6, 2.8))


def _park(rng, rect, parts):
    """Trees scattered over the block (about one per 150 m²), 2 m in from its edges."""
    x0, y0, x1, y1 = rect
    n = int(round((x1 - x0) * (y1 - y0) / 150.0))
    xs = rng.uniform(x0 + 2.0, x1 - 2.0, n)
    ys = rng.uniform(y0 + 2.0, y1 - 2.0, n)
    for x, y in zip(xs, ys):
        parts.cylinders += _random_tree(rng, x, y)


def _square(rng, rect, parts):
    """An open square: a fountain basin in the middle, a statue on a plinth, lamps on a 20 m grid."""
    x0, y0, x1, y1 = rect
    mx, my = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    parts.cylinders.append((mx, my, rng.uniform(2.0, 4.0), 0.0, 0.8))
    sx = mx + rng.uniform(-0.25, 0.25) * (x1 - x0)
    sy = my + 0.3 * (y1 - y0)
    parts.boxes.append((sx - 1.0, sy - 1.0, 0.0, sx + 1.0, sy + 1.0, 1.5))
    parts.cylinders.append((sx, sy, 0.4, 1.5, rng.uniform(3.5, 5.0)))
    for x in np.arange(x0 + 10.0, x1 - 5.0, 20.0):
        for y in np.arange(y0 + 10.0, y1 - 5.0, 20.0):
            if math.hypot(x - mx, y - my) > 6.0:
                parts.cylinders.append((x, y, 0.1, 0.0, 5.0))


_BLOCK_MAKERS = {"buildings": _buildings, "park": _park, "square": _square}


def _random_tree(rng, x, y):
    trunk_top = rng.uniform(2.5, 3.5)
    return _tree(x, y, trunk_r=rng.uniform(0.15, 0.3), crown_r=rng.uniform(1.2, 3.0),
                 trunk_top=trunk_top, top=trunk_top + rng.uniform(3.0, 6.0))


def _side_box(rect, side, u0, u1, v0, v1, z0, z1):
    """A box given in the frame of one side of a block: ``u`` along the side (world x for the south
    (0) and north (2) sides, y for the west (3) and east (1) sides), ``v`` outwards from the
    building line towards the street."""
    x0, y0, x1, y1 = rect
    if side == 0:
        return (u0, y0 - v1, z0, u1, y0 - v0, z1)
    if side == 2:
        return (u0, y1 + v0, z0, u1, y1 + v1, z1)
    if side == 3:
        return (x0 - v1, u0, z0, x0 - v0, u1, z1)
    return (x1 + v0, u0, z0, x1 + v1, u1, z1)


def _side_point(rect, side, u, v):
    x0, y0, x1, y1 = rect
    return ((u, y0 - v), (x1 + v, u), (u, y1 + v), (x0 - v, u))[side]


# vehicles in the frame of a kerb: u along it from the vehicle's rear, v from the kerb outwards;
# rows (u0, v0, z0, u1, v1, z1), and the length
_VEHICLES = (
    (_car(0.0, 0.2), 4.5),
    ([(0.0, 0.2, 0.3, 5.5, 2.2, 2.3)], 5.5),  # a van
    ([(0.0, 0.2, 0.4, 2.2, 2.6, 3.0), (2.4, 0.2, 0.5, 8.0, 2.6, 3.6)], 8.0),  # a truck: cab, box
)
_VEHICLE_ODDS = (0.75, 0.18, 0.07)


def _kerb_side(rng, rect, side, plan, parts):
    """The sidewalk and parking lane along one side of a block: lamps 0.5 m from the kerb every
    25–35 m, trees 1.3 m from it every 8–20 m (two in three places), vehicles parked along the
    kerb (a little over half the places), none within 6 m of the crossings."""
    u_lo, u_hi = (rect[0], rect[2]) if side in (0, 2) else (rect[1], rect[3])
    kerb = plan.sidewalk
    for u in np.arange(u_lo + rng.uniform(3.0, 10.0), u_hi - 2.0, rng.uniform(25.0, 35.0)):
        x, y = _side_point(rect, side, u, kerb - 0.5)
        parts.cylinders.append((x, y, 0.12, 0.0, 7.0))
    u = u_lo + rng.uniform(2.0, 8.0)
    while u < u_hi - 2.0:
        if rng.random() < 2.0 / 3.0:
            x, y = _side_point(rect, side, u, kerb - 1.3)
            parts.cylinders += _random_tree(rng, x, y)
        u += rng.uniform(8.0, 20.0)
    u = u_lo - kerb + 6.0  # the crossing's edge is at the kerb of the street across
    end = u_hi + kerb - 6.0
    while True:
        shape, length = _VEHICLES[int(rng.choice(3, p=_VEHICLE_ODDS))]
        if u + length > end:
            break
        if rng.random() < 0.55:
            for u0, v0, z0, u1, v1, z1 in shape:
                parts.boxes.append(_side_box(rect, side, u + u0, u + u1, kerb + v0, kerb + v1, z0, z1))
            u += length + rng.uniform(0.8, 3.0)
        else:
            u += rng.uniform(3.0, 8.0)


# ------------------------------------------------------------------ the route

_STEPS = ((1, 0), (0, 1), (-1, 0), (0, -1))  # east, north, west, south


def _route(rng, xs, ys, plan):
    """The drive's polyline (P, 2), ``plan.route_length`` long, and which blocks it passes.

    A walk on the crossings (i, j) at (xs[i], ys[j]) from the south-west corner; at each crossing
    it takes, among the streets ahead, left and right, one not yet driven that passes the most
    blocks not yet seen (ties at random), else the first move of a shortest walk (no turning back)
    to the nearest such street, else to the nearest street not yet driven, else the least driven
    street adjacent. Corners are then cut by arcs (:func:`_round_corners`)."""
    nx, ny = len(xs), len(ys)
    seen = np.zeros((ny - 1, nx - 1), dtype=bool)
    driven = {}

    def edge(i, j, d):
        di, dj = _STEPS[d]
        a, b = (i, j), (i + di, j + dj)
        return min(a, b), max(a, b)

    def blocks_of(e):
        (i, j), (k, m) = e
        cand = [(j, i), (j - 1, i)] if m == j else [(j, i), (j, i - 1)]
        return [(bj, bi) for bj, bi in cand if 0 <= bj < ny - 1 and 0 <= bi < nx - 1]

    def moves(i, j, heading):
        out = []
        for d in range(4):
            if heading is not None and d == (heading + 2) % 4:
                continue
            di, dj = _STEPS[d]
            if 0 <= i + di < nx and 0 <= j + dj < ny:
                out.append(d)
        return out or [(heading + 2) % 4]  # a dead end (a town one street wide)

    def useful(e):
        return e not in driven and any(not seen[b] for b in blocks_of(e))

    def nearest(i, j, heading, want):
        """First move of a shortest walk (no turning back) to an edge satisfying ``want``."""
        start = (i, j, heading)
        first = {start: None}
        queue = deque([start])
        while queue:
            ci, cj, ch = queue.popleft()
            for d in moves(ci, cj, ch):
                if want(edge(ci, cj, d)):
                    return d if first[(ci, cj, ch)] is None else first[(ci, cj, ch)]
                di, dj = _STEPS[d]
                nxt = (ci + di, cj + dj, d)
                if nxt not in first:
                    first[nxt] = d if first[(ci, cj, ch)] is None else first[(ci, cj, ch)]
                    queue.append(nxt)
        return None

    i, j, heading = 0, 0, 0
    nodes = [(i, j)]
    length = 0.0
    turns = 0
    # each corner cut by an arc shortens the walk by (2 − π/2)·r < r
    while length < plan.route_length + turns * plan.turn_radius:
        options = moves(i, j, heading)
        gain = [0 if edge(i, j, d) in driven else sum(not seen[b] for b in blocks_of(edge(i, j, d)))
                for d in options]
        if max(gain) > 0:
            best = [d for d, g in zip(options, gain) if g == max(gain)]
            d = best[int(rng.integers(len(best)))]
        else:
            d = nearest(i, j, heading, useful)
            if d is None:
                d = nearest(i, j, heading, lambda e: e not in driven)
            if d is None:
                least = min(driven[edge(i, j, o)] for o in options)
                d = [o for o in options if driven[edge(i, j, o)] == least][0]
        e = edge(i, j, d)
        driven[e] = driven.get(e, 0) + 1
        for b in blocks_of(e):
            seen[b] = True
        turns += d != heading
        di, dj = _STEPS[d]
        length += abs(xs[i + di] - xs[i]) + abs(ys[j + dj] - ys[j])
        i, j, heading = i + di, j + dj, d
        nodes.append((i, j))
    corners = np.array([(xs[a], ys[b]) for a, b in nodes])
    path = _round_corners(corners, plan.turn_radius)
    p, s = _arc_lengths(path)
    end = int(np.searchsorted(s, plan.route_length))
    t = (plan.route_length - s[end - 1]) / (s[end] - s[end - 1])
    route = np.vstack([p[:end], p[end - 1] + t * (p[end] - p[end - 1])])
    return route, seen.reshape(-1)


def _round_corners(corners, radius, step=math.radians(5.0)):
    """The polyline through ``corners`` with each turn replaced by a circular arc of ``radius``
    tangent to both legs (points every ``step`` radians); straight-through and reversing corners
    are kept."""
    out = [corners[0]]
    for a, b, c in zip(corners[:-2], corners[1:-1], corners[2:]):
        u = (b - a) / np.linalg.norm(b - a)
        w = (c - b) / np.linalg.norm(c - b)
        cross = u[0] * w[1] - u[1] * w[0]
        if abs(cross) < 1e-9:
            out.append(b)
            continue
        turn = math.copysign(math.acos(max(-1.0, min(1.0, float(u @ w)))), cross)
        r = min(radius, 0.5 * np.linalg.norm(b - a), 0.5 * np.linalg.norm(c - b))
        k = r * math.tan(abs(turn) / 2.0)  # from the corner to the arc's ends
        p0 = b - k * u
        normal = np.array([-u[1], u[0]]) * math.copysign(1.0, cross)
        centre = p0 + r * normal
        n = max(2, int(math.ceil(abs(turn) / step)))
        phi0 = math.atan2(p0[1] - centre[1], p0[0] - centre[0])
        phis = phi0 + np.linspace(0.0, turn, n + 1)
        out.extend(np.column_stack([centre[0] + r * np.cos(phis), centre[1] + r * np.sin(phis)]))
    out.append(corners[-1])
    return np.array(out)
