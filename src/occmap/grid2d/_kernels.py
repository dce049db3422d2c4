"""Numba kernels of the 2D occupancy grid: plain arrays in, arrays updated in place.

Per-cell state is ``L`` (float32 log-odds) and ``stamp`` (unsigned integers, uint16 in the grid),
updated by the rules of :mod:`occmap.raster.update` (codes ``scan0 + k`` rise within a call; the
caller keeps them within the stamp's dtype); rays are walked by :mod:`occmap.raster.walk2d`. Two
separate arrays, 6 bytes a cell in all, keep more of a scan's cells in the caches than one 8-byte
record did (5–7 % faster on the benchmark's 10 m beams, medians of alternating rounds).
"""

from __future__ import annotations

import math

import numpy as np
from numba import get_num_threads, prange

from .._jit import kernel, kernel_parallel
from .._threads import ThreadChoice
from ..geometry.so2 import wrap_angle_one
from ..raster.update import clamp_add, hit_stamp, miss_stamp
from ..raster.walk2d import cell_of, dda_init, dda_step, miss_walk


# ---------------------------------------------------------------------------------------------
# lidar: the walks along a beam
#
# Within one scan every cell gets at most one update, a hit or a miss, so the result of a scan
# does not depend on the order in which its beams are walked; across scans each cell sees its
# updates in scan order. The grid is therefore cut into rectangles of cells ("parts": the whole
# grid, or strips of rows); each part goes through the scans in order, applies the hits that end
# in it and walks every beam over its own cells only. Parts own disjoint cells, so they run on
# separate threads without any synchronisation and still give the serial result bit for bit.
# The beams' ends are found once for all parts (a sine and a cosine each: per part, that cost
# about 10 % of one thread's time for every part added).


@kernel
def beam_end(x0, y0, th, r, a, max_range):
    """``(kind, x, y)`` of one reading: kind 0 unusable (NaN, ≤ 0), 1 hit, 2 no return (cleared
    up to ``max_range``, marks nothing); (x, y) the end point for kinds 1 and 2."""
    if not (r > 0.0):  # NaN, zero and negative readings carry no information
        return 0, 0.0, 0.0
    kind = 1
    if not (r < max_range):
        r = max_range
        kind = 2
    b = th + a
    return kind, x0 + r * math.cos(b), y0 + r * math.sin(b)


@kernel
def _scan_ends(poses, ranges, angles, max_range, k, kind, ex, ey, row):
    """:func:`beam_end` of every beam of scan ``k`` into row ``row`` of ``kind``, ``ex``, ``ey``."""
    x0, y0, th = poses[k, 0], poses[k, 1], poses[k, 2]
    for b in range(ranges.shape[1]):
        kind[row, b], ex[row, b], ey[row, b] = beam_end(x0, y0, th, ranges[k, b], angles[k, b], max_range)


@kernel
def _part(Lf, Sf, base, rs, x_lo, x_hi, y_lo, y_hi, scan0, poses, k0, m, kind, ex, ey, ox, oy, inv_res,
          l_hit, l_miss, l_min, l_max):
    """The updates of scans ``k0 .. k0 + m − 1`` (their beams' ends in the first ``m`` rows of
    ``kind``, ``ex``, ``ey``, :func:`_scan_ends`) to the cells in part ``[x_lo, x_hi) × [y_lo, y_hi)``, scan after scan:
    first the scan's hits, then the free cells along each of its beams (stamps:
    :mod:`occmap.raster.update`). Cell ``(ix, iy)`` (the index rule with origin ``(ox, oy)``) is
    at ``base + iy·rs + ix`` of the flat arrays ``Lf`` and ``Sf``."""
    n_beams = kind.shape[1]
    for j in range(m):
        k = k0 + j
        s = scan0 + k
        x0, y0 = poses[k, 0], poses[k, 1]
        for b in range(n_beams):
            if kind[j, b] == 1:
                ix, iy = cell_of(ex[j, b], ey[j, b], ox, oy, inv_res)
                i = base + iy * rs + ix
                if x_lo <= ix < x_hi and y_lo <= iy < y_hi and Sf[i] != hit_stamp(s):
                    Sf[i] = hit_stamp(s)
                    Lf[i] = clamp_add(Lf[i], l_hit, l_min, l_max)
        v0 = math.floor((y0 - oy) * inv_res)  # the rows of a walk, as dda_init finds them
        for b in range(n_beams):
            if kind[j, b] != 0:
                v1 = math.floor((ey[j, b] - oy) * inv_res)
                if max(v0, v1) < y_lo or min(v0, v1) >= y_hi:  # not a cell of this part's rows
                    continue
                steps, state = dda_init(x0, y0, ex[j, b], ey[j, b], ox, oy, inv_res)
                miss_walk(Lf, Sf, base, 1, rs, steps, state, x_lo, x_hi, y_lo, y_hi, s, l_miss, l_min, l_max)


