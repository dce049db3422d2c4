"""Log-odds and probability: ``l = log(p / (1 − p))`` and back, ``p = 1 / (1 + exp(−l))``.

Every map keeps occupancy as log-odds, so Bayes' update is an addition (Thrun et al.,
*Probabilistic Robotics* §4.2). Scalars go through :mod:`math` and are checked
(:func:`occmap.checks.probability`: a probability strictly between 0 and 1, ``np.float32``
accepted); arrays go through NumPy element by element, in float64, unchecked (0 and 1 give ∓inf).

OctoMap keeps its parameters and nodes as **float32 log-odds computed in float64**
(``(float) log(p / (1 - p))`` in ``octomap_utils.h``); :func:`logit32` reproduces that rounding, so
an occmap octree holds OctoMap's values to the bit: 0.7 → 0.84729785, 0.4 → −0.4054651,
0.1192 → −2.000028, 0.971 → 3.5110307 (log-odds computed in float32 would differ in the last bit
for 0.7, 0.4 and 0.971).
"""

from __future__ import annotations

import math

import numpy as np

from .checks import probability as _check_probability

__all__ = ["logit", "logit32", "occupancy_classes", "probability"]


def logit(p, name: str = "probability"):
    """Log-odds ``log(p / (1 − p))``: a float for a scalar ``p`` (checked, ``name`` in the
    error), a float64 array for an array."""
    if np.ndim(p) == 0:
        v = _check_probability(name, p)
        return math.log(v / (1.0 - v))
    a = np.asarray(p, dtype=np.float64)
    return np.log(a / (1.0 - a))


def logit32(p, name: str = "probability") -> np.float32:
    """OctoMap's log-odds of a scalar probability: computed in float64, stored as float32."""
    return np.float32(logit(p, name))


def probability(l):
    """Probability ``1 / (1 + exp(−l))`` of log-odds ``l``: a float for a scalar, a float64 array
    for an array (float32 maps are widened first)."""
    if np.ndim(l) == 0:
        try:
            return 1.0 / (1.0 + math.exp(-float(l)))
        except OverflowError:  # l below about −709: as NumPy's inf gives
            return 0.0
    with np.errstate(over="ignore"):
        return 1.0 / (1.0 + np.exp(-np.asarray(l, dtype=np.float64)))


def occupancy_values(l) -> np.ndarray:
    """nav_msgs/OccupancyGrid values (int8) of log-odds ``l`` (NaN: unknown): −1 unknown, else
    ``round(100·p)`` in 0 … 100 — what every 2D map's ``occupancy()`` holds."""
    l = np.asarray(l)
    unknown = np.isnan(l)
    out = np.rint(100.0 * probability(np.where(unknown, 0.0, l))).astype(np.int8)
    out[unknown] = -1
    return out


def occupancy_classes(l, l_occupied) -> np.ndarray:
    """What every map's ``occupancy_at`` answers, per log-odds ``l`` (NaN: unknown): int8 −1
    unknown, 1 occupied (``l ≥ l_occupied``), else 0 free."""
    l = np.asarray(l)
    out = np.where(l >= l_occupied, 1, 0).astype(np.int8)
    out[np.isnan(l)] = -1
    return out
