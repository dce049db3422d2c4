"""The shared 8-sonar data set mapped as Udacity's occupancy-grid-mapping exercise maps it, and
compared cell by cell with the exercise's own picture (``sonar/Map_reference.png``).

What the exercise does (its C++ ``occupancyGridMapping`` / ``inverseSensorModel``, Udacity
Robotics Software Engineer nanodegree; the same code is in public notebooks and repositories):

* a 30 m × 15 m map of 0.1 m cells, indexed ``[x][y]`` with ``x < 300``, ``y < 150``; the centre
  of cell ``(x, y)`` is at ``(100·x + 50 − 6000, −(100·y + 50) + 5000)`` mm, i.e. the robot's
  start is offset 6 m from the left edge and the y axis is flipped (``y`` grows towards −y);
* for every ring of readings, every cell whose centre lies within Z_max = 5 m of the robot gets
  ``l += inverse_sensor_model − l0`` with l0 = 0 (no clamping), where the model takes the
  transducer ``k`` whose bearing is nearest to ``φ = atan2(yi − y, xi − x) − θ`` (unwrapped),
  returns l0 when ``r > min(Z_max, Z_k + α/2)``, ``|φ − θ_k| > β/2``, ``Z_k > Z_max`` or
  ``Z_k < Z_min``; ``l_occ = 0.4`` when ``Z_k < Z_max`` and ``|r − Z_k| < α/2``; ``l_free = −0.4``
  when ``r ≤ Z_k``. α = 200 mm, β = 20, Z_min = 170 mm, θ = tenths of a degree → radians.
  β is compared with an angle in radians, so β/2 = 10 rad never limits anything;
* the picture: one matplotlib dot per cell at ``(x, y)`` (y axis up), green when ``l == 0``,
  black when ``l > 0``, red otherwise, axes 0–300 × 0–150.

:meth:`SonarModel.udacity_exercise` carries that model; :func:`map_like_exercise` builds the
grid. Drawing uses Pillow only. A test harness (``test_sonar.py``), not part of the library.
"""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np

from occmap._files import write_atomic
from occmap.grid2d import OccupancyGrid2D, SonarModel

#: The exercise's Z_max in metres (readings at or beyond it are not integrated).
EXERCISE_MAX_RANGE = 5.0
#: Cell side (m), map size (width, height) in m, and the world position of the grid's corner
#: that the exercise's offsets imply (x from −6 m, y from 5 − 15 = −10 m).
EXERCISE_RESOLUTION = 0.1
EXERCISE_SIZE = (30.0, 15.0)
EXERCISE_ORIGIN = (-6.0, -10.0)
#: Clamping bounds wide enough never to bind on this data (the exercise clamps nothing):
#: log-odds in about [−36.8, 34.5]; the data reach −34.4 and +28.
NO_CLAMP = (1e-16, 1.0 - 1e-15)

#: Map classes, as the exercise colours them.
UNKNOWN, FREE, OCCUPIED = -1, 0, 1
#: A reference pixel that says nothing: anti-aliased, or black within a tick's length of the frame.
UNREADABLE = -9
_TICK_PX = 6
_COLOURS = {UNKNOWN: (0, 128, 0), FREE: (255, 0, 0), OCCUPIED: (0, 0, 0)}


def map_like_exercise(log, model: SonarModel | None = None) -> OccupancyGrid2D:
    """Map a :class:`~occmap.io.sonar.SonarLog` on the exercise's grid (0.1 m, 30 m × 15 m,
    origin (−6, −10) m, no clamping) with ``model`` (default :meth:`SonarModel.udacity_exercise`)
    and max range Z_max = 5 m."""
    model = SonarModel.udacity_exercise() if model is None else model
    g = OccupancyGrid2D(EXERCISE_RESOLUTION, size=EXERCISE_SIZE, origin=EXERCISE_ORIGIN, clamp=NO_CLAMP)
    g.insert_sonar(log.poses, log.ranges, log.bearings, max_range=EXERCISE_MAX_RANGE, model=model)
    return g


def exercise_cells(grid: OccupancyGrid2D) -> np.ndarray:
    """The grid's classes (int8) indexed like the exercise's picture, ``[x, y]`` with ``y`` up the
    plot (= grid row ``H − 1 − y``): OCCUPIED where l > 0, FREE where l < 0, UNKNOWN where no
    reading touched the cell or l == 0 (the exercise's test for green)."""
    L = np.asarray(grid.log_odds(), dtype=np.float64)
    cls = np.full(L.shape, UNKNOWN, dtype=np.int8)
    cls[L > 0] = OCCUPIED
    cls[L < 0] = FREE
    cls[~grid.observed] = UNKNOWN
    return np.ascontiguousarray(cls[::-1, :].T)


