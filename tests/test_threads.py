"""The threading layer and the per-call choice between one thread and several."""

from __future__ import annotations

import math
import multiprocessing as mp
import os
import platform
import subprocess
import sys
import threading
import time

import numba
import numpy as np
import pytest

import occmap._jit  # noqa: F401  (loads TBB before anything below starts Numba's threading layer)
import occmap._threads
from occmap._threads import ThreadChoice, _tbb_library, read_ahead, run_jobs

two_threads = pytest.mark.skipif(numba.get_num_threads() < 2, reason="Numba has one thread here")


class _Clock:
    """A stand-in for the timer: each call "takes" the time its path is given."""

    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


@pytest.fixture
def clock(monkeypatch):
    fake = _Clock()
    monkeypatch.setattr(occmap._threads, "perf_counter", fake)
    monkeypatch.setattr(occmap._threads, "free_cores", lambda: 2.0)  # the machine's load stays out of these
    return fake


def _run(choice: ThreadChoice, clock: _Clock, serial_s: float, parallel_s: float, calls: int) -> list[bool]:
    """Feed ``calls`` calls whose paths take the given times; the paths chosen."""
    chosen = []
    for _ in range(calls):
        with choice.choose(work=1.0) as parallel:
            clock.now += parallel_s if parallel else serial_s
        chosen.append(parallel)
    return chosen


@two_threads
def test_the_cheaper_path_runs_and_a_change_in_load_is_followed(clock):
    choice = ThreadChoice(min_work=1.0)
    first = _run(choice, clock, serial_s=0.004, parallel_s=0.001, calls=40)
    # a first call unmeasured, each path measured once, then several threads, one thread tried
    # again 8, then 16 calls later
    assert [i for i, p in enumerate(first) if not p] == [2, 10, 26]
    # the machine gets busy: several threads now cost more; within a few calls one thread runs
    after = _run(choice, clock, serial_s=0.001, parallel_s=0.006, calls=60)
    switched = after.index(False)
    assert switched <= 32
    assert sum(after[switched + 8:]) <= 3
    assert choice.costs[0] < choice.costs[1]


@two_threads
def test_tries_of_the_slower_path_grow_rarer(clock):
    choice = ThreadChoice(min_work=1.0)
    chosen = _run(choice, clock, serial_s=0.001, parallel_s=0.002, calls=300)
    tries = [i for i, p in enumerate(chosen) if p][2:]  # after the unmeasured call and the first measurement
    assert tries == [10, 26, 58, 122, 250]  # 8, 16, 32, 64, 128 calls apart


@two_threads
def test_a_call_that_is_no_fair_sample_runs_the_chosen_path_unlearnt(clock):
    choice = ThreadChoice(min_work=1.0)
    _run(choice, clock, serial_s=0.004, parallel_s=0.001, calls=5)
    costs = choice.costs
    # a grid that just grew: its first call costs 50 times more, whichever path it takes
    for _ in range(3):
        with choice.choose(work=1.0, sample=False) as parallel:
            clock.now += 0.05
        assert parallel
    assert choice.costs == costs
    # learnt from, one such call turns the choice to one thread
    with choice.choose(work=1.0) as parallel:
        clock.now += 0.05
    assert parallel and choice.costs[1] > choice.costs[0]
    assert _run(choice, clock, serial_s=0.004, parallel_s=0.001, calls=1) == [False]


@two_threads
def test_forget_starts_the_choice_over_as_a_new_process(clock):
    choice = ThreadChoice(min_work=1.0)
    _run(choice, clock, serial_s=0.001, parallel_s=0.004, calls=40)  # learnt: one thread
    assert choice.costs[0] < choice.costs[1]
    choice.forget()
    assert all(math.isnan(c) for c in choice.costs)
    # as a new choice: a first call unmeasured on several threads, then each path measured once
    assert _run(choice, clock, serial_s=0.004, parallel_s=0.001, calls=9) == [True, True, False] + [True] * 6
    assert choice.costs == pytest.approx((0.004, 0.001))


@two_threads
def test_while_other_processes_leave_no_second_core_one_thread_runs_unmeasured(clock, monkeypatch):
    choice = ThreadChoice(min_work=1.0)
    _run(choice, clock, serial_s=0.004, parallel_s=0.001, calls=12)
    costs = choice.costs
    monkeypatch.setattr(occmap._threads, "free_cores", lambda: 1.2)
    assert _run(choice, clock, serial_s=0.004, parallel_s=0.001, calls=20) == [False] * 20
    assert choice.costs == costs
    monkeypatch.setattr(occmap._threads, "free_cores", lambda: None)  # unknown: the choice as before
    assert _run(choice, clock, serial_s=0.004, parallel_s=0.001, calls=3) == [True] * 3


