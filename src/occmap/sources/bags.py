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
  messages (:class:`~occmap.io.bags.transforms.TransformFeed`; the tf of a run of messages read
  together, :meth:`~occmap.io.bags.Bag.runs`, goes in at once, but for the first batch, which
  takes the tf recorded up to :data:`TF_AHEAD` seconds after its last message), and a message waits until tf has
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
(one, or a batch of up to 400 laser scans, decoded and placed together), and, from opening to the
first iteration, what opening read (see below; at most :data:`HEAD_BYTES`), which that
iteration goes on from rather than reading it again.

The fixed frame defaults to the root of the sensor frame's tf tree (``odom`` or ``map`` in a
usual robot's) as tf stands :data:`ROOT_HORIZON` seconds after the topic's first message, and to
``fallback_frame`` when tf does not know the sensor frame by then.
"""

from __future__ import annotations

import itertools
import math
from collections import Counter
from typing import Iterator, NamedTuple

import numpy as np

from ..cloud import PointCloud
from ..errors import ConnectivityError, ExtrapolationError, InvalidArgumentError, TransformError, UnknownFrameError
from ..io.bags import decode_point_cloud2, open_bag, read_frame_tree
from ..io.bags.bag import Message, Run, Where
from ..io.bags.records import Raws
from ..io.bags.laserscan import decode_laser_scans
from ..io.bags.transforms import ODOMETRY, TransformFeed
from ..io.bags.wire import Wire
from ..scan import LaserScan, ScanStack, concat_stacks

__all__ = ["BagClouds", "BagScans"]

#: Seconds of tf after the first message that tell the default fixed frame (the root of the sensor's tree)
ROOT_HORIZON = 1.0
#: Bytes of messages that opening a bag source may hold for the first iteration (two clouds are more)
HEAD_BYTES = 4 << 20
#: Bytes of messages that end a batch before it has its count (see :class:`BagScans`)
BATCH_BYTES = 256 << 10
#: Seconds of tf recorded after the first batch's last message that go into the tree with it (the
#: rest of the run's tf goes in with the next batch, at once): the first scans need not wait for a
#: chunk's tf, and later batches decode a run's tf in one call, not one per batch
TF_AHEAD = 0.5
#: Largest batches of messages that may wait for tf to pass their stamps before the whole bag's tf
#: is read in a pass of its own (tf that lags far behind, or never joins the sensor frame)
WAIT_LIMIT = 3

#: A laser whose scan plane leans further than this from the fixed frame's xy plane is counted as tilted.
TILT_NOTE = math.radians(5.0)


class _BagSource:
    """What the two bag sources share: the topic, the poses, the stream and its counts."""

    MSGTYPE = ""
    FALLBACK_FRAME = ""
    BATCH = 1  # messages decoded before their poses are looked up together, at most
    FIRST_BATCH = 1  # ... in the first batch (the next ones grow 16-fold up to BATCH)

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
        self._head, self._stream = [], None  # what opening read of the first iteration's messages, and their stream
        try:
            self.topic = _pick_topic(bag, topic, self.MSGTYPE)
            bag.require_standard(self.topic)
            self.count = bag.topics[self.topic].count
            self.fixed_frame = fixed_frame or ""
            if poses is not None:
                if poses.stamps is None:
                    poses.by_index(self.count, f"messages on {self.topic}")
            elif self._has_tf(bag, unposed):
                self._by_tf = True
            self._read_head(bag, root=self._by_tf and not self.fixed_frame)
        except BaseException:
            bag.close()
            raise

    def _read_head(self, bag, root: bool) -> None:
        """Read the stream up to the topic's first message (its frame is the sensor's) or, for
        the ``root`` of the sensor frame's tf tree (the default fixed frame), :data:`ROOT_HORIZON`
        seconds past it; the first iteration goes on from there (the messages read, then the rest
        of the run, :meth:`~occmap.io.bags.Bag.runs`, that held the last). Past :data:`HEAD_BYTES`
        (point clouds), nothing is held: the first message and tf are read in passes of their own."""
        feed = TransformFeed(bag, odom_topic=self.odom_topic) if self._by_tf else None
        self.sensor_frame, first, held, rest, head = "", None, 0, None, []
        stream = bag.runs(self._topics(feed)) if self.count else iter(())
        for run in stream:
            mine = _on(run, self.topic)
            ends = held + np.cumsum(run.raws.sizes)  # bytes held with each message
            stop = ends > HEAD_BYTES
            at = 0  # where the messages from the topic's first on start in this run
            if first is None and mine.any():
                at = int(np.argmax(mine))
                first = float(run.times_ns[at]) / 1e9, run.raws[at]
            if first is not None:
                stop[at:] |= (not root) | (run.times_ns[at:] / 1e9 > first[0] + ROOT_HORIZON)
            cut = int(np.argmax(stop)) + 1 if stop.any() else len(run)
            head.append(run.take(slice(None, cut)))
            held = int(ends[cut - 1])
            if stop.any():
                rest = run.take(slice(cut, None))
                break
        if held > HEAD_BYTES:  # the head is not kept: tf up to the horizon read again, without the messages
            stream.close()
            stream, rest = None, None
            if first is None:
                m = _first(bag.messages(self.topic))
                first = m.time, m.raw
            head = _before(bag.runs(feed.topics), first[0] + ROOT_HORIZON) if root else []
        if first is not None:
            where = Where(bag.path, self.topic, 0, first[0])
            self.sensor_frame = Wire(first[1], bag.encoding, where).header()[1]
        if root:
            for run in head:
                if first is not None:
                    feed.add(run.take(np.flatnonzero(~_on(run, self.topic)
                                                     & (run.times_ns / 1e9 <= first[0] + ROOT_HORIZON))))
            self.fixed_frame = _root(feed.flush(), self.sensor_frame) or self.FALLBACK_FRAME
        if stream is not None:
            self._head = [m for run in head for m in self._messages(run, bag)]
            self._stream = stream if rest is None else itertools.chain([rest], stream)

    def _messages(self, run, bag) -> list[Message]:
        """The messages of ``run`` one by one."""
        msgtypes = [bag.topics[t].msgtype for t in run.topics]
        return [Message(run.topics[w], msgtypes[w], t, run.raws[i].tobytes(), bag.encoding, bag)
                for i, (w, t) in enumerate(zip(run.which.tolist(), run.times_ns.tolist()))]

    def _topics(self, feed) -> list[str]:
        """The topics an iteration reads: the messages' and, to place them, tf's."""
        return [self.topic] + ([] if feed is None else feed.topics)

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

    def __len__(self) -> int:
        """Messages the stream looks at (every ``every``-th of the topic's)."""
        return -(-self.count // self.every)

    def __iter__(self) -> Iterator:
        for chunk in self._chunks():
            yield from self._items(chunk)

    def _chunks(self) -> Iterator:
        """The placed records in runs (as :meth:`_place` gives them), in message order."""
        bag, head, stream = self._bag, self._head, self._stream
        self._bag, self._head, self._stream = None, [], None
        if bag is None:  # a bag opened anew: checked again, its messages then decode by the standard types
            bag = open_bag(self.path)
            bag.require_standard(self.topic)
        self.dropped.clear()
        self.tilted = 0
        with bag:
            feed = TransformFeed(bag, odom_topic=self.odom_topic) if self._by_tf else None
            if stream is None:
                stream = bag.runs(self._topics(feed))
            tree, whole = None, feed is None  # whole: the tree holds all of the bag's tf (or none is used)
            pending = []  # (numbers on the topic, Run) of the topic's messages not yet decoded
            waiting = None  # decoded messages waiting for tf to pass their stamps (a _Decoded)
            k, batch, count, held = 0, self.FIRST_BATCH, 0, 0  # count, held: pending's messages and bytes
            ahead = round(TF_AHEAD * 1e9)  # ns of tf past the first batch's last message fed with it
            for run in itertools.chain([_run_of(head)] if head else [], stream):
                mine = _on(run, self.topic)
                at = np.flatnonzero(mine)  # the topic's messages in the run, then those the stream takes
                ks = k + np.arange(len(at))
                k += len(at)
                if self.every > 1:
                    at, ks = at[ks % self.every == 0], ks[ks % self.every == 0]
                if not whole:  # tf's messages of the run (a chunk: the messages read with them), fed as batches need them
                    tf_at, fed = np.flatnonzero(~mine), 0
                taken = 0  # of at
                while taken < len(at):
                    sizes = run.raws.sizes[at[taken:]]
                    # the message that fills the batch: its count, or BATCH_BYTES
                    cut = batch - count - 1
                    full = np.flatnonzero(held + np.cumsum(sizes) >= BATCH_BYTES)
                    if len(full):
                        cut = min(cut, int(full[0]))
                    if cut >= len(sizes):
                        pending.append((ks[taken:], run.take(at[taken:])))
                        count, held = count + len(sizes), held + int(sizes.sum())
                        break
                    end = taken + cut + 1
                    pending.append((ks[taken:end], run.take(at[taken:end])))
                    taken = end
                    waiting = self._joined(waiting, self._decoded(pending, bag))
                    pending, batch, count, held = [], min(16 * batch, self.BATCH), 0, 0
                    if not whole:
                        upto = len(tf_at) if ahead is None else int(np.searchsorted(
                            run.times_ns[tf_at], run.times_ns[at[end - 1]] + ahead, "right"))
                        ahead = None  # after the first batch: the rest of each run's tf at once
                        if upto > fed:
                            feed.add(run.take(tf_at[fed:upto]))
                            fed = upto
                        tree = feed.flush()
                        if len(waiting.ks) >= WAIT_LIMIT * self.BATCH:  # tf lags far behind, or never joins the frame
                            with open_bag(self.path) as again:
                                tree, whole = read_frame_tree(again, odom_topic=self.odom_topic), True
                    n = len(waiting.ks) if whole else _covered(tree, self.fixed_frame, waiting)
                    if n:
                        yield from self._placed(self._part(waiting, slice(None, n)), tree)
                        waiting = self._part(waiting, slice(n, None))
                if not whole and fed < len(tf_at):
                    feed.add(run.take(tf_at[fed:]))
            if not whole:
                tree = feed.flush()
            if pending:
                waiting = self._joined(waiting, self._decoded(pending, bag))
            if waiting is not None and len(waiting.ks):
                yield from self._placed(waiting, tree)

    def _decoded(self, batch, bag) -> _Decoded:
        """The messages ``batch`` (``(numbers on the topic, Run)``) decoded, those that hold
        nothing dropped and counted."""
        ks = np.concatenate([k for k, _ in batch])
        times_ns = np.concatenate([run.times_ns for _, run in batch])
        times = times_ns / 1e9
        raws = Raws.concat([run.raws for _, run in batch])
        records, frames, stamps, keep = self._decode(raws, times_ns, bag,
                                                     lambda i: Where(self.path, self.topic, int(ks[i]), times[i]))
        if keep is None:
            return _Decoded(ks, times, records, frames, stamps)
        return _Decoded(ks[keep], times[keep], self._take(records, keep), [f for f, y in zip(frames, keep) if y],
                        stamps[keep])

    def _part(self, d: _Decoded, rows: slice) -> _Decoded:
        return _Decoded(d.ks[rows], d.times[rows], self._take(d.records, rows), d.frames[rows], d.stamps[rows])

    def _joined(self, a: _Decoded | None, b: _Decoded) -> _Decoded:
        if a is None or not len(a.ks):
            return b
        if not len(b.ks):
            return a
        return _Decoded(np.concatenate([a.ks, b.ks]), np.concatenate([a.times, b.times]),
                        self._join(a.records, b.records), a.frames + b.frames, np.concatenate([a.stamps, b.stamps]))

    def _placed(self, d: _Decoded, tree) -> Iterator:
        """The records of ``d`` that have a pose, placed (at most one run); their poses found at
        once when they share a frame (a lookup costs 20 µs, one of 200 not much more)."""
        n = len(d.ks)
        keep = None
        if self.pose_track is not None:
            if self.pose_track.stamps is None:
                T = self.pose_track.poses.matrix[d.ks]
            else:
                poses, keep = self.pose_track.at(d.stamps, self.tolerance)
                T = poses.matrix
                if not keep.all():
                    self.dropped[f"no pose in {self.pose_track.path} within {self.tolerance:g} s"] += \
                        int(np.count_nonzero(~keep))
        elif tree is None:  # unposed: at the origin, for scan matching to place
            T = np.broadcast_to(np.eye(4), (n, 4, 4))
        else:
            T = None
            if n > 1 and d.frames.count(d.frames[0]) == n:
                try:
                    T = tree.lookup(self.fixed_frame, d.frames[0], d.stamps).matrix
                except TransformError:  # a stamp outside the tf data, or no tf at all: told message by message
                    pass
            if T is None:
                T = np.empty((n, 4, 4))
                keep = np.ones(n, dtype=bool)
                for i in range(n):
                    pose = self._pose(i, d, tree)
                    keep[i] = pose is not None
                    if keep[i]:
                        T[i] = pose
        records = d.records
        if keep is not None and not keep.all():
            records, T = self._take(records, keep), T[keep]
        if len(T):
            yield self._place(records, T)

    def _pose(self, i: int, d: _Decoded, tree):
        """``T_fixed_sensor`` of record ``i`` of ``d`` from tf as an (4, 4) array, or None (counted)."""
        frame, stamp = d.frames[i], float(d.stamps[i])
        try:
            return tree.lookup(self.fixed_frame, frame, stamp).matrix
        except ExtrapolationError:
            self.dropped["no tf at that time (outside the tf data)"] += 1
            return None
        except (UnknownFrameError, ConnectivityError) as e:
            where = Where(self.path, self.topic, int(d.ks[i]), float(d.times[i]))
            raise InvalidArgumentError(f"{where}: no tf from {self.fixed_frame!r} to the sensor frame {frame!r} at "
                                       f"{stamp:.9f} s ({e}); --fixed-frame names the frame to map in") from None


class _Decoded(NamedTuple):
    """Decoded messages of the topic: their numbers on it, record times, the source's records
    (:meth:`_BagSource._decode`), frames and header stamps."""

    ks: np.ndarray
    times: np.ndarray
    records: object
    frames: list[str]
    stamps: np.ndarray


class BagScans(_BagSource):
    """The ``sensor_msgs/LaserScan`` messages of a bag topic as :class:`~occmap.scan.LaserScan`
    records in the fixed frame (see :mod:`occmap.sources.bags`), or as
    :class:`~occmap.scan.ScanStack` runs (:meth:`stacks`), which is how a grid takes them.

    The planar pose ``(x, y, theta)`` is the sensor's position and the heading of its x axis
    projected on the fixed frame's xy plane; a laser mounted upside down (its z axis pointing down)
    sweeps clockwise there, so its beam angles are negated. Scans whose plane leans more than 5°
    are kept and counted in ``tilted``: a 2D map sees their beams as if level.
    ``topic`` defaults to the bag's only LaserScan topic; ``max_range`` (metres), when given,
    replaces the messages' ``range_max``, as it does for a CARMEN log.
    """

    MSGTYPE = "sensor_msgs/msg/LaserScan"
    FALLBACK_FRAME = "odom"
    BATCH = 400  # a batch costs about 0.5 ms beside its messages (tf brought up to date, lookups)
    FIRST_BATCH = 25  # the first run a grid takes (map_scan_stream's first chunk)

    def __init__(self, path, *args, max_range: float | None = None, **kwargs):
        super().__init__(path, *args, **kwargs)
        self.max_range = None if max_range is None else float(max_range)

    def stacks(self) -> Iterator[ScanStack]:
        """The scans as :class:`~occmap.scan.ScanStack` runs, in order: batches of 25, then 400 or
        :data:`BATCH_BYTES` of messages (more while tf lags behind them), rows NaN-padded to the
        widest scan of a run."""
        for stack, _ in self._chunks():
            yield stack

    def _items(self, chunk):
        stack, beams = chunk
        shared = stack.angles.ndim == 1
        for i in range(len(beams)):
            b = int(beams[i])
            yield LaserScan(stack.poses[i], stack.ranges[i, :b], stack.angles[:b] if shared else stack.angles[i, :b],
                            float(stack.max_ranges[i]), float(stack.stamps[i]))

    def _decode(self, raws, times_ns, bag, where):
        """``(records, frames, stamps, keep)`` of the messages ``raws`` (a :class:`Raws`, recorded
        at ``times_ns``): records ``(ScanStack, beams)``; keep None or the mask of the scans that have beams."""
        stack, beams, frames = decode_laser_scans(raws, bag.encoding, where)
        if self.max_range is not None:
            stack = stack._replace(max_ranges=np.full(len(beams), self.max_range))
        keep = beams > 0
        if keep.all():
            keep = None
        else:
            self.dropped["scan with no beams"] += int(np.count_nonzero(~keep))
        return (stack, beams), frames, stack.stamps, keep

    @staticmethod
    def _take(records, rows):
        stack, beams = records
        return stack.take(rows), beams[rows]

    @staticmethod
    def _join(a, b):
        return concat_stacks([a[0], b[0]]), np.concatenate([a[1], b[1]])

    def _place(self, records, T):
        stack, beams = records
        up = T[:, 2, 2]
        self.tilted += int(np.count_nonzero(np.arccos(np.minimum(1.0, np.abs(up))) > TILT_NOTE))
        poses = np.stack([T[:, 0, 3], T[:, 1, 3], np.arctan2(T[:, 1, 0], T[:, 0, 0])], axis=1)
        angles, flip = stack.angles, up < 0
        if flip.any():
            rows = np.broadcast_to(angles, stack.ranges.shape)
            angles = -angles if flip.all() else np.where(flip[:, None], -rows, rows)
        return stack._replace(poses=poses, angles=angles), beams


class BagClouds(_BagSource):
    """The ``sensor_msgs/PointCloud2`` messages of a bag topic as
    :class:`~occmap.cloud.PointCloud` records posed in the fixed frame (see
    :mod:`occmap.sources.bags`); points with a non-finite coordinate are left out (the cloud's
    ``dropped``). ``topic`` defaults to the bag's only PointCloud2 topic."""

    MSGTYPE = "sensor_msgs/msg/PointCloud2"
    FALLBACK_FRAME = "map"
    BATCH = 1  # a cloud is megabytes; its lookup is nothing beside its insertion

    def _items(self, chunk):
        return chunk

    def _decode(self, raws, times_ns, bag, where):
        """``(records, frames, stamps, keep)`` of the messages ``raws`` (a :class:`Raws`, recorded
        at ``times_ns``): records a list of clouds in their own frames."""
        clouds = []
        for i in range(len(raws)):
            m = Message(self.topic, self.MSGTYPE, int(times_ns[i]), raws[i], bag.encoding, bag)
            clouds.append(decode_point_cloud2(m.msg, where=where(i), fields=False))
        keep = np.array([len(c.points) > 0 for c in clouds], dtype=bool)
        for c in clouds:
            if not len(c.points):
                self.dropped["cloud with no points" if not c.dropped else "cloud with no finite points"] += 1
        return (clouds, [c.frame_id for c in clouds], np.array([c.stamp for c in clouds], dtype=np.float64),
                None if keep.all() else keep)

    @staticmethod
    def _take(records, rows):
        if isinstance(rows, slice):
            return records[rows]
        return [r for r, y in zip(records, rows) if y]

    @staticmethod
    def _join(a, b):
        return a + b

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


def _first(stream):
    """The first message of ``stream``, which is then closed."""
    try:
        return next(stream)
    finally:
        stream.close()


def _before(runs, time: float) -> list:
    """The messages of ``runs`` (an iterator of :class:`Run`) recorded at or before ``time``, in
    runs holding their own bytes (not their chunks'); the iterator is then closed."""
    kept = []
    try:
        for run in runs:
            late = np.flatnonzero(run.times_ns / 1e9 > time)
            part = run.take(slice(None, int(late[0]))) if len(late) else run
            kept.append(Run(part.topics, part.which, part.times_ns, part.raws.compact()))
            if len(late):
                break
    finally:
        runs.close()
    return kept


def _run_of(messages) -> Run:
    """The messages (:class:`~occmap.io.bags.Message`) in one run."""
    slots = {}
    which = np.array([slots.setdefault(m.topic, len(slots)) for m in messages], np.intp)
    return Run(tuple(slots), which, np.array([m.time_ns for m in messages], np.int64),
               Raws.of([m.raw for m in messages]))


def _on(run, topic: str) -> np.ndarray:
    """Which messages of ``run`` are on ``topic``: bool (messages,)."""
    return np.array([t == topic for t in run.topics] + [False])[run.which]


def _covered(tree, fixed_frame: str, waiting: _Decoded) -> int:
    """How many of the first ``waiting`` messages tf has passed: their stamps at or before the
    newest time at which every link from their frame to the fixed frame has a sample (any stamp
    when those links are static). A frame tf does not yet join to the fixed frame waits."""
    latest = {}
    for frame in dict.fromkeys(waiting.frames):
        try:
            t = tree.latest_common_time(fixed_frame, frame)
        except TransformError:
            t = -math.inf
        latest[frame] = math.inf if t is None else t
    if len(latest) == 1:
        limit = latest[waiting.frames[0]]
    else:
        limit = np.array([latest[f] for f in waiting.frames])
    late = np.flatnonzero(waiting.stamps > limit)
    return int(late[0]) if len(late) else len(waiting.stamps)


def _root(tree, frame: str) -> str | None:
    """The root of ``frame``'s tree, or None when tf does not know the frame."""
    if frame not in tree:
        return None
    while (parent := tree.parent(frame)) is not None:
        frame = parent
    return frame
