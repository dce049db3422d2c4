"""The synthetic 3D world: exact ray casting (hand cases, an independent NumPy reference, sampling
along rays), the simulated spinning LiDAR, the default town block and its drive, and the voxel
truth."""

from __future__ import annotations

import math

import numpy as np
import pytest

from occmap.cloud import PointCloud
from occmap.errors import InvalidArgumentError, NonFiniteError, ShapeError
from occmap.geometry.se3 import SE3
from occmap.sim import _kernels3d
from occmap.sim.world3d import (
    VELODYNE_HDL32,
    VELODYNE_HDL64,
    LidarModel,
    World3D,
    simulate_drive,
    simulate_lidar,
)

NO_BOXES = np.zeros((0, 6))
NO_CYLINDERS = np.zeros((0, 5))
COARSE = math.radians(4.0)  # azimuth step for fast simulations in tests
SQ2 = math.sqrt(2.0)


@pytest.fixture(scope="module")
def town():
    return World3D.default()


def world(boxes=NO_BOXES, cylinders=NO_CYLINDERS, ground_z=None):
    return World3D(boxes, cylinders, ground_z=ground_z, bounds=(-50, -50, -50, 50, 50, 50))


def cast1(w, origin, direction, max_range=np.inf):
    return float(w.cast(origin, direction, max_range)[0])


def pose_at(x, y, z, yaw=0.0):
    return SE3.from_euler_zyx(yaw, 0.0, 0.0, (x, y, z))


def room(half=3.0, height=4.0, wall=0.2):
    """A closed room [-half, half]² × [0, height] of walls ``wall`` thick, ground and ceiling
    included: every beam from inside returns."""
    h, t = half, wall
    boxes = [(-h - t, -h - t, -t, h + t, h + t, 0.0), (-h - t, -h - t, height, h + t, h + t, height + t),
             (-h - t, -h - t, 0, -h, h + t, height), (h, -h - t, 0, h + t, h + t, height),
             (-h, -h - t, 0, h, -h, height), (-h, h, 0, h, h + t, height)]
    return World3D(boxes, NO_CYLINDERS, ground_z=None)


def inflated(w, eps=1e-9):
    """The same world with every solid grown by ``eps``: a point within ``eps`` of a surface is
    inside it."""
    b = w.boxes.copy()
    b[:, :3] -= eps
    b[:, 3:] += eps
    c = w.cylinders.copy()
    c[:, 2] += eps
    c[:, 3] -= eps
    c[:, 4] += eps
    g = None if w.ground_z is None else w.ground_z + eps
    return World3D(b, c, ground_z=g, bounds=w.bounds)


# ------------------------------------------------------------------ an independent reference


def ref_cast(w, origins, directions, max_range=np.inf):
    """Rays (N, 3) against the world, vectorised over rays with NumPy: Kay–Kajiya slabs written
    with divisions and ``where``, the textbook quadratic for cylinders."""
    o = np.asarray(origins, dtype=float)
    d = np.asarray(directions, dtype=float)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    best = np.full(len(d), np.inf)
    par = d == 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        for box in w.boxes:
            lo, hi = box[:3], box[3:]
            t1 = (lo - o) / d
            t2 = (hi - o) / d
            inside = (o >= lo) & (o <= hi)
            tmin = np.where(par, np.where(inside, -np.inf, np.inf), np.minimum(t1, t2))
            tmax = np.where(par, np.where(inside, np.inf, -np.inf), np.maximum(t1, t2))
            tn, tf = tmin.max(axis=1), tmax.min(axis=1)
            hit = (tn <= tf) & (tf >= 0)
            best = np.where(hit, np.minimum(best, np.maximum(tn, 0.0)), best)
        for cx, cy, r, z0, z1 in w.cylinders:
            fx, fy = o[:, 0] - cx, o[:, 1] - cy
            A = d[:, 0] ** 2 + d[:, 1] ** 2
            B = 2 * (fx * d[:, 0] + fy * d[:, 1])
            C = fx ** 2 + fy ** 2 - r * r
            disc = B * B - 4 * A * C
            sq = np.sqrt(np.maximum(disc, 0.0))
            ra = np.where(A > 0, (-B - sq) / (2 * A), np.where(C <= 0, -np.inf, np.inf))
            rb = np.where(A > 0, (-B + sq) / (2 * A), np.where(C <= 0, np.inf, -np.inf))
            ok = (A == 0) | (disc >= 0)
            za, zb = (z0 - o[:, 2]) / d[:, 2], (z1 - o[:, 2]) / d[:, 2]
            inz = (o[:, 2] >= z0) & (o[:, 2] <= z1)
            zmin = np.where(par[:, 2], np.where(inz, -np.inf, np.inf), np.minimum(za, zb))
            zmax = np.where(par[:, 2], np.where(inz, np.inf, -np.inf), np.maximum(za, zb))
            tn, tf = np.maximum(ra, zmin), np.minimum(rb, zmax)
            hit = ok & (tn <= tf) & (tf >= 0)
            best = np.where(hit, np.minimum(best, np.maximum(tn, 0.0)), best)
        if w.ground_z is not None:
            g = w.ground_z
            tg = np.where(o[:, 2] <= g, 0.0, np.where(d[:, 2] < 0, (g - o[:, 2]) / d[:, 2], np.inf))
            best = np.minimum(best, tg)
    return np.where(best <= max_range, best, np.inf)


