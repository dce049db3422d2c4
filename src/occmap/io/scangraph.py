"""OctoMap ScanGraph files (``.graph``, binary): a list of scans with their poses, and edges.

Layout (all little-endian, no padding; checked against OctoMap 1.10's ``ScanGraph.cpp``,
``Pointcloud.cpp``, ``Pose6D.cpp``, ``Vector3.cpp`` and ``Quaternion.cpp``)::

    u32 node_count
    node_count × node:
        u32 point_count
        point_count × point:   i32 3, f64 x, f64 y, f64 z          (Vector3::writeBinary)
        pose:                  i32 3, f64 x, f64 y, f64 z           (translation)
                               i32 4, f64 w, f64 x, f64 y, f64 z    (rotation quaternion)
        u32 id
    u32 edge_count
    edge_count × edge:
        u32 first_id, u32 second_id
        constraint pose:       i32 3 + 3 × f64, i32 4 + 4 × f64     (as above)
        f64 weight

The ``i32 3`` / ``i32 4`` size prefixes are written by OctoMap and ignored by its reader; this
reader requires them (a wrong prefix is the surest sign of a corrupt or misaligned file).
Points are stored relative to the node's pose, i.e. in the **sensor** frame: OctoMap builds a
graph with ``addNode(scan, pose)`` from sensor-frame scans and places them in the world only
with ``transformScans()`` / ``insertPointCloud(scan, origin, pose)``. The pose is
``T_world_sensor``. OctoMap keeps coordinates as float and widens them to f64 on writing, so
values read here are float32-exact; they are kept as read (float64), NaN included.

Every count is checked against the bytes that remain before anything is allocated, so a corrupt
or truncated file raises :class:`~occmap.errors.FormatError` naming the byte offset, quickly and
with memory bounded by the file size. Trailing bytes after the last edge are an error too.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._files import write_atomic
from ..cloud import PointCloud
from ..errors import FormatError, InvalidArgumentError, ShapeError
from ..geometry.quaternion import quat_to_matrix
from ..geometry.se3 import SE3
from ._compression import read_bytes

__all__ = ["ScanGraph", "read_scangraph", "write_scangraph"]

_POINT = np.dtype([("n", "<i4"), ("xyz", "<f8", (3,))])  # 28 bytes
_POSE = np.dtype([("nt", "<i4"), ("t", "<f8", (3,)), ("nq", "<i4"), ("q", "<f8", (4,))])  # 64 bytes
_EDGE = np.dtype([("first", "<u4"), ("second", "<u4"), ("pose", _POSE), ("weight", "<f8")])  # 80 bytes
_NODE_MIN = 4 + _POSE.itemsize + 4  # a node with no points
_QUAT_TOL = 1e-3  # |‖q‖ − 1| accepted (and normalised away) in a stored quaternion


@dataclass(eq=False)
class ScanGraph:
    """An OctoMap scan graph.

    Attributes
    ----------
    nodes : list[PointCloud]
        One cloud per node, points in the sensor frame, ``pose`` = ``T_world_sensor``.
    ids : ndarray (N,) uint32
        The node ids, in file order (OctoMap numbers them 0, 1, … but any distinct ids do).
    edge_first, edge_second : ndarray (E,) uint32
        Node ids joined by each edge.
    edge_constraints : SE3 of shape (E,)
        Each edge's constraint; OctoMap sets it to ``pose_first⁻¹ · pose_second``.
    edge_weights : ndarray (E,) float64
        Each edge's weight (OctoMap writes 1.0).

    ``read_scangraph`` also remembers the translation and quaternion of every pose exactly as
    stored, so that a graph written back unchanged is byte-identical to the file (a quaternion
    recomputed from a matrix can differ in the last bit, or in sign). A pose that no longer
    matches what was read is written from its matrix.
    """

    nodes: list[PointCloud]
    ids: np.ndarray = None
    edge_first: np.ndarray = None
    edge_second: np.ndarray = None
    edge_constraints: SE3 = None
    edge_weights: np.ndarray = None
    _raw_node_poses: np.ndarray | None = field(default=None, repr=False)
    _raw_edge_poses: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self):
        self.nodes = list(self.nodes)
        n = len(self.nodes)
        for k, node in enumerate(self.nodes):
            if not isinstance(node, PointCloud):
                raise InvalidArgumentError(f"nodes[{k}] must be a PointCloud, got {type(node).__name__}")
        self.ids = np.arange(n, dtype=np.uint32) if self.ids is None else _ids(self.ids, "ids", n)
        if len(np.unique(self.ids)) != n:
            raise InvalidArgumentError("node ids must be distinct")
        first = np.zeros(0, np.uint32) if self.edge_first is None else _ids(self.edge_first, "edge_first")
        e = first.shape[0]
        self.edge_first = first
        second = self.edge_second
        self.edge_second = np.zeros(0, np.uint32) if second is None else _ids(second, "edge_second", e)
        if self.edge_constraints is None:
            self.edge_constraints = SE3.identity(e)
        elif not isinstance(self.edge_constraints, SE3):
            self.edge_constraints = SE3(self.edge_constraints)
        if self.edge_constraints.shape != (e,):
            raise ShapeError(f"edge_constraints must have shape ({e},), got {self.edge_constraints.shape}")
        w = np.ones(e) if self.edge_weights is None else np.asarray(self.edge_weights, dtype=np.float64)
        if w.shape != (e,):
            raise ShapeError(f"edge_weights must have shape ({e},), got {w.shape}")
        self.edge_weights = w
        known = np.isin(np.concatenate((self.edge_first, self.edge_second)), self.ids)
        if not known.all():
            bad = np.concatenate((self.edge_first, self.edge_second))[~known][0]
            raise InvalidArgumentError(f"an edge refers to node id {bad}, which is not in ids")

    def __len__(self) -> int:
        return len(self.nodes)

    def world_points(self) -> np.ndarray:
        """All nodes' points in the world frame, stacked (sum of N_i, 3)."""
        if not self.nodes:
            return np.zeros((0, 3))
        return np.concatenate([n.world_points() for n in self.nodes])

    def __repr__(self) -> str:
        pts = sum(len(n) for n in self.nodes)
        return f"ScanGraph({len(self.nodes)} nodes, {pts} points, {self.edge_first.shape[0]} edges)"


