"""A tiled octree is the one tree: node for node and byte for byte in ``.bt`` after joining, for
any tile size, split into regions, stored and resumed, evicted under a memory limit; and its
refusals (issue 17)."""

from __future__ import annotations

import numpy as np
import pytest

from occmap.errors import FormatError, InvalidArgumentError
from occmap.io.octomap import encode_bt, encode_ot
from occmap.octree import OcTree
from occmap.sim.world3d import VELODYNE_HDL32, simulate_drive
from occmap.world.octree_tiles import TiledOcTree
from occmap.world.store import IncompleteStoreError, StoreBusyError

EVERYWHERE = ((-10**6,) * 3, (10**6,) * 3)


@pytest.fixture(scope="module")
def drive():
    """Six scans of a simulated town drive (sensor-frame points with poses)."""
    return [(c.world_points(), c.origin) for c in
            simulate_drive(6, VELODYNE_HDL32.with_azimuth_step(np.radians(2.0)), rng=5)]


def _one_tree(scans, res, **kw):
    tree = OcTree(res)
    for points, origin in scans:
        tree.insert_point_cloud(points, origin, **kw)
    return tree


def _tiled(scans, res, tile_size, **kw):
    tiled = TiledOcTree(res, tile_size, region=kw.pop("region", None))
    for points, origin in scans:
        tiled.insert_point_cloud(points, origin, **kw)
    return tiled


def _regions(tiled, parts):
    """``parts`` regions that split the map's tiles along x at their quantiles."""
    xs = np.array(list(tiled.tiles()))[:, 0]
    cuts = [int(np.quantile(xs, q)) for q in np.linspace(0, 1, parts + 1)[1:-1]]
    edges = [-10**6] + [c + 1 for c in cuts] + [10**6 + 1]
    return [((a, -10**6, -10**6), (b - 1, 10**6, 10**6)) for a, b in zip(edges[:-1], edges[1:])]


@pytest.mark.parametrize("tile_size", [8, 64, 4096])
def test_tiles_joined_are_the_one_tree_byte_for_byte(drive, tile_size):
    ref = _one_tree(drive, 0.2, max_range=40.0)
    tiled = _tiled(drive, 0.2, tile_size, max_range=40.0)
    assert len(tiled.tiles()) > (100 if tile_size == 8 else 1)  # many rays cross tile borders
    tree = tiled.to_octree()
    assert tree.num_nodes() == ref.num_nodes()
    assert encode_ot(tree) == encode_ot(ref) and encode_bt(tree) == encode_bt(ref)
    probe = np.random.default_rng(0).uniform([-5, 0, -1], [60, 40, 8], size=(20000, 3))
    np.testing.assert_array_equal(tiled.log_odds_at(probe), ref.log_odds_at(probe))
    np.testing.assert_array_equal(tiled.occupancy_at(probe), ref.occupancy_at(probe))
    box = ([2.0, 3.0, -1.0], [30.0, 20.0, 4.0])
    a, b = ref.leaves(*box), tiled.leaves(*box)
    if tile_size > 8:  # (tiles of 8 voxels: uniform ones that the tree holds as one larger leaf)
        ka, kb = (np.lexsort(np.c_[lv.centers, lv.depths].T) for lv in (a, b))
        for field in ("centers", "sizes", "log_odds", "depths"):
            np.testing.assert_array_equal(getattr(b, field)[kb], getattr(a, field)[ka])
    assert tiled.stats == ref.stats


@pytest.mark.parametrize("tile_size", [8, 512])
def test_rays_cast_across_tiles_stop_where_the_one_trees_do(drive, tile_size):
    ref = _one_tree(drive, 0.2, max_range=40.0)
    tiled = _tiled(drive, 0.2, tile_size, max_range=40.0)
    directions = np.random.default_rng(1).normal(size=(4000, 3))
    directions[0] = 0.0  # no direction: not cast
    origin = drive[1][1]
    for max_range, ignore_unknown in [(-1.0, False), (15.0, False), (25.0, True), (-1.0, True)]:
        hit, ends = ref.cast_ray(origin, directions, max_range, ignore_unknown)
        t_hit, t_ends = tiled.cast_ray(origin, directions, max_range, ignore_unknown)
        np.testing.assert_array_equal(t_hit, hit)
        same = hit if ignore_unknown and max_range <= 0 else slice(None)  # (borders differ: the tiles', the keys')
        np.testing.assert_array_equal(t_ends[same], ends[same])
        assert np.isnan(t_ends[0]).all()
    assert not TiledOcTree(0.2).cast_ray(origin, directions, ignore_unknown=True)[0].any()  # an empty map


@pytest.mark.parametrize("parts", [2, 4])
def test_regions_together_hold_the_one_map(drive, parts):
    ref = _tiled(drive, 0.2, 64, discretize=True)
    pieces = [_tiled(drive, 0.2, 64, region=r, discretize=True) for r in _regions(ref, parts)]
    owned = [set(p.tiles()) for p in pieces]
    assert sum(len(o) for o in owned) == len(ref.tiles()) and set().union(*owned) == set(ref.tiles())
    for piece in pieces:
        for index in piece.tiles():
            assert encode_ot(piece.tile(index)) == encode_ot(ref.tile(index))