def _axes_box(rgb: np.ndarray) -> tuple[int, int, int, int]:
    """(left, top, right, bottom) pixel of the plot's frame: the dark lines nearest outside the
    bounding box of the green (unknown) plot area, or that box grown by one pixel."""
    R, G, B = (rgb[..., i].astype(np.int32) for i in range(3))
    green = (G > R + 40) & (G > B + 40)
    if not green.any():
        raise ValueError("no green (unknown) plot area in the reference picture")
    ys, xs = np.nonzero(green)
    y0, y1, x0, x1 = ys.min(), ys.max(), xs.min(), xs.max()
    dark = (R + G + B) < 100
    cols = np.flatnonzero(dark[y0:y1 + 1, :].mean(axis=0) > 0.5)
    rows = np.flatnonzero(dark[:, x0:x1 + 1].mean(axis=1) > 0.5)

    def nearest(lines, lo, hi):
        below, above = lines[(lines < lo) & (lines >= lo - 4)], lines[(lines > hi) & (lines <= hi + 4)]
        return (below.max() if below.size else lo - 1), (above.min() if above.size else hi + 1)

    left, right = nearest(cols, x0, x1)
    top, bottom = nearest(rows, y0, y1)
    return int(left), int(top), int(right), int(bottom)


def reference_cells(png, cells=(300, 150)) -> tuple[np.ndarray, tuple[int, int, int, int]]:
    """Classes (int8, ``[x, y]``, y up) read from the exercise's picture, and its axes box
    ``(left, top, right, bottom)`` in pixels.

    The frame spans 0…W cells across and 0…H up; cell ``(x, y)`` is the dot drawn at data
    ``(x, y)``. Dots overlap their later neighbours (column x + 1, row y + 1) by about half,
    so each cell is read 0.7 px left of and 0.3 px below its dot's centre. Green → UNKNOWN, red
    → FREE, black → OCCUPIED; anti-aliased pixels that are none of these, and black ones within
    6 px of the frame (where matplotlib draws its tick marks inwards), read as UNREADABLE."""
    from PIL import Image

    rgb = np.asarray(Image.open(png).convert("RGB"))
    left, top, right, bottom = _axes_box(rgb)
    W, H = cells
    u = np.floor(left + np.arange(W) * (right - left) / W - 0.7).astype(int)
    v = np.floor(bottom - np.arange(H) * (bottom - top) / H + 0.3).astype(int)
    px = rgb[v[None, :], u[:, None]].astype(np.int32)  # (W, H, 3)
    R, G, B = px[..., 0], px[..., 1], px[..., 2]
    cls = np.full((W, H), UNREADABLE, dtype=np.int8)
    cls[(R + G + B) < 150] = OCCUPIED
    cls[(G > R + 40) & (G > B + 40)] = UNKNOWN
    cls[R > G + 100] = FREE
    # the tick marks are black lines drawn inwards over the plot from the frame
    tick = _TICK_PX
    near_frame = ((u[:, None] < left + tick) | (u[:, None] > right - tick)
                  | (v[None, :] < top + tick) | (v[None, :] > bottom - tick))
    cls[near_frame & (cls == OCCUPIED)] = UNREADABLE
    return cls, (left, top, right, bottom)


def agreement(ours: np.ndarray, ref: np.ndarray) -> dict:
    """Over the cells the reference shows readably: the fraction classified alike, and the
    intersection-over-union of the free and of the occupied cells; plus how many were read."""
    readable = ref != UNREADABLE
    a_all, b_all = ours[readable], ref[readable]

    def iou(c):
        a, b = a_all == c, b_all == c
        union = (a | b).sum()
        return float((a & b).sum() / union) if union else 1.0

    return {"agree": float((a_all == b_all).mean()), "free_iou": iou(FREE), "occupied_iou": iou(OCCUPIED),
            "cells": int(readable.sum())}


def _panel(cls: np.ndarray, scale: int = 2):
    """An image of classes ``[x, y]`` (y up) with the exercise's colours, ``scale`` px per cell."""
    from PIL import Image

    W, H = cls.shape
    rgb = np.zeros((H, W, 3), dtype=np.uint8)
    img_cls = cls.T[::-1]  # image row 0 = top of the plot
    for c, colour in _COLOURS.items():
        rgb[img_cls == c] = colour
    return Image.fromarray(rgb).resize((W * scale, H * scale), Image.NEAREST)


