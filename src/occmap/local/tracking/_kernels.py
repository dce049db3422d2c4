"""Numba kernels of the tracker: optimal assignment (the Hungarian method), the clustering, box
fitting and occlusion test of detections, box corners, and the probability that a place lies under
a tracked object. Plain arrays in and out; the callers check shapes and values."""

from __future__ import annotations

import math

import numpy as np

from ..._jit import inline_kernel, kernel


@kernel
def min_cost_assignment(cost, out):
    """Rows matched to distinct columns at least total cost, for ``cost`` ``(n, m)`` with
    ``n ≤ m`` and finite entries: ``out[i]`` = the column of row ``i``.

    Shortest augmenting paths with row and column potentials (Kuhn–Munkres as in Jonker and
    Volgenant 1987): ``O(n² m)``."""
    n, m = cost.shape
    u = np.zeros(n + 1)
    v = np.zeros(m + 1)
    owner = np.zeros(m + 1, np.int64)  # owner[j]: the row (1-based) holding column j; 0 none
    way = np.zeros(m + 1, np.int64)
    minv = np.empty(m + 1)
    used = np.empty(m + 1, np.bool_)
    for i in range(1, n + 1):
        owner[0] = i
        j0 = 0
        minv[:] = np.inf
        used[:] = False
        while True:
            used[j0] = True
            i0 = owner[j0]
            delta = np.inf
            j1 = 0
            for j in range(1, m + 1):
                if not used[j]:
                    cur = cost[i0 - 1, j - 1] - u[i0] - v[j]
                    if cur < minv[j]:
                        minv[j] = cur
                        way[j] = j0
                    if minv[j] < delta:
                        delta = minv[j]
                        j1 = j
            for j in range(m + 1):
                if used[j]:
                    u[owner[j]] += delta
                    v[j] -= delta
                else:
                    minv[j] -= delta
            j0 = j1
            if owner[j0] == 0:
                break
        while j0 != 0:  # flip the augmenting path
            j1 = way[j0]
            owner[j0] = owner[j1]
            j0 = j1
    for j in range(1, m + 1):
        if owner[j] != 0:
            out[owner[j] - 1] = j - 1
    return out


@kernel
def gated_assignment(cost, rows, cols):
    """:func:`~.assignment.assign` of a cost matrix ``(n, m)`` (``inf`` = not allowed; no NaN, no
    −inf): the matched pairs into ``rows`` and ``cols`` (room for ``min(n, m)``), sorted by row;
    returns their number."""
    n, m = cost.shape
    lo = np.inf
    for i in range(n):
        for j in range(m):
            if cost[i, j] < lo:
                lo = cost[i, j]
    if lo == np.inf:
        return 0
    total = 0.0
    for i in range(n):
        for j in range(m):
            if cost[i, j] < np.inf:
                total += cost[i, j] - lo
    big = 1.0 + total * 2.0  # more than any sum of allowed costs (shifted to be non-negative)
    flip = n > m
    work = np.empty((m, n) if flip else (n, m))
    for i in range(n):
        for j in range(m):
            c = cost[i, j] - lo if cost[i, j] < np.inf else big
            if flip:
                work[j, i] = c
            else:
                work[i, j] = c
    chosen = min_cost_assignment(work, np.empty(work.shape[0], np.int64))
    col_of = chosen
    if flip:  # chosen[j] is column j's row
        col_of = np.full(n, -1, np.int64)
        for j in range(m):
            col_of[chosen[j]] = j
    k = 0
    for i in range(n):
        j = col_of[i]
        if j >= 0 and cost[i, j] < np.inf:
            rows[k] = i
            cols[k] = j
            k += 1
    return k


@inline_kernel
def corner(x, y, c, s, length, width, k):
    """Corner ``k`` (0 – 3, counter-clockwise from the rear right) of a box centred at ``(x, y)``
    with heading ``(cos, sin) = (c, s)`` along its ``length`` and ``width`` across (m)."""
    u = (0.5 if k == 1 or k == 2 else -0.5) * length
    v = (0.5 if k >= 2 else -0.5) * width
    return x + c * u - s * v, y + s * u + c * v


@kernel
def box_corners(x, y, heading, length, width, out):
    """:func:`~.detection.box_corners` into ``out`` (N, 4, 2)."""
    for i in range(x.shape[0]):
        c = np.cos(heading[i])
        s = np.sin(heading[i])
        for k in range(4):
            out[i, k, 0], out[i, k, 1] = corner(x[i], y[i], c, s, length[i], width[i], k)
    return out


@kernel
def stable_order(key):
    """The indices that sort non-negative ``key`` (N,) (int64), equal keys in their order: an LSD
    radix sort on bytes, as many passes as the largest key has bytes (Numba's merge sort takes
    ~50 ns a key; this ~3 ns a key a pass)."""
    n = key.shape[0]
    order = np.arange(n)
    if n == 0:
        return order
    top = key.max()
    spare = np.empty(n, np.int64)
    count = np.empty(257, np.int64)
    shift = 0
    while shift < 64 and (top >> shift) > 0:
        count[:] = 0
        for i in range(n):
            count[((key[order[i]] >> shift) & 255) + 1] += 1
        for d in range(256):
            count[d + 1] += count[d]
        for i in range(n):
            d = (key[order[i]] >> shift) & 255
            spare[count[d]] = order[i]
            count[d] += 1
        order, spare = spare, order
        shift += 8
    return order


