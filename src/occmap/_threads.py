"""How occmap uses more than one core, in one place.

**Threading layer.** Numba's parallel kernels run on Intel TBB when the ``tbb`` package is there
(a dependency wherever it has wheels): TBB's threads steal work and sleep when idle, so a call
never spins waiting for a thread the scheduler has taken away, and a process that forks after a
parallel kernel (``multiprocessing``'s default on Linux) keeps working, where GNU OpenMP, Numba's
other layer, aborts the child. The ``tbb`` wheel puts ``libtbb.so.12`` into the environment's
``lib`` folder, which the dynamic loader does not search: :func:`prefer_tbb` loads it by path before
Numba picks its layer. ``NUMBA_THREADING_LAYER``, when the user sets it, wins. Without TBB,
OpenMP's threads are told to wait passively (``OMP_WAIT_POLICY``, unless set); a child forked
from a process whose kernels ran on OpenMP takes one thread (:func:`thread_count`).

**Threads per call.** Robots stream one scan per call on computers where other processes compete
for the cores: there a second thread waits for a core and a parallel call takes longer than one
thread would; on an idle machine it takes less. :class:`ThreadChoice` runs one thread while other
processes leave no second core free (:func:`free_cores`, as GNU OpenMP's ``OMP_DYNAMIC`` sizes its
teams by the load), and otherwise measures both paths of a kernel as the calls come and runs the
cheaper one, trying the other now and then. The load must be asked for, not learnt from the
kernel's time: a worker thread spins for a while after a parallel region (TBB), and beside a busy
process the main thread's next work, outside the kernel, pays for it (a local map's cycle beside
one busy process: its kernel as fast on two threads as on one, the cycle 15 % slower).

**One map, several threads.** Every map and the localizer derive from :class:`OneCallAtATime`:
each public method runs holding the object's lock, so calls from several threads on one object
take turns, each seeing the object as the previous call left it (insertions in some order, never
a mix). Different objects run side by side. The lock is per process: a child made by ``fork``
while another thread is inside a call must not use that object.

**Python worker threads** (for kernels that release the GIL and share work that Numba's
``prange`` cannot): :func:`share` runs a task on the calling thread and on pool threads at once,
keeps the pool threads off the calling thread's CPU while it works (:class:`_Away`), and never
waits for a pool thread that has not started. As many threads as Numba has
(``NUMBA_NUM_THREADS``, ``numba.set_num_threads``); pools are made per process, so a child made by
``fork`` has its own. :func:`read_ahead` reads a stream (a bag: Python, holding the GIL) on a
thread of its own while the caller's kernels (which release it) insert what was read.
"""

from __future__ import annotations

import ctypes
import functools
import inspect
import math
import os
import sys
import threading
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path
from time import monotonic, perf_counter, process_time

_TBB_SONAME = "libtbb.so.12"


def _tbb_library() -> Path | None:
    """Path of the ``tbb`` wheel's shared library, if installed."""
    try:
        dist = metadata.distribution("tbb")
    except metadata.PackageNotFoundError:
        return None
    for f in dist.files or ():
        if f.name == _TBB_SONAME:
            path = Path(dist.locate_file(f)).resolve()
            if path.is_file():
                return path
    candidate = Path(sys.prefix) / "lib" / _TBB_SONAME
    return candidate if candidate.is_file() else None


def prefer_tbb() -> str | None:
    """Make TBB available to Numba (see the module's docstring); returns the path loaded, or None
    when TBB is not installed, cannot be loaded, or the user chose a layer."""
    if os.environ.get("NUMBA_THREADING_LAYER"):
        return None
    path = _tbb_library() if sys.platform.startswith("linux") else None
    if path is not None:
        try:
            ctypes.CDLL(str(path), mode=ctypes.RTLD_GLOBAL)
            return str(path)
        except OSError:
            pass
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    return None


