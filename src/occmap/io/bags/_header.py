"""What the decoders of ``rosbags``' message objects share (PointCloud2's; the others read the
bytes, :mod:`.wire`): a message's stamp, and a clear error for a message whose definition lacks a
field the decoder reads."""

from __future__ import annotations

from contextlib import contextmanager

from ...errors import FormatError, OccmapError


def stamp_seconds(stamp) -> float:
    """A ``builtin_interfaces/Time`` (ROS 1 ``time``, as rosbags decodes it) in float seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


@contextmanager
def fields_of(where, msgtype: str):
    """Turn a missing field or a field of the wrong kind (a bag whose definition of ``msgtype`` is
    not ROS's) into a :class:`FormatError` naming ``where``."""
    try:
        yield
    except (AttributeError, TypeError, ValueError) as e:
        if isinstance(e, OccmapError):
            raise
        raise FormatError(where, f"not a {msgtype} as ROS defines it ({type(e).__name__}: {e})") from e
