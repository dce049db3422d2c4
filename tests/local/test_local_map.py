"""occmap.local.LocalMap: rolling window, sensing rules, forgetting, path checks, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

from occmap.errors import InvalidArgumentError, NonFiniteError
from occmap.logodds import logit
from occmap.local import LETHAL, LocalMap
from occmap.raster.walk2d import traverse_2d

L_HIT, L_MISS, L_MIN, L_MAX = logit(0.7), logit(0.4), logit(0.1192), logit(0.971)


# ------------------------------------------------------------------ a reference built from occmap.raster.walk2d


def reference_log_odds(lm: LocalMap, scans):
    """Log-odds (window order, NaN unknown) from first principles: per scan, every end cell of a
    return is hit once, then one exact traversal (occmap.raster.walk2d) from the sensor to the centre
    of each distinct end cell frees the cells before it that this scan has not yet updated."""
    H, W = lm.shape
    res = lm.resolution
    gx0, gy0 = (np.rint(lm.origin / res)).astype(int)
    L = np.zeros((H, W))
    seen = np.zeros((H, W), bool)
    for pose, ranges, angles, max_range in scans:
        done = np.zeros((H, W), bool)
        ends, kinds = [], []
        for r, a in zip(ranges, angles):
            if not r > 0:
                continue
            k = 1 if r < max_range else 2
            r = min(r, max_range)
            ends.append((pose[0] + r * math.cos(pose[2] + a), pose[1] + r * math.sin(pose[2] + a)))
            kinds.append(k)
        cells = np.floor(np.array(ends) / res).astype(int)
        for (cx, cy), k in zip(cells, kinds):
            wx, wy = cx - gx0, cy - gy0
            if k == 1 and 0 <= wx < W and 0 <= wy < H and not done[wy, wx]:
                done[wy, wx] = seen[wy, wx] = True
                L[wy, wx] = min(max(L[wy, wx] + L_HIT, L_MIN), L_MAX)
        for cx, cy in {(int(a), int(b)) for a, b in cells}:
            iy, ix, _ = traverse_2d(pose[:2], ((cx + 0.5) * res, (cy + 0.5) * res), res)
            for y, x in zip(iy[:-1] - gy0, ix[:-1] - gx0):
                if 0 <= x < W and 0 <= y < H and not done[y, x]:
                    done[y, x] = seen[y, x] = True
                    L[y, x] = min(max(L[y, x] + L_MISS, L_MIN), L_MAX)
    return np.where(seen, L, np.nan)


def random_scan(rng, centre, n=180, max_range=6.0):
    pose = np.array([centre[0] + rng.uniform(-0.5, 0.5), centre[1] + rng.uniform(-0.5, 0.5), rng.uniform(-3, 3)])
    angles = np.linspace(-math.pi, math.pi, n, endpoint=False)
    ranges = rng.uniform(0.2, 1.3 * max_range, n)  # some beyond max_range: clear only
    ranges[rng.random(n) < 0.05] = np.nan
    return pose, ranges, angles, max_range


@pytest.mark.parametrize("parallel", [False, True])
def test_insert_scan_matches_exact_traversal_reference(parallel):
    rng = np.random.default_rng(1)
    lm = LocalMap((6.0, 5.0), 0.1, center=(1.0, -2.0))
    lm.parallel = parallel  # two threads: the window cut at the sensor's column
    lm.move_to(1.73, -1.61)  # storage offsets ≠ 0: the circular indexing is exercised
    scans = [random_scan(rng, (1.7, -1.6)) for _ in range(4)]  # rays cross the window's edges
    for t, (pose, ranges, angles, max_range) in enumerate(scans):
        lm.insert_scan(pose, ranges, angles, stamp=float(t), max_range=max_range)
    ref = reference_log_odds(lm, scans)
    got = lm.log_odds()
    np.testing.assert_array_equal(np.isnan(got), np.isnan(ref))
    np.testing.assert_allclose(got[~np.isnan(got)], ref[~np.isnan(ref)], atol=1e-5)


# ------------------------------------------------------------------ moving


@pytest.mark.parametrize("k", [(1, 0), (0, -3), (7, 5), (-12, 4), (39, -2), (60, 0)])
def test_move_touches_only_the_strips_that_left(k):
    lm = LocalMap((4.0, 3.0), 0.1)  # W = 40, H = 30
    H, W = lm.shape
    kx, ky = k
    touched = lm.move_to(kx * 0.1 + 1e-6, ky * 0.1 + 1e-6)
    if abs(kx) >= W or abs(ky) >= H:
        assert touched == H * W
    else:
        assert touched == abs(kx) * H + abs(ky) * W  # O(k · width): never the whole window
        assert touched < H * W or (kx and ky)


@pytest.mark.parametrize("half_life", [None, 3.0])
@pytest.mark.parametrize("shift", [(0.73, 0.0), (-1.26, 0.41), (2.2, -1.9), (-0.05, 1.17), (9.0, 0.0)])
def test_move_equals_rebuild_from_scratch(shift, half_life):
    rng = np.random.default_rng(5)
    a = LocalMap((5.0, 4.0), 0.1, half_life=half_life)
    a.move_to(0.31, 0.22)  # start with non-zero storage offsets
    scans = [random_scan(rng, (0.3, 0.2), max_range=4.0) for _ in range(3)]
    for t, s in enumerate(scans):
        a.insert_scan(s[0], s[1], s[2], stamp=0.5 * t, max_range=s[3])
    before = a.log_odds()
    origin_before = a.origin
    a.move_to(0.31 + shift[0], 0.22 + shift[1])
    # rebuilt: a fresh map at the new place given the same scans
    b = LocalMap((5.0, 4.0), 0.1, half_life=half_life, center=(0.31 + shift[0], 0.22 + shift[1]))
    for t, s in enumerate(scans):
        b.insert_scan(s[0], s[1], s[2], stamp=0.5 * t, max_range=s[3])
    np.testing.assert_array_equal(a.origin, b.origin)
    la, lb = a.log_odds(), b.log_odds()
    H, W = a.shape
    d = np.rint((a.origin - origin_before) / 0.1).astype(int)
    stayed = np.zeros((H, W), bool)
    ys, xs = np.mgrid[0:H, 0:W]
    stayed[(xs + d[0] >= 0) & (xs + d[0] < W) & (ys + d[1] >= 0) & (ys + d[1] < H)] = True
    # the cells that stayed hold what they held, and what a rebuild gives them
    np.testing.assert_array_equal(la[stayed], lb[stayed])
    np.testing.assert_array_equal(la[stayed], before[(ys + d[1])[stayed], (xs + d[0])[stayed]])
    # nothing remains of the cells that left: the entering ones are unknown
    assert np.isnan(la[~stayed]).all()
    assert not a.observed[~stayed].any()
    np.testing.assert_array_equal(a.occupancy()[~stayed], -1)
    assert set(np.unique(a.costmap()[0][~stayed])) <= {253, 255}  # unknown (253: within the inscribed radius)


# ------------------------------------------------------------------ forgetting


def test_decay_leaves_lethal_at_the_predicted_time():
    lm = LocalMap((4.0, 4.0), 0.1, half_life=2.0)
    pose = np.array([0.0, 0.0, 0.0])
    for t in range(12):  # one beam, hit 12 times: the cell reaches the upper clamp
        lm.insert_scan(pose, [1.0], [0.0], stamp=0.01 * t, max_range=5.0)
    cell = lm.world_to_cell(np.array([1.0, 0.0]))
    l0 = lm.log_odds()[tuple(cell)]
    assert l0 == pytest.approx(L_MAX, abs=1e-5)
    T = lm.time_to_clear()
    assert T == pytest.approx(2.0 * math.log2(L_MAX / logit(0.65)))
    assert 4.9 < T < 5.1
    t_last = 0.11
    lm.advance_time(t_last + T - 1e-3)
    assert lm.cost_at([1.0, 0.0]) == LETHAL
    lm.advance_time(t_last + T + 1e-3)
    assert lm.cost_at([1.0, 0.0]) != LETHAL
    assert lm.log_odds()[tuple(cell)] == pytest.approx(l0 * 2 ** (-(T + 1e-3) / 2.0), rel=1e-5)
    # after many half-lives the folded global factor keeps values exact
    lm.advance_time(t_last + 70.0)
    assert lm.log_odds()[tuple(cell)] == pytest.approx(l0 * 2 ** (-(70.0 - 0.0) / 2.0), rel=1e-4, abs=1e-12)


def test_refreshed_free_space_clears_faster_than_decay():
    lm = LocalMap((6.0, 6.0), 0.1, half_life=10.0)
    pose = np.array([0.0, 0.0, 0.0])
    for t in range(12):
        lm.insert_scan(pose, [1.5], [0.0], stamp=0.1 * t, max_range=5.0)
    assert lm.cost_at([1.5, 0.0]) == LETHAL
    t = 1.2
    while lm.cost_at([1.5, 0.0]) == LETHAL:  # the obstacle is gone: the beam now reads 3 m
        lm.insert_scan(pose, [3.0], [0.0], stamp=t, max_range=5.0)
        t += 0.1
    assert t - 1.1 < 0.5 * lm.time_to_clear()


# ------------------------------------------------------------------ scenario


def test_corridor_with_a_crossing_person():
    """The robot drives down a corridor while a person crosses in front of it; 2 s half-life."""
    from occmap.sim.world2d import World2D, simulate_lidar

    walls = np.array([[-5.0, -1.0, 40.0, -1.0], [-5.0, 1.0, 40.0, 1.0]])
    half_life, dt, speed = 2.0, 0.1, 0.5
    lm = LocalMap((6.0, 6.0), 0.05, half_life=half_life)
    rng = np.random.default_rng(3)
    person_x, person_r = 4.0, 0.25
    leave_t = None
    person_cells = set()
    T = lm.time_to_clear()
    for step in range(int(16.0 / dt)):
        t = step * dt
        x = speed * t
        # the person walks across (from y = −0.8 to +0.8) during t ∈ [2, 4], then is gone
        if 2.0 <= t <= 4.0:
            py = -0.8 + 0.8 * (t - 2.0)
            circles = np.array([[person_x, py, person_r]])
        else:
            circles = np.zeros((0, 3))
            if t > 4.0 and leave_t is None:
                leave_t = t - dt
        world = World2D(walls, circles, (-6.0, -2.0, 41.0, 2.0))
        pose = np.array([x, 0.0, 0.0])
        lm.move_to(x, 0.0)
        scan = simulate_lidar(world, pose, n_beams=180, fov=math.radians(240), max_range=8.0, sigma=0.005, rng=rng)
        # the person is only seen through a narrow window in the scan: the rest of the time their
        # cells are occluded by nothing but also not re-observed (the beams are cut to 3.5 m)
        lm.insert_scan(pose, scan.ranges, scan.angles, stamp=t, max_range=scan.max_range)
        if 2.0 <= t <= 4.0:
            cost, origin = lm.costmap()
            cells = np.argwhere(cost == LETHAL)
            for wy, wx in cells:
                c = lm.cell_to_world(np.array([wy, wx]))
                if abs(c[1]) < 0.85 and abs(c[0] - person_x) < 0.5:
                    person_cells.add((round(c[0], 4), round(c[1], 4)))
        if leave_t is not None and t >= leave_t + T + dt:
            break
    assert len(person_cells) >= 5, "the person was mapped as an obstacle while crossing"
    pts = np.array(sorted(person_cells))
    # within the predicted time after leaving, none of the person's cells is lethal any more
    assert (lm.cost_at(pts) != LETHAL).all()
    # the walls (re-observed every scan) stay lethal where the robot sees them beside it
    xs = np.arange(x - 1.5, x + 1.5, 0.05)
    for wall_y in (-1.0, 1.0):  # the wall lies on a cell boundary: its hits fill one of the two rows
        lethal = [(lm.cost_at(np.stack([xs, np.full_like(xs, wall_y + dy)], 1)) == LETHAL) for dy in (-0.025, 0.025)]
        assert (lethal[0] | lethal[1]).mean() > 0.95
    # the corridor's start has left the window: nothing of it remains, even when the window
    # comes back over it (the walls there were lethal while the robot was near)
    far_edge = lm.origin[0]
    assert far_edge > 0.5
    lm.move_to(0.0, 0.0)
    occ, origin = lm.occupancy(), lm.origin
    back = lm.world_to_cell(np.array([[-0.5, -1.0], [-0.5, 0.99], [0.2, 0.0]]))
    assert (occ[back[:, 0], back[:, 1]] == -1).all()
    centres_x = origin[0] + (np.arange(lm.shape[1]) + 0.5) * lm.resolution
    assert (occ[:, centres_x < far_edge] == -1).all()
    assert (occ[:, centres_x > far_edge] != -1).any()


def test_corridor_person_decays_without_reobservation():
    """The same with the person's cells never seen again (the beams that saw them are gone):
    they leave lethal by decay alone, within the formula's time and not before."""
    lm = LocalMap((10.0, 10.0), 0.1, half_life=2.0)
    pose = np.array([0.0, 0.0, 0.0])
    angles = np.radians(np.arange(-10.0, 10.5, 1.0))
    t = 0.0
    for _ in range(15):  # the person stands 2 m ahead: every beam ends on them
        lm.insert_scan(pose, np.full(angles.shape, 2.0), angles, stamp=t, max_range=8.0)
        t += 0.1
    seen = np.argwhere(lm.costmap()[0] == LETHAL)
    assert len(seen) >= 3
    t_last = t - 0.1
    T = lm.time_to_clear()
    lm.advance_time(t_last + 0.98 * T)
    cost = lm.costmap()[0]
    assert (cost[seen[:, 0], seen[:, 1]] == LETHAL).any()
    lm.advance_time(t_last + T + 1e-6)
    cost = lm.costmap()[0]
    assert (cost[seen[:, 0], seen[:, 1]] != LETHAL).all()  # unknown again (255): forgotten