#: Weight of the newest call in a path's average cost.
_ALPHA = 0.3
#: Calls between tries of the path that is not chosen: at first, and at most (the interval
#: doubles each time a try confirms the choice, and starts again when a try changes it).
_FIRST_INTERVAL = 8
_MAX_INTERVAL = 256


#: Cores other processes must leave free for a call to take several threads: with half a core
#: taken, a second thread's half of the work runs at about half speed and the parallel call is no
#: faster than one thread.
_FREE_FOR_PARALLEL = 1.5
#: Seconds over which :func:`free_cores` averages the other processes' load (at least).
_LOAD_WINDOW = 0.1


class _Load:
    """The CPU time other processes take on the CPUs this process may run on: ``/proc/stat``'s
    busy ticks of those CPUs less this process's own CPU time, over windows of at least
    :data:`_LOAD_WINDOW` seconds (the last full window's figure is kept between samples)."""

    def __init__(self):
        self._cpus = None
        self._last = None  # (monotonic s, busy s of our CPUs, our CPU s)
        self.free = None

    def sample(self) -> float | None:
        now = monotonic()
        if self._last is not None and now - self._last[0] < _LOAD_WINDOW:
            return self.free
        busy = self._busy_seconds()
        if busy is None:
            return None
        mine = process_time()
        if self._last is not None:
            wall = now - self._last[0]
            others = max(0.0, (busy - self._last[1]) - (mine - self._last[2])) / wall
            self.free = len(self._cpus) - others
        self._last = (now, busy, mine)
        return self.free

    def _busy_seconds(self) -> float | None:
        """Seconds the CPUs this process may use have been busy since boot (user, nice, system,
        irq, softirq and steal: time a thread of ours could not have had); None off Linux."""
        if self._cpus == frozenset():  # tried: no /proc/stat here
            return None
        try:
            if self._cpus is None:
                self._cpus = {f"cpu{i}".encode() for i in os.sched_getaffinity(0)}
                self._tick = 1.0 / os.sysconf("SC_CLK_TCK")
            with open("/proc/stat", "rb") as f:
                text = f.read()
        except (OSError, AttributeError, ValueError):
            self._cpus = frozenset()
            return None
        ticks = 0
        for line in text.split(b"\n"):
            if not line.startswith(b"cpu"):
                break
            name, *fields = line.split()
            if name in self._cpus:
                user, nice, system, _idle, _iowait, irq, softirq, steal = (int(v) for v in fields[:8])
                ticks += user + nice + system + irq + softirq + steal
        return ticks * self._tick


_load = _Load()
_load.sample()  # (the first window starts here: a program's first calls, a tenth of a second on, find a figure)


def free_cores() -> float | None:
    """Cores of those this process may run on that other processes have left free lately
    (about the last :data:`_LOAD_WINDOW` seconds); None where the system does not say (not
    Linux) or before a window has passed."""
    return _load.sample()


