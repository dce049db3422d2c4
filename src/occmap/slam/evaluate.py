"""Accuracy of a trajectory against a reference: the relative pose error over segments of travel.

Kümmerle et al., "On measuring the accuracy of SLAM algorithms" (Autonomous Robots 27, 2009)
compare the *relative* motions ``δᵢⱼ = xᵢ⁻¹ ⊕ xⱼ`` of an estimate with those of the reference,
``εᵢⱼ = (δ*ᵢⱼ)⁻¹ ⊕ δᵢⱼ``, instead of the poses themselves: the measure does not depend on the
frame either trajectory is expressed in, and an error made once counts once, not at every later
pose. Here the pairs are, for every pose ``i``, the first later pose ``j`` at least ``distance``
metres of travel along the reference away (the "1 m segments" of the Freiburg SLAM benchmark).
The translation error of a pair is ``‖t(εᵢⱼ)‖`` (m), its rotation error ``|θ(εᵢⱼ)|`` (rad).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .. import checks
from ..errors import ShapeError
from ..geometry.se2 import SE2

__all__ = ["RelativePoseError", "relative_pose_error"]


class RelativePoseError(NamedTuple):
    """Per-segment errors of :func:`relative_pose_error` and their summary.

    Attributes
    ----------
    start, end : ndarray (k,) int64
        The pose indices ``i``, ``j`` of each segment.
    translation : ndarray (k,)
        ``‖t(εᵢⱼ)‖`` per segment, metres.
    rotation : ndarray (k,)
        ``|θ(εᵢⱼ)|`` per segment, radians.
    """

    start: np.ndarray
    end: np.ndarray
    translation: np.ndarray
    rotation: np.ndarray

    def summary(self) -> dict:
        """Mean, standard deviation, RMS and maximum of each error (translation in m, rotation
        in degrees, as the benchmark reports them) and the number of segments."""
        out = {"segments": int(self.start.size)}
        for name, v in (("translation", self.translation), ("rotation_deg", np.degrees(self.rotation))):
            if v.size == 0:
                out.update({f"{name}_{k}": np.nan for k in ("mean", "std", "rms", "max")})
                continue
            out.update({f"{name}_mean": float(v.mean()), f"{name}_std": float(v.std()),
                        f"{name}_rms": float(np.sqrt(np.mean(v * v))), f"{name}_max": float(v.max())})
        return out


def relative_pose_error(poses, reference, distance: float = 1.0) -> RelativePoseError:
    """The relative pose error of ``poses`` (N, 3) against ``reference`` (N, 3) over segments of
    ``distance`` metres travelled along the reference (see the module's description).

    Pairs are ``(i, j)`` with ``j`` the first index whose path length along the reference from
    ``i`` is at least ``distance``; poses near the end with no such ``j`` start no segment.
    Rows with a non-finite pose in either trajectory take part in no segment.

    Raises
    ------
    ShapeError
        When the two are not (N, 3) of one N.
    InvalidArgumentError
        When ``distance`` is not positive (from :func:`occmap.checks.positive`).
    """
    est = np.asarray(poses, dtype=np.float64)
    ref = np.asarray(reference, dtype=np.float64)
    if est.ndim != 2 or est.shape[1:] != (3,) or ref.shape != est.shape:
        raise ShapeError(f"poses and reference must both be (N, 3) of one N, got {est.shape} and {ref.shape}")
    distance = checks.positive("distance", distance, "metres")
    good = np.isfinite(est).all(axis=1) & np.isfinite(ref).all(axis=1)
    est, ref = est[good], ref[good]
    index = np.flatnonzero(good)
    if len(ref) < 2:
        return RelativePoseError(*(np.zeros(0, dtype=np.int64),) * 2, np.zeros(0), np.zeros(0))
    along = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(ref[:, 0]), np.diff(ref[:, 1])))])
    j = np.searchsorted(along, along + distance, side="left")
    i = np.flatnonzero(j < len(ref))
    j = j[i]
    e, r = SE2(est), SE2(ref)
    err = (r[i].inv() @ r[j]).inv() @ (e[i].inv() @ e[j])
    xyt = err.xytheta
    return RelativePoseError(index[i], index[j], np.hypot(xyt[:, 0], xyt[:, 1]), np.abs(xyt[:, 2]))
