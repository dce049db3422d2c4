"""Queries of the node pool (OctoMap's ``search``, leaf iterators, ``castRay``): Numba kernels on
the slots of :mod:`.pool`, keys as in :mod:`.keys`."""

from __future__ import annotations

import numpy as np
from numba import prange

from .._intrinsics import bit_length
from .._jit import kernel, kernel_parallel
from . import raywalk
from .keys import DEPTH, MAX_KEY, child_index, coord_to_key, key_in_range, key_to_coord

@kernel
def search_keys(slots, keys, depth):
    """Slot of the node holding each key at ``depth`` (a pruned ancestor if the tree stops
    above it), −1 where the space is unknown. ``keys`` (N, 3) int64."""
    n = keys.shape[0]
    out = np.full(n, -1, np.int64)
    if np.isnan(slots[0].value):
        return out
    for j in range(n):
        kx, ky, kz = keys[j, 0], keys[j, 1], keys[j, 2]
        node = 0
        d = 0
        while d < depth and slots[node].child >= 0:
            nxt = slots[node].child + child_index(kx, ky, kz, d)
            if np.isnan(slots[nxt].value):
                node = -1
                break
            node = nxt
            d += 1
        out[j] = node
    return out


@kernel
def count_leaves(slots, top):
    n = 0
    for i in range(top):
        if slots[i].child < 0 and not np.isnan(slots[i].value):
            n += 1
    return n


@kernel
def collect_nodes(slots, max_depth, kmin, kmax, leaves_only, count_only, out_key, out_depth, out_value):
    """Pre-order walk of the nodes down to ``max_depth`` that overlap the key box [kmin, kmax];
    a node at ``max_depth`` counts as a leaf. Fills the out arrays (min-corner key, depth, value)
    unless ``count_only``; returns the number of nodes reported."""
    if np.isnan(slots[0].value):
        return 0
    nodes = np.empty(DEPTH + 1, np.int64)
    corner = np.zeros((DEPTH + 1, 3), np.int64)
    next_child = np.zeros(DEPTH + 1, np.int64)
    nodes[0] = 0
    sp = 0
    m = 0
    if not leaves_only or slots[0].child < 0 or max_depth == 0:
        if not count_only:
            out_key[0, :] = 0
            out_depth[0] = 0
            out_value[0] = slots[0].value
        m = 1
        if slots[0].child < 0 or max_depth == 0:
            return m
    while sp >= 0:
        node = nodes[sp]
        c = slots[node].child
        i = next_child[sp]
        half = 1 << (DEPTH - 1 - sp)
        pushed = False
        while i < 8:
            k = c + i
            pos = i
            i += 1
            if np.isnan(slots[k].value):
                continue
            x0 = corner[sp, 0] + (pos & 1) * half
            y0 = corner[sp, 1] + ((pos >> 1) & 1) * half
            z0 = corner[sp, 2] + ((pos >> 2) & 1) * half
            if (x0 > kmax[0] or x0 + half - 1 < kmin[0] or y0 > kmax[1] or y0 + half - 1 < kmin[1]
                    or z0 > kmax[2] or z0 + half - 1 < kmin[2]):
                continue
            d = sp + 1
            is_leaf = slots[k].child < 0 or d == max_depth
            if is_leaf or not leaves_only:
                if not count_only:
                    out_key[m, 0] = x0
                    out_key[m, 1] = y0
                    out_key[m, 2] = z0
                    out_depth[m] = d
                    out_value[m] = slots[k].value
                m += 1
            if not is_leaf:
                next_child[sp] = i
                sp += 1
                nodes[sp] = k
                corner[sp, 0] = x0
                corner[sp, 1] = y0
                corner[sp, 2] = z0
                next_child[sp] = 0
                pushed = True
                break
        if not pushed:
            sp -= 1
    return m


