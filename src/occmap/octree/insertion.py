"""Inserting scans: the orchestration of the kernels of :mod:`.marking`, :mod:`.blocks` and
:mod:`.update` over threads (OctoMap's ``insertPointCloud`` / ``insertRay`` / ``updateNode``,
without a tree class: functions of a :class:`.pool.Pool` and plain arrays).

A scan goes through two stages: its rays are marked into blocks (:func:`cloud_blocks`, which
leaves the tree alone, so the next scan can be traced while the tree takes this one), and the
blocks update the pool (:func:`apply_marked`; listed as voxels in Morton order first where a list
is wanted: :func:`cloud_voxels`, :func:`apply`). Every Numba kernel releases the GIL, so Python
threads run kernels side by side: the calling thread and workers, as many threads in all as Numba
has (:func:`occmap._threads.share`). The work is cut into runs that the threads take in turn and
a worker that has not started when the calling thread is done is cancelled; and while other
processes keep the cores busy, a scan takes one thread (:func:`occmap._threads.free_for_parallel`:
a worker the scheduler sets aside in the middle of its run keeps the calling thread waiting).
(A per-call choice by measured cost, as the 2D kernels make, would compare scans of very
different cost per point.)
"""

from __future__ import annotations

import threading
from collections import deque

import numba
import numpy as np

from .. import _threads
from .._threads import run_jobs, share
from . import blocks as B
from . import marking as M
from . import pool as P
from .keys import DEPTH, coord_to_keys, shared_depth
from .update import BLOCK_ROOM, apply_blocks, apply_voxels, new_work, settle_blocks

#: Scans with at least this many rays are marked by several threads, in runs of rays
#: (:func:`_guided`).
_PARALLEL_RAYS = 20_000
#: Scans with at least this many marked blocks list their voxels on several threads, in runs of
#: blocks (:func:`_guided`).
_PARALLEL_BLOCKS = 256
#: Scans with at least this many voxels update the tree on two threads, in runs of voxels
#: (:func:`_guided`). (Below it the threads' start, the cuts between runs and the join cost more
#: than the second thread saves: the update of a scan with 225k voxels, in slots already in
#: memory, took 1.77 ms on one thread and 2.13 ms on two; with 617k, 10.2 and 8.3 ms.)
_PARALLEL_VOXELS = 250_000
#: Slots a two-thread update may need, a voxel (the pool's room is made that large first); and
#: the slots of 2 MiB: the chunks of slots the threads take from the top as they need them end at
#: multiples of it, so that the two never fault on one page (not even a huge one: the pool asks
#: for small pages, :func:`.pool._reserve`, but where huge ones were given, the system would clear
#: one for each thread that faults on it, and keep one). (Chunks of 256 or 64 KiB: no faster.)
_ROOM_PER_VOXEL = 2
_CHUNK = (2 << 20) // P.SLOT.itemsize
#: Scans with at least this many rays mark the voxels near the sensor in a dense cube (see
#: occmap.octree.marking.CUBE).
_CUBE_RAYS = 4096

#: Batches of at least this many scans settle their changes once, after the last
#: (:func:`settle_changes`). (A region seen by scan after scan is settled once instead of after
#: each; the settle walks its blocks again, out of the cache by then: a simulated drive at 0.1 m,
#: one core, 1.18x faster over 50 scans, 1.13x over 8, as fast over 3; the dense pairs and
#: triples of the sample scans 0.91 - 0.93x.)
SETTLE_AFTER_SCANS = 4

#: Depths for updates that are all voxels (:func:`apply`).
VOXELS = np.zeros(0, np.int8)


#: Per thread, its cube (:func:`.marking.new_cube`: 2.25 MiB) kept between scans, zeroed, its box empty;
#: ``storage``, its block storage (:func:`_storage`); ``blocks_per_ray``, the blocks its last
#: scan's rays marked outside the cube, a ray (the room asked for the next scan's blocks: storage
#: that fills up is grown and rehashed); and ``rays``, room for a scan's rays (:func:`_ray_room`).
#: (Scratch allocated anew each scan goes back to the system and is faulted in again: on a
#: virtual machine after a pause, memory the host has taken back costs about 2 ms a MiB.)
_kept = threading.local()
#: Blocks a ray is taken to mark before a thread has marked a scan.
_BLOCKS_PER_RAY = 1 / 32
_NO_CUBE = (np.zeros(0, np.int64), np.zeros(0, np.uint8), np.zeros((2, 3), np.int64))
_NO_INDICES = np.zeros(0, np.int64)
_NO_SPINES = np.full((2, DEPTH + 1), -1, np.int64)


