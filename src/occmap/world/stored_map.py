"""What the tiled maps share, written once: their life in a tile store (:mod:`occmap.world.store`),
:class:`StoredMap`, and the region of tiles a map owns, :func:`region_box`."""

from __future__ import annotations

import numpy as np

from .._threads import OneCallAtATime
from ..errors import InvalidArgumentError
from .store import TileStore


def region_box(region, dims: int) -> np.ndarray:
    """The checked region ``((t0, …), (t1, …))`` of ``dims`` tile indices each (an inclusive box
    of tiles, ``t0 ≤ t1`` per axis) as int64 (2, dims)."""
    r = np.asarray(region)
    if r.shape != (2, dims) or not np.issubdtype(r.dtype, np.integer) or not np.all(r[0] <= r[1]):
        names = ("tx", "ty", "tz")[:dims]
        lo, hi = ", ".join(f"{n}0" for n in names), ", ".join(f"{n}1" for n in names)
        raise InvalidArgumentError(f"region must be (({lo}), ({hi})) integers with {names[0]}0 ≤ {names[0]}1 …, "
                                   f"got {region!r}")
    return r.astype(np.int64)


class StoredMap(OneCallAtATime):
    """Base of the tiled maps: a map in a store folder (one call at a time, :class:`OneCallAtATime`).

    :meth:`create` a new store, :meth:`open` one (to read, or ``writable`` to add scans: mapping
    resumes with the stored log-odds), :meth:`build_part` for one worker of a parallel build (the
    driver holds the store), :meth:`write_tiles`, :meth:`flush`, :meth:`close` (or a ``with``
    block, which leaves the store marked incomplete when it ends by an exception).

    A subclass names its store ``KIND``; its constructor takes ``(resolution, tile_size, …)`` and
    the keywords ``region`` and ``memory_limit``, sets ``stats`` and calls :meth:`_no_store`; it
    defines :meth:`_from_store` (a map with a store's parameters), ``_write_changed()`` (write its
    changed tiles in memory, each through the store's index, adding them to ``_written``) and may
    extend :meth:`_attach` (to open its tiles' files).
    """

    KIND = ""

    def _no_store(self) -> None:
        self._store: TileStore | None = None
        self._writable = True  # False for a stored map opened to read
        self._writer = None  # the store's writer lock while this map holds it
        self._dirty: set = set()  # tiles changed since last written
        self._written: set = set()  # tiles this map has written
        self.extent = None  # the box of cells the scans reached, where the map keeps one (TileStore.extent)

    @classmethod
    def _from_store(cls, store: TileStore, region, memory_limit):
        """A map with the store's resolution, tile size and parameters (no store attached)."""
        raise NotImplementedError

    @classmethod
    def create(cls, path, *args, **kwargs):
        """A new map (the constructor's arguments) in a new store folder ``path``, open for
        writing."""
        tiled = cls(*args, **kwargs)
        store = TileStore.create(path, cls.KIND, tiled.resolution, tiled.tile_size, tiled.params)
        tiled._attach(store, writable=True, new=True)
        return tiled

    @classmethod
    def open(cls, path, writable: bool = False, memory_limit: int | None = None, region=None):
        """The map stored at ``path``; tiles are read as they are needed. ``writable``: hold the
        store (one writer at a time) to add scans; :meth:`close` writes the tiles and the index."""
        store = TileStore.open(path, kind=cls.KIND)
        tiled = cls._from_store(store, region, memory_limit)
        tiled.stats["scans"] = store.scans
        tiled.extent = store.extent
        tiled._attach(store, writable)
        return tiled

    @classmethod
    def build_part(cls, path, region, memory_limit: int | None = None):
        """The map of one worker of a parallel build (:mod:`occmap.world.build`): the store at
        ``path``, which the build's driver holds, open to write the tiles of ``region`` only;
        :meth:`write_tiles` hands the driver what it wrote."""
        store = TileStore.open(path, kind=cls.KIND, incomplete_ok=True)
        part = cls._from_store(store, region, memory_limit)
        part._attach(store, writable=True, lock=False)
        return part

    def _attach(self, store: TileStore, writable: bool, new: bool = False, lock: bool = True) -> None:
        """Keep the map in ``store`` (``new``: just created); ``writable`` with ``lock``: hold its
        writer."""
        self._store = store
        self._writable = writable
        if writable and lock:
            self._writer = store.writer()
            self._writer.__enter__()

    def _check_writable(self) -> None:
        """Refuse to change a map opened to read, or one with a memory limit and no store."""
        if not self._writable:
            raise InvalidArgumentError(f"{self._store.path}: the map was opened to read; open it with writable=True")
        if self.memory_limit is not None and self._store is None:
            raise InvalidArgumentError(f"memory_limit needs a store to write tiles to: {type(self).__name__}"
                                       ".create(path, …)")

    def write_tiles(self) -> dict:
        """Write the tiles changed since they were last written to the store; returns the index
        entries (tile index → entry) of every tile this map has written."""
        self._write_changed()
        return {index: self._store.tiles[index] for index in self._written}

    def flush(self) -> None:
        """Write the changed tiles and the index to the store (the map stays open); nothing for a
        map that does not hold its store's writer."""
        if self._writer is None:
            return
        self.write_tiles()
        self._store.scans = self.stats["scans"]
        self._store.extent = self.extent
        self._store.save_index()

    def close(self) -> None:
        """Write what changed and let the store go (marked complete)."""
        if self._writer is not None:
            self.flush()
            writer, self._writer = self._writer, None
            writer.__exit__(None, None, None)

    def __enter__(self):
        return self

    def __exit__(self, kind, value, tb):
        if kind is None:
            self.close()
        elif self._writer is not None:  # an error: the store stays marked incomplete
            writer, self._writer = self._writer, None
            writer.__exit__(kind, value, tb)


def union_extent(a, b):
    """The box holding two boxes ``[x0, y0, …, x1, y1, …]`` (half-open; None: none)."""
    if a is None or b is None:
        return b if a is None else a
    d = len(a) // 2
    return [min(a[i], b[i]) for i in range(d)] + [max(a[i], b[i]) for i in range(d, 2 * d)]
