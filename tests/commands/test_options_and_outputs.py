"""The CLI checks its options and output names before it reads anything, refuses to overwrite an
input or half of a map_server pair, and reports bad input as one line with exit code 2."""

from __future__ import annotations

import subprocess
import sys

import pytest

from occmap.cli import main


@pytest.fixture
def log(tmp_path):
    path = tmp_path / "run.log"
    path.write_text("FLASER 3 1.0 1.0 1.0 0 0 0 0 0 0 1.0 host 1.0\n")
    return path


def _refused(argv, capsys, *words):
    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err
    assert all(w in err for w in words), err
    return err


def test_map2d_refuses_a_pgm_as_its_yaml(tmp_path, log, capsys):
    """Issue 15: `map2d LOG -o x.pgm` wrote the YAML text into x.pgm and exited 0."""
    out = tmp_path / "x.pgm"
    _refused(["map2d", log, "-o", out], capsys, "x.pgm", ".yaml")
    assert not out.exists()


def test_map2d_refuses_to_overwrite_the_other_half_or_the_log(tmp_path, log, capsys):
    _refused(["map2d", log, "-o", tmp_path / "m.yaml", "--png", tmp_path / "m.pgm"], capsys, "m.pgm", "one file")
    assert not (tmp_path / "m.pgm").exists() and not (tmp_path / "m.yaml").exists()
    _refused(["map2d", log, "-o", tmp_path / "m.yaml", "--png", tmp_path / "m.yaml"], capsys, "one file")
    image_log = tmp_path / "scans.pgm"
    image_log.write_text(log.read_text())
    _refused(["map2d", image_log, "-o", tmp_path / "scans.yaml"], capsys, "would overwrite LOG")
    assert image_log.read_text() == log.read_text()
    yaml_log = tmp_path / "scans.yml"
    yaml_log.write_text(log.read_text())
    _refused(["map2d", yaml_log, "-o", yaml_log], capsys, "would overwrite LOG")


def test_options_are_checked_before_the_data_is_read(tmp_path, capsys):
    """A missing log is not what the user hears about when an option is wrong."""
    missing = tmp_path / "missing.log"
    for option in (["--resolution", "0"], ["--resolution", "nan"], ["--every", "0"], ["--max-range", "-3"],
                   ["--prob-hit", "1.5"], ["--every", "two"]):
        with pytest.raises(SystemExit) as stop:
            main(["map2d", str(missing), "-o", str(tmp_path / "m.yaml"), *option])
        assert stop.value.code == 2
        err = capsys.readouterr().err
        assert option[0] in err and "missing.log" not in err
    # a pair of probabilities the lidar model rejects, still before the log is opened
    _refused(["map2d", missing, "-o", tmp_path / "m.yaml", "--prob-hit", "0.3"], capsys, "prob_hit")
    assert "missing.log" not in capsys.readouterr().err


def test_octree_commands_refuse_bad_outputs_before_reading(tmp_path, capsys):
    missing = tmp_path / "missing.pcd"
    _refused(["map3d", missing, "-o", tmp_path / "a.xyz"], capsys, ".bt")
    _refused(["map3d", missing, "-o", tmp_path / "a.bt", "--png", tmp_path / "a.bt"], capsys, "one file")
    cloud = tmp_path / "cloud.ply"  # a point cloud in, occupied voxels out: one name for both
    _refused(["map3d", cloud, "-o", cloud], capsys, "would overwrite input")
    tree = tmp_path / "t.bt"
    _refused(["convert", tree, tree], capsys, "would overwrite INPUT")
    _refused(["convert", tree, tmp_path / "t.pcd"], capsys, ".ply")
    _refused(["render", tree, "-o", tree], capsys, "would overwrite FILE")
    for argv in (["render", tree, "-o", tmp_path / "p.png", "--pixel", "0"],
                 ["map3d", missing, "-o", tmp_path / "a.bt", "--resolution", "-0.1"]):
        with pytest.raises(SystemExit) as stop:
            main([str(a) for a in argv])
        assert stop.value.code == 2


def test_replay_commands_refuse_to_overwrite_their_inputs(tmp_path, log, capsys):
    _refused(["local", log, "-o", log], capsys, "would overwrite LOG")
    assert log.read_text().startswith("FLASER")
    yaml = tmp_path / "map.yaml"
    _refused(["localize", yaml, log, "-o", tmp_path / "t.csv", "--png", yaml], capsys, "would overwrite MAP.yaml")
    _refused(["localize", yaml, log, "-o", log], capsys, "would overwrite LOG")
    with pytest.raises(SystemExit):
        main(["local", str(log), "-o", str(tmp_path / "a.gif"), "--fps", "0"])


def test_bad_input_is_one_line_without_a_traceback(tmp_path):
    bad = tmp_path / "bad.xyz"
    bad.write_text("1 2 3\n4 five 6\n")
    for argv in (["map2d", str(tmp_path / "missing.log"), "-o", str(tmp_path / "m.yaml")],
                 ["map3d", str(bad), "-o", str(tmp_path / "b.bt")],
                 ["map2d", str(bad), "-o", str(tmp_path / "m.pgm")]):
        run = subprocess.run([sys.executable, "-m", "occmap", *argv], capture_output=True, text=True)
        assert run.returncode == 2
        assert "Traceback" not in run.stderr and run.stderr.startswith(f"occmap {argv[0]}: error: ")
        assert len(run.stderr.strip().splitlines()) == 1


def test_map2d_and_local_say_what_they_assumed_of_the_log(tmp_path, log, capsys):
    """The log has no PARAM for its laser's maximum range and 3 beams (no known angular step)."""
    for argv in (["map2d", log, "-o", tmp_path / "m.yaml"], ["local", log, "-o", tmp_path / "l.gif"]):
        assert main([str(a) for a in argv]) == 0
        err = capsys.readouterr().err
        assert "note: 1 FLASER/RLASER scans have no maximum range in the log" in err and "81 m assumed" in err
        assert "note: 1 FLASER/RLASER scans have a beam count" in err
    assert main(["map2d", str(log), "-o", str(tmp_path / "n.yaml"), "--max-range", "20"]) == 0
    assert "maximum range" not in capsys.readouterr().err