def _guided(total: float, smallest: float = 1 / 32) -> np.ndarray:
    """Bounds ``0 .. total`` of runs for threads that take them in turn: each run a quarter of
    what is left, and no smaller than ``smallest`` of the whole (guided scheduling: the cost of a
    run is hard to foresee, so the runs taken last are small, and the threads finish together)."""
    bounds = [0.0]
    while 1.0 - bounds[-1] > 2 * smallest:
        bounds.append(bounds[-1] + max((1.0 - bounds[-1]) / 4, smallest))
    return np.array(bounds + [1.0]) * total


def _parallel() -> bool:
    """Whether a large scan's work may be shared between threads: Numba allows two or more, and
    other processes leave the cores for them (:func:`occmap._threads.free_for_parallel`: on a
    busy computer a thread the scheduler sets aside keeps the others waiting at the end)."""
    return _threads.thread_count() >= 2 and _threads.free_for_parallel()


def _ray_room(n: int):
    """This thread's arrays for a scan's rays (ends float32 (≥ n, 3), hit flags (≥ n,)), kept
    between scans (:func:`.marking.prepare_rays_into`) and grown by half as much again when a scan
    needs more. (The rays are read only while :func:`cloud_voxels` runs on this thread.)"""
    room = getattr(_kept, "rays", None)
    if room is None or len(room[1]) < n:
        size = max(n, int(1.5 * len(room[1])) if room is not None else 0)
        room = _kept.rays = np.empty((size, 3), np.float32), np.empty(size, np.bool_)
    return room


def ahead(scan_blocks, *args):
    """``scan_blocks(*args)`` (the next scan of ``OcTree.insert_point_clouds``) submitted to a
    thread of its own while the calling thread's tree takes the current scan; it runs with the
    calling thread's Numba thread count (a per-thread setting), so that its rays are marked by
    that thread and the workers together (:func:`mark`): a scan whose marking outweighs the
    tree's update (small clouds, few voxels a ray: Osnabrück at 0.2 m, 3.5 ms against 0.4 ms)
    would otherwise be marked on one thread while the other waits."""
    n = _threads.thread_count()

    def traced():
        numba.set_num_threads(n)
        return scan_blocks(*args)

    return _threads.pool("octree-next", 1).submit(traced)


def _storage(capacity: int):
    """This thread's block storage kept from its last scan (taken until the blocks marked in it
    are copied out), emptied, where it has room for ``capacity`` blocks and not eight times more
    (emptying clears its table); else new storage, at least twice the kept one's room where that
    was too small (so that storage kept for scans of one size stops being replaced)."""
    storage = getattr(_kept, "storage", None)
    _kept.storage = None
    if storage is None or len(storage[2]) > 8 * capacity:
        return B.new_blocks(capacity)
    if len(storage[2]) < capacity:
        return B.new_blocks(max(capacity, 2 * len(storage[2])))
    B.empty_blocks(*storage)
    return storage


def _mark_runs(origin, ends, hit, res, shift, rays, corner, runs: deque, capacity: int, prepare):
    """Block masks of the runs ``(start, stop)`` of rays this thread takes from ``runs`` (shared
    by the threads, each run taken once) until none is left (with ``prepare``, runs of points whose
    rays it prepares first: :func:`mark`), marked in this thread's storage
    (:func:`_storage`, grown until they fit) and copied out, a block possibly listed twice; with
    a cube (``corner`` ≥ 0) the voxels around the sensor are marked in a dense one of this
    thread's. Returns them with the number of blocks marked outside the cube, or None when the
    runs were all taken."""
    storage = cube = None
    while True:
        try:
            start, stop = runs.popleft()
        except IndexError:
            break
        if storage is None:  # (a thread that finds the runs taken allocates nothing)
            storage = _storage(capacity)
            cube = _NO_CUBE
            if corner >= 0:  # this thread's kept cube, taken until cube_blocks has zeroed it again
                cube = getattr(_kept, "cube", None) or M.new_cube()
                _kept.cube = None
        if prepare is not None:
            stop = prepare(start, stop)
        while True:
            start = M.mark_scan(origin, ends, hit, res, shift, rays, start, stop, *storage, *cube, corner)
            if start == stop:
                break
            storage = B.grow_blocks(*storage)
    if storage is None:
        return None
    table, slots, codes, hits, frees, count = storage
    n = int(count[0])
    blocks = codes[:n], hits[:n], frees[:n]
    if corner >= 0:  # and the cube's (merge_blocks ors a block marked in both)
        blocks = tuple(np.concatenate(pair) for pair in zip(blocks, M.cube_blocks(*cube, corner)))
        _kept.cube = cube
    else:
        blocks = tuple(b.copy() for b in blocks)
    _kept.storage = storage
    return blocks, n


