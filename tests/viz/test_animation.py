"""Costmap animations: the raster sits pixel for pixel in a frame labelled once, and the GIF holds
every frame."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from occmap.errors import ShapeError
from occmap.local.replay import cost_palette
from occmap.viz.animation import CostmapAnimation


def test_frames_hold_the_costmap_cell_for_pixel_with_the_key_and_axes(tmp_path):
    cost = np.zeros((40, 60), np.uint8)
    cost[:] = 255  # unknown
    cost[10:30, 10:50] = 0  # free
    cost[20, 30] = 254  # one obstacle
    anim = CostmapAnimation(cost.shape, 0.1, scale=3, title="test", tracking=True)
    anim.add(cost, robot_cell=(15, 15), caption="t = 0.0 s")
    anim.add(np.where(cost == 254, 0, cost).astype(np.uint8))
    rgb = np.asarray(anim._images[0].convert("RGB"))
    r0, r1, c0, c1 = anim._box
    assert (r1 - r0, c1 - c0) == (120, 180)
    inner = rgb[r0:r1, c0:c1]
    palette = np.array(cost_palette(), np.uint8).reshape(256, 3)
    # row 0 of the costmap is the bottom of the picture
    assert (inner[(40 - 1 - 20) * 3 + 1, 30 * 3 + 1] == palette[254]).all()
    assert (inner[(40 - 1 - 12) * 3 + 1, 40 * 3 + 1] == palette[0]).all()
    assert (inner[0, 0] == palette[255]).all()
    assert (inner[(40 - 1 - 15) * 3 + 1, 15 * 3 + 1] == palette[130]).all()  # the robot
    outside = np.concatenate([rgb[:r0].reshape(-1, 3), rgb[:, c1:].reshape(-1, 3)])
    for index in (130, 131, 132, 253):  # the key shows the colours of the raster
        assert (np.abs(outside.astype(int) - palette[index]).max(axis=1) <= 8).any()
    assert (rgb[:r0] < 100).all(axis=-1).any()  # title text above the raster
    path = anim.save(tmp_path / "a.gif", 5.0)
    with Image.open(path) as gif:
        assert gif.n_frames == len(anim) == 2 and gif.size == (rgb.shape[1], rgb.shape[0])
    with pytest.raises(ShapeError):
        anim.add(np.zeros((10, 10), np.uint8))


def test_a_local_map_shows_itself_in_a_notebook():
    import io

    from occmap.local import LocalMap

    for tracking in (False, True):
        lm = LocalMap((8.0, 6.0), 0.1, tracking=tracking)
        empty = Image.open(io.BytesIO(lm._repr_png_()))
        lm.insert_scan((0.0, 0.0, 0.0), [2.0], [0.0], 0.0, max_range=5.0)
        seen = np.asarray(Image.open(io.BytesIO(lm._repr_png_())).convert("RGB"))
        assert seen.shape[:2] == empty.size[::-1]
        r0, r1, c0, c1 = CostmapAnimation(lm.shape, 0.1)._box
        raster = seen[r0:r1, c0:c1]
        lethal = np.array(cost_palette(), np.uint8).reshape(256, 3)[254]
        assert (raster == lethal).all(axis=-1).sum() == 4  # the hit: one cell, 2 × 2 px
