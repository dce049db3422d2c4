"""The clamped log-odds cell update and the per-scan stamps, shared by the 2D maps (grid
conventions in :mod:`occmap.raster`).

Update: ``l ← min(max(l + d, lo), hi)`` with ``d = l_sensor − l_prior`` (``DESIGN.md``'s log-odds
rule); the maps pass ``d`` and the bounds in the scale they store (the local map's cells hold a
scaled log-odds).

Stamps: each cell has an integer stamp beside its log-odds. :data:`UNSEEN` (0) means never
observed, :data:`SEEN` (1) observed before every scan still to come; within the scan of code
``s ≥ 1`` a miss writes ``2s`` and a hit ``2s + 1``. A scan applies its hits first, then its
misses, so one compare says both "already updated in this scan" and "a hit wins over a miss":
each cell is updated at most once per scan, whatever the order of its beams. Codes rise from
scan to scan; :class:`ScanCodes` hands them out and starts again when the stamp's dtype runs out.

In a kernel, with ``L`` and ``S`` a map's log-odds and stamps and ``i`` a cell::

    if S[i] < miss_stamp(s):          # a miss (a hit: S[i] != hit_stamp(s))
        S[i] = miss_stamp(s)
        L[i] = clamp_add(L[i], d, lo, hi)

The helpers take scalars, not arrays: inlined into a loop they cost nothing, where a helper
taking the arrays (inlined or not) made the grid's walk 9× slower.
"""

from __future__ import annotations

import numpy as np

from .._jit import inline_kernel

__all__ = ["UNSEEN", "SEEN", "clamp_add", "hit_stamp", "miss_stamp", "ScanCodes"]

#: Stamp of a cell no reading has touched.
UNSEEN = 0
#: Stamp of a cell observed before every scan still to come (below every scan's codes).
SEEN = 1


@inline_kernel
def clamp_add(l, d, lo, hi):
    """``l + d`` clamped to ``[lo, hi]``."""
    return min(max(l + d, lo), hi)


@inline_kernel
def hit_stamp(s):
    """The stamp of a cell hit by scan ``s``; a hit updates a cell whose stamp differs from it."""
    return 2 * s + 1


@inline_kernel
def miss_stamp(s):
    """The stamp of a cell missed by scan ``s``; a miss updates a cell whose stamp is below it
    (neither hit nor missed by this scan)."""
    return 2 * s


class ScanCodes:
    """The scan codes of one map's stamps of integer ``dtype``: 1, 2, … up to the last whose hit
    stamp ``2s + 1`` fits the dtype; once they are used up every observed cell's stamp drops to
    :data:`SEEN` and the codes start again at 1."""

    def __init__(self, dtype):
        #: The last code the dtype can hold.
        self.last = (int(np.iinfo(dtype).max) - 1) // 2
        #: The code handed out last (0: none yet).
        self.code = 0

    def take(self, n: int, stamps: np.ndarray) -> tuple[int, int]:
        """Codes for the next ``k`` of ``n ≥ 1`` scans: returns ``(first code, k)``, ``1 ≤ k ≤ n``
        (fewer than ``n`` when the codes run out; ask again for the rest). ``stamps`` (the map's
        stamps, or a view of them) are lowered first when no code is left."""
        if self.code == self.last:
            np.minimum(stamps, SEEN, out=stamps)
            self.code = 0
        k = min(n, self.last - self.code)
        first = self.code + 1
        self.code += k
        return first, k
