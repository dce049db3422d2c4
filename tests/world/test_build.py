"""A parallel build on Dask is the one-process map whatever the workers (issue 17), its regions
cover the plane and split the work, and a build stopped part way leaves the store incomplete."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from occmap.io.octomap import encode_bt
from occmap.io.pointclouds import write_pcd
from occmap.octree import OcTree
from occmap.sim.world3d import VELODYNE_HDL32, simulate_drive
from occmap.world.build import UNBOUNDED, build_octree, partition
from occmap.world.octree_tiles import TiledOcTree
from occmap.sources import CloudFiles
from occmap.world.store import IncompleteStoreError


@pytest.fixture(scope="module")
def scans(tmp_path_factory):
    """Eight scans of a simulated drive as PCD files (pose in VIEWPOINT)."""
    folder = tmp_path_factory.mktemp("drive")
    paths = []
    for i, c in enumerate(simulate_drive(8, VELODYNE_HDL32.with_azimuth_step(np.radians(2.0)), rng=5)):
        paths.append(folder / f"scan{i}.pcd")
        write_pcd(paths[-1], c)
    return CloudFiles(paths)


def _one_tree(source, **kw):
    tree = OcTree(0.2)
    for k in range(len(source)):
        cloud = source.scan(k)
        tree.insert_point_cloud(cloud.world_points(), cloud.origin, **kw)
    return tree


@pytest.mark.parametrize("workers, tile_size", [(1, 16), (2, 16), (4, 256)])
def test_any_number_of_workers_builds_the_one_map(tmp_path, scans, workers, tile_size):
    ref = _one_tree(scans, max_range=30.0)
    lines = []
    summary = build_octree(tmp_path / "s", scans, 0.2, tile_size, max_range=30.0, workers=workers,
                           progress=lines.append)
    assert len(summary.regions) == len(lines) <= workers
    assert summary.stats == ref.stats
    assert encode_bt(TiledOcTree.open(tmp_path / "s").to_octree()) == encode_bt(ref)


def test_a_build_resumes_an_existing_store(tmp_path, scans):
    ref = _one_tree(scans)
    half = CloudFiles(scans.paths[:4])
    build_octree(tmp_path / "s", half, 0.2, 32)
    build_octree(tmp_path / "s", CloudFiles(scans.paths[4:]), workers=2)
    tiled = TiledOcTree.open(tmp_path / "s")
    assert tiled.stats["scans"] == 8 and encode_bt(tiled.to_octree()) == encode_bt(ref)


def test_regions_cover_the_plane_and_split_the_work():
    rng = np.random.default_rng(3)
    cells = np.concatenate([rng.integers(0, 40, (300, 2)), rng.integers(100, 110, (100, 2))])
    weights = rng.uniform(1, 2, len(cells))
    assert len(partition(np.zeros((5, 2), np.int64), np.ones(5), 4)) == 1  # one column: nothing to cut
    for parts in (1, 2, 3, 4, 16):
        regions = partition(cells, weights, parts)
        assert len(regions) == parts
        probe = np.concatenate([cells, rng.integers(-UNBOUNDED // 2, UNBOUNDED // 2, (2000, 2))])
        inside = [np.all((np.array(lo[:2]) <= probe) & (probe <= np.array(hi[:2])), axis=1) for lo, hi in regions]
        np.testing.assert_array_equal(np.sum(inside, axis=0), 1)  # every column in exactly one region
        shares = [weights[m[: len(cells)]].sum() / weights.sum() for m in inside]
        assert max(shares) < 1.6 / parts  # about even (the sensors are clustered, cuts fall on columns)


_KILLED_BUILD = """
import sys
from occmap.world.build import build_octree
from occmap.sources import CloudFiles
build_octree(sys.argv[1], CloudFiles(sys.argv[2:] * 50), 0.2, 16, memory_limit=1)  # tiles written as it goes
"""


def test_a_killed_build_leaves_the_store_marked_incomplete(tmp_path, scans):
    proc = subprocess.Popen([sys.executable, "-c", _KILLED_BUILD, str(tmp_path / "s"), *scans.paths])
    deadline = time.monotonic() + 120
    while not (tmp_path / "s" / "tiles").is_dir() or not any((tmp_path / "s" / "tiles").iterdir()):
        assert time.monotonic() < deadline and proc.poll() is None
        time.sleep(0.05)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    with pytest.raises(IncompleteStoreError, match="incomplete"):
        TiledOcTree.open(tmp_path / "s")


def _office_log(path):
    """A CARMEN log of the simulated office (FLASER, 180 beams, 30 scans)."""
    from occmap.sim import World2D, simulate_scans

    world = World2D.default()
    poses = world.default_trajectory(n=30)
    lines = []
    for k, (p, s) in enumerate(zip(poses, simulate_scans(world, poses, n_beams=180, rng=0))):
        r = " ".join(f"{v:.3f}" for v in np.minimum(s.ranges, 10.0))
        lines.append(f"FLASER {len(s.ranges)} {r} {p[0]} {p[1]} {p[2]} {p[0]} {p[1]} {p[2]} {k}.0 test {k}.0\n")
    path.write_text("".join(lines))
    return path


@pytest.mark.parametrize("workers", [1, 2])
def test_a_grid_built_on_any_workers_exports_map2ds_files(tmp_path, workers):
    """The tiled grid's export of the whole map is ``occmap map2d``'s pair, byte for byte: on the
    simulated office, and (two workers) on the Intel log when the shared data is there."""
    from pathlib import Path

    from occmap._data import find_shared_data
    from occmap.cli import main

    logs = [_office_log(tmp_path / "office.log")]
    data = find_shared_data(Path(__file__).resolve().parent) if workers == 2 else None
    if data is not None:
        logs.append(data / "carmen" / "intel-corrected.log.gz")  # (Freiburg 079's tiles: test_grid_tiles.py)
    for i, log in enumerate(logs):
        every = ["--every", "8"] if i else []
        assert main(["map2d", str(log), "-o", str(tmp_path / f"one{i}.yaml"), *every]) == 0
        assert main(["map2d", str(log), "--tiles", str(tmp_path / f"s{i}"), "--tile-size", "64", "--workers",
                     str(workers), "-o", str(tmp_path / f"tiled{i}.yaml"), *every]) == 0
        assert (tmp_path / f"one{i}.pgm").read_bytes() == (tmp_path / f"tiled{i}.pgm").read_bytes()
        one, tiled = ((tmp_path / f"{n}{i}.yaml").read_text().replace(f"{n}{i}.pgm", "") for n in ("one", "tiled"))
        assert one == tiled