def random_rays(rng, n, bounds, axis_fraction=0.2):
    lo, hi = np.array(bounds[:3]), np.array(bounds[3:])
    o = lo + rng.random((n, 3)) * (hi - lo)
    d = rng.normal(size=(n, 3))
    # some rays run parallel to one or two coordinate planes
    k = rng.random(n) < axis_fraction
    d[k, rng.integers(0, 3, k.sum())] = 0.0
    k = rng.random(n) < axis_fraction / 2
    d[k, rng.integers(0, 3, k.sum())] = 0.0
    d[np.all(d == 0, axis=1)] = (0.0, 0.0, 1.0)
    return o, d


def random_world(rng, n_boxes=12, n_cyl=8, ground=True):
    lo = rng.uniform(-10, 8, (n_boxes, 3))
    boxes = np.hstack([lo, lo + rng.uniform(0.1, 6, (n_boxes, 3))])
    cyl = np.column_stack([rng.uniform(-10, 10, (n_cyl, 2)), rng.uniform(0.05, 2, n_cyl),
                           z0 := rng.uniform(-5, 5, n_cyl), z0 + rng.uniform(0.1, 5, n_cyl)])
    return World3D(boxes, cyl, ground_z=-3.0 if ground else None, bounds=(-12, -12, -6, 12, 12, 12))


# ------------------------------------------------------------------ hand-computed hits


BOX = World3D([(2.0, -1.0, -1.0, 4.0, 1.0, 1.0)], NO_CYLINDERS, ground_z=None)


def test_axis_rays_into_box_faces():
    assert cast1(BOX, (0, 0, 0), (1, 0, 0)) == 2.0
    assert cast1(BOX, (6, 0, 0), (-1, 0, 0)) == 2.0
    assert cast1(BOX, (3, 0, 5), (0, 0, -1)) == 4.0
    assert cast1(BOX, (3, -7, 0.5), (0, 2.0, 0)) == 6.0  # any length of direction
    assert cast1(BOX, (0, 0, 0), (-1, 0, 0)) == np.inf  # pointing away


def test_oblique_ray_into_box():
    w = World3D([(2.0, 1.0, -1.0, 4.0, 3.0, 1.0)], NO_CYLINDERS, ground_z=None)
    assert cast1(w, (0, 0, 0), (1, 1, 0)) == pytest.approx(2 * SQ2, abs=1e-12)  # enters the x = 2 face
    assert cast1(w, (0, 0, 0), (1, 0.2, 0)) == np.inf  # passes below y = 1 until x = 5 > 4


def test_ray_parallel_to_slabs():
    # running along a face (closed solid): touches it
    assert cast1(BOX, (0, 1.0, 0), (1, 0, 0)) == 2.0
    assert cast1(BOX, (0, 1.0 + 1e-12, 0), (1, 0, 0)) == np.inf
    # along an edge
    assert cast1(BOX, (0, 1.0, 1.0), (1, 0, 0)) == 2.0
    # parallel to the x slabs but outside them
    assert cast1(BOX, (0, -5, 0), (0, 1, 0)) == np.inf
    assert cast1(BOX, (3, -5, 0), (0, 1, 0)) == 4.0


