"""Writing an octree by the output's extension, for ``map3d`` and ``convert``."""

from __future__ import annotations

from pathlib import Path

from ._outputs import check_suffix

#: ``.bt`` OctoMap's maximum-likelihood binary, ``.ot`` its full values, ``.ply`` occupied voxels.
SUFFIXES = (".bt", ".ot", ".ply")


def check_octree_output(path) -> None:
    """Refuse an output name no writer handles (before any work)."""
    check_suffix("octree output", path, SUFFIXES)


def save_octree(tree, path) -> None:
    """Write ``tree`` as ``.bt``, ``.ot`` or a ``.ply`` of its occupied voxels, by extension."""
    check_octree_output(path)
    from ..io.octomap import write_bt, write_ot

    suffix = Path(path).suffix.lower()
    if suffix == ".bt":
        write_bt(tree, path)
    elif suffix == ".ot":
        write_ot(tree, path)
    else:
        tree.export_ply(path)
