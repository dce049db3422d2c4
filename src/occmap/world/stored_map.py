"""What the tiled maps share, written once: their life in a tile store (:mod:`occmap.world.store`),
:class:`StoredMap`, and the region of tiles a map owns, :func:`region_box`."""

from __future__ import annotations

import numpy as np

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


class StoredMap:
    """Base of the tiled maps: holding the store's writer, refusing changes to a map opened to
    read, writing out (:meth:`flush`), finishing (:meth:`close`, or a ``with`` block, which leaves
    the store marked incomplete when it ends by an exception).

    A subclass sets ``_store`` and ``_writer`` to None, ``memory_limit`` and ``stats`` (with
    ``"scans"``) in its constructor, calls :meth:`_attach` when it is in a store, and writes its
    changed tiles and their index entries in ``_write_tiles()``.
    """

    def _attach(self, store: TileStore, writable: bool) -> None:
        self._store = store
        if writable:
            self._writer = store.writer()
            self._writer.__enter__()

    def _check_writable(self) -> None:
        """Refuse to change a map opened to read, or one with a memory limit and no store."""
        if self._store is not None and self._writer is None:
            raise InvalidArgumentError(f"{self._store.path}: the map was opened to read; open it with writable=True")
        if self.memory_limit is not None and self._store is None:
            raise InvalidArgumentError(f"memory_limit needs a store to write tiles to: {type(self).__name__}"
                                       ".create(path, …)")

    def flush(self) -> None:
        """Write the changed tiles and the index to the store (the map stays open)."""
        if self._writer is None:
            return
        self._write_tiles()
        self._store.scans = self.stats["scans"]
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
