"""ROS map_server / map_saver files: round trips, exact bytes, the YAML subset, errors, atomicity."""

from __future__ import annotations

import hashlib

import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image

from occmap.errors import FormatError, InvalidArgumentError, OccmapError, ShapeError
from occmap.io.mapserver import MapFile, load_map, save_map


def trinary(occ: np.ndarray) -> np.ndarray:
    """The classification a map_saver trinary file keeps (defaults 0.65 / 0.196)."""
    occ = occ.astype(np.int64)
    out = np.full(occ.shape, -1, dtype=np.int8)
    out[(occ >= 0) & (occ <= 19)] = 0
    out[(occ >= 65) & (occ <= 100)] = 100
    return out


def write(path, text: str):
    path.write_text(text, encoding="utf-8")
    return path


def write_pgm(path, rows):
    rows = np.asarray(rows, dtype=np.uint8)
    path.write_bytes(b"P5\n%d %d\n255\n" % (rows.shape[1], rows.shape[0]) + rows.tobytes())
    return path


# ----------------------------------------------------------------------------------------------
# saving and reading back


@settings(max_examples=25, deadline=None)
@given(
    st.integers(1, 9),
    st.integers(1, 9),
    st.integers(0, 2**32 - 1),
)
def test_round_trip_random_maps(tmp_path_factory, height, width, seed):
    folder = tmp_path_factory.mktemp("rt")
    rng = np.random.default_rng(seed)
    occ = rng.integers(-1, 101, size=(height, width)).astype(np.int8)
    save_map(folder / "map.yaml", occ, 0.05, (1.0, -2.0))
    loaded = load_map(folder / "map.yaml")
    assert loaded.occupancy.dtype == np.int8
    assert loaded.occupancy.shape == (height, width)
    np.testing.assert_array_equal(loaded.occupancy, trinary(occ))
    assert loaded.resolution == 0.05
    assert loaded.origin == (1.0, -2.0, 0.0)


def test_round_trip_every_value(tmp_path):
    occ = np.arange(-1, 101, dtype=np.int8).reshape(6, 17)
    save_map(tmp_path / "m.yaml", occ, 0.1, (0.0, 0.0))
    loaded = load_map(tmp_path / "m.yaml").occupancy
    np.testing.assert_array_equal(loaded, trinary(occ))
    flat = dict(zip(occ.ravel().tolist(), loaded.ravel().tolist()))
    assert flat[-1] == -1 and flat[0] == 0 and flat[19] == 0 and flat[20] == -1
    assert flat[64] == -1 and flat[65] == 100 and flat[100] == 100


def test_pgm_bytes_top_row_first(tmp_path):
    # row 0 (lowest y): free, occupied, unknown ; row 1: 19, 20, 65 ; row 2 (top): 100, 0, -1
    occ = np.array([[0, 100, -1], [19, 20, 65], [100, 0, -1]], dtype=np.int8)
    image = save_map(tmp_path / "small.yaml", occ, 0.05, (-10.0, -10.0))
    assert image == tmp_path / "small.pgm"
    data = image.read_bytes()
    header = b"P5\n3 3\n255\n"
    assert data.startswith(header)
    body = data[len(header):]
    assert body == bytes([0, 254, 205, 254, 205, 0, 254, 0, 205])
    # Pillow agrees on the picture: top row = highest-y map row
    picture = np.asarray(Image.open(image))
    np.testing.assert_array_equal(picture[0], [0, 254, 205])


def test_non_square_header_is_width_then_height(tmp_path):
    occ = np.zeros((2, 5), dtype=np.int8)
    image = save_map(tmp_path / "w.yaml", occ, 0.05, (0.0, 0.0))
    assert image.read_bytes().startswith(b"P5\n5 2\n255\n")


def test_yaml_text_matches_map_saver_layout(tmp_path):
    occ = np.zeros((2, 2), dtype=np.int8)
    save_map(tmp_path / "office.yaml", occ, 0.05, (-12.5, -3.25))
    assert (tmp_path / "office.yaml").read_text() == (
        "image: office.pgm\n"
        "mode: trinary\n"
        "resolution: 0.05\n"
        "origin: [-12.5, -3.25, 0.0]\n"
        "negate: 0\n"
        "occupied_thresh: 0.65\n"
        "free_thresh: 0.196\n"
        "# the image this file was written with; occmap checks it on loading\n"
        f"occmap_image_sha256: {hashlib.sha256((tmp_path / 'office.pgm').read_bytes()).hexdigest()}\n"
    )


