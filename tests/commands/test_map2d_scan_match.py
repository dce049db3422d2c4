"""``occmap map2d LOG --scan-match``: a log whose laser poses are all zero (the robot never
knew where it was) maps onto the simulated world's walls."""

from __future__ import annotations

import numpy as np
import pytest

from occmap.cli import main
from occmap.geometry.se2 import SE2
from occmap.grid2d import OccupancyGrid2D
from occmap.sim.world2d import World2D, simulate_scans


def _flaser(scan, pose, odom) -> str:
    """A FLASER line: 181 ranges over 180° (CARMEN's angles for 181 beams)."""
    ranges = " ".join(f"{r:.4f}" for r in scan.ranges)
    p, o = (" ".join(f"{v:.6f}" for v in x) for x in (pose, odom))
    return f"FLASER {len(scan)} {ranges} {p} {o} {scan.stamp:.3f} sim {scan.stamp:.3f}\n"


@pytest.fixture(scope="module")
def run():
    world = World2D.default()
    truth = world.default_trajectory(1000)[:150]
    scans = simulate_scans(world, truth, n_beams=181, fov=np.pi, max_range=10.0, sigma=0.01, rng=4)
    return world, truth, scans


def _on_walls(yaml_path, world, first_pose) -> float:
    """The share of the map's occupied cells whose centre (placed in the world by the pose of the
    first scan, which defines the map's frame) lies within 8 cm of a wall of the simulated world."""
    grid = OccupancyGrid2D.load(yaml_path)
    cells = np.argwhere(grid.maximum_likelihood() == 1)
    world_xy = SE2(first_pose).apply(grid.cell_to_world(cells))
    return float(np.mean(world.clearance(world_xy) < 0.08))


def test_scan_match_replaces_the_missing_poses(tmp_path, run, capsys):
    world, truth, scans = run
    log = tmp_path / "zero_poses.log"
    log.write_text("".join(_flaser(s, np.zeros(3), t) for s, t in zip(scans, truth)))
    out = tmp_path / "matched.yaml"
    assert main(["map2d", str(log), "--max-range", "10", "--scan-match", "-o", str(out)]) == 0
    assert "scan matching: 150 scans, 149 matched, 0 failed and 0 rejected" in capsys.readouterr().out
    assert _on_walls(out, world, truth[0]) > 0.97
    as_logged = tmp_path / "as_logged.yaml"
    assert main(["map2d", str(log), "--max-range", "10", "-o", str(as_logged)]) == 0
    assert _on_walls(as_logged, world, truth[0]) < 0.75


def test_scan_match_and_tiles_are_refused(tmp_path, run, capsys):
    _, truth, scans = run
    log = tmp_path / "one.log"
    log.write_text(_flaser(scans[0], truth[0], truth[0]))
    assert main(["map2d", str(log), "--scan-match", "--tiles", str(tmp_path / "t")]) == 2
    assert "--scan-match" in capsys.readouterr().err


def test_local_with_scan_match_sees_a_still_world_still(tmp_path, run, capsys):
    """``occmap local LOG --tracking --scan-match``: the same log, poses matched scan by scan; the
    walls do not move, so nothing is taken for a moving object — without matching the walls swim
    with the robot's motion and turn into tracks. ``--register`` (the local map inserts each scan
    where it fits) keeps them still too, though every pose of the log is zero."""
    import re

    _, truth, scans = run
    log = tmp_path / "zero_poses.log"
    log.write_text("".join(_flaser(s, np.zeros(3), t) for s, t in zip(scans, truth)))
    found = {}
    for flag in ("--scan-match", "--register", None):
        argv = ["local", str(log), "--tracking", "--max-range", "10", "-o", str(tmp_path / "l.gif"), "--max-frames", "80"]
        assert main(argv + ([flag] if flag else [])) == 0
        out = capsys.readouterr().out
        m = re.search(r"tracking: (\d+) tracks confirmed of \d+ started, ([\d,]+) returns taken as moving", out)
        found[flag] = int(m.group(1)), int(m.group(2).replace(",", ""))
        assert ("scan matching: 150 scans" in out) == (flag == "--scan-match")
    for flag in ("--scan-match", "--register"):
        assert found[flag][0] == 0 and found[flag][1] * 10 < found[None][1]