def map_with_cone_model(log) -> OccupancyGrid2D:
    """occmap's own cone model on the exercise's grid, for contrast: beam 20°, arc 0.2 m,
    quadratic weighting, OctoMap's clamping, no-echo readings (5.11 m) clearing their cone."""
    g = OccupancyGrid2D(EXERCISE_RESOLUTION, size=EXERCISE_SIZE, origin=EXERCISE_ORIGIN)
    g.insert_sonar(log.poses, log.ranges, log.bearings, max_range=log.max_range,
                      model=SonarModel(beam_width=math.radians(20), arc=0.2))
    return g


def _save_png(image, path) -> Path:
    buffer = io.BytesIO()
    image.save(buffer, format="PNG")
    return write_atomic(path, buffer.getvalue())


def sonar_map_png(data_dir, out_png) -> Path:
    """occmap's cone-model map of ``data_dir/sonar`` (:func:`map_with_cone_model`) as a labelled
    figure (free white, occupied black, never observed light blue; north up) at ``out_png``."""
    from occmap.io.sonar import read_sonar_ring

    g = map_with_cone_model(read_sonar_ring(Path(data_dir) / "sonar"))
    return g.save_png(out_png, "8-sonar ring, occmap's cone model (20°, no echo clears)")


def sonar_side_by_side(data_dir, out_png) -> dict:
    """Map ``data_dir/sonar`` with :meth:`SonarModel.udacity_exercise` and write ``out_png``, four
    panels: the exercise's ``Map_reference.png`` (its plot area, read at run time), occmap's map in
    the same colours and orientation, the cells where the two differ, and occmap's own cone model
    (:func:`map_with_cone_model`) for contrast. Returns the agreement of both maps with the
    reference, ``{"exercise_model": {...}, "cone_model": {...}}`` (see :func:`agreement`)."""
    from PIL import Image, ImageDraw

    from occmap.io.sonar import read_sonar_ring

    folder = Path(data_dir) / "sonar"
    log = read_sonar_ring(folder)
    ref, (left, top, right, bottom) = reference_cells(folder / "Map_reference.png")
    ours = exercise_cells(map_like_exercise(log))
    cone = exercise_cells(map_with_cone_model(log))
    figures = {"exercise_model": agreement(ours, ref), "cone_model": agreement(cone, ref)}

    scale = 2
    pw, ph = ref.shape[0] * scale, ref.shape[1] * scale
    with Image.open(folder / "Map_reference.png") as img:
        reference = img.convert("RGB").crop((left + 1, top + 1, right, bottom)).resize((pw, ph), Image.NEAREST)
    readable = ref != UNREADABLE
    differ = (ours != ref) & readable
    diff_rgb = np.full((ref.shape[1], ref.shape[0], 3), 235, dtype=np.uint8)
    diff_rgb[differ.T[::-1]] = (200, 0, 200)
    diff_rgb[~readable.T[::-1]] = (160, 160, 160)
    diff_img = Image.fromarray(diff_rgb).resize((pw, ph), Image.NEAREST)

    ex, co = figures["exercise_model"], figures["cone_model"]
    pad, title_h, foot_h = 16, 22, 34
    out = Image.new("RGB", (2 * pw + 3 * pad, 2 * (ph + title_h) + 3 * pad + foot_h), (255, 255, 255))
    draw = ImageDraw.Draw(out)
    panels = [
        (reference, "Map_reference.png (Udacity exercise, read at run time)"),
        (_panel(ours, scale), f"occmap, SonarModel.udacity_exercise(): {100 * ex['agree']:.2f} % alike"),
        (diff_img, f"where they differ (magenta: {differ.sum()} cells; grey: reference unreadable)"),
        (_panel(cone, scale), f"occmap's cone model (20 deg, no echo clears): {100 * co['agree']:.1f} % alike"),
    ]
    for i, (img, title) in enumerate(panels):
        x = pad + (i % 2) * (pw + pad)
        y = pad + (i // 2) * (ph + title_h + pad)
        draw.text((x, y + 4), title, fill=(0, 0, 0))
        out.paste(img, (x, y + title_h))
        draw.rectangle((x - 1, y + title_h - 1, x + pw, y + title_h + ph), outline=(0, 0, 0))
    foot = out.height - foot_h - 4
    draw.text((pad, foot), "green unknown, red free, black occupied; 300 x 150 cells of 0.1 m, y index up as in the "
              "exercise's plot (world y flipped, start 6 m from the left, 5 m below the top).", fill=(0, 0, 0))
    draw.text((pad, foot + 16), f"exercise model vs reference over {ex['cells']} readable cells: "
              f"{100 * ex['agree']:.2f} % alike, free IoU {ex['free_iou']:.4f}, occupied IoU {ex['occupied_iou']:.3f}"
              f"  |  cone model: free IoU {co['free_iou']:.3f}, occupied IoU {co['occupied_iou']:.3f}",
              fill=(0, 0, 0))
    _save_png(out, out_png)
    return figures
