"""Log-odds ↔ probability, and OctoMap's float32 log-odds (computed in float64)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from occmap.errors import InvalidArgumentError
from occmap.logodds import logit, logit32, occupancy_classes, probability

# OctoMap's parameters as it stores them: (float) log(p / (1 - p)) evaluated in double, written
# here as float32 bit patterns (checked against octomap-python below where it is installed)
OCTOMAP_LOGODDS = {0.7: 0x3F58E883, 0.4: 0xBECF991F, 0.1192: 0xC0000075, 0.971: 0x4060B4BA}


@pytest.mark.parametrize("p, bits", sorted(OCTOMAP_LOGODDS.items()))
def test_logit32_is_octomaps_float32(p, bits):
    v = logit32(p)
    assert v.dtype == np.float32 and int(v.view(np.uint32)) == bits
    assert float(v) == pytest.approx(math.log(p / (1 - p)), abs=1e-6)


def test_float32_arithmetic_would_differ():
    """Why logit32 computes in float64: the same formula in float32 misses OctoMap's value."""
    p32 = np.float32(0.7)
    in_float32 = np.float32(np.log(p32 / (np.float32(1) - p32)))
    assert in_float32 != logit32(0.7)


def test_octomap_python_agrees():
    octomap = pytest.importorskip("octomap")
    t = octomap.OcTree(0.1)
    got = (t.getProbHitLog(), t.getProbMissLog(), t.getClampingThresMinLog(), t.getClampingThresMaxLog())
    assert got == tuple(float(logit32(p)) for p in (0.7, 0.4, 0.1192, 0.971))


def test_round_trip_scalars_and_arrays():
    p = np.linspace(0.001, 0.999, 999)
    np.testing.assert_allclose(probability(logit(p)), p, rtol=0, atol=1e-15)
    for q in (0.5, 0.12, np.float32(0.7), 0.999999):
        assert probability(logit(q)) == pytest.approx(float(q), abs=1e-15)
    assert logit(0.5) == 0.0 and probability(0.0) == 0.5
    assert type(logit(0.7)) is float and type(probability(1.0)) is float
    assert probability(-1000.0) == 0.0 and probability(1000.0) == 1.0
    np.testing.assert_array_equal(probability(np.array([-1000.0, 1000.0], np.float32)), [0.0, 1.0])


@pytest.mark.parametrize("bad", [0.0, 1.0, -0.1, math.nan, True])
def test_scalar_probability_is_checked(bad):
    with pytest.raises(InvalidArgumentError, match="prob_hit must be a probability"):
        logit(bad, "prob_hit")


def test_occupancy_classes():
    l = np.array([[np.nan, -0.5, 0.0], [0.4, 0.41, np.inf]], np.float32)
    got = occupancy_classes(l, 0.4)
    assert got.dtype == np.int8 and got.tolist() == [[-1, 0, 0], [1, 1, 1]]
