"""Reading ROS bags: PointCloud2 decoding against a plain NumPy decode, and a whole bag streamed.

* Decoding one HDL-32E scan (the shared ``hdl32_pair`` scan, 69,088 points) packed as a
  Velodyne driver does (``x y z`` float32, ``intensity`` float32, ``ring`` uint16, ``time``
  float32 in a 32-byte point; also big-endian, and organised 32 × 2,159 with padded rows) by
  :func:`occmap.io.bags.decode_point_cloud2`, against the plain NumPy decode a user writes for a
  layout known in advance (``np.frombuffer`` with the structured dtype, ``x y z`` stacked into
  float64, the other fields copied). Both give the same arrays; GB/s count the message's data bytes.
* A bag of clouds written with rosbags (ROS 1, ROS 2 sqlite3, ROS 2 MCAP), read start to end:
  open, every message deserialised by rosbags and decoded into points and fields; beside it the
  decoding alone of the same messages, so the difference is what reading the bag costs.
* Maps from bags end to end, against the insertion alone: the HDL-32E scan driven along a line
  (placed by tf: a static mount and moving ``map → base_link``) into an octree as ``occmap map3d
  BAG`` does (:class:`occmap.sources.BagClouds`: open, read tf, stream, decode, look up, insert),
  beside inserting the same placed clouds; and the Intel corrected log as LaserScan + tf into a
  grid as ``occmap map2d BAG`` does (:class:`occmap.sources.BagScans` into
  :func:`occmap.mapping2d.map_scan_stream`), beside :func:`occmap.mapping2d.map_scans` of the
  same placed scans, each map made with the grid's choice of threads learnt afresh (as by a new
  process: :func:`fresh_choices`).

    python benchmarks/bench_bags.py [--clouds N] [--map-clouds N] [--no-write]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import median_times, round_times, write_section  # noqa: E402

from occmap._data import find_shared_data  # noqa: E402
from occmap.io.bags import decode_point_cloud2, open_bag, point_dtype  # noqa: E402
from occmap.io.carmen import read_carmen  # noqa: E402
from occmap.io.pointclouds import read_pcd  # noqa: E402

CLOUD = "sensor_msgs/msg/PointCloud2"
SCAN = "sensor_msgs/msg/LaserScan"
TF = "tf2_msgs/msg/TFMessage"
FIELDS = [("x", 0, 7), ("y", 4, 7), ("z", 8, 7), ("intensity", 16, 7), ("ring", 20, 4), ("time", 24, 7)]


def velodyne_message(typestore, pts, big_endian=False, height=1, row_pad=0):
    """The scan as a PointCloud2 of ``typestore`` (32-byte points, the fields of FIELDS)."""
    T = typestore.types
    n = len(pts) // height * height
    order = ">" if big_endian else "<"
    dt = np.dtype({"names": [f[0] for f in FIELDS],
                   "formats": [order + c for c in ("f4", "f4", "f4", "f4", "u2", "f4")],
                   "offsets": [f[1] for f in FIELDS], "itemsize": 32})
    rec = np.zeros(n, dtype=dt)
    for k, axis in enumerate("xyz"):
        rec[axis] = pts[:n, k]
    rec["intensity"] = np.linalg.norm(pts[:n], axis=1)
    rec["ring"] = np.arange(n) % 32
    rec["time"] = np.linspace(0.0, 0.1, n)
    width = n // height
    data = np.frombuffer(rec.tobytes(), np.uint8).reshape(height, width * 32)
    if row_pad:
        data = np.concatenate([data, np.zeros((height, row_pad), np.uint8)], axis=1)
    header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=1, nanosec=0), frame_id="velodyne",
                                      **({"seq": 0} if "seq" in typestore.fielddefs["std_msgs/msg/Header"][1][0] else {}))
    F = T["sensor_msgs/msg/PointField"]
    return T[CLOUD](header=header, height=height, width=width,
                    fields=[F(name=a, offset=o, datatype=d, count=1) for a, o, d in FIELDS],
                    is_bigendian=big_endian, point_step=32, row_step=width * 32 + row_pad,
                    data=data.reshape(-1), is_dense=True)


def plain_numpy(msg):
    """The decode a user writes for this one layout: one structured view, xyz stacked, fields copied."""
    dt = point_dtype(msg.fields, msg.point_step, msg.is_bigendian)
    if msg.row_step != msg.width * msg.point_step:
        rows = msg.data.reshape(msg.height, msg.row_step)[:, : msg.width * msg.point_step]
        a = np.ascontiguousarray(rows).view(dt).reshape(-1)
    else:
        a = np.frombuffer(msg.data, dtype=dt)
    xyz = np.stack([a["x"], a["y"], a["z"]], axis=1).astype(np.float64)
    return xyz, {name: a[name].astype(a[name].dtype.newbyteorder("=")) for name in ("intensity", "ring", "time")}


def decoding_rows(pts, repeat):
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.LATEST)
    rows = ["| layout | bytes | occmap | plain NumPy | occmap / NumPy time |", "|---|---:|---:|---:|---:|"]
    cases = {"32-byte points, little-endian": velodyne_message(ts, pts),
             "32-byte points, big-endian": velodyne_message(ts, pts, big_endian=True),
             "organised 32 rows, rows padded by 16 bytes": velodyne_message(ts, pts, height=32, row_pad=16)}
    for label, msg in cases.items():
        ours, theirs = decode_point_cloud2(msg, finite_only=False), plain_numpy(msg)
        assert np.array_equal(ours.points, theirs[0]) and all(np.array_equal(ours.fields[k], v) for k, v in theirs[1].items())
        t_ours, t_numpy = median_times([lambda: decode_point_cloud2(msg, finite_only=False), lambda: plain_numpy(msg)],
                                       number=20, repeat=repeat)
        size = msg.data.nbytes
        rows.append(f"| {label} | {size:,} | {size / t_ours / 1e9:.2f} GB/s ({t_ours * 1e3:.2f} ms) | "
                    f"{size / t_numpy / 1e9:.2f} GB/s ({t_numpy * 1e3:.2f} ms) | {t_ours / t_numpy:.2f}× |")
    return "\n".join(rows)


def bag_rows(pts, clouds, repeat):
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin, Writer as Writer2
    from rosbags.typesys import Stores, get_typestore

    rows = ["| bag | size | read + decode | decode alone | reading's share |", "|---|---:|---:|---:|---:|"]
    with tempfile.TemporaryDirectory() as tmp:
        for kind in ("ROS 1", "ROS 2 sqlite3", "ROS 2 MCAP"):
            ts = get_typestore(Stores.ROS1_NOETIC if kind == "ROS 1" else Stores.LATEST)
            msg = velodyne_message(ts, pts)
            if kind == "ROS 1":
                path, writer, raw = Path(tmp) / "b.bag", Writer1(Path(tmp) / "b.bag"), ts.serialize_ros1(msg, CLOUD)
            else:
                path = Path(tmp) / kind.replace(" ", "_")
                plugin = StoragePlugin.MCAP if "MCAP" in kind else StoragePlugin.SQLITE3
                writer, raw = Writer2(path, version=9, storage_plugin=plugin), ts.serialize_cdr(msg, CLOUD)
            with writer:
                c = writer.add_connection("/points", CLOUD, typestore=ts)
                for k in range(clouds):
                    writer.write(c, (k + 1) * 100_000_000, raw)
            size = sum(f.stat().st_size for f in ([path] if path.is_file() else path.iterdir()))

            def read_all():
                n = 0
                with open_bag(path) as bag:
                    for m in bag.messages("/points", msgtype=CLOUD):
                        n += len(decode_point_cloud2(m.msg).points)
                assert n == clouds * len(pts)

            def decode_only():
                for _ in range(clouds):
                    decode_point_cloud2(msg)

            t_read, t_decode = median_times([read_all, decode_only], number=1, repeat=repeat)
            rows.append(f"| {kind}, {clouds} clouds | {size / 2**20:.0f} MiB | {t_read:.3f} s ({size / t_read / 1e9:.2f} GB/s) | "
                        f"{t_decode:.3f} s | {(t_read - t_decode) / t_read:.0%} |")
    return "\n".join(rows)


def _writer(kind, path, ts):
    """A rosbags writer of ``kind`` at ``path`` and its serializer."""
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin, Writer as Writer2

    if kind == "ROS 1":
        return Writer1(path.with_suffix(".bag")), ts.serialize_ros1, path.with_suffix(".bag")
    plugin = StoragePlugin.MCAP if "MCAP" in kind else StoragePlugin.SQLITE3
    return Writer2(path, version=9, storage_plugin=plugin), ts.serialize_cdr, path


def _header(ts, stamp, frame):
    T = ts.types
    sec = int(stamp // 1)
    time = T["builtin_interfaces/msg/Time"](sec=sec, nanosec=round((stamp - sec) * 1e9))
    extra = {"seq": 0} if "seq" in ts.fielddefs["std_msgs/msg/Header"][1][0] else {}
    return T["std_msgs/msg/Header"](stamp=time, frame_id=frame, **extra)


def _tf(ts, stamp, parent, child, translation, yaw):
    T = ts.types
    header = _header(ts, stamp, parent)
    tr = T["geometry_msgs/msg/Transform"](translation=T["geometry_msgs/msg/Vector3"](x=translation[0], y=translation[1],
                                                                                     z=translation[2]),
                                          rotation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=np.sin(yaw / 2),
                                                                                     w=np.cos(yaw / 2)))
    stamped = T["geometry_msgs/msg/TransformStamped"](header=header, child_frame_id=child, transform=tr)
    return T[TF](transforms=[stamped]), header


def _typestore(kind):
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC if kind == "ROS 1" else Stores.LATEST)
    if kind == "ROS 1":  # Noetic's store holds no tf2_msgs
        ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", TF))
    return ts


def write_map_bag(path, kind, messages):
    """A bag of ``messages(ts)``: (topic, type, stamp s, message)."""
    ts = _typestore(kind)
    writer, serialize, path = _writer(kind, path, ts)
    with writer:
        conns = {}
        for topic, msgtype, stamp, msg in messages(ts):
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=ts)
            writer.write(conns[topic], round(stamp * 1e9), serialize(msg, msgtype))
    return path


def map3d_rows(pts, clouds, repeat):
    from occmap._threads import read_ahead
    from occmap.octree import OcTree
    from occmap.sources import BagClouds

    def messages(ts):
        yield "/tf_static", TF, 0.5, _tf(ts, 0.0, "base_link", "velodyne", (0.0, 0.0, 1.8), 0.0)[0]
        for k in range(clouds):
            stamp = 1.0 + 0.1 * k
            msg = velodyne_message(ts, pts)
            yield "/tf", TF, stamp, _tf(ts, stamp, "map", "base_link", (1.5 * k, 0.2 * k, 0.0), 0.05 * k)[0]
            msg.header.stamp = _tf(ts, stamp, "map", "base_link", (0, 0, 0), 0.0)[1].stamp
            yield "/points", CLOUD, stamp, msg

    rows = ["| bag | clouds, points | map end to end | insertion alone | end to end / insertion | "
            "lower quartiles: end to end / insertion | rounds with > 0.1 s system time: end to end / insertion | "
            "reading and placing alone | insertion in a plain loop (end to end / it) |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    with tempfile.TemporaryDirectory() as tmp:
        for kind in ("ROS 1", "ROS 2 MCAP"):
            path = write_map_bag(Path(tmp) / kind.replace(" ", "_"), kind, messages)
            placed = [(c.world_points(), c.origin) for c in BagClouds(path)]
            assert len(placed) == clouds

            def end_to_end():  # as map3d: the next cloud read while this one is inserted
                tree = OcTree(0.1)
                for c in read_ahead(BagClouds(path)):
                    tree.insert_point_cloud(c.world_points(), c.origin, -1.0, False)
                return tree

            def insertion():  # the same loop over the clouds already placed: the same reader thread and switch interval
                tree = OcTree(0.1)
                for world, origin in read_ahead(placed):
                    tree.insert_point_cloud(world, origin, -1.0, False)
                return tree

            def plain_loop():  # as a caller's loop would: Python's 5 ms switch interval
                tree = OcTree(0.1)
                for world, origin in placed:
                    tree.insert_point_cloud(world, origin, -1.0, False)
                return tree

            def reading():
                for c in BagClouds(path):
                    c.world_points()

            assert end_to_end().num_nodes() == insertion().num_nodes() == plain_loop().num_nodes()
            system = ([], [])
            rounds = round_times([system_time(end_to_end, system[0]), system_time(insertion, system[1]), reading,
                                  plain_loop], number=1, repeat=repeat)
            t_all, t_insert, t_read, t_plain = (statistics.median(r) for r in rounds)
            q_all, q_insert = (statistics.quantiles(r, n=4)[0] for r in rounds[:2])
            slow = [sum(s > _SLOW_SYSTEM_S for s in seconds[1:]) for seconds in system]  # (not the warm-up call)
            n = sum(len(w) for w, _ in placed)
            rows.append(f"| {kind}, 3D at 0.1 m | {clouds}, {n:,} | {t_all:.3f} s | {t_insert:.3f} s | "
                        f"{t_all / t_insert:.2f}× | {q_all:.3f} s / {q_insert:.3f} s: **{q_all / q_insert:.2f}×** | "
                        f"{slow[0]} / {slow[1]} of {repeat} | "
                        f"{t_read:.3f} s ({t_read / t_insert:.0%} of the insertion) | "
                        f"{t_plain:.3f} s ({t_all / t_plain:.2f}×) |")
    return "\n".join(rows)


#: System time that marks a round as one that touched memory its host had taken back (other rounds
#: take 0.02-0.05 s).
_SLOW_SYSTEM_S = 0.1


def system_time(fn, seconds: list):
    """``fn``, appending the system CPU time of each call to ``seconds``."""
    def timed():
        before = os.times().system
        result = fn()
        seconds.append(os.times().system - before)
        return result

    return timed


def fresh_choices(fn, picks):
    """``fn`` run as a new ``occmap map2d`` process runs it: the grid's choice of threads
    (:data:`occmap.grid2d._kernels.THREADS`, one per process) learnt afresh, not carried over from
    the call timed before (a choice settled on one thread in one round held for twenty: the
    insertion alone took 0.051 s in one row, 0.085 s in the next). The paths the call's
    insertions take are added to ``picks`` (True: several threads)."""
    from occmap.grid2d import _kernels

    def run():
        choice = _kernels.THREADS
        choice.forget()
        choose = choice.choose

        @contextmanager
        def counted(work, sample=True):
            with choose(work, sample) as parallel:
                picks.append(parallel)
                yield parallel

        choice.choose = counted
        try:
            return fn()
        finally:
            del choice.choose

    return run


def map2d_rows(scans, repeat):
    from occmap.mapping2d import map_scan_stream, map_scans
    from occmap.scan import concat_stacks, stack_scans
    from occmap.sources import BagScans

    def messages(ts):
        T = ts.types
        for s in scans:
            yield "/tf", TF, s.stamp, _tf(ts, s.stamp, "odom", "laser", (s.pose[0], s.pose[1], 0.0), s.pose[2])[0]
            inc = float(s.angles[1] - s.angles[0])
            yield "/scan", SCAN, s.stamp, T[SCAN](header=_header(ts, s.stamp, "laser"), angle_min=float(s.angles[0]),
                                                  angle_max=float(s.angles[-1]), angle_increment=inc,
                                                  time_increment=0.0, scan_time=0.0, range_min=0.0,
                                                  range_max=s.max_range, ranges=s.ranges.astype(np.float32),
                                                  intensities=np.zeros(0, np.float32))

    rows = ["| bag | scans, beams | map end to end | insertion alone | end to end / insertion | "
            "reading and placing alone | grid calls on several threads: end to end / insertion |",
            "|---|---:|---:|---:|---:|---:|---:|"]
    with tempfile.TemporaryDirectory() as tmp:
        for kind in ("ROS 1", "ROS 2 MCAP"):
            path = write_map_bag(Path(tmp) / kind.replace(" ", "_"), kind, messages)
            stack = stack_scans(BagScans(path))
            # tf placed the scans at their poses (but where the log's stamps go back, 4 times: tf interpolates there)
            assert np.mean(np.all(np.abs(stack.poses - [s.pose for s in scans]) < 1e-6, axis=1)) > 0.99

            def end_to_end():
                return map_scan_stream(BagScans(path), 0.05)

            def insertion():
                return map_scans(stack, 0.05)

            def reading():  # what map_scan_stream reads: the source's runs of stacked scans
                concat_stacks(list(BagScans(path).stacks()))

            assert np.array_equal(end_to_end().grid.log_odds(), insertion().grid.log_odds(), equal_nan=True)
            picks_all, picks_insert = [], []
            t_all, t_insert, t_read = median_times([fresh_choices(end_to_end, picks_all),
                                                    fresh_choices(insertion, picks_insert), reading],
                                                   number=1, repeat=repeat)
            rows.append(f"| {kind}, 2D at 0.05 m | {len(scans)}, {stack.ranges.size:,} | {t_all:.3f} s | "
                        f"{t_insert:.3f} s | {t_all / t_insert:.2f}× | {t_read:.3f} s ({t_read / t_insert:.0%} of "
                        f"the insertion) | {np.mean(picks_all):.0%} / {np.mean(picks_insert):.0%} |")
    return "\n".join(rows)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clouds", type=int, default=40, help="clouds per bag (default 40)")
    ap.add_argument("--map-clouds", type=int, default=30, help="clouds in the bag mapped end to end (default 30)")
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--no-write", action="store_true", help="print, do not rewrite BENCHMARKS.md")
    args = ap.parse_args()
    data = find_shared_data(Path(__file__).resolve().parent)
    if data is None:
        sys.exit("the shared data is needed: set OCCMAP_DATA or place it at ../shared/data")
    pts = read_pcd(data / "scans3d" / "hdl32_pair" / "251370668.pcd", drop_origin=False).points.astype(np.float32)
    intel = read_carmen(data / "carmen" / "intel-corrected.log.gz").scans
    t0 = time.perf_counter()
    body = "\n\n".join([
        "## ROS bags: PointCloud2 decoding and bags read (`benchmarks/bench_bags.py`)",
        f"One HDL-32E scan ({len(pts):,} points) as a Velodyne driver packs it (x y z, intensity float32, ring "
        "uint16, time float32 in 32-byte points). `decode_point_cloud2` works for any layout; the plain NumPy "
        "decode is what one writes for this layout alone (one structured view, x y z stacked into float64, the "
        "fields copied). Both give the same arrays. Medians of alternating rounds.",
        decoding_rows(pts, args.repeat),
        f"A bag of {args.clouds} such clouds, written by rosbags, read start to end (open, rosbags deserialises "
        "each message, then `decode_point_cloud2`), beside decoding the same messages alone.",
        bag_rows(pts, args.clouds, args.repeat),
        f"Maps from bags end to end against the insertion alone (target: at most 10 % above). 3D: {args.map_clouds} "
        "copies of the scan driven 1.5 m apart, placed by tf (a static mount and moving `map → base_link`), "
        "into an octree at 0.1 m as `occmap map3d BAG` does — open, read tf, stream, decode, look up the pose, "
        "insert — beside inserting the same placed clouds. 2D: the Intel corrected log (910 scans) as LaserScan "
        "+ tf (the laser's pose as `odom → laser`) into a grid at 0.05 m as `occmap map2d BAG` does, beside "
        "`map_scans` of the same placed scans (checked to be the log's poses). "
        f"The maps are checked equal; medians of {3 * args.repeat} alternating rounds. This machine is a virtual "
        "one that hands free memory back to its host (virtio-balloon free page reporting, 2 MiB blocks) and "
        "shares its cores with the host's other guests: a 3D round may take 0.2-0.35 s more system time than "
        "the others' 0.02-0.05 s with as many page faults (most likely its pages are memory the host took back "
        "and must supply again; the table counts those rounds), or more user time for the same work, so that one "
        "map end to end took 0.68-1.24 s in eight rounds and a median of 21 moves by 0.2 s (0.74× to 1.36× from "
        "run to run). The 3D rows compare the lower quartiles too, which such rounds disturb least; the target is "
        "judged there. Both read ahead on a thread of their own (`occmap._threads.read_ahead`) "
        "while the kernels insert, which hides the reading only where a core is idle. \"Reading and placing alone\" times the bag's part alone (open, tf, stream, decode, "
        "place: `world_points` for clouds; for scans the runs of stacked scans `BagScans.stacks()` gives), the "
        "figure that the machine's load disturbs least. The octree's insertion hands work to Python worker "
        "threads, which the interpreter's switch interval delays: the 3D insertion alone is timed through the same "
        "`read_ahead` over the clouds already placed (its 0.1 ms interval; like against like), and in a plain loop "
        "(Python's 5 ms, a caller's own loop) in the last column. The grid chooses one thread or two per call by their "
        "measured costs (`ThreadChoice`, one per process); each 2D map is timed with that choice learnt afresh, "
        "as a new `occmap map2d` process learns it, not left by the map timed before it (carried over, a choice "
        "of one thread held for twenty rounds and the insertion alone took 0.051 s in one row, 0.085 s in the "
        "next); the last column counts the grid's calls that took two threads.",
        # many rounds steady the medians: seven of the 3D rows read 0.95-1.17x from run to run
        map3d_rows(pts, args.map_clouds, 3 * args.repeat),
        map2d_rows(intel, 3 * args.repeat),
    ])
    print(body)
    print(f"\n({time.perf_counter() - t0:.0f} s)")
    if not args.no_write:
        write_section("bench_bags", body)


if __name__ == "__main__":
    main()
