"""A synthetic 3D world with known truth, and a simulated spinning LiDAR that looks at it.

The world is a set of solid axis-aligned boxes (buildings, walls, car bodies, a bridge), solid
vertical cylinders (poles, tree trunks and crowns) and, optionally, the ground: the half-space
``z <= ground_z``. Every solid is closed (a point on its surface is inside). Rays are cast
exactly against them (:meth:`World3D.cast`: the slab test for boxes, the radial quadratic for
cylinders; in a world of more than :data:`GRID_MIN_SOLIDS` solids through a 2D grid of them,
:mod:`occmap.sim.solid_grid`, with the same results), :func:`simulate_lidar` turns one sensor
pose into an :class:`~occmap.cloud.PointCloud` the way a Velodyne would, and
:meth:`World3D.truth_voxels` rasterises the truth on the octree's voxel grid (voxel ``k`` per
axis spans ``[k·res, (k+1)·res)``, key ``k + 32768``).

>>> world = World3D.default()
>>> poses = world.default_trajectory(n_scans=60)            # (60, 4, 4) T_world_sensor
>>> cloud = simulate_lidar(world, poses[0], VELODYNE_HDL64, rng=np.random.default_rng(0))
>>> clouds = simulate_drive(60, VELODYNE_HDL32, rng=0)       # the whole drive
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property, lru_cache
from typing import NamedTuple

import numpy as np

from .. import checks
from ..cloud import PointCloud
from ..errors import InvalidArgumentError, NonFiniteError, ShapeError
from ..geometry.se3 import SE3
from . import _kernels3d
from .solid_grid import SolidGrid, build_grid
from .world2d import _as_rows, _resample_path, _rng

__all__ = [
    "LidarModel",
    "VELODYNE_HDL32",
    "VELODYNE_HDL64",
    "VELODYNE_VLP16",
    "VoxelTruth",
    "World3D",
    "simulate_drive",
    "simulate_lidar",
]


# ------------------------------------------------------------------ the default town block

# A 60 m × 40 m block: a main street along x (y ∈ [14, 26]: sidewalks [14, 16] and [24, 26], road
# [16, 24]) and a side street going north from it (x ∈ [34, 42]: sidewalks [34, 36] and [40, 42]).


def _car(x0, y0):
    """A parked car along x, 4.5 m × 1.8 m: a body 0.3–1.0 m above the ground (nothing under it:
    the wheels are not modelled) and a narrower cabin on top up to 1.5 m."""
    return [(x0, y0, 0.3, x0 + 4.5, y0 + 1.8, 1.0),
            (x0 + 1.0, y0 + 0.1, 1.0, x0 + 3.3, y0 + 1.7, 1.5)]


_DEFAULT_BOXES = np.array(
    [
        # buildings south of the main street
        (1.0, 3.0, 0.0, 14.0, 14.0, 8.0),  # corner shop
        (15.0, 4.0, 0.0, 27.0, 14.0, 12.0),  # office tower
        (28.0, 2.0, 0.0, 40.0, 13.0, 6.0),  # set back 1 m from the sidewalk
        (42.0, 2.0, 0.0, 59.0, 14.0, 10.0),
        # buildings north of the main street, either side of the side street
        (1.0, 26.0, 0.0, 12.0, 38.0, 5.0),
        (13.0, 27.0, 0.0, 33.0, 39.0, 9.0),
        (43.0, 26.0, 0.0, 59.0, 37.0, 7.0),
        # overhangs: a skywalk across the main street between the office tower and the north
        # building, an awning over the north sidewalk, a bus-shelter roof on the south sidewalk
        (20.0, 14.0, 5.0, 23.0, 27.0, 7.0),
        (45.0, 24.0, 2.8, 55.0, 26.0, 3.0),
        (34.0, 14.3, 2.5, 37.0, 15.8, 2.6),
        # a low wall closing the side street
        (33.0, 39.5, 0.0, 43.0, 40.0, 2.0),
        # a van at the north curb, under the awning's edge
        (50.0, 22.0, 0.3, 55.5, 23.9, 2.2),
    ]
    + _car(5.0, 16.2) + _car(30.0, 16.2) + _car(47.0, 16.2)  # south curb
    + _car(14.0, 22.0) + _car(25.0, 22.0),  # north curb
    dtype=np.float64,
)


def _tree(x, y, trunk_r=0.2, crown_r=1.0, trunk_top=3.0, top=6.5):
    """A trunk (by default r 0.2 m, up to 3 m) and a crown above it (r 1.0 m, 3–6.5 m): the
    crown overhangs."""
    return [(x, y, trunk_r, 0.0, trunk_top), (x, y, crown_r, trunk_top, top)]


_DEFAULT_CYLINDERS = np.array(
    [
        # street lamps, 6 m
        (4.0, 15.2, 0.1, 0.0, 6.0),
        (16.0, 15.2, 0.1, 0.0, 6.0),
        (28.0, 15.2, 0.1, 0.0, 6.0),
        (46.0, 15.2, 0.1, 0.0, 6.0),
        (56.0, 15.2, 0.1, 0.0, 6.0),
        (8.0, 24.8, 0.1, 0.0, 6.0),
        (26.0, 24.8, 0.1, 0.0, 6.0),
        (33.0, 25.0, 0.1, 0.0, 6.0),
        (57.0, 24.8, 0.1, 0.0, 6.0),
        # the bus shelter's posts
        (34.2, 14.5, 0.05, 0.0, 2.5),
        (36.8, 14.5, 0.05, 0.0, 2.5),
        # a water tank on the set-back building's roof
        (32.0, 7.0, 1.5, 6.0, 9.0),
    ]
    + _tree(5.0, 24.9) + _tree(18.0, 15.0)  # main street
    + _tree(35.0, 31.0) + _tree(41.0, 35.0) + _tree(35.0, 37.0),  # side street
    dtype=np.float64,
)


def _default_path():
    """The drive: east along the main street's centre line (y = 20) from x = 3, a quarter circle
    of radius 6 m left into the side street, north along its centre line (x = 38) to y = 36."""
    phi = np.linspace(0.0, np.pi / 2.0, 91)
    arc = np.stack([32.0 + 6.0 * np.sin(phi), 26.0 - 6.0 * np.cos(phi)], axis=1)
    return np.vstack([[(3.0, 20.0)], arc, [(38.0, 36.0)]])


#: Worlds with more solids than this are cast against through a grid of them (World3D._grid).
GRID_MIN_SOLIDS = 64


# ------------------------------------------------------------------ voxel truth


class VoxelTruth(NamedTuple):
    """A dense voxel raster on the octree's grid.

    ``occupied[i, j, l]`` is global voxel ``index_min + (i, j, l)``: the voxel spanning
    ``[k·res, (k+1)·res)`` per axis, whose octree key is ``k + 32768`` and whose centre is
    ``(k + 0.5)·res`` (what ``OcTree.key_to_coord`` returns)."""

    occupied: np.ndarray  # (nx, ny, nz) bool, indexed [ix, iy, iz]
    index_min: np.ndarray  # (3,) int64
    resolution: float

    @property
    def origin(self) -> np.ndarray:
        """World position (3,) of the outer corner of voxel (0, 0, 0)."""
        return self.index_min * self.resolution

    def centres(self, mask=None) -> np.ndarray:
        """Centres (M, 3) of the voxels where ``mask`` (default: :attr:`occupied`) is true, in
        C order of the raster."""
        m = self.occupied if mask is None else np.asarray(mask, dtype=bool)
        idx = np.argwhere(m)
        return (idx + self.index_min + 0.5) * self.resolution

    def keys(self, mask=None) -> np.ndarray:
        """Octree keys (M, 3) int64 of the voxels where ``mask`` (default: :attr:`occupied`) is
        true, in the order of :meth:`centres`."""
        m = self.occupied if mask is None else np.asarray(mask, dtype=bool)
        return np.argwhere(m) + self.index_min + 32768


# ------------------------------------------------------------------ the world


def level_poses(poses2d, z) -> np.ndarray:
    """Transforms ``T_world_sensor`` (N, 4, 4) of a level sensor (no roll or pitch) at planar
    poses ``(x, y, theta)`` (N, 3) and height ``z``: its x axis along ``theta``."""
    p = np.asarray(poses2d, dtype=np.float64).reshape(-1, 3)
    c = np.cos(p[:, 2])
    s = np.sin(p[:, 2])
    T = np.zeros((p.shape[0], 4, 4))
    T[:, 0, 0] = c
    T[:, 0, 1] = -s
    T[:, 1, 0] = s
    T[:, 1, 1] = c
    T[:, 2, 2] = 1.0
    T[:, 3, 3] = 1.0
    T[:, 0, 3] = p[:, 0]
    T[:, 1, 3] = p[:, 1]
    T[:, 2, 3] = z
    return T


def _as_points(name, a):
    arr = np.asarray(a, dtype=np.float64)
    if arr.shape[-1:] != (3,):
        raise ShapeError(f"{name} must have shape (..., 3), got {arr.shape}")
    return arr


@dataclass(eq=False)
class World3D:
    """A world of solid axis-aligned boxes and vertical cylinders above an optional ground.

    Parameters
    ----------
    boxes : array_like (B, 6)
        ``[xmin, ymin, zmin, xmax, ymax, zmax]`` per box, metres, min < max on every axis.
    cylinders : array_like (C, 5)
        ``[cx, cy, r, zmin, zmax]`` per vertical cylinder (r > 0, zmin < zmax); solid, capped.
    ground_z : float or None
        Height of the ground plane; the half-space below it is solid. ``None``: no ground.
    bounds : (xmin, ymin, zmin, xmax, ymax, zmax) or None
        The extent of interest (the default box of :meth:`truth_voxels`). ``None``: the bounding
        box of the solids (and 1 m below the ground).
    waypoints : array_like (P, 2) or None
        A collision-free polyline in the ground plane for :meth:`default_trajectory`.
    """

    boxes: np.ndarray
    cylinders: np.ndarray
    ground_z: float | None = 0.0
    bounds: tuple | None = None
    waypoints: np.ndarray | None = field(default=None)

    def __post_init__(self):
        self.boxes = _as_rows("boxes", self.boxes, 6)
        self.cylinders = _as_rows("cylinders", self.cylinders, 5)
        if np.any(self.boxes[:, :3] >= self.boxes[:, 3:]):
            raise InvalidArgumentError("every box needs min < max on each axis")
        if np.any(self.cylinders[:, 2] <= 0.0):
            raise InvalidArgumentError("cylinder radii must be positive")
        if np.any(self.cylinders[:, 3] >= self.cylinders[:, 4]):
            raise InvalidArgumentError("every cylinder needs zmin < zmax")
        if self.ground_z is not None:
            self.ground_z = float(self.ground_z)
            if not math.isfinite(self.ground_z):
                raise NonFiniteError(f"ground_z must be finite, got {self.ground_z}")
        if self.bounds is None:
            lo = np.full(3, np.inf)
            hi = np.full(3, -np.inf)
            if len(self.boxes):
                lo = np.minimum(lo, self.boxes[:, :3].min(axis=0))
                hi = np.maximum(hi, self.boxes[:, 3:].max(axis=0))
            if len(self.cylinders):
                c = self.cylinders
                lo = np.minimum(lo, [(c[:, 0] - c[:, 2]).min(), (c[:, 1] - c[:, 2]).min(), c[:, 3].min()])
                hi = np.maximum(hi, [(c[:, 0] + c[:, 2]).max(), (c[:, 1] + c[:, 2]).max(), c[:, 4].max()])
            if self.ground_z is not None:
                lo[2] = min(lo[2], self.ground_z - 1.0)
                hi[2] = max(hi[2], self.ground_z)
            if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
                raise InvalidArgumentError("an empty world needs explicit bounds")
            self.bounds = (*lo, *hi)
        b = np.asarray(self.bounds, dtype=np.float64)
        if b.shape != (6,):
            raise ShapeError(f"bounds must be (xmin, ymin, zmin, xmax, ymax, zmax), got shape {b.shape}")
        if not np.all(np.isfinite(b)) or not np.all(b[:3] < b[3:]):
            raise InvalidArgumentError(f"bounds must be finite with min < max: {b}")
        self.bounds = tuple(float(v) for v in b)
        if self.waypoints is not None:
            self.waypoints = _as_rows("waypoints", self.waypoints, 2)

    def _ground(self):
        return (0.0, False) if self.ground_z is None else (self.ground_z, True)

    # ------------------------------------------------------------------ construction

    @classmethod
    def default(cls) -> World3D:
        """A town block of 60 m × 40 m on flat ground (z = 0).

        A main street runs along x (road y ∈ [16, 24], sidewalks either side) and a side street
        leaves it northwards (road x ∈ [36, 40]). Seven buildings, 5–12 m tall, line them; a
        skywalk crosses the main street at x ∈ [20, 23], 5–7 m up; an awning (2.8–3 m) and a
        bus-shelter roof (2.5–2.6 m) overhang the sidewalks; five cars (bodies 0.3–1 m above the
        ground, cabins to 1.5 m) and a van are parked at the curbs; nine street lamps, two shelter
        posts, a water tank on a roof and five trees (trunk to 3 m, an overhanging crown from 3 to
        6.5 m) are cylinders; a low wall closes the side street. 22 boxes, 22 cylinders. The drive
        (:meth:`default_trajectory`) goes east along the main street, under the skywalk, and
        turns left into the side street."""
        return cls(_DEFAULT_BOXES.copy(), _DEFAULT_CYLINDERS.copy(), ground_z=0.0,
                   bounds=(0.0, 0.0, -1.0, 60.0, 40.0, 13.0), waypoints=_default_path())

    def default_trajectory(self, n_scans: int = 60, height: float = 1.8) -> np.ndarray:
        """Sensor poses ``T_world_sensor`` (n_scans, 4, 4): evenly spaced by arc length along the
        world's waypoints at ``height`` above the ground (above z = 0 without ground), the sensor
        level (no roll or pitch) and its x axis along the path (yaw following the path). For the
        default world the drive is 48.4 m long (about 0.8 m between 60 scans, 29 km/h at 10 Hz)
        and keeps at least 1.9 m (horizontally) from every solid up to 3 m above the ground —
        the parked cars and the side street's trees come nearest — and passes 3.2 m under the
        skywalk."""
        if self.waypoints is None or len(self.waypoints) < 2:
            raise InvalidArgumentError("this world has no waypoints to build a trajectory from")
        n = checks.count("n_scans", n_scans, 2)
        if not math.isfinite(height):
            raise NonFiniteError(f"height must be finite, got {height}")
        return level_poses(_resample_path(self.waypoints, n), (self.ground_z or 0.0) + float(height))

    # ------------------------------------------------------------------ queries

    def cast(self, origins, directions, max_range: float = np.inf) -> np.ndarray:
        """Exact range from each origin along each direction to the first solid.

        Parameters
        ----------
        origins : array_like (N, 3) or (3,)
            Ray origins; a single one is shared by all rays.
        directions : array_like (N, 3) or (3,)
            Ray directions in the world frame, any non-zero length (normalised here).
        max_range : float
            Hits farther than this are ignored.

        Returns
        -------
        ranges : ndarray (N,)
            Distance to the first surface along the unit direction, ``inf`` when nothing lies
            within ``max_range``. A ray starting inside or on a solid (or on or below the ground)
            reads 0; a ray that only touches a surface (tangent to a cylinder, along a box face or
            edge) hits it.
        """
        d = np.array(directions, dtype=np.float64)  # a copy: normalised in place below
        if d.shape == (3,):
            d = d.reshape(1, 3)
        if d.ndim != 2 or d.shape[1] != 3:
            raise ShapeError(f"directions must have shape (N, 3) or (3,), got {np.shape(directions)}")
        o = np.asarray(origins, dtype=np.float64)
        if o.shape == (3,):
            o = o.reshape(1, 3)
        if o.ndim != 2 or o.shape[1] != 3 or o.shape[0] not in (1, d.shape[0]):
            raise ShapeError(f"origins must be (3,) or (N, 3) matching directions ({d.shape[0]}, 3), "
                             f"got {np.shape(origins)}")
        o = np.ascontiguousarray(o)
        if not (np.all(np.isfinite(o)) and np.all(np.isfinite(d))):
            raise NonFiniteError("ray origins and directions must be finite")
        if not max_range > 0.0:
            raise InvalidArgumentError(f"max_range must be positive, got {max_range}")
        norm = np.sqrt(np.einsum("ij,ij->i", d, d))
        if np.any(norm == 0.0):
            raise InvalidArgumentError("ray directions must be non-zero")
        d /= norm[:, None]
        return self._cast(o, d, float(max_range))

    @cached_property
    def _grid(self) -> SolidGrid | None:
        """The solids binned on a 2D grid (:mod:`occmap.sim.solid_grid`) when there are more than
        :data:`GRID_MIN_SOLIDS`, else None: casts and point tests then visit only the solids near
        each ray or point, with the same results. Built on first use; the solids must not change
        after that."""
        if len(self.boxes) + len(self.cylinders) <= GRID_MIN_SOLIDS:
            return None
        return build_grid(self.boxes, self.cylinders)

    def _cast(self, origins, unit_directions, max_range):
        out = np.empty(unit_directions.shape[0])
        gz, has_ground = self._ground()
        n = unit_directions.shape[0]
        args = (origins, unit_directions, self.boxes, self.cylinders, gz, has_ground, max_range)
        if self._grid is None:
            f = _kernels3d.cast_rays_parallel if n >= _kernels3d.PARALLEL_MIN else _kernels3d.cast_rays
            f(*args, out)
        else:
            f = (_kernels3d.cast_grid_rays_parallel if n >= _kernels3d.PARALLEL_MIN
                 else _kernels3d.cast_grid_rays)
            f(*args, *self._grid, out)
        return out

    def occupied(self, points) -> np.ndarray:
        """Whether each point (..., 3) lies inside or on a solid, or on or below the ground:
        bool array of shape (...)."""
        p = _as_points("points", points)
        flat = np.ascontiguousarray(p.reshape(-1, 3))
        out = np.empty(flat.shape[0], dtype=np.bool_)
        gz, has_ground = self._ground()
        if self._grid is None:
            _kernels3d.occupied(flat, self.boxes, self.cylinders, gz, has_ground, out)
        else:
            _kernels3d.occupied_grid(flat, self.boxes, self.cylinders, gz, has_ground, *self._grid, out)
        return out.reshape(p.shape[:-1])

    def truth_voxels(self, resolution: float, bbx_min=None, bbx_max=None,
                     mode: str = "centre") -> VoxelTruth:
        """The true occupancy on the octree's voxel grid of ``resolution``.

        The raster covers every voxel that overlaps the box ``[bbx_min, bbx_max]`` (default: the
        world's :attr:`bounds`), i.e. global indices ``floor(bbx_min / res)`` to
        ``floor(bbx_max / res)`` per axis, computed as the octree computes keys.

        ``mode="centre"``: a voxel is occupied when its centre lies inside (or on) a solid — the
        voxel-volume truth. ``mode="overlap"``: when its closed cube meets a solid — every surface
        point a noise-free lidar can return lies in such a voxel, so it bounds what a map may call
        occupied. (Centre truth misses about half the voxels that hold a face: a face at x = 10.03
        puts its hits in voxel [10.0, 10.1), whose centre 10.05 lies outside a box ending there.)
        """
        res = checks.resolution(resolution)
        if mode not in ("centre", "overlap"):
            raise InvalidArgumentError(f"mode must be 'centre' or 'overlap', got {mode!r}")
        lo = np.asarray(self.bounds[:3] if bbx_min is None else bbx_min, dtype=np.float64)
        hi = np.asarray(self.bounds[3:] if bbx_max is None else bbx_max, dtype=np.float64)
        if lo.shape != (3,) or hi.shape != (3,):
            raise ShapeError(f"bbx_min and bbx_max must have shape (3,), got {lo.shape} and {hi.shape}")
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            raise NonFiniteError("bbx_min and bbx_max must be finite")
        if np.any(lo > hi):
            raise InvalidArgumentError(f"bbx_min must not exceed bbx_max: {lo} > {hi}")
        k0 = np.floor(lo * (1.0 / res)).astype(np.int64)
        k1 = np.floor(hi * (1.0 / res)).astype(np.int64)
        shape = tuple(int(v) for v in (k1 - k0 + 1))
        if math.prod(shape) > 2_000_000_000:
            raise InvalidArgumentError(f"the raster would hold {math.prod(shape):,} voxels {shape}")
        out = np.zeros(shape, dtype=np.bool_)
        gz, has_ground = self._ground()
        _kernels3d.rasterize(self.boxes, self.cylinders, gz, has_ground, k0, res,
                             mode == "overlap", out)
        return VoxelTruth(out, k0, res)


# ------------------------------------------------------------------ simulated LiDAR


@dataclass(frozen=True)
class LidarModel:
    """The beam layout of a spinning multi-laser LiDAR.

    Every laser fires from the sensor's origin (the real sensors' few-centimetre offsets between
    lasers are not modelled) at a fixed elevation, once per azimuth column; the sensor frame has x
    forward, y left and z up, azimuth counter-clockwise from +x. One revolution has
    ``n_columns = round(2π / azimuth_step)`` columns at azimuths ``−π + k·2π/n_columns``, so the
    step used is ``2π / n_columns``, within half a column of the nominal one.

    Attributes
    ----------
    name : str
    elevations : tuple of float
        Elevation of each laser above the sensor's xy plane, radians, in the order the points
        of one column are emitted.
    azimuth_step : float
        Nominal horizontal step between columns, radians.
    max_range : float
        Nothing farther returns.
    min_range : float
        Returns nearer than this are dropped (the blind zone around the sensor).
    rate : float
        Revolutions per second; :func:`simulate_drive` stamps scans ``1 / rate`` apart.
    """

    name: str
    elevations: tuple
    azimuth_step: float
    max_range: float
    min_range: float = 0.5
    rate: float = 10.0

    def __post_init__(self):
        el = tuple(float(e) for e in np.asarray(self.elevations, dtype=np.float64).reshape(-1))
        if not el:
            raise InvalidArgumentError("a lidar needs at least one laser")
        if not all(-math.pi / 2 <= e <= math.pi / 2 for e in el):
            raise InvalidArgumentError("elevations must lie in [-π/2, π/2] radians")
        object.__setattr__(self, "elevations", el)
        step = checks.positive("azimuth_step", self.azimuth_step, "radians")
        if not step <= 2.0 * math.pi:
            raise InvalidArgumentError(f"azimuth_step must be in (0, 2π], got {self.azimuth_step}")
        min_range = checks.non_negative("min_range", self.min_range, "metres")
        max_range = checks.positive("max_range", self.max_range, "metres")
        if not min_range < max_range:
            raise InvalidArgumentError(
                f"need 0 <= min_range < max_range < inf, got {self.min_range}, {self.max_range}")
        values = {"azimuth_step": step, "max_range": max_range, "min_range": min_range,
                  "rate": checks.positive("rate", self.rate, "scans per second")}
        for name, value in values.items():
            object.__setattr__(self, name, value)

    @classmethod
    def from_degrees(cls, name: str, elevations_deg, azimuth_step_deg: float, max_range: float,
                     min_range: float = 0.5, rate: float = 10.0) -> LidarModel:
        """A model from a datasheet's angles in degrees."""
        return cls(name, tuple(np.radians(np.asarray(elevations_deg, dtype=np.float64))),
                   math.radians(azimuth_step_deg), max_range, min_range, rate)

    def with_azimuth_step(self, azimuth_step: float) -> LidarModel:
        """The same lasers with another horizontal step (radians): coarser is faster."""
        return replace(self, azimuth_step=float(azimuth_step))

    @property
    def n_lasers(self) -> int:
        return len(self.elevations)

    @property
    def n_columns(self) -> int:
        return max(1, int(round(2.0 * math.pi / self.azimuth_step)))

    @property
    def n_beams(self) -> int:
        """Beams per revolution, ``n_lasers · n_columns``."""
        return self.n_lasers * self.n_columns

    def azimuths(self) -> np.ndarray:
        """Azimuth of each column (n_columns,), radians, from −π."""
        return -math.pi + np.arange(self.n_columns) * (2.0 * math.pi / self.n_columns)

    def directions(self) -> np.ndarray:
        """Unit beam directions in the sensor frame, (n_columns, n_lasers, 3): column by column
        (azimuth), each column's lasers in the order of :attr:`elevations`. Read-only."""
        return _directions(self.elevations, self.n_columns)