@inline_kernel
def _root(parent, i):
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@kernel
def cluster_points(points, gap, labels):
    """Single-linkage clusters of points ``(N, 2)``: two points share a cluster when a chain of
    points at most ``gap`` apart joins them. ``labels[i]`` = cluster of point ``i``, numbered
    ``0, 1, …`` in order of first point; returns the number of clusters.

    Points are binned into square cells of side just under ``gap / √2``, so the points of a cell
    are all within ``gap`` of each other and join at once; cells are then joined to the cells up
    to two away (the only ones that may hold points within ``gap``), a pair of cells compared
    point by point only while they are apart, until the first pair within ``gap``, and only for
    the points within ``gap`` of the other cell's bounding box. The cost grows with the number of
    points, not with the square of a cell's (a 3D cloud's pole projects hundreds of returns into one
    cell)."""
    n = points.shape[0]
    if n == 0:
        return 0
    inv = math.sqrt(2.0) / gap * (1.0 + 1e-9)
    cx = np.empty(n, np.int64)
    cy = np.empty(n, np.int64)
    for i in range(n):
        cx[i] = np.int64(np.floor(points[i, 0] * inv))
        cy[i] = np.int64(np.floor(points[i, 1] * inv))
    ox = cx.min()
    span = cy.max() - cy.min() + 5
    key = (cx - ox + 2) * span + (cy - cy.min() + 2)
    order = stable_order(key)
    skey = key[order]
    # cells: sorted keys, their runs in `order`, bounding boxes of their points
    n_cells = 1
    for a in range(1, n):
        if skey[a] != skey[a - 1]:
            n_cells += 1
    ckey = np.empty(n_cells, np.int64)
    first = np.empty(n_cells + 1, np.int64)
    box = np.empty((n_cells, 4))
    cell_of = np.empty(n, np.int64)
    c = -1
    for a in range(n):
        i = order[a]
        if a == 0 or skey[a] != skey[a - 1]:
            c += 1
            ckey[c] = skey[a]
            first[c] = a
            box[c, 0] = box[c, 1] = points[i, 0]
            box[c, 2] = box[c, 3] = points[i, 1]
        else:
            box[c, 0] = min(box[c, 0], points[i, 0])
            box[c, 1] = max(box[c, 1], points[i, 0])
            box[c, 2] = min(box[c, 2], points[i, 1])
            box[c, 3] = max(box[c, 3], points[i, 1])
        cell_of[i] = c
    first[n_cells] = n
    parent = np.arange(n_cells)
    g2 = gap * gap
    for c in range(n_cells):
        for dx in range(0, 3):
            for dy in range(-2, 3):
                if dx == 0 and dy <= 0:
                    continue  # each pair of cells once
                e = np.searchsorted(ckey, ckey[c] + dx * span + dy)
                if e >= n_cells or ckey[e] != ckey[c] + dx * span + dy:
                    continue
                rc = _root(parent, c)
                re = _root(parent, e)
                if rc == re:
                    continue
                joined = False
                for a in range(first[c], first[c + 1]):
                    i = order[a]
                    # distance from point i to cell e's bounding box
                    ex = max(box[e, 0] - points[i, 0], 0.0, points[i, 0] - box[e, 1])
                    ey = max(box[e, 2] - points[i, 1], 0.0, points[i, 1] - box[e, 3])
                    if ex * ex + ey * ey > g2:
                        continue
                    for b in range(first[e], first[e + 1]):
                        j = order[b]
                        ex = points[i, 0] - points[j, 0]
                        ey = points[i, 1] - points[j, 1]
                        if ex * ex + ey * ey <= g2:
                            joined = True
                            break
                    if joined:
                        break
                if joined:
                    parent[max(rc, re)] = min(rc, re)
    count = 0
    number = np.full(n_cells, -1, np.int64)
    for i in range(n):
        r = _root(parent, cell_of[i])
        if number[r] < 0:
            number[r] = count
            count += 1
        labels[i] = number[r]
    return count


@inline_kernel
def _extents(points, a, b, c, s):
    """Extent ``(lo1, hi1, lo2, hi2)`` of ``points[a:b]`` along ``(c, s)`` and ``(−s, c)``."""
    lo1 = np.inf
    hi1 = -np.inf
    lo2 = np.inf
    hi2 = -np.inf
    for i in range(a, b):
        p1 = c * points[i, 0] + s * points[i, 1]
        p2 = -s * points[i, 0] + c * points[i, 1]
        lo1 = min(lo1, p1)
        hi1 = max(hi1, p1)
        lo2 = min(lo2, p2)
        hi2 = max(hi2, p2)
    return lo1, hi1, lo2, hi2


