"""Scan sources read from files: point-cloud files (poses from the files or a pose file) and
CARMEN laser logs. Both open any scan by number, so a world-scale build's workers each read just
the scans their region needs."""

from __future__ import annotations

from collections import Counter
from functools import lru_cache
from pathlib import Path
from typing import Iterator

from ..cloud import PointCloud


class CloudFiles:
    """Point-cloud files as a scan source, in order: each file one scan with its pose (PCD
    ``VIEWPOINT``, 3DTK ``.frames``; identity where the format has none), an OctoMap ScanGraph
    (``.graph``) one scan per node. ``**read_options`` go to :func:`occmap.io.pointclouds.read_cloud`.

    ``poses`` (a :class:`~occmap.io.poses.PoseTrack`) replaces the files' poses: pose ``k`` for
    scan ``k`` (a file holding fewer poses than there are scans raises
    :class:`~occmap.errors.InvalidArgumentError` naming both counts)."""

    def __init__(self, paths, poses=None, **read_options):
        self.paths = [str(p) for p in paths]
        self.read_options = read_options
        self.dropped = Counter()  # nothing is: every file is a scan
        self._scans = []  # (file, node or None)
        for path in self.paths:
            if path.endswith(".graph"):
                self._scans += [(path, k) for k in range(len(_graph(path).nodes))]
            else:
                self._scans.append((path, None))
        self._poses = None if poses is None else poses.by_index(len(self._scans), "point clouds")

    def __iter__(self) -> Iterator:
        return (self.scan(k) for k in range(len(self)))

    def __len__(self) -> int:
        return len(self._scans)

    def scan(self, k: int):
        """Scan ``k`` as a :class:`occmap.cloud.PointCloud`."""
        path, node = self._scans[k]
        if node is not None:
            cloud = _graph(path).nodes[node]
        else:
            from ..io.pointclouds import read_cloud

            cloud = read_cloud(path, **self.read_options)
        if self._poses is None:
            return cloud
        return PointCloud(cloud.points, self._poses[k], cloud.stamp, cloud.dropped)

    def name(self, k: int) -> str:
        path, node = self._scans[k]
        return path if node is None else f"{path} node {node}"


@lru_cache(maxsize=1)
def _graph(path: str):
    """The last ScanGraph read in this process (a build reads its nodes one after another)."""
    from ..io.scangraph import read_scangraph

    return read_scangraph(Path(path))


class CarmenScans:
    """The laser scans of a CARMEN log as a scan source (``read_options`` as for
    :func:`occmap.io.carmen.read_carmen`: ``every``, ``max_range``, ``lenient``, …). Iterating
    streams the log (nothing held but a line); ``len`` and ``scan(k)`` read it whole, once per
    process."""

    def __init__(self, path, **read_options):
        self.path = str(path)
        self.read_options = read_options
        self.dropped = Counter()  # the reader counts what it skips in :attr:`stats`
        self._streamed = None

    def __len__(self) -> int:
        return len(self._log())

    def __iter__(self) -> Iterator:
        from ..io.carmen import CarmenStats, iter_carmen

        self._streamed = CarmenStats()
        return iter_carmen(self.path, stats=self._streamed, **self.read_options)

    def scan(self, k: int):
        return self._log().scans[k]

    def name(self, k: int) -> str:
        return f"{self.path} scan {k}"

    @property
    def stats(self):
        """The reader's counts (:class:`occmap.io.carmen.CarmenStats`): of the last iteration
        when there was one, else of the whole log."""
        return self._streamed if self._streamed is not None else self._log().stats

    def _log(self):
        return _carmen(self.path, tuple(sorted(self.read_options.items())))


@lru_cache(maxsize=1)
def _carmen(path: str, options: tuple):
    """The last CARMEN log read in this process."""
    from ..io.carmen import read_carmen

    return read_carmen(path, **dict(options))
