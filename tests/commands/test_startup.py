"""`import occmap` loads no Numba, a command loads only the parts it uses, and printed timings
leave out compiling and loading kernels."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time

import numpy as np


def _python(code: str, *args) -> str:
    run = subprocess.run([sys.executable, "-c", code, *map(str, args)], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    return run.stdout


def test_import_occmap_loads_neither_numpy_nor_numba():
    loaded = json.loads(_python("import json, sys, occmap; print(json.dumps(sorted(sys.modules)))"))
    assert "numba" not in loaded and "numpy" not in loaded


def test_every_public_name_loads_on_first_use():
    import occmap

    names = json.loads(_python("import json, occmap; print(json.dumps([occmap.__all__, dir(occmap)]))"))
    assert set(names[0]) <= set(names[1])
    assert {"OccupancyGrid2D", "OcTree", "LocalMap", "MonteCarloLocalizer", "geometry", "io"} <= set(names[0])
    for name in occmap.__all__:
        assert getattr(occmap, name) is not None
    from occmap import OcTree
    from occmap.octree import OcTree as same

    assert OcTree is same
    try:
        occmap.no_such_name  # noqa: B018
    except AttributeError as e:
        assert "no_such_name" in str(e)
    else:
        raise AssertionError("an unknown name must raise AttributeError")


def test_help_loads_no_kernels():
    loaded = json.loads(_python("import json, sys\nfrom occmap.cli import build_parser\nbuild_parser()\n"
                                "print(json.dumps(sorted(sys.modules)))"))
    assert "numba" not in loaded


def test_info_loads_only_the_octree(tmp_path):
    from occmap.io.octomap import write_bt
    from occmap.octree import OcTree

    tree = OcTree(0.5)
    tree.insert_point_cloud(np.array([[2.0, 0.0, 0.0], [0.0, 3.0, 1.0]]), np.zeros(3))
    write_bt(tree, tmp_path / "t.bt")
    code = ("import json, sys\nfrom occmap.cli import main\nassert main(['info', sys.argv[1]]) == 0\n"
            "print(json.dumps(sorted(sys.modules)))")
    loaded = set(json.loads(_python(code, tmp_path / "t.bt").splitlines()[-1]))
    assert "occmap.octree" in loaded
    for other in ("occmap.grid2d", "occmap.local", "occmap.localize", "occmap.sim", "occmap.io.carmen"):
        assert other not in loaded


def test_work_clock_leaves_out_compiling():
    from numba import njit

    from occmap._clock import WorkClock

    @njit  # a new function: its first call compiles
    def twice(x):
        return 2.0 * x

    clock = WorkClock()
    t0 = time.perf_counter()
    with clock.running():
        twice(1.0)
        time.sleep(0.05)
    elapsed = time.perf_counter() - t0
    assert 0.05 <= clock.seconds < elapsed - 0.02  # the sleep counted, the compilation not


def test_map3d_reports_the_insertion_alone(tmp_path):
    """map3d printed "inserted in 3.10 s (1 points/s)" for a 2-point file: compiling counted."""
    (tmp_path / "two.xyz").write_text("1 0 0\n0 2 0\n")
    run = subprocess.run([sys.executable, "-m", "occmap", "map3d", str(tmp_path / "two.xyz"), "-o",
                          str(tmp_path / "two.bt")], capture_output=True, text=True, check=True)
    seconds = float(re.search(r"inserted in (\S+) s", run.stdout).group(1))
    total = float(re.search(r"total (\S+) s", run.stdout).group(1))
    assert seconds < 0.1 and seconds < 0.2 * total, run.stdout  # (compiling took seconds; loading cached kernels ~0.05 s)
