"""Monte Carlo localization: motion sampling, resampling, tracking and recovery in a simulated
world, and the answers to bad input."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from occmap.errors import InvalidArgumentError, NonFiniteError, OccmapError, ShapeError
from occmap.geometry.motion import apply_odometry, odometry_delta
from occmap.geometry.se2 import compose_poses
from occmap.geometry.so2 import wrap_angle
from occmap.grid2d import OccupancyGrid2D
from occmap.localize import LocalizationWarning, MonteCarloLocalizer
from occmap.localize import _kernels as K
from occmap.sim import World2D, simulate_scans

RES = 0.05


@pytest.fixture(scope="module")
def world():
    return World2D.default()


@pytest.fixture(scope="module")
def sim_map(world):
    """The default office mapped at 5 cm from true poses along its trajectory (360° lidar)."""
    path = world.default_trajectory(n=600)
    scans = simulate_scans(world, path, n_beams=360, max_range=10.0, sigma=0.01, rng=1)
    grid = OccupancyGrid2D(RES, size=(20.4, 15.4), origin=(-0.2, -0.2))
    grid.insert_scans(path, np.array([s.ranges for s in scans]), scans[0].angles, max_range=10.0)
    return grid


def _drifting_odometry(truth, rng, scale=0.02, rot=0.01, frame=(3.0, -2.0, 0.7)):
    """Odometry of a robot that followed ``truth``: each step's motion with a few per cent of noise,
    chained in an odometry frame of its own."""
    odo = np.empty_like(truth)
    odo[0] = frame
    for i in range(1, len(truth)):
        d = np.array(odometry_delta(truth[i - 1], truth[i], min_trans=0.0))
        d *= 1.0 + scale * rng.standard_normal(3)
        d[0] += rot * rng.standard_normal() * 0.1
        odo[i] = apply_odometry(odo[i - 1], tuple(d))
    return odo


def _track(loc, world, truth, odo, rng, fov=2 * math.pi, n_beams=180):
    scans = simulate_scans(world, truth, n_beams=n_beams, fov=fov, max_range=10.0, sigma=0.01, p_outlier=0.02, rng=rng)
    out = np.empty((len(truth), 3))
    for i, s in enumerate(scans):
        out[i] = loc.update(odo[i], s.ranges, s.angles, s.max_range).pose
    return out


# ---------------------------------------------------------------------------------------- motion


def test_motion_sampling_matches_analytic_mean_and_spread(sim_map):
    """A cloud started at one pose and moved 1 m straight ahead by the filter (the scan has no valid
    reading, so only the motion model acts) has the exact moments of the odometry model:
    rot1, trans, rot2 ~ N(0, a2), N(1, a3), N(0, a2) for a unit translation."""
    a1, a2, a3, a4 = 0.05, 0.01, 0.02, 0.03
    n = 200_000
    loc = MonteCarloLocalizer(sim_map, n, motion=(a1, a2, a3, a4), seed=3)
    loc.initialize((5.0, 7.5, 0.0), np.zeros((3, 3)))
    nan = np.full(10, np.nan)
    angles = np.linspace(-1, 1, 10)
    with pytest.warns(LocalizationWarning, match="no valid reading"):
        loc.update((0.0, 0.0, 0.0), nan, angles, 10.0)
    with pytest.warns(LocalizationWarning, match="no valid reading"):
        loc.update((1.0, 0.0, 0.0), nan, angles, 10.0)
    p = loc.particles
    x, y, t = p[:, 0] - 5.0, p[:, 1] - 7.5, p[:, 2]
    e_cos, e_cos2, e_sin2 = math.exp(-a2 / 2), (1 + math.exp(-2 * a2)) / 2, (1 - math.exp(-2 * a2)) / 2
    moments = {
        "mean x": (x.mean(), e_cos, math.sqrt((1 + a3) * e_cos2 - e_cos ** 2)),
        "mean y": (y.mean(), 0.0, math.sqrt((1 + a3) * e_sin2)),
        "mean theta": (t.mean(), 0.0, math.sqrt(2 * a2)),
        "var x": (x.var(), (1 + a3) * e_cos2 - e_cos ** 2, None),
        "var y": (y.var(), (1 + a3) * e_sin2, None),
        "var theta": (t.var(), 2 * a2, None),
    }
    for name, (got, want, sd) in moments.items():
        if sd is not None:  # a mean: within 4 standard errors
            assert abs(got - want) < 4 * sd / math.sqrt(n), name
        else:  # a variance: within 2 %
            assert got == pytest.approx(want, rel=0.02), name


def test_rotation_noise_grows_with_rotation(sim_map):
    loc = MonteCarloLocalizer(sim_map, 50_000, motion=(0.1, 0.0, 0.0, 0.0), seed=4)
    loc.initialize((5.0, 7.5, 0.0), np.zeros(3))
    nan = np.full(3, np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LocalizationWarning)
        loc.update((0.0, 0.0, 0.0), nan, np.zeros(3), 10.0)
        loc.update((0.0, 0.0, 1.0), nan, np.zeros(3), 10.0)
    # pure rotation: all of it is rot2 (AMCL's min_trans rule), std = sqrt(a1) · |rot2|
    assert np.std(loc.particles[:, 2]) == pytest.approx(math.sqrt(0.1) * 1.0, rel=0.03)
    assert np.allclose(loc.particles[:, :2], (5.0, 7.5))


# ------------------------------------------------------------------------------------- resampling


def test_systematic_resampling_preserves_the_distribution():
    rng = np.random.default_rng(7)
    n = 20_000
    values = rng.normal(0.0, 1.0, n)
    w = np.exp(-0.5 * (values - 1.0) ** 2 / 0.25)  # reweight N(0, 1) towards N(0.8, 0.2)
    w /= w.sum()
    cum = np.cumsum(w)
    idx = np.empty(n, dtype=np.int64)
    K.systematic_indices(cum, float(rng.random()), idx)
    counts = np.bincount(idx, minlength=n)
    # low-variance resampling: every particle is copied floor(N w) or ceil(N w) times
    assert np.all(counts >= np.floor(n * w) - 1e-9) and np.all(counts <= np.ceil(n * w) + 1e-9)
    # the resampled values follow the weighted distribution: weighted mean and variance, and a
    # two-sample Kolmogorov-Smirnov distance against an independent weighted draw
    mean = w @ values
    var = w @ (values - mean) ** 2
    got = values[idx]
    assert got.mean() == pytest.approx(mean, abs=3e-3)
    assert got.var() == pytest.approx(var, rel=3e-2)
    ref = np.sort(rng.choice(values, size=n, p=w))
    grid = np.linspace(-1, 3, 400)
    ks = np.abs(np.searchsorted(np.sort(got), grid) - np.searchsorted(ref, grid)).max() / n
    assert ks < 1.36 * math.sqrt(2.0 / n)  # 95 % critical value


def test_filter_resamples_when_ess_is_low(sim_map):
    loc = MonteCarloLocalizer(sim_map, 1000, seed=5)
    loc.initialize((5.0, 7.5, 0.0), np.diag([1e-6, 1e-6, 1e-8]))
    loc.particles[:500, 0] += 1.0
    loc.weights[:] = np.where(np.arange(1000) < 500, 1.0, 1e-6)
    loc.weights /= loc.weights.sum()
    loc._resample()
    assert loc.stats.resamples == 1
    assert np.all(np.abs(loc.particles[:, 0] - 6.0) < 1e-2)
    assert np.allclose(loc.weights, 1e-3)


def test_kld_adapts_the_particle_count(sim_map, world):
    loc = MonteCarloLocalizer(sim_map, kld=True, min_particles=200, max_particles=5000, global_particles=20_000,
                              seed=6)
    loc.initialize_global()
    assert len(loc.particles) == 20_000
    truth = world.default_trajectory(n=600)[:120]
    odo = _drifting_odometry(truth, np.random.default_rng(6))
    _track(loc, world, truth, odo, np.random.default_rng(7), n_beams=90)
    assert len(loc.particles) < 2000  # a compact cloud needs few particles


# -------------------------------------------------------------------------------- tracking


def test_simulated_robot_is_tracked_within_two_cells(sim_map, world):
    rng = np.random.default_rng(11)
    truth = world.default_trajectory(n=600)[:400]
    odo = _drifting_odometry(truth, rng)
    loc = MonteCarloLocalizer(sim_map, 1000, motion=(0.05, 0.05, 0.05, 0.05), refine=True, seed=12)
    loc.initialize(truth[0], np.diag([0.05 ** 2, 0.05 ** 2, 0.02 ** 2]))
    est = _track(loc, world, truth, odo, rng, fov=math.pi)
    err = np.hypot(*(est[:, :2] - truth[:, :2]).T)
    herr = np.abs(wrap_angle(est[:, 2] - truth[:, 2]))
    odo_err = np.hypot(*(odo[:, :2] - odo[0, :2] + truth[0, :2] - truth[:, :2]).T)
    assert odo_err.max() > 0.3  # the odometry alone drifts well away ...
    assert err[5:].max() <= 2 * RES  # ... the filter stays within two cells
    assert np.degrees(herr[5:]).max() < 2.0
    assert np.isfinite(est).all()


def test_a_turn_on_the_spot_the_odometry_misses_is_followed_from_the_scans(sim_map, world):
    """The robot drives 0.3 m, then turns 0.6 rad on the spot while its wheels slip: the odometry
    reports no turn, so it never asks for a filter run (every 5 cm / 0.1 rad). The scans do: their
    match from the estimate turns it by more than 0.1 rad in place, the filter runs and its
    refinement turns the cloud. Without that the estimate stays 0.6 rad off."""
    rng = np.random.default_rng(5)
    start = world.default_trajectory(n=600)[100]
    drive = np.array([apply_odometry(start, (0.0, 0.03 * k, 0.0)) for k in range(11)])
    turn = np.array([[*drive[-1, :2], drive[-1, 2] + 0.03 * k] for k in range(1, 21)])
    truth = np.concatenate([drive, turn])
    odo = np.concatenate([drive, np.repeat(drive[-1:], len(turn), axis=0)])  # the turn unseen
    loc = MonteCarloLocalizer(sim_map, 500, motion=(0.05, 0.05, 0.05, 0.05), refine=True, refine_feedback=True,
                              update_min_d=0.05, update_min_a=0.1, seed=3)
    loc.initialize(truth[0], np.diag([0.02 ** 2, 0.02 ** 2, 0.01 ** 2]))
    est = _track(loc, world, truth, odo, rng)
    herr = np.abs(wrap_angle(est[:, 2] - truth[:, 2]))
    # at most the filter's spacing (0.1 rad, 5.7°) plus a step (0.03 rad) behind, never 0.6 rad
    assert np.degrees(herr).max() < 8.0
    assert loc.stats.scan_triggered >= 4
    assert np.hypot(*(est[-1, :2] - truth[-1, :2])) < 2 * RES


def test_global_localization_converges_in_simulation(sim_map, world):
    rng = np.random.default_rng(21)
    truth = world.default_trajectory(n=600)[100:300]
    odo = _drifting_odometry(truth, rng)
    loc = MonteCarloLocalizer(sim_map, kld=True, min_particles=500, max_particles=30_000, refine=True, seed=22)
    loc.initialize_global()
    with pytest.warns(LocalizationWarning):  # a scan without a reading: not converged yet
        assert not loc.update(odo[0], np.full(10, np.inf), np.zeros(10), 10.0).converged
    est = _track(loc, world, truth, odo, rng)
    err = np.hypot(*(est[:, :2] - truth[:, :2]).T)
    assert err[-50:].max() < 0.1
    assert loc.estimate.converged and loc.stats.converged_after is not None


def test_kidnapped_robot_recovers(sim_map, world):
    rng = np.random.default_rng(31)
    path = world.default_trajectory(n=600)
    truth = np.concatenate([path[:80], path[380:560]])  # teleported from the first rooms to the far ones
    odo = _drifting_odometry(np.concatenate([path[:80], path[80:80 + 180]]), rng)  # odometry never knew
    loc = MonteCarloLocalizer(sim_map, 3000, recovery_alpha_slow=0.001, recovery_alpha_fast=0.1, refine=True, seed=32,
                              z_rand_span="range")
    loc.initialize(truth[0], np.diag([0.05 ** 2, 0.05 ** 2, 0.02 ** 2]))
    scans = simulate_scans(world, truth, n_beams=180, fov=2 * math.pi, max_range=10.0, sigma=0.01, p_outlier=0.02,
                           rng=rng)
    out = [loc.update(odo[i], s.ranges, s.angles, s.max_range) for i, s in enumerate(scans)]
    est = np.array([e.pose for e in out])
    lost = np.array([e.lost for e in out])
    fit = np.array([e.fit for e in out])
    err = np.hypot(*(est[:, :2] - truth[:, :2]).T)
    assert err[10:80].max() < 0.1  # tracked before
    assert err[85] > 1.0  # lost right after the kidnapping
    assert loc.stats.injected > 0
    assert err[-40:].max() < 0.1  # and found again
    assert np.isfinite(est).all()
    # the lost flag: down while tracked, up from the kidnapping until the filter is found again
    assert not lost[:80].any() and fit[:80].min() > 0.9
    found = 80 + int(np.argmax(err[80:] < 0.1))
    assert found > 85 and lost[80:found].all()
    # after it, a handful of scans of places the simulated map shows poorly (fit near 0.2) raise it too
    assert lost[found:].mean() < 0.05 and (fit[found:][lost[found:]] < 0.7).all()


def test_scans_the_map_does_not_explain_are_coasted_through(sim_map, world):
    """For 12 steps (2.2 m) the robot sees a place 1.1 m and 46° away from where it is (a room the
    map shows wrongly): with ``coast_fit`` those scans are left out and the odometry carries the
    cloud (error within the odometry's drift); without it they drag the estimate over a metre off.
    ``coast_max_d`` bounds how far the filter coasts: past it the scans weigh the cloud again (and
    drag it), but the estimate stays the odometry's until the cloud's is confirmed, and the cloud
    is brought back once a scan fits the odometry's pose again. The scans fit the wrong pose
    perfectly, so the cloud is confirmed there once it has been not lost on ``coast_confirm`` (5)
    runs: the wrong view must end before cap + drag + confirmation. With the refinement's finishing
    pass (``refine_finish``) the cloud is dragged there in 2 runs instead of 3, so the cap here is
    1.2 m (6 steps), not 1.0 m, for the 12-step view."""
    rng = np.random.default_rng(41)
    truth = world.default_trajectory(n=600)[100:300]
    odo = _drifting_odometry(truth, rng)
    seen = truth.copy()
    seen[60:72] = compose_poses(truth[60:72], np.array([1.0, 0.5, 0.8]))
    scans = simulate_scans(world, seen, n_beams=180, fov=2 * math.pi, max_range=10.0, sigma=0.01, p_outlier=0.02,
                           rng=rng)

    def run(**settings):
        loc = MonteCarloLocalizer(sim_map, refine=True, refine_feedback=True, seed=42, **settings)
        loc.initialize(truth[0], np.diag([0.05 ** 2, 0.05 ** 2, 0.02 ** 2]))
        est, cloud = [], []
        for i, s in enumerate(scans):
            est.append(loc.update(odo[i], s.ranges, s.angles, s.max_range).pose)
            cloud.append(np.average(loc.particles[:, :2], axis=0, weights=loc.weights))
        run.cloud_err = np.hypot(*(np.array(cloud) - truth[:, :2]).T)
        return np.hypot(*(np.array(est)[:, :2] - truth[:, :2]).T), loc.stats.coasted

    err, coasted = run(coast_fit=0.75)
    assert coasted == 12 and err[10:60].max() < 0.1 and err[60:72].max() < 0.3 and err[80:].max() < 0.1
    err, coasted = run()
    assert coasted == 0 and err[60:72].max() > 1.0
    err, _ = run(coast_fit=0.75, coast_max_d=1.2)  # about 1.2 m (6 steps) of coasting, then the scans weigh again
    assert err[60:66].max() < 0.1 and run.cloud_err[69:72].min() > 1.0  # the cloud is dragged ...
    assert err[60:72].max() < 0.1 and err[72:].max() < 0.1  # ... the estimate is not, and the cloud comes back


# ------------------------------------------------------------------------------------ bad input


def test_empty_map_is_rejected():
    with pytest.raises(InvalidArgumentError, match="empty"):
        MonteCarloLocalizer(OccupancyGrid2D(0.05))


def test_map_without_free_cell_is_rejected():
    grid = OccupancyGrid2D(0.1, size=(2.0, 2.0))
    # one short beam: its end cell is occupied, nothing was ever seen free
    grid.insert_scans(np.array([[1.05, 1.05, 0.0]]), np.array([[0.02]]), np.array([0.0]), max_range=5.0)
    with pytest.raises(InvalidArgumentError, match="no free cell") as info:
        MonteCarloLocalizer(grid)
    assert isinstance(info.value, OccmapError)


def test_map_without_obstacle_is_rejected(sim_map):
    grid = OccupancyGrid2D(0.1, size=(2.0, 2.0))
    with pytest.raises(InvalidArgumentError, match="no occupied cell"):
        MonteCarloLocalizer(grid)


def test_bad_arguments(sim_map):
    loc = MonteCarloLocalizer(sim_map, 100, seed=1)
    with pytest.raises(InvalidArgumentError, match="initialize"):
        loc.update((0, 0, 0), [1.0], [0.0], 10.0)
    with pytest.raises(NonFiniteError):
        loc.initialize((np.nan, 0, 0))
    with pytest.raises(InvalidArgumentError, match="semi-definite"):
        loc.initialize((1, 1, 0), np.diag([1.0, -1.0, 1.0]))
    loc.initialize((5.0, 7.5, 0.0))
    with pytest.raises(NonFiniteError):
        loc.update((0, np.inf, 0), [1.0], [0.0], 10.0)
    with pytest.raises(ShapeError):
        loc.update((0, 0, 0), [1.0, 2.0], [0.0], 10.0)
    with pytest.raises(InvalidArgumentError):
        loc.update((0, 0, 0), [1.0], [0.0], -1.0)
    with pytest.raises(InvalidArgumentError):
        MonteCarloLocalizer(sim_map, 0)
    with pytest.raises(InvalidArgumentError):
        MonteCarloLocalizer(sim_map, model="beam")
    with pytest.raises(InvalidArgumentError, match="coast_fit"):
        MonteCarloLocalizer(sim_map, coast_fit=1.5)
    with pytest.raises(InvalidArgumentError, match="coast_max_d"):
        MonteCarloLocalizer(sim_map, coast_max_d=-1.0)
    with pytest.raises(InvalidArgumentError):
        MonteCarloLocalizer(sim_map, sigma_hit=0.0)
    with pytest.raises(InvalidArgumentError):
        MonteCarloLocalizer(sim_map, global_particles=0)
    with pytest.raises(InvalidArgumentError):
        MonteCarloLocalizer(sim_map, converged_weight=0.0)
    with pytest.raises(InvalidArgumentError):
        MonteCarloLocalizer(3.0)


def test_scans_with_no_valid_reading_warn_and_move_by_odometry(sim_map):
    loc = MonteCarloLocalizer(sim_map, 500, seed=2)
    loc.initialize((5.0, 7.5, 0.0), np.diag([1e-4, 1e-4, 1e-5]))
    bad = np.array([np.nan, np.inf, -1.0, 0.0, 10.0, 12.0])  # NaN, inf, negative, zero, max range, beyond
    ang = np.linspace(-1, 1, 6)
    with pytest.warns(LocalizationWarning, match="no valid reading"):
        loc.update((0, 0, 0), bad, ang, 10.0)
    with pytest.warns(LocalizationWarning):
        est = loc.update((0.5, 0, 0), bad, ang, 10.0)
    assert np.isfinite(est.pose).all() and np.isfinite(est.covariance).all()
    assert est.pose[0] == pytest.approx(5.5, abs=0.05)
    assert loc.stats.empty_scans == 2


def test_a_large_step_is_integrated_with_its_noise(sim_map, world):
    """Two scans dropped in a turn: one step of 0.6 m and more than 60° between two calls (the kind
    a real log holds). The filter moves the cloud by it, with noise grown to its size, as AMCL does;
    nothing is refused, nothing warned, and the track holds."""
    rng = np.random.default_rng(41)
    path = world.default_trajectory(n=600)
    turn3 = np.abs(wrap_angle(path[3:, 2] - path[:-3, 2]))
    j = int(np.argmax(turn3[20:300])) + 20  # the sharpest three-step turn
    keep = np.r_[j - 20:j + 1, j + 3:j + 40]
    truth = path[keep]
    step = truth[21] - truth[20]
    assert math.hypot(step[0], step[1]) > 0.5 and abs(wrap_angle(step[2])) > math.radians(60)
    odo = _drifting_odometry(truth, rng)
    loc = MonteCarloLocalizer(sim_map, 1000, refine=True, refine_feedback=True, seed=42)
    loc.initialize(truth[0], np.diag([0.05 ** 2, 0.05 ** 2, 0.02 ** 2]))
    with warnings.catch_warnings():
        warnings.simplefilter("error", LocalizationWarning)
        poses = _track(loc, world, truth, odo, rng, n_beams=180)
    err = np.hypot(*(poses[:, :2] - truth[:, :2]).T)
    assert err.max() < 0.3
    assert err[25:].max() < 0.1  # a few scans after the step the scans have pulled it in


def test_estimate_uses_circular_mean(sim_map):
    loc = MonteCarloLocalizer(sim_map, 4, seed=0)
    loc.initialize((5.0, 7.5, 0.0))
    loc.particles[:] = [[5.0, 7.5, math.pi - 0.1], [5.0, 7.5, -math.pi + 0.1], [5.0, 7.5, math.pi - 0.05],
                        [5.0, 7.5, -math.pi + 0.05]]
    mean, cov, _ = loc._mean()
    assert abs(wrap_angle(mean[2] - math.pi)) < 1e-12
    assert cov[2, 2] == pytest.approx((0.1 ** 2 + 0.05 ** 2) / 2)


def test_random_term_is_spread_over_the_field_or_the_sensor_range(sim_map):
    """The per-beam score of an end point far from every obstacle: ``z_rand / max_dist`` with the
    default ``z_rand_span="field"`` whatever the sensor, AMCL's ``z_rand / max_range`` with
    ``"range"``; next to an obstacle both are ``z_hit + the random term``."""
    from occmap.localize.likelihood_field import LikelihoodField
    from occmap.localize.params import LocalizationParams

    for span, max_range, floor in (("field", 80.0, 0.05 / 2.0), ("field", 5.0, 0.05 / 2.0),
                                   ("range", 80.0, 0.05 / 80.0), ("range", 5.0, 0.05 / 5.0)):
        field = LikelihoodField(sim_map, LocalizationParams(z_rand_span=span))
        table, outside = field.table(max_range, 0.2)
        assert outside == pytest.approx(math.log(floor), rel=1e-6)
        far = field.distance >= field.max_dist
        assert np.allclose(table[far], math.log(floor), rtol=1e-5)
        assert table[field.occupied].max() == pytest.approx(math.log(0.95 + floor), rel=1e-5)
    with pytest.raises(InvalidArgumentError, match="z_rand_span must be 'field' or 'range', got 'beam'"):
        LocalizationParams(z_rand_span="beam")
