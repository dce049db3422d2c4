"""What a path holds, as arrays a 3D viewer draws: octree nodes at any depth (``.bt``/``.ot``
files, octree tile stores), points (point clouds, scan graphs), a textured plane (map_server maps,
2D tile stores) and the sensor's path where the file records one.

Every reader is occmap's own (:mod:`occmap.io`, :mod:`occmap.world`); this module only turns what
they return into :class:`Scene` arrays. Coordinates are the map's, in metres.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Callable

import numpy as np

from ..errors import InvalidArgumentError, MissingFileError
from ..logodds import logit32
from ._lod import Voxels

if TYPE_CHECKING:
    from ..local.recording import LocalMapRecording
    from ..localize.recording import LocalizationRecording
    from ..mapping2d_recording import MappingRecording

#: Extensions read as OctoMap files, map_server maps and scan graphs; point clouds are those of
#: :func:`occmap.io.pointclouds.read_cloud`.
OCTREE_SUFFIXES = (".bt", ".ot")
MAP2D_SUFFIXES = (".yaml", ".yml")
GRAPH_SUFFIXES = (".graph",)
RECORDING_SUFFIXES = (".npz",)
#: Pixels a 2D map's picture spans at most per side (a browser's texture); wider maps are drawn
#: with coarser pixels.
MAX_PLANE_PIXELS = 4096


@dataclass
class Plane:
    """A picture lying in the plane z = 0: RGB (H, W, 3) uint8 with row 0 along the map's lowest
    y (as nav_msgs rows; the viewer lays an image's first row along the plane's −y edge), its size
    in metres, its centre and yaw (radians)."""

    rgb: np.ndarray
    width: float
    height: float
    center: np.ndarray
    yaw: float = 0.0


@dataclass
class Scene:
    """A map ready to draw. ``nodes_at(depth)`` gives an octree's known nodes down to ``depth``
    (None for maps without voxels); ``counts(depth)``, where a map can tell without building them
    (a tile store, read tile by tile), how many of them are occupied and free; ``occupied_log_odds``
    is its threshold; ``recording`` a run to replay over the map."""

    path: Path
    kind: str
    summary: str
    resolution: float
    bounds: tuple[np.ndarray, np.ndarray]
    nodes_at: Callable[[int], Voxels] | None = None
    counts: Callable[[int], tuple[int, int]] | None = None
    occupied_log_odds: float = 0.0
    points: np.ndarray | None = None
    plane: Plane | None = None
    sensor_path: np.ndarray | None = field(default=None)
    recording: LocalizationRecording | MappingRecording | LocalMapRecording | None = None


def viewable(path: Path) -> bool:
    """Whether :func:`open_scene` takes ``path`` (by its name and kind; the content is not read)."""
    from ..io._compression import EXTENSIONS
    from ..io.pointclouds import _READERS

    if path.is_dir():
        return (path / "index.json").is_file()
    suffixes = [s.lower() for s in path.suffixes]
    if suffixes and suffixes[-1] in EXTENSIONS:
        suffixes.pop()
    last = suffixes[-1] if suffixes else ""
    return last in OCTREE_SUFFIXES + MAP2D_SUFFIXES + GRAPH_SUFFIXES + RECORDING_SUFFIXES or last in _READERS


def open_scene(path) -> Scene:
    """Read ``path``: an OctoMap file, a tile store folder, a map_server ``.yaml``, a scan graph, a
    recorded run (``.npz``: localization, mapping or local map, by its ``format`` entry) or a point
    cloud.
    Raises :class:`~occmap.errors.OccmapError` (a missing file, a bad format, a kind of file it
    cannot show) naming the path."""
    path = Path(path)
    if not path.exists():
        raise MissingFileError(path, "no such file or folder")
    suffix = path.suffix.lower()
    if path.is_dir():
        return _tile_store(path)
    if suffix in OCTREE_SUFFIXES:
        return _octree(path)
    if suffix in MAP2D_SUFFIXES:
        return _map2d(path)
    if suffix in GRAPH_SUFFIXES:
        return _graph(path)
    if suffix in RECORDING_SUFFIXES:
        return _recording(path)
    if viewable(path):
        return _cloud(path)
    raise InvalidArgumentError(f"{str(path)!r}: cannot show this kind of file; expected an OctoMap file (.bt, .ot), "
                               "a tile store folder, a map_server .yaml, a scan graph (.graph), a recorded run "
                               "(.npz) or a point cloud (.pcd, .ply, .xyz, .bin, .3d, ...)")


def _octree(path: Path) -> Scene:
    from ..io.octomap import read_octree

    tree = read_octree(path)
    lo, hi = _bounds(tree.leaves(depth=8))  # a cheap box: nodes 256 voxels wide, the map's reach
    summary = f"{tree.num_nodes():,} nodes, {tree.num_leaves():,} leaves, {tree.resolution:g} m"
    return Scene(path, "octree", summary, tree.resolution, (lo, hi),
                 nodes_at=lambda d: Voxels.of_leaves(tree.leaves(depth=d)),
                 occupied_log_odds=float(tree.occupied_log_odds))


def _bounds(leaves) -> tuple[np.ndarray, np.ndarray]:
    if not len(leaves.sizes):
        return np.zeros(3), np.zeros(3)
    half = 0.5 * leaves.sizes[:, None]
    return (leaves.centers - half).min(axis=0), (leaves.centers + half).max(axis=0)


def _tile_store(path: Path) -> Scene:
    """An octree tile store, read one tile at a time: once at opening to count its nodes per depth
    (:attr:`Scene.counts`), then once per level drawn. Memory holds a tile and the boxes drawn,
    whatever the store's size."""
    from ..world.store import TileStore

    store = TileStore.open(path)
    if store.kind == "grid":
        return _grid_store(path)
    from ..io.octomap import read_ot
    from ..octree.keys import DEPTH

    params = {k: tuple(v) if k == "clamp" else v for k, v in store.params.items()}
    l_occ = float(logit32(params.get("occupied_threshold", 0.5)))
    side = store.tile_size * store.resolution
    entries = sorted(store.tiles.items())
    top = DEPTH - (store.tile_size.bit_length() - 1)  # a tile is one node of this depth: no coarser node is its own

    def trees():
        for index, entry in entries:
            yield np.array(index, np.float64) * side, read_ot(store.path / entry["file"], **params)

    counts = np.zeros((DEPTH + 1, 2), np.int64)  # per depth: occupied nodes, free nodes
    nodes = 0
    for _, tree in trees():
        nodes += tree.num_nodes()
        for d in range(top, DEPTH + 1):
            log_odds = tree.leaves(depth=d).log_odds
            occupied = np.count_nonzero(log_odds >= l_occ)
            counts[d] += occupied, len(log_odds) - occupied
    counts[:top] = counts[top]

    def nodes_at(depth: int) -> Voxels:
        d = max(depth, top)
        return Voxels.concatenate(Voxels.of_leaves(tree.leaves(depth=d), shift) for shift, tree in trees())

    if entries:
        corners = np.array([index for index, _ in entries], np.float64) * side
        lo, hi = corners.min(axis=0), corners.max(axis=0) + side
    else:
        lo = hi = np.zeros(3)
    summary = f"{len(entries):,} tiles of {store.tile_size} voxels, {nodes:,} nodes, {store.resolution:g} m"
    return Scene(path, "octree tile store", summary, store.resolution, (lo, hi), nodes_at=nodes_at,
                 occupied_log_odds=l_occ, counts=lambda d: tuple(int(c) for c in counts[d]))