def test_rays_from_inside_or_on_a_box_read_zero():
    for d in [(1, 0, 0), (0, -1, 0), (0.3, 0.4, -0.5)]:
        assert cast1(BOX, (3, 0, 0), d) == 0.0
    assert cast1(BOX, (4.0, 0, 0), (1, 0, 0)) == 0.0  # on a face, leaving


def test_max_range():
    assert cast1(BOX, (0, 0, 0), (1, 0, 0), max_range=1.9) == np.inf
    assert cast1(BOX, (0, 0, 0), (1, 0, 0), max_range=2.0) == 2.0


CYL = World3D(NO_BOXES, [(0.0, 0.0, 1.0, 0.0, 2.0)], ground_z=None)


def test_cylinder_side_cap_tangent_and_miss():
    assert cast1(CYL, (-5, 0, 1), (1, 0, 0)) == 4.0
    assert cast1(CYL, (0, 5, 1), (0, -1, 0)) == 4.0
    assert cast1(CYL, (-5, 1.0, 1), (1, 0, 0)) == 5.0  # tangent: touches at (0, 1, 1)
    assert cast1(CYL, (-5, 1.0 + 1e-9, 1), (1, 0, 0)) == np.inf  # just misses
    assert cast1(CYL, (-5, 0, 2.5), (1, 0, 0)) == np.inf  # above the top
    assert cast1(CYL, (0.5, 0, 5), (0, 0, -1)) == 3.0  # onto the cap
    assert cast1(CYL, (1.5, 0, 5), (0, 0, -1)) == np.inf  # vertical, outside the disc
    # oblique onto the cap: the side is met (t = 2√2) above the top, the cap at t = 3√2
    assert cast1(CYL, (-3, 0, 5), (1, 0, -1)) == pytest.approx(3 * SQ2, abs=1e-12)
    # oblique through the side: 45° down from (-3, 0, 3) meets x = -1 at z = 1
    assert cast1(CYL, (-3, 0, 3), (1, 0, -1)) == pytest.approx(2 * SQ2, abs=1e-12)
    assert cast1(CYL, (0.2, 0.3, 1), (0.6, -0.8, 0.1)) == 0.0  # inside
    assert cast1(CYL, (3, 0, 1), (1, 0, 0)) == np.inf  # outside, heading away


def test_ground_plane():
    g = World3D(NO_BOXES, NO_CYLINDERS, ground_z=0.5, bounds=(0, 0, 0, 1, 1, 1))
    assert cast1(g, (0, 0, 2.5), (1, 0, -1)) == pytest.approx(2 * SQ2, abs=1e-12)
    assert cast1(g, (0, 0, 2.5), (1, 0, 0)) == np.inf
    assert cast1(g, (0, 0, 2.5), (0, 0, 1)) == np.inf
    assert cast1(g, (0, 0, 0.5), (0, 0, 1)) == 0.0  # on the ground
    assert cast1(g, (0, 0, -1), (0, 0, 1)) == 0.0  # below it
    nog = World3D(NO_BOXES, NO_CYLINDERS, ground_z=None, bounds=(0, 0, 0, 1, 1, 1))
    assert cast1(nog, (0, 0, 2.5), (0, 0, -1)) == np.inf


def test_nearest_of_several_solids():
    w = World3D([(2.0, -1.0, -1.0, 4.0, 1.0, 1.0), (6.0, -1.0, -1.0, 7.0, 1.0, 1.0)],
                [(1.0, 0.0, 0.25, -1.0, 1.0)], ground_z=-2.0)
    assert cast1(w, (0, 0, 0), (1, 0, 0)) == 0.75
    assert cast1(w, (0, 0.5, 0), (1, 0, 0)) == 2.0
    assert cast1(w, (5, 0, 0), (1, 0, 0)) == 1.0
    assert cast1(w, (5, 0, 0), (0, 0, -1)) == 2.0


def test_cast_shapes_and_broadcast(town):
    o = np.array([30.0, 20.0, 1.8])
    d = np.random.default_rng(1).normal(size=(50, 3))
    a = town.cast(o, d)
    b = town.cast(np.tile(o, (50, 1)), d)
    assert a.shape == (50,)
    np.testing.assert_array_equal(a, b)
    assert town.cast(o, (1, 0, 0)).shape == (1,)
    assert town.cast(o, np.zeros((0, 3))).shape == (0,)
    assert World3D(NO_BOXES, NO_CYLINDERS, None, (0, 0, 0, 1, 1, 1)).cast(o, d).tolist() == [np.inf] * 50


