"""The octree against OctoMap: its own unit tests' figures (octomap/src/testing) and voxel-by-voxel
agreement with octomap-python on the same inputs (skipped without octomap-python), and the
tests that need no peer (they run without it)."""

from __future__ import annotations

import bz2
import math
import sys

import numba
import numpy as np
import pytest

from occmap.errors import InvalidArgumentError, ShapeError
from occmap.io.octomap import encode_ot, read_bt
from occmap.octree import OcTree, marking


# ----------------------------------------------------------------------------- helpers

def _octomap():
    """octomap-python, for a test that compares with OctoMap (skipped, saying so, without it)."""
    return pytest.importorskip("octomap", reason="compares with OctoMap itself: octomap-python is not installed")


@numba.njit(cache=False)
def _rotate_ip(v, pitch, yaw):
    """octomath::Vector3::rotate_IP(0, pitch, yaw) on a float32 vector: pitch then yaw, each
    result rounded to float (roll 0 leaves the value unchanged)."""
    x, z = np.float64(v[0]), np.float64(v[2])
    v[0] = np.float32(z * math.sin(pitch) + x * math.cos(pitch))
    v[2] = np.float32(z * math.cos(pitch) - x * math.sin(pitch))
    x, y = np.float64(v[0]), np.float64(v[1])
    v[0] = np.float32(x * math.cos(yaw) - y * math.sin(yaw))
    v[1] = np.float32(x * math.sin(yaw) + y * math.cos(yaw))
    y, z = np.float64(v[1]), np.float64(v[2])
    v[1] = np.float32(y * 1.0 - z * 0.0)
    v[2] = np.float32(y * 0.0 + z * 1.0)


@numba.njit(cache=False)
def _sphere(origin, start, n, angle):
    """The sphere of points OctoMap's tests build: ``origin + p`` with p rotated by ``angle`` in yaw
    n times per row and in pitch after each row (float32 throughout, as octomath)."""
    out = np.empty((n * n, 3), np.float32)
    p = start.copy()
    k = 0
    for _ in range(n):
        for _ in range(n):
            for a in range(3):
                out[k, a] = origin[a] + p[a]
            k += 1
            _rotate_ip(p, 0.0, angle)
        _rotate_ip(p, angle, 0.0)
    return out


ORIGIN = np.array([0.01, 0.01, 0.02], np.float32)
SURFACE = np.array([2.01, 0.01, 0.01], np.float32)


def _leaf_table(tree: OcTree) -> np.ndarray:
    lv = tree.leaves()  # octomap-python reports centres as float32 (octomath's point3d)
    t = np.c_[lv.centers.astype(np.float32), lv.depths, lv.log_odds.astype(np.float64)]
    return t[np.lexsort(t[:, [4, 3, 2, 1, 0]].T)]


def _octomap_leaf_table(tree) -> np.ndarray:
    rows = [(*it.getCoordinate(), it.getDepth(), it.getValue()) for it in tree.begin_leafs()]
    t = np.array(rows, dtype=np.float64).reshape(-1, 5)
    t[:, 4] = t[:, 4].astype(np.float32)
    return t[np.lexsort(t[:, [4, 3, 2, 1, 0]].T)]


def assert_same_as_octomap(ours: OcTree, ref) -> None:
    """Same node count, same leaves (centre, depth) and the same float32 log-odds in each."""
    assert ours.num_nodes() == ref.size()
    assert ours.num_leaves() == ref.getNumLeafNodes()
    a, b = _leaf_table(ours), _octomap_leaf_table(ref)
    assert a.shape == b.shape
    np.testing.assert_array_equal(a[:, 3], b[:, 3])
    np.testing.assert_array_equal(a[:, :3], b[:, :3])
    np.testing.assert_array_equal(a[:, 4].astype(np.float32), b[:, 4].astype(np.float32))


def _cores_free(monkeypatch):
    """The machine's load judged free for threads (:func:`occmap._threads.free_for_parallel`), so
    that a test of the threads' paths takes them however busy the machine running it is."""
    from occmap import _threads
    from occmap.octree import tree

    monkeypatch.setattr(_threads, "free_for_parallel", lambda: True)
    monkeypatch.setattr(tree, "free_for_parallel", lambda: True)


def _room_cloud(rng, n, half=4.0):
    """Points on the walls, floor and ceiling of a box around the origin, plus a few inside."""
    pts = rng.uniform(-half, half, size=(n, 3))
    axis = rng.integers(0, 3, size=n)
    pts[np.arange(n), axis] = np.where(rng.random(n) < 0.5, -half, half) * rng.uniform(0.7, 1.0, n)
    return pts


# ----------------------------------------------------------------------------- OctoMap's unit tests

def test_insert_scan_sphere_matches_octomap_unit_test():
    """unit_tests InsertScan: a 360×360 sphere of points at 2 m, 0.05 m → 53,959 nodes."""
    cloud = _sphere(ORIGIN, SURFACE, 360, math.pi / 180.0)
    tree = OcTree(0.05)
    tree.insert_point_cloud(cloud.astype(np.float64), ORIGIN.astype(np.float64))
    assert tree.num_nodes() == 53959


def test_insert_ray_sphere_matches_octomap_unit_test():
    """unit_tests InsertRay: the same sphere as 129,600 separate insertRay calls, then the
    maximum-likelihood, pruned tree writeBinary leaves → 50,615 nodes."""
    cloud = _sphere(ORIGIN, SURFACE, 360, math.pi / 180.0)
    tree = OcTree(0.05)
    tree.insert_rays(ORIGIN.astype(np.float64), cloud.astype(np.float64))
    tree.to_max_likelihood()
    tree.prune()
    assert tree.num_nodes() == 50615


def test_raycasting_sphere_matches_octomap_test():
    """test_raycasting: every ray from the centre of a 500×500-beam sphere hits it, at 2 ± 0.05 m."""
    n = 500
    angle = 2.0 * math.pi / n
    tree = OcTree(0.05)
    tree.insert_point_cloud(_sphere(ORIGIN, SURFACE, n, angle).astype(np.float64), ORIGIN.astype(np.float64))
    directions = _sphere(np.zeros(3, np.float32), np.array([1.0, 0.0, 0.0], np.float32), n, angle)
    hit, ends = tree.cast_ray(ORIGIN.astype(np.float64), directions.astype(np.float64), max_range=3.0)
    assert hit.all()
    assert abs(np.linalg.norm(ends - ORIGIN.astype(np.float32).astype(np.float64), axis=1).mean() - 2.0) < 0.05


def _cube_tree() -> OcTree:
    """test_raycasting's cube: free voxels for x < 0.9, occupied beyond, four extra hits."""
    res = 0.1
    steps = np.arange(-0.95, 1.0 + 1e-6, res, dtype=np.float64)  # float loop of the test, same voxels
    g = np.stack(np.meshgrid(steps, steps, steps, indexing="ij"), axis=-1).reshape(-1, 3)
    tree = OcTree(res)
    tree.update_nodes(g, g[:, 0] >= 0.9)
    h = res / 2
    tree.update_nodes(np.array([[h, h, -h], [3 * h, h, -h], [-h, h, -h], [-3 * h, h, -h]]), True)
    return tree


def test_raycasting_cube_matches_octomap_test():
    tree = _cube_tree()
    hit, ends = tree.cast_ray([0.0, 0.0, 0.0], [[0.95, 0.95, 0.95], [1.0, 0.0, 0.0]])
    assert hit.all()
    assert (tree.occupancy_at(ends) == 1).all()
    assert abs(np.linalg.norm(ends[1]) - 1.0) <= 0.05
    # straight down onto the occupied voxels at z = -0.05, then straight up to the free ceiling
    origin = np.array([0.05, 0.05, 0.5], np.float32).astype(np.float64)
    hit, ends = tree.cast_ray(origin, [0.0, 0.0, -1.0])
    assert hit[0] and tree.occupancy_at(ends)[0] == 1
    assert ends[0, 0] == np.float32(origin[0]) and ends[0, 1] == np.float32(origin[1])
    assert abs(ends[0, 2] - (-0.05)) < 1e-6
    hit, _ = tree.cast_ray(origin, [0.0, 0.0, 1.0])
    assert not hit[0]


