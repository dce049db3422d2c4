"""``occmap view``: the viewer opened in a real headless Chromium (system package ``chromium``,
driven by Playwright), its screenshots checked pixel by pixel; the level of detail checked against
the octree's leaves; the command's start, address and clean stop.

The browser may reach the viewer's own address only: every other request is refused and recorded,
so the screenshots also show that the viewer draws with no internet.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
import urllib.request

import numpy as np
import pytest

from headless import VIEW, Page, image, keep

@pytest.fixture(scope="module")
def geb079(data_dir):
    return data_dir / "octomap" / "geb079.bt"


def small_tile_store(path):
    """A tile store of one synthetic scan: a room 6 × 4 × 2.5 m seen from its middle, tiles of
    32 voxels (1.6 m), so the room spans many tiles."""
    from occmap.world import TiledOcTree

    u, v = np.meshgrid(np.linspace(0, 1, 120), np.linspace(0, 1, 50))
    u, v = u.ravel(), v.ravel()
    walls = [np.stack([u * 6, np.zeros_like(u), v * 2.5], 1), np.stack([u * 6, np.full_like(u, 4.0), v * 2.5], 1),
             np.stack([np.zeros_like(u), u * 4, v * 2.5], 1), np.stack([np.full_like(u, 6.0), u * 4, v * 2.5], 1)]
    points = np.concatenate(walls) + [0.013, 0.017, 0.011]
    with TiledOcTree.create(path, 0.05, tile_size=32) as tiles:
        tiles.insert_point_cloud(points, [3.0, 2.0, 1.2])
    return TiledOcTree.open(path)


def test_geb079_drawn_offline_then_a_tile_store_opened_from_the_panel(browser, geb079, tmp_path):
    from occmap.viz.viewer import Viewer

    store = tmp_path / "room-tiles"
    tiled = small_tile_store(store)
    with Viewer(geb079, port=0) as viewer:
        assert viewer.url.startswith("http://127.0.0.1:")
        # every occupied leaf drawn: OctoMap's count for this file (143,729, the data's README)
        assert (viewer.occupied.depth, viewer.occupied.voxels.count, viewer.occupied.leaves) == (16, 143_729, 143_729)
        tab = Page(browser, viewer.url)
        first, n_first = tab.drawn()
        keep("geb079", first)
        assert n_first >= 2000, f"the map is not drawn: {n_first} pixels of the height ramp"
        assert tab.refused == [], f"the viewer asked for other addresses: {tab.refused}"
        viewer._show_free.value = True  # as the panel's check box does: every free leaf (284,415, the README)
        assert (viewer.free.depth, viewer.free.voxels.count) == (16, 284_415)
        assert np.all(viewer.free.voxels.log_odds < 0)
        viewer._show_free.value = False

        tab.open_in_panel(store)  # the second map, in the same server and the same tab
        deadline = time.monotonic() + 20
        while viewer.scene.path != store and time.monotonic() < deadline:
            time.sleep(0.1)
        assert viewer.scene.kind == "octree tile store"
        lv = tiled.leaves()
        occupied = lv.centers[lv.log_odds >= 0]
        drawn = viewer.occupied.voxels.centers
        assert len(drawn) == len(occupied) > 1000
        assert np.allclose(np.sort(drawn, axis=0), np.sort(occupied, axis=0), atol=1e-4)  # the same voxels, placed
        tab.page.wait_for_timeout(1000)
        second, n_second = tab.drawn()
        keep("tile-store", second)
        assert n_second >= 2000, f"the tile store is not drawn: {n_second} pixels of the height ramp"
        a = np.asarray(image(first), np.int64)
        b = np.asarray(image(second), np.int64)
        changed = np.mean(np.any(np.abs(a - b) > 40, axis=2)[:, : VIEW["width"] // 2])
        assert changed > 0.05, f"only {changed:.1%} of the picture changed after opening the second map"
        assert tab.refused == []

        tab.open_in_panel(tmp_path / "no-such-map.bt")  # a bad path: said in the panel, the map stays
        tab.page.get_by_text("could not open").wait_for(timeout=10_000)
        assert viewer.scene.path == store


def test_large_map_level_of_detail_is_conservative_and_capped(data_dir):
    """fr_079.bt capped at 50,000 boxes: a coarser depth, at most the cap, and every occupied leaf
    inside a drawn box (an inner node holds its children's maximum: nothing hidden)."""
    from occmap.io.octomap import read_octree
    from occmap.viz._lod import pick_level
    from occmap.viz._maps import open_scene

    scene = open_scene(data_dir / "octomap" / "fr_079.bt")
    occ = lambda v: v.log_odds >= scene.occupied_log_odds  # noqa: E731
    level = pick_level(scene.nodes_at, occ, 50_000)
    assert level.leaves == 372_904 and level.depth == 14 and level.voxels.count <= 50_000
    tree = read_octree(data_dir / "octomap" / "fr_079.bt")
    lv = tree.leaves()
    size = tree.resolution * 2 ** (16 - level.depth)
    fine = (lv.log_odds >= tree.occupied_log_odds) & (lv.sizes <= size)  # leaves no larger than a drawn box
    small = np.isclose(level.voxels.sizes, size)
    assert small.sum() > 0.9 * level.voxels.count
    boxes = {tuple(k) for k in np.floor(level.voxels.centers[small] / size).astype(np.int64).tolist()}
    assert len(boxes) == small.sum()  # each box once
    # the boxes are exactly those holding an occupied leaf: none hidden, none drawn in vain
    assert boxes == {tuple(k) for k in np.floor(lv.centers[fine] / size).astype(np.int64).tolist()}


def test_command_serves_until_interrupted(geb079):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    cmd = [sys.executable, "-m", "occmap", "view", str(geb079), "--port", "0", "--no-browser"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        url = None
        deadline = time.monotonic() + 60
        while url is None and time.monotonic() < deadline:
            line = proc.stdout.readline()
            found = re.search(r"serving at (http://127\.0\.0\.1:\d+/)", line)
            url = found and found.group(1)
        assert url, "the command never printed its address"
        with urllib.request.urlopen(url, timeout=10) as r:
            assert r.status == 200 and b"<html" in r.read(2000).lower()
        proc.send_signal(signal.SIGINT)  # Ctrl-C
        out, err = proc.communicate(timeout=30)
        assert proc.returncode == 0, err
        assert "Traceback" not in err
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()



def test_command_refuses_bad_paths_in_one_line(tmp_path, capsys):
    from occmap.cli import main

    bad = tmp_path / "not-a-map.bt"
    bad.write_bytes(b"# Octomap OcTree binary file\nid OcTree\nsize 7\nres 0.1\ndata\n\x03")
    for path, says in ((tmp_path / "missing.bt", "missing.bt"), (bad, "not-a-map.bt"), (tmp_path, "index.json"),
                       (tmp_path / "notes.txt.md", "cannot show")):
        if path.suffix == ".md":
            path.write_text("hello")
        assert main(["view", str(path), "--port", "0", "--no-browser"]) == 2
        err = capsys.readouterr().err
        assert err.startswith("occmap view: error:") and says in err and err.count("\n") == 1, err


def test_a_tile_store_is_counted_tile_by_tile_and_drawn_at_the_level_that_fits(tmp_path):
    """A tile store's nodes per depth counted one tile at a time equal the whole map's; with a
    small cap the viewer builds only the coarser level, which hides no occupied voxel."""
    from occmap.viz.viewer import Viewer

    tiled = small_tile_store(tmp_path / "room-tiles")
    lv = tiled.leaves()
    occupied = lv.centers[lv.log_odds >= 0]
    with Viewer(tmp_path / "room-tiles", port=0, max_voxels=len(occupied) // 3) as viewer:
        counts = viewer.scene.counts
        assert viewer._colour.visible and viewer._show_free.visible and not viewer._step.visible
        assert counts(16) == (len(occupied), int(np.count_nonzero(lv.log_odds < 0)))
        assert counts(15)[0] < counts(16)[0] and counts(14)[0] < counts(15)[0]
        level = viewer.occupied
        assert level.depth < 16 and level.voxels.count == counts(level.depth)[0] <= len(occupied) // 3
        assert level.leaves == len(occupied)
        v = level.voxels
        half = v.sizes[:, None] / 2
        inside = np.all(np.abs(occupied[:, None, :] - v.centers[None]) <= half[None] + 1e-4, axis=2).any(axis=1)
        assert inside.all(), f"{np.count_nonzero(~inside)} occupied voxels outside every drawn box"


def test_a_port_in_use_is_refused_not_moved(tmp_path, capsys):
    """viser moves on to the next free port; the user asked for this one, so it is an error."""
    import socket

    from occmap.cli import main
    from occmap.io.mapserver import save_map

    save_map(tmp_path / "m.yaml", np.zeros((2, 2), np.int8), 0.5, (0.0, 0.0, 0.0))
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        assert main(["view", str(tmp_path / "m.yaml"), "--port", str(port), "--no-browser"]) == 2
        err = capsys.readouterr().err
        assert f"port {port}" in err and "in use" in err and err.count("\n") == 1, err


def test_play_keeps_the_run_s_pace():
    from occmap.viz.viewer import PLAY_RATE, played_to

    stamps = np.concatenate([np.arange(10) * 0.1, 5.0 + np.arange(10) * 0.1])  # a 4.1 s gap after step 9
    assert played_to(stamps, 0, 0.35, 1.0) == 3  # stamps 0.0 … 0.3 reached
    assert played_to(stamps, 0, 0.36, 2.0) == 7
    assert played_to(stamps, 2, 0.05, 1.0) == 2  # nothing new yet
    assert played_to(stamps, 9, 4.0, 1.0) == 9  # the gap is waited through, as recorded
    assert played_to(stamps, 9, 4.15, 1.0) == 10
    assert played_to(stamps, 5, 1e6, 50.0) == 19  # stops at the last step
    flat = np.zeros(20)  # no pace of its own: PLAY_RATE steps a second
    assert played_to(flat, 4, 1.0, 1.0) == 4 + int(PLAY_RATE)
    assert played_to(flat, 4, 1.0, 2.0) == min(4 + int(2 * PLAY_RATE), 19)


def test_slice_and_colour_modes_select_and_colour_the_right_boxes():
    from occmap.viz._lod import Voxels, cut, ramp

    v = Voxels(np.array([[0, 0, 0.5], [0, 0, 1.5], [0, 0, 2.25]], np.float32), np.array([1, 1, 0.5], np.float32),
               np.zeros(3, np.float32))
    assert cut(v, "below", 1.0).tolist() == [True, True, False]  # bottoms at 0, 1, 2
    assert cut(v, "at", 1.0).tolist() == [False, True, False]
    assert cut(v, "at", 2.3).tolist() == [False, False, True]
    assert cut(v, "off", -5.0).all()
    c = ramp(v.centers[:, 2], (0.5, 2.25))
    assert c[0].tolist() == [48, 18, 59] and c[2].tolist() == [250, 230, 40]  # the ramp's two ends


def test_a_2d_map_lies_where_its_yaml_puts_it(tmp_path):
    from occmap.io.mapserver import save_map
    from occmap.viz._maps import open_scene

    occ = np.zeros((2, 4), np.int8)
    occ[0, 0], occ[1, 3] = 100, -1
    save_map(tmp_path / "m.yaml", occ, 0.5, (1.0, 2.0, np.pi / 2))
    plane = open_scene(tmp_path / "m.yaml").plane
    # the map's x axis along the world's +y (yaw 90°): centre = corner + R(yaw) · (1.0, 0.5)
    assert np.allclose(plane.center, [0.5, 3.0, 0.0]) and (plane.width, plane.height) == (2.0, 1.0)
    assert plane.yaw == pytest.approx(np.pi / 2)
    assert plane.rgb[0, 0].tolist() == [0, 0, 0] and plane.rgb[1, 3].tolist() == [205] * 3  # row 0: lowest y
    assert plane.rgb[1, 0].tolist() == [255] * 3


def test_a_cloud_is_shown_in_the_world_with_its_sensor(tmp_path):
    from occmap.geometry import SE3
    from occmap.io.pointclouds import write_pcd
    from occmap.viz._maps import open_scene

    pose = SE3.from_euler_zyx(np.pi / 2, 0.0, 0.0, translation=[10.0, 0.0, 1.0])
    write_pcd(tmp_path / "c.pcd", np.array([[1.0, 0.0, 0.0], [0.0, 2.0, 0.5]]), viewpoint=pose)
    scene = open_scene(tmp_path / "c.pcd")
    assert np.allclose(scene.points, [[10.0, 1.0, 1.0], [8.0, 0.0, 1.5]], atol=1e-6)
    assert np.allclose(scene.sensor_path, [[10.0, 0.0, 1.0]])


def test_a_2d_tile_store_is_a_plane_around_its_scans(tmp_path):
    from occmap.viz._maps import open_scene
    from occmap.world import TiledGrid2D

    angles = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    with TiledGrid2D.create(tmp_path / "grid", 0.1, tile_size=32) as grid:  # a round room, radius 3 m, at (1, 2)
        grid.insert_scans(np.array([[1.0, 2.0, 0.0]]), np.full((1, 360), 3.0), angles, max_range=10.0)
    plane = open_scene(tmp_path / "grid").plane
    assert np.allclose(plane.center[:2], [1.0, 2.0], atol=0.1) and abs(plane.width - 6.0) < 0.3
    grey = plane.rgb[..., 0]
    h, w = grey.shape
    assert grey[h // 2, w // 2] > 128 and grey[0, 0] == 205  # free at the robot, unknown in the corners
    assert (grey < 128).sum() > 100  # the wall


def test_a_wide_2d_tile_store_is_drawn_coarser_with_every_wall_kept(tmp_path, monkeypatch):
    """A store wider than the picture's pixels: 4-cell pixels, each the most occupied of its cells,
    read tile by tile; the same store at full size agrees cell block by cell block."""
    from occmap.logodds import occupancy_values
    from occmap.viz import _maps
    from occmap.world import TiledGrid2D

    angles = np.linspace(-np.pi, np.pi, 720, endpoint=False)
    with TiledGrid2D.create(tmp_path / "grid", 0.1, tile_size=16) as grid:  # a room 8 × 8 m around (-1.3, 0.7)
        ranges = 4.0 / np.maximum(np.abs(np.cos(angles)), np.abs(np.sin(angles)))
        grid.insert_scans(np.array([[-1.3, 0.7, 0.0]]), ranges[None], angles, max_range=10.0)
        x0, y0, x1, y1 = grid.extent
        full = occupancy_values(grid.log_odds(((x0 + 0.5) * 0.1, (y0 + 0.5) * 0.1, (x1 - 0.5) * 0.1,
                                               (y1 - 0.5) * 0.1)))
    monkeypatch.setattr(_maps, "MAX_PLANE_PIXELS", (x1 - x0) // 4 + 1)
    plane = _maps.open_scene(tmp_path / "grid").plane
    k = 4
    assert plane.width == pytest.approx(plane.rgb.shape[1] * k * 0.1)
    # the full raster on the lattice of 4-cell pixels, reduced by the same rule
    px0, py0 = x0 // k, y0 // k
    padded = np.full(((y1 - 1) // k - py0 + 1, (x1 - 1) // k - px0 + 1), -1, np.int16)
    big = np.full((padded.shape[0] * k, padded.shape[1] * k), -1, np.int16)
    big[y0 - py0 * k:y1 - py0 * k, x0 - px0 * k:x1 - px0 * k] = full
    expected = big.reshape(padded.shape[0], k, padded.shape[1], k).max(axis=(1, 3))
    grey = plane.rgb[..., 0].astype(np.int16)
    expected_grey = np.where(expected < 0, 205, np.rint(255 * (1 - np.clip(expected, 0, 100) / 100.0)))
    np.testing.assert_array_equal(grey, expected_grey)
    assert (expected >= 65).sum() >= 4 * (8 / 0.4) - 4  # the four walls, unbroken at 0.4 m pixels
