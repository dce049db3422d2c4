"""A synthetic planar world with known truth, and simulated range sensors that look at it.

The world is a set of wall segments (infinitely thin lines) and solid discs (pillars, bins) inside
rectangular bounds. Rays are cast exactly against them (:meth:`World2D.cast`), the simulated lidar
and sonar add the usual imperfections, and :meth:`World2D.occupancy` / :meth:`World2D.free_space`
rasterise the truth on the grid convention of the whole package: cell ``(row, col) = (iy, ix)``,
``origin`` is the world position of the outer corner of cell (0, 0), and cell (iy, ix) spans
``[ox + ix·res, ox + (ix+1)·res] × [oy + iy·res, oy + (iy+1)·res]``.

>>> world = World2D.default()
>>> path = world.default_trajectory(n=400)
>>> scan = simulate_lidar(world, path[0], rng=np.random.default_rng(0))
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .. import checks
from ..errors import InvalidArgumentError, NonFiniteError, ShapeError
from ..raster.walk2d import cell_of
from ..scan import LaserScan
from . import _kernels

__all__ = [
    "World2D",
    "default_path",
    "simulate_lidar",
    "simulate_scans",
    "simulate_sonar",
]


def _as_rows(name, a, width):
    arr = np.ascontiguousarray(a, dtype=np.float64)
    if arr.size == 0:
        arr = arr.reshape(0, width)
    if arr.ndim != 2 or arr.shape[1] != width:
        raise ShapeError(f"{name} must have shape (n, {width}), got {np.shape(a)}")
    if not np.all(np.isfinite(arr)):
        raise NonFiniteError(f"{name} holds NaN or infinity")
    return arr


# ------------------------------------------------------------------ the default office world

_W, _H = 20.0, 15.0
_CORRIDOR = (6.5, 8.5)  # y of the corridor's lower and upper walls
_DOOR = 0.9
# doors: x centre of each gap in the lower and the upper corridor wall
_DOORS_LOW = (3.0, 9.5, 17.0)
_DOORS_HIGH = (3.5, 10.5, 17.0)


def _wall_with_gaps(y, centres, width=_DOOR, x0=0.0, x1=_W):
    segs = []
    x = x0
    for c in sorted(centres):
        segs.append((x, y, c - width / 2, y))
        x = c + width / 2
    segs.append((x, y, x1, y))
    return segs


def _default_segments():
    segs = [
        (0.0, 0.0, _W, 0.0),  # outer walls, closed
        (_W, 0.0, _W, _H),
        (_W, _H, 0.0, _H),
        (0.0, _H, 0.0, 0.0),
    ]
    segs += _wall_with_gaps(_CORRIDOR[0], _DOORS_LOW)
    segs += _wall_with_gaps(_CORRIDOR[1], _DOORS_HIGH)
    # partitions between the rooms below and above the corridor
    segs += [(6.0, 0.0, 6.0, _CORRIDOR[0]), (13.0, 0.0, 13.0, _CORRIDOR[0])]
    segs += [(7.0, _CORRIDOR[1], 7.0, _H), (14.0, _CORRIDOR[1], 14.0, _H)]
    # a short free-standing wall (a shelf) in the lower right room, and a cupboard corner
    segs += [(19.0, 3.0, 19.0, 5.0)]
    segs += [(0.0, 10.5, 0.8, 10.5), (0.8, 10.5, 0.8, 9.6)]
    return np.array(segs, dtype=np.float64)


_DEFAULT_CIRCLES = np.array(
    [
        (3.0, 3.0, 0.30),  # pillar, room A (lower left)
        (10.0, 2.5, 0.40),  # pillar, room B (lower middle)
        (17.0, 3.0, 0.25),  # bin, room C (lower right)
        (4.5, 12.0, 0.25),  # bin, room D (upper left)
        (10.5, 12.2, 0.30),  # pillar, room E (upper middle)
        (17.0, 12.0, 0.35),  # pillar, room F (upper right)
    ],
    dtype=np.float64,
)


def _room_loop(door_x, sign, x_lo, x_hi, y_near, y_far):
    """Waypoints from the corridor's centre line through a door into a room, round it, and back."""
    yc = 7.5
    yd = yc + sign * 2.0  # one metre past the door
    return [
        (door_x, yc),
        (door_x, yd),
        (x_lo, y_near),
        (x_lo, y_far),
        (x_hi, y_far),
        (x_hi, y_near),
        (door_x, yd),
        (door_x, yc),
    ]


