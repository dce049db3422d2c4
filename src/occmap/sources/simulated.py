"""The procedural town drive (:mod:`occmap.sim.city`) as a scan source, for benchmarks and
demos of world-scale builds."""

from __future__ import annotations

from collections import Counter
from typing import Iterator


class SimulatedDrive:
    """The LiDAR drive through the procedural town (:mod:`occmap.sim.city`) as a scan source:
    scan ``k`` is made where it is needed, the same bits in every process."""

    def __init__(self, drive=None, stop: int | None = None):
        from ..sim.city import CityDrive

        self.drive = CityDrive() if drive is None else drive
        self.stop = self.drive.n_scans if stop is None else min(int(stop), self.drive.n_scans)
        self.dropped = Counter()  # every scan is made

    def __len__(self) -> int:
        return self.stop

    def __iter__(self) -> Iterator:
        return (self.scan(k) for k in range(len(self)))

    def scan(self, k: int):
        from ..sim.city import city_scan

        if not 0 <= k < self.stop:
            raise IndexError(f"scan {k} of {self.stop}")
        return city_scan(k, self.drive)

    def name(self, k: int) -> str:
        return f"simulated town drive scan {k}"