@kernel_parallel
def _parts(Lf, Sf, base, rs, parts, scan0, poses, ranges, angles, max_range, ox, oy, inv_res,
           l_hit, l_miss, l_min, l_max, k0, m, kind, ex, ey):
    """Scans ``k0 .. k0 + m − 1`` with the work shared between threads: their beams' ends
    (:func:`_scan_ends`) side by side, then the parts (rows ``(x_lo, x_hi, y_lo, y_hi)`` of
    ``parts``, disjoint, :func:`_part`) side by side, with no synchronisation until all are done."""
    for j in prange(m):
        _scan_ends(poses, ranges, angles, max_range, k0 + j, kind, ex, ey, j)
    for p in prange(parts.shape[0]):
        _part(Lf, Sf, base, rs, parts[p, 0], parts[p, 1], parts[p, 2], parts[p, 3], scan0, poses, k0, m, kind,
              ex, ey, ox, oy, inv_res, l_hit, l_miss, l_min, l_max)


#: Beams looked at (evenly spread over the call's scans) to choose where to cut the grid.
_SPLIT_SAMPLE = 4096


@kernel
def _choose_parts(poses, ranges, angles, max_range, ox, oy, gx0, gy0, inv_res, H, W, min_cells, parts):
    """Fill ``parts`` (k, 4) with the cell rectangles the work is split into and return how many:
    one (the whole grid, cells ``[gx0, gx0 + W) × [gy0, gy0 + H)``) for less than ``min_cells``
    cells of work (estimated from a sample of the beams), else up to k strips of whole rows that
    share the cells to walk evenly (rows, not columns: a part's cells are then one block of
    memory)."""
    n_scans, n_beams = ranges.shape
    parts[0, 0], parts[0, 1], parts[0, 2], parts[0, 3] = gx0, gx0 + W, gy0, gy0 + H
    n = n_scans * n_beams
    if min_cells < 0 or n == 0 or H < 2:
        return 1
    step = max(1, n // _SPLIT_SAMPLE)
    density = np.zeros(H + 1)  # difference array of the sampled cells per row
    total = 0.0
    for i in range(0, n, step):
        k, b = i // n_beams, i % n_beams
        x0, y0 = poses[k, 0], poses[k, 1]
        kind, x1, y1 = beam_end(x0, y0, poses[k, 2], ranges[k, b], angles[k, b], max_range)
        if kind == 0:
            continue
        u0, v0 = cell_of(x0, y0, ox, oy, inv_res)
        u1, v1 = cell_of(x1, y1, ox, oy, inv_res)
        c = abs(u1 - u0) + abs(v1 - v0) + 1.0
        lo, hi = max(min(v0, v1) - gy0, 0), min(max(v0, v1) - gy0, H - 1)
        if lo <= hi:  # the beam's cells spread evenly over its rows in the grid
            total += c
            density[lo] += c / (hi - lo + 1)
            density[hi + 1] -= c / (hi - lo + 1)
    if total * step < min_cells:
        return 1
    k = min(parts.shape[0], H)
    m = 0  # rows [parts[m, 2], gy0 + row) make part m
    acc = 0.0
    d = 0.0
    for row in range(H):
        d += density[row]
        acc += d
        if m < k - 1 and acc >= total * (m + 1) / k:
            parts[m, 3] = gy0 + row + 1
            m += 1
            parts[m, 0], parts[m, 1], parts[m, 2] = gx0, gx0 + W, gy0 + row + 1
    parts[m, 3] = gy0 + H
    return m + 1


#: Calls with fewer cells to walk than this run on one thread.
SPLIT_MIN_CELLS = 20_000
#: Beams whose ends are held at once (:func:`_integrate_lidar`): 17 bytes each.
BLOCK_BEAMS = 1 << 16
#: One thread or several, per call, by their measured cost per cell along the beams
#: (:func:`count_readings`; calls too small to split take one thread).
THREADS = ThreadChoice(min_work=SPLIT_MIN_CELLS)


def _flat(L, stamp):
    """Flat views ``(Lf, Sf)`` of the grid's cells, two C-contiguous (H, W) arrays: cell (iy, ix)
    is ``Lf[iy·W + ix]`` and ``Sf[iy·W + ix]``."""
    if L.flags.c_contiguous and stamp.flags.c_contiguous and stamp.shape == L.shape:
        return L.reshape(-1), stamp.reshape(-1)
    raise ValueError("L and stamp must be C-contiguous (H, W) arrays")


def integrate_lidar(L, stamp, scan0, poses, ranges, angles, max_range, ox, oy, gx0, gy0, inv_res,
                    l_hit, l_miss, l_min, l_max, split_min_cells=None, fresh=False):
    """Integrate scans ``k = 0..N-1`` (poses (N, 3), ranges (N, n), angles (N, n)) into the grid
    ``L`` (float32 log-odds), ``stamp`` (unsigned integers), both (H, W), with scan codes
    ``scan0 + k`` (see the module's docstring for what they must fit). ``L[r, c]`` is the cell
    ``(gx0 + c, gy0 + r)`` of the lattice with origin ``(ox, oy)`` (:mod:`occmap.raster`'s index
    rule). Returns (beams used, readings dropped as NaN/≤ 0, max-range readings).

    With at least ``split_min_cells`` cells to walk (default :data:`SPLIT_MIN_CELLS` when
    :data:`THREADS` chooses several threads, else never; negative: never) the grid is cut into
    strips of rows, one per thread (at least two), updated side by side; the result is the same
    either way. ``fresh``: the grid's storage is new (this call is
    the first to touch its pages, so its time is no sample of the paths' costs)."""
    Lf, Sf = _flat(L, stamp)
    H, W = L.shape
    max_parts = max(get_num_threads(), 2)
    block = max(1, BLOCK_BEAMS // max(1, ranges.shape[1]))  # scans at a time
    used, dropped, maxed, length = count_readings(ranges, max_range)
    if split_min_cells is None:
        with THREADS.choose(length * inv_res, sample=not fresh) as parallel:
            _integrate_lidar(Lf, Sf, H, W, scan0, poses, ranges, angles, max_range, ox, oy, gx0, gy0, inv_res,
                             l_hit, l_miss, l_min, l_max, SPLIT_MIN_CELLS if parallel else -1, max_parts, block)
    else:
        _integrate_lidar(Lf, Sf, H, W, scan0, poses, ranges, angles, max_range, ox, oy, gx0, gy0, inv_res,
                         l_hit, l_miss, l_min, l_max, split_min_cells, max_parts, block)
    return used, dropped, maxed


@kernel
def count_readings(ranges, max_range):
    """(readings used, dropped as NaN/≤ 0, at or beyond ``max_range``, the used beams' length in
    metres, each up to ``max_range``) of ranges (N, n). The length in cells is about the cells
    the beams walk (a walk's steps are its length in cells along x plus along y)."""
    used = 0
    dropped = 0
    maxed = 0
    length = 0.0
    for k in range(ranges.shape[0]):
        for b in range(ranges.shape[1]):
            r = ranges[k, b]
            if not (r > 0.0):
                dropped += 1
            else:
                used += 1
                length += min(r, max_range)
                if not (r < max_range):
                    maxed += 1
    return used, dropped, maxed, length


@kernel
def _integrate_lidar(Lf, Sf, H, W, scan0, poses, ranges, angles, max_range, ox, oy, gx0, gy0, inv_res,
                     l_hit, l_miss, l_min, l_max, split_min_cells, max_parts, block):
    parts = np.empty((max_parts, 4), dtype=np.int64)
    n_parts = _choose_parts(poses, ranges, angles, max_range, ox, oy, gx0, gy0, inv_res, H, W, split_min_cells,
                            parts)
    base = -(gy0 * W + gx0)
    n_scans = ranges.shape[0]
    kind = np.empty((min(block, n_scans), ranges.shape[1]), dtype=np.int8)  # the ends of a block's beams
    ex = np.empty(kind.shape)
    ey = np.empty(kind.shape)
    for k0 in range(0, n_scans, block):  # ``block`` scans at a time: their ends, then their updates
        m = min(block, n_scans - k0)
        if n_parts == 1:
            for j in range(m):
                _scan_ends(poses, ranges, angles, max_range, k0 + j, kind, ex, ey, j)
            _part(Lf, Sf, base, W, gx0, gx0 + W, gy0, gy0 + H, scan0, poses, k0, m, kind, ex, ey, ox, oy, inv_res,
                  l_hit, l_miss, l_min, l_max)
        else:
            _parts(Lf, Sf, base, W, parts[:n_parts], scan0, poses, ranges, angles, max_range, ox, oy, inv_res,
                   l_hit, l_miss, l_min, l_max, k0, m, kind, ex, ey)


@kernel
def beam_extent(poses, ranges, angles, max_range):
    """World box ``(xmin, ymin, xmax, ymax)`` of the sensor positions and the ends of the beams
    that will be walked (:func:`beam_end`, the same arithmetic as the walk); infinite where an
    end overflows. Used to find the cells scans reach before inserting them."""
    xmin, ymin, xmax, ymax = np.inf, np.inf, -np.inf, -np.inf
    n_scans, n_beams = ranges.shape
    for k in range(n_scans):
        x0, y0, th = poses[k, 0], poses[k, 1], poses[k, 2]
        xmin, xmax, ymin, ymax = min(xmin, x0), max(xmax, x0), min(ymin, y0), max(ymax, y0)
        for b in range(n_beams):
            kind, x, y = beam_end(x0, y0, th, ranges[k, b], angles[k, b], max_range)
            if kind != 0:
                if not (math.isfinite(x) and math.isfinite(y)):
                    return -np.inf, -np.inf, np.inf, np.inf
                xmin, xmax, ymin, ymax = min(xmin, x), max(xmax, x), min(ymin, y), max(ymax, y)
    return xmin, ymin, xmax, ymax


@kernel
def integrate_sonar(L, stamp, scan0, poses, ranges, bearings, sector_lo, sector_hi, half_width, wrap, uniform,
                    min_range, max_range, ignore_max, arc, ox, oy, gx0, gy0, res, l_occ, l_free, l_min, l_max):
    """Cone updates for N readings rings (poses (N, 3), ranges (N, k), bearings (k,)).

    For reading b a cell's angle from the transducer axis is φ = atan2(cell − robot) − θ − bearing,
    wrapped into (−π, π] when ``wrap``. The reading updates, once, every cell within its reach whose
    φ satisfies |φ| ≤ half_width and sector_lo[b] ≤ φ < sector_hi[b] (±inf: no sector limit),
    weighted by 1 − (φ/half_width)², or by 1 when ``uniform``. Readings that are NaN, ≤ 0 or below
    ``min_range`` are dropped; those at or beyond ``max_range`` clear their cone up to it, except
    that with ``ignore_max`` those beyond it are skipped. No cell beyond ``max_range`` is touched (an arc near it is cut
    there). ``L[r, c]`` is the cell ``(gx0 + c, gy0 + r)`` of the lattice with origin ``(ox, oy)``.
    Returns (readings used, readings dropped, max-range readings)."""
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
            if not (r > 0.0) or r < min_range:
                dropped += 1
                continue
            hit = r < max_range
            reach = r if hit else max_range
            if not hit:
                maxed += 1
                if ignore_max and r > max_range:
                    continue
            used += 1
            axis = th + bearings[b]
            lo = sector_lo[b]
            hi = sector_hi[b]
            outer = min(reach + 0.5 * arc, max_range)  # nothing beyond max_range (Table 9.2)
            ix0 = max(0, int(math.floor((x0 - outer - ox) / res)) - gx0)
            ix1 = min(W - 1, int(math.floor((x0 + outer - ox) / res)) - gx0)
            iy0 = max(0, int(math.floor((y0 - outer - oy) / res)) - gy0)
            iy1 = min(H - 1, int(math.floor((y0 + outer - oy) / res)) - gy0)
            for iy in range(iy0, iy1 + 1):
                cy = oy + (gy0 + iy + 0.5) * res - y0
                for ix in range(ix0, ix1 + 1):
                    cx = ox + (gx0 + ix + 0.5) * res - x0
                    d = math.sqrt(cx * cx + cy * cy)
                    if d > outer:
                        continue
                    phi = math.atan2(cy, cx) - axis
                    if wrap:
                        phi = wrap_angle_one(phi)
                    if abs(phi) > half_width or phi < lo or phi >= hi:
                        continue
                    w = 1.0 if uniform else 1.0 - (phi / half_width) ** 2
                    if hit and d >= reach - 0.5 * arc:
                        L[iy, ix] = clamp_add(L[iy, ix], w * l_occ, l_min, l_max)
                        stamp[iy, ix] = hit_stamp(s)
                    else:
                        L[iy, ix] = clamp_add(L[iy, ix], w * l_free, l_min, l_max)
                        if stamp[iy, ix] < miss_stamp(s):
                            stamp[iy, ix] = miss_stamp(s)
    return used, dropped, maxed


# ---------------------------------------------------------------------------------------------
# radar: one wedge per detection


@kernel
def _first_obstacle(L, x0, y0, x1, y1, ox, oy, gx0, gy0, res, l_obstacle):
    """Distance from (x0, y0) to the centre of the first cell at or above ``l_obstacle`` on the
    walk from (x0, y0) to (x1, y1); inf when there is none (cells outside ``L`` are unknown)."""
    H, W = L.shape
    steps, state = dda_init(x0, y0, x1, y1, ox, oy, 1.0 / res)
    for _ in range(steps + 1):
        ix, iy = state[0] - gx0, state[1] - gy0
        if 0 <= ix < W and 0 <= iy < H and L[iy, ix] >= l_obstacle:
            return math.hypot(ox + (state[0] + 0.5) * res - x0, oy + (state[1] + 0.5) * res - y0)
        state = dda_step(state)
    return math.inf


@kernel
def integrate_radar(L, stamp, scan0, poses, starts, ranges, azimuths, moving, sigma_range, extent, ghost_margin,
                    ox, oy, gx0, gy0, res, l_occ, l_free, l_obstacle, l_min, l_max):
    """Updates for radar detections (:class:`~occmap.grid2d.RadarModel`).

    Sweep ``k`` was seen from ``poses[k]`` (x, y, heading); its detections are
    ``starts[k] .. starts[k + 1] − 1``, detection ``j`` at ``ranges[j]`` along ``azimuths[j]``
    (from the heading). In its frame a cell centre has axial offset ``a > 0``, lateral offset
    ``l`` and distance ``d``; with ``σ_r = max(sigma_range, res/2)`` and ``σ_l = res/2``, cells
    with ``|l| ≤ extent·σ_l`` get ``l_free · exp(−½(l/σ_l)²)`` where ``d < r − extent·σ_r`` and,
    unless the detection is ``moving``, ``l_occ · exp(−½((d − r)/σ_r)² − ½(l/σ_l)²)`` where
    ``|d − r| ≤ extent·σ_r``. A detection whose central ray meets a cell at or above
    ``l_obstacle`` more than ``ghost_margin`` before ``r − extent·σ_r`` lies behind a known
    obstacle (a multipath ghost, or clutter beyond a wall) and updates nothing. Where the ray meets
    such a cell after that (within the margin or the band), the detection is of that surface:
    no free evidence from a cell before it on, no occupied evidence more than half a cell beyond
    it (the range error would otherwise thin known surfaces or thicken them on their far side).
    These tests read the map as it was before the sweep, so a sweep's detections are
    simultaneous. Returns (detections used, ghosts)."""
    sr = max(sigma_range, 0.5 * res)
    sl = 0.5 * res
    used = 0
    ghosts = 0
    free_to = np.empty(ranges.shape[0])
    hit_to = np.empty(ranges.shape[0])
    for k in range(poses.shape[0]):
        s = scan0 + k
        x0, y0 = poses[k, 0], poses[k, 1]
        for j in range(starts[k], starts[k + 1]):
            r = ranges[j]
            ux, uy = math.cos(poses[k, 2] + azimuths[j]), math.sin(poses[k, 2] + azimuths[j])
            free_to[j] = r - extent * sr
            hit_to[j] = r + extent * sr
            seen_to = free_to[j] - ghost_margin
            if seen_to > 0.0 and _first_obstacle(L, x0, y0, x0 + seen_to * ux, y0 + seen_to * uy, ox, oy, gx0, gy0,
                                                 res, l_obstacle) < math.inf:
                hit_to[j] = -1.0  # a ghost
                continue
            # a known surface within the margin and the band: the detection is of it
            near = max(seen_to, 0.0)
            surface = near + _first_obstacle(L, x0 + near * ux, y0 + near * uy, x0 + hit_to[j] * ux,
                                             y0 + hit_to[j] * uy, ox, oy, gx0, gy0, res, l_obstacle)
            hit_to[j] = min(hit_to[j], surface + 0.5 * res)
            free_to[j] = min(free_to[j], surface - res)
        for j in range(starts[k], starts[k + 1]):
            if hit_to[j] < 0.0:
                ghosts += 1
                continue
            used += 1
            ux, uy = math.cos(poses[k, 2] + azimuths[j]), math.sin(poses[k, 2] + azimuths[j])
            _radar_strip(L, stamp, s, x0, y0, ux, uy, ranges[j], free_to[j], hit_to[j], moving[j], sr, sl, extent,
                         ox, oy, gx0, gy0, res, l_occ, l_free, l_min, l_max)
    return used, ghosts


@kernel
def _radar_strip(L, stamp, s, x0, y0, ux, uy, r, free_to, hit_to, moving, sr, sl, extent, ox, oy, gx0, gy0, res,
                 l_occ, l_free, l_min, l_max):
    """One detection's updates (:func:`integrate_radar`) on the cells of its strip."""
    H, W = L.shape
    inv_res = 1.0 / res
    # walk the strip along its major axis m (x or y); per column of it, the cells of the minor
    # axis n within the strip's half-width (plus a cell) of the centre line
    steep = abs(uy) > abs(ux)
    if steep:
        m0, n0, um, un, om, on, gm0, gn0, M, N = y0, x0, uy, ux, oy, ox, gy0, gx0, H, W
    else:
        m0, n0, um, un, om, on, gm0, gn0, M, N = x0, y0, ux, uy, ox, oy, gx0, gy0, W, H
    margin = extent * sl + res
    half = margin / abs(um)
    reach = max(hit_to, free_to)
    i0 = max(0, int(math.floor((min(m0, m0 + reach * um) - margin - om) * inv_res)) - gm0)
    i1 = min(M - 1, int(math.floor((max(m0, m0 + reach * um) + margin - om) * inv_res)) - gm0)
    for i in range(i0, i1 + 1):
        cn = n0 + (om + (gm0 + i + 0.5) * res - m0) * un / um
        k0 = max(0, int(math.floor((cn - half - on) * inv_res)) - gn0)
        k1 = min(N - 1, int(math.floor((cn + half - on) * inv_res)) - gn0)
        for kk in range(k0, k1 + 1):
            ix, iy = (kk, i) if steep else (i, kk)
            cx = ox + (gx0 + ix + 0.5) * res - x0
            cy = oy + (gy0 + iy + 0.5) * res - y0
            a = cx * ux + cy * uy
            lat = cy * ux - cx * uy
            if a <= 0.0 or abs(lat) > extent * sl:
                continue
            d = math.sqrt(cx * cx + cy * cy)
            if d < free_to:
                L[iy, ix] = clamp_add(L[iy, ix], math.exp(-0.5 * (lat / sl) ** 2) * l_free, l_min, l_max)
                if stamp[iy, ix] < miss_stamp(s):
                    stamp[iy, ix] = miss_stamp(s)
            elif d <= hit_to and not moving:
                w = math.exp(-0.5 * ((d - r) / sr) ** 2 - 0.5 * (lat / sl) ** 2)
                L[iy, ix] = clamp_add(L[iy, ix], w * l_occ, l_min, l_max)
                stamp[iy, ix] = hit_stamp(s)
