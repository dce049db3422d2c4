"""Writing PNG pictures: every picture occmap saves goes through :func:`write_png`.

A picture is a Pillow image or a uint8 pixel array in image order — row 0 is the **top** of the
picture, so a map (row 0 = lowest y) is passed flipped, ``pixels[::-1]``: ``(H, W)`` gray,
``(H, W, 2)`` gray + alpha, ``(H, W, 3)`` RGB or ``(H, W, 4)`` RGBA. The file is written
atomically (:func:`occmap._files.write_atomic`): a crash leaves the old file or the new one.
Pillow is imported on the first call, so importing this module costs nothing.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from ._files import write_atomic
from .errors import InvalidArgumentError, ShapeError

__all__ = ["write_png"]


def write_png(path, picture) -> Path:
    """Write ``picture`` (a ``PIL.Image.Image`` or a uint8 array, see the module) as a PNG file at
    ``path``; returns the path."""
    from PIL import Image

    if not isinstance(picture, Image.Image):
        pixels = np.asarray(picture)
        if pixels.dtype != np.uint8:
            raise InvalidArgumentError(f"pixels must be a uint8 array, got dtype {pixels.dtype}")
        if not (pixels.ndim == 2 or (pixels.ndim == 3 and pixels.shape[2] in (2, 3, 4))) or 0 in pixels.shape:
            raise ShapeError(f"pixels must be (H, W), (H, W, 2), (H, W, 3) or (H, W, 4), got {pixels.shape}")
        picture = Image.fromarray(np.ascontiguousarray(pixels))
    buffer = io.BytesIO()
    picture.save(buffer, format="PNG")
    return write_atomic(path, buffer.getvalue())