@lru_cache(maxsize=16)
def _directions(elevations, n_columns):
    el = np.asarray(elevations, dtype=np.float64)
    az = -math.pi + np.arange(n_columns) * (2.0 * math.pi / n_columns)
    ce = np.cos(el)[None, :]
    d = np.empty((n_columns, el.shape[0], 3))
    d[..., 0] = ce * np.cos(az)[:, None]
    d[..., 1] = ce * np.sin(az)[:, None]
    d[..., 2] = np.sin(el)[None, :]
    d.flags.writeable = False
    return d


#: Velodyne HDL-32E: 32 lasers evenly from −30.67° to +10.67° (1.33° apart), 0.16° azimuth step
#: at 10 Hz (2,250 columns, 72,000 beams per revolution), 100 m range.
VELODYNE_HDL32 = LidarModel.from_degrees("Velodyne HDL-32E", np.linspace(-30.67, 10.67, 32), 0.16,
                                         100.0)

#: Velodyne VLP-16 ("Puck"): 16 lasers from −15° to +15° (2° apart), 0.2° azimuth step at 10 Hz
#: (1,800 columns, 28,800 beams per revolution), 100 m range.
VELODYNE_VLP16 = LidarModel.from_degrees("Velodyne VLP-16", np.linspace(-15.0, 15.0, 16), 0.2, 100.0)

