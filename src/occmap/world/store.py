"""A tile store: the folder a world-scale map lives in, readable without occmap.

Layout::

    DIR/index.json     what the folder holds (below), rewritten whole after each change
    DIR/LOCK           held (``flock``) by the one process building the store
    DIR/tiles/...      the tiles, in the format of the store's kind (an octree's tiles are OctoMap
                       ``.ot`` files, a grid's a zarr array)

``index.json`` (modelled on Autoware's point-cloud map metadata: one entry per tile with its
bounds, so a reader loads only the tiles it needs)::

    {"format": "occmap-tiles", "version": 1, "kind": "octree" | "grid",
     "resolution": 0.1,              # metres per voxel / cell
     "tile_size": 1024,              # voxels / cells per tile side (a power of two)
     "params": {...},                # the map's sensor model and clamping (prob_hit, ...)
     "state": "complete" | "building",
     "scans": 1234,                  # scans the tiles hold, in the order they were inserted
     "extent": [x0, y0, x1, y1],     # (grids) the cells the scans reached: [x0, x1) × [y0, y1)
     "tiles": [{"index": [tx, ty, tz], "file": "tiles/...", "min": [...], "max": [...], ...}, ...]}

Tile ``(tx, ty[, tz])`` covers ``[t · tile_size · resolution, (t + 1) · tile_size · resolution)``
metres per axis. ``state`` is ``"building"`` from the moment a writer opens the store until it
finishes: a store found in that state with no live writer was stopped part way (killed, crashed)
and is *incomplete*: :meth:`TileStore.open` refuses it unless asked to read it anyway.

One writer at a time: :meth:`TileStore.writer` holds an exclusive ``flock`` on ``LOCK`` (the
kernel drops it when the process ends, however it ends); a second writer is refused with
:class:`StoreBusyError`. Readers take no lock; they see the index of the last finished write.
"""

from __future__ import annotations

import fcntl
import json
import math
import os
import socket
from contextlib import contextmanager
from pathlib import Path

from .. import checks
from .._files import write_atomic
from ..errors import FormatError, InvalidArgumentError, MissingFileError, OccmapError

INDEX = "index.json"
LOCK = "LOCK"
TILES = "tiles"
FORMAT = "occmap-tiles"
VERSION = 1
KINDS = {"octree": 3, "grid": 2}  # kind → dimensions of a tile index


class StoreBusyError(OccmapError):
    """Another process is writing the store."""


class IncompleteStoreError(FormatError):
    """The store's last build stopped part way."""


