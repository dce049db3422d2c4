"""Labelled figures: what is drawn where (read back from the PNG at the world point's pixel), the
crop, the colour keys, the indoor height cut, and bad input."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

from occmap.errors import InvalidArgumentError, ShapeError
from occmap.grid2d import OccupancyGrid2D
from occmap.octree import OcTree
from occmap.octree import views
from occmap.viz import figure, maps


def drawn(fig):
    """The figure as an RGB array and a function from world (x, y) on its map axes to that pixel."""
    rgb = np.asarray(Image.open(io.BytesIO(figure.png_bytes(fig))).convert("RGB"))
    ax = fig.axes[0]

    def at(x, y):
        u, v = ax.transData.transform((x, y))
        return rgb[rgb.shape[0] - 1 - int(v), int(u)]

    return rgb, at


def close(colour, expected, tol=12):
    return np.abs(np.asarray(colour, float) - 255 * np.asarray(expected, float)).max() <= tol


def test_nice_length_is_one_two_or_five_times_a_power_of_ten():
    assert figure.nice_length(50.0) == 10.0
    assert figure.nice_length(12.0) == 2.0
    assert figure.nice_length(30.0) == 5.0
    assert figure.nice_length(0.7) == pytest.approx(0.1)


def test_known_box_keeps_the_walls_and_drops_far_beams_and_specks():
    known = np.zeros((400, 400), bool)
    known[10:390, 10:390] = True  # beams through windows reach far out
    occ = np.zeros_like(known)
    occ[150:250, 150] = occ[150:250, 249] = occ[150, 150:250] = occ[249, 150:250] = True  # a room
    occ[380, 20] = True  # one stray reading far out
    rows, cols = figure.known_box(known, occ, margin=10)
    assert (rows.start, rows.stop, cols.start, cols.stop) == (140, 260, 140, 260)
    rows, cols = figure.known_box(known, None, margin=10)  # no walls: every known cell
    assert (rows.start, rows.stop, cols.start, cols.stop) == (10, 390, 10, 390)
    rows, cols = figure.known_box(np.zeros((3, 4), bool))
    assert (rows.stop, cols.stop) == (3, 4)


def test_grid_figure_draws_free_white_occupied_black_unknown_blue_where_they_are(tmp_path):
    g = OccupancyGrid2D(0.1, size=(6.0, 4.0), origin=(-1.0, -2.0))
    pose = (0.05, 0.05, 0.0)
    for _ in range(3):
        g.insert_scan(pose, [2.0, 2.0], [0.0, np.pi / 2])  # hits at (2.05, 0.05) and (0.05, 2.05)
    fig = g.figure("two beams", crop=False)
    rgb, at = drawn(fig)
    assert at(1.0, 0.05).min() > 225  # three misses: p = 0.23, near white
    assert at(2.05, 0.05).max() < 60  # three hits: p = 0.93, dark
    assert close(at(4.5, -1.5), figure.UNKNOWN)
    ax = fig.axes[0]
    assert ax.get_xlim() == pytest.approx((-1.0, 5.0)) and ax.get_ylim() == pytest.approx((-2.0, 2.0))
    assert ax.get_xlabel() == "x [m]" and ax.get_ylabel() == "y [m]" and "two beams" in ax.get_title()
    assert "occupancy probability" in fig.axes[1].get_ylabel()  # the colour key
    # cropped (default): around the hits, never past the observed cells
    lo, hi = fig.axes[0].get_xlim(), g.figure().axes[0].get_xlim()
    assert hi[0] >= lo[0] and hi[1] < lo[1]
    path = g.save_png(tmp_path / "g.png")
    assert Image.open(path).format == "PNG" and g._repr_png_()[:8] == b"\x89PNG\r\n\x1a\n"
    # a box in metres: the cells it touches, the same picture there (two maps of one place drawn alike)
    boxed = g.figure("box", crop=(0.52, -0.31, 2.33, 1.0))
    assert boxed.axes[0].get_xlim() == pytest.approx((0.5, 2.4)) and boxed.axes[0].get_ylim() == pytest.approx((-0.4, 1.0))
    _, at_box = drawn(boxed)
    assert at_box(2.05, 0.05).max() < 60 and at_box(1.0, 0.05).min() > 225
    for bad in ((0, 0, 0, 1), (np.nan, 0, 1, 1), (10.0, 10.0, 11.0, 11.0), (1, 2)):
        with pytest.raises(InvalidArgumentError, match="crop"):
            g.figure(crop=bad)


def test_grid_figure_refuses_bad_input():
    with pytest.raises(ShapeError):
        maps.grid_figure(np.zeros((2, 2)), np.ones((3, 3), bool), (0, 0), 0.1)
    with pytest.raises(InvalidArgumentError, match=r"probability\[0, 1\] = 1.5"):
        maps.grid_figure(np.array([[0.5, 1.5]]), np.ones((1, 2), bool), (0, 0), 0.1)
    fig = maps.grid_figure(np.array([[np.nan, 0.0]]), np.ones((1, 2), bool), (0, 0), 0.1, crop=False)
    _, at = drawn(fig)
    assert close(at(0.05, 0.05), figure.UNKNOWN)  # NaN is unknown


def room(ceiling: float = 2.5, res: float = 0.1) -> OcTree:
    """A 4 m × 4 m room: floor at z 0, walls, a ceiling at ``ceiling``, free inside; and a 1 m
    high box on the floor at (1, 1)."""
    tree = OcTree(res)
    c = np.arange(0.05, 4.0, res)
    zs = np.arange(0.05, ceiling, res)
    X, Y = np.meshgrid(c, c, indexing="ij")
    floor = np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, 0.05)])
    top = np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, ceiling + 0.05)])
    edge = (X == c[0]) | (X == c[-1]) | (Y == c[0]) | (Y == c[-1])
    walls = np.concatenate([np.column_stack([X[edge], Y[edge], np.full(edge.sum(), z)]) for z in zs])
    inside = np.concatenate([np.column_stack([X[~edge], Y[~edge], np.full((~edge).sum(), z)]) for z in zs[1:]])
    tree.update_nodes(inside, False)
    box = np.array([[x, y, z] for x in (0.95, 1.05) for y in (0.95, 1.05) for z in np.arange(0.15, 1.0, res)])
    for part in (floor, top, walls, box):
        tree.update_nodes(part, True)
    return tree


def test_ceiling_is_found_indoors_and_not_in_a_town():
    assert views.ceiling(room(2.5)) == pytest.approx(2.5)
    town = OcTree(0.5)
    rng = np.random.default_rng(3)
    for x, y, h in zip(rng.uniform(0, 100, 30), rng.uniform(0, 100, 30), rng.uniform(5, 40, 30)):
        z = np.arange(0.25, h, 0.5)
        town.update_nodes(np.column_stack([np.full_like(z, x), np.full_like(z, y), z]), True)  # towers
    ground = np.column_stack([np.repeat(np.arange(0.25, 100, 0.5), 200), np.tile(np.arange(0.25, 100, 0.5), 200),
                              np.full(40000, 0.25)])
    town.update_nodes(ground, True)
    assert views.ceiling(town) is None


def test_height_figure_cuts_under_the_ceiling_and_keys_heights_in_metres():
    tree = room(2.5)
    fig = maps.height_figure(tree)
    _, at = drawn(fig)
    key = fig.axes[1]
    assert "height" in key.get_ylabel() and "[m]" in key.get_ylabel()
    assert "below z = 2.50 m" in fig.axes[0].get_title()
    lo, hi = key.get_ylim()
    assert hi == pytest.approx(2.5, abs=0.11)  # the walls' top under the ceiling
    # the floor and the box differ in colour: seen from under the ceiling
    assert np.abs(at(2.5, 2.5).astype(int) - at(1.0, 1.0).astype(int)).max() > 40
    whole = maps.height_figure(tree, z_max=None)
    _, at_whole = drawn(whole)
    assert np.abs(at_whole(2.5, 2.5).astype(int) - at_whole(1.0, 1.0).astype(int)).max() < 10  # all ceiling


def test_slice_figure_shows_walls_free_inside_and_unknown_outside(tmp_path):
    tree = room(2.5)
    fig = maps.slice_figure(tree, 1.5)
    _, at = drawn(fig)
    assert at(0.05, 2.0).max() < 60  # a wall
    assert close(at(2.0, 2.0), figure.FREE)
    assert "z = 1.5 m" in fig.axes[0].get_title()
    tree.update_nodes([[6.05, 6.05, 1.55]], True)  # widen the map: a known voxel outside the room
    _, at = drawn(maps.slice_figure(tree, 1.5))
    assert close(at(5.0, 2.0), figure.UNKNOWN)
    assert tree.save_slice_png(tmp_path / "s.png", 1.5).exists() and tree._repr_png_()[:4] == b"\x89PNG"


def test_track_figure_draws_the_estimate_over_the_map_and_names_every_line():
    from occmap.viz import localization

    occ = np.zeros((100, 200), bool)
    occ[0, :] = occ[-1, :] = True
    free = ~occ
    free[:, 150:] = False  # the east end was never seen
    xs = np.linspace(1.0, 8.0, 50)
    est = np.column_stack([xs, np.full(50, 2.5), np.zeros(50)])
    odo = est + [0.0, 0.5, 0.0]
    fig = localization.track_figure(occ, free, (0.0, 0.0), 0.05, est, odo, est[::5], title="corridor")
    rgb, at = drawn(fig)
    u, v = fig.axes[0].transData.transform((4.0, 2.5))
    r, c = rgb.shape[0] - 1 - int(v), int(u)
    near = rgb[r - 2:r + 3, c - 2:c + 3].reshape(-1, 3).astype(int)
    assert ((near[:, 2] > 150) & (near[:, 0] < 120)).any()  # the estimate, blue, where it was
    assert at(4.0, 0.02).max() < 80  # the southern wall
    assert close(at(9.0, 4.0), figure.UNKNOWN)
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert labels == ["occupied", "free", "unknown", "odometry (from the first estimate)", "reference poses",
                      "estimate", "start"]


def test_error_figure_labels_units_and_keeps_a_spike_from_flattening_the_rest():
    from occmap.viz import localization

    d = np.linspace(0, 100, 1000)
    pe = np.full(1000, 0.05)
    pe[500] = 50.0  # one spike
    fig = localization.error_figure(d, [("filter", pe, np.radians(np.full(1000, 1.0)))], "t")
    top, bottom = fig.axes[:2]
    assert top.get_ylabel() == "position error [m]" and bottom.get_ylabel() == "heading error [°]"
    assert bottom.get_xlabel() == "distance travelled [m]"
    assert top.get_ylim()[1] == pytest.approx(0.055) and bottom.get_ylim()[1] == pytest.approx(1.1)