_DEFAULT_WAYPOINTS = (
    [(1.0, 7.5)]
    + _room_loop(3.0, -1, 1.5, 4.5, 4.5, 1.5)
    + _room_loop(9.5, -1, 7.5, 11.5, 4.5, 1.3)
    + _room_loop(10.5, +1, 8.5, 12.5, 11.0, 13.6)
    + _room_loop(17.0, -1, 15.0, 18.0, 4.5, 1.5)
    + _room_loop(17.0, +1, 15.5, 18.5, 11.0, 13.6)
    + _room_loop(3.5, +1, 2.2, 5.8, 11.0, 13.6)
)


def _chaikin(points, iterations):
    """Corner cutting: each pass replaces every corner by two points at 1/4 and 3/4 of its legs.
    The curve stays inside the convex hull of each corner, and straight stretches stay straight."""
    p = _drop_duplicates(np.asarray(points, dtype=np.float64))
    for _ in range(iterations):
        a, b = p[:-1], p[1:]
        q = np.empty((2 * len(a), 2))
        q[0::2] = 0.75 * a + 0.25 * b
        q[1::2] = 0.25 * a + 0.75 * b
        p = np.vstack([p[:1], q, p[-1:]])
    return p


def _drop_duplicates(p):
    keep = np.ones(len(p), dtype=bool)
    keep[1:] = np.any(np.diff(p, axis=0) != 0.0, axis=1)
    return p[keep]


def _resample_path(points, n):
    """``n`` poses evenly spaced by arc length along the polyline, heading along the path."""
    p, s = _arc_lengths(points)
    # heading from the chord between points half a step ahead and behind (one-sided at the ends)
    return _poses_along(p, s, np.linspace(0.0, s[-1], n), 0.5 * s[-1] / (n - 1))


def _arc_lengths(points):
    """The polyline without repeated points, and the arc length at each of its points."""
    p = _drop_duplicates(np.asarray(points, dtype=np.float64))
    seg = np.hypot(*np.diff(p, axis=0).T)
    return p, np.concatenate([[0.0], np.cumsum(seg)])


def _poses_along(p, s, t, h):
    """Poses ``(len(t), 3)`` at arc lengths ``t`` along the polyline ``p`` (arc lengths ``s``),
    heading along the chord from ``t − h`` to ``t + h`` (clipped to the ends)."""
    x = np.interp(t, s, p[:, 0])
    y = np.interp(t, s, p[:, 1])
    ta = np.clip(t + h, 0.0, s[-1])
    tb = np.clip(t - h, 0.0, s[-1])
    dx = np.interp(ta, s, p[:, 0]) - np.interp(tb, s, p[:, 0])
    dy = np.interp(ta, s, p[:, 1]) - np.interp(tb, s, p[:, 1])
    theta = np.arctan2(dy, dx)
    return np.stack([x, y, theta], axis=1)


