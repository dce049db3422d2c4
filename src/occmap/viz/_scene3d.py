"""What the browser viewer and the inline (notebook) scenes share: a viser server set up for maps,
boxes drawn as square points or shaded cubes, and the camera's first view of a box."""

from __future__ import annotations

import contextlib
import io

import numpy as np

from ._lod import Voxels

#: The page behind the map: light grey, so that the white of free space on a 2D map stands out.
BACKGROUND = (232, 234, 238)
STYLES = ("points", "boxes")

# a unit cube centred on the origin: 8 corners, 12 triangles wound outwards
_CUBE_VERTICES = np.array([[x, y, z] for z in (-0.5, 0.5) for y in (-0.5, 0.5) for x in (-0.5, 0.5)], np.float32)
_CUBE_FACES = np.array([[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
                        [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]], np.uint32)


def new_server(host: str = "127.0.0.1", port: int = 0):
    """A viser server (z up, no environment light: it washes the height colours out), silent: the
    caller says where it is."""
    import viser

    with contextlib.redirect_stdout(io.StringIO()):  # viser's banner
        server = viser.ViserServer(host=host, port=port, label="occmap", verbose=False)
    server.scene.set_up_direction("+z")
    server.scene.configure_environment_map(hdri=None)
    server.scene.set_background_image(np.full((8, 8, 3), BACKGROUND, np.uint8), format="png")
    return server


def close_server(server) -> None:
    """Close ``server`` without its goodbye line on standard output."""
    with contextlib.redirect_stdout(io.StringIO()):
        server.stop()


def add_boxes(scene, name: str, v: Voxels, colors, style: str = "points", see_through: bool = False) -> None:
    """Draw ``v`` under ``name`` in a viser scene: as square points one per box and as wide as it
    (one vertex each: smooth with half a million even on software graphics), or as instances of one
    shaded cube (12 triangles each). ``see_through`` boxes (free space) are drawn translucent, or
    as points a third as wide, so that the occupied ones show through them."""
    scene.remove_by_name(name)
    if not v.count:
        return
    if style == "points":
        colors = np.broadcast_to(colors, (v.count, 3))
        for size in np.unique(v.sizes):
            sel = v.sizes == size
            scene.add_point_cloud(f"{name}/{size:g}", v.centers[sel], colors[sel],
                                  point_size=float(size) / (3 if see_through else 1), point_shape="square",
                                  precision="float32", point_shading="flat")
        return
    scene.add_batched_meshes_simple(
        name, _CUBE_VERTICES, _CUBE_FACES,
        batched_wxyzs=np.broadcast_to(np.array([1, 0, 0, 0], np.float32), (v.count, 4)),
        batched_positions=v.centers, batched_scales=v.sizes, batched_colors=colors,
        opacity=0.25 if see_through else None,
        lod="off", material="toon3", cast_shadow=False, receive_shadow=False)


def camera_view(lo, hi, from_above: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Where a camera showing the box ``lo`` … ``hi`` (metres) stands and what it looks at: from
    aside and above (a map), or nearly straight from above (a run on a 2D map: the robot's moves
    read as on paper)."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    center = (lo + hi) / 2
    reach = max(float(np.linalg.norm(hi - lo)), 1.0)
    return center + reach * np.array([0.0, -0.2, 0.5] if from_above else [-0.25, -0.45, 0.4]), center
