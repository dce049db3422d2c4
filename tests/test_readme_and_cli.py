"""The README's code runs as written, and the command-line entry points work."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
from PIL import Image

from occmap.cli import main

ROOT = Path(__file__).resolve().parent.parent


def test_readme_code_runs(tmp_path, monkeypatch):
    """Every python block of the README, run as written in a scratch folder; blocks that read the
    shared robot data get its real location, and are skipped when it is absent."""
    from occmap._data import find_shared_data

    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert len(blocks) >= 2, "README lost its code examples"
    data = find_shared_data(ROOT)
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    for block in blocks:
        if "../shared/data" in block:
            if data is None:
                continue
            block = block.replace("../shared/data", str(data))
        exec(compile(block, "README.md", "exec"), namespace)
    T = namespace["T"]
    # halfway between the stamps 0 and 1 at t = 0.25: base_link moved 0.25 m along its own x
    expected = namespace["T_map_base"] @ namespace["SE3"].from_rt(np.eye(3), [0.25, 0, 0]) @ namespace["T_base_laser"]
    assert np.allclose(T.matrix, expected.matrix, atol=1e-12)
    assert namespace["town"].stats["scans"] == 20 and (tmp_path / "town-tiles" / "index.json").is_file()
    if data is not None:
        assert (tmp_path / "intel.yaml").is_file() and (namespace["occupancy"] >= 65).any()  # clamped at 97


def test_readme_names_the_two_commands():
    text = (ROOT / "README.md").read_text()
    assert "make demo" in text and "make test" in text


def test_help_and_version(capsys):
    assert main([]) == 0
    assert "demo" in capsys.readouterr().out
    out = subprocess.run([sys.executable, "-m", "occmap", "--version"], capture_output=True, text=True, check=True)
    assert out.stdout.startswith("occmap ")


def test_demo_writes_a_picture(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "picture:" in printed
    with Image.open(tmp_path / "motion.png") as im:
        assert im.size[0] > 300 and im.size[1] > 200
        colours = im.convert("RGB").getcolors(maxcolors=1 << 20)
    assert len(colours) > 10  # paths, particles and text were drawn, not a blank canvas
    with Image.open(tmp_path / "street.gif") as im:
        assert im.n_frames > 50
        im.seek(im.n_frames // 2)
        frame = np.asarray(im.convert("RGB"))
        assert (frame == (0, 170, 60)).all(axis=-1).any()  # a confirmed track drawn mid-way through the street
    assert "0 track-scans on nothing moving" in printed


def test_map2d_on_the_intel_log_writes_a_map_that_loads_back(tmp_path, capsys, data_dir):
    from occmap import OccupancyGrid2D

    out = tmp_path / "intel.yaml"
    code = main(["map2d", str(data_dir / "carmen" / "intel-corrected.log.gz"), "-o", str(out),
                 "--png", str(tmp_path / "intel.png"), "--max-range", "30", "--every", "3"])
    assert code == 0
    printed = capsys.readouterr().out
    assert "scans 304," in printed and "integrated in" in printed
    grid = OccupancyGrid2D.load(out)
    ml = grid.maximum_likelihood()
    assert (ml == 1).sum() > 5_000 and (ml == 0).sum() > 100_000  # walls and free space of a building
    assert (tmp_path / "intel.png").stat().st_size > 10_000


def test_map2d_reports_a_malformed_log_with_its_line(tmp_path, capsys):
    log = tmp_path / "bad.log"
    log.write_text("FLASER 3 1.0 1.0 1.0 0 0 0 0 0 0 1.0 host 1.0\nFLASER 3 1.0 oops 1.0 0 0 0 0 0 0 2.0 host 2.0\n")
    assert main(["map2d", str(log), "-o", str(tmp_path / "m.yaml")]) == 2
    err = capsys.readouterr().err
    assert "bad.log" in err and "line 2" in err


def test_map2d_reports_an_empty_log_and_a_missing_file(tmp_path, capsys):
    empty = tmp_path / "empty.log"
    empty.write_text("# a comment and nothing else\n")
    assert main(["map2d", str(empty), "-o", str(tmp_path / "m.yaml")]) == 2
    assert "no laser scans" in capsys.readouterr().err
    assert main(["map2d", str(tmp_path / "missing.log"), "-o", str(tmp_path / "m.yaml")]) == 2
    assert "missing.log" in capsys.readouterr().err
    assert not (tmp_path / "m.yaml").exists()
