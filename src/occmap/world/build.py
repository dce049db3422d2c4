"""Building a tiled map — octree or 2D grid — in parallel on Dask, equal to the map one process
builds.

Why it is exact. Clamping makes a voxel's log-odds depend on the order of its updates, so each
voxel must take its updates in scan order. The build partitions *space*: the plane is cut along
tile borders into as many regions as workers (:func:`partition`), and each worker takes every scan
that can reach its region, in scan order, and applies the part of each ray inside its region
(:class:`~occmap.world.octree_tiles.TiledOcTree` or :class:`~occmap.world.grid_tiles.TiledGrid2D`
with ``region``): its walk is the global walk, computed from the sensor. A voxel lies in exactly one region, so it gets the updates it gets in
one process, in the same order, whatever the number of workers, the tile size or the order in
which Dask runs the work.

The steps: (1) the *footprint* of each scan (its sensor, the box its rays can reach, its points),
on the workers; (2) :func:`partition`: regions of about equal work (points), cut where the scans'
sensors lie; (3) one task per region, which writes its tiles into the store; (4) the driver — which
holds the store for writing all along — records the tiles in the index and marks the store
complete. A build that stops part way leaves the store marked incomplete (:mod:`.store`).

A scan read by several workers (near a region border) costs each of them the reading and the
walking of its rays up to their region: that overlap, and the balance of the regions, are what
keep the speed-up below the number of workers (``benchmarks/bench_world.py`` estimates them).
"""

from __future__ import annotations

import os
import resource
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import InvalidArgumentError
from .grid_tiles import TiledGrid2D
from .octree_tiles import TiledOcTree
from .store import TileStore
from .stored_map import union_extent

#: A tile index far beyond any map: the open sides of the outer regions.
UNBOUNDED = 1 << 40
#: Seconds between a region's progress lines, and the Dask topic that carries them to the driver.
PROGRESS_SECONDS = 5.0
PROGRESS_TOPIC = "occmap-build-progress"
#: Scans a footprint task reads.
_FOOTPRINT_RUN = 64


@dataclass
class BuildSummary:
    """What a build did: the scans' counts (``stats``), the scans that had no pose (``no_pose``,
    their numbers), the regions, and per region the scans it read, its points inserted, seconds,
    peak memory (bytes) and tiles written."""

    stats: dict
    no_pose: list
    regions: list
    parts: list = field(default_factory=list)
    seconds: float = 0.0
    tiles: int = 0

    def line(self) -> str:
        """Tiles, regions, time, points per second and the peak memory of the busiest process."""
        peak = max(part["peak_rss"] for part in self.parts)
        rate = self.stats["points"] / max(self.seconds, 1e-9)
        return (f"{self.tiles:,} tiles, {len(self.regions)} region(s), {self.seconds:.1f} s ({rate:,.0f} points/s), "
                f"peak memory per process {peak / 2**20:,.0f} MiB")


class Clouds:
    """How a build inserts point clouds into a :class:`TiledOcTree` (``max_range``, ``discretize``
    as for :meth:`~occmap.world.octree_tiles.TiledOcTree.insert_point_cloud`)."""

    MAP = TiledOcTree

    def __init__(self, max_range: float = -1.0, discretize: bool = False):
        self.max_range, self.discretize = float(max_range), bool(discretize)

    def footprint(self, cloud):
        """The sensor (3,), the corners (3,), (3,) of the box the rays can reach (within
        ``max_range`` of the sensor when ≥ 0) and the number of finite points."""
        origin = cloud.origin
        finite = cloud.world_points()
        finite = finite[np.all(np.isfinite(finite), axis=1)]
        lo = np.minimum(finite.min(axis=0), origin) if len(finite) else origin.copy()
        hi = np.maximum(finite.max(axis=0), origin) if len(finite) else origin.copy()
        if self.max_range >= 0:
            lo, hi = np.maximum(lo, origin - self.max_range), np.minimum(hi, origin + self.max_range)
        return origin, lo, hi, len(finite)

    def insert(self, part, cloud) -> dict:
        return part.insert_point_cloud(cloud.world_points(), cloud.origin, self.max_range, self.discretize)


