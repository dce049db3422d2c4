"""`occmap map3d / info / convert / render` on small clouds written by the test itself."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from occmap.cli import main
from occmap.geometry import SE3
from occmap.io.octomap import read_bt, read_octree, write_ot
from occmap.io.pointclouds import read_ply, write_pcd, write_xyz
from occmap.octree import OcTree
from occmap.sim.world3d import VELODYNE_HDL32, simulate_drive


@pytest.fixture(scope="module")
def clouds():
    return simulate_drive(3, VELODYNE_HDL32.with_azimuth_step(np.radians(2.0)), rng=5)


def _write_inputs(folder, clouds):
    paths = []
    for i, c in enumerate(clouds):
        path = folder / f"scan{i}.pcd"
        write_pcd(path, c.points, viewpoint=c.pose)  # sensor-frame points, pose in VIEWPOINT
        paths.append(str(path))
    return paths


def test_map3d_builds_the_same_tree_as_the_library(tmp_path, capsys, clouds):
    inputs = _write_inputs(tmp_path, clouds)
    out = tmp_path / "map.bt"
    assert main(["map3d", *inputs, "-o", str(out), "--resolution", "0.2", "--max-range", "30",
                 "--png", str(tmp_path / "map.png")]) == 0
    text = capsys.readouterr().out
    assert "3 scans" in text and "points/s" in text
    tree = OcTree(0.2)
    for c in clouds:
        tree.insert_point_cloud(c.world_points(), c.origin, max_range=30.0)
    loaded = read_bt(out)
    probe = np.random.default_rng(0).uniform([-5, 0, -1], [60, 40, 8], size=(5000, 3))
    np.testing.assert_array_equal(loaded.occupancy_at(probe), tree.occupancy_at(probe))
    assert Image.open(tmp_path / "map.png").size[0] > 100


def test_info_convert_render(tmp_path, capsys, clouds):
    tree = OcTree(0.25)
    for c in clouds:
        tree.insert_point_cloud(c.world_points(), c.origin, max_range=30.0)
    write_ot(tree, tmp_path / "map.ot")
    assert main(["info", str(tmp_path / "map.ot")]) == 0
    text = capsys.readouterr().out
    assert f"{tree.num_nodes():,}" in text and "occupied" in text
    assert main(["convert", str(tmp_path / "map.ot"), str(tmp_path / "map.bt")]) == 0
    assert read_octree(tmp_path / "map.bt").num_nodes() <= tree.num_nodes()
    assert main(["convert", str(tmp_path / "map.ot"), str(tmp_path / "map.ply")]) == 0
    assert len(read_ply(tmp_path / "map.ply")) == len(tree.occupied_centers())
    assert main(["render", str(tmp_path / "map.ot"), "-o", str(tmp_path / "top.png")]) == 0
    assert main(["render", str(tmp_path / "map.ot"), "-o", str(tmp_path / "cut.png"), "--slice", "1.0"]) == 0
    cut = np.asarray(Image.open(tmp_path / "cut.png").convert("RGB"))
    assert (cut == 26).all(axis=-1).any() and (cut == 255).all(axis=-1).any()  # occupied and free pixels
    assert main(["render", str(tmp_path / "map.ot"), "-o", str(tmp_path / "low.png"), "--z-max", "1.0"]) == 0
    low, top = (np.asarray(Image.open(tmp_path / n).convert("RGB")) for n in ("low.png", "top.png"))
    assert low.shape == top.shape and (low != top).any()  # the cut changes what is drawn


def test_map3d_reads_xyz_and_reports_bad_input(tmp_path, capsys, clouds):
    path = tmp_path / "scan.xyz"
    write_xyz(path, clouds[0].points)  # sensor at the origin
    assert main(["map3d", str(path), "-o", str(tmp_path / "a.bt")]) == 0
    bad = tmp_path / "bad.xyz"
    bad.write_text("1 2 3\n4 five 6\n")
    assert main(["map3d", str(bad), "-o", str(tmp_path / "b.bt")]) == 2
    assert "line 2" in capsys.readouterr().err
    assert main(["map3d", str(path), "-o", str(tmp_path / "c.xyz")]) == 2
    assert not (tmp_path / "c.xyz").exists()
    assert main(["info", str(tmp_path / "missing.bt")]) == 2


def test_pose_moves_the_map(tmp_path, clouds):
    """A cloud written with a pose lands where the pose puts it."""
    c = clouds[0]
    shifted = SE3.from_rt(np.eye(3), [100.0, 0.0, 0.0]) @ c.pose
    write_pcd(tmp_path / "a.pcd", c.points, viewpoint=c.pose)
    write_pcd(tmp_path / "s.pcd", c.points, viewpoint=shifted)
    for name in ("a", "s"):
        assert main(["map3d", str(tmp_path / f"{name}.pcd"), "-o", str(tmp_path / f"{name}.bt"), "--resolution", "0.5"]) == 0
    lo_a, hi_a = read_bt(tmp_path / "a.bt").metric_bounds()
    lo_s, hi_s = read_bt(tmp_path / "s.bt").metric_bounds()
    np.testing.assert_allclose(lo_s - lo_a, [100, 0, 0], atol=0.5)
    np.testing.assert_allclose(hi_s - hi_a, [100, 0, 0], atol=0.5)


def test_map3d_says_when_it_assumes_the_identity_pose(tmp_path, capsys, clouds):
    posed = _write_inputs(tmp_path, clouds[:1])
    bare = []
    for i, c in enumerate(clouds[1:]):
        bare.append(str(tmp_path / f"bare{i}.xyz"))
        write_xyz(bare[-1], c.points)  # no pose in an XYZ file
    assert main(["map3d", *posed, *bare, "-o", str(tmp_path / "m.bt"), "--resolution", "0.5"]) == 0
    err = capsys.readouterr().err
    assert "note: 2 of 3 point clouds carry no sensor pose" in err and "bare0.xyz" in err and "scan0" not in err
    assert main(["map3d", *posed, "-o", str(tmp_path / "n.bt"), "--resolution", "0.5"]) == 0
    assert "note" not in capsys.readouterr().err
    pcl = []  # PCD files written without a pose: PCL's default VIEWPOINT, the identity
    for i, c in enumerate(clouds[:2]):
        pcl.append(str(tmp_path / f"pcl{i}.pcd"))
        write_pcd(pcl[-1], c.points)
    assert main(["map3d", *pcl, "-o", str(tmp_path / "p.bt"), "--resolution", "0.5"]) == 0
    assert "note: 2 of 2 point clouds carry no sensor pose" in capsys.readouterr().err


def test_map3d_skips_points_outside_the_key_range_and_says_so(tmp_path, capsys, clouds):
    """A stray point 50 km away skips its ray only (OctoMap's rule): the map is the one without it."""
    c = clouds[0]
    stray = np.concatenate([c.points[:10], [[50_000.0, 0.0, 0.0]], c.points[10:]])
    write_pcd(tmp_path / "stray.pcd", stray, viewpoint=c.pose)
    write_pcd(tmp_path / "clean.pcd", c.points, viewpoint=c.pose)
    for name in ("stray", "clean"):
        assert main(["map3d", str(tmp_path / f"{name}.pcd"), "-o", str(tmp_path / f"{name}.bt"), "--resolution", "0.5"]) == 0
    err = capsys.readouterr().err
    assert "note: points outside the octree's key range (±16384 m at 0.5 m) skipped: 1," in err
    assert (tmp_path / "stray.bt").read_bytes() == (tmp_path / "clean.bt").read_bytes()