@dataclass(eq=False)
class World2D:
    """A planar world of wall segments and solid discs.

    Parameters
    ----------
    segments : array_like (M, 4)
        Walls ``[x0, y0, x1, y1]``, infinitely thin lines, metres.
    circles : array_like (K, 3)
        Solid discs ``[cx, cy, r]``, metres (r > 0).
    bounds : (xmin, ymin, xmax, ymax)
        The extent of the world; the default raster covers it.
    waypoints : array_like (P, 2) or None
        Optional corner points of a collision-free path; :meth:`default_trajectory` smooths them.
    """

    segments: np.ndarray
    circles: np.ndarray
    bounds: tuple
    waypoints: np.ndarray | None = field(default=None)

    def __post_init__(self):
        self.segments = _as_rows("segments", self.segments, 4)
        self.circles = _as_rows("circles", self.circles, 3)
        if np.any(self.circles[:, 2] <= 0.0):
            raise InvalidArgumentError("circle radii must be positive")
        b = np.asarray(self.bounds, dtype=np.float64)
        if b.shape != (4,):
            raise ShapeError(f"bounds must be (xmin, ymin, xmax, ymax), got shape {b.shape}")
        if not np.all(np.isfinite(b)) or not (b[0] < b[2] and b[1] < b[3]):
            raise InvalidArgumentError(f"bounds must be finite with xmin < xmax, ymin < ymax: {b}")
        self.bounds = tuple(float(v) for v in b)
        if self.waypoints is not None:
            self.waypoints = _as_rows("waypoints", self.waypoints, 2)

    # ------------------------------------------------------------------ construction

    @classmethod
    def default(cls) -> World2D:
        """An office of 20 m × 15 m: a 2 m corridor along y ∈ [6.5, 8.5] with three rooms below
        and three above, each entered through a 0.9 m door; pillars and bins in the rooms, a
        free-standing shelf and a cupboard corner; the outer walls closed."""
        return cls(_default_segments(), _DEFAULT_CIRCLES.copy(), (0.0, 0.0, _W, _H),
                   waypoints=np.array(_DEFAULT_WAYPOINTS, dtype=np.float64))

    def default_trajectory(self, n: int = 1000, smoothing: int = 5) -> np.ndarray:
        """Poses ``(n, 3)`` along the world's waypoints, corners cut by ``smoothing`` Chaikin
        passes and resampled evenly by arc length, heading along the path. For the default world
        the path starts in the corridor's west end and loops through all six rooms, staying at
        least 0.2 m (in fact about 0.45 m, at the door jambs) from every wall and obstacle."""
        if self.waypoints is None or len(self.waypoints) < 2:
            raise InvalidArgumentError("this world has no waypoints to build a trajectory from")
        n = checks.count("n", n, 2)
        return _resample_path(_chaikin(self.waypoints, smoothing), n)

    # ------------------------------------------------------------------ ray casting

    def cast(self, origins, angles, max_range: float = np.inf) -> np.ndarray:
        """Exact range from each origin along each world angle to the first wall or disc.

        Parameters
        ----------
        origins : array_like (N, 2) or (2,)
            Ray origins, broadcast against ``angles``.
        angles : array_like (N,)
            Ray directions in the world frame, radians, counter-clockwise from +x.
        max_range : float
            Hits farther than this are ignored.

        Returns
        -------
        ranges : ndarray (N,)
            Distance to the first hit, ``inf`` when nothing lies within ``max_range``. A ray that
            starts inside or on a disc, or on a wall, returns 0. A ray running exactly along a wall
            hits the wall's nearest end.
        """
        angles = np.ascontiguousarray(angles, dtype=np.float64).reshape(-1)
        o = np.asarray(origins, dtype=np.float64)
        if o.shape == (2,):
            o = np.broadcast_to(o, (angles.shape[0], 2))
        if o.ndim != 2 or o.shape[1] != 2 or o.shape[0] != angles.shape[0]:
            raise ShapeError(f"origins must be (N, 2) matching angles ({angles.shape[0]},), got {o.shape}")
        o = np.ascontiguousarray(o)
        if not (np.all(np.isfinite(o)) and np.all(np.isfinite(angles))):
            raise NonFiniteError("ray origins and angles must be finite")
        if not max_range > 0.0:
            raise InvalidArgumentError(f"max_range must be positive, got {max_range}")
        out = np.empty(angles.shape[0])
        f = _kernels.cast_rays_parallel if angles.shape[0] >= _kernels.PARALLEL_MIN else _kernels.cast_rays
        f(o, angles, self.segments, self.circles, float(max_range), out)
        return out

    # ------------------------------------------------------------------ ground truth

    def _grid(self, resolution, origin, shape):
        resolution = checks.resolution(resolution)
        xmin, ymin, xmax, ymax = self.bounds
        if origin is None:
            origin = (xmin, ymin)
        ox, oy = (float(v) for v in origin)
        if shape is None:
            shape = (int(math.ceil((ymax - oy) / resolution - 1e-9)),
                     int(math.ceil((xmax - ox) / resolution - 1e-9)))
        H, W = (int(v) for v in shape)
        if H <= 0 or W <= 0:
            raise InvalidArgumentError(f"the grid is empty: shape {(H, W)}")
        return float(resolution), np.array([ox, oy]), (H, W)

    def occupancy(self, resolution: float, origin=None, shape=None):
        """The true occupancy raster.

        A cell is occupied iff its closed square meets a wall segment (exact segment–box test; a
        wall lying exactly on a grid line therefore marks the cells on both sides) or overlaps a
        disc. ``origin`` defaults to ``(xmin, ymin)`` of the bounds and ``shape`` ``(H, W)`` to the
        cells needed to cover the bounds from it.

        Returns
        -------
        occupied : ndarray (H, W) bool
        origin : ndarray (2,)
        """
        res, org, (H, W) = self._grid(resolution, origin, shape)
        out = np.zeros((H, W), dtype=np.bool_)
        _kernels.rasterize(self.segments, self.circles, org[0], org[1], res, out)
        return out, org

    def cell_centres(self, resolution: float, origin, shape):
        """World coordinates ``(H, W, 2)`` of the cell centres."""
        H, W = shape
        x = origin[0] + (np.arange(W) + 0.5) * resolution
        y = origin[1] + (np.arange(H) + 0.5) * resolution
        X, Y = np.meshgrid(x, y)
        return np.stack([X, Y], axis=-1)

    def free_space(self, resolution: float, origin=None, shape=None, start=None):
        """Cells a mapping run could observe as free: centre inside the bounds, not occupied, and
        4-connected through such cells to the cell of ``start`` (x, y) — by default the first pose
        of :meth:`default_trajectory`.

        Returns
        -------
        free : ndarray (H, W) bool
        origin : ndarray (2,)
        """
        occ, org = self.occupancy(resolution, origin, shape)
        H, W = occ.shape
        res = float(resolution)
        c = self.cell_centres(res, org, (H, W))
        xmin, ymin, xmax, ymax = self.bounds
        inside = (c[..., 0] >= xmin) & (c[..., 0] <= xmax) & (c[..., 1] >= ymin) & (c[..., 1] <= ymax)
        passable = inside & ~occ
        if start is None:
            start = self.default_trajectory(n=2)[0, :2]
        sx, sy = cell_of(float(start[0]), float(start[1]), org[0], org[1], 1.0 / res)
        out = np.zeros((H, W), dtype=np.bool_)
        if 0 <= sx < W and 0 <= sy < H:
            _kernels.flood_fill(passable, sy, sx, out)
        return out, org

    def clearance(self, points) -> np.ndarray:
        """Distance ``(N,)`` from each point ``(N, 2)`` to the nearest wall or disc surface
        (negative inside a disc)."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        d = np.full(p.shape[0], np.inf)
        for x0, y0, x1, y1 in self.segments:
            e = np.array([x1 - x0, y1 - y0])
            ee = e @ e
            w = p - (x0, y0)
            t = np.clip(w @ e / ee, 0.0, 1.0) if ee > 0 else np.zeros(len(p))
            d = np.minimum(d, np.hypot(*(w - t[:, None] * e).T))
        for cx, cy, r in self.circles:
            d = np.minimum(d, np.hypot(p[:, 0] - cx, p[:, 1] - cy) - r)
        return d

    # ------------------------------------------------------------------ picture

    def render_png(self, path, resolution: float = 0.05, poses=None, title: str = "simulated world (truth)"):
        """Write a labelled figure of the world (:func:`occmap.viz.maps.plan_figure`): walls and
        obstacles dark, the free space the robot can reach white, the rest light blue, and
        ``poses`` (N, 3) (default: the default trajectory, when there are waypoints) as a red
        line from a green start. Returns the path."""
        from ..viz import figure, maps

        occ, org = self.occupancy(resolution)
        free, _ = self.free_space(resolution) if self.waypoints is not None else (~occ, org)
        if poses is None and self.waypoints is not None:
            poses = self.default_trajectory(n=2000)
        tracks = []
        if poses is not None:
            poses = np.asarray(poses, dtype=np.float64)
            tracks = [("trajectory", poses, dict(color="#d62728", lw=1.2)),
                      ("start", poses[:1], dict(ls="none", marker="o", color="#2ca02c", ms=7))]
        plan = np.where(occ, 1, np.where(free, 0, -1))
        return figure.save(maps.plan_figure(plan, org, resolution, f"{title}\n{resolution:g} m cells", tracks), path)


def default_path(world: World2D, n: int = 1000) -> np.ndarray:
    """``world.default_trajectory(n)``: poses (n, 3) along the world's waypoints."""
    return world.default_trajectory(n=n)