@two_threads
def test_a_forced_path_runs_whatever_the_load_and_costs_and_teaches_nothing(clock, monkeypatch):
    choice = ThreadChoice(min_work=1.0)
    _run(choice, clock, serial_s=0.004, parallel_s=0.001, calls=12)  # learnt: several threads
    costs = choice.costs
    with occmap._threads.forced_path(False):
        assert _run(choice, clock, serial_s=0.004, parallel_s=0.001, calls=3) == [False] * 3
        assert not occmap._threads.free_for_parallel()  # (the octree's scans ask it)
    monkeypatch.setattr(occmap._threads, "free_cores", lambda: 0.0)
    with occmap._threads.forced_path(True):
        assert _run(choice, clock, serial_s=0.001, parallel_s=0.004, calls=3) == [True] * 3
        assert occmap._threads.free_for_parallel()
        with choice.choose(work=0.5) as parallel:  # too little work for several threads, forced or not
            assert not parallel
    assert choice.costs == costs
    assert _run(choice, clock, serial_s=0.004, parallel_s=0.001, calls=1) == [False]  # the load again


@pytest.mark.skipif(not os.path.exists("/proc/stat"), reason="the load is read from Linux's /proc/stat")
def test_free_cores_sees_a_busy_process_and_not_this_one():
    cpus = len(os.sched_getaffinity(0))
    occmap._threads.free_cores()
    spin_until = time.monotonic() + 0.3
    while time.monotonic() < spin_until:  # this process's own work is not another's load
        pass
    mine = occmap._threads.free_cores()
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        time.sleep(0.3)
        occmap._threads.free_cores()
        time.sleep(0.3)
        theirs = occmap._threads.free_cores()
    finally:
        busy.kill()
        busy.wait()
    # the busy process takes a whole core (or all there is, on one): a core less than this one's own work left;
    # on a machine other processes already load (less than a core free) it takes what there was: 0.3 at most left
    assert theirs <= max(mine - min(0.7, cpus - 0.3), 0.3), (mine, theirs)


@pytest.mark.skipif(not os.path.exists("/proc/stat"), reason="the load is read from Linux's /proc/stat")
def test_a_programs_first_call_finds_a_load_figure_and_a_forked_childs_its_own():
    """The load's first window starts when occmap is imported, so that a program's first calls (a
    robot's first scans, on a machine other processes may keep busy) are judged on a figure rather
    than taken as free; a child made by ``fork`` starts its own (the parent's counted the parent's
    CPU time)."""
    code = ("import os, time, occmap._threads as t\n"
            "time.sleep(0.15)\n"
            "first = t.free_cores()\n"
            "pid = os.fork()\n"
            "if pid == 0:\n"
            "    os._exit(0 if t._load._last is not None and t._load.free is None else 1)\n"
            "_, status = os.waitpid(pid, 0)\n"
            "print(first, os.waitstatus_to_exitcode(status))\n")
    first, child = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert first != "None" and 0.0 <= float(first) <= len(os.sched_getaffinity(0)) + 0.5
    assert child == "0"


def test_small_work_takes_one_thread_unmeasured():
    choice = ThreadChoice(min_work=100.0)
    with choice.choose(work=99.0) as parallel:
        assert parallel is False
    with choice.choose(work=float("nan")) as parallel:
        assert parallel is False
    assert np.isnan(choice.costs).all()


@pytest.mark.skipif(not (sys.platform.startswith("linux") and platform.machine() == "x86_64"),
                    reason="the tbb dependency is for Linux x86_64")