class ThreadChoice:
    """Chooses, call by call, between a kernel's one-thread and many-thread paths: whichever has
    cost less per unit of work lately (an exponential average of the measured calls).

    Calls with less than ``min_work`` units of work, with Numba limited to one thread, or while
    other processes leave fewer than :data:`_FREE_FOR_PARALLEL` cores free (:func:`free_cores`),
    take one thread and are not measured; inside :func:`forced_path` the others take the path it
    names, unmeasured. The first call takes several threads unmeasured: it pays for
    first-touch page faults and thread start-up (a grid's parallel path looked 3× slower than one
    thread after it, where it is 1.4–1.7× faster). So does a call that is not a fair ``sample``
    (the caller knows it writes memory never touched before: a grid's first call after it grew
    cost 5–15× more a cell walked). The next calls try each path once; after that the
    other path is tried again every few calls, from every 8th call up to every 256th while it
    stays the slower one, so that a change in the machine's load is noticed. Both paths must give
    the same result: only the time differs. Safe to share between threads (a race only blurs an
    average).

    Examples
    --------
    >>> choice = ThreadChoice(min_work=20_000)
    >>> with choice.choose(work=cells) as parallel:   # doctest: +SKIP
    ...     kernel(..., parallel)
    """

    def __init__(self, min_work: float):
        self.min_work = float(min_work)
        self._cost = [math.nan, math.nan]  # seconds per unit of work: one thread, several
        self._since = 0
        self._interval = _FIRST_INTERVAL
        self._warm = False

    def forget(self) -> None:
        """Forget what the calls taught, as a new process starts: the next call is again a first
        call (a benchmark that times two ways of making a map gives each the state the command's
        fresh process has, not the state the other left)."""
        self.__init__(self.min_work)

    @property
    def costs(self) -> tuple[float, float]:
        """Average seconds per unit of work on one thread and on several (NaN: not measured)."""
        return self._cost[0], self._cost[1]

    @contextmanager
    def choose(self, work: float, sample: bool = True):
        """Yields whether the block should run on several threads; times the block and learns
        from it (unless ``sample`` is false: the path chosen now, not timed)."""
        if not work >= self.min_work or thread_count() < 2:
            yield False
            return
        if _forced is not None:
            yield _forced
            return
        if not free_for_parallel():
            yield False
            return
        if not (self._warm and sample):  # the first call starts Numba's threads: not a fair sample either
            self._warm = True
            yield self._best()
            return
        parallel, trying = self._pick()
        start = perf_counter()
        yield parallel
        self._learn(parallel, trying, (perf_counter() - start) / work)

    def _best(self) -> bool:
        """Whether several threads have cost less than one lately (several while either path is
        unmeasured)."""
        serial, several = self._cost
        return not serial <= several

    def _pick(self) -> tuple[bool, bool]:
        serial, several = self._cost
        if math.isnan(several):
            return True, True
        if math.isnan(serial):
            return False, True
        best = self._best()
        self._since += 1
        if self._since >= self._interval:
            self._since = 0
            return not best, True
        return best, False

    def _learn(self, parallel: bool, trying: bool, cost: float) -> None:
        i = int(parallel)
        before = self._cost[1] < self._cost[0]
        old = self._cost[i]
        self._cost[i] = cost if math.isnan(old) else old + _ALPHA * (cost - old)
        if trying and not (math.isnan(old) or math.isnan(self._cost[1 - i])):  # a try, not a first measurement
            changed = (self._cost[1] < self._cost[0]) != before
            self._interval = _FIRST_INTERVAL if changed else min(2 * self._interval, _MAX_INTERVAL)


_forced: bool | None = None


@contextmanager
def forced_path(parallel: bool):
    """Within the block, this process's :class:`ThreadChoice` blocks with enough work take the
    given path, whatever the load and the costs, and learn nothing; and :func:`free_for_parallel`
    answers ``parallel``, so the octree's scans take that path too. (``occmap warmup`` runs each
    job once on each path: every kernel of both paths gets compiled, with every argument type,
    however many calls a job makes and however busy its own processes keep the cores.)"""
    global _forced
    before, _forced = _forced, bool(parallel)
    try:
        yield
    finally:
        _forced = before


def free_for_parallel() -> bool:
    """Whether other processes leave at least :data:`_FREE_FOR_PARALLEL` cores free lately
    (:func:`free_cores`; where the system does not say, True): below that, a call split between
    threads waits for a thread the scheduler has set aside, and one thread is the faster. Inside
    :func:`forced_path`, the path it names."""
    if _forced is not None:
        return _forced
    free = free_cores()
    return free is None or free >= _FREE_FOR_PARALLEL


def thread_count() -> int:
    """Threads a call may use: Numba's count for this thread (``numba.set_num_threads``); one in
    a child forked from a process whose parallel kernels ran on OpenMP (see :func:`_forked`)."""
    if _forked_from_openmp:
        return 1
    from numba import get_num_threads

    return get_num_threads()