# ------------------------------------------------------------------ 3D clouds


def test_insert_point_cloud_height_band(data_dir):
    from occmap.io.pointclouds import read_pcd

    cloud = read_pcd(data_dir / "scans3d" / "hdl32_pair" / "251370668.pcd")
    pts = cloud.world_points()
    lm = LocalMap((40.0, 40.0), 0.1)
    bad = pts.copy()
    bad[::1000, 1] = np.nan
    out = lm.insert_point_cloud(bad, cloud.origin, stamp=0.0, z_min=-1.5, z_max=0.5)
    assert out["dropped"] == len(pts[::1000])
    assert lm.stats["dropped"] == out["dropped"]
    assert out["points"] == len(pts) - out["dropped"]
    band = (pts[:, 2] >= -1.5) & (pts[:, 2] <= 0.5) & np.isfinite(bad).all(1)
    wc = lm.world_to_cell(pts[:, :2])
    inside = ((wc >= 0) & (wc < np.array(lm.shape))).all(1)
    # every band point's cell is an obstacle (one scan: hit → l_hit ≥ occupied? 0.7 ≥ 0.65)
    assert (lm.cost_at(pts[band & inside][:, :2]) == LETHAL).all()
    # ground points mark nothing: a cell is hit exactly when a band point ends in it
    occ = lm.occupancy()
    assert occ.dtype == np.int8 and set(np.unique(occ)) <= {-1, 40, 50, 70}
    hit = np.zeros(lm.shape, bool)
    c = lm.world_to_cell(pts[band & inside][:, :2])
    hit[c[:, 0], c[:, 1]] = True
    np.testing.assert_array_equal(occ == 70, hit)


