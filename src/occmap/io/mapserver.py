"""ROS ``map_server`` / ``map_saver`` map files: a small YAML file next to an image.

The pair is what ROS 1 ``map_server``/``map_saver`` and ROS 2 ``nav2_map_server`` read and write::

    image: map.pgm
    mode: trinary
    resolution: 0.05
    origin: [-10.0, -10.0, 0.0]
    negate: 0
    occupied_thresh: 0.65
    free_thresh: 0.196

Array convention (shared with ``nav_msgs/OccupancyGrid`` and the rest of occmap): ``occupancy`` is
an int8 array ``(H, W)``, ``occupancy[row, col]`` is cell ``(iy, ix)``, row 0 is the row at the
origin (lowest y); −1 unknown, 0 free … 100 occupied. The image stores the map the other way up:
its first (top) row is the map's highest-y row, so both directions flip vertically.

Saving (:func:`save_map`), trinary mode, as ``map_saver`` does:

* ``0 <= occ <= floor(free_thresh·100)`` → 254 (free; 0 … 19 with the default 0.196),
* ``occ >= ceil(occupied_thresh·100)`` → 0 (occupied; 65 … 100 with the default 0.65),
* everything else, unknown (−1) and values outside 0 … 100 included → 205.

  ROS 1's ``map_saver`` uses integer thresholds of its own (``--free 25 --occ 65`` in recent
  versions) and nav2 uses ``rint(free_thresh·100)`` (20 for 0.196); here the cut is derived from
  the very thresholds written into the YAML, so "free" in the file means the same thing as "free"
  when the file is read back (a cell of 20 % is not below 0.196, so it is not free).

With these values a saved map reads back exactly: 254 → p = 1/255 < free_thresh → 0,
0 → p = 1 > occupied_thresh → 100 and 205 → p = 50/255 = 0.19608 → −1 (which is why map_saver
writes the odd-looking ``free_thresh: 0.196``). :func:`save_map` therefore requires
``1/255 < free_thresh < 50/255 < occupied_thresh < 1``. Two other modes are offered:

* ``"raw"``: gray = occ for 0 … 100, 255 for unknown; reads back exactly (255 is −1 as a byte).
* ``"scale"``: gray = round(255·(100 − occ)/100), unknown cells fully transparent (so PNG only),
  as nav2 writes it; reading applies map_server's scale rule, so it does not read back exactly.

Loading (:func:`load_map`) follows ``map_server``'s image loader:

* colour images are averaged to gray over their channels (as map_server does: in trinary mode an
  alpha channel is averaged in with the colour channels — a map_server quirk kept for fidelity —
  in scale and raw mode it is left out of the average);
* ``p = (255 − gray)/255``, or ``gray/255`` with ``negate: 1``;
* trinary: ``p > occupied_thresh`` → 100, ``p < free_thresh`` → 0, else −1;
* scale: the same two ends; between them nav2_map_server's ``rint(100·(p − free)/(occupied −
  free))`` (ROS 1's map_server uses ``1 + 98·ratio`` instead, never 0 or 100 between the
  thresholds; occmap follows ROS 2), and −1 where the image has an alpha channel and the pixel's
  alpha is 0;
* raw: the gray value itself, reinterpreted as a signed byte (255 → −1); with ``negate: 1`` it is
  ``255 − gray`` first, as in ROS 1's loader. Colour pixels are averaged and truncated.

16-bit gray images are brought to 0 … 255 by dividing by 257.

The YAML file is read with PyYAML's safe parser (any YAML: flow ``[x, y, yaw]`` or block-style
lists, comments, quotes, a leading ``---``); numbers must be plain unquoted decimals (``0.05``,
``.196``, ``-1e3``), strings may be quoted. Unknown keys are ignored (as map_server does); a
repeated key is an error. Any problem raises :class:`~occmap.errors.FormatError` naming the file,
the line and the key.

Saving a pair is all-or-nothing for a reader of the pair: each file is written atomically
(:func:`occmap._files.write_atomic`: the old file or the new one, never a mix or half a file),
the image first, then the YAML, which ends with ``occmap_image_sha256:`` — the SHA-256 of the
image bytes it was written with. :func:`load_map` checks that digest when the key is there, so
a save killed between the two files (the new image beside the old YAML) fails to load with a
FormatError saying so, instead of loading at the wrong size or origin. YAML files without the key
(map_saver's, hand-written ones) load as before. A YAML path that would also be the image's path
(``map.pgm`` with ``image_format="pgm"``) is refused.
"""

