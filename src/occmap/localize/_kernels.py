"""Numba kernels of Monte Carlo localization: plain arrays in, arrays filled in place.

The measurement model scores every particle against every (subsampled) beam in one kernel,
parallel over particles; the per-beam work is two multiply-adds, a floor and one table look-up,
all inline. The table holds each cell's per-beam score (the log-likelihood of a beam ending
there, or AMCL's ``pz³``), so the model's maths is done once per cell, not once per beam.

The scan matcher takes Gauss-Newton steps of a pose against the bilinearly interpolated
distance field (distance to the nearest occupied cell).
"""

from __future__ import annotations

import math

from numba import prange

from .._jit import kernel, kernel_parallel
from ..geometry.so2 import wrap_angle_one


@kernel
def _score_range(particles, bx, by, table, outside, ox, oy, inv_res, out, i0, i1):
    """The measurement score of particles ``i0 .. i1 - 1``; see :func:`score_particles`."""
    n = bx.shape[0]
    H = table.shape[0]
    W = table.shape[1]
    for i in range(i0, i1):
        c = math.cos(particles[i, 2])
        s = math.sin(particles[i, 2])
        # the particle and its rotated axes in cell units: each end point is two multiply-adds
        px = (particles[i, 0] - ox) * inv_res
        py = (particles[i, 1] - oy) * inv_res
        cs = c * inv_res
        ss = s * inv_res
        acc = 0.0
        for j in range(n):
            gx = px + cs * bx[j] - ss * by[j]
            gy = py + ss * bx[j] + cs * by[j]
            if gx >= 0.0 and gy >= 0.0:
                ix = int(gx)
                iy = int(gy)
                if ix < W and iy < H:
                    acc += table[iy, ix]
                    continue
            acc += outside
        out[i] = acc


@kernel
def score_particles(particles, bx, by, table, outside, ox, oy, inv_res, out):
    """``out[i] = Σ_j table[cell of particle i ⊕ (bx[j], by[j])]`` (``outside`` for off-map ends).

    ``particles`` (N, 3) poses ``(x, y, theta)``; ``bx``, ``by`` (n,) beam end points in the
    particle's frame; ``table`` (H, W) float32 per-cell beam scores; ``origin`` ``(ox, oy)`` and
    ``inv_res`` place the grid. One thread."""
    _score_range(particles, bx, by, table, outside, ox, oy, inv_res, out, 0, particles.shape[0])


#: Particles per task of :func:`score_particles_parallel`.
CHUNK = 256


@kernel_parallel
def score_particles_parallel(particles, bx, by, table, outside, ox, oy, inv_res, out):
    """:func:`score_particles`, parallel over chunks of :data:`CHUNK` particles."""
    N = particles.shape[0]
    chunks = (N + CHUNK - 1) // CHUNK
    for k in prange(chunks):
        _score_range(particles, bx, by, table, outside, ox, oy, inv_res, out, k * CHUNK, min(N, (k + 1) * CHUNK))


@kernel
def _bilinear(field, gx, gy, far):
    """Value and gradient (per cell) of ``field`` sampled at cell coordinates ``(gx, gy)``
    (cell centres at integer + 0.5); ``far`` off the map (gradient 0)."""
    H = field.shape[0]
    W = field.shape[1]
    u = gx - 0.5
    v = gy - 0.5
    if u < 0.0 or v < 0.0 or u >= W - 1 or v >= H - 1:
        return far, 0.0, 0.0
    ix = int(u)
    iy = int(v)
    fx = u - ix
    fy = v - iy
    f00 = field[iy, ix]
    f01 = field[iy, ix + 1]
    f10 = field[iy + 1, ix]
    f11 = field[iy + 1, ix + 1]
    a = f00 + fx * (f01 - f00)
    b = f10 + fx * (f11 - f10)
    val = a + fy * (b - a)
    dgx = (1.0 - fy) * (f01 - f00) + fy * (f11 - f10)
    dgy = b - a
    return val, dgx, dgy