#: Velodyne HDL-64E: 64 lasers from −24.9° to +2.0° in two blocks as on the real sensor — the
#: lower 32 evenly from −24.9° to −8.83°, the upper 32 from −8.33° to +2.0° (1/3° apart) — with a
#: 0.17° azimuth step at 10 Hz (2,118 columns, 135,552 beams per revolution), 120 m range.
VELODYNE_HDL64 = LidarModel.from_degrees(
    "Velodyne HDL-64E",
    np.concatenate([np.linspace(-24.9, -8.83, 32), np.linspace(-8.33, 2.0, 32)]), 0.17, 120.0)


def _pose_matrix(pose):
    if isinstance(pose, SE3):
        if pose.shape != ():
            raise ShapeError(f"pose must be a single SE3, got shape {pose.shape}")
        return pose
    m = np.asarray(pose, dtype=np.float64)
    if m.shape != (4, 4):
        raise ShapeError(f"pose must be an SE3 or a (4, 4) matrix, got shape {m.shape}")
    return SE3(m)


def simulate_lidar(world: World3D, pose, model: LidarModel = VELODYNE_HDL32, *, rng=None,
                   noise_std: float = 0.02, dropout: float = 0.0, azimuth_step: float | None = None,
                   stamp: float | None = None) -> PointCloud:
    """One revolution of a spinning LiDAR at ``pose``, as a point cloud in the sensor frame.

    All beams of ``model`` (``azimuth_step`` radians overrides its step) are cast from the pose
    at once — the sensor does not move during the revolution. Each beam that hits a solid within
    the model's ``max_range`` reads the true range plus Gaussian noise of std ``noise_std`` along
    the beam; readings outside ``[min_range, max_range]`` are then dropped, and each remaining one
    independently with probability ``dropout``.

    **No-return beams are omitted**, not reported as NaN or max-range points (so
    ``cloud.dropped`` stays 0: that field counts points a file reader removed). Points are in
    column order (azimuth from −π), each column's lasers in the order of ``model.elevations``.

    Parameters
    ----------
    world : World3D
    pose : SE3 or array_like (4, 4)
        ``T_world_sensor``: the sensor's x axis forward, z up.
    model : LidarModel
        :data:`VELODYNE_HDL32`, :data:`VELODYNE_HDL64` or a custom layout.
    rng : numpy.random.Generator, int or None
        The noise and dropout source; a seed makes the scan reproducible, ``None`` draws fresh
        entropy.
    stamp : float or None
        Copied to the cloud.

    Returns
    -------
    PointCloud
        ``points`` (M, 3) in the sensor frame, ``pose`` the :class:`~occmap.geometry.SE3`.
    """
    T = _pose_matrix(pose)
    if azimuth_step is not None:
        model = model.with_azimuth_step(azimuth_step)
    checks.non_negative("noise_std", noise_std, "metres")
    checks.fraction("dropout", dropout)
    rng = _rng(rng)
    dirs = model.directions().reshape(-1, 3)
    m = T.matrix
    world_dirs = _kernels3d.rotate(np.ascontiguousarray(m[:3, :3]), dirs, np.empty_like(dirs))
    ranges = world._cast(np.ascontiguousarray(m[:3, 3]).reshape(1, 3), world_dirs, model.max_range)
    n_hit = int(np.count_nonzero(np.isfinite(ranges)))
    noise = rng.normal(0.0, noise_std, size=n_hit) if noise_std > 0.0 else np.empty(0)
    uniform = rng.random(n_hit) if dropout > 0.0 else np.empty(0)
    out = np.empty((n_hit, 3))
    n = _kernels3d.lidar_points(dirs, ranges, noise, uniform, float(dropout), model.min_range,
                                model.max_range, out)
    return PointCloud(out if n == n_hit else out[:n].copy(), T, stamp=stamp)


def simulate_drive(n_scans: int = 60, model: LidarModel = VELODYNE_HDL32, *,
                   world: World3D | None = None, rng=None, noise_std: float = 0.02,
                   dropout: float = 0.0, azimuth_step: float | None = None,
                   height: float = 1.8) -> list[PointCloud]:
    """Clouds from ``n_scans`` poses of ``world.default_trajectory(n_scans, height)`` (default
    world: :meth:`World3D.default`), stamped ``i / model.rate`` seconds; see
    :func:`simulate_lidar` for the sensor model. One ``rng`` (a generator or a seed) feeds all
    scans in order, so a seed makes the whole drive reproducible."""
    world = World3D.default() if world is None else world
    if azimuth_step is not None:
        model = model.with_azimuth_step(azimuth_step)
    rng = _rng(rng)
    poses = world.default_trajectory(n_scans, height)
    return [simulate_lidar(world, SE3(T), model, rng=rng, noise_std=noise_std, dropout=dropout,
                           stamp=i / model.rate) for i, T in enumerate(poses)]
