"""Resampling a particle cloud: low-variance selection, Fox's KLD particle count, Gordon's roughening.

Particles are poses ``(N, 3)`` ``(x, y, theta)``; weights ``(N,)`` sum to 1; every random draw comes
from the ``rng`` passed in, so a seeded filter repeats itself exactly.
"""

from __future__ import annotations

import math

import numpy as np

from ..geometry.so2 import wrap_angle
from . import _kernels as K

__all__ = ["kld_count", "roughen", "systematic"]

#: KLD's histogram bins: 0.5 m × 0.5 m × 10°, as AMCL's.
KLD_BIN_XY = 0.5
KLD_BIN_THETA = math.radians(10.0)


def systematic(weights: np.ndarray, m: int, rng: np.random.Generator) -> np.ndarray:
    """Indices (m,) of low-variance (systematic) resampling: one uniform draw, then evenly spaced
    (Thrun et al., *Probabilistic Robotics* table 4.4)."""
    cum = np.cumsum(weights)
    cum /= cum[-1]
    idx = np.empty(m, dtype=np.int64)
    K.systematic_indices(cum, float(rng.random()), idx)
    return idx


def kld_count(samples: np.ndarray, kld_err: float, kld_z: float, lo: int, hi: int) -> int:
    """Fox's KLD bound (Fox 2003): the smallest prefix of ``samples`` at least as long as the
    count its own occupied bins call for, clipped to ``[lo, hi]``."""
    keys = np.floor(samples[:, 0] / KLD_BIN_XY).astype(np.int64) * 1_000_003
    keys = (keys + np.floor(samples[:, 1] / KLD_BIN_XY).astype(np.int64)) * 1_000_033
    keys += np.floor(samples[:, 2] / KLD_BIN_THETA).astype(np.int64)
    _, first = np.unique(keys, return_index=True)
    new = np.zeros(len(samples), dtype=np.int64)
    new[first] = 1
    k = np.cumsum(new)
    km1 = np.maximum(k - 1, 1).astype(np.float64)
    b = 2.0 / (9.0 * km1)
    need = km1 / (2.0 * kld_err) * (1.0 - b + np.sqrt(b) * kld_z) ** 3
    need = np.where(k <= 1, 1.0, need)
    enough = np.flatnonzero(np.arange(1, len(samples) + 1) >= need)
    n = int(enough[0]) + 1 if enough.size else len(samples)
    return int(min(max(n, lo), hi))


def roughen(parts: np.ndarray, k: float, rng: np.random.Generator) -> None:
    """Gordon, Salmond & Smith's roughening, in place: each particle jittered by a Gaussian of
    standard deviation ``k · E · N^(−1/3)`` per dimension, ``E`` the cloud's 2nd–98th percentile
    spread (the heading's about its circular mean)."""
    n = len(parts)
    lo, hi = np.percentile(parts[:, :2], [2.0, 98.0], axis=0)
    mean_t = math.atan2(np.sin(parts[:, 2]).mean(), np.cos(parts[:, 2]).mean())
    dt = wrap_angle(parts[:, 2] - mean_t)
    tlo, thi = np.percentile(dt, [2.0, 98.0])
    spread = np.array([hi[0] - lo[0], hi[1] - lo[1], thi - tlo])
    sigma = k * spread * n ** (-1.0 / 3.0)
    parts += rng.standard_normal((n, 3)) * sigma
    parts[:, 2] = wrap_angle(parts[:, 2])
