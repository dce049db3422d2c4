"""Replays to scrub: a localization run in the simulated office recorded step by step
(:mod:`occmap.localize.recording`), written and read back, then opened in the viewer in headless
Chromium; moving the time slider (as the panel does) moves the particles and the estimate drawn.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from occmap.errors import FormatError, InvalidArgumentError

from headless import Page, image, keep

STEPS = 40
KEEP = 150
GAP = slice(10, 20)
WIDE = {"width": 1200, "height": 700}  # the map left of the panel


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """40 scans along the office's trajectory, the odometry drifting, tracked by 600 particles from
    a spread-out start; the true poses recorded as the reference, but for a gap (steps 10 … 19)."""
    from occmap.geometry.motion import apply_odometry, odometry_delta
    from occmap.grid2d import OccupancyGrid2D
    from occmap.localize.recording import LocalizationRecording
    from occmap.localize.replay import make_localizer, replay
    from occmap.scan import LaserScan
    from occmap.sim import World2D, simulate_scans

    world = World2D.default()
    truth = world.default_trajectory(n=300)[:STEPS * 2:2]
    scans = simulate_scans(world, truth, n_beams=180, max_range=10.0, sigma=0.01, rng=2)
    grid = OccupancyGrid2D(0.05, size=(20.4, 15.4), origin=(-0.2, -0.2))
    grid.insert_scans(truth, np.array([s.ranges for s in scans]), scans[0].angles, max_range=10.0)
    rng = np.random.default_rng(3)
    odo = [np.array([1.0, -2.0, 0.5])]
    for a, b in zip(truth[:-1], truth[1:]):
        d = np.array(odometry_delta(a, b, min_trans=0.0)) * (1 + 0.03 * rng.standard_normal(3))
        odo.append(apply_odometry(odo[-1], tuple(d)))
    log = [LaserScan(pose=truth[i], ranges=s.ranges, angles=s.angles, max_range=10.0, stamp=0.1 * i, odom=odo[i])
           for i, s in enumerate(scans)]
    loc = make_localizer(grid, particles=600, seed=4)
    result = replay(loc, log, init=truth[0] + [0.3, -0.2, 0.1], cov=np.diag([0.3 ** 2, 0.3 ** 2, 0.15 ** 2]),
                    keep_particles=KEEP)
    reference = truth.copy()
    reference[GAP] = np.nan
    rec = LocalizationRecording.of_replay(result, grid, reference)
    path = rec.save(tmp_path_factory.mktemp("run") / "office-run.npz")
    return rec, path, truth, loc


def test_a_recording_keeps_the_run_and_reads_back(run):
    from occmap.localize.recording import LocalizationRecording

    rec, path, truth, loc = run
    assert len(rec) == STEPS and rec.particles.shape == (STEPS, KEEP, 3) and rec.particles.dtype == np.float32
    # the last step holds the filter's own cloud, subsampled evenly
    assert np.array_equal(rec.particles[-1], loc.particles[np.linspace(0, 599, KEEP).round().astype(int)]
                          .astype(np.float32))
    # each step's cloud and estimate are that step's: around the true pose as the robot travels 11 m
    centre = np.median(rec.particles[:, :, :2], axis=1)
    assert np.hypot(*(centre - truth[:, :2]).T).max() < 0.15
    assert np.hypot(*(rec.estimates[:, :2] - truth[:, :2]).T).max() < 0.05
    assert np.hypot(*(truth[-1, :2] - truth[0, :2])) > 10
    back = LocalizationRecording.load(path)
    for name in ("stamps", "estimates", "particles", "reference", "occupancy", "origin"):
        np.testing.assert_array_equal(getattr(back, name), getattr(rec, name), err_msg=name)
    assert back.resolution == rec.resolution == 0.05
    assert np.isnan(back.reference[GAP]).all() and np.isfinite(back.reference).sum() == 3 * (STEPS - 10)


def test_bad_recordings_are_refused_naming_file_and_entry(run, tmp_path):
    from occmap.localize.recording import LocalizationRecording

    rec, path, _, _ = run
    not_zip = tmp_path / "junk.npz"
    not_zip.write_bytes(b"hello")
    with pytest.raises(FormatError, match=r"junk\.npz: not a NumPy \.npz"):
        LocalizationRecording.load(not_zip)
    cut = tmp_path / "cut.npz"
    cut.write_bytes(path.read_bytes()[:300])
    with pytest.raises(FormatError, match=r"cut\.npz: not a NumPy \.npz"):
        LocalizationRecording.load(cut)
    other = tmp_path / "other.npz"
    np.savez(other, a=np.zeros(3))
    with pytest.raises(FormatError, match=r"other\.npz: not an occmap localization recording"):
        LocalizationRecording.load(other)
    short = tmp_path / "short.npz"
    LocalizationRecording(rec.stamps, rec.estimates[:-1], rec.particles, rec.reference, rec.occupancy,
                          rec.resolution, rec.origin).save(short)
    with pytest.raises(FormatError, match=r"short\.npz: entry 'estimates' has 39 steps, 'stamps' 40"):
        LocalizationRecording.load(short)


def _colour_pixels(png: bytes, colour, tol: int = 40) -> np.ndarray:
    """(row, col) of a screenshot's pixels within ``tol`` of ``colour`` in every channel, left of
    the panel and right of the axes key."""
    rgb = np.asarray(image(png), np.int64)[:, 80: WIDE["width"] - 360]  # not the axes key, not the panel
    return np.argwhere(np.all(np.abs(rgb - colour) <= tol, axis=2))


def test_the_run_scrubbed_in_the_browser(browser, run):
    from occmap.viz.viewer import ESTIMATE_COLOR, PARTICLE_COLOR, REFERENCE_COLOR, Viewer

    rec, path, _, _ = run
    with Viewer(path, port=0) as viewer:
        assert viewer.scene.kind == "localization run" and viewer.step == 0
        tab = Page(browser, viewer.url)
        tab.page.get_by_text(f"step 1 of {STEPS}").wait_for(timeout=20_000)
        tab.page.locator(".mantine-Notification-closeButton").click()  # "software WebGL": orange too
        tab.page.set_viewport_size(WIDE)
        tab.page.wait_for_timeout(1500)
        first = tab.page.screenshot()
        keep("replay-first", first)
        orange0 = _colour_pixels(first, PARTICLE_COLOR)
        assert len(orange0) > 200, f"particles not drawn: {len(orange0)} orange pixels"

        viewer.step = STEPS - 1  # as the slider does
        tab.page.get_by_text(f"step {STEPS} of {STEPS}").wait_for(timeout=10_000)
        tab.page.wait_for_timeout(1500)
        last = tab.page.screenshot()
        keep("replay-last", last)
        orange1 = _colour_pixels(last, PARTICLE_COLOR)
        blue1 = _colour_pixels(last, ESTIMATE_COLOR)
        assert len(orange1) > 20, f"particles not drawn at the last step: {len(orange1)} orange pixels"
        # the cloud has moved with the robot; the estimate's track and the reference poses are drawn
        moved = np.hypot(*(orange1.mean(axis=0) - orange0.mean(axis=0)))
        assert moved > 20, f"the particles moved {moved:.1f} pixels between the first and last step"
        assert len(blue1) > 50, f"the estimate's track is not drawn: {len(blue1)} blue pixels"
        green1 = _colour_pixels(last, REFERENCE_COLOR)
        assert len(green1) > 50, f"the reference poses are not drawn: {len(green1)} green pixels"
        assert len(_colour_pixels(first, ESTIMATE_COLOR)) < len(blue1) / 4  # at step 0 no track yet
        assert tab.refused == []

        with pytest.raises(InvalidArgumentError, match=f"step must be 0 .. {STEPS - 1}"):
            viewer.step = STEPS
        viewer.step = 0
        viewer._play.value = True  # the panel's "Play" at 1×: the run's pace, 10 scans a second, to the end
        tab.page.wait_for_timeout(1000)
        assert 3 <= viewer.step < STEPS
        deadline = tab.page.wait_for_timeout
        for _ in range(math.ceil(STEPS / 10) * 2 + 4):
            if not viewer._play.value:
                break
            deadline(500)
        assert viewer.step == STEPS - 1 and viewer._play.value is False
