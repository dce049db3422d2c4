"""One map used from several threads keeps its promise (occmap._threads.OneCallAtATime): calls
take turns, so concurrent insertions equal the same insertions made one after another."""

from __future__ import annotations

import pickle
import threading

import numba
import numpy as np
import pytest

from occmap import LocalMap, OccupancyGrid2D, OcTree

THREADS = 4


def _concurrently(jobs):
    """Run the callables at once on their own threads (started together), re-raising errors."""
    start = threading.Barrier(len(jobs))
    errors = []

    def run(job):
        start.wait()
        try:
            job()
        except BaseException as e:  # noqa: BLE001 - reported below
            errors.append(e)

    threads = [threading.Thread(target=run, args=(job,)) for job in jobs]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    if errors:
        raise errors[0]


def _clouds():
    """Scans far apart (no voxel in two of them), so the order of insertion does not matter."""
    rng = np.random.default_rng(7)
    out = []
    for k in range(THREADS):
        origin = np.array([60.0 * k, 0.0, 1.0])
        points = origin + rng.normal(size=(25_000, 3)) * [6.0, 6.0, 1.5]
        out.append((points, origin))
    return out


@pytest.mark.parametrize("repeat", range(3))
def test_octree_from_several_threads_equals_one_after_another(repeat):
    clouds = _clouds()
    alone = OcTree(0.2)
    for points, origin in clouds:
        alone.insert_point_cloud(points, origin)
    shared = OcTree(0.2)
    _concurrently([lambda p=p, o=o: shared.insert_point_cloud(p, o) for p, o in clouds])
    assert shared.num_nodes() == alone.num_nodes()
    a, b = alone.leaves(), shared.leaves()
    order_a, order_b = np.lexsort(a.centers.T), np.lexsort(b.centers.T)
    np.testing.assert_array_equal(a.centers[order_a], b.centers[order_b])
    np.testing.assert_array_equal(a.log_odds[order_a], b.log_odds[order_b])


@pytest.mark.parametrize("repeat", range(3))
def test_growing_grid_from_several_threads_equals_one_after_another(repeat):
    angles = np.linspace(-np.pi, np.pi, 720, endpoint=False)
    scans = [((40.0 * k, 0.0, 0.0), np.full(720, 5.0 + k)) for k in range(THREADS)]
    # growing to the right only (origin fixed below every scan): the cells do not depend on the order
    alone = OccupancyGrid2D(0.05, origin=(-20.0, -20.0))
    for pose, ranges in scans:
        alone.insert_scan(pose, ranges, angles, max_range=30.0)
    shared = OccupancyGrid2D(0.05, origin=(-20.0, -20.0))
    _concurrently([lambda p=p, r=r: shared.insert_scan(p, r, angles, max_range=30.0) for p, r in scans])
    # the grid grows to fit each scan as it comes, so its extent depends on the order
    H, W = alone.shape
    iy, ix = np.mgrid[0:H, 0:W]
    centres = alone.cell_to_world(np.stack([iy.ravel(), ix.ravel()], axis=1))
    np.testing.assert_array_equal(shared.log_odds_at(centres), alone.log_odds_at(centres))
    assert np.count_nonzero(~np.isnan(shared.log_odds())) == np.count_nonzero(~np.isnan(alone.log_odds()))
    assert shared.stats == alone.stats


def test_local_map_queries_while_another_thread_inserts():
    lm = LocalMap(size=(20.0, 20.0), resolution=0.1)
    angles = np.linspace(-np.pi, np.pi, 720, endpoint=False)
    stamps = iter(np.arange(0.0, 100.0, 0.1))

    def insert():
        for _ in range(50):
            lm.insert_scan((0.0, 0.0, 0.0), np.full(720, 4.0), angles, next(stamps))

    def read():
        for _ in range(50):
            cost, _ = lm.costmap()
            assert cost.shape == lm.shape

    _concurrently([insert, read, read])
    assert lm.stats["scans"] == 50


def test_maps_pickle_without_their_lock():
    tree = OcTree(0.1)
    tree.insert_point_cloud(np.array([[1.0, 0.0, 0.0]]), np.zeros(3))
    copy = pickle.loads(pickle.dumps(tree))
    assert copy.num_nodes() == tree.num_nodes() and copy._lock is not tree._lock
    copy.insert_point_cloud(np.array([[0.0, 1.0, 0.0]]), np.zeros(3))  # its own lock works


@pytest.mark.skipif(numba.get_num_threads() < 2, reason="tracing ahead needs two threads")
def test_tracing_ahead_does_not_wait_for_the_lock_its_call_holds():
    """insert_point_clouds traces the next scan on another thread while the call holds the
    tree's lock: what that thread uses must not take the lock (a deadlock before)."""
    clouds = _clouds()
    tree, done = OcTree(0.2), threading.Event()

    def insert():
        tree.insert_point_clouds([p for p, _ in clouds], np.array([o for _, o in clouds]))
        done.set()

    threading.Thread(target=insert, daemon=True).start()
    assert done.wait(180), "insert_point_clouds deadlocked"
    alone = OcTree(0.2)
    for points, origin in clouds:
        alone.insert_point_cloud(points, origin)
    assert tree.num_nodes() == alone.num_nodes()
