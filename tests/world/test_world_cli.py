"""``occmap map3d --tiles``, ``occmap info DIR`` and ``occmap export``: the store's export is the
one-process map byte for byte; far maps export with their offset in the header."""

from __future__ import annotations

import numpy as np
import pytest

from occmap.cli import main
from occmap.io.octomap import read_octree
from occmap.io.pointclouds import write_pcd
from occmap.sim.world3d import VELODYNE_HDL32, simulate_drive


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("clouds")
    paths = []
    for i, c in enumerate(simulate_drive(3, VELODYNE_HDL32.with_azimuth_step(np.radians(3.0)), rng=5)):
        paths.append(str(folder / f"s{i}.pcd"))
        write_pcd(paths[-1], c)
    return paths


def test_map3d_tiles_info_export(tmp_path, inputs, capsys):
    store, one, joined = tmp_path / "store", tmp_path / "one.bt", tmp_path / "joined.bt"
    assert main(["map3d", *inputs, "--tiles", str(store), "--tile-size", "32", "--resolution", "0.25",
                 "--max-range", "30", "-o", str(joined)]) == 0
    out = capsys.readouterr().out
    assert "3 scans" in out and "tiles" in out and "peak memory" in out
    assert main(["map3d", *inputs, "-o", str(one), "--resolution", "0.25", "--max-range", "30"]) == 0
    assert joined.read_bytes() == one.read_bytes()
    assert main(["info", str(store)]) == 0
    text = capsys.readouterr().out
    assert "octree tile store" in text and "scans           3" in text and "tile size       32 × 0.25 m = 8 m" in text
    assert main(["export", str(store), "-o", str(tmp_path / "box.ot"), "--box", "0", "0", "-5", "10", "10", "5"]) == 0
    box = read_octree(tmp_path / "box.ot")
    lo, hi = box.metric_bounds()
    assert np.all(lo >= [-0.01, -0.01, -8.01]) and np.all(hi <= [16.01, 16.01, 8.01])  # whole tiles of 8 m


def test_far_export_records_its_offset(tmp_path):
    from occmap.world.octree_tiles import TiledOcTree

    tiled = TiledOcTree(0.1, 256)
    rng = np.random.default_rng(2)
    origin = np.array([20_000.0, 5.0, 1.0])
    tiled.insert_point_cloud(origin + rng.normal(size=(500, 3)) * 5, origin)
    offset = tiled.export(tmp_path / "far.bt")
    assert offset.tolist() == [tiled.tile_of(origin[None] - 30)[0, 0] * 25.6, -25.6, -25.6]
    text = (tmp_path / "far.bt").read_bytes()
    assert f"# occmap offset: {offset[0]!r} {offset[1]!r} {offset[2]!r}\n".encode() in text
    near = read_octree(tmp_path / "far.bt")
    centres = near.occupied_centers() + offset
    np.testing.assert_array_equal(tiled.occupancy_at(centres), 1)


def test_tile_options_need_tiles(tmp_path, inputs, capsys):
    for extra, words in [(["--workers", "2"], "--workers: only with --tiles"),
                         (["--tiles", str(tmp_path / "s"), "--workers", "2", "--scheduler", "tcp://x:1"], "give one"),
                         (["--tiles", str(tmp_path / "s"), "--png", str(tmp_path / "p.png")], "--png is not made")]:
        assert main(["map3d", *inputs, "-o", str(tmp_path / "m.bt"), *extra]) == 2
        assert words in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["map3d", inputs[0], "--tiles", str(tmp_path / "s"), "--memory-limit", "lots"])
    with pytest.raises(SystemExit):
        main(["map3d", inputs[0], "--tiles", str(tmp_path / "s"), "--tile-size", "48"])


def test_map3d_builds_on_a_running_scheduler(tmp_path, inputs, capsys):
    """--scheduler ADDRESS uses a cluster that is already running, unchanged: same bytes."""
    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                      silence_logs=40) as cluster:
        assert main(["map3d", *inputs, "--tiles", str(tmp_path / "s"), "--tile-size", "32", "--resolution", "0.25",
                     "--scheduler", cluster.scheduler_address, "-o", str(tmp_path / "remote.bt")]) == 0
    assert "2 region(s)" in capsys.readouterr().out
    assert main(["map3d", *inputs, "--resolution", "0.25", "-o", str(tmp_path / "one.bt")]) == 0
    assert (tmp_path / "remote.bt").read_bytes() == (tmp_path / "one.bt").read_bytes()