# ------------------------------------------------------------------ simulated sensors


def _rng(rng):
    return rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)


def _beam_angles(n_beams, fov):
    """``n_beams`` angles across ``fov`` centred on the heading; a full circle has no duplicate
    beam at ±π."""
    n_beams = checks.count("n_beams", n_beams)
    fov = checks.positive("fov", fov, "radians")
    if not fov <= 2.0 * np.pi + 1e-12:
        raise InvalidArgumentError(f"fov must be in (0, 2π], got {fov}")
    if n_beams == 1:
        return np.zeros(1)
    if fov >= 2.0 * np.pi - 1e-12:
        return -np.pi + np.arange(n_beams) * (2.0 * np.pi / n_beams)
    return np.linspace(-fov / 2.0, fov / 2.0, n_beams)


def _corrupt(true, max_range, sigma, p_outlier, p_dropout, rng):
    """Noise, outliers and dropouts on true ranges (inf = nothing within max_range)."""
    r = np.array(true, dtype=np.float64)
    hit = np.isfinite(r)
    if sigma > 0.0:
        r[hit] += rng.normal(0.0, sigma, size=int(hit.sum()))
    r = np.clip(r, 0.0, max_range)  # inf -> max_range: the "no return" reading
    if p_outlier > 0.0:
        o = rng.random(r.shape) < p_outlier
        r[o] = rng.random(int(o.sum())) * np.minimum(true[o], max_range)
    if p_dropout > 0.0:
        r[rng.random(r.shape) < p_dropout] = np.nan
    return r