_pools: dict[str, ThreadPoolExecutor] = {}
_forked_from_openmp = False


def _forked() -> None:
    """In a child made by ``fork``: the parent's pool threads (and its calls keeping workers away,
    :class:`_Away`) do not exist here, and its load windows start anew; and where the
    parent ran parallel kernels on OpenMP (Numba started before occmap could load TBB, e.g. a
    caller's own parallel code ran first), a parallel region would abort the child (GNU OpenMP),
    so the child's calls take one thread."""
    global _forked_from_openmp, _load
    _pools.clear()
    _pool_threads.clear()
    _load = _Load()  # (the parent's figures count the parent's own CPU time, not the child's)
    _load.sample()
    _Away._active, _Away._active_lock = None, threading.Lock()  # (a parent's thread may have held the lock)
    if "numba" in sys.modules and not _forked_from_openmp:
        try:
            _forked_from_openmp = sys.modules["numba"].threading_layer() == "omp"
        except ValueError:  # no parallel kernel has run: no layer yet
            pass


os.register_at_fork(after_in_child=_forked)


def pool(name: str, workers: int) -> ThreadPoolExecutor:
    """This process's pool of ``workers`` threads named ``occmap-{name}``, made on first use; the
    native ids of its threads started so far in :data:`_pool_threads` under ``name``."""
    if name not in _pools:
        threads = _pool_threads[name] = []
        _pools[name] = ThreadPoolExecutor(max_workers=workers, thread_name_prefix=f"occmap-{name}",
                                          initializer=lambda: threads.append(threading.get_native_id()))
    return _pools[name]


_pool_threads: dict[str, list[int]] = {}


def share(task, threads: int | None = None) -> list:
    """Call ``task()`` on this thread and on up to ``threads − 1`` worker threads at once (default:
    Numba's thread count) and return the results of the calls that ran, this thread's first.

    ``task`` must take its work from a queue that the calls share (e.g. a ``collections.deque``
    of ranges), so that whichever calls run do all of it: a worker that has not started when this
    thread's call returns is cancelled, so no call waits for a thread the scheduler has not run.
    The workers run away from this thread's CPU, and this thread on it, until its call returns
    (:class:`_Away`).
    """
    n = thread_count() if threads is None else threads
    futures = []
    away = None
    if n > 1:
        helpers = pool("workers", max(_max_threads() - 1, 1))
        away = _Away(_pool_threads["workers"])
        futures = [helpers.submit(away.run, task) for _ in range(n - 1)]
        away.hold()
    results = [task()]
    if away is not None:
        away.release()
    results += [f.result() for f in futures if not f.cancel()]
    return results