def _ids(values, name, n=None) -> np.ndarray:
    a = np.asarray(values)
    if a.ndim != 1 or (n is not None and a.shape[0] != n):
        want = f"({n},)" if n is not None else "(E,)"
        raise ShapeError(f"{name} must have shape {want}, got {a.shape}")
    if a.size and (not np.issubdtype(a.dtype, np.integer) or a.min() < 0 or a.max() > 0xFFFFFFFF):
        raise InvalidArgumentError(f"{name} must be integers in 0 .. 2**32 - 1")
    return a.astype(np.uint32)


# --------------------------------------------------------------------------------------------
# reading


def _check_prefix(path, values: np.ndarray, expect: int, base: int, stride: int, field_off: int, what: str):
    bad = values != expect
    if bad.any():
        i = int(np.argmax(bad))
        raise FormatError(
            path, f"{what}: size prefix {int(values[i])}, expected {expect}", offset=base + i * stride + field_off
        )


def _poses_to_se3(path, recs: np.ndarray, base: int, stride: int, pose_off: int, what: str) -> np.ndarray:
    """(K,) pose records → (K, 4, 4) matrices, checking prefixes and quaternions."""
    _check_prefix(path, recs["nt"], 3, base, stride, pose_off, f"{what} translation")
    _check_prefix(path, recs["nq"], 4, base, stride, pose_off + 28, f"{what} rotation")
    t = recs["t"]
    q = recs["q"]
    norm = np.linalg.norm(q, axis=-1)
    bad = ~(np.isfinite(t).all(axis=-1) & (np.abs(norm - 1.0) <= _QUAT_TOL))
    if bad.any():
        i = int(np.argmax(bad))
        raise FormatError(
            path,
            f"{what}: pose translation {t[i].tolist()} / quaternion {q[i].tolist()} is not finite or not of unit norm",
            offset=base + i * stride + pose_off,
        )
    m = np.zeros(t.shape[:-1] + (4, 4))
    m[..., :3, :3] = quat_to_matrix(q / norm[..., None])
    m[..., :3, 3] = t
    m[..., 3, 3] = 1.0
    return m


