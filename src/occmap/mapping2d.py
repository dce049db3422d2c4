"""Building a 2D map from a laser log: the job behind ``occmap map2d`` and the demo."""

from __future__ import annotations

import sys
from dataclasses import dataclass

import numpy as np

from ._clock import WorkClock
from .errors import InvalidArgumentError
from .grid2d import LidarModel, OccupancyGrid2D
from .grid2d.grid import DEFAULT_MAX_EXTENT
from .scan import ScanStack


@dataclass
class MappingSummary:
    scans: int
    points: int
    dropped: int
    beyond_max_range: int
    seconds: float
    grid: OccupancyGrid2D

    def lines(self) -> list[str]:
        H, W = self.grid.shape
        ml = self.grid.maximum_likelihood()
        res = self.grid.resolution
        return [
            f"scans {self.scans:,}, beams {self.points:,}, dropped readings {self.dropped:,}, "
            f"no-return readings {self.beyond_max_range:,}",
            f"map {W} × {H} cells at {res} m ({W * res:.1f} m × {H * res:.1f} m), origin "
            f"({self.grid.origin[0]:.2f}, {self.grid.origin[1]:.2f}); occupied {(ml == 1).sum():,}, "
            f"free {(ml == 0).sum():,}, unknown {(ml == -1).sum():,} cells",
            f"integrated in {self.seconds:.2f} s",
        ]


def map_scans(stack: ScanStack, resolution: float, max_range: float | None = None, chunk: int = 200,
              progress: bool = False, model: LidarModel | None = None,
              max_extent: float | None = DEFAULT_MAX_EXTENT) -> MappingSummary:
    """Integrate a stacked log into a new growing grid.

    A reading at or beyond its own scan's maximum range means "no return"; it frees the cells up
    to ``max_range`` (default: the largest maximum range of the log) and marks nothing.
    ``seconds`` of the summary is the integration alone (no kernel loading, no progress bar).
    A scan that would grow the map beyond ``max_extent`` metres per side (see
    :class:`OccupancyGrid2D`) stops it with an :class:`~occmap.errors.InvalidArgumentError` that
    names the scan's number in the log.
    """
    poses, ranges, angles, max_ranges, _ = stack
    grid = OccupancyGrid2D(resolution, max_extent=max_extent)
    n = len(poses)
    limit = float(max_range) if max_range is not None else (float(max_ranges.max()) if n else 1.0)
    no_return = ranges >= max_ranges[:, None]
    ranges = np.where(no_return, np.inf, ranges)
    clock = WorkClock()
    for start in range(0, n, chunk):
        stop = min(n, start + chunk)
        a = angles if angles.ndim == 1 else angles[start:stop]
        with clock.running():
            try:
                grid.insert_scans(poses[start:stop], ranges[start:stop], a, max_range=limit, model=model)
            except InvalidArgumentError as e:
                raise InvalidArgumentError(f"scans {start}–{stop - 1} of the log (indices below count from {start}): "
                                           f"{e}") from None
        if progress:
            done = stop / n
            bar = "#" * int(30 * done)
            print(f"\r[{bar:<30s}] {100 * done:5.1f}% {stop:,}/{n:,} scans", end="", file=sys.stderr, flush=True)
    if progress and n:
        print(file=sys.stderr)
    s = grid.stats
    return MappingSummary(s["scans"], s["points"], s["dropped"], s["beyond_max_range"], clock.seconds, grid)
