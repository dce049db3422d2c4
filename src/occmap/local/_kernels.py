"""Numba kernels of the local map: plain arrays in, arrays updated in place.

Storage (see :class:`occmap.local.LocalMap`): ``cells`` float32 (H, W, 2) and ``stamps``, an
int32 view of the same buffer; per cell ``cells[r, c, 0]`` is the *scaled* log-odds
``u = (l − l_prior) / g`` (``g`` the map's global decay factor) and ``stamps[r, c, 1]`` the scan
stamp (:mod:`occmap.raster.update`). The sensing kernels see them flat: ``Lf = cells.reshape(-1)``
and ``Sf = stamps.reshape(-1)[1:]``, so cell ``(r, c)`` is index ``2·(r·W + c)`` of both.
``rmark`` (int32, (H, W)) holds, per end cell, the last scan that cast a ray to it.

The storage is a circular buffer, one ring per axis (:mod:`occmap.raster.ring`): window cell
``(wy, wx)`` (row 0 at the window's origin) lives at storage ``(slot(wy, sr, H), slot(wx, sc, W))``.
Window cell (wy, wx) is the cell ``(gy0 + wy, gx0 + wx)`` of the world lattice (the grid
conventions of :mod:`occmap.raster` with the origin at (0, 0)).
"""

from __future__ import annotations

import math

import numpy as np

from numba import prange

from .._jit import kernel, kernel_parallel
from .._threads import ThreadChoice
from ..raster.edt import row_envelope
from ..raster.ring import run_of, slot, wrap_point
from ..raster.update import UNSEEN, clamp_add, hit_stamp
from ..raster.walk2d import cell_of, dda_setup, dda_span, dda_step, miss_walk

#: Above this many cells of inflation radius the row pass uses the Felzenszwalb–Huttenlocher
#: lower envelope instead of the direct (2R + 1)-wide window minimum.
WINDOW_MAX_RADIUS = 24

# ---------------------------------------------------------------------------------------------
# moving the window


@kernel
def clear_columns(cells, c0, n):
    """Zero (unknown, never observed) ``n`` storage columns from ``c0`` on (modulo W), all rows.
    Returns the number of cells written."""
    H, W = cells.shape[0], cells.shape[1]
    touched = 0
    for y in range(H):
        for k in range(n):
            c = slot(k, c0, W)
            cells[y, c, 0] = 0.0
            cells[y, c, 1] = 0.0  # all-zero bits: stamp 0
            touched += 1
    return touched


@kernel
def clear_rows(cells, r0, n):
    """Zero ``n`` storage rows from ``r0`` on (modulo H), all columns. Returns cells written."""
    H, W = cells.shape[0], cells.shape[1]
    touched = 0
    for k in range(n):
        r = slot(k, r0, H)
        for c in range(W):
            cells[r, c, 0] = 0.0
            cells[r, c, 1] = 0.0
            touched += 1
    return touched


# ---------------------------------------------------------------------------------------------
# sensing


@kernel
def _walk(Lf, Sf, sr, sc, gx0, gy0, H, W, xlo, xhi, u0, v0, ex, ey, s, d_miss, lo, hi):
    """Free update of the cells from lattice point (u0, v0) (cell units) to the centre of lattice
    cell (ex, ey), end cell excluded, that lie in the part ``xlo ≤ wx < xhi`` of the window (all
    rows), each at most once per scan: the walk of :mod:`occmap.raster.walk2d`, over each of the
    (at most four) rectangles of the part whose storage does not wrap (a window range lies in at
    most two runs of a ring, :func:`occmap.raster.ring.wrap_point`), so no step wraps.
    Returns (cells updated, cells visited)."""
    steps, state = dda_setup(u0, v0, ex + 0.5, ey + 0.5)
    s_in, s_out, _, _ = dda_span(state, gx0 + xlo, gx0 + xhi, gy0, gy0 + H)
    n = min(s_out, steps) - s_in
    if n <= 0:
        return 0, 0
    px = wrap_point(sc, W)
    py = wrap_point(sr, H)
    updated = 0
    for qy in range(2):
        ya, yb = (0, py) if qy == 0 else (py, H)
        dy = sr if qy == 0 else sr - H  # storage row = window row + dy in this run
        for qx in range(2):
            xa, xb = (max(xlo, 0), min(xhi, px)) if qx == 0 else (max(xlo, px), min(xhi, W))
            if ya >= yb or xa >= xb:
                continue
            dx = sc if qx == 0 else sc - W
            # lattice cell (gx, gy) is storage (gy − gy0 + dy, gx − gx0 + dx), two floats a cell
            base = 2 * ((dy - gy0) * W + (dx - gx0))
            updated += miss_walk(Lf, Sf, base, 2, 2 * W, steps, state, gx0 + xa, gx0 + xb, gy0 + ya, gy0 + yb,
                                 s, d_miss, lo, hi)
    return updated, n