def read_scangraph(path) -> ScanGraph:
    """Read an OctoMap ``.graph`` file (plain, .gz, .bz2 or .xz) into a :class:`ScanGraph` (layout in
    the module docstring; byte offsets in errors count the decompressed data)."""
    data = read_bytes(path)
    size = len(data)
    pos = 0

    def need(n_bytes: int, what: str):
        if size - pos < n_bytes:
            raise FormatError(path, f"file truncated: {what} needs {n_bytes} bytes, {size - pos} left", offset=pos)

    need(4, "node count")
    n_nodes = int(np.frombuffer(data, "<u4", 1, pos)[0])
    if n_nodes * _NODE_MIN > size - 4 - 4:
        raise FormatError(
            path,
            f"node count {n_nodes} needs at least {n_nodes * _NODE_MIN} bytes, the file has "
            f"{size - 8} after the counts",
            offset=0,
        )
    pos = 4
    nodes_pts, ids, raw_node = [], np.empty(n_nodes, np.uint32), np.empty((n_nodes, 7))
    node_mats = np.empty((n_nodes, 4, 4))
    for k in range(n_nodes):
        need(4, f"node {k} point count")
        n_pts = int(np.frombuffer(data, "<u4", 1, pos)[0])
        start = pos + 4
        if n_pts * _POINT.itemsize > size - start - _POSE.itemsize - 4:
            raise FormatError(
                path,
                f"node {k}: point count {n_pts} needs {n_pts * _POINT.itemsize} bytes plus its pose and "
                f"id, only {size - start} bytes left",
                offset=pos,
            )
        pts = np.frombuffer(data, _POINT, n_pts, start)
        _check_prefix(path, pts["n"], 3, start, _POINT.itemsize, 0, f"node {k} point")
        pos = start + n_pts * _POINT.itemsize
        rec = np.frombuffer(data, _POSE, 1, pos)
        node_mats[k] = _poses_to_se3(path, rec, pos, _POSE.itemsize, 0, f"node {k}")[0]
        raw_node[k, :3] = rec["t"][0]
        raw_node[k, 3:] = rec["q"][0]
        pos += _POSE.itemsize
        ids[k] = np.frombuffer(data, "<u4", 1, pos)[0]
        pos += 4
        nodes_pts.append(np.array(pts["xyz"], dtype=np.float64))
    if len(np.unique(ids)) != n_nodes:
        raise FormatError(path, "node ids are not distinct", offset=pos)

    need(4, "edge count")
    n_edges = int(np.frombuffer(data, "<u4", 1, pos)[0])
    pos += 4
    if n_edges * _EDGE.itemsize != size - pos:
        if n_edges * _EDGE.itemsize > size - pos:
            raise FormatError(
                path,
                f"edge count {n_edges} needs {n_edges * _EDGE.itemsize} bytes, {size - pos} left",
                offset=pos - 4,
            )
        end = pos + n_edges * _EDGE.itemsize
        raise FormatError(path, f"{size - end} unexpected bytes after the last edge", offset=end)
    edges = np.frombuffer(data, _EDGE, n_edges, pos)
    pose_off = _EDGE.fields["pose"][1]
    edge_mats = _poses_to_se3(path, edges["pose"], pos, _EDGE.itemsize, pose_off, "edge")
    first = edges["first"].astype(np.uint32)
    second = edges["second"].astype(np.uint32)
    for which, col, off in (("first", first, 0), ("second", second, 4)):
        known = np.isin(col, ids)
        if not known.all():
            i = int(np.argmax(~known))
            at = pos + i * _EDGE.itemsize + off
            raise FormatError(path, f"edge {i}: {which} node id {int(col[i])} is not a node", offset=at)
    raw_edge = np.concatenate((edges["pose"]["t"], edges["pose"]["q"]), axis=1) if n_edges else np.zeros((0, 7))

    poses = SE3(node_mats, _trusted=True)
    nodes = [PointCloud(p, poses[k]) for k, p in enumerate(nodes_pts)]
    return ScanGraph(
        nodes,
        ids,
        first,
        second,
        SE3(edge_mats, _trusted=True),
        np.array(edges["weight"], dtype=np.float64),
        _raw_node_poses=raw_node,
        _raw_edge_poses=raw_edge,
    )


