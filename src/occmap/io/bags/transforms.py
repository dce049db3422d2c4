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
from .bag import Where
from .records import Raws
from .definitions import TF_TYPES
from .wire import Wire, by_layout, column, frame_name, stamps

__all__ = ["Odometry", "TF_TYPES", "TransformFeed", "TransformsMessage", "decode_odometry", "decode_tf_message",
           "read_frame_tree", "read_odometry", "ros_poses"]

ODOMETRY = "nav_msgs/msg/Odometry"
# The fewest bytes a TransformStamped takes (stamp, two empty strings, seven float64), so that a
# corrupt count is caught before anything is allocated for it.
_TRANSFORM_BYTES = 8 + 4 + 4 + 7 * 8
# Odometry after its pose: the pose covariance, the twist and its covariance, 78 float64
_ODOMETRY_TAIL = (36 + 6 + 36) * 8


class TransformsMessage(NamedTuple):
    """A decoded TFMessage: transform ``i`` is ``T_{parents[i]}_{children[i]}`` at ``stamps[i]``
    seconds, by its translation (N, 3) in metres and its ROS quaternion ``(x, y, z, w)`` (N, 4)."""

    parents: list[str]
    children: list[str]
    stamps: np.ndarray
    translations: np.ndarray
    quaternions_xyzw: np.ndarray


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


def decode_tf_message(raw, encoding: str, where: str = "TFMessage") -> TransformsMessage:
    """Decode a ``tf2_msgs/TFMessage`` (or ROS 1's ``tf/tfMessage``) from its serialised bytes
    in ``encoding`` ``"ros1"`` or ``"cdr"`` (see :mod:`.wire`). ``where`` names the message in
    errors; the quaternions are as recorded (:func:`ros_poses` normalises them)."""
    layout = _tf_layout(raw, encoding, where)
    stamps, values = _tf_samples(layout, Raws.of([raw]))
    values = values.reshape(-1, 7)
    return TransformsMessage([p for p, _ in layout.links], [c for _, c in layout.links], stamps.reshape(-1),
                             values[:, :3], values[:, 3:])


def _tf_samples(layout: _TFLayout, raws: Raws) -> tuple[np.ndarray, np.ndarray]:
    """Stamps (messages, transforms) in seconds and ``(x, y, z, qx, qy, qz, qw)`` (messages,
    transforms, 7) of the messages ``raws`` of ``layout``."""
    o, count = layout.order, len(raws)
    times = np.empty((count, len(layout.links)))
    values = np.empty((count, len(layout.links), 7))
    for t in range(len(layout.links)):
        times[:, t] = stamps(raws, layout.stamps_at[t], o)
        values[:, t] = column(raws, layout.values_at[t], o + "f8", 7)
    return times, values


class _TFLayout(NamedTuple):
    """Where a TFMessage's fields sit in its bytes, read from one message (see :func:`.wire.by_layout`)."""

    size: int
    order: str
    same: tuple
    links: list  # (parent, child) of each transform
    stamps_at: list
    values_at: list  # translation and rotation, 7 float64


def _tf_layout(raw, encoding: str, where) -> _TFLayout:
    w = Wire(raw, encoding, where)
    same = [(w.pos, w.pos + 4)] + ([(0, 2)] if w.cdr else [])
    links, stamps_at, values_at = [], [], []
    for i in range(w.count("transforms", _TRANSFORM_BYTES)):
        field = f"transforms[{i}]"
        stamp_at, parent = w.header_at(field + ".header")
        child = frame_name(w.string(field, ".child_frame_id"))
        same.append((stamp_at + 8, w.pos))  # both frames
        w.values("7d", field, ".transform")
        links.append((parent, child))
        stamps_at.append(stamp_at)
        values_at.append(w.pos - 56)
    return _TFLayout(len(raw), w.order, tuple(same), links, stamps_at, values_at)


def _odometry(raw, encoding: str, where: str) -> tuple[float, str, str, tuple]:
    """Stamp, frame, child frame and pose ``(x, y, z, qx, qy, qz, qw)`` of an Odometry."""
    w = Wire(raw, encoding, where)
    stamp, frame = w.header()
    child = frame_name(w.string("child_frame_id"))
    pose = w.values("7d", "pose.pose")
    w.skip(_ODOMETRY_TAIL, 8, "pose.covariance..twist.covariance")
    return stamp, frame, child, pose


