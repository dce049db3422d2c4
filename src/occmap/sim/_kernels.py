"""Numba kernels of the 2D simulator: exact ray casting against segments and discs, the exact
segment/disc rasterisation of the ground truth, and a 4-connected flood fill.

Plain float64 arrays in, arrays out; the caller validates shapes and finiteness and allocates
``out``. No fastmath: the tests compare with a Python reference to 1e-12.
"""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from .._jit import kernel, kernel_parallel

# Rays per task of the parallel kernel; batches this long or longer run on all cores.
CHUNK = 512
PARALLEL_MIN = 1 << 14


@kernel
def _ray_hit(px, py, dx, dy, segments, circles, max_range):
    """Distance along the unit ray ``p + t·d`` (t ≥ 0) to the first segment or disc, or +inf when
    nothing lies within ``max_range``. A ray starting inside (or on) a disc, or on a segment,
    returns 0."""
    best = np.inf
    for j in range(segments.shape[0]):
        ax = segments[j, 0]
        ay = segments[j, 1]
        ex = segments[j, 2] - ax
        ey = segments[j, 3] - ay
        wx = ax - px
        wy = ay - py
        denom = dx * ey - dy * ex  # cross(d, e)
        if denom != 0.0:
            t = (wx * ey - wy * ex) / denom  # cross(w, e) / cross(d, e)
            u = (wx * dy - wy * dx) / denom  # cross(w, d) / cross(d, e)
            if t >= 0.0 and u >= 0.0 and u <= 1.0 and t < best:
                best = t
        elif wx * dy - wy * dx == 0.0:
            # collinear: the ray runs along the wall; hit at its nearest point ahead
            ta = wx * dx + wy * dy
            tb = (segments[j, 2] - px) * dx + (segments[j, 3] - py) * dy
            lo = min(ta, tb)
            hi = max(ta, tb)
            t = -1.0
            if lo <= 0.0 <= hi:
                t = 0.0
            elif lo > 0.0:
                t = lo
            if t >= 0.0 and t < best:
                best = t
    for j in range(circles.shape[0]):
        fx = px - circles[j, 0]
        fy = py - circles[j, 1]
        r = circles[j, 2]
        c = fx * fx + fy * fy - r * r
        if c <= 0.0:
            best = 0.0
            continue
        b = fx * dx + fy * dy
        if b >= 0.0:
            continue  # outside and heading away
        disc = b * b - c
        if disc < 0.0:
            continue
        # the near root -b - sqrt(disc), written without cancellation
        t = c / (-b + math.sqrt(disc))
        if t < best:
            best = t
    if best > max_range:
        return np.inf
    return best


@kernel
def cast_span(origins, angles, segments, circles, max_range, start, stop, out):
    """``out[i]`` for ``start <= i < stop`` = range of ray i from ``origins[i]`` (N, 2) at world
    angle ``angles[i]``."""
    for i in range(start, stop):
        out[i] = _ray_hit(origins[i, 0], origins[i, 1], math.cos(angles[i]), math.sin(angles[i]),
                          segments, circles, max_range)
    return out


@kernel
def cast_rays(origins, angles, segments, circles, max_range, out):
    """:func:`cast_span` over all rays, on one core."""
    return cast_span(origins, angles, segments, circles, max_range, 0, angles.shape[0], out)


