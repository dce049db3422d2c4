"""Scan sources read from ROS bags: the ``sensor_msgs/LaserScan`` or ``sensor_msgs/PointCloud2``
messages of one topic, each placed in a fixed frame, streamed.

Where each message was taken comes, in this order, from:

* a pose file (:class:`~occmap.io.poses.PoseTrack`): by the message's header stamp for a track
  with stamps (TUM), else pose ``k`` for message ``k``;
* tf: ``T_fixed_sensor`` looked up in the bag's :class:`~occmap.geometry.frames.FrameTree`
  (``/tf`` and ``/tf_static``) from the fixed frame to the message's ``header.frame_id`` at its
  header stamp, interpolated between tf samples. An odometry topic (``nav_msgs/Odometry``) joins
  the tree as the link ``header.frame_id → child_frame_id`` of its messages, so odometry serves
  where a bag has no tf, or only a static sensor mount. tf is read in the same pass as the
  messages (:class:`~occmap.io.bags.transforms.TransformFeed`), and a message waits until tf has
  passed its stamp, as tf2's message filters make a node wait; if tf lags so far behind that
  :data:`WAIT_LIMIT` batches wait, or never joins the sensor frame, the bag's whole tf is read in a
  pass of its own. With tf recorded in stamp order, the poses are those the whole bag's tf gives.

A message whose stamp lies outside the tf samples (or beyond the pose file's tolerance) is not
guessed at: it is dropped and counted in ``dropped`` under its reason, as are scans with no beams
and clouds with no finite points. A sensor frame that tf does not join to the fixed frame at all
stops the stream with an :class:`~occmap.errors.InvalidArgumentError` naming both frames and the
time. A topic (the scans', tf, odometry) whose connection defines its type otherwise than ROS does
is refused with a :class:`~occmap.errors.FormatError` saying what differs
(:mod:`occmap.io.bags.definitions`). Memory holds the frame tree and the messages waiting for tf
(one, or a batch of 50 for laser scans, whose poses are looked up together).

The fixed frame defaults to the root of the sensor frame's tf tree (``odom`` or ``map`` in a
usual robot's) as tf stands :data:`ROOT_HORIZON` seconds after the topic's first message, and to
``fallback_frame`` when tf does not know the sensor frame by then.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import replace
from typing import Iterator

import numpy as np

from ..cloud import PointCloud
from ..errors import ConnectivityError, ExtrapolationError, InvalidArgumentError, TransformError, UnknownFrameError
from ..io.bags import decode_laser_scan, decode_point_cloud2, open_bag, read_frame_tree
from ..io.bags.bag import Where
from ..io.bags.transforms import ODOMETRY, TransformFeed
from ..io.bags.wire import Wire
from ..scan import LaserScan

__all__ = ["BagClouds", "BagScans"]

#: Seconds of tf after the first message that tell the default fixed frame (the root of the sensor's tree)
ROOT_HORIZON = 1.0
#: Batches of messages that may wait for tf to pass their stamps before the whole bag's tf is read
#: in a pass of its own (tf that lags far behind, or never joins the sensor frame)
WAIT_LIMIT = 10

#: A laser whose scan plane leans further than this from the fixed frame's xy plane is counted as tilted.
TILT_NOTE = math.radians(5.0)


class _BagSource:
    """What the two bag sources share: the topic, the poses, the stream and its counts."""

    MSGTYPE = ""
    FALLBACK_FRAME = ""
    BATCH = 1  # messages decoded before their poses are looked up together

    def __init__(self, path, topic: str | None = None, fixed_frame: str | None = None,
                 odom_topic: str | None = None, poses=None, tolerance: float = 0.05, every: int = 1,
                 unposed: bool = False):
        self.path = str(path)
        self.every = int(every)
        self.tolerance = float(tolerance)
        self.dropped: Counter = Counter()
        self.tilted = 0  # laser scans whose plane leans more than TILT_NOTE (see BagScans)
        self.pose_track = poses
        self.odom_topic = odom_topic
        self._by_tf = False  # whether tf (and odometry) place the messages
        bag = self._bag = open_bag(path)  # kept for the first iteration: opening a ROS 2 bag costs 0.1 s
        try:
            self.topic = _pick_topic(bag, topic, self.MSGTYPE)
            bag.require_standard(self.topic)
            self.count = bag.topics[self.topic].count
            self.sensor_frame, first_time = _first_frame(bag, self.topic)
            self.fixed_frame = fixed_frame or ""
            if poses is not None:
                if poses.stamps is None:
                    poses.by_index(self.count, f"messages on {self.topic}")
            elif self._has_tf(bag, unposed):
                self._by_tf = True
                self.fixed_frame = self.fixed_frame or self._tf_root(bag, first_time) or self.FALLBACK_FRAME
        except BaseException:
            bag.close()
            raise

    def _has_tf(self, bag, unposed: bool) -> bool:
        """Whether the bag has tf or the odometry topic to place messages by; when it has neither,
        False if the caller takes ``unposed`` messages (scan matching gives them poses), else an error."""
        if self.odom_topic is not None or any(bag.topics[t].count for t in ("/tf", "/tf_static") if t in bag.topics):
            return True
        if unposed:
            return False
        odoms = [t.name for t in bag.topics.values() if t.msgtype == ODOMETRY]
        raise InvalidArgumentError(
            f"{self.path}: its {self.topic} messages have no poses: the bag has no tf (/tf, /tf_static)"
            + (f" (odometry on {', '.join(odoms)}: give --odom-topic)" if odoms else " and no odometry")
            + "; give a pose file with --poses, or build the poses from the scans with --scan-match")

    def _tf_root(self, bag, first_time: float | None) -> str | None:
        """The root of the sensor frame's tf tree as tf stands :data:`ROOT_HORIZON` seconds after
        the first message (None when tf does not know the sensor frame by then)."""
        feed = TransformFeed(bag, odom_topic=self.odom_topic)
        stream = bag.messages(feed.topics)
        try:
            for m in stream:
                feed.add(m)
                if first_time is None or m.time > first_time + ROOT_HORIZON:
                    break
        finally:
            stream.close()
        return _root(feed.flush(), self.sensor_frame)

    def __len__(self) -> int:
        """Messages the stream looks at (every ``every``-th of the topic's)."""
        return -(-self.count // self.every)

    def __iter__(self) -> Iterator:
        bag, self._bag = self._bag, None
        if bag is None:  # a bag opened anew: checked again, its messages then decode by the standard types
            bag = open_bag(self.path)
            bag.require_standard(self.topic)
        self.dropped.clear()
        self.tilted = 0
        with bag:
            feed = TransformFeed(bag, odom_topic=self.odom_topic) if self._by_tf else None
            tree, whole = None, feed is None  # whole: the tree holds all of the bag's tf (or none is used)
            waiting = []  # decoded messages waiting for tf to pass their stamps
            k = -1
            for m in bag.messages([self.topic] + ([] if feed is None else feed.topics)):
                if m.topic != self.topic:
                    if not whole:
                        feed.add(m)
                    continue
                k += 1
                if k % self.every:
                    continue
                where = Where(self.path, self.topic, k, m.time)
                item = self._decode(m, where)
                if item is not None:
                    waiting.append((k, where, *item))
                if len(waiting) < self.BATCH:
                    continue
                if not whole:
                    tree = feed.flush()
                    if len(waiting) >= WAIT_LIMIT * self.BATCH:  # tf lags far behind, or never joins the frame
                        with open_bag(self.path) as again:
                            tree, whole = read_frame_tree(again, odom_topic=self.odom_topic), True
                n = len(waiting) if whole else _covered(tree, self.fixed_frame, waiting)
                yield from self._placed(waiting[:n], tree)
                del waiting[:n]
            if not whole:
                tree = feed.flush()
            yield from self._placed(waiting, tree)

    def _placed(self, batch, tree):
        """The records of ``batch`` (``(k, where, record, frame, stamp)``) that have a pose, placed;
        their poses found at once when they share a frame (a lookup costs 20 µs, one of 50 the same)."""
        if len(batch) > 1 and self.pose_track is None and tree is not None \
                and all(b[3] == batch[0][3] for b in batch):
            try:
                poses = tree.lookup(self.fixed_frame, batch[0][3], np.array([b[4] for b in batch])).matrix
            except TransformError:  # a stamp outside the tf data, or no tf at all: told message by message
                pass
            else:
                return self._place([b[2] for b in batch], poses)
        records, poses = [], []
        for k, where, record, frame, stamp in batch:
            pose = self._pose(k, frame, stamp, where, tree)
            if pose is not None:
                records.append(record)
                poses.append(pose)
        return self._place(records, np.array(poses).reshape(-1, 4, 4))

    def _pose(self, k: int, frame: str, stamp: float, where: Where, tree):
        """``T_fixed_sensor`` of message ``k`` as an (4, 4) array, or None (counted)."""
        if self.pose_track is not None:
            if self.pose_track.stamps is None:
                return self.pose_track.poses[k].matrix
            pose, ok = self.pose_track.at([stamp], self.tolerance)
            if not ok[0]:
                self.dropped[f"no pose in {self.pose_track.path} within {self.tolerance:g} s"] += 1
                return None
            return pose.matrix[0]
        if tree is None:  # unposed: at the origin, for scan matching to place
            return np.eye(4)
        try:
            return tree.lookup(self.fixed_frame, frame, stamp).matrix
        except ExtrapolationError:
            self.dropped["no tf at that time (outside the tf data)"] += 1
            return None
        except (UnknownFrameError, ConnectivityError) as e:
            raise InvalidArgumentError(f"{where}: no tf from {self.fixed_frame!r} to the sensor frame {frame!r} at "
                                       f"{stamp:.9f} s ({e}); --fixed-frame names the frame to map in") from None


class BagScans(_BagSource):
    """The ``sensor_msgs/LaserScan`` messages of a bag topic as :class:`~occmap.scan.LaserScan`
    records in the fixed frame (see :mod:`occmap.sources.bags`).

    The planar pose ``(x, y, theta)`` is the sensor's position and the heading of its x axis
    projected on the fixed frame's xy plane; a laser mounted upside down (its z axis pointing down)
    sweeps clockwise there, so its beam angles are negated. Scans whose plane leans more than 5°
    are kept and counted in ``tilted``: a 2D map sees their beams as if level.
    ``topic`` defaults to the bag's only LaserScan topic; ``max_range`` (metres), when given,
    replaces the messages' ``range_max``, as it does for a CARMEN log.
    """

    MSGTYPE = "sensor_msgs/msg/LaserScan"
    FALLBACK_FRAME = "odom"
    BATCH = 50

    def __init__(self, path, *args, max_range: float | None = None, **kwargs):
        super().__init__(path, *args, **kwargs)
        self.max_range = None if max_range is None else float(max_range)

    def _decode(self, m, where):
        scan, frame = decode_laser_scan(m.raw, m.encoding, where)
        if not len(scan):
            self.dropped["scan with no beams"] += 1
            return None
        if self.max_range is not None:
            scan = replace(scan, max_range=self.max_range)
        return scan, frame, scan.stamp

    def _place(self, scans, T):
        up = T[:, 2, 2]
        self.tilted += int(np.count_nonzero(np.arccos(np.minimum(1.0, np.abs(up))) > TILT_NOTE))
        poses = np.stack([T[:, 0, 3], T[:, 1, 3], np.arctan2(T[:, 1, 0], T[:, 0, 0])], axis=1)
        # LaserScan(...), not dataclasses.replace, which costs as much as the rest of the placing
        return [LaserScan(pose, s.ranges, -s.angles if flip else s.angles, s.max_range, s.stamp, s.odom)
                for s, pose, flip in zip(scans, poses, (up < 0).tolist())]


class BagClouds(_BagSource):
    """The ``sensor_msgs/PointCloud2`` messages of a bag topic as
    :class:`~occmap.cloud.PointCloud` records posed in the fixed frame (see
    :mod:`occmap.sources.bags`); points with a non-finite coordinate are left out (the cloud's
    ``dropped``). ``topic`` defaults to the bag's only PointCloud2 topic."""

    MSGTYPE = "sensor_msgs/msg/PointCloud2"
    FALLBACK_FRAME = "map"
    BATCH = 1  # a cloud is megabytes; its lookup is nothing beside its insertion

    def _decode(self, m, where):
        cloud = decode_point_cloud2(m.msg, where=where)
        if not len(cloud.points):
            self.dropped["cloud with no points" if not cloud.dropped else "cloud with no finite points"] += 1
            return None
        return cloud, cloud.frame_id, cloud.stamp

    def _place(self, clouds, T):
        return [PointCloud(c.points, pose, c.stamp, c.dropped) for c, pose in zip(clouds, T)]


def _pick_topic(bag, topic: str | None, msgtype: str) -> str:
    """``topic``, checked to hold ``msgtype``; by default the bag's only topic of that type."""
    name = msgtype.rsplit("/", 1)[-1]
    if topic is not None:
        if topic not in bag.topics:
            raise InvalidArgumentError(f"{bag.path}: no topic {topic!r}; its topics: {_listing(bag)}")
        if bag.topics[topic].msgtype != msgtype:
            raise InvalidArgumentError(f"{bag.path}: topic {topic!r} holds {bag.topics[topic].msgtype}, not {msgtype}")
        return topic
    found = [t.name for t in bag.topics.values() if t.msgtype == msgtype]
    if len(found) != 1:
        raise InvalidArgumentError(f"{bag.path}: {'no' if not found else 'several'} {name} topics; "
                                   f"{'name one with' if found else 'its topics:'} "
                                   + (f"--topic ({', '.join(found)})" if found else _listing(bag)))
    return found[0]


def _listing(bag) -> str:
    return ", ".join(f"{t.name} ({t.msgtype})" for t in bag.topics.values()) or "(none)"


def _first_frame(bag, topic: str) -> tuple[str, float | None]:
    """The frame of the first message on ``topic`` and its record time ("" and None when the
    topic has no message)."""
    stream = bag.messages(topic)
    try:
        first = next(stream, None)
    finally:
        stream.close()
    if first is None:
        return "", None
    return Wire(first.raw, first.encoding, Where(bag.path, topic, 0, first.time)).header()[1], first.time


def _covered(tree, fixed_frame: str, waiting) -> int:
    """How many of the first ``waiting`` messages (``(k, where, record, frame, stamp)``) tf has
    passed: their stamps at or before the newest time at which every link from their frame to the
    fixed frame has a sample (any stamp when those links are static). A frame tf does not yet join
    to the fixed frame waits."""
    latest: dict[str, float] = {}
    for n, (_, _, _, frame, stamp) in enumerate(waiting):
        if frame not in latest:
            try:
                t = tree.latest_common_time(fixed_frame, frame)
            except TransformError:
                t = -math.inf
            latest[frame] = math.inf if t is None else t
        if stamp > latest[frame]:
            return n
    return len(waiting)


def _root(tree, frame: str) -> str | None:
    """The root of ``frame``'s tree, or None when tf does not know the frame."""
    if frame not in tree:
        return None
    while (parent := tree.parent(frame)) is not None:
        frame = parent
    return frame