@kernel
def fit_boxes(points, starts, sample, sample_starts, weights, steps, min_distance, out):
    """Oriented boxes around point clusters by L-shape fitting with the closeness criterion (Zhang
    et al., "Efficient L-shape fitting for vehicle detection using laser scanners", IV 2017).

    Cluster ``k`` is ``points[starts[k]:starts[k + 1]]``; its direction is searched over
    ``sample[sample_starts[k]:sample_starts[k + 1]]``, points standing for ``weights`` of its
    points each. For each of ``steps`` directions θ in [0, π/2) the sample is projected on
    ``e1 = (cos θ, sin θ)`` and ``e2 = (−sin θ, cos θ)``; the score sums, over the sample,
    ``weight / max(d, min_distance)`` with ``d`` the distance to the nearer of the box's two
    nearest edges; the best θ gives the box, around all the cluster's points. ``out[k]`` =
    (centre x, centre y, heading of the longer side in [−π/2, π/2), length, width)."""
    for k in range(starts.shape[0] - 1):
        a = sample_starts[k]
        b = sample_starts[k + 1]
        best = -1.0
        best_t = 0.0
        for s in range(steps):
            t = 0.5 * np.pi * s / steps
            c = np.cos(t)
            sn = np.sin(t)
            lo1, hi1, lo2, hi2 = _extents(sample, a, b, c, sn)
            score = 0.0
            for i in range(a, b):
                p1 = c * sample[i, 0] + sn * sample[i, 1]
                p2 = -sn * sample[i, 0] + c * sample[i, 1]
                d = min(min(hi1 - p1, p1 - lo1), min(hi2 - p2, p2 - lo2))
                score += weights[i] / max(d, min_distance)
            if score > best:
                best = score
                best_t = t
        c = np.cos(best_t)
        sn = np.sin(best_t)
        lo1, hi1, lo2, hi2 = _extents(points, starts[k], starts[k + 1], c, sn)
        m1 = 0.5 * (lo1 + hi1)
        m2 = 0.5 * (lo2 + hi2)
        out[k, 0] = c * m1 - sn * m2
        out[k, 1] = sn * m1 + c * m2
        if hi1 - lo1 >= hi2 - lo2:
            out[k, 2] = best_t
            out[k, 3] = hi1 - lo1
            out[k, 4] = hi2 - lo2
        else:
            out[k, 2] = best_t - 0.5 * np.pi
            out[k, 3] = hi2 - lo2
            out[k, 4] = hi1 - lo1
    return out


@kernel
def elevation_steps(points, ox, oy, oz, step, out):
    """``out[i]`` = ⌊elevation / ``step``⌋ of 3D point ``i`` (N, 3) seen from ``(ox, oy, oz)``:
    its angle above the horizontal plane (rad, in [−π/2, π/2]) in steps of ``step``; 0 for
    non-finite points and the origin itself. Compared with the tangents of the steps' bounds
    (the angle's tangent is the point's rise over its distance), with no arctangent a point:
    a rational guess within 0.005 rad picks the step, one comparison a side settles it."""
    n_half = int(np.ceil(0.5 * np.pi / step))
    bound = np.empty(2 * n_half + 1)  # bound[k] = tan((k − n_half) · step), ±inf past ±π/2
    for k in range(2 * n_half + 1):
        a = (k - n_half) * step
        bound[k] = np.tan(a) if abs(a) < 0.5 * np.pi else (np.inf if a > 0.0 else -np.inf)
    inv_step = 1.0 / step
    top = 2 * n_half - 1
    wide = step > 0.005
    for i in range(points.shape[0]):
        dx = points[i, 0] - ox
        dy = points[i, 1] - oy
        dz = points[i, 2] - oz
        u = dz / np.sqrt(dx * dx + dy * dy)
        if u != u:  # non-finite, or the origin itself
            out[i] = 0
            continue
        if np.isinf(u):  # straight above or below
            out[i] = int(np.floor(np.copysign(0.5 * np.pi, u) / step))
            continue
        if abs(u) <= 1.0:
            guess = u / (1.0 + 0.28 * u * u)
        else:
            guess = np.copysign(0.5 * np.pi, u) - u / (u * u + 0.28)
        k = min(max(int(guess * inv_step + n_half), 0), top)
        if wide:  # the guess is off by less than a step: one comparison a side
            k += u >= bound[k + 1]
            k -= u < bound[k]
        else:
            while k > 0 and u < bound[k]:
                k -= 1
            while k < top and u >= bound[k + 1]:
                k += 1
        out[i] = k - n_half
    return out


@inline_kernel
def _pseudo_bearing(dx, dy):
    """A cheap stand-in for the bearing of ``(dx, dy)``: in [0, 4], rising with the angle from 0
    (the +x axis) to 2π (4 ≡ 0); NaN at the origin."""
    if dy >= 0.0:
        return dy / (dx + dy) if dx >= 0.0 else 1.0 - dx / (dy - dx)
    return 2.0 - dy / (-dx - dy) if dx < 0.0 else 3.0 + dx / (dx - dy)