def test_cast_rejects_bad_input(town):
    with pytest.raises(ShapeError):
        town.cast(np.zeros((3, 3)), np.ones((4, 3)))
    with pytest.raises(ShapeError):
        town.cast(np.zeros(3), np.ones((4, 2)))
    with pytest.raises(NonFiniteError):
        town.cast((0, 0, np.nan), (1, 0, 0))
    with pytest.raises(InvalidArgumentError):
        town.cast((0, 0, 1), (0, 0, 0))
    with pytest.raises(InvalidArgumentError):
        town.cast((0, 0, 1), (1, 0, 0), max_range=0.0)


def test_world_validation():
    with pytest.raises(ShapeError):
        World3D(np.zeros((1, 5)), NO_CYLINDERS)
    with pytest.raises(InvalidArgumentError):
        World3D([(0, 0, 0, 1, 0, 1)], NO_CYLINDERS)  # flat box
    with pytest.raises(InvalidArgumentError):
        World3D(NO_BOXES, [(0, 0, 0.0, 0, 1)])  # zero radius
    with pytest.raises(InvalidArgumentError):
        World3D(NO_BOXES, [(0, 0, 1.0, 2, 1)])  # zmin > zmax
    with pytest.raises(NonFiniteError):
        World3D(NO_BOXES, NO_CYLINDERS, ground_z=np.inf)
    with pytest.raises(InvalidArgumentError):
        World3D(NO_BOXES, NO_CYLINDERS, ground_z=None)  # nothing to take bounds from
    w = World3D([(0, 0, 0, 1, 2, 3)], [(5, 5, 1, 0, 4)], ground_z=0.0)
    assert w.bounds == (0.0, 0.0, -1.0, 6.0, 6.0, 4.0)


# ------------------------------------------------------------------ random rays


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_cast_matches_numpy_reference(seed):
    rng = np.random.default_rng(seed)
    w = random_world(rng)
    o, d = random_rays(rng, 3000, w.bounds)
    got = w.cast(o, d, max_range=40.0)
    want = ref_cast(w, o, d, max_range=40.0)
    assert np.array_equal(np.isfinite(got), np.isfinite(want))
    f = np.isfinite(got)
    np.testing.assert_allclose(got[f], want[f], rtol=1e-9, atol=1e-9)
    assert 0.2 < f.mean() < 0.99 and (got == 0).mean() > 0.05  # the cases are mixed


def test_cast_matches_reference_in_the_town(town):
    rng = np.random.default_rng(7)
    o, d = random_rays(rng, 4000, (0, 0, 0.05, 60, 40, 14))
    got = town.cast(o, d, 100.0)
    want = ref_cast(town, o, d, 100.0)
    assert np.array_equal(np.isfinite(got), np.isfinite(want))
    f = np.isfinite(got)
    np.testing.assert_allclose(got[f], want[f], rtol=1e-9, atol=1e-9)


def test_cast_against_sampling_along_the_rays(town):
    """Nothing solid lies before the hit (samples every 2 cm), and the hit point is on a surface
    (inside the world grown by 1e-9 m)."""
    rng = np.random.default_rng(3)
    free = ~town.occupied(rng.uniform((0, 0, 0.05), (60, 40, 14), (3000, 3)))
    o, d = random_rays(rng, 3000, (0, 0, 0.05, 60, 40, 14))
    o = o[free]
    d = d[free] / np.linalg.norm(d[free], axis=1, keepdims=True)
    r = town.cast(o, d, 60.0)
    steps = np.arange(0.0, 60.0, 0.02)
    samples = o[:, None, :] + steps[None, :, None] * d[:, None, :]
    occ = town.occupied(samples)
    before = steps[None, :] < r[:, None] - 1e-9
    assert not np.any(occ & before)
    hit = np.isfinite(r)
    first = np.where(occ.any(axis=1), steps[np.argmax(occ, axis=1)], np.inf)
    assert np.all(first[~hit] == np.inf)  # what sampling finds, cast finds
    assert np.all(r[hit] <= first[hit] + 1e-9)
    assert np.all(inflated(town).occupied(o[hit] + r[hit, None] * d[hit]))
    assert hit.mean() > 0.5


