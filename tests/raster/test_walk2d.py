"""occmap.raster.walk2d, the one 2D walk: exact cell sets, order and robustness (Amanatides & Woo),
where a walk is in a rectangle, and the miss walk over a rectangle of flat arrays."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from occmap.errors import InvalidArgumentError, NonFiniteError, ShapeError
from occmap.raster.walk2d import dda_init, dda_span, dda_step, miss_walk, traverse_2d


def segment_hits_cell(a, b, iy, ix, res, origin, tol=1e-9):
    """Liang–Barsky clip of segment a→b against the (slightly grown) cell square."""
    lo = np.array([origin[0] + ix * res, origin[1] + iy * res]) - tol
    hi = lo + res + 2 * tol
    d = b - a
    t0, t1 = 0.0, 1.0
    for k in range(2):
        if d[k] == 0.0:
            if not lo[k] <= a[k] <= hi[k]:
                return False
            continue
        with np.errstate(over="ignore"):  # a subnormal d gives ±inf, which clips correctly
            ta, tb = (lo[k] - a[k]) / d[k], (hi[k] - a[k]) / d[k]
        t0, t1 = max(t0, min(ta, tb)), min(t1, max(ta, tb))
    return t0 <= t1


def check_walk(a, b, res, origin):
    iy, ix, off = traverse_2d(a, b, res, origin)
    cells = np.stack([iy, ix], 1)
    # cell index = floor((x − o) · (1/res)), OctoMap's arithmetic (not floor((x − o) / res))
    start = np.floor((a - origin) * (1.0 / res)).astype(int)[::-1]
    end = np.floor((b - origin) * (1.0 / res)).astype(int)[::-1]
    assert off.tolist() == [0, len(cells)]
    assert (cells[0] == start).all() and (cells[-1] == end).all()
    assert len(cells) == abs(end - start).sum() + 1  # the exact number of cells a segment crosses
    steps = np.abs(np.diff(cells, axis=0)).sum(1)
    assert (steps == 1).all()  # 4-connected, no repeats, no skips
    assert len({tuple(c) for c in cells}) == len(cells)
    for c in cells:
        assert segment_hits_cell(a, b, c[0], c[1], res, origin)
    return cells


coord = st.floats(-50.0, 50.0, allow_nan=False, allow_infinity=False)


@settings(max_examples=300, deadline=None)
@given(coord, coord, coord, coord, st.sampled_from([0.05, 0.1, 0.37, 1.0]))
def test_random_segments_visit_exactly_the_crossed_cells(x0, y0, x1, y1, res):
    check_walk(np.array([x0, y0]), np.array([x1, y1]), res, np.array([-3.0, 1.5]))


def test_hand_computed_walk():
    # slope 1/3 from (0.05, 0.05) to (0.95, 0.35) at 0.1 m crosses y = 0.1, 0.2 and 0.3 exactly at
    # the corners x = 0.2, 0.5 and 0.8: x steps first at each
    iy, ix, _ = traverse_2d([0.05, 0.05], [0.95, 0.35], 0.1)
    assert list(zip(iy.tolist(), ix.tolist())) == [
        (0, 0), (0, 1), (0, 2), (1, 2), (1, 3), (1, 4), (1, 5), (2, 5), (2, 6), (2, 7), (2, 8), (3, 8), (3, 9)
    ]


@pytest.mark.parametrize(
    "a, b, expected",
    [
        ([0.5, 0.5], [3.5, 0.5], [(0, 0), (0, 1), (0, 2), (0, 3)]),  # along +x
        ([0.5, 0.5], [0.5, -2.5], [(0, 0), (-1, 0), (-2, 0), (-3, 0)]),  # along −y into negative cells
        ([0.5, 0.5], [0.7, 0.9], [(0, 0)]),  # inside one cell
        ([0.5, 0.5], [0.5, 0.5], [(0, 0)]),  # zero length
        ([1.0, 1.0], [3.0, 1.0], [(1, 1), (1, 2), (1, 3)]),  # along a grid line: the cells above it
    ],
)
def test_axis_aligned_and_degenerate(a, b, expected):
    iy, ix, _ = traverse_2d(a, b, 1.0)
    assert list(zip(iy.tolist(), ix.tolist())) == expected


def test_batched_equals_one_by_one(rng):
    a = rng.uniform(-10, 10, (200, 2))
    b = a + rng.uniform(-5, 5, (200, 2))
    iy, ix, off = traverse_2d(a, b, 0.05)
    assert off[0] == 0 and off[-1] == len(iy) and (np.diff(off) >= 1).all()
    for i in (0, 17, 199):
        jy, jx, _ = traverse_2d(a[i], b[i], 0.05)
        assert (iy[off[i] : off[i + 1]] == jy).all() and (ix[off[i] : off[i + 1]] == jx).all()


def test_long_rays_far_from_the_origin_end_in_their_end_cell():
    a = np.array([12345.678, -9876.543])
    for angle in np.linspace(0, 2 * np.pi, 37):
        b = a + 30.0 * np.array([np.cos(angle), np.sin(angle)])
        check_walk(a, b, 0.05, np.array([0.0, 0.0]))


def test_bad_input():
    with pytest.raises(ShapeError):
        traverse_2d([0, 0, 0], [1, 1, 1], 0.1)
    with pytest.raises(NonFiniteError):
        traverse_2d([0, np.nan], [1, 1], 0.1)
    with pytest.raises(InvalidArgumentError):
        traverse_2d([0, 0], [1, 1], 0.0)


@settings(max_examples=300, deadline=None)
@given(coord, coord, coord, coord, st.sampled_from([0.05, 0.37, 1.0]),
       st.integers(-60, 60), st.integers(0, 80), st.integers(-60, 60), st.integers(0, 80))
def test_span_in_a_rectangle_is_where_the_walk_is_there(x0, y0, x1, y1, res, x_lo, w, y_lo, h):
    """dda_span finds, without walking, the steps of the walk inside a rectangle and the walk's
    exact state at the first of them (the additions of a walk and the products agree bit for bit)."""
    origin = (-3.0, 1.5)
    steps, state = dda_init(x0, y0, x1, y1, origin[0], origin[1], 1.0 / res)
    s_in, s_out, jx, jy = dda_span(state, x_lo, x_lo + w, y_lo, y_lo + h)
    walked = [state]
    for _ in range(steps):
        walked.append(dda_step(walked[-1]))
    inside = [s for s, w_ in enumerate(walked) if x_lo <= w_[0] < x_lo + w and y_lo <= w_[1] < y_lo + h]
    if not inside:
        assert s_out <= s_in
        return
    assert (s_in, s_out) == (inside[0], inside[-1] + 1)
    assert inside == list(range(s_in, s_out))  # one run
    ix, iy, _, _, sx, sy, t_max_x, t_max_y, t_dx, t_dy = state
    at = walked[s_in]
    assert (at[0], at[1]) == (ix + sx * jx, iy + sy * jy)
    if jx:
        assert at[6] == t_max_x + jx * t_dx
    if jy:
        assert at[7] == t_max_y + jy * t_dy


@settings(max_examples=300, deadline=None)
@given(coord, coord, coord, coord, st.sampled_from([0.05, 0.37, 1.0]),
       st.integers(-60, 60), st.integers(1, 80), st.integers(-60, 60), st.integers(1, 80), st.integers(1, 3))
def test_miss_walk_updates_the_walks_cells_in_a_rectangle_once(x0, y0, x1, y1, res, x_lo, w, y_lo, h, cs):
    """miss_walk on a rectangle laid out in flat arrays with any strides (here: ``cs`` slots a
    cell, rows padded) frees exactly the walk's cells there, end cell excluded, each once."""
    origin = (-3.0, 1.5)
    rs = w * cs + 5
    base = 1 - (y_lo * rs + x_lo * cs)
    n = 2 + (h - 1) * rs + (w - 1) * cs + 1
    L = np.zeros(n, dtype=np.float32)
    S = np.zeros(n, dtype=np.uint16)
    steps, state = dda_init(x0, y0, x1, y1, origin[0], origin[1], 1.0 / res)
    got = miss_walk(L, S, base, cs, rs, steps, state, x_lo, x_lo + w, y_lo, y_lo + h, 3, -0.4, -2.0, 3.5)
    iy, ix, _ = traverse_2d([x0, y0], [x1, y1], res, origin)
    inside = [(y, x) for y, x in zip(iy[:-1].tolist(), ix[:-1].tolist()) if x_lo <= x < x_lo + w and y_lo <= y < y_lo + h]
    expected = np.zeros(n, dtype=bool)
    for y, x in inside:
        expected[base + y * rs + x * cs] = True
    assert got == len(inside)
    np.testing.assert_array_equal(S != 0, expected)
    assert (S[expected] == 6).all() and (L[expected] == np.float32(-0.4)).all()
    assert miss_walk(L, S, base, cs, rs, steps, state, x_lo, x_lo + w, y_lo, y_lo + h, 3, -0.4, -2.0, 3.5) == 0
