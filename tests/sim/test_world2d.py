"""The synthetic 2D world: exact ray casting (hand cases and a brute-force reference), the simulated
lidar and sonar, the default office and its trajectory, and the ground-truth rasters."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from occmap.errors import InvalidArgumentError, NonFiniteError, ShapeError
from occmap.scan import LaserScan
from occmap.sim.world2d import World2D, default_path, simulate_lidar, simulate_scans, simulate_sonar

NO_CIRCLES = np.zeros((0, 3))
NO_SEGMENTS = np.zeros((0, 4))


@pytest.fixture(scope="module")
def office():
    return World2D.default()


def world(segments=NO_SEGMENTS, circles=NO_CIRCLES, bounds=(-50.0, -50.0, 50.0, 50.0)):
    return World2D(segments, circles, bounds)


# ------------------------------------------------------------------ brute-force references


def ref_cast(segments, circles, origin, angle, max_range):
    """One ray, written independently of the kernel: a batched 2×2 solve for the walls, the
    textbook quadratic for the discs."""
    p = np.asarray(origin, dtype=float)
    d = np.array([math.cos(angle), math.sin(angle)])
    best = math.inf
    segs = np.asarray(segments, dtype=float).reshape(-1, 4)
    if len(segs):
        a, b = segs[:, :2], segs[:, 2:]
        A = np.empty((len(segs), 2, 2))
        A[:, :, 0] = d  # p + t d = a + u (b - a)
        A[:, :, 1] = a - b
        ok = np.abs(np.linalg.det(A)) > 1e-300  # parallel walls: never drawn by the random cases
        tu = np.linalg.solve(A[ok], (a - p)[ok][:, :, None])[:, :, 0]
        t, u = tu[:, 0], tu[:, 1]
        t = t[(t >= 0) & (u >= 0) & (u <= 1)]
        if len(t):
            best = float(t.min())
    for cx, cy, r in circles:
        f = p - (cx, cy)
        if f @ f <= r * r:
            best = 0.0
            continue
        bb = 2 * (f @ d)
        cc = f @ f - r * r
        disc = bb * bb - 4 * cc
        if disc < 0:
            continue
        for t in ((-bb - math.sqrt(disc)) / 2, (-bb + math.sqrt(disc)) / 2):
            if t >= 0:
                best = min(best, t)
                break
    return best if best <= max_range else math.inf


def dist_to_world(w, pts):
    """Distance from points (N, 2) to the nearest wall or disc surface, by plain NumPy."""
    pts = np.asarray(pts, dtype=float)
    out = np.full(len(pts), np.inf)
    for x0, y0, x1, y1 in w.segments:
        a = np.array([x0, y0])
        e = np.array([x1 - x0, y1 - y0])
        t = np.clip(((pts - a) @ e) / (e @ e), 0, 1)
        out = np.minimum(out, np.linalg.norm(pts - a - t[:, None] * e, axis=1))
    for cx, cy, r in w.circles:
        out = np.minimum(out, np.linalg.norm(pts - (cx, cy), axis=1) - r)
    return out


# ------------------------------------------------------------------ ray casting, by hand


def test_ray_perpendicular_to_wall():
    w = world(segments=[[2.0, -1.0, 2.0, 1.0]])
    assert w.cast([[0.0, 0.0]], [0.0])[0] == 2.0
    assert w.cast([[0.0, 0.5]], [0.0])[0] == 2.0
    # a wall at 45°: from (0, 0) along +x to the wall x + y = 2 -> 2
    w = world(segments=[[2.0, 0.0, 0.0, 2.0]])
    assert w.cast([0.0, 0.0], [0.0])[0] == pytest.approx(2.0, abs=1e-15)
    assert w.cast([0.0, 0.0], [np.pi / 4])[0] == pytest.approx(math.sqrt(2.0), abs=1e-15)
    # behind the ray and beside the wall's ends: no hit
    assert np.isinf(w.cast([0.0, 0.0], [np.pi])[0])
    assert np.isinf(world(segments=[[2.0, 1.0, 2.0, 2.0]]).cast([0.0, 0.0], [0.0])[0])


def test_ray_hits_segment_end_exactly():
    w = world(segments=[[2.0, 0.0, 2.0, 1.0]])
    assert w.cast([0.0, 0.0], [0.0])[0] == 2.0  # the end point counts


def test_ray_through_door_gap(office):
    # from the corridor at x = 3 straight down through the 0.9 m door (2.55 .. 3.45) of room A:
    # the next obstacle is the pillar at (3, 3), r = 0.3
    r = office.cast([3.0, 7.5], [-np.pi / 2])[0]
    assert r == pytest.approx(7.5 - 3.3, abs=1e-12)
    # 0.6 m to the side the ray meets the corridor wall instead
    assert office.cast([2.4, 7.5], [-np.pi / 2])[0] == pytest.approx(1.0, abs=1e-12)
    # up through the door at x = 3.5 to the outer wall at y = 15
    assert office.cast([3.5, 7.5], [np.pi / 2])[0] == pytest.approx(7.5, abs=1e-12)
    # x = 3.0 is outside the upper door (3.05 .. 3.95): the corridor wall at 8.5
    assert office.cast([3.0, 7.5], [np.pi / 2])[0] == pytest.approx(1.0, abs=1e-12)


def test_ray_grazing_a_circle():
    # disc of radius 1 at (0, 1): a ray along y = 0 touches it at (0, 0)
    w = world(circles=[[0.0, 1.0, 1.0]])
    assert w.cast([-5.0, 0.0], [0.0])[0] == 5.0
    # lifted by 1e-9 the ray misses
    w2 = world(circles=[[0.0, 1.0 + 1e-9, 1.0]])
    assert np.isinf(w2.cast([-5.0, 0.0], [0.0])[0])
    # head-on
    assert w.cast([-5.0, 1.0], [0.0])[0] == 4.0
    # heading away
    assert np.isinf(w.cast([-5.0, 1.0], [np.pi])[0])


def test_ray_starting_inside_or_on_a_disc_or_wall_reads_zero():
    w = world(segments=[[0.0, -1.0, 0.0, 1.0]], circles=[[5.0, 0.0, 1.0]])
    assert np.all(w.cast([5.2, 0.1], np.linspace(-3, 3, 7)) == 0.0)  # inside the disc
    assert w.cast([4.0, 0.0], [np.pi])[0] == 0.0  # on its rim, facing out
    assert w.cast([0.0, 0.3], [1.0])[0] == 0.0  # on the wall


def test_ray_along_a_wall_hits_its_near_end():
    w = world(segments=[[2.0, 0.0, 5.0, 0.0]])
    assert w.cast([0.0, 0.0], [0.0])[0] == 2.0
    assert w.cast([3.0, 0.0], [0.0])[0] == 0.0
    assert np.isinf(w.cast([6.0, 0.0], [0.0])[0])


def test_max_range_cuts_hits():
    w = world(segments=[[2.0, -1.0, 2.0, 1.0]])
    assert np.isinf(w.cast([0.0, 0.0], [0.0], max_range=1.99)[0])
    assert w.cast([0.0, 0.0], [0.0], max_range=2.0)[0] == 2.0


def test_empty_world_and_empty_batch():
    w = world()
    assert np.all(np.isinf(w.cast(np.zeros((5, 2)), np.arange(5.0))))
    assert w.cast(np.zeros((0, 2)), np.zeros(0)).shape == (0,)


# ------------------------------------------------------------------ ray casting, vs brute force


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_cast_matches_brute_force_reference(seed):
    rng = np.random.default_rng(seed)
    segs = rng.uniform(-10, 10, (40, 4))
    circles = np.column_stack([rng.uniform(-10, 10, (8, 2)), rng.uniform(0.1, 1.5, 8)])
    w = world(segs, circles)
    n = 400
    origins = rng.uniform(-12, 12, (n, 2))
    angles = rng.uniform(-4, 4, n)
    max_range = 15.0
    got = w.cast(origins, angles, max_range)
    want = np.array([ref_cast(segs, circles, o, a, max_range) for o, a in zip(origins, angles)])
    assert np.array_equal(np.isinf(got), np.isinf(want))
    fin = np.isfinite(want)
    assert fin.sum() > n // 2
    assert np.max(np.abs(got[fin] - want[fin])) <= 1e-12


@settings(deadline=None, max_examples=30)
@given(x=st.floats(0.3, 19.7), y=st.floats(0.3, 14.7), angle=st.floats(-4.0, 4.0))
def test_cast_lands_on_the_world_and_nothing_comes_before(office, x, y, angle):
    p = np.array([x, y])
    clear = dist_to_world(office, p[None])[0]
    r = office.cast(p, [angle])[0]
    if clear <= 0.0:
        assert r == 0.0
        return
    assert np.isfinite(r) and r >= clear - 1e-12  # the office is closed
    d = np.array([math.cos(angle), math.sin(angle)])
    assert dist_to_world(office, (p + r * d)[None])[0] <= 1e-9
    before = p + np.linspace(0.0, r, 200)[:-1, None] * d
    assert np.all(dist_to_world(office, before) > 0.0)


def test_parallel_and_serial_kernels_agree(office):
    from occmap.sim import _kernels

    rng = np.random.default_rng(7)
    n = _kernels.PARALLEL_MIN + 123
    o = rng.uniform([0, 0], [20, 15], (n, 2))
    a = rng.uniform(-np.pi, np.pi, n)
    par = office.cast(o, a, 12.0)
    ser = np.empty(n)
    _kernels.cast_rays(o, a, office.segments, office.circles, 12.0, ser)
    assert np.array_equal(par, ser)


def test_cast_rejects_bad_input(office):
    with pytest.raises(ShapeError):
        office.cast(np.zeros((3, 3)), np.zeros(3))
    with pytest.raises(ShapeError):
        office.cast(np.zeros((3, 2)), np.zeros(4))
    with pytest.raises(NonFiniteError):
        office.cast([[np.nan, 0.0]], [0.0])
    with pytest.raises(InvalidArgumentError):
        office.cast([[1.0, 1.0]], [0.0], max_range=0.0)
    with pytest.raises(InvalidArgumentError):
        World2D(NO_SEGMENTS, [[0.0, 0.0, -1.0]], (0, 0, 1, 1))
    with pytest.raises(InvalidArgumentError):
        World2D(NO_SEGMENTS, NO_CIRCLES, (0, 0, -1, 1))


# ------------------------------------------------------------------ lidar


def test_lidar_scan_record(office):
    pose = np.array([1.0, 7.5, 0.3])
    s = simulate_lidar(office, pose, n_beams=360, rng=0, stamp=4.5)
    assert isinstance(s, LaserScan)
    assert len(s) == 360 and s.angles.shape == (360,)
    assert s.angles[0] == -np.pi and np.allclose(np.diff(s.angles), 2 * np.pi / 360)
    assert np.array_equal(s.pose, pose) and s.max_range == 10.0 and s.stamp == 4.5
    s = simulate_lidar(office, pose, n_beams=181, fov=np.pi, rng=0)
    assert s.angles[0] == -np.pi / 2 and s.angles[-1] == np.pi / 2


def test_lidar_noise_statistics(office):
    pose = np.array([3.0, 7.5, 0.0])
    sigma = 0.01
    poses = np.repeat(pose[None], 2000, axis=0)
    scans = simulate_scans(office, poses, n_beams=90, max_range=10.0, sigma=sigma, rng=123)
    R = np.stack([s.ranges for s in scans])
    true = office.cast(pose[:2], pose[2] + scans[0].angles, 10.0)
    hit = np.isfinite(true) & (true < 10.0 - 10 * sigma)
    assert hit.sum() > 50
    err = R[:, hit] - true[hit]
    assert abs(err.mean()) < 3 * sigma / math.sqrt(err.size) + 1e-12
    assert np.all(np.abs(err.mean(axis=0)) < 4 * sigma / math.sqrt(len(R)))
    assert err.std() == pytest.approx(sigma, rel=0.02)


def test_lidar_noise_free_reads_truth(office):
    pose = np.array([9.5, 4.0, 1.0])
    s = simulate_lidar(office, pose, sigma=0.0, max_range=30.0, rng=0)
    want = office.cast(pose[:2], pose[2] + s.angles, 30.0)
    assert np.array_equal(s.ranges, want)


def test_lidar_no_return_reads_exactly_max_range():
    w = world(segments=[[3.0, -1.0, 3.0, 1.0]])
    s = simulate_lidar(w, [0.0, 0.0, 0.0], n_beams=360, max_range=8.0, sigma=0.05, rng=1)
    none = np.isinf(w.cast([0.0, 0.0], s.angles, 8.0))
    assert none.sum() > 300
    assert np.all(s.ranges[none] == 8.0)
    assert np.all(s.ranges[~none] < 3.5)
    assert np.all(s.ranges <= 8.0)
    # a wall beyond max_range is not seen
    s = simulate_lidar(w, [0.0, 0.0, 0.0], n_beams=8, max_range=2.0, sigma=0.0)
    assert np.all(s.ranges == 2.0)


def test_lidar_dropout_gives_nan(office):
    poses = office.default_trajectory(n=50)
    scans = simulate_scans(office, poses, n_beams=200, p_dropout=0.1, rng=5)
    R = np.stack([s.ranges for s in scans])
    frac = np.isnan(R).mean()
    assert frac == pytest.approx(0.1, abs=0.01)
    assert np.all(np.isfinite(R[~np.isnan(R)]))
    assert not np.any(np.isnan(simulate_lidar(office, poses[0], rng=5).ranges))


def test_lidar_outliers_are_short(office):
    pose = np.array([10.5, 7.5, 0.0])
    poses = np.repeat(pose[None], 200, axis=0)
    scans = simulate_scans(office, poses, n_beams=180, sigma=0.001, p_outlier=0.2, rng=9)
    R = np.stack([s.ranges for s in scans])
    true = np.minimum(office.cast(pose[:2], pose[2] + scans[0].angles, 10.0), 10.0)
    short = R < true - 0.01
    assert short.mean() == pytest.approx(0.2, abs=0.02)  # a few outliers land within 1 cm
    assert np.all(R >= 0.0) and np.all(R <= 10.0)


def test_simulate_scans_matches_single_scans(office):
    poses = office.default_trajectory(n=7)
    batch = simulate_scans(office, poses, n_beams=64, sigma=0.0, stamps=np.arange(7) * 0.1)
    for i, s in enumerate(batch):
        one = simulate_lidar(office, poses[i], n_beams=64, sigma=0.0)
        assert np.array_equal(s.ranges, one.ranges)
        assert s.stamp == pytest.approx(0.1 * i)


def test_lidar_rejects_bad_parameters(office):
    with pytest.raises(ShapeError):
        simulate_lidar(office, [1.0, 2.0])
    with pytest.raises(InvalidArgumentError):
        simulate_lidar(office, [1.0, 7.5, 0.0], p_outlier=1.5)
    with pytest.raises(InvalidArgumentError):
        simulate_lidar(office, [1.0, 7.5, 0.0], sigma=-1.0)
    with pytest.raises(InvalidArgumentError):
        simulate_lidar(office, [1.0, 7.5, 0.0], n_beams=0)
    with pytest.raises(InvalidArgumentError):
        simulate_lidar(office, [1.0, 7.5, 0.0], max_range=np.inf)


# ------------------------------------------------------------------ sonar


def _disc_at(bearing_deg, rng_m, r=0.1):
    b = math.radians(bearing_deg)
    return [rng_m * math.cos(b), rng_m * math.sin(b), r]


def test_sonar_sees_off_axis_obstacle_inside_the_cone():
    w = world(circles=[_disc_at(5.0, 3.0)])  # 5° off axis, cone half-width 7.5°
    s = simulate_sonar(w, [0.0, 0.0, 0.0], [0.0], sigma=0.0)
    assert isinstance(s, LaserScan)
    assert 2.9 - 1e-9 <= s.ranges[0] < 3.0
    # a lidar beam on the axis misses it
    assert simulate_lidar(w, [0.0, 0.0, 0.0], n_beams=1, fov=0.1, sigma=0.0, max_range=5.0).ranges[0] == 5.0


def test_sonar_ignores_obstacle_outside_the_cone():
    w = world(circles=[_disc_at(12.0, 3.0)])
    s = simulate_sonar(w, [0.0, 0.0, 0.0], [0.0], sigma=0.0)
    assert s.ranges[0] == 5.0
    # the transducer pointing at it sees it
    s = simulate_sonar(w, [0.0, 0.0, 0.0], [0.0, math.radians(12.0)], sigma=0.0)
    assert s.ranges[0] == 5.0 and s.ranges[1] == pytest.approx(2.9, abs=1e-9)


def test_sonar_takes_the_minimum_over_the_cone():
    # a far wall on the axis and a nearer disc 6° off it: the disc wins
    w = world(segments=[[4.0, -2.0, 4.0, 2.0]], circles=[_disc_at(-6.0, 2.0)])
    s = simulate_sonar(w, [0.0, 0.0, 0.0], [0.0], sigma=0.0)
    # no sample ray passes the disc's centre, so the reading lies a little beyond 1.9
    assert 1.9 - 1e-12 <= s.ranges[0] < 1.91
    # heading rotates the ring: pose facing +y, bearing -90° looks along +x
    s2 = simulate_sonar(w, [0.0, 0.0, np.pi / 2], [-np.pi / 2], sigma=0.0)
    assert s2.ranges[0] == pytest.approx(s.ranges[0], abs=1e-12)
    # the reading is the minimum of the cone's rays
    offs = np.linspace(-np.radians(7.5), np.radians(7.5), 15)
    assert s.ranges[0] == np.min(w.cast([0.0, 0.0], offs, 5.0))


def test_sonar_noise(office):
    bearings = np.radians(np.arange(0, 360, 30))
    rs = np.stack([simulate_sonar(office, [10.5, 7.5, 0.0], bearings, sigma=0.02, rng=i).ranges
                   for i in range(300)])
    clean = simulate_sonar(office, [10.5, 7.5, 0.0], bearings, sigma=0.0).ranges
    hit = clean < 4.5
    assert hit.sum() >= 4
    assert (rs[:, hit] - clean[hit]).std() == pytest.approx(0.02, rel=0.1)
    assert np.all(rs[:, ~hit] == 5.0)


# ------------------------------------------------------------------ the default office


def test_default_world_shape(office):
    xmin, ymin, xmax, ymax = office.bounds
    assert (xmax - xmin, ymax - ymin) == (20.0, 15.0)
    assert len(office.circles) >= 3
    assert len(office.segments) >= 10


def test_default_trajectory_keeps_clear_of_walls(office):
    poses = office.default_trajectory(n=1500)
    assert poses.shape == (1500, 3)
    # sample densely between consecutive poses
    t = np.linspace(0, 1, 11)[:-1]
    pts = (poses[:-1, None, :2] * (1 - t)[None, :, None] + poses[1:, None, :2] * t[None, :, None]).reshape(-1, 2)
    pts = np.vstack([pts, poses[-1:, :2]])
    d = dist_to_world(office, pts)
    assert d.min() >= 0.2
    assert np.allclose(office.clearance(pts), d)
    xmin, ymin, xmax, ymax = office.bounds
    assert np.all((pts > (xmin, ymin)) & (pts < (xmax, ymax)))


def test_default_trajectory_is_smooth_and_tours_the_rooms(office):
    poses = office.default_trajectory(n=2000)
    step = np.linalg.norm(np.diff(poses[:, :2], axis=0), axis=1)
    assert step.max() < 1.05 * np.median(step)  # even spacing by arc length
    dth = np.angle(np.exp(1j * np.diff(poses[:, 2])))
    assert np.abs(dth).max() < 0.3  # no jumps in heading: turn radius above ~0.25 m
    # heading follows the direction of travel
    move = np.arctan2(*np.diff(poses[:, :2], axis=0).T[::-1])
    assert np.abs(np.angle(np.exp(1j * (move - poses[:-1, 2])))).max() < 0.2
    x, y = poses[:, 0], poses[:, 1]
    rooms = [(0, 6, 0, 6.5), (6, 13, 0, 6.5), (13, 20, 0, 6.5),
             (0, 7, 8.5, 15), (7, 14, 8.5, 15), (14, 20, 8.5, 15)]
    for x0, x1, y0, y1 in rooms:
        inside = (x > x0) & (x < x1) & (y > y0) & (y < y1)
        assert inside.sum() > 50, (x0, x1, y0, y1)
    assert np.array_equal(default_path(office, n=2000), poses)


def test_world_without_waypoints_has_no_trajectory():
    with pytest.raises(InvalidArgumentError):
        world().default_trajectory()


# ------------------------------------------------------------------ ground truth


@pytest.mark.parametrize("res", [0.05, 0.1, 0.137])
def test_occupancy_contains_every_wall_and_leaves_open_space_free(office, res):
    occ, origin = office.occupancy(res)
    assert np.array_equal(origin, [0.0, 0.0])
    H, W = occ.shape
    assert W * res >= 20.0 - 1e-9 and H * res >= 15.0 - 1e-9
    # every sampled point of every wall lies in an occupied cell
    for x0, y0, x1, y1 in office.segments:
        t = np.linspace(0, 1, 500)
        px = x0 + t * (x1 - x0)
        py = y0 + t * (y1 - y0)
        ix = np.minimum(np.floor((px - origin[0]) / res).astype(int), W - 1)
        iy = np.minimum(np.floor((py - origin[1]) / res).astype(int), H - 1)
        assert occ[iy, ix].all()
    # discs: the cell under each centre is occupied
    for cx, cy, r in office.circles:
        assert occ[int((cy - origin[1]) // res), int((cx - origin[0]) // res)]
    # a cell whose centre is farther than half its diagonal from everything is free; and an
    # occupied cell's centre is within half a diagonal of something
    c = office.cell_centres(res, origin, occ.shape).reshape(-1, 2)
    d = dist_to_world(office, c).reshape(occ.shape)
    half_diag = res * math.sqrt(2) / 2
    assert not occ[d > half_diag + 1e-9].any()
    assert np.all(d[occ] <= half_diag + 1e-9)


def test_occupancy_random_segments_exact():
    """On random walls, occupancy = cells met by the segment: sampled points are inside, and every
    occupied cell is met by a dense sampling of the segment or touched within rounding."""
    rng = np.random.default_rng(3)
    segs = rng.uniform(0.2, 4.8, (15, 4))
    w = world(segs, bounds=(0.0, 0.0, 5.0, 5.0))
    res = 0.1
    occ, origin = w.occupancy(res)
    hits = np.zeros_like(occ)
    t = np.linspace(0, 1, 20001)
    for x0, y0, x1, y1 in segs:
        ix = np.floor((x0 + t * (x1 - x0)) / res).astype(int)
        iy = np.floor((y0 + t * (y1 - y0)) / res).astype(int)
        hits[iy, ix] = True
    assert occ[hits].all()
    extra = occ & ~hits
    # cells marked beyond the sampled ones: the segment passes within a hair of their square
    for iy, ix in zip(*np.nonzero(extra)):
        box = np.array([ix * res, iy * res, (ix + 1) * res, (iy + 1) * res])
        near = min(_seg_box_distance(s, box) for s in segs)
        assert near < 1e-3


def _seg_box_distance(seg, box):
    x0, y0, x1, y1 = seg
    t = np.linspace(0, 1, 20001)
    px, py = x0 + t * (x1 - x0), y0 + t * (y1 - y0)
    dx = np.maximum(np.maximum(box[0] - px, px - box[2]), 0)
    dy = np.maximum(np.maximum(box[1] - py, py - box[3]), 0)
    return np.hypot(dx, dy).min()


def test_occupancy_custom_origin_and_shape(office):
    occ, origin = office.occupancy(0.1, origin=(-1.0, -1.0), shape=(170, 220))
    assert occ.shape == (170, 220) and np.array_equal(origin, [-1.0, -1.0])
    ref, _ = office.occupancy(0.1)
    # same world, shifted by 10 cells (up to cells whose edges now fall on the walls)
    inner = occ[10:160, 10:210]
    assert np.mean(inner == ref) > 0.995
    assert not occ[:5].any() and not occ[:, :5].any()


def test_free_space_excludes_outside_and_obstacles(office):
    res = 0.1
    free, origin = office.free_space(res, origin=(-1.0, -1.0), shape=(170, 220))
    occ, _ = office.occupancy(res, origin=(-1.0, -1.0), shape=(170, 220))
    c = office.cell_centres(res, origin, free.shape)
    outside = (c[..., 0] < 0) | (c[..., 0] > 20) | (c[..., 1] < 0) | (c[..., 1] > 15)
    assert not free[outside].any()
    assert not (free & occ).any()
    # the start cell and a cell in every room are reachable
    for x, y in [(1.0, 7.5), (1.5, 1.5), (9.0, 1.0), (18.5, 1.0), (2.0, 14.0), (12.0, 14.0), (19.0, 14.0)]:
        assert free[int((y + 1.0) / res), int((x + 1.0) / res)], (x, y)
    # most of the interior is free
    assert free.sum() > 0.9 * (~occ & ~outside).sum()


def test_free_space_excludes_a_closed_room():
    segs = [[0, 0, 10, 0], [10, 0, 10, 10], [10, 10, 0, 10], [0, 10, 0, 0],
            [6, 6, 9, 6], [9, 6, 9, 9], [9, 9, 6, 9], [6, 9, 6, 6]]
    w = World2D(segs, NO_CIRCLES, (0, 0, 10, 10), waypoints=[[1.0, 1.0], [2.0, 2.0]])
    free, origin = w.free_space(0.25)
    assert free[4, 4]
    assert not free[30, 30]  # (7.6, 7.6) inside the closed box
    # an explicit start inside it
    free2, _ = w.free_space(0.25, start=(7.6, 7.6))
    assert free2[30, 30] and not free2[4, 4]


def test_render_png_draws_walls_free_space_and_the_trajectory(office, tmp_path):
    from PIL import Image

    p = office.render_png(tmp_path / "world.png", resolution=0.1)
    rgb = np.asarray(Image.open(p).convert("RGB")).astype(int)
    red = (rgb[..., 0] > 180) & (rgb[..., 1] < 90) & (rgb[..., 2] < 90)
    assert red.sum() > 200  # the default trajectory
    assert (rgb.max(axis=-1) < 60).sum() > 1000  # walls (and text)