def _grid_store(path: Path) -> Scene:
    """A 2D tile store as a plane, read one tile at a time: memory holds a tile and the picture,
    whatever the store's size. A store wider than :data:`MAX_PLANE_PIXELS` cells is drawn with
    pixels 2, 4, 8 … cells wide, each the most occupied of its known cells (unknown only where all
    are), so that no obstacle drops out of the picture."""
    from ..logodds import occupancy_values
    from ..world import TiledGrid2D

    with TiledGrid2D.open(path) as grid:
        res, T = grid.resolution, grid.tile_size
        tiles = list(grid.tiles())
        x0, y0, x1, y1 = grid.extent or (0, 0, 1, 1)  # the cells the scans reached
        k = 1
        while max(x1 - x0, y1 - y0) > MAX_PLANE_PIXELS * k:
            k *= 2
        px0, py0 = x0 // k, y0 // k  # the picture's first pixel, on the lattice of k-cell pixels
        raster = np.full(((y1 - 1) // k - py0 + 1, (x1 - 1) // k - px0 + 1), -1, np.int8)
        for index in tiles:
            lo, hi = grid.tile_bounds(index)
            occ = occupancy_values(grid.log_odds((lo[0], lo[1], hi[0], hi[1])))
            block = block_max(occ, min(k, T))  # tiles and pixels share the lattice's power-of-two alignment
            cx, cy = index[0] * T // k - px0, index[1] * T // k - py0  # the tile's first pixel
            r0, c0 = max(cy, 0), max(cx, 0)
            r1, c1 = min(cy + len(block), raster.shape[0]), min(cx + len(block), raster.shape[1])
            if r0 < r1 and c0 < c1:
                view = raster[r0:r1, c0:c1]
                np.maximum(view, block[r0 - cy:r1 - cy, c0 - cx:c1 - cx], out=view)
    plane = occupancy_plane(raster, res * k, np.array([px0 * k * res, py0 * k * res]), 0.0)
    pixels = "" if k == 1 else f", drawn in {res * k:g} m pixels"
    summary = f"2D tile store, {x1 - x0} × {y1 - y0} cells, {res:g} m{pixels}"
    return Scene(path, "grid tile store", summary, res, _plane_bounds(plane), plane=plane)


def _map2d(path: Path) -> Scene:
    from ..io.mapserver import load_map

    m = load_map(path)
    plane = occupancy_plane(m.occupancy, m.resolution, np.array(m.origin[:2]), m.origin[2])
    summary = f"2D map, {m.occupancy.shape[1]} × {m.occupancy.shape[0]} cells, {m.resolution:g} m"
    return Scene(path, "2D map", summary, m.resolution, _plane_bounds(plane), plane=plane)


def _recording(path: Path) -> Scene:
    from .. import _recordings
    from ..errors import FormatError
    from ..local import recording as local
    from ..localize import recording as localize
    from .. import mapping2d_recording as mapping

    entries = _recordings.read(path)
    kinds = {localize.FORMAT: _localization_run, mapping.FORMAT: _mapping_run, local.FORMAT: _local_map_run}
    scene = kinds.get(entries.format)
    if scene is None:
        raise FormatError(path, f"not an occmap recording (format entry {entries.arrays.get('format')!r}; expected "
                                f"one of {', '.join(map(repr, kinds))})")
    return scene(entries)


def _localization_run(entries) -> Scene:
    from ..localize.recording import LocalizationRecording

    rec = LocalizationRecording.of_entries(entries)
    plane = occupancy_plane(rec.occupancy, rec.resolution, rec.origin, 0.0)
    h, w = rec.occupancy.shape
    has_ref = int(np.isfinite(rec.reference[:, 0]).sum())
    summary = (f"{len(rec):,} steps over {rec.stamps[-1] - rec.stamps[0]:.1f} s, up to "
               f"{rec.particles.shape[1]} particles a step, {has_ref:,} reference poses; map {w} × {h} cells, "
               f"{rec.resolution:g} m")
    return Scene(entries.path, "localization run", summary, rec.resolution, _plane_bounds(plane), plane=plane,
                 recording=rec)


def _mapping_run(entries) -> Scene:
    """The plane is drawn step by step (the viewer asks the recording for the map at its step)."""
    from ..mapping2d_recording import MappingRecording

    rec = MappingRecording.of_entries(entries)
    h, w = rec.shape
    summary = (f"{len(rec):,} scans over {rec.stamps[-1] - rec.stamps[0]:.1f} s, {len(rec.delta_steps):,} map "
               f"states; map {w} × {h} cells, {rec.resolution:g} m")
    corner = np.append(rec.origin, 0.0)
    return Scene(entries.path, "mapping run", summary, rec.resolution,
                 (corner, corner + [w * rec.resolution, h * rec.resolution, 0.0]), recording=rec)


def _local_map_run(entries) -> Scene:
    """The window's plane is drawn step by step, where the window is at that step; the scene spans
    the ground it swept and half a window around (room for the camera's view)."""
    from ..local.recording import LocalMapRecording

    rec = LocalMapRecording.of_entries(entries)
    h, w = rec.costs.shape[1:]
    size = np.array([w, h]) * rec.resolution
    lo, hi = rec.origins.min(axis=0) - size / 2, rec.origins.max(axis=0) + 1.5 * size
    summary = (f"{len(rec):,} steps over {rec.stamps[-1] - rec.stamps[0]:.1f} s, a {w} × {h} window at "
               f"{rec.resolution:g} m, {len(rec.track_id):,} track boxes")
    return Scene(entries.path, "local map run", summary, rec.resolution, (np.append(lo, 0.0), np.append(hi, 0.0)),
                 recording=rec)


def block_max(occupancy: np.ndarray, k: int) -> np.ndarray:
    """nav_msgs values (H, W) in blocks of k × k cells from the corner, each block its largest value
    (an occupied cell shows through free ones, a known one through unknown ones; no wall drops out
    of a coarser picture); the last blocks padded with unknown."""
    h, w = occupancy.shape
    rows, cols = -(-h // k), -(-w // k)
    if (rows * k, cols * k) != (h, w):
        padded = np.full((rows * k, cols * k), -1, np.int8)
        padded[:h, :w] = occupancy
        occupancy = padded
    return occupancy.reshape(rows, k, cols, k).max(axis=(1, 3))


def occupancy_plane(occupancy: np.ndarray, resolution: float, corner: np.ndarray, yaw: float) -> Plane:
    """nav_msgs values (row 0 at the lowest y) as map_server's picture: unknown grey, free white,
    occupied black, grey levels between; its centre from the outer corner of cell (0, 0)."""
    occ = np.asarray(occupancy)
    grey = np.where(occ < 0, 205, np.rint(255 * (1 - np.clip(occ, 0, 100) / 100.0))).astype(np.uint8)
    rgb = np.repeat(grey[:, :, None], 3, axis=2)
    h, w = occ.shape
    c, s = np.cos(yaw), np.sin(yaw)
    half = np.array([w, h]) * resolution / 2
    center = corner + np.array([c * half[0] - s * half[1], s * half[0] + c * half[1]])
    return Plane(rgb, w * resolution, h * resolution, np.array([center[0], center[1], 0.0]), float(yaw))


def _plane_bounds(plane: Plane) -> tuple[np.ndarray, np.ndarray]:
    r = 0.5 * np.hypot(plane.width, plane.height)
    return plane.center - [r, r, 0.0], plane.center + [r, r, 0.0]


def _graph(path: Path) -> Scene:
    from ..io.scangraph import read_scangraph

    graph = read_scangraph(path)
    points = graph.world_points()
    origins = np.array([n.origin for n in graph.nodes]).reshape(-1, 3)
    summary = f"scan graph, {len(graph)} scans, {len(points):,} points"
    return _points_scene(path, "scan graph", summary, points, origins)


def _cloud(path: Path) -> Scene:
    from ..io.pointclouds import read_cloud

    cloud = read_cloud(path)
    summary = f"point cloud, {len(cloud.points):,} points" + (f" ({cloud.dropped:,} dropped)" if cloud.dropped else "")
    return _points_scene(path, "point cloud", summary, cloud.world_points(),
                         cloud.origin[None, :] if cloud.has_pose else None)


def _points_scene(path, kind, summary, points, origins) -> Scene:
    both = points if origins is None else np.concatenate([points, origins])
    lo, hi = (both.min(axis=0), both.max(axis=0)) if len(both) else (np.zeros(3), np.zeros(3))
    size = float(np.clip(np.linalg.norm(hi - lo) / 2000, 0.01, 0.2))  # about a pixel at full view
    return Scene(path, kind, summary, size, (lo, hi), points=points.astype(np.float32), sensor_path=origins)