from __future__ import annotations

import hashlib
import io
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import checks
from .._files import write_atomic
from ..errors import FormatError, InvalidArgumentError, ShapeError
from . import _limits
from ._compression import read_bytes

__all__ = ["MapFile", "load_map", "save_map"]

#: Pixel values map_saver writes in trinary mode.
FREE_PIXEL = 254
OCCUPIED_PIXEL = 0
UNKNOWN_PIXEL = 205

_MODES = ("trinary", "scale", "raw")
#: YAML key holding the SHA-256 of the image a pair was saved with (map_server ignores it).
_DIGEST_KEY = "occmap_image_sha256"
_IMAGE_FORMATS = {"pgm": "PPM", "png": "PNG", "bmp": "BMP"}


@dataclass(frozen=True, eq=False)
class MapFile:
    """A map read by :func:`load_map`.

    Attributes:
        occupancy: int8 array ``(H, W)`` in nav_msgs order (row 0 = lowest y; −1 unknown,
            0 free … 100 occupied; in raw mode the raw bytes).
        resolution: cell size in metres.
        origin: ``(x, y, yaw)`` of the outer corner of cell (0, 0), metres and radians.
        mode: ``"trinary"``, ``"scale"`` or ``"raw"``.
        negate: whether ``negate: 1`` was set (white = occupied).
        occupied_thresh, free_thresh: the thresholds from the YAML.
        image_path: the image file that was read (absolute, resolved against the YAML's folder).
        yaml_path: the YAML file that was read.
    """

    occupancy: np.ndarray
    resolution: float
    origin: tuple[float, float, float]
    mode: str
    negate: bool
    occupied_thresh: float
    free_thresh: float
    image_path: Path
    yaml_path: Path


# ----------------------------------------------------------------------------------------------
# saving


def _fmt_float(value: float) -> str:
    """Shortest text that reads back to the same float (``0.05``, ``-10.0``); −0 prints as 0.0."""
    return repr(float(value) + 0.0)


_BARE_STRING = re.compile(r"^[A-Za-z0-9_./+][A-Za-z0-9_./+ -]*(?<! )$")


def _yaml_string(text: str) -> str:
    """A YAML scalar for ``text``: bare when safe, otherwise double-quoted."""
    if _BARE_STRING.match(text) and _parse_number(text) is None and text.lower() not in (
        "true", "false", "yes", "no", "on", "off", "null", "~",
    ):
        return text
    escaped = text.replace("\\", "\\\\").replace('"', '\\"')
    return f'"{escaped}"'


