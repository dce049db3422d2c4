"""A clock for the work alone: the figures occmap prints leave out compiling and loading kernels."""

from __future__ import annotations

import time
from contextlib import contextmanager


class WorkClock:
    """Accumulates the wall time of the blocks it runs, minus the time Numba held its compiler
    lock in them: compiling a kernel or loading it from the on-disk cache (the first call of
    each kernel in a process does one or the other). ``seconds`` is the total so far.

    >>> clock = WorkClock()
    >>> with clock.running():
    ...     pass
    """

    def __init__(self) -> None:
        self.seconds = 0.0

    @contextmanager
    def running(self):
        from numba.core.event import install_timer

        loading: list[float] = []
        t0 = time.perf_counter()
        with install_timer("numba:compiler_lock", loading.append):
            yield self
        self.seconds += time.perf_counter() - t0 - sum(loading)
