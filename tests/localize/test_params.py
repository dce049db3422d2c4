"""LocalizationParams: AMCL's names and defaults, one place of validation, and the ways a
MonteCarloLocalizer takes it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from occmap.errors import InvalidArgumentError
from occmap.geometry.motion import OdometryMotionModel
from occmap.grid2d import OccupancyGrid2D
from occmap.io.mapserver import save_map
from occmap.localize import LocalizationParams, MonteCarloLocalizer


def test_defaults_are_amcls():
    p = LocalizationParams()
    assert (p.z_hit, p.z_rand, p.sigma_hit, p.laser_likelihood_max_dist, p.max_beams) == (0.95, 0.05, 0.2, 2.0, 60)
    assert (p.min_particles, p.max_particles, p.kld_err, p.kld_z) == (500, 5000, 0.01, 0.99)
    assert (p.recovery_alpha_slow, p.recovery_alpha_fast, p.laser_min_range) == (0.0, 0.0, 0.0)
    assert p.motion == OdometryMotionModel() and p.global_update_min_a == math.pi / 6


def test_numpy_scalars_are_accepted_and_normalised():
    p = LocalizationParams(n_particles=np.int64(300), sigma_hit=np.float32(0.25), max_beams=np.uint16(30),
                           motion=(0.1, 0.1, 0.1, 0.1), coast_motion=(0.01, 0.02, 0.03, 0.04),
                           sensor_offset=np.array([0.2, 0.0, np.float32(0.5)]))
    assert isinstance(p.coast_motion, OdometryMotionModel) and p.coast_motion.alphas == (0.01, 0.02, 0.03, 0.04)
    assert type(p.n_particles) is int and p.n_particles == 300 and type(p.max_beams) is int
    assert type(p.sigma_hit) is float and p.sigma_hit == float(np.float32(0.25))
    assert isinstance(p.motion, OdometryMotionModel) and p.motion.alphas == (0.1, 0.1, 0.1, 0.1)
    assert p.sensor_offset == (0.2, 0.0, 0.5) and all(type(v) is float for v in p.sensor_offset)


@pytest.mark.parametrize("changes, match", [
    (dict(n_particles=True), "n_particles must be an integer"),
    (dict(n_particles=100.0), "n_particles must be an integer"),
    (dict(sigma_hit=math.nan), "sigma_hit must be a positive finite number, got nan"),
    (dict(sigma_hit=0.0), "sigma_hit must be a positive"),
    (dict(laser_likelihood_max_dist=math.inf), "laser_likelihood_max_dist"),
    (dict(z_hit=False), "z_hit must be a non-negative"),
    (dict(z_hit=0.0, z_rand=0.0), "z_hit \\+ z_rand must be positive"),
    (dict(free_thresh=0.7), "free_thresh <= occupied_thresh"),
    (dict(occupied_thresh=1.5), "occupied_thresh must be a fraction"),
    (dict(converged_weight=0.0), "converged_weight must be a fraction in \\(0, 1\\]"),
    (dict(min_particles=600, max_particles=500), "min_particles <= max_particles"),
    (dict(model="beam"), "model must be"),
    (dict(sensor_offset=(0.0, math.nan, 0.0)), "sensor_offset\\[1\\]"),
    (dict(sensor_offset=(0.0, 0.0)), "sensor_offset must be three"),
    (dict(relocalize_after=-1), "relocalize_after must be an integer ≥ 0"),
    (dict(relocalize_confirm_d=-1.0), "relocalize_confirm_d must be a non-negative"),
    (dict(coast_evidence=-1.0), "coast_evidence must be a non-negative"),
    (dict(coast_motion=(0.1, 0.1, -0.1, 0.1)), "alphas\\[2\\]"),
    (dict(refine_finish=0.0), "refine_finish must be a positive"),
])
def test_bad_values_name_the_field(changes, match):
    with pytest.raises(InvalidArgumentError, match=match):
        LocalizationParams(**changes)
    with pytest.raises(InvalidArgumentError, match=match):
        LocalizationParams().replace(**changes)


def test_replace_and_unknown_names():
    p = LocalizationParams().replace(refine=True, sigma_hit=0.1)
    assert p.refine and p.sigma_hit == 0.1 and LocalizationParams().sigma_hit == 0.2
    with pytest.raises(TypeError):
        LocalizationParams(alpha_slow=0.1)  # the old name: AMCL's is recovery_alpha_slow
    with pytest.raises(TypeError):
        LocalizationParams(500)  # keyword-only: no field depends on the order of the others


def test_localizer_takes_params_or_keywords(tmp_path):
    occ = np.zeros((40, 40), dtype=np.int8)
    occ[[0, -1], :] = occ[:, [0, -1]] = 100  # a 4 m square room
    save_map(tmp_path / "room.yaml", occ, 0.1, (0.0, 0.0))
    grid = OccupancyGrid2D.load(tmp_path / "room.yaml")
    base = LocalizationParams(n_particles=50, refine=True)
    a = MonteCarloLocalizer(grid, params=base, seed=1)
    b = MonteCarloLocalizer(grid, 50, refine=True, seed=1)
    c = MonteCarloLocalizer(grid, params=base.replace(n_particles=10), n_particles=50, seed=1)
    assert a.params == b.params == c.params
    for loc in (a, b, c):
        loc.initialize((2.0, 2.0, 0.0))
    np.testing.assert_array_equal(a.particles, b.particles)
    with pytest.raises(InvalidArgumentError, match="params must be a LocalizationParams"):
        MonteCarloLocalizer(grid, params={"n_particles": 5})
