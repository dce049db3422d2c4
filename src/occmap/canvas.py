"""A small raster canvas in world coordinates (metres, y up) for the PNG pictures occmap writes.

Pillow does the drawing; this class only maps world points to pixels and keeps the styling in
one place. Batched: every method takes arrays of points.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from .png import write_png


class Canvas:
    """An RGB image showing the world rectangle ``[xmin, xmax] × [ymin, ymax]`` at ``scale`` px/m."""

    def __init__(self, bounds: tuple[float, float, float, float], scale: float = 100.0, margin: int = 20,
                 background=(255, 255, 255)):
        self.xmin, self.xmax, self.ymin, self.ymax = map(float, bounds)
        self.scale = float(scale)
        self.margin = int(margin)
        w = int(np.ceil((self.xmax - self.xmin) * scale)) + 2 * margin
        h = int(np.ceil((self.ymax - self.ymin) * scale)) + 2 * margin
        self.image = Image.new("RGB", (w, h), background)
        self.draw = ImageDraw.Draw(self.image)

    def pixels(self, xy) -> np.ndarray:
        """World points (..., 2) to pixel coordinates (..., 2) (image y grows downward)."""
        p = np.asarray(xy, dtype=np.float64)
        u = (p[..., 0] - self.xmin) * self.scale + self.margin
        v = (self.ymax - p[..., 1]) * self.scale + self.margin
        return np.stack([u, v], -1)

    def polyline(self, xy, color, width: int = 2) -> None:
        pts = self.pixels(xy)
        if len(pts) >= 2:
            self.draw.line([tuple(p) for p in pts], fill=color, width=width, joint="curve")

    def points(self, xy, color, radius: float = 1.0) -> None:
        """Dots; one ``point`` call per pixel when ``radius`` ≤ 1 (fast for clouds of thousands)."""
        pts = self.pixels(xy).reshape(-1, 2)
        if radius <= 1.0:
            self.draw.point([tuple(p) for p in np.rint(pts)], fill=color)
            return
        for u, v in pts:
            self.draw.ellipse((u - radius, v - radius, u + radius, v + radius), fill=color)

    def poses(self, xytheta, color, length: float = 0.3, width: int = 2) -> None:
        """Arrows for poses (..., 3): a line along the heading with a small head."""
        p = np.asarray(xytheta, dtype=np.float64).reshape(-1, 3)
        tip = p[:, :2] + length * np.stack([np.cos(p[:, 2]), np.sin(p[:, 2])], -1)
        for a, b, th in zip(p[:, :2], tip, p[:, 2]):
            self.polyline([a, b], color, width)
            for side in (2.5, -2.5):
                h = b + 0.35 * length * np.array([np.cos(th + side), np.sin(th + side)])
                self.polyline([b, h], color, width)

    def text(self, xy, message: str, color=(0, 0, 0)) -> None:
        u, v = self.pixels(xy)
        self.draw.text((u, v), message, fill=color)

    def grid(self, step: float = 1.0, color=(235, 235, 235)) -> None:
        for x in np.arange(np.ceil(self.xmin / step) * step, self.xmax + 1e-9, step):
            self.polyline([(x, self.ymin), (x, self.ymax)], color, 1)
        for y in np.arange(np.ceil(self.ymin / step) * step, self.ymax + 1e-9, step):
            self.polyline([(self.xmin, y), (self.xmax, y)], color, 1)

    def save(self, path) -> Path:
        """Write a PNG atomically (:func:`occmap.png.write_png`)."""
        return write_png(path, self.image)