@kernel
def nearest_by_bearing(scene, layers, sx, sy, limit, need, out):
    """Range of the nearest point of ``scene`` (K, 2) seen from ``(sx, sy)`` in each of the
    ``len(need)`` equal bearing sectors over the full circle where ``need`` is set, per elevation
    layer (``layers`` (K,), each point's in ``0 … L − 1``): ``out`` (bins, L), +inf where none or not
    needed. Only the points nearer than ``limit`` (m) count (the others are not looked at,
    non-finite ones neither). A point's exact bearing is computed only when a coarse
    pseudo-bearing (:func:`_pseudo_bearing`, buckets grown by one on each side) puts it near a
    needed sector."""
    bins = need.shape[0]
    out[:, :] = np.inf
    scale = bins / (2.0 * np.pi)
    n_coarse = 4 * bins
    coarse = np.zeros(n_coarse, np.bool_)
    for b in range(bins):
        if need[b]:
            a0 = -np.pi + b / scale
            a1 = -np.pi + (b + 1) / scale
            c0 = int(_pseudo_bearing(np.cos(a0), np.sin(a0)) * bins) - 1
            c1 = int(_pseudo_bearing(np.cos(a1), np.sin(a1)) * bins) + 1
            if c1 < c0:  # the sector ending at bearing 0
                c1 += n_coarse
            for c in range(c0, c1 + 1):
                coarse[c % n_coarse] = True
    limit2 = limit * limit
    for j in range(scene.shape[0]):
        dx = scene[j, 0] - sx
        dy = scene[j, 1] - sy
        if not dx * dx + dy * dy < limit2:
            continue
        q = _pseudo_bearing(dx, dy)
        if q == q and not coarse[int(q * bins) % n_coarse]:
            continue
        b = int((np.arctan2(dy, dx) + np.pi) * scale) % bins
        if need[b]:
            out[b, layers[j]] = min(out[b, layers[j]], np.hypot(dx, dy))
    return out


@kernel
def beyond_ends(points, point_layers, starts, scene, scene_layers, n_layers, sx, sy, bins, angle, slack, ends,
                out):
    """The angular ends of each cluster seen from the sensor at ``(sx, sy)`` and what lies just
    beyond them: cluster ``k`` is ``points[starts[k]:starts[k + 1]]``; ``ends[k]`` = the indices
    (into ``points``) of its clockwise and its counter-clockwise end (the least and the greatest
    bearing about the cluster's mean direction; the first such point on ties); ``out[k, e]`` =
    the range (m) of the nearest return of ``scene`` (K, 2) in the ``bins`` equal bearing sectors
    over the full circle within ``angle`` (rad) beyond end ``e``, counting only the returns less
    than ``slack`` (m) farther than that end and in the end's elevation layer or next to it
    (``point_layers``, ``scene_layers``: each point's in ``0 … n_layers − 1``; one layer for a
    planar scan) (+inf where none; :func:`nearest_by_bearing` over those sectors only)."""
    scale = bins / (2.0 * np.pi)
    reach = int(np.ceil(angle * scale))
    n = starts.shape[0] - 1
    b_lo = np.empty(n, np.int64)
    b_hi = np.empty(n, np.int64)
    r_lo = np.zeros(n)
    r_hi = np.zeros(n)
    need = np.zeros(bins, np.bool_)
    limit = 0.0
    for k in range(n):
        a = starts[k]
        b = starts[k + 1]
        mx = 0.0
        my = 0.0
        for i in range(a, b):
            mx += points[i, 0] - sx
            my += points[i, 1] - sy
        mid = np.arctan2(my, mx)
        # the ends by a pseudo-angle about the mean direction, rising from -pi to pi (turned
        # by pi: _pseudo_bearing's cut lies behind the cluster); exact bearings for the two only
        lo = np.inf
        hi = -np.inf
        ends[k, 0] = ends[k, 1] = a
        for i in range(a, b):
            dx = points[i, 0] - sx
            dy = points[i, 1] - sy
            q = _pseudo_bearing(-(mx * dx + my * dy), -(mx * dy - my * dx))
            if q < lo:
                lo = q
                ends[k, 0] = i
            if q > hi:
                hi = q
                ends[k, 1] = i
        for e in range(2):
            dx = points[ends[k, e], 0] - sx
            dy = points[ends[k, e], 1] - sy
            rel = np.arctan2(dy, dx) - mid
            rel = rel - 2.0 * np.pi * np.floor((rel + np.pi) / (2.0 * np.pi))
            if e == 0:
                r_lo[k] = np.hypot(dx, dy)
                b_lo[k] = int((mid + rel + np.pi) * scale)
            else:
                r_hi[k] = np.hypot(dx, dy)
                b_hi[k] = int((mid + rel + np.pi) * scale)
        for j in range(1, reach + 1):
            need[(b_lo[k] - j) % bins] = True
            need[(b_hi[k] + j) % bins] = True
        limit = max(limit, r_lo[k] + slack, r_hi[k] + slack)
    nearest = nearest_by_bearing(scene, scene_layers, sx, sy, limit, need, np.empty((bins, n_layers)))
    for k in range(n):
        for e in range(2):
            out[k, e] = np.inf
            layer = point_layers[ends[k, e]]
            r_end = r_lo[k] if e == 0 else r_hi[k]
            for j in range(1, reach + 1):
                b = (b_lo[k] - j) % bins if e == 0 else (b_hi[k] + j) % bins
                for m in range(max(layer - 1, 0), min(layer + 1, n_layers - 1) + 1):
                    q = nearest[b, m]
                    if q < r_end + slack:
                        out[k, e] = min(out[k, e], q)
    return out