def decode_odometry(raw, encoding: str, where: str = "Odometry") -> tuple[float, SE3]:
    """``(stamp in seconds, pose)`` of one ``nav_msgs/Odometry`` from its serialised bytes in
    ``encoding`` ``"ros1"`` or ``"cdr"``; the pose is ``T_{header.frame_id}_{child_frame_id}`` of
    shape ()."""
    stamp, _, _, pose = _odometry(raw, encoding, where)
    return stamp, SE3(ros_poses(pose[:3], pose[3:], where).matrix[0])


def read_odometry(bag, topic: str) -> Odometry:
    """Every message of an odometry topic of ``bag`` (an open :class:`~occmap.io.bags.Bag`), in the
    order recorded. Raises :class:`FormatError` when the frames change between messages."""
    stamps, poses, frames = [], [], None
    messages = bag.messages(topic, msgtype=ODOMETRY)
    bag.require_standard(topic)
    for k, m in enumerate(messages):
        stamp, *pair, pose = _odometry(m.raw, m.encoding, Where(bag.path, topic, k, m.time))
        frames = _same_frames(bag.path, topic, m.time, frames, pair)
        stamps.append(stamp)
        poses.append(pose)
    if frames is None:
        return Odometry(np.zeros(0), SE3.identity(0), "", "")
    poses = np.array(poses)
    return Odometry(np.array(stamps), ros_poses(poses[:, :3], poses[:, 3:], f"{bag.path}: topic {topic!r}"), *frames)


def _same_frames(path, topic: str, time: float, frames, pair):
    """The frames ``(frame_id, child_frame_id)`` of an odometry topic: ``pair`` for its first
    message (``frames`` None), else ``frames``, which ``pair`` must equal (:class:`FormatError`)."""
    if frames is not None and pair != frames:
        raise FormatError(path, f"topic {topic!r}: odometry of {pair[0]!r} -> {pair[1]!r} at {time:.9f} s, "
                          f"earlier messages were {frames[0]!r} -> {frames[1]!r}")
    return pair if frames is None else frames


def read_frame_tree(bag, topics=None, odom_topic: str | None = None) -> FrameTree:
    """Every transform on the tf topics of ``bag`` (an open :class:`~occmap.io.bags.Bag`) in one
    :class:`FrameTree` that keeps the whole bag's history.

    ``topics`` defaults to whichever of ``/tf`` and ``/tf_static`` the bag has; a topic whose name
    ends in ``tf_static`` holds static links (valid at all times, the last one of a link wins).
    Dynamic samples are stored at their header stamps, so lookups interpolate between them and
    raise :class:`~occmap.errors.ExtrapolationError` outside them. A link both static and dynamic
    ends up dynamic. ``odom_topic``, an odometry topic, joins the tree as the link
    ``frame_id -> child_frame_id`` of its messages (see :class:`TransformFeed`). Raises
    :class:`FormatError` for a transform that is not rigid or links that would form a loop.
    """
    feed = TransformFeed(bag, topics, odom_topic)
    for run in bag.runs(feed.topics):
        feed.add(run)
    return feed.flush()


