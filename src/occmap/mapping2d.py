"""Building a 2D map from a laser log: the job behind ``occmap map2d`` and the demo."""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Iterable

import numpy as np

from ._clock import WorkClock
from .errors import InvalidArgumentError
from .grid2d import LidarModel, OccupancyGrid2D
from .grid2d.grid import DEFAULT_MAX_EXTENT
from ._progress import Progress
from ._threads import read_ahead
from .scan import LaserScan, ScanStack, concat_stacks, stack_scans


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
              max_extent: float | None = DEFAULT_MAX_EXTENT, recorder=None) -> MappingSummary:
    """Integrate a stacked log into a new growing grid.

    A reading at or beyond its own scan's maximum range means "no return"; it frees the cells up
    to ``max_range`` (default: the largest maximum range of the log) and marks nothing.
    ``seconds`` of the summary is the integration alone (no kernel loading, no progress bar).
    A scan that would grow the map beyond ``max_extent`` metres per side (see
    :class:`OccupancyGrid2D`) stops it with an :class:`~occmap.errors.InvalidArgumentError` that
    names the scan's number in the log.
    A ``recorder`` (:class:`~occmap.mapping2d_recording.MappingRecorder`) is told each batch of
    ``recorder.every`` scans once they are in the grid (then the chunks are that long).
    """
    n = len(stack.poses)
    chunk = recorder.every if recorder is not None else chunk
    limit = float(max_range) if max_range is not None else (float(stack.max_ranges.max()) if n else 1.0)
    chunks = (stack.take(slice(s, s + chunk)) for s in range(0, n, chunk))
    return _integrate(chunks, resolution, lambda _: limit, model, max_extent, Progress(n, "scans", progress),
                      recorder)


def map_scan_stream(scans: Iterable[LaserScan], resolution: float, max_range: float | None = None,
                    chunk: int = 200, progress: Progress | None = None, model: LidarModel | None = None,
                    max_extent: float | None = DEFAULT_MAX_EXTENT, recorder=None) -> MappingSummary:
    """:func:`map_scans` for scans that arrive one by one (a bag, a log read as it goes): they are
    stacked ``chunk`` at a time, the next chunk read on a thread of its own while the grid takes
    the last (:func:`occmap._threads.read_ahead`), so memory holds two or three chunks. The first
    chunks are smaller (:func:`_sizes`: :data:`FIRST_CHUNK` scans three times, then doubling up to
    ``chunk``): nothing overlaps the reading of the first, so the grid starts as soon as a few scans
    are in, and the grid's tries of its two thread paths (its second and third calls,
    :class:`occmap._threads.ThreadChoice`) cost little where the slower one is tried. A source that stacks
    its scans itself (``scans.stacks()``, a bag's) has its stacks cut to those lengths at most,
    never joined (a copy): a chunk ends where a stack does. Without ``max_range``, no-return
    readings clear up to the largest maximum range of their chunk (one sensor has one; for scans
    of one maximum range the grid is :func:`map_scans`'s to the bit). ``progress`` is told the
    scans done; a ``recorder`` each batch, as by :func:`map_scans` (batches of its ``every`` scans
    then, from the first)."""
    first = FIRST_CHUNK
    if recorder is not None:
        chunk = first = recorder.every
    if hasattr(scans, "stacks"):  # a source that decodes many scans at once (a bag's)
        stacks = _restacked(scans.stacks(), chunk, first, exact=recorder is not None)
    else:
        stacks = (stack_scans(batch) for batch in _batches(scans, chunk, first))
    chunks = read_ahead(stacks)
    return _integrate(chunks, resolution, lambda c: float(max_range) if max_range is not None
                      else float(c.max_ranges.max()), model, max_extent, progress, recorder)


#: Scans in the first chunk of :func:`map_scan_stream` (a bag's take 1-2 ms to read)
FIRST_CHUNK = 25


def _sizes(size: int, first: int):
    """``first`` three times, then twice as many each time up to ``size``, for ever. The three
    short runs are a growing grid's first call (not timed: it touches new memory) and its first
    try of each thread path (:class:`occmap._threads.ThreadChoice`): on the Intel log the try of
    one thread on a third run of 100 scans cost 10.6 ms where two threads took about 6, and the
    stream took 1.05x ``map_scans``' time; the choice fixed, the runs' sizes cost nothing (1.00x,
    one thread or two)."""
    n = max(1, min(first, size))
    yield n
    yield n
    while True:
        yield n
        n = min(2 * n, size)


def _batches(items, size: int, first: int):
    """Lists of the items in order, as long as :func:`_sizes` says (the last shorter)."""
    it = iter(items)
    for n in _sizes(size, first):
        batch = list(itertools.islice(it, n))
        if not batch:
            return
        yield batch


def _restacked(stacks, size: int, first: int, exact: bool):
    """The scans of ``stacks`` in runs as long as :func:`_sizes` says (the last shorter). Unless
    ``exact``, a run also ends where a stack does: the rest of a stack goes in as it is, not
    copied together with the next stack's first scans (views of the stacks, no copy)."""
    sizes = _sizes(size, first)
    n = next(sizes)
    if not exact:
        for s in stacks:
            at, count = 0, len(s.poses)
            while at < count:
                take = min(n, count - at)
                yield s if take == count else s.take(slice(at, at + take))
                at += take
                if take == n:
                    n = next(sizes)
        return
    held, count = [], 0
    for s in stacks:
        held.append(s)
        count += len(s.poses)
        while count >= n:
            run = concat_stacks(held)
            yield run.take(slice(None, n))
            held, count = [run.take(slice(n, None))], count - n
            n = next(sizes)
    if count:
        yield concat_stacks(held)


def _integrate(chunks, resolution, limit_of, model, max_extent, progress, recorder) -> MappingSummary:
    """Insert stacked chunks of scans in order into a new grid; ``limit_of(chunk)`` is the range
    up to which its no-return readings clear."""
    grid = OccupancyGrid2D(resolution, max_extent=max_extent)
    clock = WorkClock()
    done = 0
    for c in chunks:
        ranges = np.where(c.ranges >= c.max_ranges[:, None], np.inf, c.ranges)
        limit = limit_of(c)
        with clock.running():
            try:
                grid.insert_scans(c.poses, ranges, c.angles, max_range=limit, model=model)
            except InvalidArgumentError as e:
                raise InvalidArgumentError(f"scans {done}–{done + len(c.poses) - 1} of the log (indices below count "
                                           f"from {done}): {e}") from None
        done += len(c.poses)
        if recorder is not None:
            recorder.add(grid, c.poses, ranges, c.angles, limit, c.stamps)
        if progress is not None:
            progress.update(done)
    if progress is not None:
        progress.close()
    s = grid.stats
    return MappingSummary(s["scans"], s["points"], s["dropped"], s["beyond_max_range"], clock.seconds, grid)