def test_pruning_sequence_matches_octomap_test():
    """test_pruning: node counts through single inserts, the pruning of eight equal siblings,
    a filled cube, expand() and prune()."""
    res = np.float32(0.01)
    tree = OcTree(float(res))
    assert tree.num_nodes() == 0
    tree.prune()
    assert tree.num_nodes() == 0
    key = tree.coord_to_key(np.array([-0.05, -0.02, 1.0], np.float32).astype(np.float64))[0]

    def update(offset, occupied=True):
        tree.update_nodes(tree.key_to_coord(key + np.asarray(offset))[None, :], occupied)

    update((0, 0, 0))
    assert tree.num_nodes() == 17
    assert tree.occupancy_at(tree.key_to_coord(key)[None, :])[0] == 1
    update((1, 1, 1))
    assert tree.num_nodes() == 18
    for off in ((1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1)):
        update(off)
    assert tree.num_nodes() == 23
    update((0, 1, 1))  # the eighth sibling: the parent is pruned
    assert tree.num_nodes() == 16
    assert tree.leaves().depths.min() == 15
    # a 32×32×32 cube of occupied voxels collapses into few nodes
    xs = np.arange(np.float32(0.005), np.float32(0.32) + np.float32(1e-7), res, dtype=np.float32)
    cube = np.stack(np.meshgrid(xs, xs, xs, indexing="ij"), axis=-1).reshape(-1, 3).astype(np.float64)
    tree.update_nodes(cube, True)
    assert tree.num_nodes() == 27
    tree.prune()
    assert tree.num_nodes() == 27
    tree.expand()
    assert tree.num_nodes() == 37483
    tree.prune()
    assert tree.num_nodes() == 27
    assert (tree.occupancy_at(cube) == 1).all()
    tree.update_nodes(np.array([[0.1, 0.1, 0.1]], np.float32).astype(np.float64), True)
    assert tree.num_nodes() == 67
    tree.update_nodes(np.array([[-2.0, -2.0, -2.0]]), True)
    assert tree.num_nodes() == 83
    tree.clear()
    assert tree.num_nodes() == 0


# ----------------------------------------------------------------------------- agreement with octomap-python

@pytest.mark.parametrize("res", [0.05, 0.1, 0.2])
def test_random_scans_match_octomap(res):
    """Several overlapping scans from different origins, with a max range: identical trees after
    every scan (pruning, expansion of pruned nodes and clamping all exercised)."""
    octomap = _octomap()
    rng = np.random.default_rng(int(res * 1000))
    ours, ref = OcTree(res), octomap.OcTree(res)
    for k in range(4):
        origin = rng.uniform(-0.5, 0.5, 3)
        pts = _room_cloud(rng, 3000)
        ours.insert_point_cloud(pts, origin, max_range=5.0)
        ref.insertPointCloud(pts, origin, 5.0)
        assert ours.num_nodes() == ref.size()
    assert_same_as_octomap(ours, ref)


@pytest.mark.parametrize("res", [0.1, 0.2])
def test_large_scans_match_octomap(res):
    """Scans large enough to be split between two threads and to use the dense cube around the
    sensor, with rays that leave the cube (a 16 m room) and rays cut at max range."""
    octomap = _octomap()
    rng = np.random.default_rng(11)
    ours, ref = OcTree(res), octomap.OcTree(res)
    for origin in ((0.3, -0.2, 0.1), (3.1, 2.4, -1.7)):
        pts = _room_cloud(rng, 21_000, half=8.0)
        ours.insert_point_cloud(pts, np.array(origin), max_range=9.0)
        ref.insertPointCloud(pts, np.array(origin), 9.0)
    assert ours.num_nodes() == ref.size()
    assert encode_ot(ours) == ref.write()  # every node and value, in OctoMap's own bytes


def test_scans_of_changing_size_reuse_the_thread_s_ray_room():
    """The rays of a scan go into arrays the thread keeps (``insertion._ray_room``): scans that
    shrink (the room's rows past them hold the last scan's rays), grow (the room is replaced), and
    drop points (NaN) give OctoMap's tree after every scan; and ``prepare_rays_into`` writes into
    the first rows of larger arrays what ``prepare_rays`` returns."""
    from occmap.octree import insertion, marking

    octomap = _octomap()
    rng = np.random.default_rng(17)
    ours, ref = OcTree(0.2), octomap.OcTree(0.2)
    for n in (6000, 2500, 9000):
        pts = _room_cloud(rng, n)
        pts[rng.integers(0, n, 40), 1] = np.nan
        origin = rng.uniform(-0.5, 0.5, 3)
        counts = ours.insert_point_cloud(pts, origin, max_range=4.0)
        ref.insertPointCloud(pts, origin, 4.0)
        assert counts["dropped"] == np.count_nonzero(np.isnan(pts[:, 1]))
        assert encode_ot(ours) == ref.write()
        assert len(insertion._kept.rays[1]) >= n
    o32 = np.float32(origin)[None]
    box, shift = np.empty((0, 3), np.float32), np.zeros(3, np.int64)
    ends, hit, kept, non_finite, outside = marking.prepare_rays(pts, o32, 4.0, 0.2, box, shift)
    room_ends, room_hit = np.full((len(pts) + 7, 3), np.nan, np.float32), np.ones(len(pts) + 7, bool)
    m, nf, out = marking.prepare_rays_into(pts, o32, 4.0, 0.2, box, shift, room_ends, room_hit, np.zeros(0, np.int64))
    assert (m, nf, out) == (len(ends), non_finite, outside)
    assert non_finite == np.count_nonzero(np.isnan(pts[:, 1])) and m == len(pts) - non_finite - outside
    np.testing.assert_array_equal(room_ends[:m], ends)
    np.testing.assert_array_equal(room_hit[:m], hit)


def test_ray_stopped_by_the_range_test_marks_its_end_voxel_beyond_the_cube():
    """A ray from the origin with a y of −4·10⁻¹⁶ (a UOS scan has one): its end voxel is at
    y key 32767, but its walk never crosses y = 0 before the range test stops it, 64 voxels out,
    past the dense cube. OctoMap marks the end voxel occupied all the same (it was once marked at
    the walk's last voxel instead)."""
    octomap = _octomap()
    rng = np.random.default_rng(13)
    pts = np.vstack([[[6.48370, -4.12815e-16, 1.84829]], _room_cloud(rng, 5000, half=3.0)])
    ours, ref = OcTree(0.1), octomap.OcTree(0.1)
    ours.insert_point_cloud(pts, np.zeros(3))
    ref.insertPointCloud(pts, np.zeros(3))
    assert ours.occupancy_at(np.array([[6.45, -0.05, 1.85]]))[0] == 1
    assert encode_ot(ours) == ref.write()


@pytest.mark.parametrize("res, one_sided", [(0.05, False), (0.2, False), (0.05, True), (0.2, True)])
def test_dense_cube_walks_give_the_plain_walks_voxels(res, one_sided, monkeypatch):
    """The cube phase (slabs along each ray's major axis, x, y and z all among them, ties of
    directions along diagonals, rays ending inside and beyond the cube) against OctoMap's plain
    step-by-step walk (``ray_voxels``), voxel for voxel, hits included, and without hits (the end
    voxels that slabs reaching the end's column must leave unmarked); also with a scan that
    lies on one side of its sensor (+x, +y, −z), which moves the cube to that side; on one
    thread and on two (taking runs of rays in turn). The calling thread's cube serves its
    markings in turn: each leaves it zeroed for the next."""
    from occmap.octree import blocks, insertion, marking
    from occmap.octree.keys import pack_keys, unpack

    rng = np.random.default_rng(14)
    d = rng.normal(size=(6000, 3))
    d[:1000] = np.round(d[:1000])  # axis-aligned and diagonal directions: ties between axes
    d[np.all(d == 0, axis=1)] = (1.0, 1.0, 0.0)
    if one_sided:  # a cone of rays that all end far away: no ray ends near the sensor's block
        d = (np.abs(d) + 0.5) * (1.0, 1.0, -1.0)
    near = 3.0 if one_sided else 0.2
    pts = d / np.linalg.norm(d, axis=1)[:, None] * rng.uniform(near, 9.0, (len(d), 1)) + (0.013, -0.021, 0.034)
    origin = np.array([0.013, -0.021, 0.034], np.float32)
    none = np.zeros(3, np.int64)
    ends, hit, _, _, _ = marking.prepare_rays(pts, origin[None], -1.0, res, np.empty((0, 3), np.float32), none)
    corner = marking.cube_corner(origin, ends, res, none)
    sensor_block = (np.floor(origin.astype(np.float64) * (1 / res)).astype(np.int64) + 32768) >> 3
    shift = sensor_block - (np.array(unpack(corner)) >> 3)
    if one_sided and res == 0.05:  # rays out to 180 voxels: the cube goes to their side
        np.testing.assert_array_equal(shift, [0, 0, 15])
    else:  # centred (within a block): at 0.2 m every ray lies in the centred cube
        assert np.all(np.abs(shift - 8) <= 1)
    monkeypatch.setattr(insertion, "_PARALLEL_RAYS", 1000)
    # keys local to a shift (the tiled maps' 64-bit key space) are the same voxels, less the shift;
    # and rays without hits (as cut at a max range): no end voxel marked unless another ray crosses it
    no_hits = np.zeros_like(hit)
    for shift, threads, hit in [(none, False, hit), (none, True, hit),
                                (np.array([8 * 300, -8 * 1000, 8], np.int64), True, hit), (none, False, no_hits)]:
        ref_keys, ref_hit = marking.ray_voxels(origin[None], ends, hit, res)
        unique, inverse = np.unique(ref_keys, return_inverse=True)
        unique_hit = np.zeros(len(unique), bool)
        np.logical_or.at(unique_hit, inverse, ref_hit)
        keys, depths, is_hit = blocks.block_voxels(*insertion.mark(origin, ends, hit, res, shift, True, threads),
                                                   np.empty((0, 3), np.int64), False)
        assert np.all(depths == 16)
        order = np.argsort(keys)
        np.testing.assert_array_equal(keys[order] + pack_keys(shift), unique)
        np.testing.assert_array_equal(is_hit[order], unique_hit)
        cube_hits, cube_frees, cube_box = insertion._kept.cube
        assert not cube_hits.any() and not cube_frees.any()
        np.testing.assert_array_equal(cube_box, [[128] * 3, [-1] * 3])


