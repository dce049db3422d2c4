"""Scan-to-map matching recovers known poses of simulated scans, uses odometry as its prior, gives
the same poses streamed and batched, counts what it cannot match, and beats raw odometry on Intel."""

from __future__ import annotations

import itertools
import math
from dataclasses import replace

import numpy as np
import pytest

from occmap.errors import InvalidArgumentError
from occmap.geometry.se2 import SE2
from occmap.scan import LaserScan, with_poses
from occmap.sim.world2d import World2D, simulate_scans
from occmap.slam import ScanMatcher, ScanMatchParams, match_scans, relative_pose_error
from occmap.slam.scan_matching import FAILED, FIRST, MATCHED, distance_fields


def _in_first_frame(truth):
    """Truth poses in the frame of the first one: the frame scan matching reports in."""
    return (SE2(truth[0]).inv() @ SE2(truth)).xytheta


def _errors(poses, truth):
    ref = _in_first_frame(truth)
    d = SE2(ref).inv() @ SE2(poses)
    return np.hypot(d.xytheta[:, 0], d.xytheta[:, 1]), np.abs(d.xytheta[:, 2])


@pytest.fixture(scope="module")
def office():
    """300 scans 12 cm apart (turns up to 20° a scan) along the default office's path."""
    world = World2D.default()
    truth = world.default_trajectory(1000)[:300]
    return truth, simulate_scans(world, truth, n_beams=360, max_range=10.0, sigma=0.01, rng=1)


def test_recovers_simulated_poses_from_the_ranges_alone(office):
    truth, scans = office
    track = match_scans(scans)
    pos, head = _errors(track.poses, truth)
    # 5 cm cells: the walls are known to within half a cell, so is the trajectory
    assert pos.max() < 0.08 and math.degrees(head.max()) < 0.5
    assert track.stats == {"scans": 300, "matched": 299, "failed": 0, "rejected": 0, "degenerate": 0,
                           "inserted": track.stats["inserted"]}
    assert track.status[0] == FIRST and (track.status[1:] == MATCHED).all()
    assert 250 < track.stats["inserted"] <= 300
    good = track.inliers[1:] / track.beams[1:]
    assert good.min() > 0.7 and np.nanmax(track.rms) < 0.05
    rpe = relative_pose_error(track.poses, _in_first_frame(truth)).summary()
    assert rpe["translation_mean"] < 0.01 and rpe["rotation_deg_mean"] < 0.1


def test_streaming_gives_the_batch_poses_and_the_first_scan_defines_the_frame(office):
    _, scans = office
    params = ScanMatchParams(initial_pose=(1.0, -2.0, 0.5))
    matcher = ScanMatcher(params)
    streamed = np.array([matcher.add(s) for s in scans[:60]])
    batch = match_scans(scans[:60], params)
    np.testing.assert_array_equal(streamed, batch.poses)
    assert streamed[0].tolist() == [1.0, -2.0, 0.5]
    assert matcher.stats == batch.stats
    np.testing.assert_array_equal(matcher.pose, streamed[-1])


def test_odometry_is_the_prior_and_carries_sparse_scans_the_constant_velocity_cannot():
    """Every third pose (35 cm and up to 60° a scan): odometry with a drift of 1° a scan brings
    each match within reach; the constant-velocity prior alone does not."""
    world = World2D.default()
    truth = world.default_trajectory(1000)[:600:3]
    scans = simulate_scans(world, truth, n_beams=360, max_range=10.0, sigma=0.01, rng=2)
    steps = (SE2(truth[:-1]).inv() @ SE2(truth[1:])).xytheta + [0.0, 0.0, math.radians(1.0)]
    odom = [np.array([5.0, 5.0, 2.0])]
    for step in steps:
        odom.append((SE2(odom[-1]) @ SE2(step)).xytheta)
    with_odom = [replace(s, odom=o) for s, o in zip(scans, odom)]
    matcher = ScanMatcher()
    poses = []
    for k, s in enumerate(with_odom):
        poses.append(matcher.add(s))
        if k:
            step = SE2(odom[k - 1]).inv() @ SE2(odom[k])
            np.testing.assert_allclose(matcher.prior, (SE2(poses[k - 1]) @ step).xytheta, atol=1e-12)
    pos, head = _errors(np.array(poses), truth)
    assert pos.max() < 0.1 and math.degrees(head.max()) < 0.5
    assert matcher.stats["matched"] == len(truth) - 1
    blind, _ = _errors(match_scans(scans).poses, truth)
    assert blind.max() > 1.0


def test_empty_and_nan_scans_are_counted_and_left_at_the_prior(office):
    truth, scans = office
    empty = LaserScan(np.zeros(3), np.zeros(0), np.zeros(0), 10.0)
    nan = replace(scans[5], ranges=np.full(len(scans[5]), np.nan))
    run = [empty, nan] + list(scans[:20]) + [nan, empty] + list(scans[20:40])
    track = match_scans(run)
    s = track.stats
    assert s["scans"] == 44 and s["failed"] == 4 and s["matched"] == 39
    assert (track.status[[1, 22, 23]] == FAILED).all()
    np.testing.assert_array_equal(track.poses[22], track.priors[22])
    # the run goes on after the gap: the scans after it are placed as well as the ones before
    pos, _ = _errors(track.poses[2:22], truth[:20])
    assert pos.max() < 0.08
    assert all(not math.isfinite(r) for r in track.rms[[0, 1]])


