"""Octrees as 3D scenes in one HTML document (notebooks' ``_repr_html_``, ``OcTree.save_html``):
which voxels go in (the ceiling cut, the level of detail hiding nothing occupied), and the document
drawn in a real headless Chromium that may fetch nothing at all."""

from __future__ import annotations

import numpy as np
import pytest

from headless import Page, keep

from occmap.errors import InvalidArgumentError

RES = 0.1


@pytest.fixture(scope="module")
def room():
    """An octree of a room 6 × 4 m, walls 2.5 m high under a ceiling, seen from its middle."""
    from occmap.octree import OcTree

    u, v = np.meshgrid(np.linspace(0, 1, 90), np.linspace(0, 1, 40))
    u, v = u.ravel(), v.ravel()
    walls = [np.stack([u * 6, np.zeros_like(u), v * 2.5], 1), np.stack([u * 6, np.full_like(u, 4.0), v * 2.5], 1),
             np.stack([np.zeros_like(u), u * 4, v * 2.5], 1), np.stack([np.full_like(u, 6.0), u * 4, v * 2.5], 1)]
    g = np.stack(np.meshgrid(np.linspace(0.05, 5.95, 60), np.linspace(0.05, 3.95, 40)), -1).reshape(-1, 2)
    ceiling = np.column_stack([g, np.full(len(g), 2.55)])
    tree = OcTree(RES)
    tree.insert_point_cloud(np.concatenate(walls + [ceiling]) + [0.013, 0.017, 0.011], [3.0, 2.0, 1.2])
    return tree


def occupied_centers(tree):
    lv = tree.leaves()
    return lv.centers[lv.log_odds >= tree.occupied_log_odds]


def test_the_ceiling_is_cut_and_nothing_else(room):
    from occmap.octree.views import ceiling
    from occmap.viz.inline import octree_voxels

    top = ceiling(room)
    assert top == pytest.approx(2.5)
    occ = occupied_centers(room)
    under = occ[occ[:, 2] < top]
    cut = octree_voxels(room)
    assert np.all(cut.centers[:, 2] - cut.sizes / 2 < top)
    assert np.allclose(np.sort(cut.centers, axis=0), np.sort(under, axis=0), atol=1e-4)  # every voxel under it
    whole = octree_voxels(room, z_max=None)
    assert whole.count == len(occ) > cut.count + 2000  # the ceiling's 60 × 40 voxels are back
    assert octree_voxels(room, z_max=1.0).centers[:, 2].max() < 1.0


def test_a_cap_coarsens_without_hiding_anything_occupied(room):
    from occmap.viz.inline import octree_voxels

    occ = occupied_centers(room)
    v = octree_voxels(room, max_voxels=1500, z_max=None)
    assert 0 < v.count <= 1500 and v.sizes.min() > RES
    half = v.sizes[:, None] / 2
    inside = np.all(np.abs(occ[:, None, :] - v.centers[None]) <= half[None] + 1e-4, axis=2).any(axis=1)
    assert inside.all(), f"{np.count_nonzero(~inside)} occupied voxels outside every drawn box"


def test_bad_arguments(room):
    from occmap.viz.inline import octree_voxels

    with pytest.raises(InvalidArgumentError, match="z_max"):
        octree_voxels(room, z_max="roof")
    with pytest.raises(InvalidArgumentError, match="max_voxels"):
        octree_voxels(room, max_voxels=0)


def test_the_notebook_scene_is_drawn_offline(browser, room, tmp_path):
    fragment = room._repr_html_()
    assert fragment.startswith("<iframe srcdoc=") and "__VISER_EMBED_DATA__" in fragment
    tab = Page(browser, content=f"<html><body style='margin:0'>{fragment}</body></html>")
    png, n = tab.drawn()
    keep("inline-room", png)
    assert n >= 2000, f"the scene is not drawn: {n} pixels of the height ramp"
    assert tab.refused == [], f"the page asked for addresses: {tab.refused}"

    path = room.save_html(tmp_path / "room.html", z_max=None)
    text = path.read_text()
    assert text.lstrip().lower().startswith("<!doctype html") and "__VISER_EMBED_DATA__" in text
    assert [p.name for p in tmp_path.iterdir()] == ["room.html"]  # no temporary file left



def test_render_writes_the_scene_and_refuses_png_options_for_it(room, tmp_path, capsys):
    from occmap.cli import main
    from occmap.io.octomap import write_bt

    bt = write_bt(room, tmp_path / "room.bt")
    out = tmp_path / "room.html"
    assert main(["render", str(bt), "-o", str(out), "--max-voxels", "500", "--no-cut"]) == 0
    assert "__VISER_EMBED_DATA__" in out.read_text()
    for extra, word in ((["--slice", "1.0"], "--slice"), (["--pixel", "0.2"], "--pixel")):
        assert main(["render", str(bt), "-o", str(tmp_path / "x.html"), *extra]) == 2
        assert word in capsys.readouterr().err
    assert main(["render", str(bt), "-o", str(tmp_path / "x.png"), "--max-voxels", "10"]) == 2
    assert "--max-voxels" in capsys.readouterr().err
    assert not (tmp_path / "x.html").exists() and not (tmp_path / "x.png").exists()
