"""Where a world-scale build reads its scans: a *scan source* is a picklable sequence of scans
that any process can open by number, so Dask workers (local or remote, sharing the files) each read
just the scans their region needs, in the same order.

A source has ``len(source)``, ``source.scan(k)``: scan ``k`` — for octrees a
:class:`~occmap.cloud.PointCloud` (its ``world_points()`` and ``origin`` are what a map inserts;
``has_pose`` false where the data gave no pose), for grids a :class:`~occmap.scan.LaserScan` —
and ``source.name(k)`` to name it in messages.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path


class CloudFiles:
    """Point-cloud files as a scan source, in order: each file one scan with its pose (PCD
    ``VIEWPOINT``, 3DTK ``.frames``; identity where the format has none), an OctoMap ScanGraph
    (``.graph``) one scan per node. ``**read_options`` go to :func:`occmap.io.pointclouds.read_cloud`."""

    def __init__(self, paths, **read_options):
        self.paths = [str(p) for p in paths]
        self.read_options = read_options
        self._scans = []  # (file, node or None)
        for path in self.paths:
            if path.endswith(".graph"):
                self._scans += [(path, k) for k in range(len(_graph(path).nodes))]
            else:
                self._scans.append((path, None))

    def __len__(self) -> int:
        return len(self._scans)

    def scan(self, k: int):
        """Scan ``k`` as a :class:`occmap.cloud.PointCloud`."""
        path, node = self._scans[k]
        if node is not None:
            return _graph(path).nodes[node]
        from ..io.pointclouds import read_cloud

        return read_cloud(path, **self.read_options)

    def name(self, k: int) -> str:
        path, node = self._scans[k]
        return path if node is None else f"{path} node {node}"


@lru_cache(maxsize=1)
def _graph(path: str):
    """The last ScanGraph read in this process (a build reads its nodes one after another)."""
    from ..io.scangraph import read_scangraph

    return read_scangraph(Path(path))


class SimulatedDrive:
    """The LiDAR drive through the procedural town (:mod:`occmap.sim.city`) as a scan source:
    scan ``k`` is made where it is needed, the same bits in every process."""

    def __init__(self, drive=None, stop: int | None = None):
        from ..sim.city import CityDrive

        self.drive = CityDrive() if drive is None else drive
        self.stop = self.drive.n_scans if stop is None else min(int(stop), self.drive.n_scans)

    def __len__(self) -> int:
        return self.stop

    def scan(self, k: int):
        from ..sim.city import city_scan

        if not 0 <= k < self.stop:
            raise IndexError(f"scan {k} of {self.stop}")
        return city_scan(k, self.drive)

    def name(self, k: int) -> str:
        return f"simulated town drive scan {k}"


class CarmenScans:
    """The laser scans of a CARMEN log as a scan source (``read_options`` as for
    :func:`occmap.io.carmen.read_carmen`: ``every``, ``max_range``, ``lenient``, …); each process
    reads the log once."""

    def __init__(self, path, **read_options):
        self.path = str(path)
        self.read_options = read_options
        self._count = len(_carmen(self.path, tuple(sorted(read_options.items()))))

    def __len__(self) -> int:
        return self._count

    def scan(self, k: int):
        return _carmen(self.path, tuple(sorted(self.read_options.items()))).scans[k]

    def name(self, k: int) -> str:
        return f"{self.path} scan {k}"

    @property
    def stats(self):
        """The reader's counts (:class:`occmap.io.carmen.CarmenStats`)."""
        return _carmen(self.path, tuple(sorted(self.read_options.items()))).stats


@lru_cache(maxsize=1)
def _carmen(path: str, options: tuple):
    """The last CARMEN log read in this process."""
    from ..io.carmen import read_carmen

    return read_carmen(path, **dict(options))
