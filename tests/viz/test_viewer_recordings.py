"""Mapping and local-map replays to scrub (:mod:`occmap.mapping2d_recording`,
:mod:`occmap.local.recording`): recorded by ``occmap map2d --record`` on a part of the Intel log
and ``occmap local --record`` on the simulated street, read back, checked against what the
commands build, opened in the viewer in headless Chromium and moved through with the time slider;
and broken files refused, naming the file and the entry.
"""

from __future__ import annotations

import numpy as np
import pytest

from occmap.cli import main
from occmap.errors import FormatError

from occmap.viz._scene3d import BACKGROUND

from headless import Page, image, keep

EVERY = 10  # the Intel log's every 10th scan: 91 scans
RECORD_EVERY = 5
STREET_SECONDS = 4.0
WIDE = {"width": 1200, "height": 700}  # the scene left of the panel


@pytest.fixture(scope="module")
def mapping(data_dir, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("mapping")
    log = data_dir / "carmen" / "intel-corrected.log.gz"
    argv = ["map2d", str(log), "--every", str(EVERY), "--resolution", "0.1", "--max-range", "30",
            "-o", str(tmp / "intel.yaml"), "--record", str(tmp / "intel.npz"), "--record-every", str(RECORD_EVERY)]
    assert main(argv) == 0
    return log, tmp


def _street_log(path, seconds: float) -> None:
    """The simulated street's lidar as a CARMEN log: FLASER lines, 181 beams over the 180° ahead,
    the true pose as the laser's and the odometry, 10 Hz."""
    from occmap.sim.street import Street
    from occmap.sim.world2d import simulate_lidar

    street = Street.default()
    rng = np.random.default_rng(0)
    lines = []
    for t in np.arange(0.0, seconds + 1e-9, 0.1):
        pose = street.robot_pose(float(t))
        scan = simulate_lidar(street.world(float(t)), pose, n_beams=181, fov=np.pi, max_range=30.0, sigma=0.02,
                              rng=rng)
        ranges, p = " ".join(f"{r:.3f}" for r in scan.ranges), " ".join(f"{v:.6f}" for v in pose)
        lines.append(f"FLASER 181 {ranges} {p} {p} {t:.3f} sim {t:.3f}\n")
    path.write_text("".join(lines))


@pytest.fixture(scope="module")
def local(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("local")
    _street_log(tmp / "street.log", STREET_SECONDS)
    assert main(["local", str(tmp / "street.log"), "-o", str(tmp / "street.gif"), "--tracking", "--max-range", "30",
                 "--frame-every", "1", "--record", str(tmp / "street.npz")]) == 0
    return tmp


def test_the_mapping_replay_ends_on_the_map_map2d_wrote(mapping):
    from occmap.io.carmen import read_carmen
    from occmap.io.mapserver import save_map
    from occmap.mapping2d import map_scans
    from occmap.mapping2d_recording import MappingRecording
    from occmap.scan import ScanStack

    log, tmp = mapping
    rec = MappingRecording.load(tmp / "intel.npz")
    stack = read_carmen(log, every=EVERY, max_range=30.0).stack()
    n = len(stack.poses)
    assert len(rec) == n == 91 and np.array_equal(rec.poses, stack.poses) and np.array_equal(rec.stamps, stack.stamps)
    assert rec.delta_steps.tolist() == [*range(RECORD_EVERY - 1, n, RECORD_EVERY), n - 1]
    # the last state is the map: the same picture map2d wrote, and the same values as a map built in one go
    final = rec.occupancy_at(n - 1)
    save_map(tmp / "replayed.yaml", final, rec.resolution, rec.origin)
    assert (tmp / "replayed.pgm").read_bytes() == (tmp / "intel.pgm").read_bytes()
    whole = map_scans(stack, 0.1, 30.0).grid
    assert np.array_equal(final, whole.occupancy()) and np.allclose(rec.origin, whole.origin)
    # a middle state is the map of the scans so far (a smaller map: placed in the final one's frame)
    k = 40
    part = map_scans(ScanStack(*(a if a is stack.angles and a.ndim == 1 else a[:k] for a in stack)), 0.1, 30.0).grid
    r, c = np.rint((part.origin - rec.origin) / rec.resolution).astype(int)[::-1]
    h, w = part.shape
    expected = np.full(rec.shape, -1, np.int8)
    expected[r:r + h, c:c + w] = part.occupancy()
    np.testing.assert_array_equal(rec.occupancy_at(k - 1), expected)
    assert 0 < (rec.occupancy_at(k - 1) >= 0).sum() < 0.8 * (final >= 0).sum()
    # scrubbing back and forth gives the same states as going forward once
    for step in (n - 1, 3, 60, 59, 0, 90, 17):
        state = np.full(rec.shape, -1, np.int8).reshape(-1)
        for j in range(rec.deltas_at(step)):
            cut = slice(rec.delta_offsets[j], rec.delta_offsets[j + 1])
            state[rec.delta_cells[cut]] = rec.delta_values[cut]
        np.testing.assert_array_equal(rec.occupancy_at(step).reshape(-1), state, err_msg=f"step {step}")


def test_the_local_replay_follows_the_robot(local):
    from PIL import Image

    from occmap.local.recording import LocalMapRecording
    from occmap.sim.street import Street

    rec = LocalMapRecording.load(local / "street.npz")
    n = int(round(STREET_SECONDS / 0.1)) + 1
    with Image.open(local / "street.gif") as gif:
        assert gif.n_frames == len(rec) == n
    assert rec.costs.shape == (n, 200, 200) and rec.costs.dtype == np.uint8
    # the window is centred on the robot (to a cell), which drives 0.6 m/s … along the street
    centres = rec.origins + 0.5 * 200 * rec.resolution
    assert np.abs(centres - rec.poses[:, :2]).max() <= rec.resolution
    street = Street.default()
    truth = np.array([street.robot_pose(float(t)) for t in rec.stamps])
    np.testing.assert_allclose(rec.poses, truth, atol=1e-5)
    assert np.hypot(*(rec.poses[-1, :2] - rec.poses[0, :2])) > 4
    # the costmap holds lethal cells (the street's walls, parked cars) from the first scan, free
    # space once a few scans have cleared it
    assert (rec.costs == 254).any(axis=(1, 2)).all() and (rec.costs[5:] == 0).any(axis=(1, 2)).all()
    # confirmed tracks lie on the simulated movers present then
    confirmed = 0
    for i in range(n):
        t = rec.tracks_at(i)
        objects = street.objects(float(rec.stamps[i]))
        for x, y in zip(t["x"][t["confirmed"]], t["y"][t["confirmed"]]):
            assert np.hypot(objects.x - x, objects.y - y).min() < 1.5
            confirmed += 1
    assert confirmed >= 10


def _mapped(png: bytes) -> np.ndarray:
    """(row, col) of a screenshot's pixels (left of the panel, right of the axes key) drawn as
    known cells: a grey (free white … occupied black) other than the unknown cells' 205 and the
    page's background; not the coloured path, frame or palette."""
    rgb = np.asarray(image(png), np.int64)[:, 80: WIDE["width"] - 360]
    grey = rgb.max(axis=2) - rgb.min(axis=2) <= 12
    unknown = np.abs(rgb.mean(axis=2) - 205) <= 4
    page = np.abs(rgb - BACKGROUND).max(axis=2) <= 4
    return np.argwhere(grey & ~unknown & ~page)


def _white(png: bytes) -> np.ndarray:
    """(row, col) of a screenshot's white pixels (free cells of a costmap), left of the panel."""
    rgb = np.asarray(image(png), np.int64)[:, 80: WIDE["width"] - 360]
    return np.argwhere((rgb >= 248).all(axis=2))


def _at_step(tab, viewer, step: int, steps: int, name: str) -> bytes:
    viewer.step = step
    tab.page.get_by_text(f"step {step + 1} of {steps}").wait_for(timeout=10_000)
    tab.page.wait_for_timeout(1000)
    png = tab.page.screenshot()
    keep(name, png)
    return png


def _open(browser, viewer, steps: int):
    tab = Page(browser, viewer.url)
    tab.page.get_by_text(f"step 1 of {steps}").wait_for(timeout=20_000)
    tab.page.locator(".mantine-Notification-closeButton").click()  # "software WebGL"
    tab.page.set_viewport_size(WIDE)
    return tab


def test_the_map_grows_in_the_browser(browser, mapping):
    from occmap.viz.viewer import Viewer

    _, tmp = mapping
    with Viewer(tmp / "intel.npz", port=0) as viewer:
        assert viewer.scene.kind == "mapping run"
        # the panel shows the run's controls, not those of voxels (colour, boxes, free space, slices)
        assert viewer._step.visible and viewer._speed.visible
        assert not any(c.visible for c in (viewer._colour, viewer._style, viewer._show_free, viewer._slice_mode))
        tab = _open(browser, viewer, 91)
        early = _mapped(_at_step(tab, viewer, 9, 91, "mapping-early"))
        late = _mapped(_at_step(tab, viewer, 90, 91, "mapping-late"))
        # more known cells drawn where the map grew; what was known early stays drawn (but where the
        # path's line and the robot's frame now lie over it)
        assert len(late) > 2 * len(early) > 5000, (len(early), len(late))
        late_set = set(map(tuple, late))
        assert sum(tuple(p) in late_set for p in early) > 0.8 * len(early)
        assert tab.refused == []


def test_the_costmap_moves_in_the_browser(browser, local):
    from occmap.viz.viewer import Viewer

    n = int(round(STREET_SECONDS / 0.1)) + 1
    with Viewer(local / "street.npz", port=0) as viewer:
        assert viewer.scene.kind == "local map run"
        tab = _open(browser, viewer, n)
        first = _white(_at_step(tab, viewer, 5, n, "local-first"))  # free space cleared by then
        last = _white(_at_step(tab, viewer, n - 1, n, "local-last"))
        assert len(first) > 2000 and len(last) > 2000, (len(first), len(last))
        # the window drove along the street (+x: to the right on the screen, the camera facing +y)
        shift = last.mean(axis=0) - first.mean(axis=0)
        assert shift[1] > 30, shift
        assert tab.refused == []


@pytest.mark.parametrize("kind", ["mapping", "local"])
def test_broken_recordings_are_refused_naming_file_and_entry(kind, request, tmp_path, capsys):
    from occmap.viz._maps import open_scene

    source = (request.getfixturevalue("mapping")[1] / "intel.npz" if kind == "mapping"
              else request.getfixturevalue("local") / "street.npz")
    with np.load(source) as z:
        entries = {k: z[k] for k in z.files}
    opened = open_scene(source)
    assert opened.kind == {"mapping": "mapping run", "local": "local map run"}[kind]

    def broken(name, **change):
        path = tmp_path / f"{name}.npz"
        np.savez(path, **{k: v for k, v in {**entries, **change}.items() if v is not None})
        return path

    with pytest.raises(FormatError, match=r"missing\.npz: entry 'poses' missing"):
        open_scene(broken("missing", poses=None))
    with pytest.raises(FormatError, match=r"shape\.npz: entry 'poses' has shape \(\d+, 2\), expected 2 axes ending in "
                                          r"\(3,\)"):
        open_scene(broken("shape", poses=entries["poses"][:, :2]))
    with pytest.raises(FormatError, match=r"steps\.npz: entry 'poses' has \d+ steps, 'stamps' \d+"):
        open_scene(broken("steps", poses=entries["poses"][:-1]))
    with pytest.raises(FormatError, match=r"foreign\.npz: not an occmap recording \(format entry "
                                          r"array\('occmap octree recording'"):
        open_scene(broken("foreign", format=np.array("occmap octree recording")))
    capsys.readouterr()
    assert main(["view", str(tmp_path / "foreign.npz"), "--port", "0", "--no-browser"]) == 2  # one line, no server
    assert "foreign.npz: not an occmap recording" in capsys.readouterr().err
    with pytest.raises(FormatError, match=r"version\.npz: recording version array\(2\)"):
        open_scene(broken("version", version=np.array(2)))
    with pytest.raises(FormatError, match=r"offsets\.npz: entry '(delta|track)_offsets' must rise from 0"):
        name = "delta_offsets" if kind == "mapping" else "track_offsets"
        open_scene(broken("offsets", **{name: entries[name][::-1]}))
    if kind == "mapping":
        cells = entries["delta_cells"].copy()
        cells[-1] = int(np.prod(entries["shape"]))
        with pytest.raises(FormatError, match=r"cells\.npz: entry 'delta_cells' holds cells outside the 807 × 676"):
            open_scene(broken("cells", delta_cells=cells))
    else:
        with pytest.raises(FormatError, match=r"costs\.npz: entry 'costs' holds float64, expected uint8"):
            open_scene(broken("costs", costs=entries["costs"].astype(np.float64)))


def test_a_wide_map_is_drawn_in_blocks_keeping_its_obstacles():
    from occmap.viz.viewer import _pooled

    occ = np.full((2500, 3001), -1, np.int8)
    occ[:1000, :1500] = 0  # free space, a wall across it, one occupied cell alone
    occ[500, :1500] = 100
    occ[2499, 3000] = 100
    blocks, k = _pooled(occ, 1024)
    assert k == 3 and blocks.shape == (834, 1001)
    padded = np.full((834 * 3, 1001 * 3), -1, np.int8)
    padded[:2500, :3001] = occ
    np.testing.assert_array_equal(blocks, padded.reshape(834, 3, 1001, 3).max(axis=(1, 3)))
    assert (blocks[166, :500] == 100).all() and blocks[833, 1000] == 100 and (blocks[:166, :500] == 0).all()
    small = occ[:1000, :1000]
    assert _pooled(small, 1024)[0] is small


def test_record_options_are_checked(data_dir, tmp_path, capsys):
    log = str(data_dir / "carmen" / "intel-corrected.log.gz")
    assert main(["map2d", log, "--tiles", str(tmp_path / "t"), "--record", str(tmp_path / "r.npz")]) == 2
    assert "--record keeps the map in memory as it grows: leave out --tiles" in capsys.readouterr().err
    assert main(["map2d", log, "-o", str(tmp_path / "m.yaml"), "--record-every", "5"]) == 2
    assert "--record-every sets how --record records" in capsys.readouterr().err
    assert main(["map2d", log, "-o", str(tmp_path / "m.yaml"), "--record", log]) == 2  # never over an input
    assert not (tmp_path / "m.yaml").exists() and not (tmp_path / "t").exists()