def test_parallel_and_serial_give_the_same_cells(data_dir):
    from occmap.io.pointclouds import read_pcd

    pts = read_pcd(data_dir / "scans3d" / "hdl32_pair" / "251371071.pcd").world_points()
    maps = []
    for parallel in (False, True):
        lm = LocalMap((30.0, 30.0), 0.1, half_life=2.0)
        lm.parallel = parallel
        counts = []
        for k in range(3):
            shift = np.array([0.37 * k, -0.21 * k, 0.0])
            lm.move_to(shift[0], shift[1])
            counts.append(lm.insert_point_cloud(pts + shift, shift, 0.1 * k, -1.5, 0.5))
        maps.append((lm, counts))
    (a, ca), (b, cb) = maps
    assert ca == cb
    np.testing.assert_array_equal(a._cells, b._cells)
    np.testing.assert_array_equal(a.costmap()[0], b.costmap()[0])


# ------------------------------------------------------------------ queries


def point_in_polygon(px, py, poly):
    inside = np.zeros(px.shape, bool)
    n = len(poly)
    for i in range(n):
        (xa, ya), (xb, yb) = poly[i], poly[(i + 1) % n]
        cross = ((ya <= py) & (py < yb)) | ((yb <= py) & (py < ya))
        with np.errstate(divide="ignore", invalid="ignore"):
            xi = xa + (py - ya) * (xb - xa) / (yb - ya)
        inside ^= cross & (px < xi)
    return inside


