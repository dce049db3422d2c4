"""Readers and writers: bytes in, plain arrays and :class:`~occmap.scan.LaserScan` /
:class:`~occmap.cloud.PointCloud` records out.

Readers read regular files only and bound the memory a file can make them use by its size
(:func:`read_limits` raises the bound for a file you trust; the rule is in :mod:`._limits`); every
error a file can cause is an :class:`~occmap.errors.OccmapError` naming the file. Writers replace
a file atomically (:func:`occmap._files.write_atomic`)."""

from ..cloud import PointCloud
from ._limits import ReadLimits, read_limits
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
    "ReadLimits",
    "ScanGraph",
    "read_cloud",
    "read_kitti_bin",
    "read_limits",
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
