"""Bags written with rosbags' own writers (ROS 1, ROS 2 sqlite3, ROS 2 MCAP) for the bag tests:
the messages, built from a type store, and the writer."""

from __future__ import annotations

import math

import numpy as np
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin, Writer as Writer2
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

KINDS = ("ros1", "ros1_chunks", "sqlite3", "mcap")  # ros1_chunks: a ROS 1 bag read without rosbags' index
SCAN, CLOUD, ODOM, TF, TF_STATIC = ("sensor_msgs/msg/LaserScan", "sensor_msgs/msg/PointCloud2",
                                    "nav_msgs/msg/Odometry", "tf2_msgs/msg/TFMessage", "tf2_msgs/msg/TFMessage")
SHARED_BAG = "rosbag/laser_scan_matcher_demo.bag"
MOUNT = (0.12, -0.03, 0.25)  # base_link -> laser, a static sensor mount (metres)


# ---------------------------------------------------------------------- building messages


class Msgs:
    """ROS messages of one type store (ROS 1's Header has ``seq``, ROS 2's has not)."""

    def __init__(self, typestore):
        self.ts = typestore
        self.T = typestore.types

    def header(self, stamp: float, frame: str):
        sec = math.floor(stamp)
        time = self.T["builtin_interfaces/msg/Time"](sec=sec, nanosec=round((stamp - sec) * 1e9))
        extra = {"seq": 0} if "seq" in self.ts.fielddefs["std_msgs/msg/Header"][1][0] else {}
        return self.T["std_msgs/msg/Header"](stamp=time, frame_id=frame, **extra)

    def laser_scan(self, stamp, frame, ranges, angle_min, angle_inc, range_min, range_max):
        n = len(ranges)
        return self.T[SCAN](header=self.header(stamp, frame), angle_min=angle_min,
                            angle_max=angle_min + (n - 1) * angle_inc, angle_increment=angle_inc,
                            time_increment=0.0, scan_time=0.0, range_min=range_min, range_max=range_max,
                            ranges=np.asarray(ranges, dtype=np.float32), intensities=np.zeros(0, np.float32))

    def transform(self, stamp, parent, child, t, q_xyzw):
        G = self.T
        return G["geometry_msgs/msg/TransformStamped"](
            header=self.header(stamp, parent), child_frame_id=child,
            transform=G["geometry_msgs/msg/Transform"](
                translation=G["geometry_msgs/msg/Vector3"](x=t[0], y=t[1], z=t[2]),
                rotation=G["geometry_msgs/msg/Quaternion"](x=q_xyzw[0], y=q_xyzw[1], z=q_xyzw[2], w=q_xyzw[3])))

    def tf(self, transforms):
        return self.T[TF](transforms=transforms)

    def odometry(self, stamp, parent, child, t, q_xyzw):
        G = self.T
        pose = G["geometry_msgs/msg/Pose"](position=G["geometry_msgs/msg/Point"](x=t[0], y=t[1], z=t[2]),
                                           orientation=G["geometry_msgs/msg/Quaternion"](
                                               x=q_xyzw[0], y=q_xyzw[1], z=q_xyzw[2], w=q_xyzw[3]))
        twist = G["geometry_msgs/msg/Twist"](linear=G["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                                             angular=G["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0))
        return G[ODOM](header=self.header(stamp, parent), child_frame_id=child,
                       pose=G["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
                       twist=G["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)))

    def cloud(self, stamp, frame, height, width, fields, point_step, row_step, data, big_endian, dense):
        F = self.T["sensor_msgs/msg/PointField"]
        return self.T[CLOUD](header=self.header(stamp, frame), height=height, width=width,
                             fields=[F(name=n, offset=o, datatype=d, count=c) for n, o, d, c in fields],
                             is_bigendian=big_endian, point_step=point_step, row_step=row_step,
                             data=np.frombuffer(data, dtype=np.uint8), is_dense=dense)


def standard_store(kind):
    """The type store of the standard messages for a bag of ``kind``."""
    if kind.startswith("ros1"):
        ts = get_typestore(Stores.ROS1_NOETIC)  # holds no tf2_msgs: add TFMessage as ROS defines it
        ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", TF))
        return ts
    return get_typestore(Stores.LATEST)


def write_bag(tmp_path, kind, build, name="test", typestore=None):
    """Write a bag of ``kind`` whose messages ``build(Msgs)`` returns as (topic, type, time s, msg),
    their types defined by ``typestore`` (default: the standard ones)."""
    msgs = Msgs(typestore or standard_store(kind))
    if kind.startswith("ros1"):
        path = tmp_path / f"{name}.bag"
        writer, serialize = Writer1(path), msgs.ts.serialize_ros1
    else:
        path = tmp_path / name
        plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
        writer, serialize = Writer2(path, version=9, storage_plugin=plugin), msgs.ts.serialize_cdr
    with writer:
        connections = {}
        for topic, msgtype, time, msg in build(msgs):
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msgtype, typestore=msgs.ts)
            writer.write(connections[topic], round(time * 1e9), serialize(msg, msgtype))
    return path


def quat_xyzw_of_yaw(theta):
    return (0.0, 0.0, math.sin(theta / 2), math.cos(theta / 2))


def packed(columns, point_step, order):
    """Points as bytes: ``columns`` = [(name, offset, numpy type, values)] at their offsets."""
    dt = np.dtype({"names": [c[0] for c in columns], "formats": [np.dtype(c[2]).newbyteorder(order) for c in columns],
                   "offsets": [c[1] for c in columns], "itemsize": point_step})
    rec = np.zeros(len(columns[0][3]), dtype=dt)
    for name, _, _, values in columns:
        rec[name] = values
    return rec.tobytes()


ROS_TYPE = {"i1": 1, "u1": 2, "i2": 3, "u2": 4, "i4": 5, "u4": 6, "f4": 7, "f8": 8}