def brute_costs(cost, origin, res, pose, footprint):
    H, W = cost.shape
    c, s = math.cos(pose[2]), math.sin(pose[2])
    poly = np.array([[pose[0] + c * x - s * y, pose[1] + s * x + c * y] for x, y in footprint])
    ys, xs = np.mgrid[-5:H + 5, -5:W + 5]
    cx = origin[0] + (xs + 0.5) * res
    cy = origin[1] + (ys + 0.5) * res
    cells = set(zip(ys[point_in_polygon(cx, cy, poly)], xs[point_in_polygon(cx, cy, poly)]))
    for i in range(len(poly)):
        iy, ix, _ = traverse_2d(poly[i], poly[(i + 1) % len(poly)], res, origin)
        cells |= set(zip(iy, ix))
    iy, ix, _ = traverse_2d(pose[:2], pose[:2], res, origin)
    cells.add((iy[0], ix[0]))
    return [int(cost[y, x]) if 0 <= y < H and 0 <= x < W else 255 for y, x in cells]


def test_check_path_matches_brute_force_and_reports_first_collision():
    rng = np.random.default_rng(11)
    lm = LocalMap((6.0, 6.0), 0.1, half_life=None, footprint=[[0.3, 0.2], [-0.2, 0.2], [-0.2, -0.2], [0.3, -0.2]])
    pose = np.array([0.0, 0.0, 0.0])
    angles = np.linspace(-math.pi, math.pi, 360, endpoint=False)
    ranges = 1.5 + 0.8 * np.sin(3 * angles) + rng.normal(0, 0.01, 360)
    for t in range(5):  # free cells need 4 misses to fall below the free threshold (p < 0.196)
        lm.insert_scan(pose, ranges, angles, stamp=float(t), max_range=5.0)
    cost, origin = lm.costmap()
    poses = np.column_stack([rng.uniform(-2.5, 2.5, 60), rng.uniform(-2.5, 2.5, 60), rng.uniform(-3, 3, 60)])
    poses[7] = np.nan
    concave = [[0.3, 0.2], [-0.2, 0.2], [0.0, 0.0], [-0.2, -0.2], [0.3, -0.2]]
    for fp in (lm.footprint, concave):
        res = lm.check_path(poses, fp)
        assert res.dropped == 1 and res.max_cost[7] == 255
        hit = []
        for i, p in enumerate(poses):
            if i != 7:
                costs = brute_costs(cost, origin, 0.1, p, fp)
                assert res.max_cost[i] == max(costs), i
                if LETHAL in costs:
                    hit.append(i)
        assert res.first_collision == (hit[0] if hit else -1)
    # a straight path from the centre outwards collides where the footprint first meets a wall
    path = np.column_stack([np.linspace(0, 2.8, 200), np.zeros(200), np.zeros(200)])
    res = lm.check_path(path)
    assert res.first_collision > 0 and (res.max_cost[:res.first_collision] != LETHAL).all()
    unk = lm.check_path(path, unknown_is_collision=True)
    assert 0 <= unk.first_collision <= res.first_collision
    # a radius footprint
    rad = lm.check_path(path, 0.2)
    assert rad.first_collision >= res.first_collision - 10


