"""Every reader error a user can cause is an OccmapError naming the file (issue 15): the inputs
that once escaped as OverflowError, ValueError, DecompressionBombError, and a ROBOTLASER1 max
range that turned every reading into free space."""

from __future__ import annotations

import pytest

from occmap.errors import FormatError, MissingFileError, OccmapError
from occmap.io import read_pcd, read_ply
from occmap.io.carmen import read_carmen
from occmap.io.mapserver import load_map
from occmap.io.sonar import read_sonar_ring

TAIL = "1 2 0.5 0.1 0.2 0.3 100.5 host 7.25"


def _robotlaser(max_range: str) -> str:
    return (f"ROBOTLASER1 0 -0.6 1.2 0.3 {max_range} 0.01 0 3 1.0 2.0 3.0 0 "
            "3.0 4.0 0.5 2.9 3.9 0.1 0.5 0.1 0.3 0.2 0.0 55.5 host 66.5")


@pytest.mark.parametrize("count", ["inf", "-inf", "nan", "1e400", "2.5", "-1"])
def test_flaser_beam_count_that_is_not_a_count(tmp_path, count):
    path = tmp_path / "c.log"
    path.write_text(f"FLASER {count} {TAIL}\n")
    with pytest.raises(FormatError, match=r"c\.log, line 1: FLASER: beam count"):
        read_carmen(path)
    assert read_carmen(path, lenient=True).skipped_malformed == 1


@pytest.mark.parametrize("max_range", ["-1", "0", "-0.0", "nan", "inf"])
def test_robotlaser_max_range_must_be_positive_and_finite(tmp_path, max_range):
    path = tmp_path / "r.log"
    path.write_text(_robotlaser(max_range) + "\n")
    with pytest.raises(FormatError, match=r"r\.log, line 1: ROBOTLASER1: max_range .* positive finite"):
        read_carmen(path)
    assert len(read_carmen(path, lenient=True)) == 0
    # the caller's max range replaces the line's, so the line is usable
    assert read_carmen(path, max_range=20.0).scans[0].max_range == 20.0


def test_robotlaser_good_max_range_still_read(tmp_path):
    path = tmp_path / "r.log"
    path.write_text(_robotlaser("30.0") + "\n")
    assert read_carmen(path).scans[0].max_range == 30.0


def _ply(count: bytes) -> bytes:
    return (b"ply\nformat ascii 1.0\nelement vertex " + count
            + b"\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n")


@pytest.mark.parametrize("count", [b"\xb2", "²".encode(), "٣".encode(), b"9" * 5000, b"+1", b"1_0"])
def test_ply_element_count_that_is_not_a_plain_number(tmp_path, count):
    path = tmp_path / "p.ply"
    path.write_bytes(_ply(count))
    with pytest.raises(FormatError, match=r"p\.ply, line 3: element vertex count must be a whole number"):
        read_ply(path)


@pytest.mark.parametrize("width", ["9" * 5000, "\u0663", "+1", "-1"])
def test_pcd_header_integer_that_is_not_a_plain_number(tmp_path, width):
    path = tmp_path / "w.pcd"
    path.write_text(f"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH {width}\nHEIGHT 1\nDATA ascii\n1 2 3\n")
    with pytest.raises(FormatError, match=r"w\.pcd, line 5: WIDTH value"):
        read_pcd(path)


def test_non_utf8_sonar_file(tmp_path):
    (tmp_path / "measurement.txt").write_bytes(b"1 2 3 4 5 6 7 8 9\n\xff\xfe 1 2 3 4 5 6 7 8\n")
    (tmp_path / "poses.txt").write_bytes(b"1 0 0 0\n2 0 0 0\n")
    with pytest.raises(FormatError, match=r"measurement\.txt, line 2: field 1"):
        read_sonar_ring(tmp_path)


@pytest.mark.filterwarnings("ignore::PIL.Image.DecompressionBombWarning")
def test_pgm_header_of_100000_by_100000(tmp_path):
    (tmp_path / "big.pgm").write_bytes(b"P5\n100000 100000\n255\n" + bytes(1000))
    (tmp_path / "big.yaml").write_text("image: big.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n"
                                       "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    with pytest.raises(FormatError, match=r"big\.pgm: image too large: .*10000000000 pixels"):
        load_map(tmp_path / "big.yaml")
    # below Pillow's own limit, occmap's: 10000 × 10000 pixels from a 1 kB file
    (tmp_path / "big.pgm").write_bytes(b"P5\n10000 10000\n255\n" + bytes(1000))
    with pytest.raises(FormatError, match=r"^\S*big\.pgm: a 10000 × 10000 image needs 100000000 pixels, more than"):
        load_map(tmp_path / "big.yaml")


def test_missing_file_is_both_an_occmap_error_and_file_not_found(tmp_path):
    for read in (read_ply, read_carmen, load_map):
        with pytest.raises(MissingFileError) as info:
            if read is read_carmen:
                next(iter(read_carmen(tmp_path / "nope")))
            else:
                read(tmp_path / "nope")
        assert isinstance(info.value, OccmapError) and isinstance(info.value, FileNotFoundError)
        assert str(tmp_path / "nope") in str(info.value)


def test_map_yaml_number_of_thousands_of_digits(tmp_path):
    (tmp_path / "m.pgm").write_bytes(b"P5\n1 1\n255\n\x00")
    (tmp_path / "m.yaml").write_text(f"image: m.pgm\nresolution: {'9' * 5000}\norigin: [0, 0, 0]\n"
                                     "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    with pytest.raises(FormatError, match=r"m\.yaml, line 2: resolution must be > 0, got inf"):
        load_map(tmp_path / "m.yaml")
