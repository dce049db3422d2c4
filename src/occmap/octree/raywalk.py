"""The one 3D ray walk: OctoMap's voxel-stepping rule (``computeRayKeys`` and ``castRay``), as a
state and a step that every octree kernel reuses (insertion's plain walk, its dense-cube phase,
and ray casting).

A walk visits the voxels a ray crosses, one face-neighbour at a time (Amanatides & Woo). Its state
per axis: the step ``s`` (−1, 0, +1), ``t`` (the distance along the ray at which it next crosses
a voxel border on that axis) and ``g`` (the distance between two such crossings). OctoMap's
arithmetic is kept to the bit: the direction is normalised in float32 (its ``point3d``), the
distances are float64, the half-voxel offset to the first border is rounded to float32 in
``computeRayKeys`` and not in ``castRay`` (``border32``). :func:`step` moves the axis whose border
comes first, ties going to z, then y (OctoMap's comparisons).

A ray with no direction gets ``s = 0`` and ``t = g = BIG`` on every axis: its first step then
lands at ``t`` ≥ BIG, beyond any length, so every walk stops after the origin's voxel. That is a
ray whose float32 length is 0 — its end lies within ~1e-19 m of the origin (the squared
components underflow), though possibly in a neighbouring voxel — or overflows (its ends lie
~1e19 m apart, in the key range only at resolutions of ~1e34 m and more; insertion refuses those
rays before they get here). OctoMap divides by the zero or infinite length and steps forever.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import inline_kernel, kernel
from .keys import key_to_coord

#: "Never": the t of an axis the ray does not move along.
BIG = np.finfo(np.float64).max


@inline_kernel
def direction(dx, dy, dz):
    """OctoMap's normalisation of a float32 vector: (float32 length, unit vector) with the length
    as float64; (0, 0, 0, 0) — no direction — for a vector whose float32 length is 0 or
    overflows."""
    length = np.float32(math.sqrt(np.float64(dx * dx + dy * dy + dz * dz)))
    ok = (length > 0) & (length < np.inf)  # (selects, no branch: loops of rays vectorise)
    z = np.float32(0.0)
    return (np.float64(length) if ok else 0.0, dx / length if ok else z, dy / length if ok else z,
            dz / length if ok else z)


@inline_kernel
def _axis_start(o, u, k, res, border32):
    s = np.int64(u > 0) - np.int64(u < 0)
    half = s * res * 0.5
    if border32:
        half = np.float64(np.float32(half))
    t = (key_to_coord(k, res) + half - np.float64(o)) / np.float64(u)  # (±inf or NaN where u = 0: replaced)
    g = res / abs(np.float64(u))
    return s, t if s != 0 else BIG, g if s != 0 else BIG


@inline_kernel
def start(ox, oy, oz, ux, uy, uz, kx, ky, kz, res, border32):
    """Walk state of a ray from float32 point ``o`` in voxel ``k`` along the unit float32 direction
    ``u`` (from :func:`direction`): ``(sx, sy, sz, tx, ty, tz, gx, gy, gz)``. ``border32``: round
    the half-voxel offset to float32 as ``computeRayKeys`` does (``castRay`` does not)."""
    sx, tx, gx = _axis_start(ox, ux, kx, res, border32)
    sy, ty, gy = _axis_start(oy, uy, ky, res, border32)
    sz, tz, gz = _axis_start(oz, uz, kz, res, border32)
    return sx, sy, sz, tx, ty, tz, gx, gy, gz


@kernel
def step(tx, ty, tz, gx, gy, gz):
    """One step of OctoMap's walk: the axis (0, 1, 2) whose next border comes first (ties: z over
    y over x) and the three t after it crosses that border. The caller moves that axis's key by
    its ``s``; the ray has covered ``min(t)`` after the step."""
    if tx < ty:
        if tx < tz:
            return 0, tx + gx, ty, tz
        return 2, tx, ty, tz + gz
    if ty < tz:
        return 1, tx, ty + gy, tz
    return 2, tx, ty, tz + gz


@kernel
def centre_beyond(kx, ky, kz, ox, oy, oz, res, max_range_sq):
    """``castRay``'s range test: whether the centre of voxel (kx, ky, kz), as float32, lies farther
    than ``sqrt(max_range_sq)`` from the float32 origin ``o`` (squares summed in float64)."""
    ex = np.float32(key_to_coord(kx, res))
    ey = np.float32(key_to_coord(ky, res))
    ez = np.float32(key_to_coord(kz, res))
    return (np.float64((ex - ox) * (ex - ox)) + np.float64((ey - oy) * (ey - oy))
            + np.float64((ez - oz) * (ez - oz))) > max_range_sq