def test_serial_and_parallel_kernels_agree(town):
    rng = np.random.default_rng(11)
    o, d = random_rays(rng, 20000, (0, 0, 0.05, 60, 40, 14))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    args = (o, d, town.boxes, town.cylinders, 0.0, True, 80.0)
    a = _kernels3d.cast_rays(*args, np.empty(len(d)))
    b = _kernels3d.cast_rays_parallel(*args, np.empty(len(d)))
    np.testing.assert_array_equal(a, b)


def test_occupied():
    w = World3D([(0, 0, 0, 1, 1, 1)], [(5, 5, 1, 2, 3)], ground_z=-1.0)
    pts = np.array([[0.5, 0.5, 0.5], [1.0, 1.0, 1.0], [1.0 + 1e-12, 0.5, 0.5],
                    [5.9, 5, 2.5], [6.0, 5.0, 3.0], [5, 5, 1.99], [20, 20, -1.0], [20, 20, -0.999]])
    np.testing.assert_array_equal(w.occupied(pts), [1, 1, 0, 1, 1, 0, 1, 0])
    assert w.occupied(pts.reshape(2, 4, 3)).shape == (2, 4)
    assert w.occupied(pts[0]).shape == ()
    with pytest.raises(ShapeError):
        w.occupied(np.zeros((4, 2)))


# ------------------------------------------------------------------ the lidar


def test_models_match_their_datasheets():
    for m, n, lo, hi, cols, rng_ in [(VELODYNE_HDL32, 32, -30.67, 10.67, 2250, 100.0),
                                     (VELODYNE_HDL64, 64, -24.9, 2.0, 2118, 120.0)]:
        el = np.degrees(m.elevations)
        assert m.n_lasers == n and len(set(np.round(el, 9))) == n
        assert el.min() == pytest.approx(lo) and el.max() == pytest.approx(hi)
        assert m.n_columns == cols and m.n_beams == n * cols
        assert m.max_range == rng_
        assert m.directions().shape == (cols, n, 3)
        np.testing.assert_allclose(np.linalg.norm(m.directions(), axis=-1), 1.0)
    assert np.degrees(np.diff(VELODYNE_HDL32.elevations)) == pytest.approx(np.full(31, 41.34 / 31))
    upper = np.degrees(VELODYNE_HDL64.elevations[32:])
    assert np.diff(upper) == pytest.approx(np.full(31, 1 / 3), abs=1e-3)
    coarse = VELODYNE_HDL64.with_azimuth_step(COARSE)
    assert coarse.n_columns == 90 and coarse.elevations == VELODYNE_HDL64.elevations
    np.testing.assert_allclose(np.diff(coarse.azimuths()), 2 * np.pi / 90)


def test_model_validation():
    with pytest.raises(InvalidArgumentError):
        LidarModel("x", (), 0.1, 10.0)
    with pytest.raises(InvalidArgumentError):
        LidarModel("x", (2.0,), 0.1, 10.0)
    with pytest.raises(InvalidArgumentError):
        LidarModel("x", (0.0,), 0.0, 10.0)
    with pytest.raises(InvalidArgumentError):
        LidarModel("x", (0.0,), 0.1, 10.0, min_range=10.0)


def test_every_beam_returns_in_a_closed_room():
    """Noise-free, in a room: one point per beam, at the model's elevations and azimuths."""
    model = VELODYNE_HDL32.with_azimuth_step(COARSE)
    cloud = simulate_lidar(room(), pose_at(0.3, -0.2, 1.5, yaw=0.7), model, noise_std=0.0)
    assert isinstance(cloud, PointCloud) and len(cloud) == model.n_beams == 32 * 90
    p = cloud.points.reshape(model.n_columns, model.n_lasers, 3)
    el = np.arctan2(p[..., 2], np.hypot(p[..., 0], p[..., 1]))
    np.testing.assert_allclose(el, np.broadcast_to(model.elevations, el.shape), atol=1e-12)
    az = np.arctan2(p[..., 1], p[..., 0])
    np.testing.assert_allclose(az[:, 0], model.azimuths(), atol=1e-12)
    np.testing.assert_allclose(cloud.origin, (0.3, -0.2, 1.5))
    assert cloud.dropped == 0


