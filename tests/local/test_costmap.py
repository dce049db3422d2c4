"""occmap.local.costmap: Nav2 cost values, exact inflation, footprints."""

from __future__ import annotations

import math

import numpy as np
import pytest

from occmap.errors import InvalidArgumentError, NonFiniteError, ShapeError
from occmap.local import LocalMap, inflate, inscribed_radius, validate_footprint
from occmap.local.costmap import circumscribed_radius, cost_table


def brute_force_costmap(lethal, unknown, res, r_infl, k, r_ins):
    """Nav2's costs from the brute-force distance of every cell to every lethal cell."""
    H, W = lethal.shape
    obs = np.argwhere(lethal)
    d = np.full((H, W), np.inf)
    yy, xx = np.mgrid[0:H, 0:W]
    for oy, ox in obs:
        np.minimum(d, np.sqrt((yy - oy) ** 2 + (xx - ox) ** 2) * res, out=d)
    out = np.zeros((H, W), np.uint8)
    for (y, x), dist in np.ndenumerate(d):
        if lethal[y, x]:
            out[y, x] = 254
        elif unknown[y, x]:
            out[y, x] = 253 if dist <= r_ins + 1e-9 else 255
        elif dist <= r_ins + 1e-9:
            out[y, x] = 253
        elif dist <= r_infl + 1e-9:
            out[y, x] = int(252 * math.exp(-k * (dist - r_ins)))
        else:
            out[y, x] = 0
    return out


@pytest.mark.parametrize("res, r_infl, k, r_ins", [
    (0.1, 0.55, 10.0, 0.1),  # Nav2's defaults
    (0.05, 0.55, 10.0, 0.22),
    (0.05, 1.0, 3.0, 0.0),
    (0.02, 0.9, 5.0, 0.3),  # R = 45 cells: the lower-envelope row pass
])
@pytest.mark.parametrize("density", [0.0, 0.003, 0.03, 0.3])
def test_inflation_equals_brute_force_exactly(res, r_infl, k, r_ins, density):
    rng = np.random.default_rng(int(density * 1000) + int(res * 100))
    H, W = 61, 83
    lethal = rng.random((H, W)) < density
    unknown = (rng.random((H, W)) < 0.2) & ~lethal
    got = inflate(lethal, unknown, res, r_infl, k, r_ins)
    np.testing.assert_array_equal(got, brute_force_costmap(lethal, unknown, res, r_infl, k, r_ins))


def test_nav2_values_around_one_obstacle():
    lethal = np.zeros((21, 21), bool)
    lethal[10, 10] = True
    c = inflate(lethal, None, 0.1, 0.55, 10.0, 0.1)
    assert c[10, 10] == 254
    assert c[10, 11] == 253 and c[11, 10] == 253  # 0.1 m: inscribed
    assert c[11, 11] == int(252 * math.exp(-10 * (math.sqrt(2) * 0.1 - 0.1)))
    assert c[10, 13] == int(252 * math.exp(-10 * 0.2)) == 34
    assert c[10, 15] == int(252 * math.exp(-10 * 0.4))  # 0.5 m ≤ 0.55: inflated
    assert c[10, 16] == 0  # 0.6 m: beyond the inflation radius
    assert (c[0] == 0).all()
    table = cost_table(0.1, 0.55, 10.0, 0.1)
    assert table[0] == 254 and table[1] == 253 and table[-1] == 0


def test_local_map_costmap_equals_inflate_of_its_classes():
    lm = LocalMap((8.0, 6.0), 0.05, footprint=[[0.25, 0.2], [-0.25, 0.2], [-0.25, -0.2], [0.25, -0.2]])
    assert lm.inflation.inscribed_radius == pytest.approx(0.2)
    rng = np.random.default_rng(2)
    lm.move_to(0.77, -0.4)
    angles = np.linspace(-math.pi, math.pi, 720, endpoint=False)
    for t in range(6):
        ranges = 2.0 + rng.uniform(-0.3, 0.3) + 0.5 * np.cos(4 * angles)
        lm.insert_scan([0.8, -0.4, 0.0], ranges, angles, stamp=0.1 * t, max_range=10.0)
    lo = lm.log_odds()
    lethal = np.nan_to_num(lo, nan=-np.inf) >= math.log(0.65 / 0.35)
    unknown = ~(np.nan_to_num(lo, nan=np.inf) < math.log(0.196 / 0.804)) & ~lethal
    cost, origin = lm.costmap()
    assert cost.dtype == np.uint8 and cost.shape == lm.shape
    np.testing.assert_array_equal(origin, lm.origin)
    np.testing.assert_array_equal(cost, inflate(lethal, unknown, 0.05, 0.55, 10.0, 0.2))
    assert {0, 253, 254, 255} <= set(np.unique(cost))


def test_footprints():
    rect = [[0.3, 0.2], [-0.2, 0.2], [-0.2, -0.2], [0.3, -0.2]]
    np.testing.assert_array_equal(validate_footprint(rect), np.array(rect))
    np.testing.assert_array_equal(validate_footprint(rect + [rect[0]]), np.array(rect))  # closed ring
    assert inscribed_radius(rect) == pytest.approx(0.2)
    assert circumscribed_radius(rect) == pytest.approx(math.hypot(0.3, 0.2))
    assert inscribed_radius(0.25) == 0.25
    validate_footprint([[0.3, 0.2], [-0.2, 0.2], [0.0, 0.0], [-0.2, -0.2], [0.3, -0.2]])  # concave is fine
    bad = {
        "cross": [[1, 1], [-1, -1], [1, -1], [-1, 1]],  # a bow tie
        "touch": [[0, 0], [2, 0], [2, 2], [1, 0], [0, 2]],  # a vertex on another edge
        "repeat": [[0, 0], [1, 0], [1, 0], [0, 1]],
        "flat": [[0, 0], [1, 0], [2, 0]],
        "fold": [[0, 0], [2, 0], [1, 0], [1, 1]],
    }
    for name, fp in bad.items():
        with pytest.raises(InvalidArgumentError, match="simple polygon"):
            validate_footprint(fp)
    with pytest.raises(ShapeError):
        validate_footprint([[0, 0], [1, 1]])
    with pytest.raises(NonFiniteError):
        validate_footprint([[0, 0], [1, np.nan], [0, 1]])
