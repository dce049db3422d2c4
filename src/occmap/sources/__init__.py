"""Scan sources: where the maps, the local map and the localizer read their scans, whatever the
input — a CARMEN log, point-cloud files with or without a pose file, a ROS bag with tf or
odometry, or the simulated town.

A source is an iterable of records with their poses, in order — :class:`~occmap.scan.LaserScan`
for grids, :class:`~occmap.cloud.PointCloud` for octrees — with ``len(source)`` the scans it
looks at and ``source.dropped`` (a :class:`collections.Counter`, reason → count) the ones it
could not place or that held nothing, filled in as the iteration goes. File sources
(:class:`CloudFiles`, :class:`CarmenScans`, :class:`SimulatedDrive`) also open scan ``k`` by
number, ``source.scan(k)``, and name it, ``source.name(k)``: a world-scale build's workers
(:mod:`occmap.world.build`) read just the scans their region needs. Bag sources
(:class:`BagScans`, :class:`BagClouds`) stream.
"""

from .bags import BagClouds, BagScans
from .files import CarmenScans, CloudFiles
from .simulated import SimulatedDrive

__all__ = ["BagClouds", "BagScans", "CarmenScans", "CloudFiles", "SimulatedDrive"]
