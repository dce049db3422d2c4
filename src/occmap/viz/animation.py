"""Labelled costmap animations: each frame is the local map's raster (:func:`occmap.local.replay.frame_image`,
a palette image whose colour index is the cost) set into one frame drawn once with matplotlib —
axes in metres from the window's centre, a scale bar, a colour key, a title — so a few hundred
frames still write in seconds.

The frame's own colours (anti-aliased text, the legend) take palette indices 133 … 252, which the
cost palette leaves free (:func:`occmap.local.replay.cost_palette`).
"""

from __future__ import annotations

import io

import numpy as np

from ..errors import ShapeError
from .figure import figure, map_axes

__all__ = ["CostmapAnimation"]

_FIRST, _COUNT = 133, 120  # palette indices of the frame's own colours
_MARGIN = (80, 60, 250, 56)  # pixels left, bottom, right (the key), top (title)


def _key(tracking: bool):
    """``(label, palette index, outline only)`` of the colour key."""
    rows = [("free", 0, False), ("cost, low → high", 40, False), ("cost, high", 120, False),
            ("inscribed (robot touches)", 253, False), ("lethal (obstacle)", 254, False),
            ("unknown", 255, False), ("robot", 130, False)]
    if tracking:
        rows += [("tracked object", 131, True), ("its footprint 1 s ahead", 132, True)]
    return rows


class CostmapAnimation:
    """Frames of a costmap of ``shape`` (H, W) cells of ``resolution`` metres, each cell ``scale``
    pixels, labelled once; :meth:`add` a frame per costmap, :meth:`save` an animated GIF."""

    def __init__(self, shape, resolution: float, scale: int = 2, title: str = "local costmap",
                 tracking: bool = False):
        from matplotlib.patches import Patch
        from PIL import Image, ImageFont

        from ..local.replay import cost_palette

        self.shape = (int(shape[0]), int(shape[1]))
        self.scale = int(scale)
        h, w = self.shape[0] * self.scale, self.shape[1] * self.scale
        left, bottom, right, top = _MARGIN
        width, height = left + w + right, bottom + h + top
        fig = figure(width, height)
        ax = fig.add_axes((left / width, bottom / height, w / width, h / height))
        fig.set_layout_engine("none")
        half_x, half_y = self.shape[1] * resolution / 2.0, self.shape[0] * resolution / 2.0
        map_axes(ax, (-half_x, half_x, -half_y, half_y), title, "x from the window's centre [m]",
                 "y from the window's centre [m]")
        ax.set_aspect("auto")  # the axes box is the raster's, pixel for pixel
        palette = np.array(cost_palette(), dtype=np.uint8).reshape(256, 3) / 255.0
        handles = [Patch(facecolor="none" if outline else palette[i], edgecolor=palette[i] if outline else "0.4",
                         lw=2 if outline else 0.8, label=label) for label, i, outline in _key(tracking)]
        fig.legend(handles=handles, loc="center left", bbox_to_anchor=((left + w + 12) / width, 0.5),
                   fontsize="small", frameon=False)
        buffer = io.BytesIO()
        fig.savefig(buffer, format="png")
        frame = Image.open(buffer).convert("RGB").quantize(_COUNT)
        self._frame = np.asarray(frame) + np.uint8(_FIRST)
        merged = palette.copy() * 255.0
        own = np.array(frame.getpalette()[:3 * _COUNT], dtype=np.float64).reshape(-1, 3)
        merged[_FIRST:_FIRST + len(own)] = own
        self._palette = np.rint(merged).astype(np.uint8).ravel().tolist()
        self._box = (top, top + h, left, left + w)  # rows, then columns, of the raster in the frame
        self._images = []
        self._font = ImageFont.load_default(size=16)

    def add(self, cost, robot_cell=None, objects=None, caption: str = "") -> None:
        """One frame: ``cost`` (H, W) uint8 Nav2 costs, the robot's ``(row, col)`` cell, tracked
        ``objects`` (see :func:`occmap.local.replay.frame_image`), and a ``caption`` (e.g. the
        time) under the raster."""
        from PIL import Image, ImageDraw

        from ..local.replay import frame_image

        raster = np.asarray(frame_image(cost, robot_cell, self.scale, objects))
        r0, r1, c0, c1 = self._box
        if raster.shape != (r1 - r0, c1 - c0):
            raise ShapeError(f"costmap of shape {np.shape(cost)}, the animation's is {self.shape}")
        pixels = self._frame.copy()
        pixels[r0:r1, c0:c1] = raster
        image = Image.fromarray(pixels, mode="P")
        image.putpalette(self._palette)
        if caption:
            ImageDraw.Draw(image).text((c1 + 12, r1 - 20), caption, fill=254, font=self._font)
        self._images.append(image)

    def __len__(self) -> int:
        return len(self._images)

    @property
    def frame_bytes(self) -> int:
        """Bytes one frame holds in memory until :meth:`save` (one byte a pixel)."""
        return self._frame.nbytes

    def png_bytes(self, index: int = -1) -> bytes:
        """One frame (the last by default) as PNG bytes."""
        buffer = io.BytesIO()
        self._images[index].save(buffer, format="PNG")
        return buffer.getvalue()

    def save(self, path, fps: float):
        """Write the frames as a looping animated GIF (:func:`occmap.local.replay.save_gif`);
        returns the path."""
        from ..local.replay import save_gif

        return save_gif(path, self._images, fps)
