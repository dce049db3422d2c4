"""TiledGrid2D: equal to a growing OccupancyGrid2D cell for cell (same float32 log-odds, same
unknown cells) for any tile size, far from the origin, split into regions, through a store
(resumed, evicted under a memory limit, exported), and clear errors on bad stores."""

from __future__ import annotations

import numpy as np
import pytest

from occmap.errors import FormatError, InvalidArgumentError, OccmapError
from occmap.grid2d import LidarModel, OccupancyGrid2D
from occmap.world.grid_tiles import TiledGrid2D
from occmap.world.store import IncompleteStoreError, TileStore

RES = 0.05
FAR = 2**40  # a region bound beyond any tile here


def _grid(P, R, A, max_range, **kwargs):
    g = OccupancyGrid2D(RES, max_extent=None)
    g.insert_scans(P, R, A, max_range=max_range, **kwargs)
    return g


def _box(g):
    """The box (metres) of a growing grid's own cells."""
    (x0, y0), (H, W) = g.origin, g.shape
    return (x0, y0, x0 + W * RES, y0 + H * RES)


def _same(a, b):
    assert a.shape == b.shape
    np.testing.assert_array_equal(a.view(np.int32), b.view(np.int32))  # bit for bit, NaN (unknown) included


def _wander(rng, n, start, n_beams=121, fov=np.pi):
    """n scans along a random walk from ``start``: hits, no-returns (inf), NaN and negative readings."""
    xy = np.asarray(start) + np.cumsum(rng.normal(0.0, 0.8, (n, 2)), axis=0)
    P = np.column_stack([xy, rng.uniform(-np.pi, np.pi, n)])
    R = rng.uniform(0.05, 9.0, (n, n_beams))
    u = rng.random(R.shape)
    R[u < 0.05] = np.inf
    R[(u >= 0.05) & (u < 0.07)] = np.nan
    R[(u >= 0.07) & (u < 0.08)] = -1.0
    return P, R, np.linspace(-fov / 2, fov / 2, n_beams)


@pytest.fixture(scope="module")
def logs(data_dir):
    """The Intel and Freiburg 079 corrected logs (every 4th and 8th scan), as map_scans feeds them:
    readings at a scan's maximum range are no-returns; 30 m the map's maximum range."""
    from occmap.io.carmen import read_carmen

    out = {}
    for name, every in (("intel-corrected.log.gz", 4), ("freiburg-079-corrected.log.gz", 8)):
        poses, ranges, angles, max_ranges, _ = read_carmen(data_dir / "carmen" / name, every=every).stack()
        ranges = np.where(ranges >= max_ranges[:, None], np.inf, ranges)
        out[name] = (poses, ranges, angles, 30.0)
    return out