def mark(origin, ends, hit, res, shift, rays: bool, threads: bool, prepare=None, sample=None):
    """The scan's voxels as Morton-sorted blocks of hit and free bits (only hits unless ``rays``),
    keys local to ``shift`` (:mod:`.marking`);
    with ``threads``, large scans are marked by several threads (the kernels release the GIL),
    which take runs of rays in turn: the work of a run is hard to foresee (a step outside the
    cube costs several inside it), so a thread that is done early takes more.

    ``prepare``: None where ``ends`` and ``hit`` hold the rays; else the rays are prepared run by
    run on the thread that marks them: ``prepare(a, z)`` writes those of points ``a..z-1`` from
    row ``a`` on and returns the row past them, and ``sample()`` gives some rays of the scan (the
    cube is placed by them). (Prepared before the runs, a scan's rays were a pass on one thread,
    a tenth of its time at 0.2 m, and a second call to wake the workers, which started 1 - 2 ms
    later.)"""
    n = len(ends)
    corner = -1
    if rays and n >= _CUBE_RAYS:
        corner = M.cube_corner(origin, ends if sample is None else sample(), res, shift)
    # room for the blocks at the rate of this thread's last scan, and a quarter more
    room = 1.25 * getattr(_kept, "blocks_per_ray", _BLOCKS_PER_RAY) * n
    if not (threads and n >= _PARALLEL_RAYS and _parallel()):
        parts = [_mark_runs(origin, ends, hit, res, shift, rays, corner, deque([(0, n)]), max(256, int(room)), prepare)]
    else:
        bounds = _guided(n).astype(np.int64).tolist()
        runs = deque(zip(bounds[:-1], bounds[1:]))
        capacity = max(256, int(room / 2))
        parts = [p for p in share(lambda: _mark_runs(origin, ends, hit, res, shift, rays, corner, runs, capacity,
                                                     prepare))
                 if p is not None]
    if n:
        _kept.blocks_per_ray = sum(count for _, count in parts) / n
    marked = [blocks for blocks, _ in parts]
    return B.merge_blocks(*(marked[0] if len(marked) == 1 else (np.concatenate(arrays) for arrays in zip(*marked))))


def voxels(blocks, kbox, merge: bool, threads: bool):
    """:func:`occmap.octree.blocks.block_voxels` of Morton-sorted blocks: updates (keys, depths,
    hit flags); with ``threads``, many blocks are listed by several threads, in runs (Morton order
    kept)."""
    n = len(blocks[0])
    if not (threads and n >= _PARALLEL_BLOCKS and _parallel()):  # (one thread: one call, no copy)
        return B.block_voxels(*blocks, kbox, merge)
    bounds = _guided(n).astype(np.int64).tolist()
    parts = run_jobs([lambda a=a, z=z: B.block_voxels(*(b[a:z] for b in blocks), kbox, merge)
                      for a, z in zip(bounds[:-1], bounds[1:])])
    return tuple(np.concatenate(arrays) for arrays in zip(*parts))