def test_no_returns_are_omitted():
    """Over bare ground only the downward lasers that reach it within max_range return."""
    ground = World3D(NO_BOXES, NO_CYLINDERS, ground_z=0.0, bounds=(-1, -1, -1, 1, 1, 1))
    model = VELODYNE_HDL32.with_azimuth_step(COARSE)
    cloud = simulate_lidar(ground, pose_at(0, 0, 1.8), model, noise_std=0.0)
    el = np.array(model.elevations)
    reach = (el < 0) & (1.8 / np.tan(np.maximum(-el, 1e-300)) <= model.max_range)
    assert reach.sum() == 23  # the 1.33°-down laser reaches 77.5 m, the next one points up
    assert len(cloud) == reach.sum() * model.n_columns
    np.testing.assert_allclose(cloud.world_points()[:, 2], 0.0, atol=1e-12)


def test_min_range_drops_near_returns():
    model = LidarModel("near", (0.0,), COARSE, 50.0, min_range=5.0)
    assert len(simulate_lidar(room(3.0), pose_at(0, 0, 1), model, noise_std=0.0)) == 0
    model = LidarModel("near", (0.0,), COARSE, 50.0, min_range=1.0)
    assert len(simulate_lidar(room(3.0), pose_at(0, 0, 1), model, noise_std=0.0)) == 90


def test_lidar_points_lie_on_surfaces(town):
    """Noise-free points: the ray is free just before each point and the point is on a surface;
    just past it the ray is inside a solid (except where it only grazes an edge)."""
    poses = town.default_trajectory(60)
    model = VELODYNE_HDL64.with_azimuth_step(math.radians(2.0))
    for T in poses[::15]:
        cloud = simulate_lidar(town, T, model, noise_std=0.0)
        q = cloud.world_points()
        u = q - cloud.origin
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        assert not town.occupied(q - 1e-6 * u).any()
        assert inflated(town).occupied(q).all()
        assert town.occupied(q + 1e-6 * u).mean() > 0.999
        assert len(cloud) > 0.6 * model.n_beams


def test_lidar_sees_the_third_dimension(town):
    """Under the skywalk, upward beams return from its underside 3.2 m above the sensor."""
    model = LidarModel("up", (math.radians(89.0),), COARSE, 50.0)
    cloud = simulate_lidar(town, pose_at(21.5, 20.0, 1.8), model, noise_std=0.0)
    assert len(cloud) == model.n_columns
    np.testing.assert_allclose(cloud.world_points()[:, 2], 5.0, atol=1e-9)


def test_noise_and_dropout_statistics():
    model = VELODYNE_HDL64.with_azimuth_step(math.radians(1.0))
    pose = pose_at(0.1, 0.2, 2.0)
    truth = simulate_lidar(room(), pose, model, noise_std=0.0)
    noisy = simulate_lidar(room(), pose, model, noise_std=0.05, rng=4)
    assert len(noisy) == len(truth) == model.n_beams
    err = np.linalg.norm(noisy.points, axis=1) - np.linalg.norm(truth.points, axis=1)
    assert abs(err.mean()) < 0.002 and err.std() == pytest.approx(0.05, rel=0.03)
    # noise moves points along their beam only
    cosang = np.einsum("ij,ij->i", noisy.points, truth.points) / (
        np.linalg.norm(noisy.points, axis=1) * np.linalg.norm(truth.points, axis=1))
    np.testing.assert_allclose(cosang, 1.0, atol=1e-12)
    kept = simulate_lidar(room(), pose, model, noise_std=0.0, dropout=0.3, rng=5)
    assert len(kept) / model.n_beams == pytest.approx(0.7, abs=0.01)
    assert len(simulate_lidar(room(), pose, model, noise_std=0.0, dropout=1.0, rng=5)) == 0


def test_seeded_rng_is_deterministic(town):
    T = town.default_trajectory(60)[10]
    model = VELODYNE_HDL32.with_azimuth_step(COARSE)
    a = simulate_lidar(town, T, model, rng=42, dropout=0.1)
    b = simulate_lidar(town, T, model, rng=np.random.default_rng(42), dropout=0.1)
    c = simulate_lidar(town, T, model, rng=43, dropout=0.1)
    np.testing.assert_array_equal(a.points, b.points)
    assert len(a) != len(c) or not np.array_equal(a.points, c.points)
    d1 = simulate_drive(4, model, rng=9, world=town)
    d2 = simulate_drive(4, model, rng=9, world=town)
    for x, y in zip(d1, d2):
        np.testing.assert_array_equal(x.points, y.points)