def test_yaml_quotes_awkward_image_names(tmp_path):
    folder = tmp_path / "a b"
    folder.mkdir()
    save_map(folder / "my map#1.yaml", np.zeros((1, 1), np.int8), 0.5, (0, 0))
    text = (folder / "my map#1.yaml").read_text()
    assert text.splitlines()[0] == 'image: "my map#1.pgm"'
    assert load_map(folder / "my map#1.yaml").image_path == folder / "my map#1.pgm"


def test_raw_mode_round_trips_exactly(tmp_path):
    occ = np.arange(-1, 101, dtype=np.int8).reshape(2, 51)
    save_map(tmp_path / "r.yaml", occ, 0.05, (0, 0), mode="raw")
    loaded = load_map(tmp_path / "r.yaml")
    assert loaded.mode == "raw"
    np.testing.assert_array_equal(loaded.occupancy, occ)


def test_scale_mode_png_marks_unknown_transparent(tmp_path):
    occ = np.array([[-1, 0, 50, 100]], dtype=np.int8)
    image = save_map(tmp_path / "s.yaml", occ, 0.05, (0, 0), mode="scale", image_format="png")
    picture = np.asarray(Image.open(image))
    assert picture.shape == (1, 4, 2)
    np.testing.assert_array_equal(picture[0, :, 1], [0, 255, 255, 255])
    np.testing.assert_array_equal(picture[0, 1:, 0], [255, 128, 0])
    loaded = load_map(tmp_path / "s.yaml").occupancy
    # nav2: p = (255 - 128)/255 = 0.49804 → rint(100·(0.49804 − 0.196)/(0.65 − 0.196)) = rint(66.53)
    # = 67 (ROS 1's 1 + 98·0.66528 would give 66, and the old rint(99·ratio) 66 too)
    np.testing.assert_array_equal(loaded, [[-1, 0, 67, 100]])


def test_png_and_bmp_trinary(tmp_path):
    occ = np.array([[-1, 0], [100, 30]], dtype=np.int8)
    for fmt in ("png", "bmp"):
        image = save_map(tmp_path / f"{fmt}.yaml", occ, 0.05, (0, 0), image_format=fmt)
        assert image.suffix == "." + fmt
        np.testing.assert_array_equal(load_map(tmp_path / f"{fmt}.yaml").occupancy, trinary(occ))


def test_save_rejects_bad_arguments(tmp_path):
    good = np.zeros((2, 2), np.int8)
    y = tmp_path / "m.yaml"
    with pytest.raises(ShapeError):
        save_map(y, np.zeros(4, np.int8), 0.05, (0, 0))
    with pytest.raises(ShapeError):
        save_map(y, np.zeros((0, 3), np.int8), 0.05, (0, 0))
    with pytest.raises(InvalidArgumentError):
        save_map(y, good.astype(float), 0.05, (0, 0))
    with pytest.raises(InvalidArgumentError):
        save_map(y, good, 0.0, (0, 0))
    with pytest.raises(InvalidArgumentError):
        save_map(y, good, float("nan"), (0, 0))
    with pytest.raises(InvalidArgumentError):
        save_map(y, good, 0.05, (0, 0, 0, 0))
    with pytest.raises(InvalidArgumentError):
        save_map(y, good, 0.05, (0, 0), mode="fancy")
    with pytest.raises(InvalidArgumentError):
        save_map(y, good, 0.05, (0, 0), image_format="jpg")
    with pytest.raises(InvalidArgumentError):  # 205 would read back as free
        save_map(y, good, 0.05, (0, 0), free_thresh=0.25)
    with pytest.raises(InvalidArgumentError):
        save_map(y, good, 0.05, (0, 0), free_thresh=0.7, occupied_thresh=0.65, mode="raw")
    with pytest.raises(InvalidArgumentError):  # PGM has no alpha for scale's unknown cells
        save_map(y, good, 0.05, (0, 0), mode="scale")
    assert list(tmp_path.iterdir()) == []