def test_cost_at_frames():
    lm = LocalMap((6.0, 6.0), 0.1)
    angles = np.linspace(-math.pi, math.pi, 360, endpoint=False)
    lm.insert_scan([0.0, 0.0, 0.0], np.full(360, 2.0), angles, stamp=0.0, max_range=5.0)
    robot = np.array([0.5, -0.3, 0.7])
    body = np.array([[1.0, 0.0], [0.0, 1.0], [-0.4, 0.2], [np.nan, 0.0]])
    c, s = math.cos(0.7), math.sin(0.7)
    world = np.column_stack([0.5 + c * body[:, 0] - s * body[:, 1], -0.3 + s * body[:, 0] + c * body[:, 1]])
    np.testing.assert_array_equal(lm.cost_at(body, frame="body", robot_pose=robot), lm.cost_at(world))
    assert lm.cost_at(body, frame="body", robot_pose=robot)[3] == 255
    assert lm.cost_at([[100.0, 0.0]])[0] == 255
    with pytest.raises(InvalidArgumentError):
        lm.cost_at(body, frame="body")


# ------------------------------------------------------------------ bad input


def test_bad_input():
    lm = LocalMap((4.0, 4.0), 0.1, half_life=1.0)
    angles = np.linspace(-1, 1, 5)
    out = lm.insert_scan([0, 0, 0], [1.0, np.nan, 2.0, -1.0, 0.5], angles, stamp=1.0, max_range=3.0)
    assert out["dropped"] == 2 and lm.stats["dropped"] == 2
    assert out["points"] == 3 and lm.stats["points"] == 3  # the grid's and octree's rule: dropped are not used
    out = lm.insert_scan([np.nan, 0, 0], [1.0] * 5, angles, stamp=1.5, max_range=3.0)
    assert out["dropped_pose"] and lm.stats["dropped_poses"] == 1
    with pytest.raises(InvalidArgumentError, match="backwards"):
        lm.insert_scan([0, 0, 0], [1.0] * 5, angles, stamp=1.2, max_range=3.0)
    with pytest.raises(InvalidArgumentError, match="backwards"):
        lm.insert_point_cloud(np.zeros((3, 3)), (0, 0, 0), stamp=0.0, z_min=0, z_max=1)
    lm.insert_scan([0, 0, 0], [1.0] * 5, angles, stamp=1.5, max_range=3.0)  # equal stamps are fine
    with pytest.raises(NonFiniteError):
        lm.move_to(np.nan, 0.0)
    with pytest.raises(InvalidArgumentError):
        lm.insert_scan([0, 0, 0], [1.0] * 5, angles, stamp=np.nan)
    with pytest.raises(InvalidArgumentError):
        LocalMap((4.0, 4.0), 0.1, footprint=[[1, 1], [-1, -1], [1, -1], [-1, 1]])  # a bow tie
    with pytest.raises(InvalidArgumentError):
        lm.check_path(np.zeros((2, 3)), footprint=[[1, 1], [-1, -1], [1, -1], [-1, 1]])
    with pytest.raises(InvalidArgumentError):
        LocalMap((4.0, 4.0), 0.0)
    with pytest.raises(InvalidArgumentError):
        LocalMap((4.0, 4.0), 0.1, half_life=-1.0)


