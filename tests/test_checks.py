"""The one argument rule: NumPy scalars and Python numbers accepted, bools, NaN and inf rejected,
errors naming the argument and the value."""

from __future__ import annotations

import math

import numpy as np
import pytest

from occmap import LocalMap, OccupancyGrid2D, OcTree, checks
from occmap.errors import InvalidArgumentError, OccmapError


@pytest.mark.parametrize("value", [0.1, np.float32(0.1), np.float64(0.1), np.float16(0.1), np.array(0.1), 1, np.int64(1),
                                   np.uint8(1)])
def test_numbers_of_every_kind_are_accepted_at_their_exact_value(value):
    got = checks.resolution(value)
    assert type(got) is float and got == float(np.asarray(value))
    assert checks.positive("x", value) == got and checks.finite("x", value) == got


def test_float32_is_taken_exactly():
    assert checks.probability("p", np.float32(0.1)) == 0.10000000149011612


@pytest.mark.parametrize("value", [True, False, np.bool_(True), math.nan, np.float32("nan"), math.inf, -np.inf, "0.1",
                                   None, [0.1], np.array([0.1]), 1 + 0j])
@pytest.mark.parametrize("check", [checks.finite, checks.positive, checks.non_negative, checks.probability,
                                   checks.fraction])
def test_non_numbers_bools_and_non_finite_are_rejected_naming_argument_and_value(check, value):
    with pytest.raises(InvalidArgumentError) as e:
        check("sigma_hit", value)
    assert str(e.value).startswith("sigma_hit must be ") and f"got {value!r}" in str(e.value)
    assert isinstance(e.value, OccmapError) and isinstance(e.value, ValueError)


def test_ranges():
    assert checks.non_negative("x", 0) == 0.0
    for bad in (0, -1e-300, np.float32(-1)):
        with pytest.raises(InvalidArgumentError, match="resolution must be a positive finite number of metres"):
            checks.resolution(bad)
    with pytest.raises(InvalidArgumentError, match="non-negative"):
        checks.non_negative("x", -0.5)
    for bad in (0, 1, np.float32(1.0), -0.1):
        with pytest.raises(InvalidArgumentError, match="strictly between 0 and 1"):
            checks.probability("prob_hit", bad)
    assert checks.fraction("f", 0) == 0.0 and checks.fraction("f", 1) == 1.0
    with pytest.raises(InvalidArgumentError, match=r"\(0, 1\]"):
        checks.fraction("f", 0.0, zero=False)
    with pytest.raises(InvalidArgumentError):
        checks.fraction("f", 1.5)


@pytest.mark.parametrize("value", [3, np.int64(3), np.uint16(3), np.int8(3), np.array(3)])
def test_counts_accept_python_and_numpy_integers(value):
    got = checks.count("n_particles", value)
    assert type(got) is int and got == 3


@pytest.mark.parametrize("value", [True, np.bool_(True), 3.0, np.float32(3), "3", None, math.nan])
def test_counts_reject_bools_floats_and_the_rest(value):
    with pytest.raises(InvalidArgumentError, match=r"n_particles must be an integer ≥ 1, got"):
        checks.count("n_particles", value)


def test_count_minimum():
    assert checks.count("n", 0, minimum=0) == 0
    with pytest.raises(InvalidArgumentError, match="n must be an integer ≥ 1, got 0"):
        checks.count("n", 0)


MAPS = {
    "OccupancyGrid2D": OccupancyGrid2D,
    "OcTree": OcTree,
    "LocalMap": lambda **kw: LocalMap(size=(2.0, 2.0), **kw),
}


@pytest.mark.parametrize("make", MAPS.values(), ids=MAPS.keys())
def test_the_three_maps_follow_the_rule(make):
    """The maps check their arguments by this module: a float32 resolution is a resolution, a bool
    or NaN is refused with the argument's name."""
    assert make(resolution=np.float32(0.1)).resolution == 0.10000000149011612
    for bad in (True, math.nan):
        with pytest.raises(InvalidArgumentError, match="resolution"):
            make(resolution=bad)
    with pytest.raises(InvalidArgumentError, match="occupied_threshold"):
        make(resolution=0.1, occupied_threshold=np.nan)
    assert make(resolution=0.1, occupied_threshold=np.float32(0.6)).occupied_threshold == float(np.float32(0.6))