# --------------------------------------------------------------------------------------------
# writing


def _pose_values(mats: np.ndarray, raw: np.ndarray | None) -> np.ndarray:
    """(K, 7) translation + quaternion (w, x, y, z) for (K, 4, 4) matrices, reusing the values
    read from the file wherever they still give exactly the same matrix."""
    k = mats.shape[0]
    out = np.empty((k, 7))
    if k == 0:
        return out
    out[:, :3] = mats[:, :3, 3]
    out[:, 3:] = SE3(mats, _trusted=True).rotation.as_quat()
    if raw is not None and raw.shape == (k, 7):
        q = raw[:, 3:]
        m = np.zeros((k, 4, 4))
        m[:, :3, :3] = quat_to_matrix(q / np.linalg.norm(q, axis=1, keepdims=True))
        m[:, :3, 3] = raw[:, :3]
        m[:, 3, 3] = 1.0
        same = (m == mats).all(axis=(1, 2))
        out[same] = raw[same]
    return out


def _pose_records(values: np.ndarray) -> np.ndarray:
    rec = np.zeros(values.shape[0], _POSE)
    rec["nt"] = 3
    rec["t"] = values[:, :3]
    rec["nq"] = 4
    rec["q"] = values[:, 3:]
    return rec


def write_scangraph(path, graph: ScanGraph):
    """Write ``graph`` as an OctoMap ``.graph`` file (atomically); returns the path.

    Points are written as stored (sensor frame, f64); poses as translation + quaternion
    ``(w, x, y, z)``, reusing the exact values read by :func:`read_scangraph` for poses that
    were not changed, so an unchanged graph round-trips byte for byte.
    """
    if not isinstance(graph, ScanGraph):
        raise InvalidArgumentError(f"graph must be a ScanGraph, got {type(graph).__name__}")
    n = len(graph.nodes)
    if n > 0xFFFFFFFF:
        raise InvalidArgumentError("too many nodes for a u32 count")
    node_mats = np.array([node.pose.matrix for node in graph.nodes]).reshape(n, 4, 4)
    node_vals = _pose_values(node_mats, graph._raw_node_poses)
    node_poses = _pose_records(node_vals)
    parts = [np.uint32(n).tobytes()]
    for k, node in enumerate(graph.nodes):
        m = len(node)
        if m > 0xFFFFFFFF:
            raise InvalidArgumentError(f"node {k} has too many points for a u32 count")
        pts = np.empty(m, _POINT)
        pts["n"] = 3
        pts["xyz"] = node.points
        parts += [np.uint32(m).tobytes(), pts.tobytes(), node_poses[k : k + 1].tobytes()]
        parts.append(graph.ids[k : k + 1].astype("<u4").tobytes())
    e = graph.edge_first.shape[0]
    edges = np.zeros(e, _EDGE)
    edges["first"] = graph.edge_first
    edges["second"] = graph.edge_second
    if e:
        mats = graph.edge_constraints.matrix.reshape(e, 4, 4)
        edges["pose"] = _pose_records(_pose_values(mats, graph._raw_edge_poses))
    edges["weight"] = graph.edge_weights
    parts += [np.uint32(e).tobytes(), edges.tobytes()]
    return write_atomic(path, b"".join(parts))