@pytest.mark.parametrize("name", ["intel-corrected.log.gz", "freiburg-079-corrected.log.gz"])
def test_real_logs_equal_the_grid_for_any_tile_size_and_regions(logs, name):
    P, R, A, max_range = logs[name]
    g = _grid(P, R, A, max_range)
    want, box = g.log_odds(), _box(g)
    for T in (16, 64, 1024):
        t = TiledGrid2D(RES, T)
        assert t.insert_scans(P, R, A, max_range=max_range) == g.stats
        _same(t.log_odds(box), want)
    # 2 and 4 regions of tiles of 64 (cut through the map), each fed every scan: together the map
    t = TiledGrid2D(RES, 64)
    t.insert_scans(P, R, A, max_range=max_range)
    tiles = np.array(list(t.tiles()))
    mx, my = (int(np.median(tiles[:, k])) for k in range(2))
    halves = [((-FAR, -FAR), (mx - 1, FAR)), ((mx, -FAR), (FAR, FAR))]
    quarters = [((x0, y0), (x1, y1)) for x0, x1 in ((-FAR, mx - 1), (mx, FAR)) for y0, y1 in ((-FAR, my - 1), (my, FAR))]
    for regions in (halves, quarters):
        merged = np.full(want.shape, np.nan, np.float32)
        for region in regions:
            part = TiledGrid2D(RES, 64, region=region)
            part.insert_scans(P[:len(P) // 2], R[:len(P) // 2], A, max_range=max_range)
            part.insert_scans(P[len(P) // 2:], R[len(P) // 2:], A, max_range=max_range)
            got = part.log_odds(box)
            known = ~np.isnan(got)
            assert not (known & ~np.isnan(merged)).any()  # regions own disjoint cells
            assert all(np.all((np.array(i) >= region[0]) & (np.array(i) <= region[1])) for i in part.tiles())
            merged[known] = got[known]
        _same(merged, want)


@pytest.mark.parametrize("start", [(10_000.03, 7.1), (-3.3, 2.2), (-9_876.5, -10_001.25)])
def test_synthetic_scans_far_from_the_origin_equal_the_grid(rng, start):
    P, R, A = _wander(rng, 40, start)
    model = LidarModel(0.8, 0.3)
    g = OccupancyGrid2D(RES, max_extent=None)
    g.insert_scans(P[:17], R[:17], A, max_range=7.5, model=model)
    g.insert_scans(P[17:], R[17:], A, max_range=7.5, model=model)
    want = g.log_odds()
    for T in (1, 4, 16, 256):
        t = TiledGrid2D(RES, T)
        for i in range(0, len(P), 9):  # other calls than the grid's: no difference
            t.insert_scans(P[i:i + 9], R[i:i + 9], A, max_range=7.5, model=model)
        _same(t.log_odds(_box(g)), want)
        assert t.stats == g.stats
        probe = np.column_stack([rng.uniform(*_box(g)[0::2], 3000), rng.uniform(*_box(g)[1::2], 3000)])
        np.testing.assert_array_equal(t.log_odds_at(probe), g.log_odds_at(probe))
        np.testing.assert_array_equal(t.occupancy_at(probe), g.occupancy_at(probe))
        np.testing.assert_array_equal(t.occupancy(_box(g)), g.occupancy())
    assert all(abs(lo[0] - start[0]) < 50 for lo, _ in (t.tile_bounds(i) for i in t.tiles()))


def test_tiles_list_their_bounds_and_counts(rng):
    P, R, A = _wander(rng, 10, (3.0, 4.0))
    t = TiledGrid2D(RES, 32)
    t.insert_scans(P, R, A, max_range=6.0)
    g = _grid(P, R, A, 6.0)
    entries = t.tiles()
    assert sum(e["known"] for e in entries.values()) == g.observed.sum()
    assert sum(e["occupied"] for e in entries.values()) == (g.occupancy_at(g.cell_to_world(
        np.argwhere(g.observed))) == 1).sum()
    (tx, ty), e = next(iter(entries.items()))
    np.testing.assert_allclose(e["min"], [tx * 32 * RES, ty * 32 * RES])
    np.testing.assert_allclose(e["max"], [(tx + 1) * 32 * RES, (ty + 1) * 32 * RES])
    assert e["known"] == e["occupied"] + e["free"] > 0
    assert np.array_equal(t.tile_of([[tx * 32 * RES + 0.01, ty * 32 * RES + 0.01]]), [[tx, ty]])


def test_store_round_trip_resumes_with_the_full_log_odds(tmp_path, rng):
    P, R, A = _wander(rng, 60, (10_000.0, 0.0))
    g = _grid(P, R, A, 8.0)
    with TiledGrid2D.create(tmp_path / "map", RES, 64, clamp=(0.12, 0.97)) as t:
        t.insert_scans(P[:25], R[:25], A, max_range=8.0)
    ref = OccupancyGrid2D(RES, clamp=(0.12, 0.97), max_extent=None)
    ref.insert_scans(P, R, A, max_range=8.0)
    store = TileStore.open(tmp_path / "map", kind="grid")
    assert store.state == "complete" and store.scans == 25 and store.params["clamp"] == [0.12, 0.97]
    assert all((tmp_path / "map" / e["file"]).is_file() for e in store.tiles.values())
    with TiledGrid2D.open(tmp_path / "map", writable=True) as t:
        assert t.clamp == (0.12, 0.97)
        t.insert_scans(P[25:], R[25:], A, max_range=8.0)
    back = TiledGrid2D.open(tmp_path / "map")
    _same(back.log_odds(_box(ref)), ref.log_odds())
    assert back.stats["scans"] == 60 and not np.array_equal(ref.log_odds(), g.log_odds(), equal_nan=True)
    assert back.tiles() == {i: e for i, e in TileStore.open(tmp_path / "map").tiles.items()}
    with pytest.raises(InvalidArgumentError, match="writable"):
        back.insert_scans(P[:1], R[:1], A, max_range=8.0)
    # the zarr array is readable without occmap: one tile's chunk holds its cells
    import zarr

    from occmap.world.zarr_tiles import CELL_OFFSET

    (tx, ty), e = next(iter(back.tiles().items()))
    z = zarr.open_array(str(tmp_path / "map" / "tiles"), mode="r")
    r, c = ty * 64 + CELL_OFFSET, tx * 64 + CELL_OFFSET
    x0, y0 = e["min"]
    _same(z[r:r + 64, c:c + 64], back.log_odds((x0, y0, x0 + 64 * RES - 1e-9, y0 + 64 * RES - 1e-9)))


def test_memory_limit_evicts_tiles_and_changes_nothing(tmp_path, rng):
    P, R, A = _wander(rng, 150, (-500.0, 300.0))
    g = _grid(P, R, A, 8.0)
    T = 32
    limit = 80 * 6 * T * T  # 80 tiles (a scan crosses up to about 60, the map has about 190)
    with TiledGrid2D.create(tmp_path / "map", RES, T, memory_limit=limit) as t:
        for i in range(0, len(P), 10):
            t.insert_scans(P[i:i + 10], R[i:i + 10], A, max_range=8.0)
            held, held_bytes = t.in_memory()
            assert held_bytes <= limit and held <= 80
        n_tiles = len(t.tiles())
        assert n_tiles > 80 and len(t._store.tiles) > 0  # tiles were written out before the end
        _same(t.log_odds(_box(g)), g.log_odds())  # read back through the limit too
    _same(TiledGrid2D.open(tmp_path / "map", memory_limit=limit).log_odds(_box(g)), g.log_odds())
    with pytest.raises(InvalidArgumentError, match="memory_limit"):
        TiledGrid2D(RES, T, memory_limit=limit).insert_scans(P[:1], R[:1], A, max_range=8.0)  # no store


def test_export_is_the_grid_saved(tmp_path, rng):
    P, R, A = _wander(rng, 30, (10_000.0, -20.0))
    g = _grid(P, R, A, 8.0)
    t = TiledGrid2D(RES, 64)
    t.insert_scans(P, R, A, max_range=8.0)
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    g.save(tmp_path / "a" / "m.yaml")
    t.export(_box(g), tmp_path / "b" / "m.yaml")
    for name in ("m.yaml", "m.pgm"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    # a box of part of the map: the same cells as the grid's there, its corner recorded as the origin
    from occmap.io.mapserver import save_map

    x0, y0, _, _ = _box(g)
    t.export((x0 + 1.0, y0 + 2.0, x0 + 4.0, y0 + 3.0), tmp_path / "b" / "part.yaml")
    save_map(tmp_path / "a" / "part.yaml", g.occupancy()[40:60, 20:80], RES, (0.0, 0.0))
    assert (tmp_path / "a" / "part.pgm").read_bytes() == (tmp_path / "b" / "part.pgm").read_bytes()
    np.testing.assert_allclose(OccupancyGrid2D.load(tmp_path / "b" / "part.yaml").origin, [x0 + 1.0, y0 + 2.0],
                               atol=1e-9)


def test_bad_stores_are_clear_errors(tmp_path, rng):
    P, R, A = _wander(rng, 20, (0.0, 0.0))
    (tmp_path / "plain").mkdir()
    with pytest.raises(FormatError, match="not a tile store"):
        TiledGrid2D.open(tmp_path / "plain")
    with pytest.raises(OccmapError, match="no such"):
        TiledGrid2D.open(tmp_path / "nothing")
    TileStore.create(tmp_path / "octree", "octree", RES, 64)
    with pytest.raises(FormatError, match="kind"):
        TiledGrid2D.open(tmp_path / "octree")
    with TiledGrid2D.create(tmp_path / "map", RES, 16) as t:
        t.insert_scans(P, R, A, max_range=8.0)
        want = t.log_odds((-20.0, -20.0, 20.0, 20.0))
    store = TileStore.open(tmp_path / "map")
    (bad, entry), (gone, gone_entry) = list(store.tiles.items())[:2]
    chunk = tmp_path / "map" / entry["file"]
    data = bytearray(chunk.read_bytes())
    data[len(data) // 2] ^= 0x5A
    chunk.write_bytes(bytes(data))
    (tmp_path / "map" / gone_entry["file"]).unlink()
    t = TiledGrid2D.open(tmp_path / "map")
    centre = lambda index: np.array([[(index[0] + 0.5) * 16 * RES, (index[1] + 0.5) * 16 * RES]])  # noqa: E731
    with pytest.raises(FormatError, match=rf"tile \[{bad[0]}, {bad[1]}\] is damaged") as e:
        t.log_odds_at(centre(bad))
    assert entry["file"] in str(e.value)
    with pytest.raises(FormatError, match=rf"tile \[{gone[0]}, {gone[1]}\] .* missing"):
        t.log_odds_at(centre(gone))
    # the other tiles stay usable
    others = [i for i in store.tiles if i not in (bad, gone)]
    for index in others[:5]:
        (x, y), = centre(index)
        cx, cy = int(np.floor(x / RES)) + 400, int(np.floor(y / RES)) + 400  # cells of `want` from (-20, -20)
        assert t.log_odds_at([[x, y]])[0] == pytest.approx(want[cy, cx], nan_ok=True)
    # a build that stopped part way is marked incomplete and refused
    with pytest.raises(RuntimeError):
        with TiledGrid2D.create(tmp_path / "stopped", RES, 16) as t:
            t.insert_scans(P, R, A, max_range=8.0)
            raise RuntimeError("killed")
    with pytest.raises(IncompleteStoreError):
        TiledGrid2D.open(tmp_path / "stopped")
    # a tiles folder that is not the map's zarr array
    (tmp_path / "map" / "tiles" / "zarr.json").write_text("{}")
    with pytest.raises(FormatError, match="zarr"):
        TiledGrid2D.open(tmp_path / "map")


def test_bad_arguments():
    with pytest.raises(InvalidArgumentError, match="power of two"):
        TiledGrid2D(RES, 48)
    with pytest.raises(InvalidArgumentError, match="region"):
        TiledGrid2D(RES, region=((3, 0), (2, 5)))
    with pytest.raises(InvalidArgumentError, match="prior"):
        TiledGrid2D(RES, prior=0.99)
    t = TiledGrid2D(RES)
    with pytest.raises(InvalidArgumentError, match="reach"):
        t.insert_scan((1e300, 0.0, 0.0), [1.0], [0.0])
    with pytest.raises(InvalidArgumentError, match=r"beam 0 of scan 0 .* reach"):
        t.insert_scan((0.0, 0.0, 0.0), [1e300], [0.0], max_range=1e301)
    assert t.tiles() == {} and t.stats["scans"] == 0
    assert np.isnan(t.log_odds_at([[0.0, 0.0], [np.nan, 1.0]])).all()


def test_parts_of_a_parallel_build_write_into_one_store(tmp_path, rng):
    """The parallel build's protocol (occmap.world.build): the driver holds the store, each
    worker's part (one region) writes its tiles into it and hands back their index entries."""
    P, R, A = _wander(rng, 40, (2_000.0, 3_000.0))
    g = _grid(P, R, A, 8.0)
    whole = TiledGrid2D(RES, 16)
    whole.insert_scans(P, R, A, max_range=8.0)
    mx = int(np.median([i[0] for i in whole.tiles()]))
    with TiledGrid2D.create(tmp_path / "map", RES, 16) as driver:
        for region in (((-FAR, -FAR), (mx - 1, FAR)), ((mx, -FAR), (FAR, FAR))):
            part = TiledGrid2D.build_part(tmp_path / "map", region)
            part.insert_scans(P, R, A, max_range=8.0)
            driver._store.tiles.update(part.write_tiles())
        driver.stats["scans"] = len(P)
    back = TiledGrid2D.open(tmp_path / "map")
    _same(back.log_odds(_box(g)), g.log_odds())
    assert {i: {k: v for k, v in e.items() if k != "file"} for i, e in back.tiles().items()} == whole.tiles()


def test_scans_past_the_stamp_codes_equal_the_grid(rng):
    """The 16-bit stamps run out of scan codes every 32,767 scans (then every tile's stamps are
    lowered): 70,000 small scans in calls of uneven sizes give the grid's cells."""
    n = 70_000
    P = np.column_stack([rng.uniform(-0.3, 0.3, n), rng.uniform(-0.3, 0.3, n), rng.uniform(-np.pi, np.pi, n)])
    A = np.linspace(-np.pi, np.pi, 6, endpoint=False)
    R = rng.uniform(0.3, 1.2, (n, 6))
    g = _grid(P, R, A, 1.0)
    t = TiledGrid2D(RES, 8)
    for i, j in ((0, 1), (1, 32_766), (32_766, 32_768), (32_768, 65_535), (65_535, 65_536), (65_536, n)):
        t.insert_scans(P[i:j], R[i:j], A, max_range=1.0)
    _same(t.log_odds(_box(g)), g.log_odds())