def test_simulate_lidar_accepts_matrix_or_se3_and_checks(town):
    T = town.default_trajectory(60)[5]
    model = VELODYNE_HDL32.with_azimuth_step(COARSE)
    a = simulate_lidar(town, T, model, noise_std=0.0, stamp=1.5)
    b = simulate_lidar(town, SE3(T), model, noise_std=0.0)
    c = simulate_lidar(town, T, VELODYNE_HDL32, noise_std=0.0, azimuth_step=COARSE)
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.points, c.points)
    np.testing.assert_allclose(a.pose.matrix, T)
    assert a.stamp == 1.5
    with pytest.raises(ShapeError):
        simulate_lidar(town, np.eye(3), model)
    with pytest.raises(InvalidArgumentError):
        simulate_lidar(town, T, model, noise_std=-1.0)
    with pytest.raises(InvalidArgumentError):
        simulate_lidar(town, T, model, dropout=1.5)


def test_simulate_drive(town):
    model = VELODYNE_HDL32.with_azimuth_step(COARSE)
    clouds = simulate_drive(5, model, world=town, noise_std=0.0)
    poses = town.default_trajectory(5)
    assert len(clouds) == 5
    for i, c in enumerate(clouds):
        np.testing.assert_allclose(c.pose.matrix, poses[i])
        assert c.stamp == pytest.approx(0.1 * i)
        assert len(c) > 0.6 * model.n_beams


# ------------------------------------------------------------------ the default world and drive


def test_default_world_contents(town):
    assert len(town.boxes) == 22 and len(town.cylinders) == 22 and town.ground_z == 0.0
    assert town.bounds == (0.0, 0.0, -1.0, 60.0, 40.0, 13.0)
    b = town.boxes
    buildings = b[(b[:, 2] == 0) & ((b[:, 3] - b[:, 0]) * (b[:, 4] - b[:, 1]) > 50)]
    assert len(buildings) == 7 and buildings[:, 5].min() >= 4 and buildings[:, 5].max() <= 12
    assert np.sum(b[:, 2] >= 2.0) == 3  # the skywalk, the awning, the shelter roof
    assert np.sum(town.cylinders[:, 3] > 0) == 6  # five tree crowns and the water tank
    assert np.all(b[:, :2] >= 0) and np.all(b[:, 3:5] <= [60, 40])


def test_default_trajectory(town):
    P = town.default_trajectory(60)
    assert P.shape == (60, 4, 4)
    SE3(P)  # rigid transforms
    np.testing.assert_allclose(P[:, 2, 3], 1.8)
    np.testing.assert_allclose(P[[0, -1], :2, 3], [[3, 20], [38, 36]], atol=1e-9)
    step = np.linalg.norm(np.diff(P[:, :3, 3], axis=0), axis=1)
    assert step.sum() == pytest.approx(48.42, abs=0.01) and np.ptp(step) < 0.01
    # the sensor looks along the path: x axis ≈ direction of travel, no roll or pitch
    fwd = P[1:, :3, 3] - P[:-1, :3, 3]
    fwd /= np.linalg.norm(fwd, axis=1, keepdims=True)
    assert np.all(np.einsum("ij,ij->i", P[:-1, :3, 0], fwd) > 0.99)
    np.testing.assert_allclose(P[:, 2, :3], np.broadcast_to([0, 0, 1], (60, 3)), atol=1e-15)
    assert P[0, 0, 0] == pytest.approx(1.0) and P[-1, 1, 0] == pytest.approx(1.0)  # east, then north
    assert town.default_trajectory(2, height=2.5)[:, 2, 3].tolist() == [2.5, 2.5]
    with pytest.raises(InvalidArgumentError):
        town.default_trajectory(1)
    with pytest.raises(InvalidArgumentError):
        World3D(BOX.boxes, NO_CYLINDERS).default_trajectory(10)