def test_replay_cli_writes_an_animation(data_dir, tmp_path, capsys):
    from PIL import Image

    from occmap.cli import main

    out = tmp_path / "local.gif"
    assert main(["local", str(data_dir / "carmen" / "intel-corrected.log.gz"), "-o", str(out),
                 "--max-frames", "4", "--size", "12"]) == 0
    with Image.open(out) as im:
        assert im.n_frames == 4 and im.size[0] > 240 and im.size[1] > 240  # 120 × 120 cells, 2 px each, and the key
    assert "frames" in capsys.readouterr().out


def test_check_path_lethal_collides_even_beside_unknown():
    """A footprint reaching across a wall covers lethal cells and the unknown space behind them:
    max_cost reports 255 (unknown ranks highest), but the pose is a collision."""
    local = LocalMap(size=(20.0, 20.0), resolution=0.1)
    angles = np.linspace(-np.pi, np.pi, 720, endpoint=False)
    local.insert_scan((0.0, 0.0, 0.0), np.full(720, 3.0), angles, stamp=0.0)
    box = [[0.3, 0.2], [-0.3, 0.2], [-0.3, -0.2], [0.3, -0.2]]
    check = local.check_path(np.array([[0.0, 0.0, 0.0], [2.9, 0.0, 0.0]]), footprint=box)
    assert check.max_cost[1] == 255 and check.first_collision == 1
    disc = local.check_path(np.array([[0.0, 0.0, 0.0], [2.9, 0.0, 0.0]]), footprint=0.3)
    assert disc.first_collision == 1


