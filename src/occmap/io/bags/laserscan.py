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

A sensor's messages share one layout (the same frame, beam count and size): many of them are
decoded at once (:func:`decode_laser_scans`) as the rows of one array, so a stream of scans costs
no Python per message beyond collecting its bytes.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Callable, NamedTuple

import numpy as np

from ...errors import FormatError
from ...scan import LaserScan, ScanStack, concat_stacks
from .records import Raws
from .wire import Wire, by_layout, column, stamps

__all__ = ["ScanMessage", "ScanMessages", "decode_laser_scan", "decode_laser_scans"]


class ScanMessage(NamedTuple):
    """A decoded LaserScan: the scan (pose zero: the sensor frame) and the sensor's frame."""

    scan: LaserScan
    frame_id: str


class ScanMessages(NamedTuple):
    """Decoded LaserScans: the scans as a :class:`~occmap.scan.ScanStack` (poses zero), each
    scan's beam count (rows are NaN-padded to the largest) and each scan's frame."""

    stack: ScanStack
    beams: np.ndarray
    frames: list[str]


def decode_laser_scan(raw, encoding: str, where: str = "LaserScan") -> ScanMessage:
    """Decode a ``sensor_msgs/LaserScan`` from its serialised bytes (``raw``, e.g.
    :attr:`Message.raw <occmap.io.bags.Message>`) in ``encoding`` ``"ros1"`` or ``"cdr"`` (see
    :mod:`.wire`). Ranges and angles are float64; ``stamp`` is the header stamp in seconds.
    ``where`` names the message in errors.

    Raises :class:`~occmap.errors.FormatError` for a message shorter than its fields, a
    non-finite or non-positive ``range_max``, or non-finite ``angle_min`` / ``angle_increment``.
    """
    stack, beams, frames = decode_laser_scans([raw], encoding, lambda i: where)
    return ScanMessage(LaserScan(np.zeros(3), stack.ranges[0], stack.angles, float(stack.max_ranges[0]),
                                 float(stack.stamps[0])), frames[0])


def decode_laser_scans(raws, encoding: str, where: Callable[[int], str] = lambda i: f"LaserScan {i}") -> ScanMessages:
    """Decode the LaserScans ``raws`` (a sequence of serialised messages, as for
    :func:`decode_laser_scan`), those of one layout together; ``where(i)`` names message ``i`` in
    errors, which are :func:`decode_laser_scan`'s."""
    parts, order = [], []
    for group, layout, alike in by_layout(raws, lambda i: _layout(raws[i], encoding, where(i))):
        parts.append(_decode_alike(layout, alike, lambda j, group=group: where(int(group[j]))))
        order.append(group)
    if len(parts) == 1:
        return parts[0]
    if not parts:
        return ScanMessages(concat_stacks([]), np.zeros(0, np.intp), [])
    back = np.argsort(np.concatenate(order), kind="stable")
    frames = [f for p in parts for f in p.frames]
    return ScanMessages(concat_stacks([p.stack for p in parts]).take(back),
                        np.concatenate([p.beams for p in parts])[back], [frames[i] for i in back])


def _decode_alike(layout: _Layout, raws: Raws, where) -> ScanMessages:
    """The scans of ``raws``: messages of ``layout``."""
    o, n = layout.order, layout.beams
    count = len(raws)
    values = column(raws, layout.values_at, o + "f4", 7)
    start, step, lowest, max_range = (values[:, c].copy() for c in (0, 2, 5, 6))
    bad = ~(np.isfinite(max_range) & (max_range > 0))
    if bad.any():
        i = int(np.argmax(bad))
        raise FormatError(where(i), f"range_max is {max_range[i]}, not a positive finite number of metres")
    bad = ~(np.isfinite(start) & np.isfinite(step))
    if bad.any():
        i = int(np.argmax(bad))
        raise FormatError(where(i), f"angle_min {start[i]} and angle_increment {step[i]} must be finite")
    ranges = column(raws, layout.ranges_at, o + "f4", n)
    low = ranges < lowest[:, None]
    if low.any():
        ranges[low & np.isfinite(ranges)] = np.nan
    if (start == start[0]).all() and (step == step[0]).all():
        angles = beam_angles(float(start[0]), float(step[0]), n)
    else:
        angles = start[:, None] + step[:, None] * np.arange(n, dtype=np.float64)
    stack = ScanStack(np.zeros((count, 3)), ranges, angles, max_range, stamps(raws, layout.stamp_at, o))
    return ScanMessages(stack, np.full(count, n, np.intp), [layout.frame] * count)


class _Layout(NamedTuple):
    """Where a LaserScan's fields sit in its bytes, read from one message: the messages of the
    same size whose frame, counts (and CDR byte order) have the same bytes sit alike."""

    size: int
    order: str  # "<" or ">"
    stamp_at: int
    frame: str
    same: tuple  # (start, stop) byte spans every message of this layout shares
    values_at: int  # angle_min .. range_max, 7 float32
    ranges_at: int
    beams: int


def _layout(raw, encoding: str, where: str) -> _Layout:
    w = Wire(raw, encoding, where)
    stamp_at, frame = w.header_at()
    frame_span = (stamp_at + 8, w.pos)
    w.values("7f", "angle_min..range_max")
    values_at = w.pos - 28
    ranges = w.array("f4", "ranges")
    ranges_at = w.pos - ranges.nbytes
    intensities_at = w.pos
    w.skip_array(4, "intensities")  # not kept; read so that a truncated message is told
    same = (frame_span, (ranges_at - 4, ranges_at), (intensities_at, intensities_at + 4)) + (((0, 2),) if w.cdr else ())
    return _Layout(len(raw), w.order, stamp_at, frame, same, values_at, ranges_at,
                   len(ranges))


@lru_cache(maxsize=16)
def beam_angles(start: float, step: float, n: int) -> np.ndarray:
    """``start + i * step`` for the ``n`` beams, read-only: one array for every scan of a sensor
    (which :func:`~occmap.scan.stack_scans` then recognises as shared without comparing)."""
    angles = start + step * np.arange(n, dtype=np.float64)
    angles.setflags(write=False)
    return angles
