"""Poses in bags: ``tf2_msgs/TFMessage`` (``/tf``, ``/tf_static``) into a
:class:`~occmap.geometry.frames.FrameTree`, and ``nav_msgs/Odometry`` as stamped poses.

ROS stores a rotation as the quaternion ``(x, y, z, w)``; occmap's are ``(w, x, y, z)``
(:func:`~occmap.geometry.quaternion.quat_from_xyzw` reorders). Quaternions are normalised, as tf2
does, since recorded ones are rarely of unit norm to the last bit; a zero or non-finite one, or a
non-finite translation, raises :class:`~occmap.errors.FormatError` naming the bag, the topic and
the message. Frame names lose ROS 1's leading slash. A ``TransformStamped`` in ROS maps child
coordinates into its header's frame: it is ``T_parent_child`` in occmap's terms.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ...errors import FormatError, TransformError
from ...geometry.frames import FrameTree
from ...geometry.quaternion import quat_from_xyzw
from ...geometry.se3 import SE3
from ._header import fields_of, frame_name, stamp_seconds

__all__ = ["Odometry", "TF_TYPES", "decode_odometry", "read_frame_tree", "read_odometry", "ros_poses"]

# tf2's message, and ROS 1's older tf/tfMessage with the same fields
TF_TYPES = ("tf2_msgs/msg/TFMessage", "tf/msg/tfMessage")
ODOMETRY = "nav_msgs/msg/Odometry"


class Odometry(NamedTuple):
    """An odometry topic: ``poses[i]`` (``T_frame_child``) holds at ``stamps[i]`` seconds."""

    stamps: np.ndarray
    poses: SE3
    frame_id: str
    child_frame_id: str


def ros_poses(translations, quaternions_xyzw, where: str = "pose") -> SE3:
    """Rigid transforms (N,) from translations (N, 3) and ROS quaternions ``(x, y, z, w)`` (N, 4),
    normalised. Raises :class:`FormatError` (naming ``where`` and the index) for a non-finite
    value or a zero quaternion."""
    t = np.asarray(translations, dtype=np.float64).reshape(-1, 3)
    q = quat_from_xyzw(np.asarray(quaternions_xyzw, dtype=np.float64).reshape(-1, 4))
    norms = np.linalg.norm(q, axis=1)
    bad = ~(np.isfinite(t).all(axis=1) & np.isfinite(norms) & (norms > 0))
    if bad.any():
        i = int(np.argmax(bad))
        raise FormatError(where, f"transform {i}: translation {t[i].tolist()}, quaternion (x, y, z, w) "
                          f"{np.asarray(quaternions_xyzw, dtype=np.float64).reshape(-1, 4)[i].tolist()} "
                          "is not a rigid transform (non-finite, or a zero quaternion)")
    return SE3.from_quat(q / norms[:, None], t)


def decode_odometry(msg, where: str = "Odometry") -> tuple[float, SE3]:
    """``(stamp in seconds, pose)`` of one ``nav_msgs/Odometry``; the pose is
    ``T_{header.frame_id}_{child_frame_id}`` of shape ()."""
    with fields_of(where, "nav_msgs/Odometry"):
        p, o = msg.pose.pose.position, msg.pose.pose.orientation
        t, q, stamp = [p.x, p.y, p.z], [o.x, o.y, o.z, o.w], stamp_seconds(msg.header.stamp)
    return stamp, SE3(ros_poses(t, q, where).matrix[0])


def read_odometry(bag, topic: str) -> Odometry:
    """Every message of an odometry topic of ``bag`` (an open :class:`~occmap.io.bags.Bag`), in the
    order recorded. Raises :class:`FormatError` when the frames change between messages."""
    stamps, trans, quats, frames = [], [], [], None
    for m in bag.messages(topic, msgtype=ODOMETRY):
        msg = m.msg
        with fields_of(f"{bag.path}: topic {topic!r} at {m.time:.9f} s", "nav_msgs/Odometry"):
            pair = (frame_name(msg.header.frame_id), frame_name(msg.child_frame_id))
            p, o = msg.pose.pose.position, msg.pose.pose.orientation
            stamps.append(stamp_seconds(msg.header.stamp))
            trans.append((p.x, p.y, p.z))
            quats.append((o.x, o.y, o.z, o.w))
        if frames is None:
            frames = pair
        elif pair != frames:
            raise FormatError(bag.path, f"topic {topic!r}: odometry of {pair[0]!r} -> {pair[1]!r} at "
                              f"{m.time:.9f} s, earlier messages were {frames[0]!r} -> {frames[1]!r}")
    if frames is None:
        return Odometry(np.zeros(0), SE3.identity(0), "", "")
    return Odometry(np.array(stamps), ros_poses(trans, quats, f"{bag.path}: topic {topic!r}"), *frames)


def read_frame_tree(bag, topics=None) -> FrameTree:
    """Every transform on the tf topics of ``bag`` (an open :class:`~occmap.io.bags.Bag`) in one
    :class:`FrameTree` that keeps the whole bag's history.

    ``topics`` defaults to whichever of ``/tf`` and ``/tf_static`` the bag has; a topic whose name
    ends in ``tf_static`` holds static links (valid at all times, the last one of a link wins).
    Dynamic samples are stored at their header stamps, so lookups interpolate between them and
    raise :class:`~occmap.errors.ExtrapolationError` outside them. A link both static and dynamic
    ends up dynamic. Raises :class:`FormatError` for a transform that is not rigid or links that
    would form a loop.
    """
    if topics is None:
        topics = [t for t in ("/tf", "/tf_static") if t in bag.topics]
    for t in topics:
        if t in bag.topics and bag.topics[t].msgtype not in TF_TYPES:
            raise FormatError(bag.path, f"topic {t!r} holds {bag.topics[t].msgtype}, not {TF_TYPES[0]}")
    links: dict[tuple[str, str, bool], tuple[list, list, list]] = {}
    for m in bag.messages(topics):
        static = m.topic.endswith("tf_static")
        with fields_of(f"{bag.path}: topic {m.topic!r} at {m.time:.9f} s", "tf2_msgs/TFMessage"):
            for ts in m.msg.transforms:
                key = (frame_name(ts.header.frame_id), frame_name(ts.child_frame_id), static)
                stamps, trans, quats = links.setdefault(key, ([], [], []))
                tr, q = ts.transform.translation, ts.transform.rotation
                stamps.append(stamp_seconds(ts.header.stamp))
                trans.append((tr.x, tr.y, tr.z))
                quats.append((q.x, q.y, q.z, q.w))
    span = 0.0 if bag.start is None else bag.end - bag.start
    tree = FrameTree(cache_time=max(10.0, span + 1.0))
    for (parent, child, static), (stamps, trans, quats) in sorted(links.items(), key=lambda kv: not kv[0][2]):
        poses = ros_poses(trans, quats, f"{bag.path}: tf link {parent!r} -> {child!r}")
        try:
            if static:
                tree.set_transform(parent, child, SE3(poses.matrix[-1]), static=True)
            else:
                tree.set_transform(parent, child, poses, np.array(stamps))
        except TransformError as e:
            raise FormatError(bag.path, f"tf link {parent!r} -> {child!r}: {e}") from e
    return tree