@kernel_parallel
def cast_rays(slots, origins, directions, res, max_range, ignore_unknown, occ):
    """OctoMap's ``castRay`` for each ray (float32 origins and directions as its ``point3d``):
    walk the voxels from the origin's until an occupied one (hit), an unknown one (a miss unless
    ``ignore_unknown``), ``max_range`` (> 0) or the tree's border. Returns hit flags and the centre
    of the voxel where each ray stopped (float32, NaN where the ray could not be cast: origin
    outside the tree or zero direction). Spans of rays run in parallel."""
    n = max(origins.shape[0], directions.shape[0])
    hit = np.zeros(n, np.bool_)
    ends = np.full((n, 3), np.nan, np.float32)
    span = 256
    for k in prange((n + span - 1) // span):
        _cast_span(slots, origins, directions, res, max_range, ignore_unknown, occ,
                   k * span, min(n, (k + 1) * span), hit, ends)
    return hit, ends


@kernel
def _cast_span(slots, origins, directions, res, max_range, ignore_unknown, occ, start, stop, hit, ends):
    """:func:`cast_rays` for rays ``start..stop-1``, into ``hit`` and ``ends``."""
    inv_res = 1.0 / res
    n = hit.shape[0]
    path = np.zeros(DEPTH + 1, np.int64)
    known = -1
    px = py = pz = 0
    max_range_sq = max_range * max_range
    reach = 0.87 * res + 1e-3  # half a voxel diagonal, and then some for float32 rounding
    near = max_range - reach if max_range > 0.0 else np.inf
    for r in range(start, stop):
        o = origins[r] if origins.shape[0] == n else origins[0]
        ox, oy, oz = o[0], o[1], o[2]
        kx, ky, kz = coord_to_key(ox, inv_res), coord_to_key(oy, inv_res), coord_to_key(oz, inv_res)
        if not (key_in_range(kx) and key_in_range(ky) and key_in_range(kz)):
            continue
        q = directions[r] if directions.shape[0] == n else directions[0]
        _, dx, dy, dz = raywalk.direction(q[0], q[1], q[2])
        sx, sy, sz, tx, ty, tz, gx, gy, gz = raywalk.start(ox, oy, oz, dx, dy, dz, kx, ky, kz, res, False)
        # the key at which a step would leave the tree, per axis
        lim_x = 0 if sx < 0 else MAX_KEY
        lim_y = 0 if sy < 0 else MAX_KEY
        lim_z = 0 if sz < 0 else MAX_KEY
        first = True
        cast = True
        node = -1
        stop_here = False  # the node found: occupied, or unknown where unknown space stops the ray
        span = -1  # the last answer holds for every key that agrees with (px, py, pz) above this many low bits
        while True:
            diff = (kx ^ px) | (ky ^ py) | (kz ^ pz)
            if span < 0 or (diff >> span) != 0:
                # ---- search (kx, ky, kz), restarting from the node shared with the previous search
                d = 0
                if known >= 0:
                    d = min(DEPTH - bit_length(diff), known)
                px, py, pz = kx, ky, kz
                node = path[d]
                if d == 0 and np.isnan(slots[0].value):
                    node = -1
                while node >= 0 and d < DEPTH and slots[node].child >= 0:
                    nxt = slots[node].child + child_index(kx, ky, kz, d)
                    if np.isnan(slots[nxt].value):
                        node = -1
                    else:
                        node = nxt
                        d += 1
                        path[d] = node
                known = d  # path[0..d] holds existing nodes whether or not the search found one
                # a leaf at depth d covers its whole cube; an unknown child of path[d] the cube one level down
                span = DEPTH - d if node >= 0 else DEPTH - 1 - d
                stop_here = slots[node].value >= occ if node >= 0 else not ignore_unknown
            if stop_here:
                hit[r] = node >= 0
                break
            if first:
                first = False
                if sx == 0 and sy == 0 and sz == 0:
                    cast = False
                    break
            # ---- next voxel, unless the ray leaves the tree or passes max_range (the axis that
            # steps had the smallest t: min(t) reaches `near` only on a step whose own t does)
            axis, tx2, ty2, tz2 = raywalk.step(tx, ty, tz, gx, gy, gz)
            if axis == 0:
                if kx == lim_x:
                    break
                kx += sx
                far = tx2 >= near
            elif axis == 1:
                if ky == lim_y:
                    break
                ky += sy
                far = ty2 >= near
            else:
                if kz == lim_z:
                    break
                kz += sz
                far = tz2 >= near
            tx, ty, tz = tx2, ty2, tz2
            # OctoMap's range test (float32 voxel centre) only near max_range: the centre lies within
            # half a diagonal of the point where the ray leaves the voxel, min(t) from the origin
            if far and min(tx, ty, tz) >= near and raywalk.centre_beyond(kx, ky, kz, ox, oy, oz, res, max_range_sq):
                break
        if cast:
            ends[r, 0] = key_to_coord(kx, res)
            ends[r, 1] = key_to_coord(ky, res)
            ends[r, 2] = key_to_coord(kz, res)