@pytest.mark.parametrize("lazy", [False, True])
def test_blocks_applied_leave_the_tree_their_listed_voxels_leave(lazy, monkeypatch):
    """The updates of a scan's marked blocks applied straight from their masks (the insertion's
    path) leave node for node the tree the same blocks listed as voxels and applied in that order
    leave: on scans seen again and again (clamped values, pruned nodes expanded and pruned again,
    the early abort at pruned leaves at every depth), with and without a key box cutting blocks,
    eager and lazy; and a pool that must grow on the way (an update resumed where it stopped)."""
    from occmap.octree import insertion

    starts = []
    apply_blocks = insertion.apply_blocks

    def counted(slots, meta, codes, hits, frees, kbox, start, *args):
        starts.append(start)
        return apply_blocks(slots, meta, codes, hits, frees, kbox, start, *args)

    monkeypatch.setattr(insertion, "apply_blocks", counted)

    rng = np.random.default_rng(5)
    origins = rng.uniform(-0.3, 0.3, (3, 3))
    scans = [(_room_cloud(rng, 4000, half=3.0), origins[k % 3]) for k in range(14)]
    scans.append((rng.uniform(-3, 3, (300, 3)), origins[0]))  # sparse: blocks of single voxels
    for box in (None, ((-1.93, -2.71, -0.64), (2.37, 1.18, 2.5))):
        a, b = OcTree(0.1), OcTree(0.1)
        if box is not None:
            a.bbx = b.bbx = box
        for k, (pts, origin) in enumerate(scans):
            blocks, _ = a._scan_blocks(pts, origin, -1.0, False, False)
            kbox = a._bbx_keys()
            insertion.apply_marked(a._pool, blocks, kbox, a._rule, lazy)
            keys, depths, is_hit = insertion.voxels(blocks, kbox, not lazy, False)
            insertion.apply(b._pool, keys, depths, is_hit, b._rule, lazy)
            assert a.num_nodes() == b.num_nodes()
        if lazy:
            a.update_inner_occupancy()
            b.update_inner_occupancy()
        assert encode_ot(a) == encode_ot(b)
    assert any(start > 0 for start in starts)  # (the pool grew within a scan's blocks)


def test_update_kernels_take_scratch_left_dirty_by_an_earlier_call(monkeypatch):
    """The update kernels allocate nothing (they run without reference counting): their scratch
    comes from the caller (``update.new_work``), who may hand the same array to call after call.
    Left full of another call's values (here every entry 3: a slot of the root's block, no node)
    it gives the tree fresh scratch gives, scan after scan, from the blocks and from a list."""
    from occmap.octree import insertion, update

    def dirty():
        return np.full((8, 17), 3, np.int64)

    rng = np.random.default_rng(11)
    scans = [(_room_cloud(rng, 3000, half=3.0), rng.uniform(-0.3, 0.3, 3)) for _ in range(4)]
    keys, is_hit = np.array([12345, 12346, 300 << 40 | 200 << 20 | 100], np.int64), np.array([True, False, True])

    def build():
        tree = OcTree(0.1)
        for pts, origin in scans:
            tree.insert_point_cloud(pts, origin)
        scanned = encode_ot(tree)
        tree.update_voxels(keys, is_hit)
        return scanned, encode_ot(tree)

    assert update.new_work().shape == (8, 17) and not update.new_work().any()
    fresh = build()
    monkeypatch.setattr(insertion, "new_work", dirty)
    assert build() == fresh


def test_update_voxels_rejects_keys_depths_and_flags_it_cannot_apply():
    """Packed keys are checked before anything changes: a field beyond 65535 (once written into
    the tree it left the node pool inconsistent), a negative key, a depth beyond 0 .. 16, flags or
    depths of another length."""
    tree = OcTree(0.1)
    tree.insert_point_cloud(np.array([[1.0, 2.0, 0.5]]), np.zeros(3))
    before = encode_ot(tree)
    good = np.array([12345, 300 << 40 | 200 << 20 | 100], np.int64)
    for keys in ([12345, 99999], [-1, 12345], [12345, 65536 << 20], [12345, 65536 << 40]):
        with pytest.raises(InvalidArgumentError, match=r"keys\[1\]|keys\[0\]"):
            tree.update_voxels(np.array(keys, np.int64), np.array([True, True]))
    with pytest.raises(InvalidArgumentError, match=r"depths\[1\] = 17"):
        tree.update_voxels(good, np.array([True, False]), depths=np.array([16, 17]))
    with pytest.raises(ShapeError):
        tree.update_voxels(good, np.array([True]))
    with pytest.raises(ShapeError):
        tree.update_voxels(good, np.array([True, False]), depths=np.array([16]))
    assert encode_ot(tree) == before
    tree.update_voxels(good, np.array([True, False]), depths=np.array([16, 15]))
    assert encode_ot(tree) != before  # (and encodes: the pool is consistent)


def test_a_drive_s_sparse_scans_on_two_threads_give_the_one_thread_tree(monkeypatch):
    """Sparse scans (a simulated drive: most voxels alone in their block) are cut into runs of
    about as many voxels for two threads, deep in the tree: each run's paths pass beside the
    paths it shares with the runs on either side, whose nodes no thread settles. The tree is the
    one thread's, node for node, eager and lazy."""
    from occmap.octree import insertion
    from occmap.sim.world3d import VELODYNE_HDL32, simulate_drive

    drive = simulate_drive(4, VELODYNE_HDL32.with_azimuth_step(np.radians(2.0)), rng=3)
    monkeypatch.setattr(insertion, "_PARALLEL_VOXELS", 1000)
    _cores_free(monkeypatch)
    cuts = []
    runs = insertion._apply_runs

    def counted(pool, run, keys, *rest):
        cuts.append(len(keys))
        return runs(pool, run, keys, *rest)

    monkeypatch.setattr(insertion, "_apply_runs", counted)
    for lazy in (False, True):
        trees = []
        for threads in (2, 1):
            before = numba.get_num_threads()
            numba.set_num_threads(threads)
            try:
                tree = OcTree(0.1)
                for cloud in drive:
                    tree.insert_point_cloud(cloud.world_points(), cloud.origin, lazy=lazy)
            finally:
                numba.set_num_threads(before)
            if lazy:
                tree.update_inner_occupancy()
            trees.append(encode_ot(tree))
        assert trees[0] == trees[1]
    assert len(cuts) == 8


def test_a_drive_inserted_together_on_two_threads_settles_on_two_and_gives_the_one_by_one_tree(monkeypatch):
    """A drive's scans inserted together settle their changes after the last scan in runs of
    blocks on two threads (paths shared between runs settled after them): the tree the scans
    give inserted one by one on one thread."""
    from occmap.octree import insertion
    from occmap.sim.world3d import VELODYNE_HDL32, simulate_drive

    drive = simulate_drive(4, VELODYNE_HDL32.with_azimuth_step(np.radians(2.0)), rng=4)
    monkeypatch.setattr(insertion, "_PARALLEL_VOXELS", 1000)
    _cores_free(monkeypatch)
    settled = []
    runs = insertion._apply_runs

    def counted(pool, run, keys, voxels, lazy, room):
        if room == 0:
            settled.append(len(keys))
        return runs(pool, run, keys, voxels, lazy, room)

    monkeypatch.setattr(insertion, "_apply_runs", counted)
    before = numba.get_num_threads()
    numba.set_num_threads(2)
    try:
        together = OcTree(0.1)
        together.insert_point_clouds(drive)
    finally:
        numba.set_num_threads(before)
    numba.set_num_threads(1)
    try:
        one_by_one = OcTree(0.1)
        for cloud in drive:
            one_by_one.insert_point_cloud(cloud.world_points(), cloud.origin)
    finally:
        numba.set_num_threads(before)
    assert len(settled) == 1 and settled[0] > 1000
    assert encode_ot(together) == encode_ot(one_by_one)


