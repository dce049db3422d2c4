"""Frames of a replay through a :class:`LocalMap` (``occmap local``, in
:mod:`occmap.commands.local`): the costmap drawn with its Nav2 values (white free, yellow → red
graded, purple inscribed, black lethal, grey unknown), north up, the robot as a blue dot, and with
tracking the confirmed tracks as green boxes, each with its footprint predicted one second ahead
(light green) and a line between the two centres.
Frames are palette images (the cost is the colour index, no quantisation), so a few hundred frames
write in seconds.
"""

from __future__ import annotations

import numpy as np

__all__ = ["cost_indices", "cost_palette", "cost_rgb", "frame_image", "save_gif", "tracked_objects"]

_ROBOT = 130  # palette index of the robot marker (graded costs use indices 1 … 126)
_TRACK = 131  # palette index of tracked objects
_AHEAD = 132  # palette index of their predicted footprints


def cost_palette() -> list[int]:
    """768 palette entries: index 0 free (white), 1–126 graded costs (yellow → red), 130 the
    robot (blue), 131 tracked objects (green), 132 their predicted footprints (light green), 253
    inscribed (purple), 254 lethal (black), 255 unknown (grey)."""
    pal = np.zeros((256, 3), dtype=np.uint8)
    pal[:] = (255, 0, 255)
    pal[0] = (255, 255, 255)
    t = np.linspace(0.0, 1.0, 126)
    pal[1:127, 0] = 255
    pal[1:127, 1] = np.rint(230 * (1 - t)).astype(np.uint8)
    pal[1:127, 2] = np.rint(120 * (1 - t)).astype(np.uint8)
    pal[_ROBOT] = (30, 90, 255)
    pal[_TRACK] = (0, 170, 60)
    pal[_AHEAD] = (120, 220, 140)
    pal[253] = (120, 40, 140)
    pal[254] = (0, 0, 0)
    pal[255] = (200, 200, 205)
    return pal.reshape(-1).tolist()


def cost_indices(cost: np.ndarray) -> np.ndarray:
    """The palette index (:func:`cost_palette`) of each Nav2 cost: graded costs 1 … 252 two to an
    index, the others their own."""
    idx = cost.copy()
    graded = (cost >= 1) & (cost <= 252)
    idx[graded] = 1 + (cost[graded].astype(np.int32) - 1) // 2
    return idx


def cost_rgb(cost: np.ndarray) -> np.ndarray:
    """Nav2 costs (H, W) as the animation's colours, RGB (H, W, 3) uint8."""
    return np.asarray(cost_palette(), np.uint8).reshape(256, 3)[cost_indices(cost)]


def frame_image(cost: np.ndarray, robot_cell=None, scale: int = 1, objects=None):
    """A palette ``PIL.Image`` of a costmap (row 0 at the bottom, as the map's y grows up).

    ``objects``: ``(corners (T, 4, 2), ahead (T, 4, 2))`` in window cells (x = column, y = row,
    cell centres at integer + 0.5), each object's footprint now and predicted (:func:`tracked_objects`);
    drawn as outlines, with a line between their centres."""
    from PIL import Image, ImageDraw

    idx = cost_indices(cost)
    if robot_cell is not None:
        r, c = robot_cell
        idx[max(r - 1, 0):r + 2, max(c - 1, 0):c + 2] = _ROBOT
    img = Image.fromarray(np.ascontiguousarray(idx[::-1]), mode="P")
    img.putpalette(cost_palette())
    if scale > 1:
        img = img.resize((img.width * scale, img.height * scale), Image.NEAREST)
    if objects is not None:
        corners, ahead = objects
        H = cost.shape[0]
        draw = ImageDraw.Draw(img)

        def px(p):  # window cells (x, y up) to image pixels (y down)
            return float(p[0]) * scale, (H - float(p[1])) * scale

        for box, later in zip(corners, ahead):
            draw.polygon([px(p) for p in later], outline=_AHEAD)
            draw.polygon([px(p) for p in box], outline=_TRACK)
            draw.line([px(box.mean(axis=0)), px(later.mean(axis=0))], fill=_TRACK, width=max(1, scale // 2))
    return img


def tracked_objects(lm, ahead: float):
    """The confirmed tracks of a tracking :class:`~occmap.local.LocalMap` for :func:`frame_image`:
    their footprints' corners now and as predicted ``ahead`` seconds later, in window cells."""
    from .tracking.detection import box_corners

    t = lm.tracks()
    keep = np.flatnonzero(t.confirmed)
    if keep.size == 0:
        return np.zeros((0, 4, 2)), np.zeros((0, 4, 2))
    ids, states, _, sizes = lm.objects.tracker.predicted(lm.time + ahead)
    row = {int(i): k for k, i in enumerate(ids)}  # a few dozen tracks at most
    later = np.array([row[int(i)] for i in t.id[keep]], dtype=np.int64)
    now = box_corners(t.x[keep], t.y[keep], t.heading[keep], t.length[keep], t.width[keep])
    then = box_corners(states[later, 0], states[later, 1], states[later, 2], sizes[later, 0], sizes[later, 1])
    return (now - lm.origin) / lm.resolution, (then - lm.origin) / lm.resolution


def save_gif(path, frames, fps: float):
    """Write palette ``frames`` as a looping animated GIF at ``fps`` frames a second, all at once
    (:func:`occmap._files.write_atomic`); returns the path."""
    import io

    from .._files import write_atomic

    buf = io.BytesIO()
    frames[0].save(buf, format="GIF", save_all=True, append_images=frames[1:], loop=0,
                   duration=max(20, int(round(1000.0 / fps))), optimize=False)
    return write_atomic(path, buf.getvalue())