def test_a_straight_corridor_is_degenerate_counted_and_follows_the_prior_along_it():
    """Two parallel walls and nothing else in reach: across the corridor and in heading the walls
    pin the pose, along it only the prior can (here odometry that reads 10 % short)."""
    world = World2D(np.array([[-50.0, 0.0, 50.0, 0.0], [-50.0, 2.0, 50.0, 2.0]]), np.zeros((0, 3)),
                    (-50.0, -1.0, 50.0, 3.0))
    truth = np.column_stack([0.1 * np.arange(40), np.ones(40), np.zeros(40)])
    scans = simulate_scans(world, truth, n_beams=180, max_range=8.0, sigma=0.005, rng=3)
    odom = truth * [0.9, 1.0, 1.0]
    track = match_scans([replace(s, odom=o) for s, o in zip(scans, odom)])
    assert track.stats["degenerate"] == 39 and track.stats["matched"] == 39
    assert track.degenerate[1:].all() and not track.degenerate[0]
    np.testing.assert_allclose(track.poses[:, 0], odom[:, 0], atol=1e-3)
    np.testing.assert_allclose(track.poses[:, 1], 0.0, atol=0.03)
    np.testing.assert_allclose(track.poses[:, 2], 0.0, atol=math.radians(0.3))


def test_bad_settings_name_the_field():
    with pytest.raises(InvalidArgumentError, match="search_window"):
        ScanMatchParams(search_window=(0.4,))
    with pytest.raises(InvalidArgumentError, match="max_correction"):
        ScanMatchParams(max_correction=(0.0, 0.5))
    with pytest.raises(InvalidArgumentError, match="initial_pose"):
        ScanMatchParams(initial_pose=(0.0, math.nan, 0.0))
    with pytest.raises(InvalidArgumentError, match="ScanMatchParams"):
        ScanMatcher(params={"resolution": 0.05})


def test_with_poses_replaces_the_poses_only(office):
    _, scans = office
    poses = np.arange(30.0).reshape(10, 3)
    out = with_poses(scans[:10], poses)
    assert [s.pose.tolist() for s in out] == poses.tolist()
    assert all(a.ranges is b.ranges and a.stamp == b.stamp for a, b in zip(out, scans))


def test_on_intel_the_relative_pose_error_beats_raw_odometry(data_dir):
    """150 scans of the raw Intel run paired with the corrected log's: scan matching with the
    raw odometry as its prior against the corrected poses, beside the odometry itself."""
    from occmap.io.carmen import iter_carmen, read_carmen
    from occmap.localize.replay import pair_scans

    ref = read_carmen(data_dir / "carmen" / "intel-corrected.log.gz").scans[:150]
    raw = list(itertools.islice(iter_carmen(data_dir / "carmen" / "intel-raw.clf.bz2"), 2800))
    pairs = pair_scans(raw, ref)
    assert (pairs >= 0).all()
    reference = np.array([s.pose for s in ref])
    scans = [raw[j] for j in pairs]
    odometry = relative_pose_error(np.array([s.odom for s in scans]), reference).summary()
    track = match_scans(scans)
    matched = relative_pose_error(track.poses, reference).summary()
    assert track.stats["failed"] == track.stats["rejected"] == 0
    assert matched["translation_mean"] < 0.6 * odometry["translation_mean"]
    assert matched["rotation_deg_mean"] < 0.2 * odometry["rotation_deg_mean"]


@pytest.mark.parametrize("shape", [(6, 8), (7, 9), (1, 1)])
def test_coarser_levels_mark_a_cell_where_any_finer_cell_it_covers_is_occupied(shape):
    rng = np.random.default_rng(shape[0])
    mask = rng.random(shape) < 0.15
    mask[-1, -1] = True
    fields = distance_fields(mask, (0.0, 0.0), 0.1, 3, 0.3, score=False)
    level = mask
    for f in fields[::-1]:
        np.testing.assert_array_equal(f.distance == 0.0, level)
        assert f.score is None
        pad = np.zeros((level.shape[0] + level.shape[0] % 2, level.shape[1] + level.shape[1] % 2), bool)
        pad[:level.shape[0], :level.shape[1]] = level
        level = pad[0::2, 0::2] | pad[1::2, 0::2] | pad[0::2, 1::2] | pad[1::2, 1::2]
    scored = distance_fields(mask, (0.0, 0.0), 0.1, 3, 0.3)
    np.testing.assert_array_equal(scored[0].score, np.exp(-0.5 * (fields[0].distance / 0.4) ** 2).astype(np.float32))