class TileStore:
    """A tile store folder (see the module docstring). Build one with :meth:`create`, open one with
    :meth:`open`; the maps of :mod:`occmap.world` read and write their tiles through it.

    Attributes
    ----------
    path : Path
    kind : str ("octree" or "grid")
    resolution : float (metres)
    tile_size : int (voxels or cells per tile side)
    params : dict (the map's parameters, JSON values)
    state : str ("complete" or "building")
    scans : int
    extent : list[int] or None
        The box of cells the scans reached, ``[x0, y0, x1, y1]`` (half-open), where the map keeps one
        (a grid's: what a growing ``OccupancyGrid2D`` of the same scans spans).
    tiles : dict[tuple[int, ...], dict]
        Tile index → its entry (``file``, ``min``, ``max`` in metres, and counts the map adds).
    """

    def __init__(self, path: Path, index: dict):
        self.path = path
        self.kind = index["kind"]
        self.resolution = index["resolution"]
        self.tile_size = index["tile_size"]
        self.params = index["params"]
        self.state = index["state"]
        self.scans = index["scans"]
        self.extent = index.get("extent")
        self.tiles = {tuple(t["index"]): {k: v for k, v in t.items() if k != "index"} for t in index["tiles"]}
        self._lock_fd = None

    # ------------------------------------------------------------------ opening

    @classmethod
    def create(cls, path, kind: str, resolution: float, tile_size: int, params: dict | None = None) -> TileStore:
        """A new, empty store at ``path`` (a folder that does not exist or is empty)."""
        if kind not in KINDS:
            raise InvalidArgumentError(f"kind must be one of {sorted(KINDS)}, got {kind!r}")
        resolution = checks.positive("resolution", resolution, "metres")
        tile_size = checks.count("tile_size", tile_size, minimum=1)
        if tile_size & (tile_size - 1):
            raise InvalidArgumentError(f"tile_size must be a power of two, got {tile_size}")
        path = Path(path)
        if path.exists() and (not path.is_dir() or any(path.iterdir())):
            raise InvalidArgumentError(f"{str(path)!r} exists and is not an empty folder: a new store needs one")
        (path / TILES).mkdir(parents=True, exist_ok=True)
        store = cls(path, {"kind": kind, "resolution": resolution, "tile_size": tile_size,
                           "params": dict(params or {}), "state": "complete", "scans": 0, "tiles": []})
        store.save_index()
        return store

    @classmethod
    def open(cls, path, kind: str | None = None, incomplete_ok: bool = False) -> TileStore:
        """The store at ``path``; :class:`FormatError` naming the file and field when the folder
        is not one (or not of ``kind``), :class:`IncompleteStoreError` when its last build did not
        finish (unless ``incomplete_ok``)."""
        path = Path(path)
        index_path = path / INDEX
        if not path.is_dir():
            raise MissingFileError(path, "no such tile store (folder)")
        if not index_path.is_file():
            raise FormatError(path, f"not a tile store: it has no {INDEX}")
        store = cls(path, _parse_index(index_path))
        if kind is not None and store.kind != kind:
            raise FormatError(index_path, f"kind is {store.kind!r}, expected {kind!r}")
        if store.state != "complete" and not incomplete_ok and not store._writer_alive():
            raise IncompleteStoreError(index_path, "the store is incomplete: its last build stopped before it "
                                       "finished (state \"building\", no writer running); build it again")
        return store

    # ------------------------------------------------------------------ the index

    @property
    def tile_metres(self) -> float:
        """Side of a tile in metres."""
        return self.tile_size * self.resolution

    def tile_bounds(self, index) -> tuple[list[float], list[float]]:
        """``(min, max)`` corners in metres of tile ``index``."""
        side = self.tile_metres
        return [t * side for t in index], [(t + 1) * side for t in index]

    def tile_file(self, index, suffix: str) -> Path:
        """Path of tile ``index``'s file: ``tiles/<tx>_<ty>[_<tz>]<suffix>``."""
        return self.path / TILES / ("_".join(str(int(t)) for t in index) + suffix)

    def save_index(self) -> None:
        """Write ``index.json`` (all or nothing)."""
        tiles = [{"index": list(k), **v} for k, v in sorted(self.tiles.items())]
        index = {"format": FORMAT, "version": VERSION, "kind": self.kind, "resolution": self.resolution,
                 "tile_size": self.tile_size, "params": self.params, "state": self.state, "scans": self.scans,
                 "extent": self.extent, "tiles": tiles}
        write_atomic(self.path / INDEX, (json.dumps(index, indent=1) + "\n").encode())

    # ------------------------------------------------------------------ one writer

    @contextmanager
    def writer(self):
        """Hold the store for writing: refuse another writer, mark the store ``"building"`` until
        the block ends normally (then ``"complete"``, index written); an exception or a kill leaves
        it ``"building"``, i.e. incomplete."""
        fd = os.open(self.path / LOCK, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 200, 0).decode(errors="replace").strip() or "another process"
            os.close(fd)
            raise StoreBusyError(f"{self.path}: the store is being written by {holder}; one writer at a time") from None
        try:
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"pid {os.getpid()} on {socket.gethostname()}\n".encode(), 0)
            self._lock_fd = fd
            self.state = "building"
            self.save_index()
            yield self
            self.state = "complete"
            self.save_index()
        finally:
            self._lock_fd = None
            os.close(fd)  # releases the flock

    def _writer_alive(self) -> bool:
        """Whether some process holds the store's lock now."""
        try:
            fd = os.open(self.path / LOCK, os.O_RDONLY)
        except FileNotFoundError:
            return False
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return True
        finally:
            os.close(fd)
        return False


def _parse_index(path: Path) -> dict:
    """The checked contents of an ``index.json``."""
    try:
        index = json.loads(path.read_bytes())
    except (ValueError, UnicodeDecodeError) as e:
        raise FormatError(path, f"not valid JSON ({e})") from None
    if not isinstance(index, dict) or index.get("format") != FORMAT:
        raise FormatError(path, f"not a tile store index: \"format\" is not {FORMAT!r}")
    if index.get("version") != VERSION:
        raise FormatError(path, f"version {index.get('version')!r} is not supported (this occmap reads {VERSION})")

    def field(name, ok, what):
        value = index.get(name)
        if not ok(value):
            raise FormatError(path, f"field {name!r} = {value!r} must be {what}")
        return value

    kind = field("kind", lambda v: v in KINDS, f"one of {sorted(KINDS)}")
    field("resolution", lambda v: isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
          and v > 0, "a positive number")
    field("tile_size", lambda v: isinstance(v, int) and not isinstance(v, bool) and v > 0 and not v & (v - 1),
          "a power of two")
    field("params", lambda v: isinstance(v, dict), "an object")
    field("state", lambda v: v in ("complete", "building"), "\"complete\" or \"building\"")
    field("scans", lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= 0, "a count")
    field("extent", lambda v: v is None or (isinstance(v, list) and len(v) == 2 * KINDS[kind] and all(
        isinstance(i, int) and not isinstance(i, bool) for i in v)), f"null or {2 * KINDS[kind]} integers")
    tiles = field("tiles", lambda v: isinstance(v, list), "a list")
    for k, t in enumerate(tiles):
        idx = t.get("index") if isinstance(t, dict) else None
        if not (isinstance(idx, list) and len(idx) == KINDS[kind]
                and all(isinstance(i, int) and not isinstance(i, bool) for i in idx)):
            raise FormatError(path, f"tiles[{k}].index = {idx!r} must be {KINDS[kind]} integers")
    return index
