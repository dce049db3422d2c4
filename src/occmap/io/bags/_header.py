"""What every stamped message shares: its frame and its stamp."""

from __future__ import annotations


def stamp_seconds(stamp) -> float:
    """A ``builtin_interfaces/Time`` (ROS 1 ``time``, as rosbags decodes it) in float seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


def frame_name(frame_id: str) -> str:
    """A frame id without ROS 1's leading slash (``/laser`` → ``laser``), as tf2 strips it."""
    return frame_id.lstrip("/")