def save_map(
    path_yaml,
    occupancy,
    resolution: float,
    origin,
    *,
    image_format: str = "pgm",
    mode: str = "trinary",
    occupied_thresh: float = 0.65,
    free_thresh: float = 0.196,
) -> Path:
    """Write ``occupancy`` as a map_saver YAML + image pair; return the image's path.

    Args:
        path_yaml: the YAML file to write (``…/name.yaml``); the image is written beside it as
            ``name.<image_format>`` and named in the YAML relative to it.
        occupancy: integer array ``(H, W)`` in nav_msgs convention (row 0 = lowest y;
            −1 unknown, 0 free … 100 occupied; other values count as unknown).
        resolution: cell size in metres (> 0).
        origin: ``(x, y)`` or ``(x, y, yaw)`` of the outer corner of cell (0, 0).
        image_format: ``"pgm"`` (binary P5, maxval 255, as map_saver), ``"png"`` or ``"bmp"``.
        mode: ``"trinary"`` (map_saver's 254/0/205), ``"raw"`` or ``"scale"`` (PNG only); see the
            module docstring for the pixel values.
        occupied_thresh, free_thresh: written to the YAML and used to classify the cells in
            trinary mode: ``occ >= ceil(occupied_thresh·100)`` occupied,
            ``0 <= occ <= floor(free_thresh·100)`` free. Trinary mode requires
            ``1/255 < free_thresh < 50/255 < occupied_thresh < 1`` so the file reads back to the
            same classification.

    Raises:
        ShapeError: ``occupancy`` is not a non-empty 2-D array.
        InvalidArgumentError: a bad resolution, origin, mode, format or threshold.
    """
    path_yaml = Path(path_yaml)
    occ = np.asarray(occupancy)
    if occ.ndim != 2 or occ.shape[0] == 0 or occ.shape[1] == 0:
        raise ShapeError(f"occupancy must be a non-empty (H, W) array, got shape {occ.shape}")
    if occ.dtype.kind not in "iu":
        raise InvalidArgumentError(f"occupancy must be an integer array, got dtype {occ.dtype}")
    occ = occ.astype(np.int64, copy=False)
    res = checks.resolution(resolution)
    origin_vals = [checks.finite("origin", v) for v in np.asarray(origin, dtype=object).ravel()]
    if len(origin_vals) == 2:
        origin_vals.append(0.0)
    if len(origin_vals) != 3:
        raise InvalidArgumentError(f"origin must be (x, y) or (x, y, yaw), got {origin!r}")
    if mode not in _MODES:
        raise InvalidArgumentError(f"mode must be one of {_MODES}, got {mode!r}")
    fmt = str(image_format).lower().lstrip(".")
    if fmt not in _IMAGE_FORMATS:
        raise InvalidArgumentError(
            f"image_format must be one of {tuple(_IMAGE_FORMATS)}, got {image_format!r}"
        )
    occ_t = checks.finite("occupied_thresh", occupied_thresh)
    free_t = checks.finite("free_thresh", free_thresh)
    if not (0.0 <= free_t < occ_t <= 1.0):
        raise InvalidArgumentError(
            f"thresholds must satisfy 0 <= free_thresh < occupied_thresh <= 1, "
            f"got free_thresh={free_thresh!r}, occupied_thresh={occupied_thresh!r}"
        )
    if mode == "trinary" and not (1 / 255 < free_t < 50 / 255 < occ_t < 1.0):
        raise InvalidArgumentError(
            "trinary maps need 1/255 < free_thresh < 50/255 (0.19608) < occupied_thresh < 1 so "
            "that the pixels 254/205/0 read back as free/unknown/occupied; got "
            f"free_thresh={free_thresh!r}, occupied_thresh={occupied_thresh!r}"
        )
    if mode == "scale" and fmt != "png":
        raise InvalidArgumentError("scale mode marks unknown cells by transparency: use PNG")

    flipped = occ[::-1]  # image row 0 = the map's top (highest-y) row
    known = (flipped >= 0) & (flipped <= 100)
    alpha = None
    if mode == "trinary":
        free_max = math.floor(free_t * 100 + 1e-9)
        occ_min = math.ceil(occ_t * 100 - 1e-9)
        gray = np.full(flipped.shape, UNKNOWN_PIXEL, dtype=np.uint8)
        gray[known & (flipped <= free_max)] = FREE_PIXEL
        gray[known & (flipped >= occ_min)] = OCCUPIED_PIXEL
    elif mode == "raw":
        gray = np.where(known, flipped, 255).astype(np.uint8)
    else:  # scale
        gray = np.where(known, np.rint(255.0 * (100 - flipped) / 100.0), 128).astype(np.uint8)
        alpha = np.where(known, 255, 0).astype(np.uint8)

    image_path = path_yaml.with_name(path_yaml.stem + "." + fmt)
    if os.path.realpath(image_path) == os.path.realpath(path_yaml):
        raise InvalidArgumentError(
            f"the map's YAML file {str(path_yaml)!r} would be its own image: name it .yaml"
        )
    height, width = gray.shape
    if fmt == "pgm":
        data = b"P5\n%d %d\n255\n" % (width, height) + np.ascontiguousarray(gray).tobytes()
    else:
        from PIL import Image

        if alpha is not None:
            picture = Image.fromarray(np.stack([gray, alpha], axis=-1))
        else:
            picture = Image.fromarray(np.ascontiguousarray(gray))
        buffer = io.BytesIO()
        picture.save(buffer, format=_IMAGE_FORMATS[fmt])
        data = buffer.getvalue()

    text = (
        f"image: {_yaml_string(image_path.name)}\n"
        f"mode: {mode}\n"
        f"resolution: {_fmt_float(res)}\n"
        f"origin: [{', '.join(_fmt_float(v) for v in origin_vals)}]\n"
        f"negate: 0\n"
        f"occupied_thresh: {_fmt_float(occ_t)}\n"
        f"free_thresh: {_fmt_float(free_t)}\n"
        f"# the image this file was written with; occmap checks it on loading\n"
        f"{_DIGEST_KEY}: {hashlib.sha256(data).hexdigest()}\n"
    )
    write_atomic(image_path, data)  # the image first: the YAML names it and holds its digest
    write_atomic(path_yaml, text.encode("utf-8"))
    return image_path