@kernel
def measure_boxes(corners, axes, size, sx, sy, occluded, track, bare_end, position_var, centre, covariance, seen,
                  side, lever):
    """What a detected box says of an object, for ``P`` pairs of a box and a track: the box's
    ``corners`` (P, 4, 2) seen from the sensor at ``(sx, sy)``, the object's ``size`` (P, 2) along
    the measuring ``axes`` (P, 2, 2) (rows). Into ``centre`` (P, 2) and its ``covariance``
    (P, 2, 2) (m, world; ``position_var`` per axis, more where only bounded), the extent ``seen``
    (P, 2) and the ``side`` (P, 2) along the axes, and the ``lever`` (P, 2): from the centre to
    the point of the box that placed it (an edge, a corner; zero where only bounded), in world
    axes (m).

    Along an axis where the sensor lies beyond the extent seen, the near edge is the object's
    (``side`` +1: the object lies toward +axis from its lower edge, −1 from its upper edge) and
    the centre half the size behind it. Elsewhere — the sensor within the extent (``side`` 0),
    or the axis of an ``occluded`` (P,) box more across the line of sight (where the occluder
    may cut it) — the box only bounds the centre: it lies where an object of that size still
    covers all that is seen. Given the ``track``'s centre (P, 2) the measurement is the point of
    that interval nearest to it (none of a bias a part seen for many scans would build up);
    without it ((0, 2)) the interval's middle, uncertain by its length (uniform). An occluded
    box's ``bare_end`` (P, 2; NaN: none; (0, 2): none at all) is the object's own edge along
    that axis: the centre lies half the size from it toward the cut end. On the simulated street
    a car driving away 25 – 30 m off, the northern part of its rear seen past a nearer object,
    drifted 1.2 m sideways in 1.5 s while only bounded there."""
    lo = np.empty(2)
    hi = np.empty(2)
    across = np.empty(2)
    for p in range(corners.shape[0]):
        for a in range(2):
            lo[a] = np.inf
            hi[a] = -np.inf
            for c in range(4):
                v = corners[p, c, 0] * axes[p, a, 0] + corners[p, c, 1] * axes[p, a, 1]
                lo[a] = min(lo[a], v)
                hi[a] = max(hi[a], v)
        # the point midway in the measuring axes, from the sensor: the axis more across the line
        # of sight is the one an occluder cuts
        mx = 0.5 * (lo[0] + hi[0]) * axes[p, 0, 0] + 0.5 * (lo[1] + hi[1]) * axes[p, 1, 0] - sx
        my = 0.5 * (lo[0] + hi[0]) * axes[p, 0, 1] + 0.5 * (lo[1] + hi[1]) * axes[p, 1, 1] - sy
        for a in range(2):
            across[a] = abs(axes[p, a, 0] * mx + axes[p, a, 1] * my)
        least = min(across[0], across[1])
        cx = 0.0
        cy = 0.0
        lx = 0.0
        ly = 0.0
        for i in range(2):
            for j in range(2):
                covariance[p, i, j] = 0.0
        for a in range(2):
            ex, ey = axes[p, a, 0], axes[p, a, 1]
            w = hi[a] - lo[a]
            full = max(size[p, a], w)
            s_proj = ex * sx + ey * sy
            sd = 1.0 if s_proj < lo[a] else (-1.0 if s_proj > hi[a] else 0.0)
            cut = across[a] == least
            unsure = sd == 0.0 or (occluded[p] and cut)
            first = hi[a] - 0.5 * full
            last = lo[a] + 0.5 * full
            if track.shape[0] == 0:
                bound = 0.5 * (first + last)
                var = position_var + ((full - w) ** 2 / 12.0 if unsure else 0.0)
            else:
                bound = min(max(ex * track[p, 0] + ey * track[p, 1], first), last)
                var = position_var
            if unsure:
                at = bound
                offset = 0.0
            else:
                at = lo[a] + 0.5 * full if sd > 0.0 else hi[a] - 0.5 * full
                offset = -sd * 0.5 * full
            if bare_end.shape[0]:
                edge = ex * bare_end[p, 0] + ey * bare_end[p, 1]
                d = 0.5 * (lo[a] + hi[a]) - edge
                if occluded[p] and cut and d != 0.0 and np.isfinite(d):
                    toward = 1.0 if d > 0.0 else -1.0
                    at = edge + toward * 0.5 * full
                    offset = -toward * 0.5 * full
                    var = position_var
            seen[p, a] = w
            side[p, a] = sd
            cx += at * ex
            cy += at * ey
            lx += offset * ex
            ly += offset * ey
            covariance[p, 0, 0] += ex * var * ex
            covariance[p, 0, 1] += ex * var * ey
            covariance[p, 1, 0] += ey * var * ex
            covariance[p, 1, 1] += ey * var * ey
        centre[p, 0] = cx
        centre[p, 1] = cy
        lever[p, 0] = lx
        lever[p, 1] = ly
    return centre