def test_save_with_yaw_and_custom_thresholds(tmp_path):
    save_map(tmp_path / "m.yaml", np.array([[10, 15]], np.int8), 0.25, (1, 2, 0.5),
             occupied_thresh=0.7, free_thresh=0.1)
    text = (tmp_path / "m.yaml").read_text()
    assert "origin: [1.0, 2.0, 0.5]\n" in text
    assert "occupied_thresh: 0.7\nfree_thresh: 0.1\n" in text
    loaded = load_map(tmp_path / "m.yaml")
    assert loaded.origin == (1.0, 2.0, 0.5)
    np.testing.assert_array_equal(loaded.occupancy, [[0, -1]])  # free only up to 10


# ----------------------------------------------------------------------------------------------
# loading hand-written files


def test_load_hand_written_yaml_with_comments_and_quotes(tmp_path):
    # image rows, top first: [0, 255], [205, 128]
    write_pgm(tmp_path / "hand.pgm", [[0, 255], [205, 128]])
    write(tmp_path / "hand.yaml", (
        "# a map drawn by hand\n"
        "---\n"
        "image: 'hand.pgm'   # single-quoted\n"
        "\n"
        "resolution: 0.1\n"
        "origin: [ -1 , 2.5,0 ]  # yaw 0\n"
        'mode: "trinary"\n'
        "negate: 0\n"
        "occupied_thresh: 0.65\n"
        "free_thresh: .196\n"
        "extra_key: ignored\n"
    ))
    m = load_map(tmp_path / "hand.yaml")
    assert isinstance(m, MapFile)
    assert m.resolution == 0.1 and m.origin == (-1.0, 2.5, 0.0)
    assert m.mode == "trinary" and m.negate is False
    assert m.free_thresh == 0.196 and m.occupied_thresh == 0.65
    assert m.image_path == tmp_path / "hand.pgm"
    # row 0 = bottom image row: 205 → unknown, 128 → p = 0.498 → unknown
    np.testing.assert_array_equal(m.occupancy, [[-1, -1], [100, 0]])