@kernel_parallel
def cast_rays_parallel(origins, angles, segments, circles, max_range, out):
    """:func:`cast_span` over all rays, in chunks of :data:`CHUNK` rays on all cores."""
    n = angles.shape[0]
    for c in prange((n + CHUNK - 1) // CHUNK):
        cast_span(origins, angles, segments, circles, max_range, c * CHUNK, min(n, (c + 1) * CHUNK), out)
    return out


@kernel
def _segment_hits_box(x0, y0, x1, y1, bx0, by0, bx1, by1):
    """True when the closed segment (x0, y0)–(x1, y1) meets the closed box [bx0, bx1] × [by0, by1]
    (Liang–Barsky clipping)."""
    dx = x1 - x0
    dy = y1 - y0
    t0 = 0.0
    t1 = 1.0
    for k in range(4):
        if k == 0:
            p = -dx
            q = x0 - bx0
        elif k == 1:
            p = dx
            q = bx1 - x0
        elif k == 2:
            p = -dy
            q = y0 - by0
        else:
            p = dy
            q = by1 - y0
        if p == 0.0:
            if q < 0.0:
                return False
        else:
            r = q / p
            if p < 0.0:
                if r > t1:
                    return False
                if r > t0:
                    t0 = r
            else:
                if r < t0:
                    return False
                if r < t1:
                    t1 = r
    return t0 <= t1


@kernel
def rasterize(segments, circles, ox, oy, res, out):
    """Mark in ``out`` (H, W) bool every cell whose closed square meets a segment or a disc. Cell
    (iy, ix) spans ``[ox + ix·res, ox + (ix+1)·res] × [oy + iy·res, oy + (iy+1)·res]``."""
    H = out.shape[0]
    W = out.shape[1]
    for j in range(segments.shape[0]):
        x0 = segments[j, 0]
        y0 = segments[j, 1]
        x1 = segments[j, 2]
        y1 = segments[j, 3]
        ix0 = max(int(math.floor((min(x0, x1) - ox) / res)) - 1, 0)
        ix1 = min(int(math.floor((max(x0, x1) - ox) / res)) + 1, W - 1)
        iy0 = max(int(math.floor((min(y0, y1) - oy) / res)) - 1, 0)
        iy1 = min(int(math.floor((max(y0, y1) - oy) / res)) + 1, H - 1)
        for iy in range(iy0, iy1 + 1):
            by0 = oy + iy * res
            by1 = oy + (iy + 1) * res
            for ix in range(ix0, ix1 + 1):
                if out[iy, ix]:
                    continue
                if _segment_hits_box(x0, y0, x1, y1, ox + ix * res, by0, ox + (ix + 1) * res, by1):
                    out[iy, ix] = True
    for j in range(circles.shape[0]):
        cx = circles[j, 0]
        cy = circles[j, 1]
        r = circles[j, 2]
        ix0 = max(int(math.floor((cx - r - ox) / res)) - 1, 0)
        ix1 = min(int(math.floor((cx + r - ox) / res)) + 1, W - 1)
        iy0 = max(int(math.floor((cy - r - oy) / res)) - 1, 0)
        iy1 = min(int(math.floor((cy + r - oy) / res)) + 1, H - 1)
        for iy in range(iy0, iy1 + 1):
            by0 = oy + iy * res
            by1 = oy + (iy + 1) * res
            ny = min(max(cy, by0), by1) - cy
            for ix in range(ix0, ix1 + 1):
                nx = min(max(cx, ox + ix * res), ox + (ix + 1) * res) - cx
                if nx * nx + ny * ny <= r * r:
                    out[iy, ix] = True
    return out


@kernel
def flood_fill(passable, sy, sx, out):
    """Mark in ``out`` (H, W) bool the cells 4-connected to (sy, sx) through ``passable`` cells."""
    H = passable.shape[0]
    W = passable.shape[1]
    if not passable[sy, sx]:
        return out
    stack = np.empty(H * W, dtype=np.int64)
    n = 0
    stack[n] = sy * W + sx
    n += 1
    out[sy, sx] = True
    while n > 0:
        n -= 1
        k = stack[n]
        y = k // W
        x = k - y * W
        for m in range(4):
            yy = y
            xx = x
            if m == 0:
                yy = y - 1
            elif m == 1:
                yy = y + 1
            elif m == 2:
                xx = x - 1
            else:
                xx = x + 1
            if yy < 0 or yy >= H or xx < 0 or xx >= W:
                continue
            if passable[yy, xx] and not out[yy, xx]:
                out[yy, xx] = True
                stack[n] = yy * W + xx
                n += 1
    return out