@kernel
def gate_costs(tracks, covs, spread, z, R, gate, cost):
    """The assignment's costs ``cost`` (n, m): for track ``i`` (centre ``tracks[i]``, covariance
    ``covs[i]``, spread by ``spread[i]`` m² more each way) and the centre ``z[i, j]`` (noise
    ``R[i, j]``, 2 × 2) that detection ``j`` says it has, the squared Mahalanobis distance ``d²``
    with ``S = P + R + spread · I``, plus ``log det S`` (the Gaussian's normalisation: a wider
    track costs more); inf where ``d²`` exceeds ``gate``."""
    for i in range(cost.shape[0]):
        for j in range(cost.shape[1]):
            a = covs[i, 0, 0] + R[i, j, 0, 0] + spread[i]
            b = covs[i, 0, 1] + R[i, j, 0, 1]
            c = covs[i, 1, 0] + R[i, j, 1, 0]
            d = covs[i, 1, 1] + R[i, j, 1, 1] + spread[i]
            det = a * d - b * c
            rx = z[i, j, 0] - tracks[i, 0]
            ry = z[i, j, 1] - tracks[i, 1]
            d2 = (rx * (d * rx - b * ry) + ry * (a * ry - c * rx)) / det
            cost[i, j] = d2 + np.log(det) if d2 <= gate else np.inf
    return cost


@inline_kernel
def _erf(x):
    """The error function to within 1.5e-7 (Abramowitz and Stegun 7.1.26: one exponential, where
    the C library's erf costs three times as much; the occupancy model's own tail cut, at
    :data:`TAIL` standard deviations, leaves out 1.4e-3)."""
    a = abs(x)
    if a >= 6.0:  # the formula gives ±1 exactly from 5.93 on: no exponential needed
        return 1.0 if x >= 0.0 else -1.0
    t = 1.0 / (1.0 + 0.3275911 * a)
    poly = t * (0.254829592 + t * (-0.284496736 + t * (1.421413741 + t * (-1.453152027 + t * 1.061405429))))
    e = 1.0 - poly * math.exp(-a * a)
    return e if x >= 0.0 else -e


@inline_kernel
def _interval_probability(d, half, sigma):
    """P(|d + e| ≤ half) for e ~ N(0, σ²): a box edge-to-edge along one axis, smeared."""
    if sigma <= 0.0:
        return 1.0 if abs(d) <= half else 0.0
    k = 1.0 / (sigma * np.sqrt(2.0))
    return 0.5 * (_erf((half - d) * k) - _erf((-half - d) * k))


@inline_kernel
def _spread(c, s, ha, hb, cov):
    """Standard deviations along and across a box of heading ``(cos, sin) = (c, s)`` and half
    sizes ``ha``, ``hb``: its centre's covariance ``cov[:2, :2]`` in the box's axes, plus the
    heading variance ``cov[2, 2]`` moving its far edges across each axis."""
    va = c * c * cov[0, 0] + 2.0 * c * s * cov[0, 1] + s * s * cov[1, 1] + hb * hb * cov[2, 2]
    vb = s * s * cov[0, 0] - 2.0 * c * s * cov[0, 1] + c * c * cov[1, 1] + ha * ha * cov[2, 2]
    return np.sqrt(max(va, 0.0)), np.sqrt(max(vb, 0.0))


#: Standard deviations beyond a box's grown edges at which its probability counts as 0 (below
#: 0.0014: under the costs' 0.05 floor).
TAIL = 3.0


@inline_kernel
def _box_probability(da, db, ha, hb, sa, sb):
    """P(a point at ``da``, ``db`` along and across a box of half sizes ``ha``, ``hb`` lies under
    it) with the box's edges smeared by ``sa``, ``sb``; 0 farther than :data:`TAIL` of them
    beyond an edge."""
    if abs(da) > ha + TAIL * sa or abs(db) > hb + TAIL * sb:
        return 0.0
    return _interval_probability(da, ha, sa) * _interval_probability(db, hb, sb)


@inline_kernel
def _slab(a, b, half):
    """The interval of ``t`` where ``|a · t + b| ≤ half`` (empty: lo > hi; all: ±inf)."""
    if a == 0.0:
        return (-np.inf, np.inf) if abs(b) <= half else (np.inf, -np.inf)
    lo = (-half - b) / a
    hi = (half - b) / a
    return (lo, hi) if a > 0.0 else (hi, lo)