class LaserScans:
    """How a build inserts planar scans into a :class:`TiledGrid2D`, as ``occmap map2d``
    (:func:`occmap.mapping2d.map_scans`) does: a reading at or beyond its scan's maximum range is
    no return; beams clear space up to ``limit`` metres (the largest maximum range of the scans
    when not given: :meth:`prepare` finds it)."""

    MAP = TiledGrid2D

    def __init__(self, limit: float | None = None, model=None):
        self.limit, self.model = limit, model

    def prepare(self, source) -> None:
        if self.limit is None:
            self.limit = max((float(source.scan(k).max_range) for k in range(len(source))), default=1.0)

    def footprint(self, scan):
        x, y = float(scan.pose[0]), float(scan.pose[1])
        reach = np.array([self.limit, self.limit, 0.0])
        origin = np.array([x, y, 0.0])
        return origin, origin - reach, origin + reach, len(scan.ranges)

    def insert(self, part, scan) -> dict:
        ranges = np.where(scan.ranges >= scan.max_range, np.inf, scan.ranges)
        return part.insert_scan(scan.pose, ranges, scan.angles, max_range=self.limit, model=self.model)


def footprint(how, source, k: int):
    """Scan ``k``'s footprint (``how.footprint``: sensor, reach box, weight)."""
    return how.footprint(source.scan(k))


def footprints(how, source, ks) -> list:
    """The footprints of scans ``ks`` (a Dask task: a run of scans, not one, so that the
    scheduler's cost per task stays small beside the reading)."""
    return [footprint(how, source, int(k)) for k in ks]


def partition(cells: np.ndarray, weights: np.ndarray, parts: int) -> list:
    """At most ``parts`` regions (boxes of tile indices, z unbounded) that cover the plane, cut
    along tile borders so that the ``weights`` of the scans whose sensors lie in tile columns
    ``cells`` (S, 2) are split about evenly: recursive halving, each cut across the longer side of
    the sensors' spread, between two of their columns (sensors all in one column make one region)."""
    parts = int(parts)
    if parts < 1:
        raise InvalidArgumentError(f"parts must be ≥ 1, got {parts}")
    out = []

    def split(lo, hi, idx, n):
        c = cells[idx]
        spread = c.max(axis=0) - c.min(axis=0) if len(idx) else np.zeros(2, np.int64)
        if n == 1 or not spread.any():
            out.append((lo, hi))
            return
        axis = int(np.argmax(spread))
        order = idx[np.argsort(c[:, axis], kind="stable")]
        w = np.cumsum(weights[order])
        left = n // 2
        at = int(np.searchsorted(w, w[-1] * left / n))
        first, last = int(cells[order[0], axis]), int(cells[order[-1], axis])
        cut = min(max(int(cells[order[min(at, len(order) - 1)], axis]), first + 1), last)  # right side's first column
        a_hi, b_lo = list(hi), list(lo)
        a_hi[axis], b_lo[axis] = cut - 1, cut
        mask = cells[idx, axis] < cut
        split(lo, tuple(a_hi), idx[mask], left)
        split(tuple(b_lo), hi, idx[~mask], n - left)

    split((-UNBOUNDED, -UNBOUNDED), (UNBOUNDED, UNBOUNDED), np.arange(len(cells)), parts)
    return [((r[0][0], r[0][1], -UNBOUNDED), (r[1][0], r[1][1], UNBOUNDED)) for r in out]


def reaching(region, lo: np.ndarray, hi: np.ndarray, tile_metres: float) -> np.ndarray:
    """Indices of the scans whose reach boxes (``lo``, ``hi`` (S, 3) metres) meet ``region``
    (a voxel of margin is in the caller's test: here a whole tile)."""
    r_lo = np.asarray(region[0], np.float64) * tile_metres - tile_metres
    r_hi = (np.asarray(region[1], np.float64) + 1) * tile_metres + tile_metres
    return np.flatnonzero(np.all((hi >= r_lo) & (lo <= r_hi), axis=1))


