"""The occupancy octree: OctoMap's semantics on a node pool in NumPy arrays.

Conventions (OctoMap's, so maps compare voxel by voxel): depth 16; the key of a coordinate is
``floor(x / resolution) + 32768`` per axis; child index ``x-bit + 2·y-bit + 4·z-bit``; each node
holds a float32 log-odds ``l = log(p / (1 − p))``; a hit adds ``logit(prob_hit)``, a miss
``logit(prob_miss)``, and values are clamped to ``logit(clamp)``; a node is occupied when
``l ≥ logit(occupied_threshold)``; an inner node holds the maximum of its children; eight leaf
children with equal values are pruned into their parent. Space no node covers is *unknown*.
Points are metres in the map frame; rays start at the sensor origin.

Method and parameter names follow the vocabulary the three maps share (``docs/architecture.md``).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .. import checks
from .._threads import OneCallAtATime, free_for_parallel, no_lock, thread_count
from ..errors import InvalidArgumentError, ShapeError
from ..logodds import logit32, occupancy_classes
from . import insertion, pool, query, views
from .keys import (CENTER, DEPTH, MAX_KEY, NO_SHIFT, coord_to_keys, keys_in_range, node_cells, node_centers, pack_keys,
                   packed_in_range)
from .marking import prepare_rays, ray_voxels


def _depth(depth) -> int:
    """A node depth: an integer 0 (the root) .. 16 (a voxel)."""
    d = checks.count("depth", depth, 0)
    if d > 16:
        raise InvalidArgumentError(f"depth must be an integer 0 .. 16, got {depth!r}")
    return d


def points_array(name: str, points) -> np.ndarray:
    """``points`` as float64 (N, 3) (one point (3,) becomes (1, 3)); :class:`ShapeError` naming
    ``name`` otherwise."""
    P = np.asarray(points, dtype=np.float64)
    if P.ndim == 1 and P.shape == (3,):
        P = P[None, :]
    if P.ndim != 2 or P.shape[1] != 3:
        raise ShapeError(f"{name} must have shape (N, 3), got {P.shape}")
    return P


def _origin(origin) -> np.ndarray:
    o = np.asarray(origin, dtype=np.float64)
    if o.shape != (3,):
        raise ShapeError(f"origin must have shape (3,), got {o.shape}")
    if not np.all(np.isfinite(o)):
        raise InvalidArgumentError(f"origin must be finite, got {o.tolist()}")
    return o


class Leaves(NamedTuple):
    """Leaf nodes as arrays: centres (M, 3) and edge lengths (M,) in metres, log-odds (M,) and
    depth (M,) (16 = one voxel of ``resolution``)."""

    centers: np.ndarray
    sizes: np.ndarray
    log_odds: np.ndarray
    depths: np.ndarray


class Nodes(NamedTuple):
    """An octree's nodes as arrays (OctoMap's node pointers as slot indices). Nodes live in
    *slots*; the eight children of an inner node occupy one *block* of 8 consecutive slots, child
    ``i`` (= x-bit + 2·y-bit + 4·z-bit) at ``block + i``; slot 0 is the root, alone in block 0.

    slots : (slots,) records of ``value`` float32 and ``child`` int32 (:data:`.pool.SLOT`)
        ``value``: log-odds of the node in each slot; NaN where the slot holds no node.
        ``child``: first slot of the node's block of children; −1 for a leaf. (In a slot holding
        no node it may link unused blocks together: read it only where ``value`` is not NaN.)
    count : int
        The number of nodes (OctoMap's ``size()``).
    """

    slots: np.ndarray
    count: int

    @property
    def value(self) -> np.ndarray:
        """The slots' log-odds (a view)."""
        return self.slots["value"]

    @property
    def child(self) -> np.ndarray:
        """The slots' first child slots (a view)."""
        return self.slots["child"]


class OcTree(OneCallAtATime):
    """A probabilistic 3D occupancy octree with OctoMap's update rules (its files: :mod:`occmap.io.octomap`).

    Parameters
    ----------
    resolution : float
        Edge of a depth-16 voxel in metres.
    prob_hit, prob_miss : float
        Sensor model: occupancy probability after a hit / a pass-through (OctoMap: 0.7 / 0.4);
        a hit above 0.5, a miss below (as the 2D sensor models take them; OctoMap takes any, and
        its early abort then stops a hit below 0.5 only at the lower clamp).
    clamp : (p_min, p_max)
        Clamping bounds in probability (OctoMap: 0.1192 / 0.971), p_min < p_max; a new node takes
        its first update clamped to them, as OctoMap's does, even where 0.5 lies outside.
    occupied_threshold : float
        Probability at or above which a node counts as occupied (OctoMap: 0.5).
    """

    def __init__(self, resolution: float, prob_hit: float = 0.7, prob_miss: float = 0.4,
                 clamp=(0.1192, 0.971), occupied_threshold: float = 0.5):
        self.resolution = checks.resolution(resolution)
        self.prob_hit = checks.probability_on_side("prob_hit", prob_hit, True)
        self.prob_miss = checks.probability_on_side("prob_miss", prob_miss, False)
        self.clamp = (checks.probability("clamp[0]", clamp[0]), checks.probability("clamp[1]", clamp[1]))
        self.occupied_threshold = checks.probability("occupied_threshold", occupied_threshold)
        if not self.clamp[0] < self.clamp[1]:
            raise InvalidArgumentError(f"clamp must be (p_min, p_max) with p_min < p_max, got {clamp!r}")
        self._l_hit = logit32(self.prob_hit)
        self._l_miss = logit32(self.prob_miss)
        self._l_min = logit32(self.clamp[0])
        self._l_max = logit32(self.clamp[1])
        self._l_occ = logit32(self.occupied_threshold)
        self._rule = (self._l_hit, self._l_miss, self._l_min, self._l_max)  # what insertion.apply takes
        self.stats = {"scans": 0, "points": 0, "dropped": 0, "outside_key_range": 0, "beyond_max_range": 0}
        self._bbx = None
        self.clear()

    # ------------------------------------------------------------------ storage

    def clear(self) -> None:
        """Forget every node (the map becomes all unknown)."""
        self._pool = pool.Pool()

    @property
    def log_odds_hit(self) -> float:
        return float(self._l_hit)

    @property
    def log_odds_miss(self) -> float:
        return float(self._l_miss)

    @property
    def clamping_log_odds(self) -> tuple[float, float]:
        return float(self._l_min), float(self._l_max)

    @property
    def occupied_log_odds(self) -> float:
        """Log-odds at or above which a node is occupied."""
        return float(self._l_occ)

    # ------------------------------------------------------------------ bounding-box limit

    @property
    def bbx(self):
        """Insertion limit (OctoMap's ``useBBXLimit``): ``None``, or ``(min, max)`` corners in metres.
        While set, scans update only voxels inside the box: a point outside it is no hit, and a ray
        frees the voxels it crosses until it leaves the box (none when the sensor is outside).
        Corners beyond the tree's reach (keys 0 … 65535) are stored clipped to just outside it,
        as OctoMap clips the box's keys: the same voxels, and no overflow in float32."""
        return self._bbx

    @bbx.setter
    def bbx(self, box) -> None:
        if box is None:
            self._bbx = None
            return
        lo, hi = (np.asarray(c, dtype=np.float64).reshape(-1) for c in box)
        if lo.shape != (3,) or hi.shape != (3,) or not np.all(np.isfinite(lo)) or not np.all(np.isfinite(hi)):
            raise InvalidArgumentError(f"bbx must be two finite corners (min, max) of 3 values each, got {box!r}")
        if np.any(lo > hi):
            raise InvalidArgumentError(f"bbx min {lo.tolist()} exceeds max {hi.tolist()}")
        lo, hi = self._within_reach(lo), self._within_reach(hi)
        self._bbx = (lo.astype(np.float32).astype(np.float64), hi.astype(np.float32).astype(np.float64))

    def _within_reach(self, p: np.ndarray) -> np.ndarray:
        """Coordinates (metres) clipped to one voxel beyond the tree on each side: their keys,
        clipped to 0 … MAX_KEY, are those of the unclipped corner."""
        reach = (CENTER + 1) * self.resolution
        return np.clip(p, -reach, reach)

    def _bbx_keys(self) -> np.ndarray:
        if self._bbx is None:
            return np.empty((0, 3), np.int64)
        return np.clip(coord_to_keys(np.stack(self._bbx), self.resolution), 0, MAX_KEY)

    # ------------------------------------------------------------------ keys

    @no_lock
    def coord_to_key(self, points) -> np.ndarray:
        """Depth-16 keys (N, 3) int64 of points (N, 3) in metres, OctoMap's ``coordToKey``
        (``floor(x / res) + 32768`` on the float64 coordinate). Raises on keys outside 0..65535."""
        P = points_array("points", points)
        keys = coord_to_keys(P, self.resolution)
        bad = np.flatnonzero(~keys_in_range(keys))
        if bad.size:
            raise InvalidArgumentError(f"point {int(bad[0])} {P[bad[0]].tolist()} lies outside the octree's key range "
                                       f"(±{CENTER * self.resolution:g} m at resolution {self.resolution:g} m)")
        return keys

    @no_lock
    def key_to_coord(self, keys, depth: int = 16) -> np.ndarray:
        """Centres (N, 3) of the nodes at ``depth`` that hold the given keys, computed as OctoMap's
        ``keyToCoord(key, depth)`` (bit for bit)."""
        k = np.asarray(keys, dtype=np.int64)
        return node_centers(k, np.full(k.shape[:-1], depth, np.int64), self.resolution)

    # ------------------------------------------------------------------ insertion

    def insert_point_cloud(self, points, origin, max_range: float = -1.0, discretize: bool = False,
                           lazy: bool = False) -> dict:
        """Integrate one scan as OctoMap's ``insertPointCloud`` does.

        ``points`` (N, 3) are the measured end points and ``origin`` (3,) the sensor position, both
        in the map frame, metres. Every ray marks the voxels it crosses free (the origin's voxel
        included, the end voxel excluded) and its end voxel occupied; a voxel that is both is
        occupied, and no voxel is updated twice in one scan. A point farther than ``max_range``
        (< 0: no limit) clears free space up to ``max_range`` and marks nothing. ``discretize``
        merges points that fall in one voxel first (one ray per voxel, from the voxel centre).
        ``lazy`` skips updating inner nodes and pruning (call :meth:`update_inner_occupancy` and
        :meth:`prune` when done). NaN/inf points are dropped and counted, and so are points whose ray
        ends outside the key range (OctoMap skips such a ray and inserts the rest). Returns this
        scan's counts: ``scans``, ``points``, ``dropped``, ``beyond_max_range``
        (``docs/architecture.md``), and ``outside_key_range`` (of ``dropped``).
        """
        blocks, summary = self._scan_blocks(points, origin, max_range, discretize, threads=True)
        insertion.apply_marked(self._pool, blocks, self._bbx_keys(), self._rule, lazy, threads=True)
        return self._count(summary)

    def insert_point_clouds(self, clouds, origins=None, max_range: float = -1.0, discretize: bool = False,
                            lazy: bool = False) -> dict:
        """Integrate many scans in order, each as :meth:`insert_point_cloud`. ``clouds`` holds
        (N_i, 3) arrays with ``origins`` (S, 3), or objects with ``world_points()`` and ``origin``
        (:class:`occmap.cloud.PointCloud`). With two threads or more (Numba's count) and cores
        that other processes leave free, the next scan's rays are traced on another thread (shared
        with the workers where it is large) while the tree takes the current one (here when that
        thread has not started by then), the workers taking runs of the update where it is large.
        In a batch of several scans (:data:`.insertion.SETTLE_AFTER_SCANS`) inner nodes are settled
        (maximum of their children, pruned) once, after the last scan, where the scans changed
        something below them: the tree eager updates leave, with a region seen by scan after scan
        settled once rather than after each. Returns the summed summary."""
        clouds = list(clouds)
        if origins is None:
            pairs = [(c.world_points(), c.origin) for c in clouds]
        else:
            O = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
            if len(O) != len(clouds):
                raise ShapeError(f"{len(clouds)} clouds but {len(O)} origins")
            pairs = list(zip(clouds, O))
        total = dict.fromkeys(self.stats, 0)
        pending = None
        ahead = thread_count() >= 2
        # the nodes many scans change are settled once, after the last (the same tree: see
        # insertion.settle_changes), also when a scan is refused midway
        changes = [] if not lazy and len(pairs) >= insertion.SETTLE_AFTER_SCANS else None
        try:
            for k in range(len(pairs)):
                if pending is not None and pending.cancel():
                    pending = None
                current = pending.result() if pending else self._scan_blocks(*pairs[k], max_range, discretize, True)
                pending = (insertion.ahead(self._scan_blocks, *pairs[k + 1], max_range, discretize, True)
                           if ahead and k + 1 < len(pairs) and free_for_parallel() else None)
                blocks, summary = current
                # shared with a worker even while the next scan is traced: the three threads share
                # the cores, and the update (three quarters of a drive's work at 0.05 m) no longer
                # waits on this thread alone (that drive 2.1 s against 2.8 - 3.1 s)
                insertion.apply_marked(self._pool, blocks, self._bbx_keys(), self._rule, lazy, threads=True,
                                       changes=changes)
                for name, value in self._count(summary).items():
                    total[name] += value
        finally:
            insertion.settle_changes(self._pool, changes, threads=True)
        return total

    def _scan_blocks(self, points, origin, max_range: float, discretize: bool, threads: bool):
        """A scan's marked blocks (:func:`.insertion.cloud_blocks`) and its summary (no change to
        the tree: scans can be traced ahead on another thread)."""
        P = points_array("points", points)
        o32 = _origin(origin).astype(np.float32)
        self.coord_to_key(o32.astype(np.float64))  # (an origin out of range is refused)
        box = np.empty((0, 3), np.float32) if self.bbx is None else np.array(self.bbx, np.float32)
        return insertion.cloud_blocks(P, o32, max_range, discretize, self.resolution, box, self._bbx_keys(), NO_SHIFT,
                                      threads)

    def _count(self, summary: dict) -> dict:
        """This scan's counts (``scans`` = 1 and the summary's), added to :attr:`stats`."""
        counts = {"scans": 1, **summary}
        for name, value in counts.items():
            self.stats[name] += value
        return counts

    def insert_rays(self, origins, ends, max_range: float = -1.0, lazy: bool = False) -> int:
        """OctoMap's ``insertRay`` for each ray in turn: the voxels from ``origins`` (N, 3) or one
        origin (3,) to ``ends`` (N, 3) free, each end's voxel occupied; with ``max_range > 0`` a
        longer ray is cut there and marks nothing. Unlike :meth:`insert_point_cloud`, rays are
        independent updates (a voxel crossed by two rays is updated twice). A ray whose (cut) end
        lies outside the key range is skipped, as OctoMap's ``insertRay`` does. Returns the number
        of rays inserted."""
        E = points_array("ends", ends)
        O = np.asarray(origins, dtype=np.float64)
        O = points_array("origins", O) if O.ndim == 2 else _origin(O)[None, :]
        if O.shape[0] not in (1, E.shape[0]):
            raise ShapeError(f"origins must be (3,) or ({E.shape[0]}, 3), got {O.shape}")
        if not np.all(np.isfinite(E)) or not np.all(np.isfinite(O)):
            raise InvalidArgumentError("ray origins and ends must be finite")
        O32 = O.astype(np.float32)
        self.coord_to_key(O32.astype(np.float64))
        E32, with_end, kept, _, _ = prepare_rays(E, O32, float(max_range) if max_range > 0 else -1.0, self.resolution,
                                                 np.empty((0, 3), np.float32), NO_SHIFT)
        keys, is_hit = ray_voxels(O32 if len(O32) == 1 else O32[kept], E32, with_end, self.resolution)
        insertion.apply(self._pool, keys, insertion.VOXELS, is_hit, self._rule, lazy)
        return len(kept)

    def insert_ray(self, origin, end, max_range: float = -1.0, lazy: bool = False) -> bool:
        """One ray (see :meth:`insert_rays`); false where it was skipped."""
        return self.insert_rays(_origin(origin), points_array("end", end), max_range, lazy) == 1

    def update_nodes(self, points, occupied, lazy: bool = False) -> None:
        """OctoMap's ``updateNode(point, occupied)`` for each point in turn: one hit (``occupied``
        true) or miss on the voxel holding it. ``occupied`` is a bool or one bool per point."""
        P = points_array("points", points)
        if not np.all(np.isfinite(P)):
            raise InvalidArgumentError("points must be finite")
        occ = np.broadcast_to(np.asarray(occupied, dtype=bool), P.shape[:1])
        k = self.coord_to_key(P.astype(np.float32).astype(np.float64))
        insertion.apply(self._pool, pack_keys(k), insertion.VOXELS, np.ascontiguousarray(occ), self._rule, lazy)

    def update_voxels(self, keys, is_hit, threads: bool = False, depths=None) -> None:
        """Update voxels given as packed keys (int64, :func:`occmap.octree.keys.pack` of depth-16
        keys), each with one hit (``is_hit``) or miss, as one scan updates them: each key once, in
        Morton order when ``threads`` (then many voxels go on two threads). With ``depths`` (int8),
        ``keys[i]`` is the first voxel of the node at ``depths[i]``, all of whose voxels take the
        update. The path by which tiled maps (:mod:`occmap.world`) apply a scan to their tiles.
        Checked before anything changes: shapes (one flag and depth a key), every key packing keys of
        0 .. 65535, depths 0 .. 16 (:class:`ShapeError`, :class:`InvalidArgumentError`)."""
        keys = np.ascontiguousarray(keys, np.int64)
        is_hit = np.ascontiguousarray(is_hit, np.bool_)
        if keys.ndim != 1 or is_hit.shape != keys.shape:
            raise ShapeError(f"keys must be 1-D and is_hit of the same shape, got {keys.shape} and {is_hit.shape}")
        bad = np.flatnonzero(~packed_in_range(keys))
        if len(bad):
            raise InvalidArgumentError(f"keys[{bad[0]}] = {keys[bad[0]]} does not pack three keys of 0 .. {MAX_KEY} "
                                       f"({len(bad)} such keys)")
        if depths is None:
            depths = insertion.VOXELS
        else:
            depths = np.asarray(depths)
            if depths.shape != keys.shape:
                raise ShapeError(f"depths must have the shape of keys {keys.shape}, got {depths.shape}")
            bad = np.flatnonzero((depths < 0) | (depths > DEPTH))
            if len(bad):
                raise InvalidArgumentError(f"depths[{bad[0]}] = {depths[bad[0]]} is not a depth of 0 .. {DEPTH}")
            depths = np.ascontiguousarray(depths, np.int8)
        insertion.apply(self._pool, keys, depths, is_hit, self._rule, False, threads)

    def update_inner_occupancy(self) -> None:
        """Set every inner node to the maximum of its children (after ``lazy`` insertions)."""
        pool.settle_tree(self._pool.slots, self._pool.meta, -1, True, False)

    def prune(self) -> None:
        """Collapse nodes whose eight children are leaves with equal values, as OctoMap's ``prune``:
        level by level from depth 15 up to depth 1 (never the root), stopping after the first
        level where nothing collapsed."""
        for depth in range(15, 0, -1):
            if pool.settle_tree(self._pool.slots, self._pool.meta, depth, False, True) == 0:
                break

    def expand(self) -> None:
        """Expand every pruned leaf into its depth-16 voxels (OctoMap's ``expand``; memory grows by
        8^(16 − depth) per pruned leaf)."""
        depths = self.leaves().depths
        new_nodes = int(sum(((8 ** (17 - depths) - 8) // 7).tolist()))
        top = int(self._pool.meta[pool.TOP])
        if self._pool.slots.shape[0] < top + new_nodes:
            self._pool.grow(top + new_nodes)
        pool.expand_all(self._pool.slots, self._pool.meta)

    def to_max_likelihood(self) -> None:
        """Set every node to the clamping bound of its class (occupied: upper, free: lower)."""
        pool.to_max_likelihood(self._pool.slots, self._l_occ, self._l_min, self._l_max)

    # ------------------------------------------------------------------ queries

    def _search(self, points, depth: int) -> np.ndarray:
        depth = _depth(depth)
        P = points_array("points", points)
        keys = coord_to_keys(P, self.resolution)
        inside = keys_in_range(keys) & np.all(np.isfinite(P), axis=1)
        keys[~inside] = 0
        nodes = query.search_keys(self._pool.slots, keys, depth)
        nodes[~inside] = -1
        return nodes

    def log_odds_at(self, points, depth: int = 16) -> np.ndarray:
        """Log-odds (N,) of the node holding each point at ``depth`` (or of a pruned ancestor);
        NaN where the space is unknown or outside the tree."""
        nodes = self._search(points, depth)
        out = np.full(nodes.shape, np.nan)
        known = nodes >= 0
        out[known] = self._pool.slots["value"][nodes[known]]
        return out

    def occupancy_at(self, points, depth: int = 16) -> np.ndarray:
        """Per point: −1 unknown, 0 free, 1 occupied (log-odds ≥ that of ``occupied_threshold``)."""
        return occupancy_classes(self.log_odds_at(points, depth), self._l_occ)

    def cast_ray(self, origins, directions, max_range: float = -1.0, ignore_unknown: bool = False):
        """OctoMap's ``castRay`` for each ray: from the voxel of ``origins`` (N, 3) (or one (3,))
        along ``directions`` (N, 3) (or one), stop at the first occupied voxel (a hit), at an
        unknown voxel (a miss, unless ``ignore_unknown``), beyond ``max_range`` (> 0) or at the
        tree's border. Returns ``(hit (N,) bool, end_points (N, 3))``: the centre of the voxel where
        each ray stopped; NaN where it could not be cast (origin outside the tree, zero direction).
        """
        O, D = points_array("origins", origins), points_array("directions", directions)
        n = max(len(O), len(D))
        if len(O) not in (1, n) or len(D) not in (1, n):
            raise ShapeError(f"origins {O.shape} and directions {D.shape} do not match")
        hit, ends = query.cast_rays(self._pool.slots, O.astype(np.float32), D.astype(np.float32),
                                self.resolution, float(max_range), bool(ignore_unknown), self._l_occ)
        return hit, ends.astype(np.float64)

    def leaves(self, bbx_min=None, bbx_max=None, depth: int | None = None) -> Leaves:
        """The leaves (nodes at ``depth`` count as leaves when given), optionally only those
        overlapping the box [bbx_min, bbx_max] in metres."""
        return self._nodes(bbx_min, bbx_max, 16 if depth is None else depth, True)

    def _nodes(self, bbx_min, bbx_max, depth: int, leaves_only: bool) -> Leaves:
        depth = _depth(depth)
        kmin = np.zeros(3, np.int64) if bbx_min is None else np.clip(self._bbx_key(bbx_min), 0, MAX_KEY)
        kmax = np.full(3, MAX_KEY, np.int64) if bbx_max is None else np.clip(self._bbx_key(bbx_max), 0, MAX_KEY)
        args = (self._pool.slots, depth, kmin, kmax, leaves_only)
        n = query.collect_nodes(*args, True, np.empty((0, 3), np.int64), np.empty(0, np.int64), np.empty(0, np.float32))
        keys = np.empty((n, 3), np.int64)
        depths = np.empty(n, np.int64)
        values = np.empty(n, np.float32)
        query.collect_nodes(*args, False, keys, depths, values)
        sizes = self.resolution * node_cells(depths).astype(np.float64)
        return Leaves(node_centers(keys, depths, self.resolution), sizes, values, depths)

    def _bbx_key(self, p) -> np.ndarray:
        p = np.asarray(p, dtype=np.float64)
        if p.shape != (3,):
            raise ShapeError(f"bounding-box corners must have shape (3,), got {p.shape}")
        if np.isnan(p).any():
            raise InvalidArgumentError(f"bounding-box corners must not be NaN, got {p.tolist()}")
        return coord_to_keys(self._within_reach(p), self.resolution)

    def occupied_centers(self) -> np.ndarray:
        """Centres (M, 3) of the occupied leaves (at their own depth)."""
        lv = self.leaves()
        return lv.centers[lv.log_odds >= self._l_occ]

    def num_nodes(self) -> int:
        """Number of nodes, inner and leaves (OctoMap's ``size()``)."""
        return int(self._pool.meta[pool.SIZE])

    def num_leaves(self) -> int:
        """Number of leaf nodes (OctoMap's ``getNumLeafNodes()``)."""
        return int(query.count_leaves(self._pool.slots, int(self._pool.meta[pool.TOP])))

    def memory_usage(self) -> int:
        """Bytes the nodes occupy: every inner node's block of eight slots at 8 bytes a slot (float32
        value, int32 child index), plus the root. Compare with OctoMap's ``memoryUsage()``."""
        inner = self.num_nodes() - self.num_leaves()
        return (8 * inner + 1) * 8 if self.num_nodes() else 0

    def memory_allocated(self) -> int:
        """Bytes the node pool holds in memory (its slots, free room included)."""
        return self._pool.slots.nbytes + self._pool.meta.nbytes

    def metric_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(min, max) corners in metres of the box around every known leaf."""
        lv = self.leaves()
        if not len(lv.sizes):
            return np.zeros(3), np.zeros(3)
        half = 0.5 * lv.sizes[:, None]
        return (lv.centers - half).min(axis=0), (lv.centers + half).max(axis=0)

    def volume(self) -> float:
        """Volume in m³ of :meth:`metric_bounds`' box (OctoMap's ``volume()``)."""
        lo, hi = self.metric_bounds()
        return float(np.prod(hi - lo))

    # ------------------------------------------------------------------ nodes as arrays

    def nodes(self) -> Nodes:
        """The node pool's slots in use, read-only (a view, no copy; valid until the tree next
        changes): see :class:`Nodes` for the layout. File writers (:mod:`occmap.io.octomap`) read the tree
        through this."""
        p = self._pool
        slots = p.slots[:int(p.meta[pool.TOP])]
        slots.flags.writeable = False
        return Nodes(slots, int(p.meta[pool.SIZE]))

    @classmethod
    def from_nodes(cls, resolution: float, slots, count: int, **params) -> OcTree:
        """A tree of ``resolution`` whose node pool is ``slots`` (laid out as :class:`Nodes`
        describes, with no free blocks: the slots in use are ``0 .. len(slots)``) holding ``count``
        nodes; ``params`` (``prob_hit``, ``clamp``, ...) as for the constructor. The tree takes the
        array over (records of :data:`.pool.SLOT`, writeable, contiguous: it is not copied).
        Checked: length and type, not the structure (file readers check that as they build it)."""
        tree = cls(resolution, **params)
        slots = np.asarray(slots)
        if slots.dtype != pool.SLOT or slots.ndim != 1:
            raise ShapeError(f"slots must be a 1-D array of {pool.SLOT}, got {slots.dtype} {slots.shape}")
        if len(slots) < 8 or len(slots) % 8 or not slots.flags.writeable or not slots.flags.c_contiguous:
            raise InvalidArgumentError("slots must be writeable, contiguous and hold whole blocks of 8 slots (root "
                                       f"block included), got {len(slots)} slots")
        if not 0 <= count <= len(slots):
            raise InvalidArgumentError(f"count must be 0 .. {len(slots)} nodes, got {count}")
        p = tree._pool
        p.slots = slots
        p.meta = pool.new_meta(len(slots), count)
        return tree

    # ------------------------------------------------------------------ pictures and exports

    def save_height_png(self, path, pixel: float | None = None, z_max: float | str | None = "ceiling",
                        title: str = "height map"):
        """A labelled top-down figure: occupied columns coloured by their highest occupied z (an
        indoor map cut under its ceiling), known empty columns white, unknown light blue
        (:func:`occmap.viz.maps.height_figure`); returns the path."""
        from ..viz import figure, maps

        return figure.save(maps.height_figure(self, pixel, z_max, title), path)

    def save_slice_png(self, path, z: float, pixel: float | None = None, title: str = "horizontal slice"):
        """A labelled figure of the horizontal slice at height ``z`` metres: occupied dark, free
        white, unknown light blue (:func:`occmap.viz.maps.slice_figure`); returns the path."""
        from ..viz import figure, maps

        return figure.save(maps.slice_figure(self, z, pixel, title), path)

    def _repr_png_(self) -> bytes:
        """Jupyter shows an octree as its height map."""
        from ..viz import figure, maps

        return figure.png_bytes(maps.height_figure(self))

    def save_html(self, path, max_voxels: int | None = None, z_max: float | str | None = "ceiling"):
        """The occupied voxels as a 3D scene in one HTML file that any browser opens offline (turn,
        pan, zoom; :mod:`occmap.viz.inline`): at most ``max_voxels`` boxes (default
        :data:`~occmap.viz.inline.INLINE_MAX_VOXELS`, coarser nodes beyond), cut under
        ``z_max`` metres (``"ceiling"``: an indoor map's ceiling; None: nothing cut). Written
        atomically; returns the path."""
        from .._files import write_atomic
        from ..viz import inline

        voxels = inline.octree_voxels(self, max_voxels or inline.INLINE_MAX_VOXELS, z_max)
        return write_atomic(path, inline.scene_document(voxels).encode())

    def _repr_html_(self) -> str:
        """Jupyter shows an octree as a 3D scene one turns in the page (:mod:`occmap.viz.inline`);
        front ends without HTML take the height map (:meth:`_repr_png_`)."""
        from ..viz import inline

        return inline.iframe(inline.scene_document(inline.octree_voxels(self)))

    def export_ply(self, path, binary: bool = True) -> int:
        """Occupied leaf centres as a PLY point cloud coloured by height; returns the point count."""
        return views.export_ply(self, path, binary)

    def __repr__(self) -> str:
        return (f"OcTree(resolution={self.resolution:g}, nodes={self.num_nodes()}, "
                f"leaves={self.num_leaves()})")