def test_one_numba_thread_means_no_worker_thread(monkeypatch):
    """With ``numba.set_num_threads(1)`` a large scan is marked and applied on the calling thread
    alone (no pool of workers is asked for), its blocks applied in one range (not two: a call
    resumed where the pool grows), and the tree is the one two threads build."""
    from occmap import _threads
    from occmap.octree import insertion

    rng = np.random.default_rng(17)
    clouds = [(_room_cloud(rng, 30_000, half=8.0), rng.uniform(-0.5, 0.5, 3)) for _ in range(3)]
    two = OcTree(0.1)
    two.insert_point_clouds([c for c, _ in clouds], [o for _, o in clouds])

    def no_pool(*args):
        raise AssertionError("a worker thread was asked for")

    applied = []
    apply_blocks = insertion.apply_blocks

    def counted(slots, meta, codes, hits, frees, kbox, start, *args):
        applied.append((start, len(codes)))
        return apply_blocks(slots, meta, codes, hits, frees, kbox, start, *args)

    monkeypatch.setattr(_threads, "pool", no_pool)
    monkeypatch.setattr(insertion, "apply_blocks", counted)
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        one = OcTree(0.1)
        one.insert_point_cloud(*clouds[0])
        one.insert_point_clouds([c for c, _ in clouds[1:]], [o for _, o in clouds[1:]])
    finally:
        numba.set_num_threads(before)
    # a scan's calls: the first from block 0, then any resumed where the pool had to grow; each given all blocks
    scans = [n for start, n in applied if start == 0]
    assert len(scans) == 3 and min(scans) >= insertion._PARALLEL_BLOCKS
    assert all(n == applied[i - 1][1] for i, (start, n) in enumerate(applied) if start > 0)
    assert encode_ot(one) == encode_ot(two)


def test_a_busy_computer_means_no_worker_thread(monkeypatch):
    """While other processes leave less than one and a half cores free, a large scan (and the
    next of a stream) is marked and applied on the calling thread alone, as with one Numba
    thread; with the cores free it asks for workers."""
    from occmap import _threads

    if _threads.thread_count() < 2:
        pytest.skip("needs two Numba threads")
    rng = np.random.default_rng(23)
    clouds = [(_room_cloud(rng, 30_000, half=8.0), rng.uniform(-0.5, 0.5, 3)) for _ in range(3)]
    free = OcTree(0.1)
    free.insert_point_clouds([c for c, _ in clouds], [o for _, o in clouds])
    asked = []
    pool = _threads.pool

    def counted(*args):
        asked.append(args)
        return pool(*args)

    monkeypatch.setattr(_threads, "pool", counted)
    monkeypatch.setattr(_threads, "free_cores", lambda: 0.9)
    busy = OcTree(0.1)
    busy.insert_point_cloud(*clouds[0])
    busy.insert_point_clouds([c for c, _ in clouds[1:]], [o for _, o in clouds[1:]])
    assert not asked
    assert encode_ot(busy) == encode_ot(free)
    monkeypatch.setattr(_threads, "free_cores", lambda: 1.6)
    OcTree(0.1).insert_point_cloud(*clouds[0])
    assert asked


@pytest.mark.parametrize("room_per_voxel", [0, 4])
def test_two_thread_updates_in_small_chunks_match_octomap(monkeypatch, room_per_voxel):
    """The tree updated on two threads taking slots in chunks of two blocks' room: with room
    for many chunks each kernel stops and resumes at every chunk; with room for a few the
    threads find none left, stop, and the rest is applied on one thread. The tree is still
    OctoMap's."""
    octomap = _octomap()
    from occmap import _threads
    from occmap.octree import insertion, update
    monkeypatch.setattr(insertion, "_ROOM_PER_VOXEL", room_per_voxel)
    monkeypatch.setattr(insertion, "_CHUNK", 2 * update.BLOCK_ROOM)
    monkeypatch.setattr(insertion, "_PARALLEL_VOXELS", 1000)
    monkeypatch.setattr(_threads, "thread_count", lambda: 2)
    _cores_free(monkeypatch)
    resumed = []
    runs = insertion._apply_runs
    monkeypatch.setattr(insertion, "_apply_runs", lambda pool, run, *rest: runs(
        pool, lambda *args: resumed.append(args[1]) or run(*args), *rest))
    rng = np.random.default_rng(12)
    ours, ref = OcTree(0.2), octomap.OcTree(0.2)
    for origin in ((0.3, -0.2, 0.1), (1.1, 0.4, -0.7)):
        pts = _room_cloud(rng, 3000, half=6.0)
        ours.insert_point_cloud(pts, np.array(origin))
        ref.insertPointCloud(pts, np.array(origin))
    assert len(resumed) > 40  # (the kernels resumed at many chunks, or the one thread took the rest)
    assert encode_ot(ours) == ref.write()


def test_scans_inserted_again_on_two_threads_leave_the_pool_as_it_is(monkeypatch):
    """A scan inserted again adds no nodes: the threads take their slots from the blocks freed
    before (the free and spare lists) and give back the unused end of the chunk they took from
    the top, so the slots in use (``meta[TOP]``) stop growing (a margin reserved every scan grew
    them by a thousand slots a scan, written onto the free list and never used)."""
    from occmap import _threads
    from occmap.octree import insertion, pool

    monkeypatch.setattr(insertion, "_PARALLEL_VOXELS", 1000)
    monkeypatch.setattr(_threads, "thread_count", lambda: 2)
    cloud = _room_cloud(np.random.default_rng(5), 5000, half=6.0)
    tree = OcTree(0.2)
    tops = []
    for _ in range(6):
        tree.insert_point_cloud(cloud, np.array([0.1, 0.2, 0.3]))
        tops.append(int(tree._pool.meta[pool.TOP]))
    assert tops[-1] == tops[1], tops


def test_scans_seen_again_in_turn_on_two_threads_stop_growing_the_pool(monkeypatch):
    """Three scans in turn, again and again (a robot standing, its scans re-seen): the second
    thread takes its slots from the blocks it freed before (its spare list), so after a first
    round the slots in use (``meta[TOP]``) stop growing. (It took them from the top, freeing
    its own onto the other thread's list: 400 – 500 slots a call at 0.1 m, the free list
    growing as large as the tree.) The tree is the one thread's, byte for byte."""
    from occmap import _threads
    from occmap.io.octomap import encode_ot
    from occmap.octree import insertion, pool

    monkeypatch.setattr(insertion, "_PARALLEL_VOXELS", 1000)
    rng = np.random.default_rng(21)
    clouds = [_room_cloud(rng, 5000, half=6.0) for _ in range(3)]
    origin = np.array([0.1, 0.2, 0.3])
    trees = {}
    for count in (2, 1):
        monkeypatch.setattr(_threads, "thread_count", lambda count=count: count)
        tree = OcTree(0.1)
        tops = []
        for k in range(12):
            tree.insert_point_cloud(clouds[k % 3], origin)
            tops.append(int(tree._pool.meta[pool.TOP]))
        trees[count] = (tree, tops)
    tree, tops = trees[2]
    assert tops[-1] == tops[5], tops
    assert encode_ot(tree) == encode_ot(trees[1][0])
    # a one-thread update after them takes the spare blocks too
    monkeypatch.setattr(_threads, "thread_count", lambda: 1)
    tree.insert_point_cloud(clouds[0], origin)
    assert tree._pool.meta[pool.SPARE] == -1 and int(tree._pool.meta[pool.TOP]) == tops[-1]


def test_a_scan_like_the_last_one_fits_its_block_storage_from_the_start(monkeypatch):
    """The block storage of a scan starts with room for the blocks per ray of the thread's last
    scan: a second scan like the first is marked without growing (rehashing) it, and the tree
    is the same as with storage grown from a small start."""
    from occmap.octree import blocks, insertion

    grown = []
    grow = blocks.grow_blocks
    monkeypatch.setattr(blocks, "grow_blocks", lambda *a: grown.append(1) or grow(*a))
    rng = np.random.default_rng(8)
    first, second = _room_cloud(rng, 6000, half=6.0), _room_cloud(rng, 6000, half=6.0)
    origin = np.array([0.1, 0.2, 0.3])
    monkeypatch.setattr(insertion._kept, "blocks_per_ray", insertion._BLOCKS_PER_RAY, raising=False)
    tree = OcTree(0.05)
    tree.insert_point_cloud(first, origin)
    assert grown  # (a small start grows)
    grown.clear()
    tree.insert_point_cloud(second, origin)
    assert not grown
    small = OcTree(0.05)
    small.insert_point_cloud(first, origin)
    monkeypatch.setattr(insertion._kept, "blocks_per_ray", insertion._BLOCKS_PER_RAY)
    small.insert_point_cloud(second, origin)
    assert encode_ot(small) == encode_ot(tree)


@pytest.mark.parametrize("points", [3000, 6000])  # (marked without the dense cube, and with it)
def test_block_storage_kept_between_scans_is_emptied_before_reuse(monkeypatch, points):
    """A thread keeps its block storage from scan to scan: each scan empties it (table and the
    masks it held) and marks into the same arrays, and the trees are OctoMap's scan after scan
    (masks left over from the scan before would mark voxels it never crossed)."""
    octomap = _octomap()
    from occmap.octree import insertion

    monkeypatch.setattr(insertion._kept, "storage", None, raising=False)
    rng = np.random.default_rng(31)
    ours, ref = OcTree(0.1), octomap.OcTree(0.1)
    kept = []
    for k, half in enumerate((6.0, 5.0, 5.5)):
        pts = _room_cloud(rng, points, half=half)
        origin = rng.uniform(-0.5, 0.5, 3)
        ours.insert_point_cloud(pts, origin)
        ref.insertPointCloud(pts, origin)
        kept.append(insertion._kept.storage)
        assert encode_ot(ours) == ref.write(), k
    assert kept[0] is not None and kept[2] is kept[1]  # (the first may be outgrown)


