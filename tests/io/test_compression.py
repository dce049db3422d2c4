"""Compression is recognised by content: real gzip and bzip2 files from the shared data, generated
gzip/bzip2/xz under misleading names, and what a corrupt file gives with and without a compressed
extension."""

from __future__ import annotations

import bz2
import gzip
import lzma

import pytest

from occmap.errors import FormatError
from occmap.io._compression import CORRUPT, compression, open_binary, read_bytes

PACKERS = {"gzip": gzip.compress, "bzip2": bz2.compress, "xz": lzma.compress}


@pytest.mark.parametrize("name, kind, opener", [
    ("carmen/intel-corrected.log.gz", "gzip", gzip.open),
    ("carmen/intel-raw.clf.bz2", "bzip2", bz2.open),
    ("octomap/scan.dat.bz2", "bzip2", bz2.open),
])
def test_real_compressed_files(data_dir, name, kind, opener):
    path = data_dir / name
    with open(path, "rb") as f:
        assert compression(f.read(6)) == kind
    with opener(path, "rb") as f:
        expected = f.read()
    assert read_bytes(path) == expected
    with open_binary(path) as f:
        assert f.read() == expected


def test_real_plain_file(data_dir):
    path = data_dir / "octomap" / "spherical_scan.graph"
    raw = path.read_bytes()
    assert compression(raw[:6]) is None and read_bytes(path) == raw


@pytest.mark.parametrize("kind", sorted(PACKERS))
@pytest.mark.parametrize("name", ["data.txt", "data.gz", "data.xz", "data"])
def test_generated_files_detected_by_content_whatever_the_name(tmp_path, kind, name):
    body = b"1 2 3\n4 5 6\n" * 1000
    path = tmp_path / name
    path.write_bytes(PACKERS[kind](body))
    assert compression(path.read_bytes()[:6]) == kind
    assert read_bytes(path) == body
    with open_binary(path) as f:
        assert f.read() == body


def test_plain_file_with_a_compressed_name_reads_as_it_is(tmp_path):
    (tmp_path / "plain.bz2").write_bytes(b"1 2 3\n")
    assert read_bytes(tmp_path / "plain.bz2") == b"1 2 3\n"
    with open_binary(tmp_path / "plain.bz2") as f:
        assert f.read() == b"1 2 3\n"


@pytest.mark.parametrize("kind", sorted(PACKERS))
def test_truncated_file_is_an_error_only_under_a_compressed_name(tmp_path, kind):
    blob = PACKERS[kind](bytes(range(256)) * 400)[:300]
    named = tmp_path / "cut.dat.gz"
    named.write_bytes(blob)
    with pytest.raises(FormatError, match="cut.dat.gz: compressed data is truncated or corrupt"):
        read_bytes(named)
    with pytest.raises(CORRUPT):
        with open_binary(named) as f:
            f.read()
    unnamed = tmp_path / "scan.bin"  # a binary file may start with a signature by chance
    unnamed.write_bytes(blob)
    assert read_bytes(unnamed) == blob