def test_far_from_the_origin(drive):
    """At x ≈ 10 km (beyond OctoMap's ±6.5 km at 0.2 m) the map is the same scene: every voxel of
    the joined tree near the origin has its twin 10 km away (float32 rounding moves a few)."""
    shift = np.array([10_000.0, -7_000.0, 0.0])
    far = _tiled([(p + shift, o + shift) for p, o in drive], 0.2, 512, max_range=40.0)
    near = _one_tree(drive, 0.2, max_range=40.0)
    with pytest.raises(InvalidArgumentError, match="beyond OctoMap's key range"):
        far.to_octree()
    leaves = near.leaves()
    occupied = leaves.centers[(leaves.log_odds > 0) & (leaves.sizes == 0.2)]
    agree = far.occupancy_at(occupied + shift) == 1
    assert agree.mean() > 0.99
    assert far.tile_of((occupied + shift)[:1])[0, 0] == np.floor((occupied[0, 0] + shift[0]) / (0.2 * 512))


def test_stored_resumed_and_evicted_is_the_same_map(tmp_path, drive):
    ref = _one_tree(drive, 0.2)
    with TiledOcTree.create(tmp_path / "s", 0.2, 64) as tiled:
        for points, origin in drive[:3]:
            tiled.insert_point_cloud(points, origin)
    with TiledOcTree.open(tmp_path / "s", writable=True, memory_limit=2_000_000) as tiled:
        for points, origin in drive[3:]:
            tiled.insert_point_cloud(points, origin)
        assert len(tiled._tiles) < len(tiled.tiles())  # evicted tiles went to the store
        in_memory = {i: {k: e[k] for k in ("min", "max", "nodes")} for i, e in tiled.tiles().items()}
    back = TiledOcTree.open(tmp_path / "s")
    entries = back.tiles()
    assert {i: {k: e[k] for k in ("min", "max", "nodes")} for i, e in entries.items()} == in_memory
    assert all(back.tile(i).num_nodes() == e["nodes"] and (tmp_path / "s" / e["file"]).stat().st_size == e["bytes"]
               for i, e in entries.items())
    assert all(np.allclose(back.tile_bounds(i)[0], e["min"]) for i, e in entries.items())
    assert back.stats["scans"] == 6
    assert encode_bt(back.to_octree()) == encode_bt(ref)
    tile = next(iter((tmp_path / "s" / "tiles").iterdir()))
    assert tile.read_bytes().startswith(b"# Octomap OcTree file")  # each tile a valid OctoMap .ot
    with pytest.raises(InvalidArgumentError, match="opened to read"):
        back.insert_point_cloud(*drive[0])


def test_bad_stores_and_tiles(tmp_path, drive):
    with TiledOcTree.create(tmp_path / "s", 0.2, 64) as tiled:
        tiled.insert_point_cloud(*drive[0])
        with pytest.raises(StoreBusyError):
            TiledOcTree.open(tmp_path / "s", writable=True)
    tiles = sorted((tmp_path / "s" / "tiles").iterdir())
    data = tiles[0].read_bytes()
    tiles[0].write_bytes(data[: len(data) // 2])
    tiles[1].unlink()
    back = TiledOcTree.open(tmp_path / "s")
    with pytest.raises(FormatError, match=tiles[0].name):
        back.to_octree()
    with pytest.raises(FormatError, match=f"{tiles[1].name}.*file is missing"):
        back.log_odds_at(back.tile_bounds(tuple(int(v) for v in tiles[1].stem.split("_")))[0][None] + 0.01)
    probe = back.tile_bounds(tuple(int(v) for v in tiles[2].stem.split("_")))[0][None] + 0.01
    back.log_odds_at(probe)  # the other tiles stay usable
    with pytest.raises(InvalidArgumentError, match="memory_limit needs a store"):
        TiledOcTree(0.2, memory_limit=10**6).insert_point_cloud(*drive[0])
    with pytest.raises(RuntimeError):  # the build stops part way
        with TiledOcTree.create(tmp_path / "k", 0.2, 64) as tiled:
            tiled.insert_point_cloud(*drive[0])
            raise RuntimeError
    with pytest.raises(IncompleteStoreError):
        TiledOcTree.open(tmp_path / "k")


@pytest.mark.parametrize("name", ["scan.dat", "uos", "hdl32"])
def test_real_scans_tiled_are_the_one_tree(data_dir, name):
    from occmap.io.pointclouds import read_cloud, read_uos

    if name == "scan.dat":
        scans = [read_cloud(data_dir / "octomap" / "scan.dat.bz2")]
    elif name == "uos":
        scans = [read_uos(data_dir / "scans3d" / "uos_3dtk" / f"scan00{k}.3d") for k in range(3)]
    else:
        scans = [read_cloud(p) for p in sorted((data_dir / "scans3d" / "hdl32_pair").glob("*.pcd"))]
    pairs = [(c.world_points(), c.origin) for c in scans]
    ref = _one_tree(pairs, 0.1)
    for tile_size in (32, 1024):
        tiled = _tiled(pairs, 0.1, tile_size)
        assert encode_bt(tiled.to_octree()) == encode_bt(ref)