def test_default_trajectory_stays_in_free_space(town):
    """A 1.5 m ring around every pose is free from just above the ground to 2.5 m, the sensor
    passes under the skywalk, and nothing is within 1.5 m of the sensor itself."""
    P = town.default_trajectory(300)
    ang = np.linspace(0, 2 * np.pi, 72, endpoint=False)
    for h in (0.05, 0.5, 1.0, 1.5, 1.8, 2.5):
        for r in (0.5, 1.0, 1.5):
            ring = np.stack(np.broadcast_arrays(P[:, 0, 3, None] + r * np.cos(ang),
                                                P[:, 1, 3, None] + r * np.sin(ang), h), axis=-1)
            assert not town.occupied(ring).any()
    up = town.cast(P[:, :3, 3], np.tile([0.0, 0.0, 1.0], (300, 1)))
    assert np.any(np.isclose(up, 3.2))
    d = np.random.default_rng(0).normal(size=(300, 3))
    assert np.all(town.cast(P[:, :3, 3], d) > 1.5)


# ------------------------------------------------------------------ voxel truth


def test_truth_voxels_centre_mode_matches_occupied(town):
    res = 0.25
    vt = town.truth_voxels(res, (18.0, 10.0, -0.6), (40.0, 30.0, 8.0))
    kmin = np.floor(np.array([18.0, 10.0, -0.6]) / res)
    np.testing.assert_array_equal(vt.index_min, kmin)
    assert vt.occupied.shape == (89, 81, 36)
    idx = np.stack(np.meshgrid(*[np.arange(n) for n in vt.occupied.shape], indexing="ij"), -1)
    centres = (idx + vt.index_min + 0.5) * res
    np.testing.assert_array_equal(vt.occupied, town.occupied(centres))
    np.testing.assert_allclose(vt.centres(), centres[vt.occupied])
    np.testing.assert_array_equal(vt.keys(), np.floor(vt.centres() / res).astype(np.int64) + 32768)
    np.testing.assert_allclose(vt.origin, kmin * res)
    assert vt.occupied[:, :, :3].all()  # the ground: centres at z = -0.625, -0.375, -0.125
    assert not vt.occupied[:, :, 3].all()


def test_truth_voxels_overlap_holds_every_lidar_hit(town):
    res = 0.2
    centre = town.truth_voxels(res)
    over = town.truth_voxels(res, mode="overlap")
    assert centre.occupied.shape == over.occupied.shape == (301, 201, 71)
    assert np.all(over.occupied >= centre.occupied)
    assert over.occupied.sum() > centre.occupied.sum()
    model = VELODYNE_HDL32.with_azimuth_step(math.radians(2.0))
    for T in town.default_trajectory(60)[::20]:
        q = simulate_lidar(town, T, model, noise_std=0.0).world_points()
        q = q[np.all((q >= town.bounds[:3]) & (q < town.bounds[3:]), axis=1)]
        k = np.floor(q * (1.0 / res)).astype(np.int64) - over.index_min
        assert over.occupied[k[:, 0], k[:, 1], k[:, 2]].all()


def test_truth_voxels_cylinders_and_validation():
    w = World3D(NO_BOXES, [(0.5, 0.5, 0.3, 0.0, 1.0)], ground_z=None)
    vt = w.truth_voxels(0.1, (0, 0, 0), (0.99, 0.99, 0.99))
    assert vt.occupied.shape == (10, 10, 10)
    c = (np.arange(10) + 0.5) * 0.1
    X, Y = np.meshgrid(c, c, indexing="ij")
    disc = (X - 0.5) ** 2 + (Y - 0.5) ** 2 <= 0.09
    np.testing.assert_array_equal(vt.occupied, np.repeat(disc[:, :, None], 10, axis=2))
    ov = w.truth_voxels(0.1, (0, 0, 0), (0.99, 0.99, 0.99), mode="overlap")
    assert ov.occupied.sum() > vt.occupied.sum() and np.all(ov.occupied >= vt.occupied)
    with pytest.raises(InvalidArgumentError):
        w.truth_voxels(0.0)
    with pytest.raises(InvalidArgumentError):
        w.truth_voxels(0.1, mode="corners")
    with pytest.raises(InvalidArgumentError):
        w.truth_voxels(0.1, (1, 1, 1), (0, 0, 0))
    with pytest.raises(ShapeError):
        w.truth_voxels(0.1, (0, 0), (1, 1))
