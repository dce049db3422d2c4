"""An octree map cut into tiles, without OctoMap's ±32768-voxel limit: :class:`TiledOcTree`.

Keys. A voxel's *global key* is OctoMap's ``floor(x / resolution) + 32768`` per axis, as an int64
(so it may lie far outside 0 .. 65535). With ``T`` = ``tile_size`` voxels (a power of two), tile
``t = (key − 32768) >> log2 T`` holds the voxels ``[t·T, (t + 1)·T)`` of each axis, i.e. the metres
``[t·T·res, (t + 1)·T·res)``. A tile is the subtree of one node of the global tree (depth
``16 − log2 T``): within it, a voxel has the *tile key* ``((key − 32768) mod T) + 32768``, so a
tile is kept as an :class:`~occmap.octree.OcTree` whose voxels lie at ``[0, T·res)`` metres — its
own valid OctoMap tree, and the same subtree (same nodes, same values) as the global tree's.

Insertion is OctoMap's ``insertPointCloud`` (:func:`occmap.octree.insertion.cloud_voxels`) with
the scan's keys local to a shift near its sensor (:mod:`occmap.octree.marking`): the walk computes
with the global keys, so each ray crosses exactly the voxels it crosses in one tree; the scan's
voxels are then split by tile and each tile takes its part, in scan order, each voxel once with
its hit or miss. Per voxel that is the sequence of updates one tree applies, and nodes above a
tile are settled when tiles are joined (:meth:`TiledOcTree.to_octree`), so a tiled map equals the
one tree, node for node, for any tile size. A ray longer than ``32768 − T/2`` voxels from its
sensor (3.2 km less half a tile at 0.1 m) is refused.

A map may own only a *region* (a box of tiles): it then updates only the tiles in it. Maps of
disjoint regions fed the same scans in the same order together hold the one map; that is how
:mod:`occmap.world.build` builds in parallel.
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np

from .. import checks
from .._files import write_atomic
from ..errors import FormatError, InvalidArgumentError, ShapeError
from ..io.octomap import decode_ot, encode_bt, encode_ot
from ..logodds import logit32, occupancy_classes
from ..octree import OcTree, insertion, query
from ..octree.keys import CENTER, DEPTH, MAX_KEY, coord_to_keys, node_cells, node_centers
from ..octree.tree import Leaves, points_array
from ..octree.pool import TOP, new_slots, settle_tree
from . import cast, graft
from .split import split_by_tile
from .store import TileStore
from .stored_map import StoredMap, region_box

_NO_BOX = np.empty((0, 3), np.float32)
_NO_KEYS = np.empty((0, 3), np.int64)
#: The ``.ot`` ending of a tile's file in a store.
TILE_SUFFIX = ".ot"
DEFAULT_TILE_SIZE = 512


class TiledOcTree(StoredMap):
    """A 3D occupancy map with OctoMap's semantics, cut into tiles (see the module docstring).

    Parameters
    ----------
    resolution : float
        Edge of a voxel in metres.
    tile_size : int
        Voxels per tile side, a power of two from 8 to 32768 (default 512: 51.2 m at 0.1 m).
    prob_hit, prob_miss, clamp, occupied_threshold
        As for :class:`~occmap.octree.OcTree` (OctoMap's defaults).
    region : ((tx0, ty0, tz0), (tx1, ty1, tz1)), optional
        The tiles this map updates (inclusive box of tile indices); default all.
    memory_limit : int, optional
        Bytes of tiles kept in memory; beyond it the least recently used ones are written to the
        store and dropped (needs a store). Default: no limit.

    A map in a folder: :meth:`create` a new store, :meth:`open` one (to read, or ``writable`` to
    add scans: mapping resumes with the full log-odds), :meth:`close` (or a ``with`` block) to
    finish. Used from several threads, one call runs at a time (the object's lock).
    """

    def __init__(self, resolution: float, tile_size: int = DEFAULT_TILE_SIZE, prob_hit: float = 0.7,
                 prob_miss: float = 0.4, clamp=(0.1192, 0.971), occupied_threshold: float = 0.5, *,
                 region=None, memory_limit: int | None = None):
        self._template = OcTree(resolution, prob_hit, prob_miss, clamp, occupied_threshold)  # checks them
        self.resolution = self._template.resolution
        tile_size = checks.count("tile_size", tile_size, minimum=8)
        if tile_size & (tile_size - 1) or tile_size > CENTER:
            raise InvalidArgumentError(f"tile_size must be a power of two from 8 to {CENTER}, got {tile_size}")
        self.tile_size = tile_size
        self._bits = tile_size.bit_length() - 1
        self.region = None if region is None else region_box(region, 3)
        self.memory_limit = None if memory_limit is None else checks.count("memory_limit", memory_limit, minimum=1)
        self.stats = {"scans": 0, "points": 0, "dropped": 0, "outside_key_range": 0, "beyond_max_range": 0}
        self._tiles: OrderedDict[tuple[int, int, int], OcTree] = OrderedDict()  # in memory, least recent first
        self._no_store()
        self._l_occ = logit32(self._template.occupied_threshold)

    @property
    def params(self) -> dict:
        """The sensor model and thresholds, as the constructor takes them."""
        t = self._template
        return {"prob_hit": t.prob_hit, "prob_miss": t.prob_miss, "clamp": list(t.clamp),
                "occupied_threshold": t.occupied_threshold}

    # ------------------------------------------------------------------ keys

    def tile_of(self, points) -> np.ndarray:
        """Tile indices (N, 3) int64 of points (N, 3) in metres."""
        return (coord_to_keys(points_array("points", points), self.resolution) - CENTER) >> self._bits

    def tile_bounds(self, index) -> tuple[np.ndarray, np.ndarray]:
        """``(min, max)`` corners in metres of tile ``index``."""
        side = self.tile_size * self.resolution
        t = np.asarray(index, np.float64)
        return t * side, (t + 1) * side

    # ------------------------------------------------------------------ insertion

    def insert_point_cloud(self, points, origin, max_range: float = -1.0, discretize: bool = False) -> dict:
        """Integrate one scan as :meth:`occmap.octree.OcTree.insert_point_cloud` does (same
        arguments but ``lazy``; NaN/inf points dropped and counted, and so are — in
        ``outside_key_range`` — points more than ``32768 − tile_size/2`` voxels from the sensor
        along an axis: beyond one ray's keys). Returns this scan's counts (all 0 for a scan that
        cannot reach the map's region: it is not counted)."""
        P = points_array("points", points)
        o = np.asarray(origin, dtype=np.float64)
        if o.shape != (3,) or not np.all(np.isfinite(o)):
            raise InvalidArgumentError(f"origin must be 3 finite numbers, got {np.asarray(origin).tolist()}")
        self._check_writable()
        o32 = o.astype(np.float32)
        centre = coord_to_keys(o32.astype(np.float64), self.resolution)
        T = self.tile_size
        shift = (np.floor_divide(centre - CENTER + T // 2, T) * T).astype(np.int64)  # a tile corner near the sensor
        keep = None
        if self.region is not None:
            lo = self.region[0] * T + CENTER - shift
            hi = (self.region[1] + 1) * T - 1 + CENTER - shift
            if np.any(hi < 0) or np.any(lo > MAX_KEY) or not self._may_reach(P, o, max_range, lo, hi, shift):
                return dict.fromkeys(self.stats, 0)
            keep = np.stack([np.maximum(lo, 0), np.minimum(hi, MAX_KEY)])
        keys, depths, is_hit, summary = insertion.cloud_voxels(P, o32, max_range, discretize, self.resolution, _NO_BOX,
                                                               _NO_KEYS, shift, True, keep)
        self._apply(keys, depths, is_hit, shift)
        return self._record(summary)

    def _may_reach(self, P, o, max_range, lo, hi, shift) -> bool:
        """Whether any ray of the scan can touch the local key box [lo, hi]: the box of its points
        and sensor (within ``max_range`` of it), a voxel wider each way, meets it."""
        finite = P[np.all(np.isfinite(P), axis=1)]
        b_lo = np.minimum(finite.min(axis=0), o) if len(finite) else o
        b_hi = np.maximum(finite.max(axis=0), o) if len(finite) else o
        if max_range >= 0:
            b_lo, b_hi = np.maximum(b_lo, o - max_range), np.minimum(b_hi, o + max_range)
        k_lo = coord_to_keys(b_lo, self.resolution) - shift - 1
        k_hi = coord_to_keys(b_hi, self.resolution) - shift + 1
        return bool(np.all(k_hi >= lo) and np.all(k_lo <= hi))

    def _apply(self, keys, depths, is_hit, shift) -> None:
        """Give each tile its part of a scan's updates (Morton order kept within a tile; a node
        update lies in one tile: tiles are whole nodes of 8 voxels a side or more)."""
        tiles, starts, local, levels, hits = split_by_tile(keys, depths, is_hit, shift, self._bits)
        for i, index in enumerate(map(tuple, tiles.tolist())):
            a, b = starts[i], starts[i + 1]
            self._tile(index, create=True).update_voxels(local[a:b], hits[a:b], threads=True, depths=levels[a:b])
            self._dirty.add(index)
        self._evict()

    def _record(self, summary: dict) -> dict:
        counts = {"scans": 1, **summary}
        for key, value in counts.items():
            self.stats[key] += value
        return counts

    # ------------------------------------------------------------------ tiles in memory

    def _tile(self, index, create: bool) -> OcTree | None:
        """Tile ``index`` (most recently used now): in memory, else read from the store, else a
        new empty one when ``create``, else None."""
        tree = self._tiles.get(index)
        if tree is not None:
            self._tiles.move_to_end(index)
            return tree
        if self._store is not None and index in self._store.tiles:
            tree = self._read_tile(index)
        elif create:
            t = self._template
            tree = OcTree(self.resolution, t.prob_hit, t.prob_miss, t.clamp, t.occupied_threshold)
        else:
            return None
        self._tiles[index] = tree
        return tree

    def _read_tile(self, index) -> OcTree:
        path = self._store.tile_file(index, TILE_SUFFIX)
        try:
            data = path.read_bytes()
        except FileNotFoundError:
            raise FormatError(path, f"tile {list(index)} is listed in the store's index but its file is missing") from None
        t = self._template
        tree = decode_ot(data, path, prob_hit=t.prob_hit, prob_miss=t.prob_miss, clamp=t.clamp,
                         occupied_threshold=t.occupied_threshold)
        if tree.resolution != self.resolution:
            raise FormatError(path, f"tile {list(index)} has resolution {tree.resolution!r}, the store "
                              f"{self.resolution!r}")
        return tree

    def _evict(self) -> None:
        """Write out and drop least recently used tiles while over the memory limit."""
        if self.memory_limit is None:
            return
        total = self.in_memory()[1]
        while total > self.memory_limit and len(self._tiles) > 1:
            index, tree = next(iter(self._tiles.items()))
            self._write_tile(index, tree)
            del self._tiles[index]
            total -= tree.memory_allocated()

    def _write_tile(self, index, tree: OcTree) -> None:
        if index not in self._dirty:
            return
        path = self._store.tile_file(index, TILE_SUFFIX)
        data = encode_ot(tree)
        write_atomic(path, data)
        lo, hi = self.tile_bounds(index)
        self._store.tiles[index] = {"file": str(path.relative_to(self._store.path)), "min": lo.tolist(),
                                    "max": hi.tolist(), "nodes": tree.num_nodes(), "bytes": len(data)}
        self._dirty.discard(index)
        self._written.add(index)

    def in_memory(self) -> tuple[int, int]:
        """Tiles held in memory now, and the bytes their node pools take."""
        return len(self._tiles), sum(t.memory_allocated() for t in self._tiles.values())

    def tiles(self) -> dict[tuple[int, int, int], dict]:
        """The tiles holding nodes, in index order: ``(tx, ty, tz)`` → ``{"min": [x, y, z], "max":
        [x, y, z]`` (metres), ``"nodes"}`` (and ``"file"``, its ``.ot`` in the store, and
        ``"bytes"``, its size, for a tile as last written to a store)."""
        out = {} if self._store is None else {i: dict(e) for i, e in self._store.tiles.items()}
        for index, tree in self._tiles.items():
            if index in self._dirty or index not in out:
                lo, hi = self.tile_bounds(index)
                out[index] = {"min": lo.tolist(), "max": hi.tolist(), "nodes": tree.num_nodes()}
        return {i: out[i] for i in sorted(out) if out[i]["nodes"]}

    def tile(self, index) -> OcTree | None:
        """Tile ``index`` as an :class:`OcTree` in tile keys (voxels at ``[0, tile_size·res)``
        metres), or None when it holds nothing. The map's own tile: do not change it."""
        return self._tile(tuple(int(v) for v in index), create=False)

    # ------------------------------------------------------------------ queries

    def log_odds_at(self, points) -> np.ndarray:
        """Log-odds (N,) of the voxel (or pruned node) holding each point; NaN where unknown."""
        P = points_array("points", points)
        out = np.full(len(P), np.nan)
        good = np.all(np.isfinite(P), axis=1)
        keys = coord_to_keys(np.where(good[:, None], P, 0.0), self.resolution) - CENTER
        tiles = keys >> self._bits
        local = (keys & (self.tile_size - 1)) + CENTER
        for index in {tuple(t) for t in tiles[good].tolist()}:
            sel = np.flatnonzero(good & np.all(tiles == index, axis=1))
            tree = self._tile(index, create=False)
            if tree is None:
                continue
            nodes = tree.nodes()
            found = query.search_keys(nodes.slots, local[sel], DEPTH)
            known = found >= 0
            out[sel[known]] = nodes.value[found[known]]
        return out

    def occupancy_at(self, points) -> np.ndarray:
        """Per point: −1 unknown, 0 free, 1 occupied (log-odds ≥ that of ``occupied_threshold``)."""
        return occupancy_classes(self.log_odds_at(points), self._l_occ)

    def cast_ray(self, origins, directions, max_range: float = -1.0, ignore_unknown: bool = False):
        """OctoMap's ``castRay`` for each ray across the tiles, as
        :meth:`occmap.octree.OcTree.cast_ray`: from the voxel of ``origins`` (N, 3) (or one)
        along ``directions`` (N, 3) (or one), stop at the first occupied voxel (a hit), at an
        unknown one (a miss, unless ``ignore_unknown``), beyond ``max_range`` (> 0), or — for rays
        that only those two would stop — on leaving the box of the map's tiles (its border; a
        tree's is its key range). Returns ``(hit (N,), end_points (N, 3))``: the
        centre of the voxel where each ray stopped, NaN for a ray with no direction."""
        O = points_array("origins", origins).astype(np.float32)
        D = points_array("directions", directions).astype(np.float32)
        n = max(len(O), len(D))
        if len(O) not in (1, n) or len(D) not in (1, n):
            raise ShapeError(f"origins {O.shape} and directions {D.shape} do not match")
        if not (np.all(np.isfinite(O)) and np.all(np.isfinite(D))):
            raise InvalidArgumentError("ray origins and directions must be finite")
        keys, steps, t, g, _ = cast.start_rays(O, D, self.resolution)
        status = np.full(n, cast.MOVED, np.int8)
        first = np.ones(n, np.bool_)
        tiles = list(self.tiles())
        T = self.tile_size
        if ignore_unknown and max_range <= 0:
            t_all = np.array(tiles or [(0, 0, 0)], np.int64)
            lo, hi = t_all.min(axis=0) * T + CENTER, (t_all.max(axis=0) + 1) * T - 1 + CENTER
            status[np.any((keys < lo) | (keys > hi), axis=1) | (not tiles)] = cast.STOPPED  # origins outside the map
        else:  # unknown space or max_range stops every ray
            lo, hi = np.full(3, -(1 << 62), np.int64), np.full(3, 1 << 62, np.int64)
        unknown = new_slots(0)
        while True:
            active = np.flatnonzero(status == cast.MOVED)
            if not len(active):
                break
            where = (keys[active] - CENTER) >> self._bits
            order = np.lexsort(where.T[::-1])
            where, active = where[order], active[order]
            cuts = np.flatnonzero(np.any(where[1:] != where[:-1], axis=1)) + 1
            for group in np.split(np.arange(len(active)), cuts):
                index = tuple(int(v) for v in where[group[0]])
                tree = self._tile(index, create=False)
                slots = unknown if tree is None else tree.nodes().slots
                base = np.array(index, np.int64) * T + CENTER
                cast.walk_tile(slots, base, T, active[group], O, keys, steps, t, g, first, self.resolution,
                               float(max_range), bool(ignore_unknown), self._l_occ, lo, hi, status)
        ends = (keys - CENTER + 0.5) * self.resolution
        ends = ends.astype(np.float32).astype(np.float64)
        ends[status == cast.NOT_CAST] = np.nan
        return status == cast.HIT, ends

    def leaves(self, bbx_min=None, bbx_max=None):
        """The leaves of the tiles (:class:`occmap.octree.tree.Leaves`: centres, sizes in metres,
        log-odds, depths), only those overlapping the box [bbx_min, bbx_max] in metres when given;
        centres computed from global keys as OctoMap's ``keyToCoord`` does. Eight uniform tiles
        that one tree would hold as a single larger leaf come as their eight tiles' leaves."""
        box = None if bbx_min is None and bbx_max is None else (
            np.full(3, -np.inf) if bbx_min is None else np.asarray(bbx_min, np.float64),
            np.full(3, np.inf) if bbx_max is None else np.asarray(bbx_max, np.float64))
        parts = []
        for index in self._chosen(None if box is None else tuple(np.clip(b, -1e15, 1e15) for b in box)):
            base = np.array(index, np.int64) * self.tile_size  # (key − 32768) of the tile's first voxel
            if box is None:
                kmin, kmax = np.zeros(3, np.int64), np.full(3, MAX_KEY, np.int64)
            else:
                k = coord_to_keys(np.clip(np.stack(box), -1e15, 1e15), self.resolution) - CENTER - base + CENTER
                kmin, kmax = np.clip(k[0], 0, MAX_KEY), np.clip(k[1], 0, MAX_KEY)
            nodes = self._tile(index, create=False).nodes()
            args = (nodes.slots, DEPTH, kmin, kmax, True)
            n = query.collect_nodes(*args, True, np.empty((0, 3), np.int64), np.empty(0, np.int64),
                                    np.empty(0, np.float32))
            keys, depths, values = np.empty((n, 3), np.int64), np.empty(n, np.int64), np.empty(n, np.float32)
            query.collect_nodes(*args, False, keys, depths, values)
            parts.append((keys + base, depths, values))
        keys, depths, values = (np.concatenate(a) for a in zip(*parts)) if parts else (
            np.empty((0, 3), np.int64), np.empty(0, np.int64), np.empty(0, np.float32))
        return Leaves(node_centers(keys, depths, self.resolution), self.resolution * node_cells(depths).astype(np.float64),
                      values, depths)

    # ------------------------------------------------------------------ one tree

    def to_octree(self, box=None, offset=(0, 0, 0)) -> OcTree:
        """The tiles (those meeting ``box`` = (min, max) in metres, default all) joined into one
        :class:`OcTree`: node for node the tree one process builds from the same scans. The tree's
        coordinates are the world's less ``offset`` tiles (default none; see :meth:`export`).
        Raises when the tiles reach beyond OctoMap's key range."""
        chosen = self._chosen(box)
        offset = np.asarray(offset, np.int64)
        dt = DEPTH - self._bits
        sizes = []
        for index in chosen:
            lo = (np.array(index, np.int64) - offset) * self.tile_size + CENTER
            if np.any(lo < 0) or np.any(lo + self.tile_size - 1 > MAX_KEY):
                bound = CENTER * self.resolution
                raise InvalidArgumentError(f"tile {list(index)} lies beyond OctoMap's key range (±{bound:g} m at "
                                           f"{self.resolution:g} m{' from the offset' if offset.any() else ''}): "
                                           "export a smaller box")
            nodes = self._tile(index, create=False).nodes()
            sizes.append(graft.subtree_slots(nodes.slots, _tile_node(nodes, dt)))
        slots, meta = graft.new_pool(sum(sizes) + 8 * dt * (len(chosen) + 1))
        for index in chosen:
            nodes = self._tile(index, create=False).nodes()
            k = (np.array(index, np.int64) - offset) * self.tile_size + CENTER
            graft.graft(slots, meta, nodes.slots, _tile_node(nodes, dt), k[0], k[1], k[2], dt)
        for d in range(dt - 1, -1, -1):  # the nodes above the tiles, deepest first, as updates leave them
            settle_tree(slots, meta, d, True, True)
        top = int(meta[TOP])
        t = self._template
        return OcTree.from_nodes(self.resolution, slots[:top].copy(), int(meta[2]),
                                 prob_hit=t.prob_hit, prob_miss=t.prob_miss, clamp=t.clamp,
                                 occupied_threshold=t.occupied_threshold)

    def _chosen(self, box) -> list:
        indices = list(self.tiles())
        if box is not None:
            lo, hi = (np.asarray(b, np.float64) for b in box)
            if lo.shape != (3,) or hi.shape != (3,) or not np.all(lo <= hi):
                raise InvalidArgumentError(f"box must be (min, max) corners of 3 numbers, min ≤ max, got {box!r}")
            t_lo, t_hi = self.tile_of(np.stack([lo, hi]))
            indices = [i for i in indices if np.all(t_lo <= i) and np.all(np.array(i) <= t_hi)]
        return [i for i in indices if self._tile(i, create=False) is not None]

    # ------------------------------------------------------------------ the store

    KIND = "octree"

    @classmethod
    def _from_store(cls, store: TileStore, region, memory_limit) -> TiledOcTree:
        p = store.params
        return cls(store.resolution, store.tile_size, p.get("prob_hit", 0.7), p.get("prob_miss", 0.4),
                   tuple(p.get("clamp", (0.1192, 0.971))), p.get("occupied_threshold", 0.5), region=region,
                   memory_limit=memory_limit)

    def _write_changed(self) -> None:
        for index, tree in self._tiles.items():
            self._write_tile(index, tree)

    def export(self, path, box=None) -> np.ndarray:
        """Write the tiles meeting ``box`` (default all) joined into one OctoMap file, ``.bt``
        (maximum likelihood) or ``.ot`` (full log-odds) by ``path``'s extension. In world
        coordinates when they fit OctoMap's key range; else relative to the lowest corner of the
        exported tiles, and that offset is written in the header as the comment
        ``occmap offset: x y z`` (metres to add for world coordinates; OctoMap skips comments).
        Returns the offset (3,) in metres."""
        suffix = str(path).lower().rsplit(".", 1)[-1]
        if suffix not in ("bt", "ot"):
            raise InvalidArgumentError(f"{str(path)!r}: an export is a .bt or .ot file")
        offset = np.zeros(3, np.int64)
        chosen = self._chosen(box)
        if chosen:
            t = np.array(chosen, np.int64)
            reach = CENTER // self.tile_size
            if np.any(t.min(axis=0) < -reach) or np.any(t.max(axis=0) >= reach):
                offset = t.min(axis=0)
        tree = self.to_octree(box, offset)
        metres = offset * (self.tile_size * self.resolution)
        comment = f"occmap offset: {metres[0]!r} {metres[1]!r} {metres[2]!r}" if offset.any() else None
        write_atomic(path, (encode_bt if suffix == "bt" else encode_ot)(tree, comment))
        return metres

    def __repr__(self) -> str:
        return (f"TiledOcTree({self.resolution} m, tiles of {self.tile_size} voxels, {len(self.tiles())} tiles, "
                f"{self.stats['scans']} scans)")


def _tile_node(nodes, depth: int) -> int:
    """Slot of the node at ``depth`` holding key (32768, 32768, 32768): a tile's subtree root."""
    node = 0
    for d in range(depth):
        node = int(nodes.child[node]) + 7 * ((CENTER >> (DEPTH - 1 - d)) & 1)
    return node
