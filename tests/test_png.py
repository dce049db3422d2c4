"""PNG writing: arrays in image order and Pillow images, written atomically, bad pixels refused."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from occmap.errors import InvalidArgumentError, ShapeError
from occmap.png import write_png


@pytest.mark.parametrize("shape, mode", [((3, 4), "L"), ((3, 4, 2), "LA"), ((3, 4, 3), "RGB"), ((3, 4, 4), "RGBA")])
def test_arrays_round_trip(tmp_path, shape, mode):
    pixels = np.random.default_rng(0).integers(0, 256, shape, dtype=np.uint8)
    path = write_png(tmp_path / "sub" / "a.png", pixels)
    with Image.open(path) as im:
        assert im.format == "PNG" and im.mode == mode
        np.testing.assert_array_equal(np.asarray(im), pixels)  # row 0 is the top of the picture
    assert [p.name for p in path.parent.iterdir()] == ["a.png"]


def test_pillow_image(tmp_path):
    im = Image.new("P", (5, 2), 3)
    with Image.open(write_png(tmp_path / "p.png", im)) as back:
        assert back.mode == "P" and back.size == (5, 2)


@pytest.mark.parametrize("pixels, error", [(np.zeros((2, 2), np.float64), InvalidArgumentError),
                                           (np.zeros((2, 2, 5), np.uint8), ShapeError),
                                           (np.zeros(4, np.uint8), ShapeError),
                                           (np.zeros((0, 3), np.uint8), ShapeError)])
def test_bad_pixels(tmp_path, pixels, error):
    with pytest.raises(error):
        write_png(tmp_path / "x.png", pixels)
    assert not (tmp_path / "x.png").exists()