def cloud_blocks(points, origin32, max_range: float, discretize: bool, res: float, box, kbox, shift, threads: bool):
    """A scan's voxels as OctoMap's ``insertPointCloud`` finds them, as marked blocks, the tree
    left alone (so the next scan can be traced while a tree takes this one).

    ``points`` float64 (N, 3) and ``origin32`` float32 (3,) in metres; ``max_range`` (< 0: none);
    ``discretize``: one ray per voxel holding points, to its centre (:func:`.marking.voxel_centres`);
    ``box`` float32 (2, 3), points outside it are no hits ((0, 3): none); ``kbox`` (2, 3) the
    bounding box in local keys ((0, 3): none; rays from outside it free nothing); keys local to
    ``shift`` (:mod:`.marking`). Returns ``(blocks, summary)``: the blocks (:func:`mark`; voxels
    outside ``kbox`` are left to the reader: :func:`apply_marked`, :func:`voxels`) and the counts
    ``points`` (rays cast), ``dropped`` (points with NaN/inf, and those whose ray ends outside the
    key range: OctoMap skips those rays), ``outside_key_range`` (the latter) and
    ``beyond_max_range``."""
    non_finite = outside = 0
    if discretize:
        points, non_finite, outside = M.voxel_centres(points, res, shift)
    n = len(points)
    ends, hit = _ray_room(n)
    origins, limit = origin32[None, :], float(max_range)
    prepared = {}  # run's first point → its rays, points dropped (non-finite, outside the key range)

    def prepare(a, z):
        prepared[a] = M.prepare_rays_into(points[a:z], origins, limit, res, box, shift, ends[a:z], hit[a:z],
                                          _NO_INDICES)
        return a + prepared[a][0]

    def sample():
        return M.prepare_rays(np.ascontiguousarray(points[::max(1, n // M.PLACE_RAYS)]), origins, limit, res, box,
                              shift)[0]

    origin_key = coord_to_keys(origin32.astype(np.float64), res) - shift
    # with a box, a ray's free voxels are those before it first leaves the box: none from outside
    rays = not len(kbox) or bool(np.all((kbox[0] <= origin_key) & (origin_key <= kbox[1])))
    blocks = mark(origin32, ends[:n], hit[:n], res, shift, rays, threads, prepare, sample)
    m = beyond = 0
    for a, (k, more, beyond_keys) in prepared.items():
        m, non_finite, outside = m + k, non_finite + more, outside + beyond_keys
        beyond += int(np.count_nonzero(~hit[a:a + k]))
    summary = {"points": m, "dropped": int(non_finite + outside), "outside_key_range": int(outside),
               "beyond_max_range": beyond}
    return blocks, summary


def cloud_voxels(points, origin32, max_range: float, discretize: bool, res: float, box, kbox, shift,
                 threads: bool, keep=None, merge: bool = True):
    """:func:`cloud_blocks` listed as updates: ``(keys, depths, is_hit, summary)``, the updates
    (:func:`.blocks.block_voxels`) in Morton order, each voxel in one, only those within ``keep``
    (2, 3) (default ``kbox``); ``merge``: nodes whose voxels are all marked alike as one update
    (not for lazy updates)."""
    blocks, summary = cloud_blocks(points, origin32, max_range, discretize, res, box, kbox, shift, threads)
    keys, depths, is_hit = voxels(blocks, kbox if keep is None else keep, merge, threads)
    return keys, depths, is_hit, summary


def apply(pool: P.Pool, keys: np.ndarray, depths: np.ndarray, is_hit: np.ndarray, rule, lazy: bool,
          threads: bool = False) -> None:
    """Apply the updates ``keys`` (packed first voxels) at ``depths`` ((0,): voxels) to ``pool`` in
    order, each a hit or a miss under ``rule`` = (l_hit, l_miss, l_min, l_max) (float32 log-odds;
    :func:`.update.apply_voxels`); with ``threads`` (one scan's updates: each voxel in one, in
    Morton order) many updates on two threads when Numba's count and the machine's load allow."""

    def run(meta, start, stop, limit, spines):
        return apply_voxels(pool.slots, meta, keys[:stop], depths[:stop], is_hit[:stop], start, *rule, not lazy, limit,
                            spines, new_work())

    _apply(pool, run, keys, np.arange(len(keys) + 1), lazy, threads)


def apply_marked(pool: P.Pool, blocks, kbox, rule, lazy: bool, threads: bool = False, changes=None) -> None:
    """Apply a scan's marked blocks (:func:`mark`) to ``pool``, only voxels within the key box
    ``kbox`` ((0, 3): everywhere): the updates :func:`apply` makes of :func:`voxels`, with no
    list between (:func:`.update.apply_blocks`); with ``threads``, many blocks on two threads when
    Numba's count and the machine's load allow. ``changes``: a list, for updates whose settling
    is left to :func:`settle_changes` (not lazy ones), which takes the blocks' codes and changes."""
    codes, hits, frees = blocks
    settle_nodes = not lazy and changes is None
    found = np.zeros(len(codes) if changes is not None else 0, np.int64)

    def run(meta, start, stop, limit, spines):
        return apply_blocks(pool.slots, meta, codes[:stop], hits[:stop], frees[:stop], kbox, start, *rule,
                            settle_nodes, not lazy, limit, spines, new_work(), found[:stop])

    _apply(pool, run, codes - 1, B.marked_before(hits, frees), not settle_nodes, threads)
    if changes is not None:
        changes.append((codes, found))


def settle_changes(pool: P.Pool, changes, threads: bool = False) -> None:
    """Settle the nodes that updates applied by :func:`apply_marked` with ``changes`` changed
    something below, each once (:func:`.update.settle_blocks`): a batch of scans leaves the tree
    that eager updates, each settling what it changed, leave (a block of a drive is updated by
    scan after scan: settled once, not after each; pruned only at the end, not pruned and
    expanded again). With ``threads``, many nodes on two threads, as :func:`apply_marked`."""
    if not changes:
        return
    codes = np.concatenate([c for c, _ in changes])
    found = np.concatenate([f for _, f in changes])
    order = B.morton_order(codes)
    codes, found = codes[order], found[order]
    starts = np.flatnonzero(np.r_[True, codes[1:] != codes[:-1]])
    codes, found = codes[starts], np.bitwise_or.reduceat(found, starts)

    def run(meta, start, stop, limit, spines):
        return settle_blocks(pool.slots, meta, codes[:stop], found[:stop], start, spines, new_work())

    # (a node settled stands for the eight voxels below it: the weight of eight updates)
    nodes = np.unpackbits(found.view(np.uint8)).reshape(-1, 64).sum(axis=1)
    _apply(pool, run, codes - 1, np.r_[0, np.cumsum(8 * nodes)], False, threads, room=0)


def _apply(pool: P.Pool, run, keys, voxels, lazy: bool, threads: bool, room: float | None = None) -> None:
    """Updates ``run(meta, start, stop, limit, spines)`` (:func:`.update.apply_voxels` or
    :func:`.update.apply_blocks` of a scan: items ``start..stop-1``, nodes of ``spines`` left
    unsettled, returning the item where the slots below ``limit`` ran out and whether any value
    changed) whose items' first voxels have packed keys ``keys``, Morton-sorted, and ``voxels[i]``
    voxels before item ``i``: on two threads (with ``threads``) when there are many voxels and
    Numba's count and the machine's load allow (:func:`_parallel`). ``room``: slots the updates
    may need, a voxel (default :data:`_ROOM_PER_VOXEL`; 0: they allocate none, as
    :func:`.update.settle_blocks`)."""
    if threads and voxels[-1] >= _PARALLEL_VOXELS and len(keys) >= 2 and _parallel():
        _apply_runs(pool, run, keys, voxels, lazy, room)
        return
    _apply_range(pool, run, 0, len(keys))


def _apply_range(pool: P.Pool, run, start: int, stop: int) -> bool:
    """Items ``start..stop-1`` on this thread, growing the pool as needed; whether any changed."""
    P.merge_spare(pool.slots, pool.meta)
    top = int(pool.meta[P.TOP])
    changed = False
    first = start
    while True:
        start, ch = run(pool.meta, start, stop, pool.slots.shape[0], _NO_SPINES)
        changed |= ch
        if start == stop:
            return changed
        # out of slots: room for the rest at the rate of slots per item so far, and a margin
        used = int(pool.meta[P.TOP])
        rate = (used - top) / max(start - first, 1)
        pool.grow(used + 1.25 * rate * (stop - start))


def _apply_runs(pool: P.Pool, run, keys, voxels, lazy: bool, room: float | None) -> None:
    """The items in runs of voxels (:func:`_guided`), which two threads take in turn (a thread
    that is done early takes more: on a busy computer a scan takes about what one thread takes).
    Where two runs meet, the nodes their paths share (the path to the node at the cut's depth, the
    deepest holding items of both) must exist with their children: a run's items lie below
    those nodes' children on its side, or beside that path higher up; its thread passes them
    through, and they are settled after all runs. Each thread takes slots from its own free list
    and from chunks of the pool's unused slots; one that finds no chunk left in the pool's room
    leaves the rest of its run, and the runs left, to this thread afterwards. Where
    a cut's path does not exist even after the item past the cut is applied (a pruned leaf on it
    took that item), the rest is applied on this thread."""
    n = len(keys)
    cuts = np.unique(np.clip(np.searchsorted(voxels, _guided(voxels[n])[1:-1]), 1,
                             n - 1)).tolist()
    depths = [shared_depth(keys[c - 1], keys[c]) for c in cuts]
    starts, stops = [0], cuts + [n]
    for c, depth in zip(cuts, depths):
        first = c
        if not len(P.path_to(pool.slots, keys[c], depth)):  # make it: that item's update makes the nodes on its way
            _apply_range(pool, run, c, c + 1)
            first = c + 1
        starts.append(first)
    # spines[k + 1]: the path at cut k (-1 below its depth); rows 0 and -1 none, for the end runs
    spines = np.full((len(cuts) + 2, DEPTH + 1), -1, np.int64)
    for k, (c, depth) in enumerate(zip(cuts, depths)):  # (once all are made: one item's settling may prune another's)
        path = P.path_to(pool.slots, keys[c], depth)
        if not len(path):
            for a, z in zip(starts, stops):
                _apply_range(pool, run, a, z)
            return
        spines[k + 1, :len(path)] = path
    runs = deque((a, z, spines[r:r + 2]) for r, (a, z) in enumerate(zip(starts, stops)))
    # Slots: the first thread to start takes the free list first, the other its spare list (the
    # blocks it freed before: a robot standing still, its scans re-seen, leaves the pool as it
    # was); beyond those, each takes chunks of unused slots from the top as it needs them (its
    # kernel stops where its chunk runs short and resumes with the next). Afterwards the unused
    # end of a thread's last chunk joins its free list, or the top where nothing lies above it.
    # (A range sized ahead for each thread leaves most of the first thread's unused; written
    # onto the free list, it put pages into use that the tree did not need: on a virtual machine
    # 2 ms a MiB, as much as the update of a scan at 0.1 m takes.)
    top = int(pool.meta[P.TOP])
    room = _ROOM_PER_VOXEL if room is None else room
    need = int(room * voxels[n]) + 2 * _CHUNK
    if room and pool.slots.shape[0] < top + need:
        pool.grow(top + need)
    capacity = pool.slots.shape[0]  # (the pool does not grow while the threads run)
    unused = [top]  # the first slot no chunk holds
    lock = threading.Lock()
    meta_a, meta_b = P.new_meta(top), P.new_meta(top)
    meta_a[P.FREE], meta_b[P.FREE] = pool.meta[P.FREE], pool.meta[P.SPARE]
    metas = deque([meta_a, meta_b])
    ends = []  # (meta, end of its last chunk) of each thread
    left = []  # (start, stop) of items a thread left for want of room

    def take():
        meta = metas.popleft()
        limit = top  # (an empty chunk)
        changed = False
        try:
            while True:
                try:
                    a, z, bounds = runs.popleft()
                except IndexError:
                    return changed
                while True:
                    a, ch = run(meta, a, z, limit, bounds)
                    changed |= ch
                    if a == z:
                        break
                    with lock:
                        lo = unused[0]
                        hi = (lo + BLOCK_ROOM) // _CHUNK * _CHUNK + _CHUNK
                        if hi <= capacity:
                            unused[0] = hi
                    if hi > capacity:
                        left.append((a, z))
                        return changed
                    P.free_range(pool.slots, meta, int(meta[P.TOP]), limit)
                    meta[P.TOP], limit = lo, hi
        finally:
            ends.append((meta, limit))

    changed = any(share(take, 2))
    for meta, limit in sorted(ends, key=lambda e: -e[1]):
        if limit == unused[0]:
            unused[0] = int(meta[P.TOP])
        else:
            P.free_range(pool.slots, meta, int(meta[P.TOP]), limit)
    pool.meta[P.TOP] = unused[0]
    pool.meta[P.FREE], pool.meta[P.SPARE] = meta_a[P.FREE], meta_b[P.FREE]
    pool.meta[P.SIZE] += meta_a[P.SIZE] + meta_b[P.SIZE]
    for a, z in left + [(a, z) for a, z, _ in runs]:
        changed |= _apply_range(pool, run, a, z)
    if changed and not lazy:
        for spine in spines[1:-1]:
            P.settle_path(pool.slots, pool.meta, spine[spine >= 0])
