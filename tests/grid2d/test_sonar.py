"""SonarModel / integrate_sonar: cone geometry, angular weighting, max-range readings, real data."""

from __future__ import annotations

import math

import numpy as np
import pytest

from occmap.errors import InvalidArgumentError, ShapeError
from occmap.grid2d import OccupancyGrid2D, SonarModel, logit


def one_reading(r, max_range=5.0, model=SonarModel()):
    g = OccupancyGrid2D(0.05, size=(6.0, 6.0), origin=(-3.0, -3.0))
    counts = g.integrate_sonar((0.0, 0.0, 0.0), [r], [0.0], max_range=max_range, model=model)
    return g, counts


def test_cone_is_free_before_the_arc_and_occupied_on_it():
    g, counts = one_reading(2.0)
    assert counts == {"scans": 1, "beams": 1, "dropped": 0, "max_range": 0}
    v = lambda x, y: g.value_at([[x, y]])[0]  # noqa: E731
    assert v(1.0125, 0.0125) < 0 and v(1.9875, 0.0125) > 0  # on the axis: free, then the arc
    assert math.isnan(v(2.5, 0.0))  # beyond the arc: untouched
    assert math.isnan(v(1.0, 0.3))  # 16.7° off the axis, outside the 15° cone
    # the axis speaks loudest: full weight on it, less towards the rim
    cx, cy = g.cell_to_world(g.world_to_cell([[1.0125, 0.0125]]))[0]  # the weight uses the cell centre
    assert v(1.0125, 0.0125) == pytest.approx(logit(0.4) * (1 - (math.atan2(cy, cx) / math.radians(7.5)) ** 2), rel=1e-5)
    assert 0 > v(1.0, 0.11) > v(1.0125, 0.0125)


def test_no_echo_clears_the_cone_up_to_max_range_and_marks_nothing():
    g, counts = one_reading(5.11, max_range=2.5)
    assert counts["max_range"] == 1
    lo = g.log_odds[g.observed]
    assert (lo < 0).all() and lo.size > 100
    assert math.isnan(g.value_at([[2.6, 0.0]])[0])


def test_invalid_readings_and_arguments():
    g = OccupancyGrid2D(0.1, size=(4.0, 4.0), origin=(-2.0, -2.0))
    counts = g.integrate_sonar(np.zeros((1, 3)), [[np.nan, -1.0, 1.0]], [0.0, 1.0, 2.0], max_range=3.0)
    assert counts["dropped"] == 2 and counts["beams"] == 1
    with pytest.raises(ShapeError):
        g.integrate_sonar(np.zeros((1, 3)), [[1.0, 1.0]], [0.0], max_range=3.0)
    with pytest.raises(InvalidArgumentError):
        SonarModel(beam_width=0.0)


def test_shared_sonar_ring_maps_its_corridor(data_dir):
    """The shared 8-sonar data set: the robot drives a corridor; both corridor walls appear as
    occupied cells on either side of its path."""
    from occmap.io.sonar import read_sonar_ring

    log = read_sonar_ring(data_dir / "sonar")
    assert log.ranges.shape == (413, 8) and log.max_range == pytest.approx(5.11)
    g = OccupancyGrid2D(0.1, size=(30.0, 15.0), origin=(-6.0, -10.0))
    g.integrate_sonar(log.poses, log.ranges, log.bearings, max_range=log.max_range,
                      model=SonarModel(beam_width=math.radians(20), arc=0.2))
    ml = g.maximum_likelihood()
    path = log.poses[(log.poses[:, 0] > 1.0) & (log.poses[:, 0] < 8.0)]  # the straight corridor part
    y = np.median(path[:, 1])
    column = ml[:, g.world_to_cell([[4.0, y]])[0, 1]]
    rows = np.flatnonzero(column == 1)
    centre = g.world_to_cell([[4.0, y]])[0, 0]
    assert (rows > centre).any() and (rows < centre).any()  # a wall on each side
    assert column[centre] == 0  # and free where the robot drove
