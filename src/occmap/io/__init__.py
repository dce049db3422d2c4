"""Readers and writers: bytes in, plain arrays and :class:`~occmap.scan.LaserScan` /
:class:`~occmap.cloud.PointCloud` records out."""

from ..cloud import PointCloud
from .pointclouds import (
    read_cloud,
    read_kitti_bin,
    read_pcd,
    read_ply,
    read_uos,
    read_xyz,
    write_pcd,
    write_ply,
    write_xyz,
)
from .scangraph import ScanGraph, read_scangraph, write_scangraph

__all__ = [
    "PointCloud",
    "ScanGraph",
    "read_cloud",
    "read_kitti_bin",
    "read_pcd",
    "read_ply",
    "read_scangraph",
    "read_uos",
    "read_xyz",
    "write_pcd",
    "write_ply",
    "write_scangraph",
    "write_xyz",
]