def test_discretize_matches_octomap():
    octomap = _octomap()
    rng = np.random.default_rng(7)
    pts = _room_cloud(rng, 5000)
    origin = np.array([0.1, -0.2, 0.3])
    ours, ref = OcTree(0.1), octomap.OcTree(0.1)
    ours.insert_point_cloud(pts, origin, discretize=True)
    ref.insertPointCloud(pts, origin, discretize=True)
    assert_same_as_octomap(ours, ref)


@pytest.mark.parametrize("clamp", [(0.6, 0.9), (0.1, 0.4)])
def test_clamping_bounds_that_leave_out_even_odds_match_octomap(clamp):
    """A new node takes its first update from log-odds 0, clamped: with both bounds on one side of
    0.5, a miss (or a hit) on a new voxel moves it to the nearer bound although the update points
    the other way (a new voxel left unknown, counted as a node, was the bug). Scans as blocks
    (whole nodes of one update among them), discretized, lazy, and updates of voxels and their
    siblings one after another: OctoMap's trees byte for byte."""
    octomap = _octomap()
    rng = np.random.default_rng(31)

    def ref_tree():
        t = octomap.OcTree(0.1)
        t.setClampingThresMin(clamp[0])
        t.setClampingThresMax(clamp[1])
        return t

    for kwargs in ({}, {"discretize": True}, {"lazy_eval": True}):
        ours, ref = OcTree(0.1, clamp=clamp), ref_tree()
        for _ in range(2):
            pts, origin = _room_cloud(rng, 6000), rng.uniform(-0.3, 0.3, 3)
            ours.insert_point_cloud(pts, origin, discretize=kwargs.get("discretize", False),
                                    lazy=kwargs.get("lazy_eval", False))
            ref.insertPointCloud(pts, origin, **kwargs)
        assert encode_ot(ours) == ref.write()
    ours, ref = OcTree(0.1, clamp=clamp), ref_tree()
    voxels = rng.integers(-3, 3, size=(40, 3))
    pts = (np.repeat(voxels, rng.integers(1, 4, len(voxels)), axis=0) + 0.5) * 0.1
    occupied = rng.random(len(pts)) < 0.5
    ours.update_nodes(pts, occupied)
    for p, o in zip(pts, occupied):
        ref.updateNode(p, bool(o))
    assert encode_ot(ours) == ref.write()


def test_points_outside_the_key_range_are_skipped_as_octomap_does():
    """OctoMap skips a ray whose end lies outside the key range (``computeRayKeys`` fails) and
    inserts the rest; with a max range the cut end is what counts. Discretized, OctoMap's
    unchecked key wraps around and marks a voxel far away: here those points are dropped, and the
    tree is OctoMap's of the points in range."""
    octomap = _octomap()
    rng = np.random.default_rng(15)
    pts = _room_cloud(rng, 3000)
    far = np.array([[5000.0, 1.0, 0.5], [1.0, -4000.0, 2.0], [0.5, 0.5, 1e9]])
    cloud = np.concatenate([pts[:1000], far, pts[1000:]])
    origin = np.array([0.1, -0.2, 0.3])
    for max_range in (-1.0, 4.0):
        ours, ref = OcTree(0.1), octomap.OcTree(0.1)
        counts = ours.insert_point_cloud(cloud, origin, max_range)
        ref.insertPointCloud(cloud, origin, maxrange=max_range)
        assert encode_ot(ours) == ref.write()
        skipped = 3 if max_range < 0 else 0  # cut at 4 m, the far rays' ends are in range
        assert counts["outside_key_range"] == skipped and counts["dropped"] == skipped
        assert counts["points"] == len(cloud) - skipped
    ours, ref = OcTree(0.1), octomap.OcTree(0.1)
    counts = ours.insert_point_cloud(cloud, origin, discretize=True)
    ref.insertPointCloud(pts, origin, discretize=True)
    assert encode_ot(ours) == ref.write()
    assert counts["outside_key_range"] == 3
    assert ours.insert_rays(origin, far[:2]) == 0 and not ours.insert_ray(origin, far[2])
    assert encode_ot(ours) == ref.write()


@pytest.mark.parametrize("discretize", [False, True])
def test_points_dropped_within_the_runs_of_several_threads_leave_octomaps_tree(discretize, monkeypatch):
    """Rays prepared run by run on the threads that mark them (each run's rays from its first
    point's row on): points dropped in some runs (NaN, ends outside the key range) leave the
    other runs' rays whole, the tree OctoMap's of the points kept, and the counts those of one
    thread."""
    from occmap.octree import insertion

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("one Numba thread: no runs on several threads")
    monkeypatch.setattr(insertion, "_PARALLEL_RAYS", 1000)
    monkeypatch.setattr(insertion, "_CUBE_RAYS", 1000)
    _cores_free(monkeypatch)
    rng = np.random.default_rng(23)
    pts = _room_cloud(rng, 6000)
    bad = np.zeros(len(pts), bool)
    bad[rng.choice(len(pts), 40, replace=False)] = True
    cloud = pts.copy()
    cloud[bad] = np.array([[np.nan, 0.0, 1.0], [5000.0, 1.0, 0.5], [1.0, np.inf, 2.0], [0.5, 0.5, -1e9]])[
        np.arange(bad.sum()) % 4]
    origin = np.array([0.1, -0.2, 0.3])
    ref = _octomap().OcTree(0.1)
    ref.insertPointCloud(pts[~bad], origin, discretize=discretize)
    before = numba.get_num_threads()
    counts = {}
    try:
        for threads in (1, 2):
            numba.set_num_threads(threads)
            tree = OcTree(0.1)
            counts[threads] = tree.insert_point_cloud(cloud, origin, discretize=discretize)
            assert encode_ot(tree) == ref.write()
    finally:
        numba.set_num_threads(before)
    assert counts[1] == counts[2]
    assert counts[2]["dropped"] == 40 and counts[2]["outside_key_range"] == 20
    assert discretize or counts[2]["points"] == len(pts) - 40


def test_discretized_rays_are_one_per_voxel_in_first_point_order():
    """:func:`marking.voxel_centres` against the unique keys of the float32 points, first-seen
    order kept, NaN rows dropped and counted."""
    rng = np.random.default_rng(16)
    pts = np.round(rng.normal(scale=2.0, size=(5000, 3)), 1) + 0.0123
    pts[::97] = np.nan
    centres, non_finite, outside = marking.voxel_centres(pts, 0.2, np.zeros(3, np.int64))
    finite = pts[np.all(np.isfinite(pts), axis=1)]
    keys = np.floor(finite.astype(np.float32).astype(np.float64) / 0.2).astype(np.int64)
    _, first = np.unique(keys, axis=0, return_index=True)
    np.testing.assert_array_equal(centres, (keys[np.sort(first)] + 0.5) * 0.2)
    assert non_finite == len(pts) - len(finite) and outside == 0