def test_parallel_kernels_run_on_tbb():
    assert _tbb_library() is not None, "the tbb package is a dependency on this platform"
    code = ("import numpy as np, numba; from occmap.raster.walk2d import traverse_2d; "
            "from occmap.raster.edt import distance_transform; "
            "distance_transform(np.zeros((400, 400), bool) | (np.arange(400) == 7), parallel=True); "
            "print(numba.threading_layer())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.stdout.strip() == "tbb", out.stderr


def _child_integrates(_):
    from occmap import OccupancyGrid2D

    grid = OccupancyGrid2D(0.05)
    angles = np.linspace(-np.pi, np.pi, 720, endpoint=False)
    grid.insert_scan((0.0, 0.0, 0.0), np.full(720, 4.0), angles, max_range=10.0)
    return int((grid.occupancy() == 100).sum())


def test_processes_forked_after_a_parallel_kernel_work():
    """GNU OpenMP aborts a child forked after a parallel region; the children must map."""
    from occmap.raster.edt import distance_transform

    distance_transform(np.zeros((400, 400), bool) | (np.arange(400) == 7), parallel=True)
    expected = _child_integrates(None)
    for method in ("fork", "spawn"):
        with mp.get_context(method).Pool(2) as pool:
            result = pool.map_async(_child_integrates, range(4))
            assert result.get(timeout=240) == [expected] * 4, method


_FORK_AFTER_OPENMP = """
import multiprocessing as mp, numpy as np, numba
from occmap.raster.edt import distance_transform
import occmap._threads as T
from occmap import OccupancyGrid2D

def integrate(_):
    grid = OccupancyGrid2D(0.05)
    angles = np.linspace(-np.pi, np.pi, 720, endpoint=False)
    grid.insert_scan((0.0, 0.0, 0.0), np.full(720, 4.0), angles, max_range=10.0)
    return T.thread_count(), int((grid.log_odds() > 0).sum())

if __name__ == "__main__":
    distance_transform(np.zeros((400, 400), bool) | (np.arange(400) == 7), parallel=True)
    assert numba.threading_layer() == "omp"
    parent = integrate(None)
    with mp.get_context("fork").Pool(2) as pool:
        children = pool.map_async(integrate, range(4)).get(timeout=120)
    assert parent[0] == 2 and parent[1] > 0 and children == [(1, parent[1])] * 4, (parent, children)
    print("ok")
"""


@two_threads
def test_children_forked_after_openmp_kernels_take_one_thread(tmp_path):
    """When Numba's kernels ran on GNU OpenMP in the parent (a caller started Numba before occmap
    could load TBB; forced here), a forked child's parallel region would abort it: its calls take
    one thread and it maps the same."""
    script = tmp_path / "fork_after_omp.py"
    script.write_text(_FORK_AFTER_OPENMP)
    env = {**os.environ, "NUMBA_THREADING_LAYER": "omp"}
    done = subprocess.run([sys.executable, str(script)], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr[-2000:]


def test_jobs_come_back_in_order_whichever_thread_ran_them():
    assert run_jobs([lambda i=i: i * i for i in range(20)], threads=2) == [i * i for i in range(20)]


def test_a_worker_that_does_not_start_is_not_waited_for():
    """The workers are all busy (as when the scheduler gives them no core): the calling thread
    does every job itself, and the queued helper call is cancelled."""
    release = threading.Event()
    workers = occmap._threads.pool("workers", max(occmap._threads._max_threads() - 1, 1))
    blockers = [workers.submit(release.wait, 60) for _ in range(workers._max_workers)]
    try:
        ran_on = run_jobs([lambda: threading.current_thread().name for _ in range(8)], threads=2)
        assert ran_on == [threading.current_thread().name] * 8
    finally:
        release.set()
        for b in blockers:
            b.result()


def _child_inserts(_):
    from occmap.octree import OcTree

    rng = np.random.default_rng(0)
    points = rng.normal(size=(30_000, 3)) * 5.0
    tree = OcTree(0.2)
    tree.insert_point_clouds([points, points + 1.0], origins=np.zeros((2, 3)))
    return tree.num_nodes()


def test_octree_threads_work_in_forked_children():
    expected = _child_inserts(None)  # the parent's worker threads now exist
    with mp.get_context("fork").Pool(2) as pool:
        assert pool.map_async(_child_inserts, range(2)).get(timeout=240) == [expected] * 2


def test_read_ahead_keeps_order_errors_and_stops_early():
    made = []

    def items(n, fail_at=None):
        for k in range(n):
            if k == fail_at:
                raise ValueError(f"item {k}")
            made.append(k)
            yield k

    assert list(read_ahead(items(50))) == list(range(50))
    got = []
    with pytest.raises(ValueError, match="item 7"):
        for k in read_ahead(items(20, fail_at=7)):
            got.append(k)
    assert got == list(range(7))  # every item before the failure, then the failure
    made.clear()
    for k in read_ahead(items(10_000), depth=2):
        if k == 3:
            break
    assert len(made) <= 3 + 2 + 2  # the reader stopped a few items ahead, not at the end


def test_read_ahead_switches_threads_often_while_a_reader_runs_and_restores_the_interval():
    """A reader holding the GIL would keep the caller's kernels waiting 5 ms (Python's switch
    interval) each time they return: while any reader runs the interval is short; the caller's own
    interval comes back when the last reader stops, however they interleave, or at an error."""
    from occmap._threads import READ_AHEAD_SWITCH_INTERVAL

    before = sys.getswitchinterval()
    try:
        sys.setswitchinterval(0.004)
        seen = []
        outer = read_ahead(iter(range(3)))
        seen.append((next(outer), sys.getswitchinterval()))
        inner = read_ahead(iter(range(3)))
        seen.append((next(inner), sys.getswitchinterval()))
        outer.close()  # the first to start stops first: the other still runs
        seen.append(sys.getswitchinterval())
        assert list(inner) == [1, 2]
        short = pytest.approx(READ_AHEAD_SWITCH_INTERVAL, rel=1e-6)  # the interpreter keeps microseconds
        assert seen == [(0, short), (0, short), short]
        assert sys.getswitchinterval() == pytest.approx(0.004, rel=1e-6)

        def failing():
            yield 1
            raise ValueError("broken")

        with pytest.raises(ValueError):
            list(read_ahead(failing()))
        assert sys.getswitchinterval() == pytest.approx(0.004, rel=1e-6)
        sys.setswitchinterval(1e-5)  # a caller's shorter interval is kept
        inside = [sys.getswitchinterval() for _ in read_ahead(iter(range(2)))]
        assert inside == [pytest.approx(1e-5, rel=1e-6)] * 2
    finally:
        sys.setswitchinterval(before)


@pytest.mark.skipif(not hasattr(os, "sched_getaffinity") or len(os.sched_getaffinity(0)) < 2
                    or occmap._threads._current_cpu() is None, reason="needs two CPUs and a system that sets a thread's")
def test_share_keeps_its_worker_off_the_callers_cpu_until_the_callers_call_returns():
    """The worker runs on the CPUs it may use less the caller's while the caller works (Linux
    would often put it on the caller's CPU, another idle), and the caller stays on its own CPU
    (a wake-up from a worker would draw it to the worker's); both have them all back once the
    caller's own call returns, the worker while it still runs (so that a worker set aside never
    keeps the caller waiting for a CPU it may not use); a worker that has not started is
    cancelled."""
    caller = threading.get_native_id()
    full = os.sched_getaffinity(0)
    started = threading.Event()
    seen = {}

    def task():
        if threading.get_native_id() == caller:
            if not started.wait(10):
                pytest.skip("the worker did not start within 10 s")
            seen["caller's while it works"] = os.sched_getaffinity(0)
            return "caller"
        seen["while the caller works"] = os.sched_getaffinity(0)
        started.set()
        deadline = time.monotonic() + 10
        while os.sched_getaffinity(0) != full and time.monotonic() < deadline:
            time.sleep(0.001)
        seen["after the caller's call"] = os.sched_getaffinity(0)
        return "worker"

    assert occmap._threads.share(task, 2) == ["caller", "worker"]
    away = seen["while the caller works"]  # (the CPU the caller ran on when it called share)
    assert away < full and len(away) == len(full) - 1
    assert seen["caller's while it works"] == full - away
    assert seen["after the caller's call"] == full
    assert os.sched_getaffinity(0) == full


@pytest.mark.skipif(not hasattr(os, "sched_getaffinity") or len(os.sched_getaffinity(0)) < 2
                    or occmap._threads._current_cpu() is None, reason="needs two CPUs and a system that sets a thread's")
def test_share_keeps_its_pool_threads_off_the_callers_cpu_before_it_wakes_them():
    """The pool's threads (their native ids recorded as they start) are kept off the caller's CPU
    from the moment a call begins, before a task wakes one, and have their CPUs back when the
    call is released: a worker woken on the caller's CPU waited there behind the caller."""
    full = os.sched_getaffinity(0)
    occmap._threads.share(lambda: None, 2)  # (the pool's thread exists from here on)
    workers = occmap._threads._pool_threads["workers"]
    assert workers and threading.get_native_id() not in workers
    os.sched_setaffinity(0, {occmap._threads._current_cpu()})  # (the caller stays where it is)
    try:
        away = occmap._threads._Away(workers)
        caller = away._caller
        kept = [os.sched_getaffinity(tid) for tid in workers]
        away.release()
        back = [os.sched_getaffinity(tid) for tid in workers]
    finally:
        os.sched_setaffinity(0, full)
    assert kept == [full - {caller}] * len(workers)
    assert back == [full] * len(workers)
