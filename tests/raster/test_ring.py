"""occmap.raster.ring: circular-buffer indices against hand-derived values."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from occmap.raster.ring import slot, wrap, wrap_point


@pytest.mark.parametrize(
    "i, n, expected",
    [
        (0, 5, 0), (4, 5, 4),  # in range: unchanged
        (5, 5, 0), (9, 5, 4),  # one ring above
        (-1, 5, 4), (-5, 5, 0),  # one ring below
        (10, 5, 0), (12, 5, 2), (1003, 5, 3),  # many rings above
        (-6, 5, 4), (-11, 5, 4), (-1003, 5, 2),  # many rings below: −1003 = −201·5 + 2
        (7, 1, 0), (-7, 1, 0),  # a ring of one slot
        (2**40 + 3, 7, (2**40 + 3) % 7), (-(2**40) - 3, 7, (-(2**40) - 3) % 7),
    ],
)
def test_wrap_hand_values(i, n, expected):
    assert wrap(i, n) == expected


@given(st.integers(-10**12, 10**12), st.integers(1, 10**6))
def test_wrap_is_the_mathematical_modulo(i, n):
    assert wrap(i, n) == i % n


@pytest.mark.parametrize(
    "i, start, n, expected",
    [
        (0, 3, 8, 3), (4, 3, 8, 7), (5, 3, 8, 0), (7, 3, 8, 2),  # a window of 8 starting at slot 3
        (-1, 3, 8, 2), (-3, 3, 8, 0), (-4, 3, 8, 7),  # before the window (a move by −k cells)
        (8, 3, 8, 3), (21, 3, 8, 0), (-29, 3, 8, 6),  # whole rings away: (−29 + 3) mod 8 = 6
        (5, 0, 8, 5),  # start 0: slot = index
    ],
)
def test_slot_hand_values(i, start, n, expected):
    assert slot(i, start, n) == expected


@pytest.mark.parametrize("start, n, expected", [(0, 8, 8), (3, 8, 5), (7, 8, 1), (0, 1, 1)])
def test_wrap_point_splits_the_window_into_two_runs_of_slots(start, n, expected):
    p = wrap_point(start, n)
    assert p == expected
    assert [slot(i, start, n) for i in range(p)] == list(range(start, n))
    assert [slot(i, start, n) for i in range(p, n)] == list(range(start))
