"""A 2D occupancy grid cut into tiles, with no extent limit: :class:`TiledGrid2D`.

Cells. The world lattice of :mod:`occmap.raster` with origin (0, 0): cell ``(ix, iy)`` spans
``[ix·res, (ix+1)·res) × [iy·res, (iy+1)·res)``, found as ``floor(x · (1/res))``, int64 indices.
With ``T`` = ``tile_size`` cells (a power of two), tile ``(tx, ty)`` holds the cells
``[tx·T, (tx+1)·T) × [ty·T, (ty+1)·T)``, i.e. ``tx = ix >> log2 T``. These are the cells of a
growing :class:`~occmap.grid2d.OccupancyGrid2D` (no ``origin``), which sits on the same lattice.

Insertion. Each beam is given to the tiles its walk crosses, and each tile applies, scan after
scan, the hits that end in it and the misses of each beam on its own cells, walked with exactly
the global walk (entered where it enters the tile, :func:`occmap.raster.walk2d.dda_span`): per
cell the updates one grid applies, in the same order (kernels and the argument in
:mod:`occmap.world._grid_kernels`). So the map equals ``OccupancyGrid2D`` cell for cell — the
same float32 log-odds, the same unknown cells — for any tile size. (Sonar rings are not taken yet.)

Regions. A map may own only a box of tiles (``region``): it then updates those alone. Maps of
disjoint regions fed the same scans in the same order together hold the one map; that is how a
parallel build splits the work.

On disk. :meth:`TiledGrid2D.create` / :meth:`~TiledGrid2D.open` keep the map in a tile store
folder (:mod:`occmap.world.store`, kind ``"grid"``) whose tiles are one zarr array
(:mod:`occmap.world.zarr_tiles`); mapping resumes from the stored float32 log-odds, and a
``memory_limit`` keeps only the most recently used tiles in memory (the others written out).
"""

from __future__ import annotations

import math
from collections import OrderedDict

import numpy as np

from .. import checks
from .._threads import ThreadChoice
from ..errors import InvalidArgumentError, ShapeError
from ..grid2d import LidarModel, OccupancyGrid2D
from ..grid2d._kernels import beam_extent, count_readings
from ..grid2d.grid import scan_arrays
from ..logodds import occupancy_classes, occupancy_values
from ..raster.update import SEEN, UNSEEN, ScanCodes
from . import _grid_kernels as K
from .store import TILES, TileStore
from .stored_map import StoredMap, region_box, union_extent
from .zarr_tiles import CELL_OFFSET, ZarrTiles

DEFAULT_TILE_SIZE = 256
#: Most scans integrated in one run (a run is split further while it reaches too far).
_RUN_SCANS = 512
#: Largest box of tiles (table entries) and most beam-tile visits one run may list.
_RUN_TABLE = 1 << 22
_RUN_ITEMS = 1 << 23
#: One thread or several per run, by their measured cost per beam-tile visit.
THREADS = ThreadChoice(min_work=2048)
_NO_ITEMS = np.empty(0, np.int64)