def test_updates_in_any_order_with_repeats_match_octomap():
    """update_nodes, OctoMap's updateNode point after point, where consecutive points fall in
    one voxel or in its siblings (the updates that take a sibling's parent without a walk), in
    runs that reach the clamps, prune parents and expand them again: OctoMap's tree after each
    batch."""
    octomap = _octomap()
    rng = np.random.default_rng(21)
    ours, ref = OcTree(0.1), octomap.OcTree(0.1)
    for _ in range(6):
        voxels = rng.integers(-3, 3, size=(rng.integers(1, 40), 3))  # a few parents' children, around 0
        pts = (np.repeat(voxels, rng.integers(1, 6, len(voxels)), axis=0) + 0.5) * 0.1
        occupied = np.repeat(rng.random(len(pts) // 3 + 1) < 0.5, 3)[:len(pts)]
        ours.update_nodes(pts, occupied)
        for p, o in zip(pts, occupied):
            ref.updateNode(p, bool(o))
        assert encode_ot(ours) == ref.write()


def test_lazy_insertion_then_update_and_prune_matches_octomap():
    """Lazy scans leave inner nodes stale and nothing pruned, as OctoMap's lazy_eval; updating the
    inner nodes gives OctoMap's lazy tree, and pruning then gives the eagerly built one."""
    octomap = _octomap()
    rng = np.random.default_rng(8)
    ours, lazy_ref, eager_ref = OcTree(0.1), octomap.OcTree(0.1), octomap.OcTree(0.1)
    for _ in range(3):
        pts, origin = _room_cloud(rng, 2000), rng.uniform(-0.3, 0.3, 3)
        ours.insert_point_cloud(pts, origin, lazy=True)
        lazy_ref.insertPointCloud(pts, origin, lazy_eval=True)
        eager_ref.insertPointCloud(pts, origin)
    assert ours.num_nodes() == lazy_ref.size() > eager_ref.size()
    ours.update_inner_occupancy()
    lazy_ref.updateInnerOccupancy()
    assert_same_as_octomap(ours, lazy_ref)
    ours.prune()
    assert_same_as_octomap(ours, eager_ref)


def test_scans_inserted_together_after_lazy_ones_match_octomap():
    """Scans inserted together settle the nodes they change once, after the last: OctoMap's tree
    from the same scans inserted eagerly one by one. Nodes they change nothing below are left as
    they were: scans inserted lazily before (inner nodes then updated, nothing pruned) leave
    collapsible nodes that OctoMap keeps, and so must this (a prune afterwards still finds them)."""
    octomap = _octomap()
    rng = np.random.default_rng(31)
    ours, ref = OcTree(0.1), octomap.OcTree(0.1)
    for _ in range(2):
        pts, origin = _room_cloud(rng, 3000, half=3.0) + [6.0, 0.0, 0.0], rng.uniform(-0.3, 0.3, 3) + [6.0, 0.0, 0.0]
        ours.insert_point_cloud(pts, origin, lazy=True)
        ref.insertPointCloud(pts, origin, lazy_eval=True)
    ours.update_inner_occupancy()
    ref.updateInnerOccupancy()
    scans = [(_room_cloud(rng, 4000), rng.uniform(-0.3, 0.3, 3)) for _ in range(4)]
    ours.insert_point_clouds([p for p, _ in scans], [o for _, o in scans])
    for pts, origin in scans:
        ref.insertPointCloud(pts, origin)
    assert_same_as_octomap(ours, ref)
    before = ours.num_nodes()
    ours.prune()
    assert ours.num_nodes() < before


def test_whole_nodes_updated_together_after_lazy_scans_keep_octomaps_unpruned_nodes(monkeypatch):
    """Dense scans inserted together mark whole nodes near the sensor alike (one update of the
    node, passed to its subtree); lazy scans before saturated some of the voxels below, leaving
    collapsible nodes unpruned. Only the nodes below which a value changed are settled: the
    unchanged ones stay unpruned, as in OctoMap (settling the whole subtree lost 544 nodes)."""
    from occmap.octree import insertion

    octomap = _octomap()
    monkeypatch.setattr(insertion, "SETTLE_AFTER_SCANS", 2)
    rng = np.random.default_rng(33)

    def sphere(n, radius):
        v = rng.normal(size=(n, 3))
        return radius * v / np.linalg.norm(v, axis=1)[:, None]

    ours, ref = OcTree(0.1), octomap.OcTree(0.1)
    origin = np.array([0.01, 0.02, 0.03])
    sparse = sphere(400, 1.2)
    for _ in range(6):  # (free voxels near the sensor saturated)
        ours.insert_point_cloud(sparse, origin, lazy=True)
        ref.insertPointCloud(sparse, origin, lazy_eval=True)
    ours.update_inner_occupancy()
    ref.updateInnerOccupancy()
    dense = [sphere(20000, 2.0) for _ in range(2)]
    ours.insert_point_clouds(dense, [origin, origin])
    for pts in dense:
        ref.insertPointCloud(pts, origin)
    assert_same_as_octomap(ours, ref)


def test_scans_inserted_together_leave_a_settled_tree_when_one_is_refused(monkeypatch):
    """A scan refused midway (a bad array) leaves the scans before it inserted and their nodes
    settled: the tree those scans give inserted one by one."""
    from occmap.octree import insertion

    monkeypatch.setattr(insertion, "SETTLE_AFTER_SCANS", 2)
    rng = np.random.default_rng(32)
    scans = [_room_cloud(rng, 3000) for _ in range(2)]
    together, one_by_one = OcTree(0.1), OcTree(0.1)
    with pytest.raises(ShapeError):
        together.insert_point_clouds(scans + [np.zeros((5, 2))], np.zeros((3, 3)))
    for pts in scans:
        one_by_one.insert_point_cloud(pts, np.zeros(3))
    assert encode_ot(together) == encode_ot(one_by_one)


def test_real_scan_matches_octomap(data_dir):
    octomap = _octomap()
    pts = np.loadtxt(bz2.open(data_dir / "octomap" / "scan.dat.bz2"))
    assert pts.shape == (88206, 3)
    ours, ref = OcTree(0.2), octomap.OcTree(0.2)
    ours.insert_point_cloud(pts, np.zeros(3))
    ref.insertPointCloud(pts, np.zeros(3))
    assert_same_as_octomap(ours, ref)
    assert ours.memory_usage() <= ref.memoryUsage()


def test_queries_match_octomap():
    octomap = _octomap()
    rng = np.random.default_rng(9)
    ours, ref = OcTree(0.1), octomap.OcTree(0.1)
    pts = _room_cloud(rng, 4000)
    ours.insert_point_cloud(pts, np.zeros(3))
    ref.insertPointCloud(pts, np.zeros(3))
    q = rng.uniform(-5, 5, size=(500, 3))
    l = ours.log_odds_at(q)
    for p, v in zip(q, l):
        try:
            assert np.float32(v) == np.float32(ref.search(p).getLogOdds())
        except octomap.NullPointerException:  # octomap-python's way of saying "unknown"
            assert np.isnan(v)
    # ray casting: random origins inside the room, random directions, with and without max range
    O = rng.uniform(-1, 1, size=(300, 3))
    D = rng.normal(size=(300, 3))
    for max_range, ignore in ((-1.0, False), (2.0, False), (-1.0, True)):
        hit, ends = ours.cast_ray(O, D, max_range=max_range, ignore_unknown=ignore)
        for o, d, h, e in zip(O, D, hit, ends):
            end = np.zeros(3)
            ref_hit = ref.castRay(o, d, end, ignoreUnknownCells=ignore, maxRange=max_range)
            assert h == ref_hit
            np.testing.assert_array_equal(e.astype(np.float32), end.astype(np.float32))
    lo, hi = ours.metric_bounds()
    np.testing.assert_allclose(lo, ref.getMetricMin(), atol=1e-6)
    np.testing.assert_allclose(hi, ref.getMetricMax(), atol=1e-6)
    assert ours.volume() == pytest.approx(ref.volume(), rel=1e-9)


def test_bbx_leaves_match_octomap():
    """The leaves overlapping a box. OctoMap's bbx iterator also returns coarse leaves that end one
    voxel before the box's lower corner (its overlap test adds one key above each node); occmap
    returns exactly the overlapping ones, which are OctoMap's minus those."""
    octomap = _octomap()
    rng = np.random.default_rng(10)
    res = 0.1
    ours, ref = OcTree(res), octomap.OcTree(res)
    pts = _room_cloud(rng, 3000)
    ours.insert_point_cloud(pts, np.zeros(3))
    ref.insertPointCloud(pts, np.zeros(3))
    lo, hi = np.array([-1.0, -0.5, -2.0]), np.array([2.0, 1.5, 0.5])
    lv = ours.leaves(lo, hi)
    ref_rows = np.array([(*it.getCoordinate(), it.getSize()) for it in ref.begin_leafs_bbx(lo, hi)])
    kmin, kmax = ours.coord_to_key(lo)[0], ours.coord_to_key(hi)[0]
    first = np.rint((ref_rows[:, :3] - ref_rows[:, 3:] / 2) / res).astype(np.int64) + 32768
    cells = np.rint(ref_rows[:, 3] / res).astype(np.int64)[:, None]
    overlapping = np.all((first <= kmax) & (first + cells - 1 >= kmin), axis=1)
    assert 0 < np.count_nonzero(~overlapping) < 0.05 * len(ref_rows)
    ref_rows = ref_rows[overlapping]
    ours_rows = np.c_[lv.centers.astype(np.float32), lv.sizes]
    key = lambda t: t[np.lexsort(t.T[::-1])]  # noqa: E731
    np.testing.assert_allclose(key(ours_rows), key(ref_rows), rtol=0, atol=1e-12)


# ----------------------------------------------------------------------------- behaviour and bad input

def test_hit_wins_and_each_voxel_once_per_scan():
    """Two points in one voxel and a ray through another point's voxel: one hit each, no miss."""
    tree = OcTree(0.1)
    pts = np.array([[1.05, 0.05, 0.05], [1.06, 0.04, 0.05], [0.55, 0.05, 0.05]])
    tree.insert_point_cloud(pts, np.array([0.05, 0.05, 0.05]))
    l = tree.log_odds_at(np.array([[1.05, 0.05, 0.05], [0.55, 0.05, 0.05], [0.75, 0.05, 0.05]]))
    assert l[0] == tree.log_odds_hit and l[1] == tree.log_odds_hit
    assert l[2] == tree.log_odds_miss


def test_max_range_clears_without_marking():
    tree = OcTree(0.1)
    tree.insert_point_cloud(np.array([[10.05, 0.05, 0.05]]), np.array([0.05, 0.05, 0.05]), max_range=3.0)
    l = tree.log_odds_at(np.array([[2.0, 0.05, 0.05], [3.5, 0.05, 0.05], [10.05, 0.05, 0.05]]))
    assert l[0] == tree.log_odds_miss
    assert np.isnan(l[1]) and np.isnan(l[2])


def test_nan_points_are_dropped_and_counted():
    tree = OcTree(0.1)
    pts = np.array([[1.0, 0.0, 0.0], [np.nan, 0.0, 0.0], [0.0, np.inf, 0.0], [0.0, 1.0, 0.0]])
    summary = tree.insert_point_cloud(pts, np.zeros(3))
    assert summary["dropped"] == 2 and summary["points"] == 2
    assert tree.stats["dropped"] == 2


def test_empty_cloud_changes_nothing():
    tree = OcTree(0.1)
    tree.insert_point_cloud(np.empty((0, 3)), np.zeros(3))
    assert tree.num_nodes() == 0 and len(tree.leaves().sizes) == 0


def test_bad_input_raises_clear_errors():
    tree = OcTree(0.1)
    with pytest.raises(InvalidArgumentError, match="outside the octree's key range"):
        tree.insert_point_cloud(np.zeros((5, 3)), np.array([1e5, 0, 0]))
    with pytest.raises(ShapeError):
        tree.insert_point_cloud(np.zeros((5, 2)), np.zeros(3))
    with pytest.raises(InvalidArgumentError, match="origin"):
        tree.insert_point_cloud(np.zeros((5, 3)), np.array([np.nan, 0, 0]))
    with pytest.raises(InvalidArgumentError):
        OcTree(0.0)
    with pytest.raises(InvalidArgumentError):
        OcTree(0.1, prob_hit=1.0)
    with pytest.raises(InvalidArgumentError, match="prob_hit must be in"):  # a hit that lowers occupancy
        OcTree(0.1, prob_hit=0.4)
    with pytest.raises(InvalidArgumentError, match="prob_miss must be in"):
        OcTree(0.1, prob_miss=0.5)
    assert tree.num_nodes() == 0


def test_nodes_and_from_nodes_round_trip():
    """The public node arrays: read-only views of the pool; a tree built from copies of them is
    the same tree (same queries, same file bytes) and keeps growing; bad arrays are refused."""
    rng = np.random.default_rng(5)
    tree = OcTree(0.1, prob_hit=0.8)
    tree.insert_point_cloud(_room_cloud(rng, 2000), np.zeros(3))
    nodes = tree.nodes()
    assert nodes.count == tree.num_nodes() and nodes.value.dtype == np.float32 and nodes.child.dtype == np.int32
    with pytest.raises(ValueError):
        nodes.value[0] = 1.0  # read-only
    copy = OcTree.from_nodes(0.1, nodes.slots.copy(), nodes.count, prob_hit=0.8)
    assert encode_ot(copy) == encode_ot(tree) and copy.num_leaves() == tree.num_leaves()
    pts = _room_cloud(rng, 2000)
    for t in (tree, copy):
        t.insert_point_cloud(pts, np.array([0.3, 0.1, 0.0]))
    assert encode_ot(copy) == encode_ot(tree)
    with pytest.raises(ShapeError):
        OcTree.from_nodes(0.1, nodes.value.copy(), nodes.count)
    with pytest.raises(InvalidArgumentError):
        OcTree.from_nodes(0.1, nodes.slots[:-1].copy(), nodes.count)
    with pytest.raises(InvalidArgumentError):
        OcTree.from_nodes(0.1, nodes.slots, nodes.count)  # a read-only view: not taken over


def test_occupancy_and_unknown_readout():
    tree = OcTree(0.1)
    tree.insert_point_cloud(np.array([[1.05, 0.05, 0.05]]), np.array([0.05, 0.05, 0.05]))
    occ = tree.occupancy_at(np.array([[1.05, 0.05, 0.05], [0.55, 0.05, 0.05], [5.0, 5.0, 5.0], [1e9, 0, 0]]))
    np.testing.assert_array_equal(occ, [1, 0, -1, -1])
    np.testing.assert_allclose(tree.occupied_centers(), [[1.05, 0.05, 0.05]], atol=1e-12)


def test_real_3d_scans_with_poses_match_octomap(data_dir):
    """The Osnabrück scans placed by their registered poses and the HDL-32E pair placed by its
    relative transform, inserted in order: identical trees."""
    octomap = _octomap()
    from occmap.geometry import SE3
    from occmap.io.pointclouds import read_pcd, read_uos

    uos = [read_uos(data_dir / "scans3d" / "uos_3dtk" / f"scan00{i}.3d") for i in range(3)]
    hdl = sorted((data_dir / "scans3d" / "hdl32_pair").glob("*.pcd"))
    first, second = read_pcd(hdl[0]), read_pcd(hdl[1])
    relative = SE3(np.loadtxt(data_dir / "scans3d" / "hdl32_pair" / "relative.txt"))
    hdl_scans = [(first.world_points(), first.origin),
                 (relative.apply(second.world_points()), relative.apply(second.origin))]
    for scans in ([(c.world_points(), c.origin) for c in uos], hdl_scans):
        ours, ref = OcTree(0.2), octomap.OcTree(0.2)
        for pts, origin in scans:
            ours.insert_point_cloud(pts, origin, max_range=40.0)
            ref.insertPointCloud(pts, np.asarray(origin, dtype=np.float64), 40.0)
        assert_same_as_octomap(ours, ref)


def test_insert_point_clouds_pipeline_equals_scan_by_scan():
    """The batched call (next scan traced on another thread) builds the same tree, and counts alike."""
    rng = np.random.default_rng(11)
    clouds = [_room_cloud(rng, 2500) for _ in range(5)]
    clouds[2][7] = np.nan
    origins = rng.uniform(-0.5, 0.5, size=(5, 3))
    one, many = OcTree(0.1), OcTree(0.1)
    for pts, o in zip(clouds, origins):
        one.insert_point_cloud(pts, o, max_range=4.5)
    total = many.insert_point_clouds(clouds, origins, max_range=4.5)
    np.testing.assert_array_equal(_leaf_table(one), _leaf_table(many))
    assert total["scans"] == 5 and total["dropped"] == 1 and one.stats == many.stats


def test_the_next_scan_is_marked_by_the_threads_of_the_caller(monkeypatch):
    """insert_point_clouds traces the next scan on its own thread with the caller's Numba thread
    count, so a large scan's marking is shared there too (not left to that one thread while the
    other waits); the tree is the one scan-by-scan insertion builds."""
    import threading

    from occmap import _threads
    from occmap.octree import insertion

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("one Numba thread: no pipeline")
    calls = []
    share = insertion.share

    def recording(task, threads=None):
        calls.append((threading.current_thread().name, _threads.thread_count()))
        return share(task, threads)

    monkeypatch.setattr(insertion, "share", recording)
    monkeypatch.setattr(insertion, "_PARALLEL_RAYS", 1000)
    _cores_free(monkeypatch)
    rng = np.random.default_rng(19)
    clouds = [(_room_cloud(rng, 3000), rng.uniform(-0.5, 0.5, 3)) for _ in range(3)]
    before = numba.get_num_threads()
    numba.set_num_threads(2)
    try:
        many = OcTree(0.1)
        many.insert_point_clouds([c for c, _ in clouds], [o for _, o in clouds])
    finally:
        numba.set_num_threads(before)
    ahead = [count for name, count in calls if name.startswith("occmap-octree-next")]
    assert len(ahead) == 2 and set(ahead) == {2}
    one = OcTree(0.1)
    for c, o in clouds:
        one.insert_point_cloud(c, o)
    assert encode_ot(one) == encode_ot(many)


def test_bbx_limit_matches_octomap_test():
    """test_bbx: three points, a ±10.1 m box, max range 8: the x ray hits its point, the y ray stops
    at unknown space just outside the box, the z ray (point beyond max range) at max range."""
    res = np.float32(0.2)
    tree = OcTree(float(res))
    tree.bbx = ([-10.1] * 3, [10.1] * 3)
    origin = np.array([res / 2, 5 + res / 2, res / 2], np.float32)
    pts = origin + np.array([[5, 0, 0], [0, 7, 0], [0, 0, 9]], np.float32)
    tree.insert_point_cloud(pts.astype(np.float64), origin.astype(np.float64), max_range=8.0)
    hit, ends = tree.cast_ray(origin.astype(np.float64), np.eye(3))
    np.testing.assert_array_equal(hit, [True, False, False])
    np.testing.assert_allclose(ends[0], pts[0], atol=1e-3)
    np.testing.assert_allclose(ends[1], [pts[1, 0], 10.1 + res, pts[1, 2]], atol=1e-3)
    np.testing.assert_allclose(ends[2], [pts[2, 0], pts[2, 1], origin[2] + 8.0], atol=1e-3)


def test_bbx_limited_scans_match_octomap():
    octomap = _octomap()
    rng = np.random.default_rng(12)
    ours, ref = OcTree(0.1), octomap.OcTree(0.1)
    lo, hi = np.array([-2.0, -1.5, -3.0]), np.array([2.5, 3.0, 1.0])
    ours.bbx = (lo, hi)
    ref.setBBXMin(lo)
    ref.setBBXMax(hi)
    ref.useBBXLimit(True)
    origins = [rng.uniform(-0.5, 0.5, 3) for _ in range(3)] + [np.array([3.5, 0.2, 0.1])]  # the last outside
    for origin in origins:
        pts = _room_cloud(rng, 3000)
        ours.insert_point_cloud(pts, origin, max_range=4.0)
        ref.insertPointCloud(pts, origin, 4.0)
    assert_same_as_octomap(ours, ref)
    lo_m, hi_m = ours.metric_bounds()
    assert np.all(lo_m >= lo - 0.1) and np.all(hi_m <= hi + 0.1)
    with pytest.raises(InvalidArgumentError):
        ours.bbx = (hi, lo)


def test_iterators_on_geb079(data_dir):
    """test_iterators: every leaf of geb079 once (143,729 occupied + 284,415 free); leaves down
    to a coarser depth count the nodes there as leaves; the bbx leaves are those overlapping it."""
    tree = read_bt(data_dir / "octomap" / "geb079.bt")
    lv = tree.leaves()
    assert len(lv.sizes) == 143729 + 284415
    assert (lv.log_odds >= 0).sum() == 143729
    assert len(np.unique(np.c_[lv.centers, lv.sizes], axis=0)) == len(lv.sizes)
    coarse = tree.leaves(depth=12)
    assert coarse.depths.max() == 12 and len(coarse.sizes) < len(lv.sizes)
    # every finest leaf lies inside exactly one coarse leaf, whose value is the max below it
    big = coarse.sizes[:, None] / 2
    inside = np.all(np.abs(lv.centers[:, None, :] - coarse.centers[None, :, :]) < big[None], axis=2) \
        if len(coarse.sizes) * len(lv.sizes) < 5e7 else None
    if inside is not None:
        assert (inside.sum(axis=1) == 1).all()
    lo, hi = np.array([-5.0, -3.0, 0.0]), np.array([4.0, 6.0, 2.0])
    box = tree.leaves(lo, hi)
    half = lv.sizes[:, None] / 2
    kmin, kmax = tree.coord_to_key(lo)[0], tree.coord_to_key(hi)[0]
    first = tree.coord_to_key(lv.centers - half + tree.resolution / 2)
    last = tree.coord_to_key(lv.centers + half - tree.resolution / 2)
    overlap = np.all((first <= kmax) & (last >= kmin), axis=1)
    assert len(box.sizes) == overlap.sum() > 0


@pytest.mark.parametrize("room", [True, False])
def test_a_growing_pool_keeps_its_slots_in_its_own_room_or_by_copies(monkeypatch, room):
    """A large pool grows within the address room it reserved (its slots never move: an array of
    them handed out by ``nodes()`` stays a view of the tree's first slots) or, where no room can
    be had, by copies; either way the tree comes out as it would have."""
    from occmap.octree import pool

    monkeypatch.setattr(pool.Pool, "ROOM_FROM_BYTES", 1 << 15)  # (every pool beyond its first slots)
    if not room:
        monkeypatch.setattr(pool, "_reserve", lambda size: None)  # (a system that refuses)
    rng = np.random.default_rng(21)
    clouds = [_room_cloud(rng, 4000, half=6.0) for _ in range(4)]
    origin = np.array([0.1, 0.2, 0.3])
    tree, held = OcTree(0.05), []
    for pts in clouds:
        tree.insert_point_cloud(pts, origin)
        held.append(tree.nodes())
    monkeypatch.setattr(pool.Pool, "ROOM_FROM_BYTES", 1 << 62)
    plain = OcTree(0.05)
    for pts in clouds:
        plain.insert_point_cloud(pts, origin)
    assert encode_ot(tree) == encode_ot(plain)
    assert (tree._pool._room is not None) == room and plain._pool._room is None
    first = held[0].slots
    if room:  # the first array handed out still shows the tree's slots
        assert np.shares_memory(first, tree._pool.slots)
        np.testing.assert_array_equal(first[8:16]["child"], tree._pool.slots[8:16]["child"])
    assert all(np.isfinite(np.nansum(n.value)) for n in held)


def test_a_pool_holds_at_most_what_a_child_index_can_name():
    from occmap.errors import OccmapError
    from occmap.octree import pool

    p = pool.Pool()
    with pytest.raises(OccmapError, match="at most 2,147,483,648 slots"):
        p.grow(pool.Pool.MAX_SLOTS + 8)
    assert p.slots.shape[0] == pool.Pool.INITIAL_SLOTS


@pytest.mark.skipif(not hasattr(__import__("os"), "fork"), reason="needs fork")
def test_a_process_holding_many_rooms_can_still_fork():
    """Rooms reserve addresses, not memory: forty large pools (640 GiB of addresses, far past
    this machine's memory) alive, and ``fork`` (multiprocessing's workers) still works."""
    import os

    from occmap.octree import pool

    pools = []
    for _ in range(40):
        pools.append(pool.Pool())
        pools[-1].grow(1 << 18)
    assert all(p._room is not None for p in pools) or sys.platform != "linux"
    pid = os.fork()
    if pid == 0:
        os._exit(0)
    _, status = os.waitpid(pid, 0)
    assert os.WEXITSTATUS(status) == 0


@pytest.mark.skipif(not hasattr(__import__("os"), "fork"), reason="needs fork")
def test_a_forked_child_changes_its_own_copy_of_a_pool_in_its_room():
    """A pool's room is the process's own (a private map): a child made by ``fork`` (Dask's and
    multiprocessing's workers) that inserts into the tree leaves its parent's as it was."""
    import os

    rng = np.random.default_rng(22)
    tree = OcTree(0.05)
    tree.insert_point_cloud(_room_cloud(rng, 20000, half=6.0), np.zeros(3))
    assert tree._pool._room is not None
    before = encode_ot(tree)
    more = _room_cloud(rng, 20000, half=6.0)
    pid = os.fork()
    if pid == 0:  # the child: change the tree, then leave at once
        tree.insert_point_cloud(more, np.array([0.5, 0.5, 0.5]))
        os._exit(0 if encode_ot(tree) != before else 1)
    _, status = os.waitpid(pid, 0)
    assert os.WEXITSTATUS(status) == 0
    assert encode_ot(tree) == before


def test_an_update_never_allocates_past_its_limit_when_the_free_list_runs_short():
    """A leaf root and one free block, room at the top for one more: a voxel at depth 16 needs 16
    new blocks. The update must stop for room (returning where it stopped, nothing applied) rather
    than take the free block and then write past the slots it was given."""
    from occmap.octree import pool, update

    slots = pool.new_slots(4096)[:24]  # (a write past the slots given lands in memory it owns)
    slots["value"][:] = np.nan
    slots["child"][:] = -1
    slots[0]["value"] = 0.0  # the root, a leaf
    meta = np.array([16, 8, 1], np.int64)  # top at 16, the free list: block 8
    args = (np.array([12345], np.int64), np.zeros(0, np.int8), np.array([True]), 0, 0.85, -0.4, -2.0, 3.5, True)
    no_spine = np.full((2, 17), -1, np.int64)
    assert update.apply_voxels(slots, meta, *args, len(slots), no_spine, update.new_work()) == (0, False)
    np.testing.assert_array_equal(meta, [16, 8, 1])
    grown = pool.new_slots(24 + update.ROOM)  # room for it: applied, within the slots given
    grown[:24] = slots
    assert update.apply_voxels(grown, meta, *args, len(grown), no_spine, update.new_work()) == (1, True)
    assert meta[pool.TOP] <= len(grown)
    # a marked block the same (one voxel of it): it waits for the room a whole block may need
    slots[:] = grown[:24]
    slots["value"][8:] = np.nan
    slots["child"][:] = -1
    slots[0]["value"] = 0.0
    meta[:] = [16, 8, 1]
    words = np.zeros((1, 8), np.int64)
    words[0, 0] = 1
    block = (np.array([12345 + 1], np.int64), words, np.zeros((1, 8), np.int64), np.zeros((0, 3), np.int64), 0,
             0.85, -0.4, -2.0, 3.5, True, True)
    assert update.apply_blocks(slots, meta, *block, len(slots), no_spine, update.new_work(), np.zeros(0, np.int64)) == (0, False)
    np.testing.assert_array_equal(meta, [16, 8, 1])
    grown = pool.new_slots(24 + update.BLOCK_ROOM)
    grown[:24] = slots
    assert update.apply_blocks(grown, meta, *block, len(grown), no_spine, update.new_work(), np.zeros(0, np.int64)) == (1, True)
    assert meta[pool.TOP] <= len(grown)
