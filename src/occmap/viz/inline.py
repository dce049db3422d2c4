"""An octree as a 3D scene in one HTML document, for notebooks (``OcTree._repr_html_``) and for
files to send (``OcTree.save_html``): the occupied voxels as boxes coloured by height, which the
reader turns, pans and zooms in the page, with no server and no internet.

The scene is built with viser (the library behind ``occmap view``) and serialised with its
client, whose code (about 0.8 MB) is embedded in the document. The voxels go in at the deepest
depth whose occupied nodes number at most ``max_voxels`` (:mod:`occmap.viz._lod`: a coarser node
is occupied when anything inside it is, so nothing occupied is hidden), about 10 bytes each once
compressed: geb079.bt's 143,729 occupied leaves make a 1.4 MB document.
"""

from __future__ import annotations

import html

import numpy as np

from .. import checks
from ..errors import InvalidArgumentError
from ._lod import Voxels, pick_level, ramp
from ._scene3d import add_boxes, camera_view, close_server, new_server

#: Boxes in an inline scene at most: a notebook keeps its outputs, so a few MB each at most.
INLINE_MAX_VOXELS = 150_000
#: Height of the scene in a notebook, pixels.
INLINE_HEIGHT = 480


def octree_voxels(tree, max_voxels: int = INLINE_MAX_VOXELS, z_max: float | str | None = "ceiling") -> Voxels:
    """The occupied boxes of ``tree`` an inline scene draws: those whose bottom lies under
    ``z_max`` metres (``"ceiling"``: under an indoor map's ceiling, :func:`occmap.octree.views.ceiling`,
    so that one sees into the rooms from above; None: all), at the deepest depth where at most
    ``max_voxels`` remain."""
    from ..octree import views

    max_voxels = checks.count("max_voxels", max_voxels, minimum=1)
    if isinstance(z_max, str):
        if z_max != "ceiling":
            raise InvalidArgumentError(f"z_max must be a height in metres, 'ceiling' or None, got {z_max!r}")
        z_max = views.ceiling(tree)
    top = np.inf if z_max is None else checks.finite("z_max", z_max)
    occupied = tree.occupied_log_odds

    def keep(v: Voxels) -> np.ndarray:
        # a bottom on the cut's height (as a ceiling's is) must not pass by a rounding error
        return (v.log_odds >= occupied) & (v.centers[:, 2] - v.sizes / 2 < top - 1e-3 * v.sizes)

    return pick_level(lambda d: Voxels.of_leaves(tree.leaves(depth=d)), keep, max_voxels).voxels


def scene_document(voxels: Voxels, style: str = "points") -> str:
    """A standalone HTML document showing ``voxels`` coloured by height (dark blue → yellow over
    their height range), the camera looking at them from aside and above."""
    server = new_server()
    try:
        if voxels.count:
            z = voxels.centers[:, 2]
            add_boxes(server.scene, "/map/occupied", voxels, ramp(z, (float(z.min()), float(z.max()))), style)
            half = voxels.sizes[:, None] / 2
            position, look_at = camera_view((voxels.centers - half).min(axis=0), (voxels.centers + half).max(axis=0))
            server.initial_camera.position = tuple(position)
            server.initial_camera.look_at = tuple(look_at)
        return server.scene.as_html()
    finally:
        close_server(server)


def iframe(document: str, height: int = INLINE_HEIGHT) -> str:
    """``document`` as an HTML fragment a notebook shows inline: an iframe holding it (its own page,
    so that its scripts and styles leave the notebook's alone)."""
    return (f'<iframe srcdoc="{html.escape(document, quote=True)}" width="100%" height="{int(height)}" '
            'style="border:1px solid #ddd" title="occmap 3D scene"></iframe>')