@kernel
def _walk_rays(Lf, Sf, sr, sc, gx0, gy0, H, W, xlo, xhi, u0, v0, rays, n_rays, s, d_miss, lo, hi):
    """:func:`_walk` of the first ``n_rays`` rays (end cells, lattice (gx, gy) rows of ``rays``)
    over the part ``xlo ≤ wx < xhi``. Returns (cells updated, cells visited)."""
    updated = 0
    visited = 0
    for k in range(n_rays):
        a, b = _walk(Lf, Sf, sr, sc, gx0, gy0, H, W, xlo, xhi, u0, v0, rays[k, 0], rays[k, 1], s, d_miss, lo, hi)
        updated += a
        visited += b
    return updated, visited


#: Lattice indices are packed as 31-bit fields offset by this (so keys stay positive int64);
#: any index within ±2³⁰ cells (over 100,000 km at 0.1 mm) fits.
_KEY_OFFSET = 1 << 30


@kernel
def _part(Lf, Sf, rmark, sr, sc, gx0, gy0, inv_res, u0, v0, ends, kinds, s, d_hit, d_miss, lo, hi,
          xlo, xhi, split, side, own_rays, counts):
    """The updates of one part ``xlo ≤ wx < xhi`` of the window: the hits that end in it, and the
    rays it owns (``side`` 0: end column < ``split``; 1: ≥ ``split``; −1: all), one per distinct end
    cell (those ending in the window first, in the order of their points), walked over its own
    cells. Owned rays' end cells go to ``own_rays`` (lattice (gx, gy)); ``counts`` gets (hits,
    rays, free updates, cells visited)."""
    H, W = rmark.shape
    n = ends.shape[0]
    hits = 0
    for i in range(n):
        if kinds[i] != 1:
            continue
        gx, gy = cell_of(ends[i, 0], ends[i, 1], 0.0, 0.0, inv_res)
        wx = gx - gx0
        wy = gy - gy0
        if xlo <= wx < xhi and 0 <= wy < H:
            k = 2 * (slot(wy, sr, H) * W + slot(wx, sc, W))
            if Sf[k] != hit_stamp(s):
                Sf[k] = hit_stamp(s)
                Lf[k] = clamp_add(Lf[k], d_hit, lo, hi)
                hits += 1
    rays = 0
    far = np.empty(n, dtype=np.int64)  # end cells outside the window, packed, for de-duplication
    m = 0
    for i in range(n):
        if kinds[i] == 0:
            continue
        gx, gy = cell_of(ends[i, 0], ends[i, 1], 0.0, 0.0, inv_res)
        wx = gx - gx0
        wy = gy - gy0
        if side >= 0 and (wx < split) != (side == 0):
            continue
        if 0 <= wx < W and 0 <= wy < H:
            r = slot(wy, sr, H)
            c = slot(wx, sc, W)
            if rmark[r, c] == s:
                continue
            rmark[r, c] = s
            own_rays[rays, 0] = gx
            own_rays[rays, 1] = gy
            rays += 1
        else:
            far[m] = ((gx + _KEY_OFFSET) << 32) | (gy + _KEY_OFFSET)
            m += 1
    if m > 0:
        keys = np.sort(far[:m])
        for k in range(m):
            if k > 0 and keys[k] == keys[k - 1]:
                continue
            gx = (keys[k] >> 32) - _KEY_OFFSET
            gy = (keys[k] & 0xFFFFFFFF) - _KEY_OFFSET
            own_rays[rays, 0] = gx
            own_rays[rays, 1] = gy
            rays += 1
    updated, visited = _walk_rays(Lf, Sf, sr, sc, gx0, gy0, H, W, xlo, xhi, u0, v0, own_rays, rays, s, d_miss, lo, hi)
    counts[0] = hits
    counts[1] = rays
    counts[2] = updated
    counts[3] = visited