def _peak_rss() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def _dask_progress(text: str) -> None:
    from distributed import get_worker

    get_worker().log_event(PROGRESS_TOPIC, text)


def build_part(path, how, source, scans, region, memory_limit, threads, name: int = 0, progress=None):
    """One region's work (a Dask task): insert ``scans`` of ``source`` in order (``how``:
    :class:`Clouds` or :class:`LaserScans`) into the region's tiles of the store at ``path``,
    write them; returns what the driver records. ``progress(text)`` is told how far it is every
    few seconds."""
    if threads:
        import numba

        numba.set_num_threads(int(threads))
    t0 = last = time.perf_counter()
    if region is not None and how.MAP is TiledGrid2D:
        region = (region[0][:2], region[1][:2])
    part = how.MAP.build_part(path, region, memory_limit)
    summaries = {}
    no_pose = []
    inserted = 0
    for j, k in enumerate(scans):
        scan = source.scan(int(k))
        s = how.insert(part, scan)
        if s["scans"]:
            summaries[int(k)] = s
            inserted += s["points"]
        if not getattr(scan, "has_pose", True):
            no_pose.append(int(k))
        now = time.perf_counter()
        if progress is not None and now - last >= PROGRESS_SECONDS:
            last = now
            held, held_bytes = part.in_memory()
            progress(f"region {name}: {j + 1:,}/{len(scans):,} scans, {inserted / (now - t0):,.0f} points/s, "
                     f"{held:,} tiles in memory ({held_bytes / 2**20:,.0f} MiB), peak {_peak_rss() / 2**20:,.0f} MiB")
    tiles = part.write_tiles()
    return {"tiles": tiles, "extent": part.extent, "summaries": summaries, "no_pose": no_pose, "scans": len(scans),
            "points": inserted,
            "seconds": time.perf_counter() - t0, "peak_rss": _peak_rss()}


def build_octree(path, source, resolution: float | None = None, tile_size: int | None = None, *,
                 max_range: float = -1.0, discretize: bool = False, **options) -> BuildSummary:
    """Insert the point clouds of ``source`` (:mod:`occmap.sources`), in order, into the tiled octree
    stored at ``path`` (``max_range``, ``discretize`` as for ``insert_point_cloud``); see
    :func:`build`."""
    return build(path, Clouds(max_range, discretize), source, resolution, tile_size, **options)


def build_grid(path, source, resolution: float | None = None, tile_size: int | None = None, *,
               max_range: float | None = None, model=None, **options) -> BuildSummary:
    """Insert the laser scans of ``source`` (:class:`occmap.sources.CarmenScans`), in order, into the
    tiled grid stored at ``path``, as ``occmap map2d`` does (:class:`LaserScans`); see
    :func:`build`."""
    return build(path, LaserScans(max_range, model), source, resolution, tile_size, **options)


def build(path, how, source, resolution: float | None = None, tile_size: int | None = None, *, workers: int = 1,
          scheduler: str | None = None, memory_limit: int | None = None, progress=None, **params) -> BuildSummary:
    """Insert the scans of ``source`` (:mod:`occmap.sources`), in order, as ``how`` says
    (:class:`Clouds` or :class:`LaserScans`), into the tiled map stored at ``path``: a new store
    (``resolution``, ``tile_size`` (default the map's), ``params`` as for the map's class) or one
    that exists (mapping resumes).

    ``workers`` = 1 without a ``scheduler`` builds in this process; more start a local Dask
    cluster of that many worker processes; ``scheduler`` (``tcp://host:8786``) uses a running
    cluster (its workers must see ``path`` and the source's files at the same paths).
    ``memory_limit`` (bytes) bounds the tiles held in memory, split among the workers.
    ``progress(text)`` is called as regions finish. The map is the same whatever the workers.
    """
    t0 = time.perf_counter()
    store = _store(path, how.MAP, resolution, tile_size, params)
    n = len(source)
    if hasattr(how, "prepare"):
        how.prepare(source)
    with store.writer():
        if workers == 1 and scheduler is None:
            regions = [None]
            parts = [build_part(store.path, how, source, range(n), None, memory_limit, 0, 0, progress)]
            if progress:
                progress(_part_line(0, parts[0]))
        else:
            regions, parts = _on_dask(store, how, source, n, workers, scheduler, memory_limit, progress)
        stats = {"scans": 0, "points": 0, "dropped": 0, "beyond_max_range": 0}
        summaries = {}
        no_pose = set()
        for part in parts:
            store.tiles.update(part["tiles"])
            store.extent = union_extent(store.extent, part["extent"])
            summaries.update(part["summaries"])
            no_pose.update(part["no_pose"])
        for s in summaries.values():
            for key, value in s.items():
                stats[key] = stats.get(key, 0) + value
        store.scans += n
    return BuildSummary(stats, sorted(no_pose), regions, parts, time.perf_counter() - t0, len(store.tiles))


