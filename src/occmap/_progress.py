"""A progress line on stderr for the commands: a bar, the count, the rate and the time left,
redrawn at most five times a second, and only when stderr is a terminal (pipes and logs get the
summary alone)."""

from __future__ import annotations

import sys
import time


class Progress:
    """``update(done)`` as items (``unit``, e.g. ``"scans"``) are done out of ``total`` (None when
    unknown: no bar, no time left); ``close()`` ends the line. ``enabled`` defaults to whether
    stderr is a terminal."""

    def __init__(self, total: int | None, unit: str, enabled: bool | None = None):
        self.total = total
        self.unit = unit
        self.enabled = sys.stderr.isatty() if enabled is None else enabled
        self._t0 = time.perf_counter()
        self._shown = -1.0
        self._drawn = False

    def update(self, done: int, extra: str = "") -> None:
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self._shown < 0.2 and not (self.total and done >= self.total):
            return
        self._shown = now
        elapsed = now - self._t0
        rate = done / elapsed if elapsed > 0 else 0.0
        if self.total:
            frac = min(done / self.total, 1.0)
            left = (self.total - done) / rate if rate > 0 else float("nan")
            text = (f"[{'#' * int(30 * frac):<30s}] {100 * frac:5.1f}% {done:,}/{self.total:,} {self.unit}, "
                    f"{rate:,.0f}/s, {_duration(left)} left")
        else:
            text = f"{done:,} {self.unit}, {rate:,.0f}/s"
        print(f"\r{text}{', ' + extra if extra else ''}\033[K", end="", file=sys.stderr, flush=True)
        self._drawn = True

    def close(self) -> None:
        if self._drawn:
            print(file=sys.stderr)
            self._drawn = False


def _duration(seconds: float) -> str:
    if seconds != seconds:  # NaN: nothing done yet
        return "?"
    seconds = int(round(seconds))
    return f"{seconds // 60}:{seconds % 60:02d}" if seconds >= 60 else f"{seconds} s"
