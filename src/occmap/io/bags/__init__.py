"""ROS bags: ROS 1 ``.bag``, ROS 2 folders, ``.db3`` and ``.mcap`` files, read as streams of
messages (:mod:`.bag`; ROS 1 bags with an index ``rosbags`` rejects through :mod:`.ros1_chunks`),
and their messages decoded into occmap's arrays and records: point clouds (:mod:`.pointcloud2`),
planar scans (:mod:`.laserscan`, from the bytes, :mod:`.wire`), tf and odometry
(:mod:`.transforms`, likewise), after checking that the bag defines those types as ROS does
(:mod:`.definitions`).

Example::

    from occmap.io.bags import decode_point_cloud2, open_bag, read_frame_tree

    with open_bag("drive.mcap") as bag:
        tree = read_frame_tree(bag)
        for m in bag.messages("/points", msgtype="sensor_msgs/msg/PointCloud2"):
            cloud = decode_point_cloud2(m.msg)
            T_map_sensor = tree.lookup("map", cloud.frame_id, cloud.stamp)
"""

from .bag import Bag, Message, Topic, is_bag, open_bag
from .laserscan import ScanMessage, decode_laser_scan
from .pointcloud2 import CloudMessage, decode_point_cloud2, point_dtype
from .transforms import (
    Odometry,
    TransformsMessage,
    decode_odometry,
    decode_tf_message,
    read_frame_tree,
    read_odometry,
    ros_poses,
)
from .wire import frame_name

__all__ = [
    "Bag",
    "CloudMessage",
    "Message",
    "Odometry",
    "ScanMessage",
    "Topic",
    "TransformsMessage",
    "decode_laser_scan",
    "decode_odometry",
    "decode_point_cloud2",
    "decode_tf_message",
    "frame_name",
    "is_bag",
    "open_bag",
    "point_dtype",
    "read_frame_tree",
    "read_odometry",
    "ros_poses",
]