class _Away:
    """Workers of one :func:`share` call kept off the calling thread's CPU while it works.

    Linux wakes a pool thread on the CPU of the thread that woke it, or the load balancer soon
    puts the two together, while another CPU stays idle: on this 2-core virtual machine a worker
    shared the caller's CPU in most calls after a pause (a 5 ms kernel on each of two threads took
    9 – 10 ms of wall time, for 5 ms of CPU time each), and scan.dat at 0.2 m took 8.5 – 12.3 ms
    on two threads against 6.9 – 7.7 with the workers kept away (medians of 12 rounds after
    pauses). Each worker limits itself to the CPUs it may use less the caller's while it runs
    ``task``; when the caller's own call returns, the workers still running get their CPUs back
    (:meth:`release`), so that one the scheduler has set aside may move to the caller's CPU rather
    than keep the caller waiting. Where the system cannot say or set CPUs, workers run as placed."""

    #: The call whose workers are kept away now, if any: one at most (two calls at once, e.g. the
    #: next scan traced while the tree takes this one, keep none away: pinned, their threads waited
    #: on each other's CPUs, and the HDL-32E pair at 0.1 m took 1.13x the time).
    _active: _Away | None = None
    _active_lock = threading.Lock()

    def __init__(self, workers=()):
        """Kept away from the calling thread's CPU: the threads (native ids) of ``workers`` now,
        before they are woken (a thread woken by the caller lands on the caller's CPU, where it
        waited behind the caller, held there, for milliseconds: 3 - 4 ms, one call in three, the
        other CPU idle), and any other worker when it starts :meth:`run`."""
        self._lock = threading.Lock()
        self._released = False
        self._workers: dict[int, set] = {}  # native thread id → its own CPUs
        self._held: tuple[int, set] | None = None  # the caller's, while held on its CPU
        self._caller = _current_cpu()
        with _Away._active_lock:
            other = _Away._active
            _Away._active = self if other is None else None
        if other is not None:
            self._released = True
            other.release()
        with self._lock:
            for tid in workers:
                self._keep_away(tid)

    def run(self, task):
        """``task()`` on this worker, off the caller's CPU unless released."""
        tid = threading.get_native_id()
        with self._lock:
            if tid not in self._workers:
                self._keep_away(tid)
        try:
            return task()
        finally:
            with self._lock:
                mask = self._workers.pop(tid, None)
                if mask is not None:
                    _set_cpus(tid, mask)

    def _keep_away(self, tid: int) -> None:
        """Thread ``tid`` limited to the CPUs it may use but the caller's unless released (its
        CPUs before kept, to be given back)."""
        mask = self._limit(tid, away=True)
        if mask is not None:
            self._workers[tid] = mask

    def hold(self) -> None:
        """The calling thread kept on its CPU until :meth:`release`: unheld, it was drawn to a
        worker's (a thread woken by another lands on the waker's CPU: the GIL passed from a worker
        to the caller between two runs of a task took it there), and the two shared that CPU, the
        other idle, for milliseconds (scan.dat at 0.2 m: 19 - 21 ms against 10 - 13 in one round
        of four)."""
        with self._lock:
            tid = threading.get_native_id()
            mask = self._limit(tid, away=False)
            if mask is not None:
                self._held = tid, mask

    def _limit(self, tid: int, away: bool) -> set | None:
        """Thread ``tid`` limited to the CPUs it may use but the caller's (``away``) or to the
        caller's alone, unless released: its CPUs before, or None where it is left as placed
        (released, no other CPU, a thread that has ended, or a system that cannot say or set
        them)."""
        if self._released or self._caller is None:
            return None
        try:
            mask = os.sched_getaffinity(tid)
            if not mask - {self._caller}:
                return None
            os.sched_setaffinity(tid, mask - {self._caller} if away else {self._caller})
            return mask
        except OSError:
            return None

    def release(self) -> None:
        """The workers still running, and the caller, given their CPUs back; none started later is
        kept away."""
        with self._lock:
            self._released = True
            for tid, mask in list(self._workers.items()) + ([self._held] if self._held else []):
                _set_cpus(tid, mask)
            self._workers.clear()
            self._held = None
        with _Away._active_lock:
            if _Away._active is self:
                _Away._active = None


def _set_cpus(tid: int, cpus: set) -> None:
    """Thread ``tid`` (0: this one) allowed onto ``cpus``; nothing where that thread has just
    ended or the system refuses."""
    try:
        os.sched_setaffinity(tid, cpus)
    except OSError:
        pass


def _current_cpu() -> int | None:
    """The CPU this thread runs on (the C library's ``sched_getcpu``), or None where the system
    cannot say or cannot set a thread's CPUs."""
    if _sched_getcpu is None:
        return None
    cpu = _sched_getcpu()
    return cpu if cpu >= 0 else None


def _libc_sched_getcpu():
    if not hasattr(os, "sched_setaffinity"):
        return None
    try:
        return ctypes.CDLL(None).sched_getcpu
    except (OSError, AttributeError, TypeError):
        return None


_sched_getcpu = _libc_sched_getcpu()