class TransformFeed:
    """The tf of a bag (and an odometry topic's ``frame_id -> child_frame_id`` link) gathered
    into one :class:`FrameTree` message by message, as a stream of the bag reads them:
    :meth:`add` each run of messages of :attr:`topics`, :meth:`flush` to have the tree hold all those
    added (the samples of a link wait in lists and go into the tree in one call, which costs what
    one sample does). Read to the end, the tree is :func:`read_frame_tree`'s: static links first,
    the last static sample of a link wins, a link both static and dynamic ends up dynamic, and the
odometry's child frame keeps the odometry's frame as its parent whatever tf says.

    ``topics`` defaults to whichever of ``/tf`` and ``/tf_static`` the bag has (checked to hold
    TFMessage, and defined as ROS does); ``odom_topic``, when given, must hold Odometry.
    """

    def __init__(self, bag, topics=None, odom_topic: str | None = None):
        if topics is None:
            topics = [t for t in ("/tf", "/tf_static") if t in bag.topics]
        for t in topics:
            if t in bag.topics and bag.topics[t].msgtype not in TF_TYPES:
                raise FormatError(bag.path, f"topic {t!r} holds {bag.topics[t].msgtype}, not {TF_TYPES[0]}")
        if odom_topic is not None:
            bag.messages(odom_topic, msgtype=ODOMETRY).close()  # the topic exists and holds Odometry
        self.topics = list(topics) + ([] if odom_topic is None else [odom_topic])
        bag.require_standard(t for t in self.topics if t in bag.topics)
        self.path, self.odom_topic, self.encoding = bag.path, odom_topic, bag.encoding
        span = 0.0 if bag.start is None else bag.end - bag.start
        self.tree = FrameTree(cache_time=max(10.0, span + 1.0))
        self._waiting: dict[tuple[str, str, bool], list] = {}  # link -> [(order, stamps, values), ...]
        self._pending = []  # tf messages not decoded yet: (topic, order of arrival, numbers on it, times ns, Raws)
        self._arrived = 0  # messages added
        self._dynamic: set[tuple[str, str]] = set()  # links that have had a dynamic sample
        self._counts: dict[str, int] = {}
        self._odom_frames = None

    def add(self, run) -> None:
        """Read a run of messages (a :class:`~occmap.io.bags.bag.Run`, :meth:`Bag.runs
        <occmap.io.bags.Bag.runs>`), every one of them on :attr:`topics`."""
        for slot, topic in enumerate(run.topics):
            rows = np.flatnonzero(run.which == slot)
            if not len(rows):
                continue
            first = self._counts.get(topic, 0)
            self._counts[topic] = first + len(rows)
            order, ks, times = self._arrived + 1 + rows, first + np.arange(len(rows)), run.times_ns[rows]
            if topic != self.odom_topic:
                self._pending.append((topic, order, ks, times, run.raws.take(rows)))
                continue
            for j, i in enumerate(rows.tolist()):
                time = float(times[j]) / 1e9
                stamp, *pair, pose = _odometry(run.raws[i], self.encoding, Where(self.path, topic, int(ks[j]), time))
                self._odom_frames = _same_frames(self.path, topic, time, self._odom_frames, pair)
                self._wait(*pair, False, order[j: j + 1], np.array([stamp]), np.array([pose]))
        self._arrived += len(run)

    def _wait(self, parent: str, child: str, static: bool, order, stamps, values) -> None:
        """Samples of a link: their order of arrival, stamps (seconds) and ``(x, y, z, qx, qy, qz, qw)``."""
        self._waiting.setdefault((parent, child, static), []).append((order, stamps, values))

    def _decode_pending(self) -> None:
        """The tf messages added since the last flush, decoded (those of one layout together)."""
        pending, self._pending = self._pending, []
        for topic in dict.fromkeys(p[0] for p in pending):
            mine = [p for p in pending if p[0] == topic]
            order, ks, times = (np.concatenate([p[c] for p in mine]) for c in (1, 2, 3))
            raws = Raws.concat([p[4] for p in mine])
            static = topic.endswith("tf_static")

            def where(j, topic=topic, ks=ks, times=times):
                return Where(self.path, topic, int(ks[j]), float(times[j]) / 1e9)

            for group, layout, alike in by_layout(raws, lambda j: _tf_layout(raws[j], self.encoding, where(j))):
                samples, values = _tf_samples(layout, alike)
                for t, (parent, child) in enumerate(layout.links):
                    self._wait(parent, child, static, order[group], samples[:, t], values[:, t])

    def flush(self) -> FrameTree:
        """The tree, holding every sample added so far."""
        self._decode_pending()
        waiting, self._waiting = self._waiting, {}
        for (parent, child, static), parts in sorted(waiting.items(), key=lambda kv: not kv[0][2]):
            if static and (parent, child) in self._dynamic:
                continue
            if self._odom_frames is not None and child == self._odom_frames[1] and parent != self._odom_frames[0]:
                continue  # the odometry's child frame: its parent is the odometry's frame
            order = np.argsort(np.concatenate([p[0] for p in parts]), kind="stable")  # as the messages came
            stamps = np.concatenate([p[1] for p in parts])[order]
            values = np.concatenate([p[2] for p in parts])[order]
            poses = ros_poses(values[:, :3], values[:, 3:], f"{self.path}: tf link {parent!r} -> {child!r}")
            try:
                if static:
                    self.tree.set_transform(parent, child, SE3(poses.matrix[-1]), static=True)
                else:
                    self._dynamic.add((parent, child))
                    self.tree.set_transform(parent, child, poses, stamps)
            except TransformError as e:
                raise FormatError(self.path, f"tf link {parent!r} -> {child!r}: {e}") from e
        return self.tree