def _check_probs(sigma, p_outlier, p_dropout, max_range):
    checks.non_negative("sigma", sigma, "metres")
    checks.fraction("p_outlier", p_outlier)
    checks.fraction("p_dropout", p_dropout)
    checks.positive("max_range", max_range, "metres")


def simulate_scans(world: World2D, poses, n_beams: int = 360, fov: float = 2.0 * np.pi,
                   max_range: float = 10.0, sigma: float = 0.01, p_outlier: float = 0.0,
                   p_dropout: float = 0.0, rng=None, stamps=None) -> list[LaserScan]:
    """Lidar scans from many poses ``(N, 3)``, all rays cast in one kernel call.

    Each beam reads the true range plus Gaussian noise of std ``sigma`` (clipped to
    ``[0, max_range]``); a beam with nothing within ``max_range`` reads exactly ``max_range`` (no
    return). Then each reading independently, with probability ``p_outlier``, is replaced by a
    uniform random short reading in ``[0, true range)`` (true range = max_range for no-return
    beams), and with probability ``p_dropout`` becomes NaN (a sensor failure). ``rng`` is a
    ``numpy.random.Generator`` or a seed. ``stamps`` (N,) default to ``0, 1, 2, ...``.
    """
    poses = _as_rows("poses", poses, 3)
    _check_probs(sigma, p_outlier, p_dropout, max_range)
    rng = _rng(rng)
    rel = _beam_angles(n_beams, fov)
    N, n = poses.shape[0], rel.shape[0]
    angles = (poses[:, 2:3] + rel[None, :]).reshape(-1)
    origins = np.repeat(poses[:, :2], n, axis=0)
    true = world.cast(origins, angles, max_range)
    ranges = _corrupt(true, float(max_range), float(sigma), float(p_outlier), float(p_dropout), rng)
    ranges = ranges.reshape(N, n)
    if stamps is None:
        stamps = np.arange(N, dtype=np.float64)
    stamps = np.asarray(stamps, dtype=np.float64).reshape(-1)
    if stamps.shape[0] != N:
        raise ShapeError(f"stamps must have shape ({N},), got {stamps.shape}")
    return [LaserScan(pose=poses[i].copy(), ranges=ranges[i].copy(), angles=rel.copy(),
                      max_range=float(max_range), stamp=float(stamps[i])) for i in range(N)]