def run_jobs(jobs, threads: int | None = None) -> list:
    """The results of the callables ``jobs``, in their order, each called once on this thread or
    a worker thread as :func:`share` runs them."""
    queue = deque(enumerate(jobs))
    results = [None] * len(queue)

    def take():
        while True:
            try:
                i, job = queue.popleft()
            except IndexError:
                return
            results[i] = job()

    share(take, threads)
    return results


#: The interpreter's switch interval (seconds) while a :func:`read_ahead` reader runs: Python's
#: 5 ms default lets the reader, which holds the GIL while it parses, keep the caller waiting that
#: long each time a kernel returns (a map from a bag: 1.44x the insertion alone, 1.13x at 0.1 ms)
READ_AHEAD_SWITCH_INTERVAL = 1e-4
_switch_lock = threading.Lock()
_switch_users = [0, 0.0]  # readers running, the interval before the first


@contextmanager
def _short_switch_interval():
    """The switch interval at :data:`READ_AHEAD_SWITCH_INTERVAL` (never longer than it was) while
    any reader runs; the one before back when the last stops."""
    with _switch_lock:
        if _switch_users[0] == 0:
            _switch_users[1] = sys.getswitchinterval()
            sys.setswitchinterval(min(_switch_users[1], READ_AHEAD_SWITCH_INTERVAL))
        _switch_users[0] += 1
    try:
        yield
    finally:
        with _switch_lock:
            _switch_users[0] -= 1
            if _switch_users[0] == 0:
                sys.setswitchinterval(_switch_users[1])


def read_ahead(items, depth: int = 2):
    """Iterate ``items`` on a reader thread, at most ``depth`` items ahead of the caller: the
    same items in the same order, and an exception ``items`` raises surfaces here, where its item
    would have. Stopping early (``break``, an error) stops the reader at its next item. While the
    reader runs, the interpreter switches threads every :data:`READ_AHEAD_SWITCH_INTERVAL`
    seconds, so that the caller's kernels get the GIL back soon after they return."""
    import queue

    ready: queue.Queue = queue.Queue(maxsize=depth)
    stop = threading.Event()
    end = object()

    def read():
        try:
            for item in items:
                ready.put((item, None))
                if stop.is_set():
                    return
            ready.put((end, None))
        except BaseException as e:  # handed to the caller, raised there
            ready.put((end, e))

    reader = threading.Thread(target=read, name="occmap-read-ahead", daemon=True)
    with _short_switch_interval():
        reader.start()
        try:
            while True:
                item, error = ready.get()
                if item is end:
                    if error is not None:
                        raise error
                    return
                yield item
        finally:
            stop.set()
            while reader.is_alive():  # free a put blocked on a full queue
                try:
                    ready.get(timeout=0.01)
                except queue.Empty:
                    pass


def _max_threads() -> int:
    from numba import config

    return config.NUMBA_NUM_THREADS


class OneCallAtATime:
    """Base class: each public method (a plain function defined by a subclass) runs holding the
    object's re-entrant lock (see the module's docstring), except those marked :func:`no_lock`.
    Pickling leaves the lock out and an unpickled object gets its own."""

    def __new__(cls, *args, **kwargs):
        self = super().__new__(cls)
        self._lock = threading.RLock()
        return self

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        for name, value in list(vars(cls).items()):
            if not name.startswith("_") and inspect.isfunction(value) and not getattr(value, "_no_lock", False):
                setattr(cls, name, _holding_lock(value))

    def __getstate__(self):
        state = dict(self.__dict__)
        del state["_lock"]
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._lock = threading.RLock()


def no_lock(method):
    """Mark a method of a :class:`OneCallAtATime` class that reads nothing a call can change
    (arithmetic on constants fixed at construction): it runs without the lock, so the worker
    threads of a call holding it may use it."""
    method._no_lock = True
    return method


def _holding_lock(method):
    @functools.wraps(method)
    def locked(self, *args, **kwargs):
        with self._lock:
            return method(self, *args, **kwargs)

    return locked

