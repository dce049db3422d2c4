"""After `occmap warmup`, a new process running the commands compiles no kernel: every kernel
with every argument type the commands pass is in the on-disk cache."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np

# Counts Numba's "numba:compile" events (a kernel compiled, not loaded from the cache) while
# the commands given as JSON run (twice, each time writing into a new folder), then compiles one
# new function to show that the count works.
HARNESS = """
import json, os, sys
from numba import njit
from numba.core.event import Listener, install_listener

class Compiles(Listener):
    names = []
    def on_start(self, event):
        fn = event.data["dispatcher"].py_func
        self.names.append(f"{fn.__module__}.{fn.__qualname__}{event.data['args']}")
    def on_end(self, event):
        pass

import occmap._threads
from occmap.cli import main
compiles = Compiles()
with install_listener("numba:compile", compiles):
    # as on an idle machine, then as on a busy one (every thread choice on one thread): the kernels
    # of both paths, whatever the load while the test runs
    for free, out in ((2.0, "idle"), (0.0, "busy")):
        occmap._threads.free_cores = lambda free=free: free
        os.mkdir(out)
        os.chdir(out)
        for argv in json.loads(sys.argv[1]):
            assert main(argv) == 0, argv
        os.chdir("..")
    njit(lambda x: x + 1)(1)
print(json.dumps(compiles.names))
"""


def _log(path, world, poses, scans):
    lines = []
    for k, (p, s) in enumerate(zip(poses, scans)):
        r = " ".join(f"{v:.3f}" for v in np.minimum(s.ranges, 10.0))
        lines.append(f"FLASER {len(s.ranges)} {r} {p[0]} {p[1]} {p[2]} {p[0]} {p[1]} {p[2]} {k}.0 test {k}.0\n")
    path.write_text("".join(lines))


def test_commands_after_warmup_compile_nothing(tmp_path):
    from occmap.io.pointclouds import write_pcd
    from occmap.sim import World2D, simulate_scans
    from occmap.sim.world3d import VELODYNE_HDL32, simulate_drive

    subprocess.run([sys.executable, "-m", "occmap", "warmup"], check=True, capture_output=True)

    world = World2D.default()
    poses = world.default_trajectory(n=30)
    _log(tmp_path / "office.log", world, poses, simulate_scans(world, poses, n_beams=180, rng=0))
    cloud = simulate_drive(2, VELODYNE_HDL32.with_azimuth_step(np.radians(0.32)), rng=1)[0]  # 36,000 rays
    write_pcd(tmp_path / "scan.pcd", cloud.points, viewpoint=cloud.pose)
    x, y, t = poses[0]
    t_ = str(tmp_path)
    commands = [
        ["map2d", f"{t_}/office.log", "-o", "office.yaml", "--png", "office.png", "--resolution", "0.1"],
        ["map2d", f"{t_}/office.log", "--scan-match", "-o", "matched.yaml"],
        ["local", f"{t_}/office.log", "-o", "local.gif", "--max-frames", "3"],
        ["localize", "office.yaml", f"{t_}/office.log", "-o", "track.csv", "--init", f"{x},{y},{t}",
         "--particles", "300", "--png", "track.png"],
        ["map3d", f"{t_}/scan.pcd", "-o", "scan.bt", "--resolution", "0.2", "--png", "top.png"],
        ["map3d", f"{t_}/scan.pcd", "-o", "scan.ot", "--discretize", "--max-range", "20"],
        ["info", "scan.bt"],
        ["convert", "scan.ot", "scan.ply"],
        ["render", "scan.bt", "-o", "slice.png", "--slice", "1.0"],
        ["map3d", f"{t_}/scan.pcd", "--tiles", "store", "--resolution", "0.2", "-o", "store.bt"],
        ["info", "store"],
        ["export", "store", "-o", "box.ot", "--box", "-5", "-5", "-1", "5", "5", "3"],
        ["map2d", f"{t_}/office.log", "--tiles", "grid", "--tile-size", "64", "-o", "tiled.yaml"],
        ["info", "grid"],
        ["export", "grid", "-o", "corner.yaml", "--box", "0", "0", "5", "5"],
    ]
    run = subprocess.run([sys.executable, "-c", HARNESS, json.dumps(commands)], capture_output=True, text=True,
                         cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    compiled = json.loads(run.stdout.splitlines()[-1])
    assert len(compiled) == 1 and "<lambda>" in compiled[0], compiled  # only the harness's own function