def simulate_lidar(world: World2D, pose, n_beams: int = 360, fov: float = 2.0 * np.pi,
                   max_range: float = 10.0, sigma: float = 0.01, p_outlier: float = 0.0,
                   p_dropout: float = 0.0, rng=None, stamp: float = 0.0) -> LaserScan:
    """One lidar scan from ``pose`` (3,); see :func:`simulate_scans` for the sensor model. Beam
    angles are relative to the heading: a full circle starts at −π with step 2π/n_beams, a
    narrower ``fov`` spans ``[−fov/2, fov/2]`` inclusive."""
    pose = np.asarray(pose, dtype=np.float64)
    if pose.shape != (3,):
        raise ShapeError(f"pose must have shape (3,), got {pose.shape}")
    return simulate_scans(world, pose[None], n_beams, fov, max_range, sigma, p_outlier, p_dropout,
                          rng, stamps=[stamp])[0]


def simulate_sonar(world: World2D, pose, bearings, beam_width: float = np.radians(15.0),
                   max_range: float = 5.0, sigma: float = 0.02, rng=None, rays_per_beam: int = 15,
                   stamp: float = 0.0) -> LaserScan:
    """A ring of sonar transducers at ``pose`` (3,), pointing at ``bearings`` (k,) relative to the
    heading. Each reads the range of the nearest obstacle anywhere in its cone of full width
    ``beam_width`` (sampled with ``rays_per_beam`` rays spread evenly edge to edge, minimum
    taken), plus Gaussian noise of std ``sigma`` clipped to ``[0, max_range]``; ``max_range`` when
    nothing lies within it. The scan's ``angles`` are the bearings."""
    pose = np.asarray(pose, dtype=np.float64)
    if pose.shape != (3,):
        raise ShapeError(f"pose must have shape (3,), got {pose.shape}")
    _check_probs(sigma, 0.0, 0.0, max_range)
    bearings = np.ascontiguousarray(bearings, dtype=np.float64).reshape(-1)
    beam_width = checks.non_negative("beam_width", beam_width, "radians")
    m = checks.count("rays_per_beam", rays_per_beam)
    offs = np.linspace(-beam_width / 2.0, beam_width / 2.0, m) if m > 1 else np.zeros(1)
    angles = (pose[2] + bearings[:, None] + offs[None, :]).reshape(-1)
    true = world.cast(pose[:2], angles, max_range).reshape(bearings.shape[0], m).min(axis=1)
    ranges = _corrupt(true, float(max_range), float(sigma), 0.0, 0.0, _rng(rng))
    return LaserScan(pose=pose.copy(), ranges=ranges, angles=bearings.copy(),
                     max_range=float(max_range), stamp=float(stamp))