@kernel_parallel
def _two_parts(Lf, Sf, rmark, sr, sc, gx0, gy0, inv_res, u0, v0, ends, kinds, s, d_hit, d_miss, lo, hi,
               split, rays, counts):
    W = rmark.shape[1]
    for p in prange(2):
        _part(Lf, Sf, rmark, sr, sc, gx0, gy0, inv_res, u0, v0, ends, kinds, s, d_hit, d_miss, lo, hi,
              0 if p == 0 else split, split if p == 0 else W, split, p, rays[p], counts[p])


@kernel
def _serial(Lf, Sf, rmark, sr, sc, gx0, gy0, inv_res, u0, v0, ends, kinds, s, d_hit, d_miss, lo, hi,
            rays, counts):
    W = rmark.shape[1]
    _part(Lf, Sf, rmark, sr, sc, gx0, gy0, inv_res, u0, v0, ends, kinds, s, d_hit, d_miss, lo, hi,
          0, W, 0, -1, rays, counts)


#: Scans with at least this many readings, in windows of at least this many cells, may be
#: integrated by two threads (the window cut at the sensor's column), when :data:`THREADS` finds
#: two threads the cheaper.
PARALLEL_MIN_POINTS = 4096
PARALLEL_MIN_CELLS = 40_000
THREADS = ThreadChoice(min_work=PARALLEL_MIN_POINTS)


def integrate(cells, stamps, rmark, sr, sc, gx0, gy0, inv_res, px, py, ends, kinds, s, d_hit, d_miss, lo, hi,
              parallel=None):
    """One scan from sensor position (px, py): ``ends`` (N, 2) world end points, ``kinds`` (N,)
    int8: 0 skip, 1 return (the end cell is hit, the cells before it free), 2 clear only (the
    cells before the end cell free, nothing marked). Hits first, each cell once (stamp 2s + 1);
    then one ray per distinct end cell, cast to that cell's centre, freeing each cell not yet
    updated in this scan (stamp 2s). Returns (hits applied, rays cast, free updates, cells visited).

    In parallel (default: :data:`THREADS` chooses, for big enough scans and windows) the window is cut
    at the sensor's column: each half takes the hits ending in it and the rays whose end lies on
    its side, updating only its own cells; the sensor's column cells of the left rays follow,
    serially. Within a scan each cell's update does not depend on order, so the result is the
    same as one thread's."""
    H, W = rmark.shape
    n = ends.shape[0]
    u0 = px * inv_res
    v0 = py * inv_res
    split = int(math.floor(u0)) - gx0
    if parallel is None:
        with THREADS.choose(n if H * W >= PARALLEL_MIN_CELLS else 0) as parallel:
            return integrate(cells, stamps, rmark, sr, sc, gx0, gy0, inv_res, px, py, ends, kinds, s, d_hit, d_miss,
                             lo, hi, parallel)
    counts = np.zeros((2, 4), dtype=np.int64)
    rays = np.empty((2, n, 2), dtype=np.int64)
    Lf = cells.reshape(-1)
    Sf = stamps.reshape(-1)[1:]
    if parallel and 0 < split < W:
        _two_parts(Lf, Sf, rmark, sr, sc, gx0, gy0, inv_res, u0, v0, ends, kinds, s, d_hit, d_miss, lo, hi,
                   split, rays, counts)
        # the cells in column split (the sensor's) of the rays whose end lies left of it: the left
        # part skipped them, the right part never walked those rays
        a, b = _walk_rays(Lf, Sf, sr, sc, gx0, gy0, H, W, split, split + 1, u0, v0, rays[0], counts[0, 1], s,
                          d_miss, lo, hi)
        counts[0, 2] += a
        counts[0, 3] += b
    else:
        _serial(Lf, Sf, rmark, sr, sc, gx0, gy0, inv_res, u0, v0, ends, kinds, s, d_hit, d_miss, lo, hi,
                rays[0], counts[0])
    t = counts.sum(axis=0)
    return int(t[0]), int(t[1]), int(t[2]), int(t[3])


