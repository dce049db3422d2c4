"""The tiles of a 2D tile store (:mod:`occmap.world.store`, kind ``"grid"``): one zarr (v3) array.

Why zarr: a chunked array store with real readers (zarr-python, zarr.js, TensorStore, Dask's
``from_zarr``), compressed chunks, and chunks that were never written cost nothing (a reader sees
the fill value). A 2D tile is exactly one chunk.

The array is ``DIR/tiles`` (its ``zarr.json`` there, chunk files under ``tiles/c/<row>/<col>``):
float32 log-odds of the world lattice's cells (:mod:`occmap.raster`, origin (0, 0)), NaN where
unknown (the fill value), rows along y. Its shape is fixed, ``2⁵³ × 2⁵³`` cells, with the lattice
cell ``(ix, iy)`` at ``[iy + 2⁵², ix + 2⁵²]`` (attribute ``"cell_offset"``): a map may grow any
way without moving a chunk (a zarr array cannot grow below index 0), the integers stay exact in
any JSON reader, and the range, ±4.5·10¹² m at 1 mm, is no limit in practice. Read a box of it
(the store's index lists the tiles and their bounds), not the whole array. Chunks are zstd
compressed with a CRC-32C checksum, so a damaged chunk is detected when read; zarr replaces a
chunk file whole (a temporary file renamed over it).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import FormatError

#: Lattice cell 0 is at this index of each axis of the array.
CELL_OFFSET = 2**52
_SHAPE = (2 * CELL_OFFSET, 2 * CELL_OFFSET)


class ZarrTiles:
    """The zarr array of a grid store's tiles of ``tile_size`` cells (use :meth:`create` or
    :meth:`open`)."""

    def __init__(self, array, path: Path, tile_size: int):
        self._array = array
        self.path = path
        self.tile_size = tile_size

    @classmethod
    def create(cls, path, tile_size: int) -> ZarrTiles:
        """A new, empty array at folder ``path`` (which may exist, empty)."""
        import zarr
        from zarr.codecs import Crc32cCodec, ZstdCodec

        path = Path(path)
        array = zarr.create_array(str(path), shape=_SHAPE, chunks=(tile_size, tile_size), dtype="float32",
                                  fill_value=np.nan, compressors=[ZstdCodec(level=3), Crc32cCodec()],
                                  zarr_format=3, attributes={"cell_offset": [CELL_OFFSET, CELL_OFFSET]},
                                  overwrite=True)
        return cls(array, path, tile_size)

    @classmethod
    def open(cls, path, tile_size: int, writable: bool) -> ZarrTiles:
        """The array at folder ``path``; :class:`FormatError` naming it when it is not the tiles
        of a grid store of ``tile_size``."""
        import zarr

        path = Path(path)
        try:
            array = zarr.open_array(str(path), mode="r+" if writable else "r", zarr_format=3)
        except Exception as e:  # zarr raises several kinds: none is ours to let through
            raise FormatError(path, f"not a zarr v3 array of grid tiles ({type(e).__name__}: {e})") from None
        expect = {"shape": _SHAPE, "chunks": (tile_size, tile_size), "dtype": np.dtype(np.float32),
                  "cell_offset": [CELL_OFFSET, CELL_OFFSET]}
        found = {"shape": tuple(array.shape), "chunks": tuple(array.chunks), "dtype": array.dtype,
                 "cell_offset": array.attrs.get("cell_offset")}
        for field, value in expect.items():
            if found[field] != value:
                raise FormatError(path / "zarr.json", f"field {field!r} = {found[field]!r}, expected {value!r}")
        return cls(array, path, tile_size)

    def _rows_cols(self, index) -> tuple[slice, slice]:
        T = self.tile_size
        tx, ty = index
        r, c = ty * T + CELL_OFFSET, tx * T + CELL_OFFSET
        return slice(r, r + T), slice(c, c + T)

    def chunk_file(self, index) -> Path:
        """The file holding tile ``index = (tx, ty)``."""
        rows, cols = self._rows_cols(index)
        return self.path / "c" / str(rows.start // self.tile_size) / str(cols.start // self.tile_size)

    def read(self, index) -> np.ndarray:
        """Tile ``(tx, ty)``: float32 (T, T) log-odds, row 0 at its lower edge, NaN unknown.
        :class:`FormatError` naming the tile and its file when the file is missing or damaged."""
        path = self.chunk_file(index)
        if not path.is_file():
            raise FormatError(path, f"tile {list(index)} is listed in the store's index but its chunk file is "
                              "missing")
        try:
            return self._array[self._rows_cols(index)]
        except Exception as e:  # a codec's error on damaged bytes (checksum, zstd frame, size)
            raise FormatError(path, f"tile {list(index)} is damaged ({type(e).__name__}: {e})") from None

    def write(self, index, log_odds: np.ndarray) -> None:
        """Replace tile ``(tx, ty)`` by ``log_odds`` (float32 (T, T), NaN unknown)."""
        self._array[self._rows_cols(index)] = log_odds
