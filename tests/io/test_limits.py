"""Memory bounded by the input (issue 15): a reader refuses a declared size or a decompressed
stream beyond :mod:`occmap.io._limits`' budget, and never reads what is not a regular file.
The cases that once took gigabytes or blocked run in a child process with a memory and a time
limit, so a regression fails instead of taking the machine down."""

from __future__ import annotations

import gzip
import os
import struct
import zlib

import numpy as np
import pytest
from isolated import outcome

from occmap.errors import FormatError, InvalidArgumentError
from occmap.io import read_limits, read_xyz
from occmap.io._compression import open_binary, read_bytes
from occmap.io._limits import ReadLimits, current
from occmap.io.carmen import read_carmen
from occmap.io.mapserver import load_map

MAP_YAML = "resolution: 0.05\norigin: [0, 0, 0]\noccupied_thresh: 0.65\nfree_thresh: 0.196\n"


def _gzip_of_repeats(path, line: bytes, times: int):
    """A gzip file of ``line`` repeated, written a block at a time (never held whole)."""
    per = max(1, (1 << 20) // len(line))
    full, rest = divmod(times, per)
    with gzip.open(path, "wb", compresslevel=6) as f:
        for _ in range(full):
            f.write(line * per)
        f.write(line * rest)
    return path


def _png_of_zeros(path, width: int, height: int):
    """A gray PNG of ``width`` × ``height`` zero pixels, compressed row by row."""
    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    z = zlib.compressobj(9)
    row = bytes(width + 1)  # filter byte 0 + the pixels
    idat = b"".join(z.compress(row) for _ in range(height)) + z.flush()
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0))
                     + chunk(b"IDAT", idat) + chunk(b"IEND", b""))
    return path


def test_budget_rule():
    limits = ReadLimits()
    assert limits.budget(0) == 16 << 20 and limits.budget(1_000_000) == 100_000_000
    with read_limits(expansion=5, floor=10) as inside:
        assert current() is inside and inside.budget(100) == 500 and inside.budget(1) == 10
    assert current() == ReadLimits()
    with pytest.raises(InvalidArgumentError):
        with read_limits(expansion=0):
            pass


def test_xyz_gzip_bomb_refused_and_readable_when_the_limit_is_raised(tmp_path):
    # 60 MB of text in a 60 kB file: beyond 100 × the file and the 16 MiB floor
    path = _gzip_of_repeats(tmp_path / "bomb.xyz.gz", b"1 2 3\n", 10_000_000)
    assert path.stat().st_size < 200_000
    assert outcome("xyz", path, memory=1 << 30) == "error"
    with pytest.raises(FormatError, match=r"bomb\.xyz\.gz: the decompressed data needs .* raise the limit"):
        read_bytes(path)
    with read_limits(expansion=2000):
        assert len(read_bytes(path)) == 60_000_000


def test_streamed_carmen_gzip_bomb_refused(tmp_path):
    path = _gzip_of_repeats(tmp_path / "bomb.log.gz", b"# a comment line that repeats\n", 1_000_000)
    with pytest.raises(FormatError, match=r"bomb\.log\.gz: the decompressed stream needs"):
        read_carmen(path)
    with read_limits(floor=1 << 30):
        assert read_carmen(path).skipped_other == 1_000_000
    with open_binary(path) as f:  # the bound holds for any reader of the stream
        with pytest.raises(FormatError):
            f.read()


def test_png_map_of_huge_dimensions_refused(tmp_path):
    # 8000 × 8000 pixels in a 65 kB PNG: once 64 M pixels × float64 channels, gigabytes
    png = _png_of_zeros(tmp_path / "huge.png", 8000, 8000)
    assert png.stat().st_size < 100_000
    (tmp_path / "huge.yaml").write_text("image: huge.png\n" + MAP_YAML)
    assert outcome("map", tmp_path / "huge.yaml", memory=1 << 30) == "error"
    with pytest.raises(FormatError, match=r"huge\.png: a 8000 × 8000 image needs 64000000 pixels"):
        load_map(tmp_path / "huge.yaml")


def test_small_png_within_the_floor_loads(tmp_path):
    _png_of_zeros(tmp_path / "ok.png", 300, 200)
    (tmp_path / "ok.yaml").write_text("image: ok.png\n" + MAP_YAML)
    assert load_map(tmp_path / "ok.yaml").occupancy.shape == (200, 300)


def test_dev_zero_is_not_read(tmp_path):
    assert os.path.exists("/dev/zero")
    assert outcome("xyz", "/dev/zero", memory=1 << 30, seconds=5) == "error"
    with pytest.raises(FormatError, match="not a regular file"):
        read_xyz("/dev/zero")


def test_fifo_is_refused_instead_of_blocking(tmp_path):
    fifo = tmp_path / "pipe.pcd"
    os.mkfifo(fifo)
    assert outcome("pcd", fifo, seconds=5) == "error"
    for read in (read_bytes, open_binary):
        with pytest.raises(FormatError, match="a FIFO"):
            read(fifo)


def test_folder_is_refused(tmp_path):
    with pytest.raises(FormatError, match="a folder"):
        read_xyz(tmp_path)


def test_graph_with_a_huge_node_count_is_refused_at_once(tmp_path):
    path = tmp_path / "g.graph"
    path.write_bytes(np.uint32(0xFFFFFFFF).tobytes() + bytes(100))
    assert outcome("graph", path, memory=256 << 20, seconds=5) == "error"