@kernel
def scan_ends(pose, ranges, angles, max_range, ends, kinds):
    """End points and kinds of a planar scan from sensor pose (x, y, θ): NaN/≤ 0 readings kind 0
    (dropped), readings at or beyond ``max_range`` (or infinite) clear up to it (kind 2), the rest
    are returns (kind 1). Returns (dropped, max-range readings)."""
    x0, y0, th = pose[0], pose[1], pose[2]
    dropped = 0
    maxed = 0
    for i in range(ranges.shape[0]):
        r = ranges[i]
        a = angles[i]
        if not (r > 0.0) or not (a == a):
            kinds[i] = 0
            dropped += 1
            ends[i, 0] = 0.0
            ends[i, 1] = 0.0
            continue
        k = 1
        if not (r < max_range):
            r = max_range
            k = 2
            maxed += 1
        kinds[i] = k
        ends[i, 0] = x0 + r * math.cos(th + a)
        ends[i, 1] = y0 + r * math.sin(th + a)
    return dropped, maxed


@kernel
def radar_ends(cells, stamps, sr, sc, gx0, gy0, inv_res, thr_obstacle, pose, ranges, azimuths, moving, unseen_before,
               ends, kinds):
    """End points and kinds of one radar sweep's detections from sensor pose (x, y, θ): a
    detection whose ray meets an observed window cell at or above ``thr_obstacle`` before
    ``ranges[i] − unseen_before`` lies behind a known obstacle (a ghost): kind 0; ``moving`` ones
    clear up to their point (kind 2); the others are returns (kind 1). Returns the ghosts."""
    H, W = cells.shape[0], cells.shape[1]
    x0, y0, th = pose[0], pose[1], pose[2]
    ghosts = 0
    for i in range(ranges.shape[0]):
        ux, uy = math.cos(th + azimuths[i]), math.sin(th + azimuths[i])
        r = ranges[i]
        ends[i, 0] = x0 + r * ux
        ends[i, 1] = y0 + r * uy
        kinds[i] = 2 if moving[i] else 1
        seen = r - unseen_before
        if seen <= 0.0:
            continue
        steps, state = dda_setup(x0 * inv_res, y0 * inv_res, (x0 + seen * ux) * inv_res, (y0 + seen * uy) * inv_res)
        for _ in range(steps + 1):
            wx, wy = state[0] - gx0, state[1] - gy0
            if 0 <= wx < W and 0 <= wy < H:
                rr, cc = slot(wy, sr, H), slot(wx, sc, W)
                if stamps[rr, cc, 1] != UNSEEN and cells[rr, cc, 0] >= thr_obstacle:
                    kinds[i] = 0
                    ghosts += 1
                    break
            state = dda_step(state)
    return ghosts


@kernel
def cloud_ends(points, z_min, z_max, ends, kinds):
    """Kinds of 3D world points: non-finite → 0 (dropped), ``z_min ≤ z ≤ z_max`` → 1 (obstacle),
    else 2 (clears along its projected ray). Writes the (x, y) into ``ends``. Returns dropped."""
    dropped = 0
    for i in range(points.shape[0]):
        x = points[i, 0]
        y = points[i, 1]
        z = points[i, 2]
        ends[i, 0] = x
        ends[i, 1] = y
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
            kinds[i] = 0
            dropped += 1
        elif z_min <= z <= z_max:
            kinds[i] = 1
        else:
            kinds[i] = 2
    return dropped


@kernel
def rescale(cells, factor):
    """``u ← u · factor`` for every cell (folds the global decay factor into the cells)."""
    H, W = cells.shape[0], cells.shape[1]
    for r in range(H):
        for c in range(W):
            cells[r, c, 0] *= factor


# ---------------------------------------------------------------------------------------------
# read-outs


@kernel
def log_odds(cells, stamps, sr, sc, g, l_prior, out):
    """Log-odds (float32, window order) into ``out``; NaN where never observed."""
    H, W = out.shape
    for y in range(H):
        r = slot(y, sr, H)
        for x in range(W):
            c = slot(x, sc, W)
            if stamps[r, c, 1] == UNSEEN:
                out[y, x] = np.nan
            else:
                out[y, x] = l_prior + g * cells[r, c, 0]