@kernel
def match_normal_equations(pose, bx, by, field, far, cutoff, ox, oy, inv_res, Hm, g):
    """One Gauss-Newton linearisation of ``Σ_j ρ(d(pose ⊕ beam_j))`` where ``d`` is the
    bilinearly interpolated distance field (metres) and ``ρ`` drops ends farther than ``cutoff``
    from every obstacle (outliers, unmapped objects). Fills ``Hm`` (3, 3) = JᵀJ and ``g`` (3,) =
    Jᵀr; returns ``(sum of squared residuals, inliers)``."""
    for a in range(3):
        g[a] = 0.0
        for b in range(3):
            Hm[a, b] = 0.0
    c = math.cos(pose[2])
    s = math.sin(pose[2])
    cost = 0.0
    used = 0
    for j in range(bx.shape[0]):
        lx = c * bx[j] - s * by[j]
        ly = s * bx[j] + c * by[j]
        wx = pose[0] + lx
        wy = pose[1] + ly
        d, dgx, dgy = _bilinear(field, (wx - ox) * inv_res, (wy - oy) * inv_res, far)
        if d > cutoff:
            continue
        # gradient in metres per metre: the field is in metres, its argument in cells
        jx = dgx * inv_res
        jy = dgy * inv_res
        jt = -jx * ly + jy * lx
        J0, J1, J2 = jx, jy, jt
        g[0] += J0 * d
        g[1] += J1 * d
        g[2] += J2 * d
        Hm[0, 0] += J0 * J0
        Hm[0, 1] += J0 * J1
        Hm[0, 2] += J0 * J2
        Hm[1, 1] += J1 * J1
        Hm[1, 2] += J1 * J2
        Hm[2, 2] += J2 * J2
        cost += d * d
        used += 1
    Hm[1, 0] = Hm[0, 1]
    Hm[2, 0] = Hm[0, 2]
    Hm[2, 1] = Hm[1, 2]
    return cost, used


@kernel
def systematic_indices(cum, u0, out):
    """Low-variance (systematic) resampling: ``out[k]`` = the index ``i`` whose cumulative-weight
    interval ``(cum[i-1], cum[i]]`` holds ``(u0 + k) / M`` for ``M = len(out)``; ``cum`` ends at 1."""
    M = out.shape[0]
    n = cum.shape[0]
    i = 0
    step = 1.0 / M
    for k in range(M):
        u = (u0 + k) * step
        while i < n - 1 and cum[i] < u:
            i += 1
        out[k] = i


@kernel
def weighted_moments(p, w, mean, cov):
    """Weighted mean (circular for the heading) and covariance (heading residuals wrapped about
    the mean) of poses ``p`` (N, 3) under weights ``w`` (N,) summing to 1; fills ``mean`` (3,)
    and ``cov`` (3, 3)."""
    n = p.shape[0]
    sx = 0.0
    sy = 0.0
    ss = 0.0
    sc = 0.0
    for i in range(n):
        sx += w[i] * p[i, 0]
        sy += w[i] * p[i, 1]
        ss += w[i] * math.sin(p[i, 2])
        sc += w[i] * math.cos(p[i, 2])
    mean[0] = sx
    mean[1] = sy
    mean[2] = math.atan2(ss, sc)
    for a in range(3):
        for b in range(3):
            cov[a, b] = 0.0
    for i in range(n):
        dx = p[i, 0] - sx
        dy = p[i, 1] - sy
        dt = wrap_angle_one(p[i, 2] - mean[2])
        wi = w[i]
        cov[0, 0] += wi * dx * dx
        cov[0, 1] += wi * dx * dy
        cov[0, 2] += wi * dx * dt
        cov[1, 1] += wi * dy * dy
        cov[1, 2] += wi * dy * dt
        cov[2, 2] += wi * dt * dt
    cov[1, 0] = cov[0, 1]
    cov[2, 0] = cov[0, 2]
    cov[2, 1] = cov[1, 2]