class TiledGrid2D(StoredMap):
    """A 2D occupancy grid in log-odds cut into tiles (see the module docstring); the semantics,
    parameters and names of a growing :class:`~occmap.grid2d.OccupancyGrid2D`.

    Parameters
    ----------
    resolution : float
        Cell side in metres.
    tile_size : int
        Cells per tile side, a power of two (default 256: 12.8 m at 5 cm).
    prior, clamp, occupied_threshold
        As for :class:`~occmap.grid2d.OccupancyGrid2D`.
    region : ((tx0, ty0), (tx1, ty1)), optional
        The tiles this map updates (inclusive box of tile indices); default all.
    memory_limit : int, optional
        Bytes of tiles kept in memory (6 bytes a cell); beyond it the least recently used tiles
        are written to the store and dropped (needs a store). Default: no limit.

    A map in a folder: :meth:`create` a new store, :meth:`open` one (to read, or ``writable`` to
    add scans), :meth:`close` (or a ``with`` block) to finish. One call runs at a time.
    """

    def __init__(self, resolution: float, tile_size: int = DEFAULT_TILE_SIZE, prior: float = 0.5,
                 clamp=(0.1192, 0.971), occupied_threshold: float = 0.5, *, region=None,
                 memory_limit: int | None = None):
        self._template = OccupancyGrid2D(resolution, prior=prior, clamp=clamp,
                                         occupied_threshold=occupied_threshold)  # checks them
        self.resolution = self._template.resolution
        self.prior, self.clamp = float(prior), (float(clamp[0]), float(clamp[1]))
        self.occupied_threshold = self._template.occupied_threshold
        self.tile_size = checks.count("tile_size", tile_size, minimum=1)
        if self.tile_size & (self.tile_size - 1):
            raise InvalidArgumentError(f"tile_size must be a power of two, got {tile_size}")
        self._bits = self.tile_size.bit_length() - 1
        self.region = None if region is None else region_box(region, 2)
        self._tile_bytes = 6 * self.tile_size**2
        self.memory_limit = None if memory_limit is None else checks.count("memory_limit", memory_limit, minimum=1)
        if self.memory_limit is not None and self.memory_limit < self._tile_bytes:
            raise InvalidArgumentError(f"memory_limit = {memory_limit} bytes holds no tile of {self.tile_size}² "
                                       f"cells ({self._tile_bytes} bytes)")
        self.stats = {"scans": 0, "points": 0, "dropped": 0, "beyond_max_range": 0}
        T = self.tile_size
        self._L = np.empty((0, T, T), np.float32)  # the pool of tiles in memory (kernels module)
        self._S = np.empty((0, T, T), np.uint16)
        self._slots: OrderedDict[tuple[int, int], int] = OrderedDict()  # tile → slot, least recent first
        self._free: list[int] = []
        self._codes = ScanCodes(np.uint16)
        self._zarr: ZarrTiles | None = None
        self._no_store()

    @property
    def params(self) -> dict:
        """The prior, clamping and threshold, as the constructor takes them (JSON values)."""
        return {"prior": self.prior, "clamp": list(self.clamp), "occupied_threshold": self.occupied_threshold}

    # ------------------------------------------------------------------ cells and tiles

    def tile_of(self, points) -> np.ndarray:
        """Tile indices ``(tx, ty)`` (..., 2) int64 of world points (..., 2) in metres."""
        return self._cells_of(points) >> self._bits

    def _cells_of(self, points) -> np.ndarray:
        """Lattice cells ``(ix, iy)`` (..., 2) of finite points (the kernels' index rule)."""
        p = np.asarray(points, dtype=np.float64)
        if p.shape[-1:] != (2,):
            raise ShapeError(f"points must have shape (..., 2), got {p.shape}")
        return np.floor(p * (1.0 / self.resolution)).astype(np.int64)

    def tile_bounds(self, index) -> tuple[np.ndarray, np.ndarray]:
        """``(min, max)`` corners in metres of tile ``(tx, ty)``."""
        side = self.tile_size * self.resolution
        t = np.asarray(index, np.float64)
        return t * side, (t + 1) * side

    def box_cells(self, box) -> tuple[int, int, int, int]:
        """The lattice cells ``[x0, x1) × [y0, y1)`` whose centres lie in ``box = (xmin, ymin,
        xmax, ymax)`` metres: the cells :meth:`log_odds` returns for it. The world position of its
        corner cell's outer corner is ``(x0·res, y0·res)``."""
        b = np.asarray(box, dtype=np.float64)
        if b.shape != (4,) or not np.all(np.isfinite(b)) or not (b[0] <= b[2] and b[1] <= b[3]):
            raise InvalidArgumentError(f"box must be (xmin, ymin, xmax, ymax) in metres, finite, min ≤ max; got "
                                       f"{np.asarray(box).tolist()}")
        res = self.resolution
        x0, y0 = (math.ceil(v / res - 0.5) for v in b[:2])
        x1, y1 = (math.floor(v / res - 0.5) + 1 for v in b[2:])
        return x0, y0, max(x0, x1), max(y0, y1)

    # ------------------------------------------------------------------ insertion

    def insert_scan(self, pose, ranges, angles, max_range: float | None = None, model: LidarModel | None = None) -> dict:
        """Insert one scan from sensor pose ``(x, y, theta)``; see :meth:`insert_scans`."""
        r = np.asarray(ranges, dtype=np.float64)
        return self.insert_scans(np.asarray(pose, dtype=np.float64)[None], r[None], angles, max_range, model)

    def insert_scans(self, poses, ranges, angles, max_range: float | None = None, model: LidarModel | None = None) -> dict:
        """Insert N scans in one call, exactly as :meth:`occmap.grid2d.OccupancyGrid2D.insert_scans`
        (same arguments, conventions and returned counts; the counts are of every scan given, also
        those that miss the map's region)."""
        model = LidarModel() if model is None else model
        P, R, A, max_range = scan_arrays(poses, ranges, angles, max_range)
        self._check_writable()
        self._check_reach(P, R, A, max_range)
        if len(P):  # the lattice cells of the box the beams reach (OccupancyGrid2D's growth rule)
            xmin, ymin, xmax, ymax = beam_extent(P, R, A, max_range)
            inv = 1.0 / self.resolution
            box = [math.floor(xmin * inv), math.floor(ymin * inv), math.floor(xmax * inv) + 1, math.floor(ymax * inv) + 1]
            self.extent = union_extent(self.extent, box)
        d = (model.l_hit - self._template.l_prior, model.l_miss - self._template.l_prior)
        N = len(P)
        i = 0
        while i < N:
            code, k = self._codes.take(N - i, self._S)
            for j in range(i, i + k, _RUN_SCANS):  # the beams' ends of a run at a time
                s = slice(j, min(j + _RUN_SCANS, i + k))
                self._insert_run(P[s], *_beam_ends(P[s], R[s], A[s], max_range), code + j - i, d)
            i += k
        used, dropped, maxed, _ = count_readings(R, max_range)
        counts = {"scans": N, "points": int(used), "dropped": int(dropped), "beyond_max_range": int(maxed)}
        for key, value in counts.items():
            self.stats[key] += value
        return counts

    def _check_reach(self, P, R, A, max_range) -> None:
        """Refuse, naming it, a sensor position or beam end beyond the lattice's reach
        (±2⁵² cells; an overflowing end included), before anything changes."""
        limit = CELL_OFFSET * self.resolution
        xmin, ymin, xmax, ymax = beam_extent(P, R, A, max_range)
        if max(-xmin, -ymin, xmax, ymax) < limit:
            return
        far = ~(np.abs(P[:, :2]) < limit).all(axis=1)
        if far.any():
            i = int(np.argmax(far))
            raise InvalidArgumentError(f"poses[{i}] = {P[i].tolist()} lies beyond the map's reach (±{limit:.6g} m)")
        for i0 in range(0, len(P), _RUN_SCANS):
            kinds, ex, ey = _beam_ends(P[i0:i0 + _RUN_SCANS], R[i0:i0 + _RUN_SCANS], A[i0:i0 + _RUN_SCANS], max_range)
            far = (kinds != 0) & ~((np.abs(ex) < limit) & (np.abs(ey) < limit))
            if far.any():
                i, j = np.unravel_index(int(np.argmax(far)), far.shape)
                raise InvalidArgumentError(
                    f"beam {j} of scan {i0 + i} (poses[{i0 + i}] = {P[i0 + i].tolist()}) ends at ({ex[i, j]!r}, "
                    f"{ey[i, j]!r}), beyond the map's reach (±{limit:.6g} m)")

    def _insert_run(self, P, kinds, ex, ey, code: int, d) -> None:
        """Integrate scans with stamp codes ``code, code + 1, …`` in runs small enough for the
        run's table of tiles, its list of beam-tile visits and the memory limit."""
        inv_res = 1.0 / self.resolution
        cap = None if self.memory_limit is None else self.memory_limit // self._tile_bytes
        N = len(P)
        j = 0
        while j < N:
            m = min(N - j, _RUN_SCANS)
            while True:
                s = slice(j, j + m)
                tx0, ty0, tx1, ty1 = K.tile_box(P[s], kinds[s], ex[s], ey[s], inv_res, self._bits)
                shape = (ty1 - ty0 + 1, tx1 - tx0 + 1)
                if m > 1 and shape[0] * shape[1] > _RUN_TABLE:
                    m //= 2
                    continue
                table = np.zeros(shape, np.int64)
                K.bucket(P[s], kinds[s], ex[s], ey[s], inv_res, self._bits, tx0, ty0, table, _NO_ITEMS)
                rows, cols = np.nonzero(table)
                tiles = np.column_stack([cols + tx0, rows + ty0])
                if self.region is not None:
                    inside = np.all((tiles >= self.region[0]) & (tiles <= self.region[1]), axis=1)
                    rows, cols, tiles = rows[inside], cols[inside], tiles[inside]
                counts = table[rows, cols]
                if m > 1 and (counts.sum() > _RUN_ITEMS or (cap is not None and len(tiles) > cap)):
                    m //= 2
                    continue
                break
            if cap is not None and len(tiles) > cap:
                raise InvalidArgumentError(
                    f"memory_limit = {self.memory_limit} bytes holds {cap} tiles, but one scan crosses {len(tiles)} "
                    f"(tiles of {self.tile_size}² cells, {self._tile_bytes} bytes each)")
            if len(tiles):
                self._apply(P[s], kinds[s], ex[s], ey[s], code + j, d, tiles, rows, cols, counts, table, tx0, ty0)
            j += m

    def _apply(self, P, kinds, ex, ey, scan0, d, tiles, rows, cols, counts, table, tx0, ty0) -> None:
        """List each tile's beams in scan order and let the tiles apply them."""
        needed = [(int(tx), int(ty)) for tx, ty in tiles.tolist()]
        self._make_room(needed)
        slots = np.array([self._slot(index, create=True) for index in needed], np.int64)
        self._dirty.update(needed)
        ends = np.cumsum(counts)
        starts = ends - counts
        table[...] = -1
        table[rows, cols] = starts
        items = np.empty(int(ends[-1]), np.int64)
        K.bucket(P, kinds, ex, ey, 1.0 / self.resolution, self._bits, tx0, ty0, table, items)
        work = np.column_stack([slots, tiles, starts, ends])
        args = (self._L, self._S, work, self._bits, items, scan0, P, kinds, ex, ey, 1.0 / self.resolution,
                d[0], d[1], self._template.l_min, self._template.l_max)
        with THREADS.choose(len(items)) as parallel:
            (K.apply_tiles_parallel if parallel and len(work) > 1 else K.apply_tiles)(*args)

    # ------------------------------------------------------------------ tiles in memory

    def _slot(self, index, create: bool) -> int | None:
        """Slot of tile ``index`` in the pool (now the most recently used): in memory, else read
        from the store, else a new unknown tile when ``create``, else None."""
        slot = self._slots.get(index)
        if slot is not None:
            self._slots.move_to_end(index)
            return slot
        stored = self._store is not None and index in self._store.tiles
        if not (stored or create):
            return None
        if self.memory_limit is not None:
            self._make_room([index])
        slot = self._new_slot()
        if stored:
            log_odds = self._zarr.read(index)
            known = ~np.isnan(log_odds)
            self._L[slot] = np.where(known, log_odds, np.float32(self._template.l_prior))
            self._S[slot] = np.where(known, SEEN, UNSEEN)
        else:
            self._L[slot] = self._template.l_prior
            self._S[slot] = UNSEEN
        self._slots[index] = slot
        return slot

    def _new_slot(self) -> int:
        if self._free:
            return self._free.pop()
        used = len(self._L)
        grown = max(8, 2 * used)
        if self.memory_limit is not None:
            grown = min(grown, self.memory_limit // self._tile_bytes)
        self._L = np.concatenate([self._L, np.empty((grown - used,) + self._L.shape[1:], np.float32)])
        self._S = np.concatenate([self._S, np.empty((grown - used,) + self._S.shape[1:], np.uint16)])
        self._free = list(range(grown - 1, used, -1))
        return used

    def _make_room(self, needed) -> None:
        """Under a memory limit, write out and drop least recently used tiles (none of
        ``needed``) until the tiles of ``needed`` not in memory fit."""
        if self.memory_limit is None:
            return
        cap = self.memory_limit // self._tile_bytes
        keep = set(needed)
        excess = len(self._slots) + sum(1 for i in keep if i not in self._slots) - cap
        for index in [i for i in self._slots if i not in keep][:max(excess, 0)]:
            self._write_tile(index)
            self._free.append(self._slots.pop(index))

    def in_memory(self) -> tuple[int, int]:
        """Tiles held in memory now, and the bytes the pool holding them takes."""
        return len(self._slots), self._L.nbytes + self._S.nbytes

    def _known(self, slot: int) -> np.ndarray:
        """Tile in ``slot`` as float32 log-odds, NaN where unknown."""
        return np.where(self._S[slot] != UNSEEN, self._L[slot], np.float32(np.nan))

    def _write_tile(self, index) -> None:
        """Write tile ``index`` (in memory) to the store and its index entry, if it changed."""
        if index not in self._dirty:
            return
        log_odds = self._known(self._slots[index])
        self._zarr.write(index, log_odds)
        self._store.tiles[index] = self._entry(index, log_odds)
        self._dirty.discard(index)
        self._written.add(index)

    def _entry(self, index, log_odds) -> dict:
        lo, hi = self.tile_bounds(index)
        known = ~np.isnan(log_odds)
        occupied = int(np.count_nonzero(occupancy_classes(log_odds, self._template._l_occ) == 1))
        entry = {"min": lo.tolist(), "max": hi.tolist(), "known": int(known.sum()), "occupied": occupied,
                 "free": int(known.sum()) - occupied}
        if self._zarr is not None:
            entry = {"file": str(self._zarr.chunk_file(index).relative_to(self._store.path)), **entry}
        return entry

    def tiles(self) -> dict[tuple[int, int], dict]:
        """The tiles holding known cells, in index order: ``(tx, ty)`` → ``{"min": [x, y],
        "max": [x, y]`` (metres), ``"known"``, ``"occupied"``, ``"free"`` (cells)``}`` (and
        ``"file"``, its chunk in the store, for a map in a store)."""
        out = {} if self._store is None else {i: dict(e) for i, e in self._store.tiles.items()}
        for index, slot in self._slots.items():
            if index in self._dirty or index not in out:
                out[index] = self._entry(index, self._known(slot))
        return {i: out[i] for i in sorted(out) if out[i]["known"]}

    # ------------------------------------------------------------------ queries

    def log_odds_at(self, points) -> np.ndarray:
        """Log-odds (float64, shape (...)) at world points (..., 2); NaN where unknown, in no
        tile, or for a NaN point."""
        p = np.asarray(points, dtype=np.float64)
        good = np.isfinite(p).all(axis=-1) & (np.abs(p) < CELL_OFFSET * self.resolution).all(axis=-1)
        cells = self._cells_of(np.where(good[..., None], p, 0.0))
        out = np.full(good.shape, np.nan)
        tiles = cells >> self._bits
        local = cells & (self.tile_size - 1)
        for index in {tuple(t) for t in tiles[good].tolist()}:
            slot = self._slot(index, create=False)
            if slot is None:
                continue
            sel = good & np.all(tiles == index, axis=-1)
            ix, iy = local[sel][:, 0], local[sel][:, 1]
            out[sel] = np.where(self._S[slot, iy, ix] != UNSEEN, self._L[slot, iy, ix], np.nan)
        return out

    def occupancy_at(self, points) -> np.ndarray:
        """Per world point (..., 2), int8: −1 unknown, 1 occupied (``p ≥ occupied_threshold``),
        else 0 free."""
        return occupancy_classes(self.log_odds_at(points), self._template._l_occ)

    def log_odds(self, box) -> np.ndarray:
        """Log-odds of the cells of ``box = (xmin, ymin, xmax, ymax)`` metres (:meth:`box_cells`),
        float32 (H, W), row 0 at the box's lower edge, NaN where unknown: for a growing
        ``OccupancyGrid2D`` of the same scans and its own box, its ``log_odds()``."""
        return self._cells_log_odds(*self.box_cells(box))

    def _cells_log_odds(self, x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
        """:meth:`log_odds` of the cells [x0, x1) × [y0, y1)."""
        out = np.full((y1 - y0, x1 - x0), np.nan, np.float32)
        T, b = self.tile_size, self._bits
        known = set(self._slots) if self._store is None else set(self._slots) | set(self._store.tiles)
        if x1 > x0 and y1 > y0 and ((x1 - 1 >> b) - (x0 >> b) + 1) * ((y1 - 1 >> b) - (y0 >> b) + 1) < len(known):
            known &= {(tx, ty) for tx in range(x0 >> b, (x1 - 1 >> b) + 1) for ty in range(y0 >> b, (y1 - 1 >> b) + 1)}
        for tx, ty in sorted(known):
            cx0, cy0 = max(tx * T, x0), max(ty * T, y0)
            cx1, cy1 = min(tx * T + T, x1), min(ty * T + T, y1)
            if cx0 >= cx1 or cy0 >= cy1:
                continue
            tile = self._known(self._slot((tx, ty), create=False))
            out[cy0 - y0:cy1 - y0, cx0 - x0:cx1 - x0] = tile[cy0 - ty * T:cy1 - ty * T, cx0 - tx * T:cx1 - tx * T]
        return out

    def occupancy(self, box) -> np.ndarray:
        """nav_msgs/OccupancyGrid values (int8) of :meth:`log_odds`'s cells: −1 unknown, else
        round(100·p)."""
        return occupancy_values(self.log_odds(box))

    def export(self, box, path_yaml, **kwargs):
        """Write the cells of ``box`` (:meth:`box_cells`; None: :attr:`extent`, the cells the scans
        reached, which a growing ``OccupancyGrid2D`` of the same scans spans) as a ROS map_server
        pair whose origin is the box's corner cell, so the pair sits where the box does; keyword
        arguments go to :func:`occmap.io.mapserver.save_map`. Returns the image path."""
        from ..io.mapserver import save_map

        if box is None and self.extent is None:
            raise InvalidArgumentError("the map holds no scan: nothing to export")
        cells = self.extent if box is None else self.box_cells(box)
        return save_map(path_yaml, occupancy_values(self._cells_log_odds(*cells)), self.resolution,
                        (cells[0] * self.resolution, cells[1] * self.resolution), **kwargs)

    # ------------------------------------------------------------------ the store

    KIND = "grid"

    @classmethod
    def _from_store(cls, store: TileStore, region, memory_limit) -> TiledGrid2D:
        p = store.params
        return cls(store.resolution, store.tile_size, p.get("prior", 0.5), tuple(p.get("clamp", (0.1192, 0.971))),
                   p.get("occupied_threshold", 0.5), region=region, memory_limit=memory_limit)

    def _attach(self, store: TileStore, writable: bool, new: bool = False, lock: bool = True) -> None:
        folder = store.path / TILES
        self._zarr = ZarrTiles.create(folder, self.tile_size) if new else ZarrTiles.open(folder, self.tile_size,
                                                                                          writable)
        super()._attach(store, writable, new, lock)

    def _write_changed(self) -> None:
        for index in list(self._slots):
            self._write_tile(index)

    def __repr__(self) -> str:
        return (f"TiledGrid2D({self.resolution} m, tiles of {self.tile_size} cells, {len(self.tiles())} tiles, "
                f"{self.stats['scans']} scans)")


def _beam_ends(P, R, A, max_range):
    """``(kinds, ex, ey)`` (N, n) of scans' readings (:func:`._grid_kernels.beam_ends`)."""
    kinds = np.empty(R.shape, np.int8)
    ex, ey = np.empty(R.shape), np.empty(R.shape)
    K.beam_ends(P, R, A, max_range, kinds, ex, ey)
    return kinds, ex, ey