@kernel
def lethal(cells, stamps, sr, sc, g, l_prior, l_occupied, out):
    """Cells (bool, window order) into ``out`` whose log-odds, as :func:`log_odds` gives it
    (float32), is at least ``l_occupied``; False where never observed."""
    H, W = out.shape
    for y in range(H):
        r = slot(y, sr, H)
        for seg in range(2):  # a row's storage columns wrap once
            x0, x1, off = run_of(seg, sc, W)
            for x in range(x0, x1):  # branch-free, so it vectorises
                c = x + off
                out[y, x] = (stamps[r, c, 1] != UNSEEN) & (np.float32(l_prior + g * cells[r, c, 0]) >= l_occupied)


@kernel
def classify_returns(cells, stamps, sr, sc, gx0, gy0, inv_res, thr_free, thr_occ, reach, pts, kinds, open_, occupied,
                     unseen, walled, memo):
    """For each return (``kinds[i] == 1``) at world point ``pts[i]``: ``occupied[i]``, its cell is
    observed and occupied (``u ≥ thr_occ``); ``unseen[i]``, its cell is inside the window and
    never observed; ``walled[i]``, a cell within ``reach`` cells (a square, inside the window) is
    observed and occupied; ``open_[i]``, its cell and its eight neighbours are observed and free
    (``u < thr_free``) and it is not walled. All false for the other points. Each cell is looked at
    once however many returns fall in it (a 3D cloud puts dozens in one): ``memo`` (uint8 (H, W),
    window order) holds the answers meanwhile, all zero on entry and left so."""
    H, W = cells.shape[0], cells.shape[1]
    for i in range(pts.shape[0]):
        open_[i] = False
        occupied[i] = False
        unseen[i] = False
        walled[i] = False
        if kinds[i] != 1:
            continue
        gx, gy = cell_of(pts[i, 0], pts[i, 1], 0.0, 0.0, inv_res)
        wx = gx - gx0
        wy = gy - gy0
        if not (0 <= wx < W and 0 <= wy < H):
            continue
        known = memo[wy, wx]
        if known == 0:
            r = slot(wy, sr, H)
            c = slot(wx, sc, W)
            never = stamps[r, c, 1] == UNSEEN
            wall = not never and cells[r, c, 0] >= thr_occ
            known = 1 | (2 if wall else 0) | (4 if never else 0)
            free = 1 <= wx < W - 1 and 1 <= wy < H - 1
            for yy in range(max(wy - reach, 0), min(wy + reach + 1, H)):
                if wall:
                    break
                r = slot(yy, sr, H)
                for xx in range(max(wx - reach, 0), min(wx + reach + 1, W)):
                    c = slot(xx, sc, W)
                    seen = stamps[r, c, 1] != UNSEEN
                    if seen and cells[r, c, 0] >= thr_occ:
                        wall = True
                        break
                    if abs(xx - wx) <= 1 and abs(yy - wy) <= 1 and not (seen and cells[r, c, 0] < thr_free):
                        free = False
            known |= (8 if wall else 0) | (16 if free and not wall else 0)
            memo[wy, wx] = known
        occupied[i] = known & 2 != 0
        unseen[i] = known & 4 != 0
        walled[i] = known & 8 != 0
        open_[i] = known & 16 != 0
    for i in range(pts.shape[0]):
        if kinds[i] == 1:
            gx, gy = cell_of(pts[i, 0], pts[i, 1], 0.0, 0.0, inv_res)
            if 0 <= gx - gx0 < W and 0 <= gy - gy0 < H:
                memo[gy - gy0, gx - gx0] = 0
    return open_