@kernel
def footprint_probability(states, covs, sizes, grow, ox, oy, res, out):
    """Adds, into ``out`` (H, W, window order, cell (0, 0) with its outer corner at ``(ox, oy)``,
    side ``res``), the probability that each cell centre lies under one of the boxes ``sizes``
    (T, 2) grown by ``grow`` on every side, centred at ``states[:, :2]`` with heading
    ``states[:, 2]``, their centres Gaussian with covariance ``covs[:, :2, :2]`` and heading spread
    ``covs[:, 2, 2]`` (its effect at the box's ends taken as extra spread across each axis; see
    :func:`_box_probability`). Objects are taken as independent: ``out ← 1 − (1 − out)(1 − p)``."""
    H, W = out.shape
    for t in range(states.shape[0]):
        x = states[t, 0]
        y = states[t, 1]
        c = np.cos(states[t, 2])
        s = np.sin(states[t, 2])
        ha = 0.5 * sizes[t, 0] + grow
        hb = 0.5 * sizes[t, 1] + grow
        sa, sb = _spread(c, s, ha, hb, covs[t])
        reach = np.hypot(ha + TAIL * sa, hb + TAIL * sb)
        i0 = max(int(np.floor((y - reach - oy) / res)), 0)
        i1 = min(int(np.floor((y + reach - oy) / res)), H - 1)
        j0 = max(int(np.floor((x - reach - ox) / res)), 0)
        j1 = min(int(np.floor((x + reach - ox) / res)), W - 1)
        for i in range(i0, i1 + 1):
            py = oy + (i + 0.5) * res - y
            # the cells of this row within the box's tails: where both of its slabs hold px (one
            # cell more each side for rounding; beyond the tails _box_probability gives 0 anyway)
            a0, a1 = _slab(c, s * py, ha + TAIL * sa)
            b0, b1 = _slab(-s, c * py, hb + TAIL * sb)
            lo = max((max(a0, b0) + x - ox) / res - 1.5, j0 - 1.0)
            hi = min((min(a1, b1) + x - ox) / res + 0.5, j1 + 1.0)
            if not lo <= hi:  # none (both finite once this holds)
                continue
            for j in range(max(j0, int(np.floor(lo))), min(j1, int(np.ceil(hi))) + 1):
                px = ox + (j + 0.5) * res - x
                da = c * px + s * py
                db = -s * px + c * py
                p = _box_probability(da, db, ha, hb, sa, sb)
                if p > 0.0:
                    out[i, j] = 1.0 - (1.0 - out[i, j]) * (1.0 - p)
    return out


@kernel
def occupancy_costs(p, threshold, lethal, cost):
    """From the occupancy ``p`` (H, W): obstacles ``lethal`` (bool (H, W)) where it reaches
    ``threshold``, and Nav2 costs ``cost`` (uint8 (H, W)) ``252 · p / threshold`` (at most 252)
    where it is 0.05 or more, else 0 — one pass over the window."""
    H, W = p.shape
    for i in range(H):
        for j in range(W):
            q = p[i, j]
            lethal[i, j] = q >= threshold
            cost[i, j] = np.uint8(min(252.0 * q / threshold, 252.0)) if q >= 0.05 else 0
    return lethal


@kernel
def point_probability(points, at, states, covs, sizes, grow, out):
    """``out[i]`` = probability that point ``i`` (N, 2) lies under at least one box ``j`` of
    ``states[at[i], j]`` (K, T, 5), ``covs[at[i], j]`` (K, T, 5, 5), ``sizes[j]`` (T, 2) grown by
    ``grow`` — the objects predicted to point ``i``'s time, one of ``K`` (the model of
    :func:`footprint_probability`: a cell's value there is this at its centre)."""
    K, T = states.shape[0], states.shape[1]
    box = np.empty((K, T, 6))  # per box: cos, sin, half sizes, spreads
    for k in range(K):
        for t in range(T):
            c = np.cos(states[k, t, 2])
            s = np.sin(states[k, t, 2])
            ha = 0.5 * sizes[t, 0] + grow
            hb = 0.5 * sizes[t, 1] + grow
            sa, sb = _spread(c, s, ha, hb, covs[k, t])
            box[k, t, 0], box[k, t, 1], box[k, t, 2], box[k, t, 3], box[k, t, 4], box[k, t, 5] = c, s, ha, hb, sa, sb
    for i in range(points.shape[0]):
        k = at[i]
        free = 1.0
        for t in range(T):
            px = points[i, 0] - states[k, t, 0]
            py = points[i, 1] - states[k, t, 1]
            b = box[k, t]
            free *= 1.0 - _box_probability(b[0] * px + b[1] * py, -b[1] * px + b[0] * py, b[2], b[3], b[4], b[5])
        out[i] = 1.0 - free
    return out