# ----------------------------------------------------------------------------------------------
# the YAML file

_NUMBER = re.compile(r"^[-+]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][-+]?\d+)?$")


def _parse_number(text: str) -> float | None:
    """A plain decimal number as float (thousands of digits give inf), or None."""
    return float(text) if _NUMBER.match(text) else None


def _line(node) -> int:
    return node.start_mark.line + 1


def _parse_yaml(path: Path, text: str) -> dict:
    """The top-level mapping of a map YAML file as ``{key: node}`` (PyYAML's safe composer: any
    YAML, flow or block style, anchors resolved; no Python objects are built). Keys must be
    plain strings and not repeat."""
    import yaml

    try:
        root = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None) or getattr(error, "context_mark", None)
        problem = getattr(error, "problem", None) or str(error)
        raise FormatError(
            path, f"not valid YAML: {problem} (a map file holds 'key: value' lines)",
            line=None if mark is None else mark.line + 1,
        ) from None
    if root is None:
        raise FormatError(path, "empty map file: required key 'image' is missing")
    if not isinstance(root, yaml.MappingNode):
        raise FormatError(path, "a map file must be a mapping of 'key: value' lines", line=_line(root))
    fields: dict = {}
    for key, value in root.value:
        if not isinstance(key, yaml.ScalarNode):
            raise FormatError(path, "keys must be plain names", line=_line(key))
        if key.value in fields:
            first = _line(fields[key.value])
            raise FormatError(path, f"key {key.value!r} repeated (first on line {first})", line=_line(key))
        fields[key.value] = value
    return fields


# ----------------------------------------------------------------------------------------------
# typed access to the parsed YAML


def _require(path, fields, key):
    if key not in fields:
        raise FormatError(path, f"required key {key!r} is missing")
    return fields[key]


def _scalar(path, key, node, what: str):
    import yaml

    if not isinstance(node, yaml.ScalarNode):
        kind = "a list" if isinstance(node, yaml.SequenceNode) else "a mapping"
        raise FormatError(path, f"{key} must be {what}, got {kind}", line=_line(node))
    if node.style is None and node.value in ("", "~", "null", "Null", "NULL"):
        raise FormatError(path, f"key {key!r} has no value", line=_line(node))
    return node


def _as_number(path, key, node) -> float:
    """An unquoted decimal number (``0.05``, ``-10``, ``.196``, ``1e-3``), as map_server reads it."""
    node = _scalar(path, key, node, "a number")
    number = _parse_number(node.value) if node.style is None else None
    if number is None:
        raise FormatError(path, f"{key} must be a number, got {node.value[:40]!r}", line=_line(node))
    return number


