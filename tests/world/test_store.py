"""The tile store folder: index round trip, refusals naming the file and field, one writer at a
time, and a build that stopped part way marked incomplete."""

from __future__ import annotations

import json
import multiprocessing
import os
import signal

import pytest

from occmap.errors import FormatError, InvalidArgumentError, MissingFileError
from occmap.world.store import IncompleteStoreError, StoreBusyError, TileStore


def test_index_round_trip(tmp_path):
    store = TileStore.create(tmp_path / "s", "octree", 0.1, 1024, {"prob_hit": 0.7})
    store.tiles[(97, -3, 0)] = {"file": "tiles/97_-3_0.ot", "min": [1.0, 2.0, 3.0], "max": [4.0, 5.0, 6.0]}
    store.scans = 12
    store.save_index()
    back = TileStore.open(tmp_path / "s", kind="octree")
    assert (back.kind, back.resolution, back.tile_size, back.params, back.scans) == ("octree", 0.1, 1024,
                                                                                     {"prob_hit": 0.7}, 12)
    assert back.tiles == store.tiles and back.state == "complete"
    assert back.tile_bounds((97, -3, 0)) == ([97 * 102.4, -3 * 102.4, 0.0], [98 * 102.4, -2 * 102.4, 102.4])
    assert back.tile_file((97, -3, 0), ".ot").name == "97_-3_0.ot"


def test_refusals_name_the_file_and_field(tmp_path):
    with pytest.raises(MissingFileError):
        TileStore.open(tmp_path / "none")
    (tmp_path / "plain").mkdir()
    with pytest.raises(FormatError, match="no index.json"):
        TileStore.open(tmp_path / "plain")
    with pytest.raises(InvalidArgumentError, match="power of two"):
        TileStore.create(tmp_path / "x", "grid", 0.05, 100)
    (tmp_path / "plain" / "f").touch()
    with pytest.raises(InvalidArgumentError, match="not an empty folder"):
        TileStore.create(tmp_path / "plain", "grid", 0.05, 64)
    TileStore.create(tmp_path / "s", "grid", 0.05, 64)
    with pytest.raises(FormatError, match="kind is 'grid', expected 'octree'"):
        TileStore.open(tmp_path / "s", kind="octree")
    index = tmp_path / "s" / "index.json"
    good = json.loads(index.read_text())
    for field, value, words in [("tile_size", 48, "'tile_size' = 48 must be a power of two"),
                                ("resolution", -1, "'resolution' = -1"), ("state", "odd", "'state'"),
                                ("version", 99, "version 99"),
                                ("tiles", [{"index": [1, 2, 3]}], "tiles[0].index = [1, 2, 3] must be 2 integers")]:
        index.write_text(json.dumps({**good, field: value}))
        with pytest.raises(FormatError, match=words.replace("[", r"\[").replace("]", r"\]")) as e:
            TileStore.open(tmp_path / "s")
        assert "index.json" in str(e.value)
    index.write_text("{not json")
    with pytest.raises(FormatError, match="not valid JSON"):
        TileStore.open(tmp_path / "s")


def _hold(path, ready, stop):
    with TileStore.open(path).writer():
        ready.set()
        stop.wait(30)


def test_one_writer_at_a_time_and_a_killed_build_is_incomplete(tmp_path):
    TileStore.create(tmp_path / "s", "octree", 0.1, 64)
    ctx = multiprocessing.get_context("spawn")
    ready, stop = ctx.Event(), ctx.Event()
    other = ctx.Process(target=_hold, args=(tmp_path / "s", ready, stop))
    other.start()
    try:
        assert ready.wait(60)
        with pytest.raises(StoreBusyError, match=f"pid {other.pid}"):
            with TileStore.open(tmp_path / "s").writer():
                pass
        assert TileStore.open(tmp_path / "s").state == "building"  # a live build: readable
    finally:
        os.kill(other.pid, signal.SIGKILL)
        other.join()
    with pytest.raises(IncompleteStoreError, match="incomplete"):
        TileStore.open(tmp_path / "s")
    store = TileStore.open(tmp_path / "s", incomplete_ok=True)
    with store.writer():  # the lock died with its holder
        pass
    assert TileStore.open(tmp_path / "s").state == "complete"