@kernel
def costmap(cells, stamps, sr, sc, thr_occ, thr_free, R, lut, inscribed_d2, g, extra, out):
    """The inflated costmap, in window order, into ``out`` (uint8 (H, W)).

    A cell is lethal (254) when observed and ``u ≥ thr_occ`` or when ``extra`` (bool (H, W), window
    order: objects placed by the caller) holds it, free when observed and
    ``u < thr_free``, unknown (255) otherwise. Inflation from the exact squared Euclidean distance
    ``d²`` (cells, between centres) to the nearest lethal cell, needed only up to ``R`` cells: the
    column distances (capped at R + 1) then, per row, the minimum over the 2R + 1 columns around
    (or the lower envelope of parabolas, for large R). Free cells get ``lut[d²]`` (its last
    entry, 0, stands for every d² beyond the radius; d² ≤ 2R²); unknown cells become 253 within the inscribed radius
    (``d² ≤ inscribed_d2``) and stay 255 otherwise (Nav2's default, inflate_unknown false).
    ``g`` is (H, W) integer scratch (uint8 when R < 254). All per-cell work is inline.
    """
    H, W = out.shape
    C = R + 1
    # pass 1: classes and downward column distances, one window row at a time; the row's storage
    # columns wrap once
    for y in range(H):
        r = slot(y, sr, H)
        yp = y - 1 if y > 0 else 0
        for seg in range(2):
            x0, x1, off = run_of(seg, sc, W)
            for x in range(x0, x1):  # branch-free, so it vectorises
                c = x + off
                u = cells[r, c, 0]
                seen = stamps[r, c, 1] != UNSEEN
                lethal = (seen & (u >= thr_occ)) | extra[y, x]
                free = seen & (u < thr_free) & ~lethal
                out[y, x] = 255 - np.uint8(lethal) - 255 * np.uint8(free)
                gv = min(g[yp, x] + 1, C) if y > 0 else C  # row 0: nothing above
                g[y, x] = 0 if lethal else gv
    # pass 2: upward
    for y in range(H - 2, -1, -1):
        for x in range(W):
            g[y, x] = min(np.int32(g[y, x]), np.int32(g[y + 1, x]) + 1)
    # pass 3: per row, d² to the nearest lethal cell within R, then the cost
    n_lut = lut.shape[0]
    big = n_lut - 1  # lut[big] = 0: beyond the inflation radius
    d2 = np.empty(W, dtype=np.int32)
    if R <= WINDOW_MAX_RADIUS:
        gp = np.empty(W + 2 * R, dtype=np.int32)
        for j in range(R):
            gp[j] = C * C
            gp[W + R + j] = C * C
    else:
        row = np.empty(W)
        f = np.empty(W)
        v = np.empty(W, dtype=np.int64)
        z = np.empty(W + 1)
    for y in range(H):
        near = 0
        for x in range(W):
            near += g[y, x] < C
        if near == 0:  # no lethal cell within R of this row: nothing to inflate
            continue
        if R <= WINDOW_MAX_RADIUS:
            for x in range(W):
                gv = np.int32(g[y, x])
                gp[R + x] = gv * gv
            for x in range(W):
                d2[x] = gp[x + R]
            for j in range(2 * R + 1):
                dd = (j - R) * (j - R)
                for x in range(W):
                    d2[x] = min(d2[x], dd + gp[x + j])
        else:
            for x in range(W):
                row[x] = g[y, x] if g[y, x] < C else np.inf
            row_envelope(row, f, v, z)
            for x in range(W):
                d2[x] = big if row[x] >= big else int(row[x])
        for x in range(W):
            cls = out[y, x]
            dd = min(d2[x], big)
            if cls == 0:
                out[y, x] = lut[dd] if dd < n_lut else 0
            elif cls == 255 and dd <= inscribed_d2:
                out[y, x] = 253


# ---------------------------------------------------------------------------------------------
# queries


@kernel
def cost_at(cost, gx0, gy0, inv_res, pts, out):
    """Cost of the cell under each world point (N, 2); 255 outside the window or for a
    non-finite point. Returns the number of non-finite points."""
    H, W = cost.shape
    bad = 0
    for i in range(pts.shape[0]):
        x = pts[i, 0]
        y = pts[i, 1]
        if not (math.isfinite(x) and math.isfinite(y)):
            out[i] = 255
            bad += 1
            continue
        gx, gy = cell_of(x, y, 0.0, 0.0, inv_res)
        wx = gx - gx0
        wy = gy - gy0
        out[i] = cost[wy, wx] if (0 <= wx < W and 0 <= wy < H) else 255
    return bad