def test_defaults_mode_trinary_negate_zero(tmp_path):
    write_pgm(tmp_path / "d.pgm", [[0]])
    write(tmp_path / "d.yaml", "image: d.pgm\nresolution: 1\norigin: [0, 0, 0]\n"
          "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    m = load_map(tmp_path / "d.yaml")
    assert m.mode == "trinary" and m.negate is False
    assert m.occupancy.tolist() == [[100]]


def test_load_negate(tmp_path):
    write_pgm(tmp_path / "n.pgm", [[0, 255, 205]])
    write(tmp_path / "n.yaml", "image: n.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n"
          "negate: 1\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    m = load_map(tmp_path / "n.yaml")
    assert m.negate is True
    # p = gray/255: 0 → free, 255 → occupied, 205 → 0.80 → occupied
    assert m.occupancy.tolist() == [[0, 100, 100]]


def test_load_scale_mode(tmp_path):
    # p = (255 − gray)/255 for gray 255, 200, 150, 100, 50, 0
    grays = [255, 200, 150, 100, 50, 0]
    write_pgm(tmp_path / "s.pgm", [grays])
    write(tmp_path / "s.yaml", "image: s.pgm\nmode: scale\nresolution: 0.05\n"
          "origin: [0.0, 0.0, 0.0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    expected = []
    for g in grays:
        p = (255 - g) / 255
        if p > 0.65:
            expected.append(100)
        elif p < 0.196:
            expected.append(0)
        else:
            expected.append(int(np.rint(100 * (p - 0.196) / (0.65 - 0.196))))
    # by hand, nav2's rint(100·ratio): gray 200 → p 0.21569, ratio 0.04336 → 4; gray 150 → p
    # 0.41176, ratio 0.47525 → 48; gray 100 → p 0.60784, ratio 0.90714 → 91 (the old
    # rint(99·ratio) gave 47 and 90)
    assert expected == [0, 4, 48, 91, 100, 100]
    assert load_map(tmp_path / "s.yaml").occupancy.tolist() == [expected]


def test_load_raw_mode(tmp_path):
    write_pgm(tmp_path / "r.pgm", [[0, 42, 100, 255]])
    write(tmp_path / "r.yaml", "image: r.pgm\nmode: raw\nresolution: 0.05\n"
          "origin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    assert load_map(tmp_path / "r.yaml").occupancy.tolist() == [[0, 42, 100, -1]]


def test_load_colour_png_is_averaged(tmp_path):
    # one row: pure red (avg 85 → p = 0.667 → occupied), white (free), gray 205 (unknown)
    rgb = np.array([[[255, 0, 0], [255, 255, 255], [205, 205, 205]]], dtype=np.uint8)
    Image.fromarray(rgb).save(tmp_path / "c.png")
    write(tmp_path / "c.yaml", "image: c.png\nresolution: 0.05\norigin: [0, 0, 0]\n"
          "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    assert load_map(tmp_path / "c.yaml").occupancy.tolist() == [[100, 0, -1]]


def test_load_scale_png_alpha_zero_is_unknown(tmp_path):
    rgba = np.array([[[0, 0, 0, 255], [0, 0, 0, 0], [255, 255, 255, 255]]], dtype=np.uint8)
    Image.fromarray(rgba).save(tmp_path / "a.png")
    write(tmp_path / "a.yaml", "image: a.png\nmode: scale\nresolution: 0.05\n"
          "origin: [0, 0, 0]\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    assert load_map(tmp_path / "a.yaml").occupancy.tolist() == [[100, -1, 0]]


def test_load_absolute_image_path(tmp_path):
    (tmp_path / "images").mkdir()
    (tmp_path / "maps").mkdir()
    image = write_pgm(tmp_path / "images" / "abs.pgm", [[254, 0]])
    write(tmp_path / "maps" / "abs.yaml", f'image: "{image}"\nresolution: 0.05\n'
          "origin: [0, 0, 0]\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    m = load_map(tmp_path / "maps" / "abs.yaml")
    assert m.image_path == image
    assert m.occupancy.tolist() == [[0, 100]]


def test_load_relative_image_in_subfolder(tmp_path):
    (tmp_path / "img").mkdir()
    write_pgm(tmp_path / "img" / "sub.pgm", [[254]])
    write(tmp_path / "sub.yaml", "image: img/sub.pgm\nresolution: 0.05\n"
          "origin: [0, 0, 0]\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    assert load_map(tmp_path / "sub.yaml").occupancy.tolist() == [[0]]


# ----------------------------------------------------------------------------------------------
# errors

GOOD = ("image: e.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.196\n")


def load_error(tmp_path, text, name="e.yaml") -> FormatError:
    write_pgm(tmp_path / "e.pgm", [[0]])
    write(tmp_path / name, text)
    with pytest.raises(FormatError) as info:
        load_map(tmp_path / name)
    assert isinstance(info.value, OccmapError)
    assert str(tmp_path / name) in str(info.value)
    return info.value


def test_good_fixture_loads(tmp_path):
    write_pgm(tmp_path / "e.pgm", [[0]])
    write(tmp_path / "e.yaml", GOOD)
    assert load_map(tmp_path / "e.yaml").occupancy.tolist() == [[100]]


def test_error_missing_yaml(tmp_path):
    with pytest.raises(FormatError) as info:
        load_map(tmp_path / "nope.yaml")
    assert str(tmp_path / "nope.yaml") in str(info.value)
    assert "not found" in str(info.value)


def test_error_missing_image(tmp_path):
    write(tmp_path / "m.yaml", GOOD.replace("e.pgm", "gone.pgm"))
    with pytest.raises(FormatError) as info:
        load_map(tmp_path / "m.yaml")
    assert info.value.line == 1
    assert "gone.pgm" in str(info.value) and str(tmp_path / "m.yaml") in str(info.value)


def test_error_unreadable_image(tmp_path):
    (tmp_path / "e.pgm").write_bytes(b"this is no image")
    write(tmp_path / "e.yaml", GOOD)
    with pytest.raises(FormatError) as info:
        load_map(tmp_path / "e.yaml")
    assert str(tmp_path / "e.pgm") in str(info.value)


@pytest.mark.parametrize(
    ("text", "line", "words"),
    [
        (GOOD + "this is not yaml\n", 7, "key: value"),
        (GOOD + "  indented: 1\n", 6, "not valid YAML"),
        (GOOD + "mode:\n", 6, "no value"),
        (GOOD + "resolution: 0.1\n", 6, "repeated"),
        (GOOD.replace("[0, 0, 0]", "[0, [0], 0]"), 3, "origin must be a number, got a list"),
        (GOOD + "list: [1, 2\n", 7, "']'"),
        (GOOD + "name: 'open\n", 7, "not valid YAML"),
        (GOOD + "- item\n", 6, "not valid YAML"),
        (GOOD.replace("0.05", "fast"), 2, "number"),
        (GOOD.replace("0.05", "-0.05"), 2, "> 0"),
        (GOOD.replace("0.05", "0"), 2, "> 0"),
        (GOOD.replace("[0, 0, 0]", "[0, 0]"), 3, "origin"),
        (GOOD.replace("[0, 0, 0]", "0"), 3, "origin"),
        (GOOD.replace("0.65", "1.5"), 4, "[0, 1]"),
        (GOOD.replace("0.196", "-0.1"), 5, "[0, 1]"),
        (GOOD.replace("0.196", "0.7"), 5, "below"),
        (GOOD + "mode: fancy\n", 6, "mode"),
        (GOOD + "negate: 2\n", 6, "negate"),
        (GOOD.replace("image: e.pgm", "image: [e.pgm]"), 1, "string"),
    ],
)
def test_error_bad_lines_name_file_and_line(tmp_path, text, line, words):
    error = load_error(tmp_path, text)
    assert error.line == line
    assert f"line {line}" in str(error)
    assert words in str(error)


@pytest.mark.parametrize("key", ["image", "resolution", "origin", "occupied_thresh",
                                 "free_thresh"])
def test_error_missing_required_key(tmp_path, key):
    text = "".join(ln + "\n" for ln in GOOD.splitlines() if not ln.startswith(key + ":"))
    error = load_error(tmp_path, text)
    assert key in str(error) and "missing" in str(error)


# ----------------------------------------------------------------------------------------------
# atomic writes


def test_existing_files_replaced_whole_and_no_temp_files(tmp_path):
    big = np.full((40, 50), 100, dtype=np.int8)
    save_map(tmp_path / "m.yaml", big, 0.05, (-123.456789, 98.7654321))
    (tmp_path / "m.yaml").write_text("stale " * 1000)
    small = np.zeros((2, 3), dtype=np.int8)
    save_map(tmp_path / "m.yaml", small, 0.05, (0, 0))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.pgm", "m.yaml"]
    assert (tmp_path / "m.pgm").stat().st_size == len(b"P5\n3 2\n255\n") + 6
    assert "stale" not in (tmp_path / "m.yaml").read_text()
    np.testing.assert_array_equal(load_map(tmp_path / "m.yaml").occupancy, small)


def test_failed_write_leaves_old_file_and_no_temp(tmp_path, monkeypatch):
    save_map(tmp_path / "m.yaml", np.zeros((2, 2), np.int8), 0.05, (0, 0))
    before = (tmp_path / "m.yaml").read_bytes(), (tmp_path / "m.pgm").read_bytes()

    def boom(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(OSError):
        save_map(tmp_path / "m.yaml", np.full((5, 5), 100, np.int8), 0.05, (0, 0))
    monkeypatch.undo()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.pgm", "m.yaml"]
    assert ((tmp_path / "m.yaml").read_bytes(), (tmp_path / "m.pgm").read_bytes()) == before


def test_trinary_averages_alpha_in_like_map_server(tmp_path):
    # map_server quirk: in trinary mode the alpha channel joins the average.
    # black opaque: (0+0+0+255)/4 = 63.75 → p = 0.75 → occupied; gray 100 opaque:
    # (300+255)/4 = 138.75 → p = 0.456 → unknown (it would be p = 0.608 without alpha).
    rgba = np.array([[[0, 0, 0, 255], [100, 100, 100, 255]]], dtype=np.uint8)
    Image.fromarray(rgba).save(tmp_path / "t.png")
    write(tmp_path / "t.yaml", "image: t.png\nresolution: 0.05\norigin: [0, 0, 0]\n"
          "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    assert load_map(tmp_path / "t.yaml").occupancy.tolist() == [[100, -1]]
    write(tmp_path / "t.yaml", "image: t.png\nmode: scale\nresolution: 0.05\n"
          "origin: [0, 0, 0]\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    assert load_map(tmp_path / "t.yaml").occupancy.tolist() == [[100, 91]]


def test_sixteen_bit_and_palette_images(tmp_path):
    Image.fromarray(np.array([[0, 65535]], dtype=np.uint16)).save(tmp_path / "w.png")
    write(tmp_path / "w.yaml", "image: w.png\nresolution: 0.05\norigin: [0, 0, 0]\n"
          "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    assert load_map(tmp_path / "w.yaml").occupancy.tolist() == [[100, 0]]
    Image.fromarray(np.array([[0, 255]], dtype=np.uint8)).convert("P").save(tmp_path / "p.png")
    write(tmp_path / "p.yaml", "image: p.png\nresolution: 0.05\norigin: [0, 0, 0]\n"
          "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    assert load_map(tmp_path / "p.yaml").occupancy.tolist() == [[100, 0]]


def test_negative_zero_origin_prints_as_zero(tmp_path):
    save_map(tmp_path / "z.yaml", np.zeros((1, 1), np.int8), 0.05, np.array([-0.0, -0.0]))
    assert "origin: [0.0, 0.0, 0.0]\n" in (tmp_path / "z.yaml").read_text()


# ----------------------------------------------------------------------------------------------
# real YAML, and pairs from two saves


def test_block_style_lists_anchors_and_flow_mappings_are_yaml(tmp_path):
    write_pgm(tmp_path / "b.pgm", [[0, 254]])
    write(tmp_path / "b.yaml", (
        "image: b.pgm\n"
        "resolution: &res 0.25\n"
        "origin:\n"
        "  - -1.5\n"
        "  - 2\n"
        "  - 0.0\n"
        "thresholds: {unused: *res}\n"
        "occupied_thresh: 0.65\n"
        "free_thresh: 0.196\n"
    ))
    m = load_map(tmp_path / "b.yaml")
    assert m.origin == (-1.5, 2.0, 0.0) and m.resolution == 0.25
    assert m.occupancy.tolist() == [[100, 0]]


def test_block_style_origin_errors_name_the_item_line(tmp_path):
    text = GOOD.replace("origin: [0, 0, 0]", "origin:\n  - 0\n  - north\n  - 0")
    error = load_error(tmp_path, text)
    assert error.line == 5 and "origin must be a number, got 'north'" in str(error)


def test_pair_from_two_saves_fails_to_load(tmp_path):
    save_map(tmp_path / "m.yaml", np.zeros((3, 4), np.int8), 0.05, (1.0, 2.0))
    old_yaml = (tmp_path / "m.yaml").read_bytes()
    save_map(tmp_path / "m.yaml", np.full((5, 2), 100, np.int8), 0.1, (-3.0, 0.0))
    (tmp_path / "m.yaml").write_bytes(old_yaml)  # a save killed between its image and its YAML
    error = load_error(tmp_path, old_yaml.decode(), name="m.yaml")
    assert "m.pgm is not the image this file was saved with" in str(error) and error.line == 9


def test_yaml_without_the_digest_loads_as_before(tmp_path):
    save_map(tmp_path / "m.yaml", np.zeros((3, 4), np.int8), 0.05, (1.0, 2.0))
    text = (tmp_path / "m.yaml").read_text()
    (tmp_path / "m.yaml").write_text("".join(ln + "\n" for ln in text.splitlines()[:7]))
    assert load_map(tmp_path / "m.yaml").occupancy.shape == (3, 4)


@pytest.mark.parametrize("name, fmt", [("x.pgm", "pgm"), ("x.png", "png")])
def test_yaml_path_that_is_its_own_image_is_refused(tmp_path, name, fmt):
    with pytest.raises(InvalidArgumentError, match="would be its own image"):
        save_map(tmp_path / name, np.zeros((2, 2), np.int8), 0.05, (0, 0), image_format=fmt)
    assert list(tmp_path.iterdir()) == []