def _as_string(path, key, node) -> str:
    return _scalar(path, key, node, "a string").value


def load_map(path_yaml) -> MapFile:
    """Read a map_server YAML file and its image; see the module docstring for the rules.

    Raises:
        FormatError: the YAML or the image is missing or unreadable, the YAML is not valid,
            a required key (image, resolution, origin, occupied_thresh, free_thresh) is missing,
            a value is out of range (resolution <= 0, thresholds outside [0, 1] or free_thresh
            >= occupied_thresh, unknown mode, negate not 0/1), the image is larger than
            :func:`occmap.io.read_limits` allows, or it is not the image the YAML was saved
            with (``occmap_image_sha256``). The message names the file and, where there is
            one, the line.
    """
    path_yaml = Path(path_yaml)
    raw = read_bytes(path_yaml)
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        line = raw[: error.start].count(b"\n") + 1
        raise FormatError(path_yaml, "not UTF-8 text", line=line) from None
    fields = _parse_yaml(path_yaml, text)

    image_node = _require(path_yaml, fields, "image")
    image_name = _as_string(path_yaml, "image", image_node)
    if not image_name:
        raise FormatError(path_yaml, "image is empty", line=_line(image_node))

    res_node = _require(path_yaml, fields, "resolution")
    resolution = _as_number(path_yaml, "resolution", res_node)
    if not (math.isfinite(resolution) and resolution > 0):
        raise FormatError(path_yaml, f"resolution must be > 0, got {resolution!r}", line=_line(res_node))

    origin_node = _require(path_yaml, fields, "origin")
    origin_line = _line(origin_node)
    if not isinstance(origin_node.value, list) or len(origin_node.value) != 3:
        raise FormatError(path_yaml, "origin must be a list [x, y, yaw]", line=origin_line)
    origin = tuple(_as_number(path_yaml, "origin", v) for v in origin_node.value)
    if not all(math.isfinite(v) for v in origin):
        raise FormatError(path_yaml, "origin must be finite", line=origin_line)

    thresholds = {}
    for key in ("occupied_thresh", "free_thresh"):
        node = _require(path_yaml, fields, key)
        number = _as_number(path_yaml, key, node)
        if not (0.0 <= number <= 1.0):
            raise FormatError(path_yaml, f"{key} must lie in [0, 1], got {number!r}", line=_line(node))
        thresholds[key] = number
    occ_t, free_t = thresholds["occupied_thresh"], thresholds["free_thresh"]
    if free_t >= occ_t:
        raise FormatError(
            path_yaml,
            f"free_thresh ({free_t!r}) must be below occupied_thresh ({occ_t!r})",
            line=_line(fields["free_thresh"]),
        )

    mode = "trinary"
    if "mode" in fields:
        mode = _as_string(path_yaml, "mode", fields["mode"])
        if mode not in _MODES:
            raise FormatError(path_yaml, f"mode must be one of {_MODES}, got {mode[:40]!r}", line=_line(fields["mode"]))

    negate = False
    if "negate" in fields:
        node = _scalar(path_yaml, "negate", fields["negate"], "0 or 1")
        text_value = node.value.lower() if node.style is None else None
        if text_value not in ("0", "false", "1", "true"):
            raise FormatError(path_yaml, f"negate must be 0 or 1, got {node.value[:40]!r}", line=_line(node))
        negate = text_value in ("1", "true")

    digest = None
    if _DIGEST_KEY in fields:
        digest = _as_string(path_yaml, _DIGEST_KEY, fields[_DIGEST_KEY]).lower()

    image_path = Path(image_name)
    if not image_path.is_absolute():
        image_path = path_yaml.parent / image_path
    if not image_path.is_file():
        raise FormatError(
            path_yaml, f"image file {str(image_path)!r} not found", line=_line(image_node)
        )
    data = read_bytes(image_path)
    if digest is not None and hashlib.sha256(data).hexdigest() != digest:
        raise FormatError(
            path_yaml,
            f"{image_path.name} is not the image this file was saved with ({_DIGEST_KEY} differs): "
            "the pair comes from two different saves (one was interrupted, or a file was replaced)",
            line=_line(fields[_DIGEST_KEY]),
        )
    channels = _read_image(image_path, data)
    occupancy = _classify(channels, mode=mode, negate=negate, occ_t=occ_t, free_t=free_t)
    return MapFile(
        occupancy=np.ascontiguousarray(occupancy[::-1]),
        resolution=resolution,
        origin=origin,  # type: ignore[arg-type]
        mode=mode,
        negate=negate,
        occupied_thresh=occ_t,
        free_thresh=free_t,
        image_path=image_path,
        yaml_path=path_yaml,
    )


