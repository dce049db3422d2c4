"""OctoMap ScanGraph (.graph): the fixture from OctoMap, a byte-identical round trip, edges,
changed poses, and truncated / corrupted files (FormatError with the byte offset, no hang)."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from occmap.cloud import PointCloud
from occmap.errors import FormatError, InvalidArgumentError, ShapeError
from occmap.geometry import SE3
from occmap.io import ScanGraph, read_scangraph, write_scangraph


@pytest.fixture(scope="module")
def fixture_bytes(data_dir):
    return (data_dir / "octomap" / "spherical_scan.graph").read_bytes()


def test_fixture_contents(data_dir, fixture_bytes):
    g = read_scangraph(data_dir / "octomap" / "spherical_scan.graph")
    assert len(g) == 1 and repr(g) == "ScanGraph(1 nodes, 10201 points, 0 edges)"
    node = g.nodes[0]
    assert len(node) == 10_201 and node.dropped == 0
    np.testing.assert_array_equal(node.origin, [1.0, 0.0, -0.5])
    np.testing.assert_array_equal(node.pose.matrix[:3, :3], np.eye(3))
    np.testing.assert_array_equal(g.ids, [0])
    assert g.edge_first.shape == (0,) and g.edge_constraints.shape == (0,)
    # points are stored relative to the pose: a sphere about the sensor (radius ~4 m), not
    # about the world origin
    r_sensor = np.linalg.norm(node.points, axis=1)
    r_world = np.linalg.norm(node.world_points(), axis=1)
    assert r_sensor.std() < 1e-3 * r_sensor.mean()
    assert r_world.std() > 0.1
    # the first point as OctoMap wrote it: i32 3 then three f64
    n, x, y, z = struct.unpack_from("<i3d", fixture_bytes, 8)
    assert n == 3 and node.points[0].tolist() == [x, y, z]
    # OctoMap keeps floats: every coordinate is float32-exact
    np.testing.assert_array_equal(node.points.astype(np.float32).astype(np.float64), node.points)
    np.testing.assert_array_equal(g.world_points(), node.world_points())


def test_fixture_round_trip_is_byte_identical(data_dir, fixture_bytes, tmp_path):
    g = read_scangraph(data_dir / "octomap" / "spherical_scan.graph")
    write_scangraph(tmp_path / "out.graph", g)
    assert (tmp_path / "out.graph").read_bytes() == fixture_bytes


def _graph(rng):
    poses = [SE3.from_rotvec(rng.normal(size=3), rng.normal(size=3) * 5) for _ in range(3)]
    nodes = [
        PointCloud(rng.normal(size=(k, 3)).astype(np.float32).astype(np.float64), p)
        for k, p in zip((50, 0, 7), poses)
    ]
    first = np.array([0, 1], np.uint32)
    second = np.array([1, 2], np.uint32)
    cons = SE3(np.stack([(poses[a].inv() @ poses[b]).matrix for a, b in zip(first, second)]))
    return ScanGraph(nodes, np.arange(3), first, second, cons, np.array([1.0, 0.5]))


def test_edges_and_empty_node_round_trip(tmp_path, rng):
    g = _graph(rng)
    write_scangraph(tmp_path / "g.graph", g)
    data = (tmp_path / "g.graph").read_bytes()
    expect = 4 + (3 * 72 + 28 * 57) + 4 + 2 * 80
    assert len(data) == expect
    h = read_scangraph(tmp_path / "g.graph")
    assert len(h) == 3 and [len(n) for n in h.nodes] == [50, 0, 7]
    for a, b in zip(g.nodes, h.nodes):
        np.testing.assert_array_equal(a.points, b.points)
        np.testing.assert_allclose(a.pose.matrix, b.pose.matrix, atol=1e-12)
    np.testing.assert_array_equal(h.edge_first, [0, 1])
    np.testing.assert_array_equal(h.edge_second, [1, 2])
    np.testing.assert_array_equal(h.edge_weights, [1.0, 0.5])
    np.testing.assert_allclose(h.edge_constraints.matrix, g.edge_constraints.matrix, atol=1e-12)
    # the edge layout as OctoMap writes it: u32 first, u32 second, pose6d, f64 weight
    edges_at = len(data) - 2 * 80
    assert struct.unpack_from("<I", data, edges_at - 4) == (2,)
    first, second, n3 = struct.unpack_from("<IIi", data, edges_at)
    assert (first, second, n3) == (0, 1, 3)
    assert struct.unpack_from("<i", data, edges_at + 8 + 28) == (4,)
    assert struct.unpack_from("<d", data, edges_at + 72) == (1.0,)
    # written again: identical bytes (stored quaternions are reused)
    write_scangraph(tmp_path / "h.graph", h)
    assert (tmp_path / "h.graph").read_bytes() == data


def test_changed_pose_is_written_from_its_matrix(tmp_path, rng):
    g = _graph(rng)
    write_scangraph(tmp_path / "g.graph", g)
    h = read_scangraph(tmp_path / "g.graph")
    moved = SE3.from_rotvec([0, 0, 0.5], [1, 2, 3])
    h.nodes[1] = PointCloud(h.nodes[1].points, moved)
    write_scangraph(tmp_path / "m.graph", h)
    k = read_scangraph(tmp_path / "m.graph")
    np.testing.assert_allclose(k.nodes[1].pose.matrix, moved.matrix, atol=1e-12)
    np.testing.assert_allclose(k.nodes[0].pose.matrix, h.nodes[0].pose.matrix, atol=0)


def test_default_ids_and_validation(rng):
    g = ScanGraph([PointCloud(np.zeros((2, 3)))])
    np.testing.assert_array_equal(g.ids, [0])
    assert g.edge_weights.shape == (0,)
    with pytest.raises(InvalidArgumentError, match="distinct"):
        ScanGraph([PointCloud(np.zeros((1, 3)))] * 2, ids=[4, 4])
    with pytest.raises(InvalidArgumentError, match="node id 9"):
        ScanGraph([PointCloud(np.zeros((1, 3)))], edge_first=[0], edge_second=[9])
    with pytest.raises(ShapeError):
        ScanGraph([PointCloud(np.zeros((1, 3)))], edge_first=[0], edge_second=[0], edge_weights=[1.0, 2.0])
    with pytest.raises(InvalidArgumentError, match="PointCloud"):
        ScanGraph([np.zeros((1, 3))])
    with pytest.raises(InvalidArgumentError):
        write_scangraph("/nonexistent/x.graph", "not a graph")


def test_truncation_at_many_offsets(tmp_path, fixture_bytes):
    size = len(fixture_bytes)
    cuts = sorted({0, 1, 3, 4, 5, 7, 8, 35, 36, size // 2, size - 77, size - 73, size - 72, size - 40,
                   size - 9, size - 8, size - 5, size - 4, size - 1} | set(range(0, size, 9973)))  # fmt: skip
    for cut in cuts:
        (tmp_path / "t.graph").write_bytes(fixture_bytes[:cut])
        with pytest.raises(FormatError) as e:
            read_scangraph(tmp_path / "t.graph")
        assert e.value.offset is not None and 0 <= e.value.offset <= cut, (cut, str(e.value))
        assert f"byte {e.value.offset}" in str(e.value)


def test_trailing_bytes_and_corruptions(tmp_path, fixture_bytes):
    size = len(fixture_bytes)

    def bad(data: bytes, match: str, offset: int):
        (tmp_path / "c.graph").write_bytes(data)
        with pytest.raises(FormatError, match=match) as e:
            read_scangraph(tmp_path / "c.graph")
        assert e.value.offset == offset, str(e.value)

    bad(fixture_bytes + b"\x00", "unexpected bytes after the last edge", size)
    # a huge node count in a small file: refused before anything is allocated
    bad(struct.pack("<I", 0xFFFFFFFF) + fixture_bytes[4:], "node count", 0)
    # a huge point count
    bad(fixture_bytes[:4] + struct.pack("<I", 0x7FFFFFFF) + fixture_bytes[8:], "point count", 4)
    # a point whose size prefix is not 3
    at = 8 + 28 * 100
    bad(fixture_bytes[:at] + struct.pack("<i", 2) + fixture_bytes[at + 4 :], "point: size prefix 2", at)
    # the pose's quaternion prefix and value
    pose_at = 8 + 28 * 10_201
    q_at = pose_at + 28
    bad(fixture_bytes[:q_at] + struct.pack("<i", 5) + fixture_bytes[q_at + 4 :], "rotation: size prefix 5", q_at)
    bad(fixture_bytes[: q_at + 4] + struct.pack("<d", 3.0) + fixture_bytes[q_at + 12 :], "unit norm", pose_at)
    # an edge count that does not fit, and an edge naming a missing node
    bad(fixture_bytes[:-4] + struct.pack("<I", 1), "edge count 1", size - 4)
    edge = struct.pack("<II", 0, 7) + struct.pack("<i3d", 3, 0, 0, 0) + struct.pack("<i4d", 4, 1, 0, 0, 0) + struct.pack("<d", 1)
    bad(fixture_bytes[:-4] + struct.pack("<I", 1) + edge, "second node id 7", size + 4)


def test_garbage_files_fail_fast(tmp_path, rng):
    for k in range(40):
        blob = rng.integers(0, 256, int(rng.integers(0, 400)), dtype=np.uint8).tobytes()
        (tmp_path / "r.graph").write_bytes(blob)
        with pytest.raises(FormatError):
            read_scangraph(tmp_path / "r.graph")
    (tmp_path / "e.graph").write_bytes(struct.pack("<II", 0, 0))  # the empty graph is valid
    g = read_scangraph(tmp_path / "e.graph")
    assert len(g) == 0 and g.world_points().shape == (0, 3)
    write_scangraph(tmp_path / "e2.graph", g)
    assert (tmp_path / "e2.graph").read_bytes() == struct.pack("<II", 0, 0)