def _store(path, cls, resolution, tile_size, params) -> TileStore:
    """The store to build into: opened if ``path`` is one (of ``cls``'s kind), else created."""
    if (os.path.isdir(path) and os.listdir(path)) or os.path.isfile(path):
        store = TileStore.open(path, kind=cls.KIND)
        if resolution is not None and resolution != store.resolution:
            raise InvalidArgumentError(f"{path}: the store's resolution is {store.resolution:g} m, not {resolution:g}")
        if tile_size is not None and tile_size != store.tile_size:
            raise InvalidArgumentError(f"{path}: the store's tiles are {store.tile_size}, not {tile_size}, a side")
        return store
    if resolution is None:
        raise InvalidArgumentError(f"{path}: a new store needs a resolution")
    cls.create(path, resolution, *(() if tile_size is None else (tile_size,)), **params).close()
    return TileStore.open(path, kind=cls.KIND)


def _on_dask(store, how, source, n, workers, scheduler, memory_limit, progress):
    from distributed import Client, LocalCluster, as_completed

    cluster = None
    if scheduler is None:
        cluster = LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True, memory_limit=0,
                               dashboard_address=":0", silence_logs=40)  # (":0": any free port)
    client = Client(scheduler if scheduler is not None else cluster)
    if progress:
        client.subscribe_topic(PROGRESS_TOPIC, lambda event: progress(event[1]))
    try:
        count = len(client.scheduler_info()["workers"]) if scheduler is not None else int(workers)
        runs = [range(a, min(n, a + _FOOTPRINT_RUN)) for a in range(0, n, _FOOTPRINT_RUN)]
        feet = [f for run in client.gather(client.map(footprints, [how] * len(runs), [source] * len(runs), runs,
                                                      pure=False)) for f in run]
        origins = np.array([f[0] for f in feet]).reshape(-1, 3)
        lo = np.array([f[1] for f in feet]).reshape(-1, 3)
        hi = np.array([f[2] for f in feet]).reshape(-1, 3)
        weights = np.array([f[3] for f in feet], np.float64) + 1.0
        side = store.tile_size * store.resolution
        cells = np.floor(origins[:, :2] / side).astype(np.int64)
        regions = partition(cells, weights, count)
        limit = None if memory_limit is None else max(1, int(memory_limit) // len(regions))
        threads = max(1, (os.cpu_count() or 1) // len(regions)) if cluster is not None else 0
        futures = {client.submit(build_part, str(store.path), how, source, reaching(r, lo, hi, side), r, limit,
                                 threads, i, _dask_progress if progress else None, pure=False): i
                   for i, r in enumerate(regions)}
        parts = [None] * len(regions)
        for future in as_completed(futures):
            i = futures[future]
            parts[i] = future.result()
            if progress:
                progress(_part_line(i, parts[i]))
        return regions, parts
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _part_line(i: int, part: dict) -> str:
    rate = part["points"] / part["seconds"] if part["seconds"] > 0 else 0.0
    return (f"region {i}: {part['scans']:,} scans read, {part['points']:,} points in {part['seconds']:.1f} s "
            f"({rate:,.0f} points/s), {len(part['tiles']):,} tiles, peak {part['peak_rss'] / 2**20:,.0f} MiB")
