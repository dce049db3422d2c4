"""``sensor_msgs/LaserScan`` → :class:`~occmap.scan.LaserScan` in the sensor's own frame.

Beam ``i`` points at ``angle_min + i * angle_increment`` (radians, counter-clockwise about the
sensor's z axis); ``range_max`` becomes ``LaserScan.max_range``. Readings follow REP 117 as
occmap's maps read them: ``+inf`` (no return) and readings at or beyond ``range_max`` clear the
beam up to the maximum range and mark nothing; NaN (a failed reading) and ``-inf`` (too close)
are kept for the map to drop and count; a finite reading below ``range_min`` is invalid by REP
117 and becomes NaN, so it is dropped as well. ``intensities`` are not kept.

The message does not say where the sensor was: the scan's ``pose`` is ``(0, 0, 0)``, the sensor
frame itself, and :class:`ScanMessage` carries the frame name and the stamp that place it in the
world through tf.
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import NamedTuple

import numpy as np

from ...errors import FormatError
from ...scan import LaserScan
from .wire import Wire

__all__ = ["ScanMessage", "decode_laser_scan"]


class ScanMessage(NamedTuple):
    """A decoded LaserScan: the scan (pose zero: the sensor frame) and the sensor's frame."""

    scan: LaserScan
    frame_id: str


def decode_laser_scan(raw, encoding: str, where: str = "LaserScan") -> ScanMessage:
    """Decode a ``sensor_msgs/LaserScan`` from its serialised bytes (``raw``, e.g.
    :attr:`Message.raw <occmap.io.bags.Message>`) in ``encoding`` ``"ros1"`` or ``"cdr"`` (see
    :mod:`.wire`). Ranges and angles are float64; ``stamp`` is the header stamp in seconds.
    ``where`` names the message in errors.

    Raises :class:`~occmap.errors.FormatError` for a message shorter than its fields, a
    non-finite or non-positive ``range_max``, or non-finite ``angle_min`` / ``angle_increment``.
    """
    w = Wire(raw, encoding, where)
    stamp, frame = w.header()
    start, _, step, _, _, lowest, max_range = w.values("7f", "angle_min..range_max")
    ranges = w.array("f4", "ranges").astype(np.float64)
    w.skip_array(4, "intensities")  # not kept; read so that a truncated message is told
    if not (math.isfinite(max_range) and max_range > 0):
        raise FormatError(where, f"range_max is {max_range}, not a positive finite number of metres")
    if not (math.isfinite(start) and math.isfinite(step)):
        raise FormatError(where, f"angle_min {start} and angle_increment {step} must be finite")
    low = ranges < lowest
    if np.count_nonzero(low):
        ranges[low & np.isfinite(ranges)] = np.nan
    return ScanMessage(LaserScan(np.zeros(3), ranges, beam_angles(start, step, len(ranges)), max_range, stamp), frame)


@lru_cache(maxsize=16)
def beam_angles(start: float, step: float, n: int) -> np.ndarray:
    """``start + i * step`` for the ``n`` beams, read-only: one array for every scan of a sensor
    (which :func:`~occmap.scan.stack_scans` then recognises as shared without comparing)."""
    angles = start + step * np.arange(n, dtype=np.float64)
    angles.setflags(write=False)
    return angles