@kernel
def check_path(cost, gx0, gy0, inv_res, poses, footprint, radius, unknown_collides, max_cost):
    """Per pose (x, y, θ) the maximum cost of the cells under the footprint: for a polygon
    (``footprint`` (M, 2) in the body frame, ``radius`` < 0) the cells its edges cross and the
    cells whose centre lies inside; for a disc (``radius`` ≥ 0) the cells whose centre lies
    within ``radius`` of the pose and the cell under it. Cells outside the window cost 255.
    Non-finite poses get 255 and are not collisions. Writes ``max_cost`` (N,) uint8; returns
    (index of the first pose in collision or −1, non-finite poses). A collision is a lethal cell
    (254), or an unknown one (255) when ``unknown_collides``. Every per-cell step is inline."""
    H, W = cost.shape
    n = poses.shape[0]
    M = footprint.shape[0]
    us = np.empty(M + 1)
    vs = np.empty(M + 1)
    xs = np.empty(M + 2)
    first = -1
    bad = 0
    for i in range(n):
        px = poses[i, 0]
        py = poses[i, 1]
        th = poses[i, 2]
        if not (math.isfinite(px) and math.isfinite(py) and math.isfinite(th)):
            max_cost[i] = 255
            bad += 1
            continue
        u = px * inv_res - gx0  # window cell units, the lattice arithmetic of cost_at
        v = py * inv_res - gy0
        ix = int(math.floor(u))
        iy = int(math.floor(v))
        best = cost[iy, ix] if (0 <= ix < W and 0 <= iy < H) else 255
        lethal = best == 254  # a lethal cell collides even where unknown (255) outranks it in max_cost
        if radius >= 0.0:
            rr = radius * inv_res
            j0 = int(math.floor(v - rr))
            j1 = int(math.floor(v + rr))
            for j in range(j0, j1 + 1):
                dy = j + 0.5 - v
                h2 = rr * rr - dy * dy
                if h2 < 0.0:
                    continue
                h = math.sqrt(h2)
                for k in range(int(math.ceil(u - h - 0.5)), int(math.floor(u + h - 0.5)) + 1):
                    c = cost[j, k] if (0 <= k < W and 0 <= j < H) else 255
                    best = max(best, c)
                    lethal = lethal or c == 254
        else:
            ct = math.cos(th)
            st = math.sin(th)
            vmin = np.inf
            vmax = -np.inf
            for k in range(M):
                bx = footprint[k, 0]
                by = footprint[k, 1]
                us[k] = u + (ct * bx - st * by) * inv_res
                vs[k] = v + (st * bx + ct * by) * inv_res
                vmin = min(vmin, vs[k])
                vmax = max(vmax, vs[k])
            us[M] = us[0]
            vs[M] = vs[0]
            for k in range(M):  # the outline: the cells each edge crosses (the one 2D walk)
                u0 = us[k]
                v0 = vs[k]
                u1 = us[k + 1]
                v1 = vs[k + 1]
                steps, state = dda_setup(u0, v0, u1, v1)
                for t in range(steps + 1):
                    if t > 0:
                        state = dda_step(state)
                    ix, iy = state[0], state[1]
                    c = cost[iy, ix] if (0 <= ix < W and 0 <= iy < H) else 255
                    best = max(best, c)
                    lethal = lethal or c == 254
            for j in range(int(math.floor(vmin)), int(math.floor(vmax)) + 1):  # the inside, by scanlines
                yc = j + 0.5
                m = 0
                for k in range(M):
                    va = vs[k]
                    vb = vs[k + 1]
                    if (va <= yc < vb) or (vb <= yc < va):
                        xs[m] = us[k] + (yc - va) * (us[k + 1] - us[k]) / (vb - va)
                        m += 1
                for a in range(1, m):  # insertion sort: a handful of crossings
                    t = xs[a]
                    b = a - 1
                    while b >= 0 and xs[b] > t:
                        xs[b + 1] = xs[b]
                        b -= 1
                    xs[b + 1] = t
                for q in range(0, m - 1, 2):
                    for k in range(int(math.ceil(xs[q] - 0.5)), int(math.floor(xs[q + 1] - 0.5)) + 1):
                        c = cost[j, k] if (0 <= k < W and 0 <= j < H) else 255
                        best = max(best, c)
                        lethal = lethal or c == 254
        max_cost[i] = best
        if first < 0 and (lethal or (unknown_collides and best == 255)):
            first = i
    return first, bad