def test_log_odds_at_occupancy_at_and_lethal_read_the_window_cells():
    """Per point, the value log_odds() holds in its cell (after a move, so the ring is started
    mid-buffer, and with forgetting); NaN / −1 outside the window, in unknown cells and for NaN
    points; occupied from occupied_threshold on."""
    lm = LocalMap((4.0, 3.0), 0.1, half_life=1.0, occupied_threshold=0.6)
    angles = np.linspace(-np.pi, np.pi, 90, endpoint=False)
    lm.insert_scan((0.0, 0.0, 0.0), np.full(90, 1.0), angles, stamp=0.0, max_range=5.0)
    lm.move_to(0.35, -0.25)
    lm.insert_scan((0.35, -0.25, 0.0), np.full(90, 0.8), angles, stamp=0.4, max_range=5.0)
    H, W = lm.shape
    cells = np.stack(np.meshgrid(np.arange(H), np.arange(W), indexing="ij"), -1)
    centres = lm.cell_to_world(cells)
    full = lm.log_odds()
    at = lm.log_odds_at(centres)
    assert at.shape == (H, W) and at.dtype == np.float64
    np.testing.assert_array_equal(at, full)
    occ = lm.occupancy_at(centres)
    np.testing.assert_array_equal(occ == -1, np.isnan(full))
    np.testing.assert_array_equal(occ == 1, np.nan_to_num(full, nan=-np.inf) >= logit(0.6))
    np.testing.assert_array_equal(lm.lethal(), occ == 1)
    assert (occ == 1).any() and (occ == 0).any() and (occ == -1).any()
    outside = [[lm.origin[0] - 0.05, lm.origin[1] + 1.0], [lm.origin[0] + 1.0, lm.origin[1] + 3.05], [np.nan, 0.0]]
    assert np.isnan(lm.log_odds_at(outside)).all() and (lm.occupancy_at(outside) == -1).all()


def test_replay_frames_are_capped_by_the_memory_available(tmp_path, monkeypatch, capsys):
    """`occmap local` holds its frames until the GIF is written: asked for more than a third of the
    available memory holds, it draws fewer and says so (a whole-log replay once took every byte)."""
    from PIL import Image

    from occmap.cli import main
    from occmap.commands import local

    log = tmp_path / "walk.log"
    ranges = " ".join(["2.0"] * 181)
    log.write_text("".join(f"FLASER 181 {ranges} {0.1 * i} 0 0 {0.1 * i} 0 0 {i}.0 host {i}.0\n" for i in range(12)))
    out = tmp_path / "local.gif"
    args = ["local", str(log), "-o", str(out), "--size", "6", "--frame-every", "1", "--max-frames", "10"]
    assert main(args) == 0
    with Image.open(out) as im:
        assert im.n_frames == 10
        frame = im.size[0] * im.size[1]
    monkeypatch.setattr(local, "_available_memory", lambda: 3 * 4 * frame + 1)
    assert main(args) == 0
    with Image.open(out) as im:
        assert im.n_frames == 4
    assert "--max-frames 10 lowered to 4" in capsys.readouterr().out
