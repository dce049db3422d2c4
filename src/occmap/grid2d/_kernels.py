"""Numba kernels of the 2D occupancy grid: plain arrays in, arrays updated in place.

Per-cell state is ``L`` (float32 log-odds) and ``stamp`` (int32): ``stamp == 0`` means never
observed; within scan ``s`` (s ≥ 1) a free update sets ``2s`` and a hit sets ``2s + 1``, so one
array says both "already updated in this scan" and "hit wins over miss".
"""

from __future__ import annotations

import math

import numpy as np
from .._jit import kernel
from ..raycast import dda_init, dda_step

@kernel
def _update(L, iy, ix, l_delta, l_min, l_max):
    L[iy, ix] = min(max(L[iy, ix] + l_delta, l_min), l_max)


@kernel
def integrate_lidar(L, stamp, scan0, poses, ranges, angles, max_range, ox, oy, inv_res,
                    l_hit, l_miss, l_min, l_max):
    """Integrate scans ``k = 0..N-1`` (poses (N, 3), ranges (N, n), angles (N, n)) with scan ids
    ``scan0 + k``. Returns (beams used, readings dropped as NaN/≤ 0, max-range readings)."""
    H, W = L.shape
    n_scans, n_beams = ranges.shape
    ex = np.empty(n_beams)
    ey = np.empty(n_beams)
    hit = np.empty(n_beams, dtype=np.bool_)
    used = 0
    dropped = 0
    maxed = 0
    for k in range(n_scans):
        s = scan0 + k
        x0, y0, th = poses[k, 0], poses[k, 1], poses[k, 2]
        # pass 1: beam ends; hits update their cell once and claim it for this scan
        for b in range(n_beams):
            r = ranges[k, b]
            if not (r > 0.0):  # NaN, zero and negative readings carry no information
                hit[b] = False
                ex[b] = np.nan
                dropped += 1
                continue
            hit[b] = r < max_range
            if not hit[b]:
                r = max_range
                maxed += 1
            a = th + angles[k, b]
            ex[b] = x0 + r * math.cos(a)
            ey[b] = y0 + r * math.sin(a)
            used += 1
            if hit[b]:
                ix = int(math.floor((ex[b] - ox) * inv_res))
                iy = int(math.floor((ey[b] - oy) * inv_res))
                if 0 <= ix < W and 0 <= iy < H and stamp[iy, ix] != 2 * s + 1:
                    stamp[iy, ix] = 2 * s + 1
                    _update(L, iy, ix, l_hit, l_min, l_max)
        # pass 2: free cells along each beam, end cell excluded, each once, never over a hit
        for b in range(n_beams):
            if not (ex[b] == ex[b]):
                continue
            steps, state = dda_init(x0, y0, ex[b], ey[b], ox, oy, inv_res)
            for _ in range(steps):  # every cell but the end one
                ix, iy = state[0], state[1]
                if 0 <= ix < W and 0 <= iy < H and stamp[iy, ix] < 2 * s:
                    stamp[iy, ix] = 2 * s
                    _update(L, iy, ix, l_miss, l_min, l_max)
                state = dda_step(state)
    return used, dropped, maxed


@kernel
def integrate_sonar(L, stamp, scan0, poses, ranges, bearings, half_width, max_range, arc, ox, oy, res,
                    l_occ, l_free, l_min, l_max):
    """Cone updates for N readings rings (poses (N, 3), ranges (N, k), bearings (k,)): each reading
    updates every cell whose centre lies in its cone, once, weighted by 1 − (φ/half_width)².
    Returns (readings used, readings dropped as NaN/≤ 0, max-range readings)."""
    H, W = L.shape
    n_scans, n_beams = ranges.shape
    used = 0
    dropped = 0
    maxed = 0
    for k in range(n_scans):
        s = scan0 + k
        x0, y0, th = poses[k, 0], poses[k, 1], poses[k, 2]
        for b in range(n_beams):
            r = ranges[k, b]
            if not (r > 0.0):
                dropped += 1
                continue
            hit = r < max_range
            reach = r if hit else max_range
            if not hit:
                maxed += 1
            used += 1
            axis = th + bearings[b]
            outer = reach + 0.5 * arc if hit else reach
            ix0 = max(0, int(math.floor((x0 - outer - ox) / res)))
            ix1 = min(W - 1, int(math.floor((x0 + outer - ox) / res)))
            iy0 = max(0, int(math.floor((y0 - outer - oy) / res)))
            iy1 = min(H - 1, int(math.floor((y0 + outer - oy) / res)))
            for iy in range(iy0, iy1 + 1):
                cy = oy + (iy + 0.5) * res - y0
                for ix in range(ix0, ix1 + 1):
                    cx = ox + (ix + 0.5) * res - x0
                    d = math.sqrt(cx * cx + cy * cy)
                    if d > outer:
                        continue
                    phi = math.atan2(cy, cx) - axis
                    phi = (phi + math.pi) % (2.0 * math.pi) - math.pi
                    if abs(phi) > half_width:
                        continue
                    w = 1.0 - (phi / half_width) ** 2
                    if hit and d >= reach - 0.5 * arc:
                        _update(L, iy, ix, w * l_occ, l_min, l_max)
                        stamp[iy, ix] = 2 * s + 1
                    else:
                        _update(L, iy, ix, w * l_free, l_min, l_max)
                        if stamp[iy, ix] < 2 * s:
                            stamp[iy, ix] = 2 * s
    return used, dropped, maxed
