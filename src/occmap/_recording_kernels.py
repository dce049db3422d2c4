"""Numba kernel of the mapping recording (:mod:`occmap.mapping2d_recording`): plain arrays in."""

from __future__ import annotations

from ._jit import kernel


@kernel
def changed_log_odds(window, last, out):
    """The cells of ``window`` (log-odds (h, w), NaN unknown) that are known and differ from
    ``last`` (the same box of the last state, updated in place): their flat indices into
    ``window`` go to ``out`` (h·w long at least), in order; returns how many."""
    h, w = window.shape
    n = 0
    for r in range(h):
        for c in range(w):
            v = window[r, c]
            if v == v and v != last[r, c]:  # a known cell never turns unknown: NaN is "unchanged"
                last[r, c] = v
                out[n] = r * w + c
                n += 1
    return n