# ----------------------------------------------------------------------------------------------
# the image


def _read_image(path: Path, data: bytes) -> tuple[np.ndarray, np.ndarray | None]:
    """Return ``(colour, alpha)`` of the image file ``path`` whose bytes are ``data``: float64
    ``(H, W, C)`` colour channels on 0 … 255 and the alpha channel ``(H, W)`` (or None), both top
    row first as stored. The header's width × height is checked against the read limits
    (:mod:`occmap.io._limits`, one unit a pixel) before any pixel is decoded; Pillow refuses
    more than 2 × ``PIL.Image.MAX_IMAGE_PIXELS`` (179 M pixels by default) itself."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(io.BytesIO(data)) as picture:
            width, height = picture.size
            _limits.current().check(path, f"a {width} × {height} image", width * height, len(data), "pixels")
            picture.load()
            mode = picture.mode
            if mode == "P":
                picture = picture.convert("RGBA" if "transparency" in picture.info else "RGB")
            elif mode == "PA":
                picture = picture.convert("RGBA")
            elif mode == "1":
                picture = picture.convert("L")
            elif mode in ("RGBX", "CMYK", "YCbCr", "LAB", "HSV"):
                picture = picture.convert("RGB")
            elif mode in ("La", "RGBa"):
                picture = picture.convert(mode[:-1] + "A")
            mode = picture.mode
            data = np.asarray(picture)
    except FormatError:
        raise
    except Image.DecompressionBombError as error:  # Pillow's own limit, met in Image.open
        raise FormatError(path, f"image too large: {error}") from None
    except (UnidentifiedImageError, OSError, ValueError, SyntaxError) as error:
        raise FormatError(path, f"cannot read the map image: {error}") from None
    if mode.startswith("I;16") or mode == "I":
        if data.size and (data.min() < 0 or data.max() > 65535):
            raise FormatError(path, f"unsupported {mode} image values outside 0 … 65535")
        data = data.astype(np.float64) / 257.0
        mode = "L"
    elif mode not in ("L", "LA", "RGB", "RGBA"):
        raise FormatError(path, f"unsupported image mode {mode!r}")
    data = np.asarray(data, dtype=np.float64)
    if data.ndim == 2:
        data = data[:, :, None]
    if mode in ("LA", "RGBA"):
        return data, data[:, :, -1]
    return data, None


def _classify(channels, *, mode: str, negate: bool, occ_t: float, free_t: float) -> np.ndarray:
    """map_server's pixel rule; returns int8 ``(H, W)`` in image order (top row first)."""
    data, alpha = channels
    if mode == "trinary" or alpha is None:
        gray = data.mean(axis=-1)  # map_server averages alpha in, in trinary mode
    else:
        gray = data[:, :, :-1].mean(axis=-1)
    if negate:
        gray = 255.0 - gray
    if mode == "raw":
        return np.floor(gray).astype(np.uint8).view(np.int8)
    p = (255.0 - gray) / 255.0
    out = np.full(gray.shape, -1, dtype=np.int8)
    if mode == "scale":
        ratio = (p - free_t) / (occ_t - free_t)
        out[:] = np.clip(np.rint(100.0 * ratio), 0, 100).astype(np.int8)  # nav2's rule
    out[p > occ_t] = 100
    out[p < free_t] = 0
    if mode == "scale" and alpha is not None:
        out[alpha == 0] = -1
    return out