@kernel
def promote_components(pts, moving, blocked, ox, oy, res, reach, max_span, grid, out):
    """Points that belong to a component mostly moving: the points ``(N, 2)`` are put in the grid
    of ``H × W`` cells of side ``res`` whose cell (0, 0) has its outer corner at ``(ox, oy)``;
    cells within ``reach`` cells of each other (a square) join; a component whose points are at
    least half ``moving`` and whose cells span at most ``max_span`` metres (the bounding box's
    diagonal) has all its points set in ``out``, but those ``blocked``. Only components that hold
    a moving point are searched, and a search stops once its cells span more than ``max_span``
    (a wall a mover passes is not walked whole): the cost follows the movers, not the scan. A
    later search that meets the cells of a stopped one is part of it, so it is not promoted.
    ``grid`` is int32 (3, H, W) scratch, all zero on entry and left so (kept by the caller: a
    fresh window-sized array per scan costs more than the search)."""
    _, H, W = grid.shape
    count = grid[0].reshape(-1)
    movers = grid[1].reshape(-1)
    label = grid[2].reshape(-1)  # 0 unvisited, k > 0 component k, promoted when good[k]
    n = pts.shape[0]
    cell = np.full(n, -1, np.int64)  # row · W + column, −1 outside
    for i in range(n):
        c = int(np.floor((pts[i, 0] - ox) / res))
        r = int(np.floor((pts[i, 1] - oy) / res))
        if 0 <= c < W and 0 <= r < H:
            k = r * W + c
            cell[i] = k
            count[k] += 1
            movers[k] += moving[i]
    good = np.zeros(1, np.bool_)
    stack = np.empty(n, np.int64)  # cells with points, each pushed once
    comp = 0
    for i in range(n):
        k = cell[i]
        if not moving[i] or k < 0 or label[k] != 0:
            continue
        comp += 1
        if comp >= good.shape[0]:
            grown = np.zeros(2 * good.shape[0], np.bool_)
            grown[:good.shape[0]] = good
            good = grown
        top = 0
        stack[0] = k
        label[k] = comp
        n_all = 0
        n_mov = 0
        x0 = W
        x1 = -1
        y0 = H
        y1 = -1
        ok = True
        while top >= 0 and ok:
            k = stack[top]
            top -= 1
            y = k // W
            x = k % W
            n_all += count[k]
            n_mov += movers[k]
            x0 = min(x0, x)
            x1 = max(x1, x)
            y0 = min(y0, y)
            y1 = max(y1, y)
            ok = res * np.hypot(x1 - x0 + 1, y1 - y0 + 1) <= max_span
            for yy in range(max(y - reach, 0), min(y + reach + 1, H)):
                for xx in range(max(x - reach, 0), min(x + reach + 1, W)):
                    kk = yy * W + xx
                    if count[kk] > 0:
                        if label[kk] == 0:
                            label[kk] = comp
                            top += 1
                            stack[top] = kk
                        elif label[kk] != comp:  # a stopped search's cells: too wide
                            ok = False
        good[comp] = ok and 2 * n_mov >= n_all
    for i in range(n):
        k = cell[i]
        out[i] = k >= 0 and good[label[k]] and not blocked[i]
    for i in range(n):
        k = cell[i]
        if k >= 0:
            count[k] = 0
            movers[k] = 0
            label[k] = 0
    return out


@kernel
def box_owners(pts, cx, cy, heading, half_length, half_width, out):
    """Per point (N, 2): the index of the box (centre ``cx, cy``, ``heading``, half extents)
    holding it whose centre is nearest, or −1 (into ``out``, int64 (N,))."""
    n_boxes = cx.shape[0]
    c = np.cos(heading)
    s = np.sin(heading)
    r2 = half_length ** 2 + half_width ** 2  # squared radius of each box's circumscribed circle
    for i in range(pts.shape[0]):
        best = -1
        best_d2 = np.inf
        for k in range(n_boxes):
            dx = pts[i, 0] - cx[k]
            dy = pts[i, 1] - cy[k]
            d2 = dx * dx + dy * dy
            if d2 > r2[k] or d2 >= best_d2:
                continue
            if abs(c[k] * dx + s[k] * dy) <= half_length[k] and abs(-s[k] * dx + c[k] * dy) <= half_width[k]:
                best = k
                best_d2 = d2
        out[i] = best


@kernel
def near_any(pts, seeds, radius, out):
    """``out[i]``: whether a point of ``seeds`` (M, 2) lies within ``radius`` (m) of point ``i``
    of ``pts`` (N, 2). Seeds are binned into cells of side ``radius``; each point looks at the
    3 × 3 cells around its own."""
    m = seeds.shape[0]
    inv = 1.0 / radius
    out[:] = False
    if m == 0:
        return out
    cx = np.empty(m, np.int64)
    cy = np.empty(m, np.int64)
    for i in range(m):
        cx[i] = np.int64(np.floor(seeds[i, 0] * inv))
        cy[i] = np.int64(np.floor(seeds[i, 1] * inv))
    ox = cx.min() - 1
    oy = cy.min() - 1
    span = cy.max() - oy + 2
    key = (cx - ox) * span + (cy - oy)
    order = np.argsort(key)
    skey = key[order]
    r2 = radius * radius
    for i in range(pts.shape[0]):
        px = np.int64(np.floor(pts[i, 0] * inv)) - ox
        py = np.int64(np.floor(pts[i, 1] * inv)) - oy
        found = False
        for dx in range(-1, 2):
            for dy in range(-1, 2):
                yy = py + dy
                if found or yy < 0 or yy >= span:
                    continue
                k = (px + dx) * span + yy
                b = np.searchsorted(skey, k)
                while b < m and skey[b] == k:
                    j = order[b]
                    ex = pts[i, 0] - seeds[j, 0]
                    ey = pts[i, 1] - seeds[j, 1]
                    if ex * ex + ey * ey <= r2:
                        found = True
                        break
                    b += 1
        out[i] = found
    return out
