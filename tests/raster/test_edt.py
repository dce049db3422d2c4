"""occmap.raster.edt: exact Euclidean distance transform against brute force and scipy."""

import numpy as np
import pytest

from occmap.raster.edt import bounded_distance, distance_transform, squared_distance_cells
from occmap.errors import InvalidArgumentError, ShapeError

ndimage = pytest.importorskip("scipy.ndimage")


def brute_force_sq(mask):
    H, W = mask.shape
    obs = np.argwhere(mask)
    out = np.full((H, W), np.inf)
    if len(obs) == 0:
        return out
    yy, xx = np.mgrid[0:H, 0:W]
    for oy, ox in obs:
        np.minimum(out, (yy - oy) ** 2 + (xx - ox) ** 2, out=out)
    return out


@pytest.mark.parametrize("parallel", [False, True])
@pytest.mark.parametrize("shape", [(1, 1), (1, 9), (9, 1), (7, 5), (23, 41)])
@pytest.mark.parametrize("density", [0.0, 0.02, 0.3, 1.0])
def test_matches_brute_force(shape, density, parallel):
    rng = np.random.default_rng(hash((shape, density)) % 2**32)
    mask = rng.random(shape) < density
    d2 = squared_distance_cells(mask, parallel=parallel)
    assert d2.dtype == np.float64 and d2.shape == shape
    np.testing.assert_array_equal(d2, brute_force_sq(mask))


def test_single_obstacle_and_corners():
    mask = np.zeros((6, 8), bool)
    mask[5, 7] = True
    d2 = squared_distance_cells(mask)
    assert d2[0, 0] == 5**2 + 7**2
    assert d2[5, 7] == 0


@pytest.mark.parametrize("parallel", [False, True])
def test_matches_scipy_on_random_masks(parallel):
    rng = np.random.default_rng(7)
    for shape, density in [((300, 211), 0.001), ((257, 300), 0.05), ((64, 640), 0.5), ((200, 200), 0.999)]:
        mask = rng.random(shape) < density
        ref = ndimage.distance_transform_edt(~mask)
        np.testing.assert_array_equal(squared_distance_cells(mask, parallel=parallel), np.rint(ref**2))
        np.testing.assert_allclose(distance_transform(mask, 0.05, parallel=parallel), ref * 0.05, rtol=1e-15)


def test_empty_and_full_masks():
    assert np.isinf(squared_distance_cells(np.zeros((40, 30), bool))).all()
    assert np.isinf(distance_transform(np.zeros((300, 300), bool), 0.1)).all()
    assert (squared_distance_cells(np.ones((40, 30), bool)) == 0).all()
    assert squared_distance_cells(np.zeros((0, 5), bool)).shape == (0, 5)


def test_non_bool_mask_and_bad_input():
    m = np.zeros((4, 4), np.uint8)
    m[1, 2] = 3
    np.testing.assert_array_equal(squared_distance_cells(m), brute_force_sq(m != 0))
    with pytest.raises(ShapeError):
        squared_distance_cells(np.zeros(5, bool))
    with pytest.raises(InvalidArgumentError):
        distance_transform(np.zeros((3, 3), bool), resolution=0.0)


@pytest.mark.parametrize("limit", [0.05, 0.2, 0.37, 5.0])
@pytest.mark.parametrize("density", [0.0, 0.01, 0.3])
def test_bounded_distance_is_the_transform_clamped(limit, density):
    rng = np.random.default_rng(int(limit * 100) + int(density * 1000))
    mask = rng.random((37, 53)) < density
    expected = np.minimum(distance_transform(mask, 0.05), limit) if mask.any() else np.full(mask.shape, limit)
    np.testing.assert_array_equal(bounded_distance(mask, 0.05, limit), expected)


@pytest.mark.parametrize("limit", [0.1, 0.3, 0.4])
def test_bounded_distance_on_blobs_and_the_edges(limit):
    """Solid regions (inner obstacles only get 0: their border ones stamp), obstacles on and near
    every edge (the bounds-checked stamps), a limit that is a whole number of cells (0.3 / 0.1
    rounds up to 4 cells)."""
    rng = np.random.default_rng(7)
    mask = np.zeros((41, 58), bool)
    mask[5:14, 9:30] = True
    mask[20:41, 40:58] = True
    mask[0, ::7] = mask[:, 0] = mask[-1, 3] = mask[2, -2] = True
    mask |= rng.random(mask.shape) < 0.02
    expected = np.minimum(distance_transform(mask, 0.1), limit)
    np.testing.assert_array_equal(bounded_distance(mask, 0.1, limit), expected)
