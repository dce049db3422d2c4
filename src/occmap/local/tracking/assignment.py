"""Global nearest-neighbour assignment of detections to tracks under a gate.

Pairs whose cost is infinite (outside the gate) are never matched. Among all matchings the one
with the most pairs is chosen, and among those the one of least total cost: gated-out entries are
replaced by a cost larger than any sum of allowed ones, so the optimal assignment
(:func:`~occmap.local.tracking._kernels.min_cost_assignment`) takes one only where a row has no
allowed column left, and such pairs are dropped.
"""

from __future__ import annotations

import numpy as np

from ...errors import InvalidArgumentError, ShapeError
from . import _kernels as K

__all__ = ["assign"]


def assign(cost) -> tuple[np.ndarray, np.ndarray]:
    """Matched ``(rows, cols)`` of a cost matrix ``(n, m)`` (``inf`` = not allowed), sorted by row.

    >>> assign([[1.0, np.inf], [0.5, 2.0]])
    (array([0, 1]), array([0, 1]))
    """
    c = np.asarray(cost, dtype=np.float64)
    if c.ndim != 2:
        raise ShapeError(f"cost must be a matrix (n, m), got shape {c.shape}")
    if np.isnan(c).any() or (c == -np.inf).any():
        raise InvalidArgumentError("cost holds NaN or -inf")
    k = min(c.shape)
    rows, cols = np.empty(k, np.int64), np.empty(k, np.int64)
    k = K.gated_assignment(np.ascontiguousarray(c), rows, cols)
    return rows[:k], cols[:k]
