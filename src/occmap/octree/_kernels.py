"""Numba kernels of the occupancy octree's node pool: storage, settling, queries.

Storage. Nodes live in *slots*; the children of an inner node occupy one *block* of 8 consecutive
slots (child ``i`` at ``block + i``, ``i = x-bit + 2·y-bit + 4·z-bit`` as in OctoMap). Per slot:

- ``value`` (float32): the log-odds; NaN marks a slot whose node does not exist (unknown space);
- ``child`` (int32): first slot of the node's child block, −1 for a leaf; a freed block links the
  free list through the ``child`` of its first slot.

Slot 0 is the root; block 0 holds only it, real blocks start at slot 8. ``meta`` (int64) holds the
allocator and counters: ``meta[TOP]`` the next never-used slot, ``meta[FREE]`` the free-list head
(−1: empty), ``meta[SIZE]`` the number of nodes (OctoMap's ``size()``).
"""

from __future__ import annotations

import math

import numpy as np

from numba import prange

from .._intrinsics import bit_length
from .._jit import inline_kernel, kernel, kernel_parallel

TOP, FREE, SIZE = 0, 1, 2
DEPTH = 16
CENTER = 32768  # OctoMap's tree_max_val: key of the cell whose corner is the world origin
MAX_KEY = 65535


@kernel
def coord_to_key(c, inv_res):
    """OctoMap's ``coordToKey``: floor(c / res) + 32768 on the float64 value of ``c``."""
    return np.int64(math.floor(inv_res * np.float64(c))) + CENTER


@kernel
def key_to_coord(k, res):
    """Centre of depth-16 cell ``k`` along one axis (OctoMap's ``keyToCoord``)."""
    return (np.float64(k - CENTER) + 0.5) * res


@kernel
def grow(value, child, capacity):
    """The slot arrays with room for ``capacity`` slots, at least twice as many as now, contents
    kept, new slots unused."""
    n = value.shape[0]
    m = max(2 * n, capacity)
    v = np.empty(m, np.float32)
    c = np.empty(m, np.int32)
    v[:n] = value
    c[:n] = child
    v[n:] = np.nan
    c[n:] = -1
    return v, c


@kernel
def child_pos(kx, ky, kz, depth):
    """Index of the child of a node at ``depth`` that holds key (kx, ky, kz)."""
    shift = DEPTH - 1 - depth
    return ((kx >> shift) & 1) | (((ky >> shift) & 1) << 1) | (((kz >> shift) & 1) << 2)


@inline_kernel
def settle(value, child, meta, node, set_max, prune):
    """Make inner ``node`` agree with its children: collapse it into a leaf if its eight
    children are leaves with one value (``prune``), else set it to their maximum (``set_max``).
    Returns True when it was pruned."""
    c = child[node]
    first = value[c]
    m = -np.inf
    collapsible = prune
    for j in range(c, c + 8):
        v = value[j]
        if v > m:  # false for NaN: missing children do not count
            m = v
        collapsible = collapsible and child[j] < 0 and v == first  # NaN (no child) never equals
    if collapsible:
        value[node] = first
        child[node] = -1
        for j in range(c, c + 8):
            value[j] = np.nan
            child[j] = -1
        child[c] = meta[FREE]  # the block joins the free list
        meta[FREE] = c
        meta[SIZE] -= 8
        return True
    if set_max:
        value[node] = m
    return False


@kernel
def path_to(value, child, key, depth):
    """The nodes from the root down to ``depth`` on the way to the voxel with packed key ``key``
    when each of them exists and has its block of children, else an empty array."""
    kx, ky, kz = key & 0xFFFF, (key >> 16) & 0xFFFF, key >> 32
    path = np.empty(depth + 1, np.int64)
    node = 0
    for d in range(depth + 1):
        if np.isnan(value[node]) or child[node] < 0:
            return path[:0]
        path[d] = node
        node = child[node] + child_pos(kx, ky, kz, d)
    return path


@kernel
def join_pools(child, meta, meta_a, meta_b, gap_lo, gap_hi):
    """After two threads allocated from slot ranges [·, gap_hi) (``meta_a``, with the pool's free
    list) and [gap_hi, ·) (``meta_b``): one pool again, the first range's unused blocks
    [gap_lo, gap_hi) and the blocks the second freed on the free list, node counts added."""
    free = meta_a[FREE]
    for c in range(gap_lo, gap_hi, 8):
        child[c] = free
        free = c
    c = meta_b[FREE]
    while c >= 0:
        nxt = child[c]
        child[c] = free
        free = c
        c = nxt
    meta[TOP] = meta_b[TOP]
    meta[FREE] = free
    meta[SIZE] += meta_a[SIZE] + meta_b[SIZE]


@kernel
def settle_path(value, child, meta, path):
    """Settle (see :func:`settle`: maximum of the children, or pruned) the nodes of ``path``,
    deepest first."""
    for d in range(path.shape[0] - 1, -1, -1):
        settle(value, child, meta, path[d], True, True)


@kernel
def settle_tree(value, child, meta, depth, set_max, prune):
    """Post-order walk settling (see :func:`settle`) every inner node (``depth`` < 0: OctoMap's
    ``updateInnerOccupancy`` with ``set_max``) or only those at ``depth`` (one level of OctoMap's
    ``prune``). Returns how many nodes were pruned."""
    if np.isnan(value[0]) or child[0] < 0:
        return 0
    nodes = np.empty(DEPTH + 1, np.int64)
    next_child = np.zeros(DEPTH + 1, np.int64)
    nodes[0] = 0
    sp = 0
    pruned = 0
    while sp >= 0:
        node = nodes[sp]
        if sp != depth:
            c = child[node]
            i = next_child[sp]
            while i < 8 and child[c + i] < 0:
                i += 1
            if i < 8:
                next_child[sp] = i + 1
                sp += 1
                nodes[sp] = c + i
                next_child[sp] = 0
                continue
        if (depth < 0 or sp == depth) and settle(value, child, meta, node, set_max, prune):
            pruned += 1
        sp -= 1
    return pruned


@inline_kernel
def alloc_block(value, child, meta, fill):
    """First slot of a free block of 8 (from the free list, else the unused top), each slot set to
    ``fill`` with no children. The caller has checked there is room."""
    c = meta[FREE]
    if c >= 0:
        meta[FREE] = child[c]
    else:
        c = meta[TOP]
        meta[TOP] = c + 8
    for j in range(c, c + 8):
        value[j] = fill
        child[j] = -1
    return c


@kernel
def expand_all(value, child, meta):
    """Expand every pruned leaf down to depth 16 (OctoMap's ``expand``); the arrays must have room
    for the new blocks (see ``OcTree.expand``)."""
    if np.isnan(value[0]):
        return
    nodes = np.empty(DEPTH + 1, np.int64)
    next_child = np.zeros(DEPTH + 1, np.int64)
    nodes[0] = 0
    sp = 0
    while sp >= 0:
        node = nodes[sp]
        if sp < DEPTH and child[node] < 0:
            child[node] = alloc_block(value, child, meta, value[node])
            meta[SIZE] += 8
        i = next_child[sp]
        if sp == DEPTH or i == 8:
            sp -= 1
            continue
        next_child[sp] = i + 1
        k = child[node] + i
        if not np.isnan(value[k]):
            sp += 1
            nodes[sp] = k
            next_child[sp] = 0


@kernel
def to_max_likelihood(value, child, occ, lo, hi):
    """Every node's value to the clamping bound of its class (OctoMap's ``toMaxLikelihood``)."""
    for i in range(value.shape[0]):
        v = value[i]
        if not np.isnan(v):
            value[i] = hi if v >= occ else lo


# ---------------------------------------------------------------------------- queries

@kernel
def search_keys(value, child, keys, depth):
    """Slot of the node holding each key at ``depth`` (a pruned ancestor if the tree stops
    above it), −1 where the space is unknown. ``keys`` (N, 3) int64."""
    n = keys.shape[0]
    out = np.full(n, -1, np.int64)
    if np.isnan(value[0]):
        return out
    for j in range(n):
        kx, ky, kz = keys[j, 0], keys[j, 1], keys[j, 2]
        node = 0
        d = 0
        while d < depth and child[node] >= 0:
            nxt = child[node] + child_pos(kx, ky, kz, d)
            if np.isnan(value[nxt]):
                node = -1
                break
            node = nxt
            d += 1
        out[j] = node
    return out


@kernel
def count_leaves(value, child, top):
    n = 0
    for i in range(top):
        if child[i] < 0 and not np.isnan(value[i]):
            n += 1
    return n


@kernel
def collect_nodes(value, child, max_depth, kmin, kmax, leaves_only, count_only, out_key, out_depth, out_value):
    """Pre-order walk of the nodes down to ``max_depth`` that overlap the key box [kmin, kmax];
    a node at ``max_depth`` counts as a leaf. Fills the out arrays (min-corner key, depth, value)
    unless ``count_only``; returns the number of nodes reported."""
    if np.isnan(value[0]):
        return 0
    nodes = np.empty(DEPTH + 1, np.int64)
    corner = np.zeros((DEPTH + 1, 3), np.int64)
    next_child = np.zeros(DEPTH + 1, np.int64)
    nodes[0] = 0
    sp = 0
    m = 0
    if not leaves_only or child[0] < 0 or max_depth == 0:
        if not count_only:
            out_key[0, :] = 0
            out_depth[0] = 0
            out_value[0] = value[0]
        m = 1
        if child[0] < 0 or max_depth == 0:
            return m
    while sp >= 0:
        node = nodes[sp]
        c = child[node]
        i = next_child[sp]
        half = 1 << (DEPTH - 1 - sp)
        pushed = False
        while i < 8:
            k = c + i
            pos = i
            i += 1
            if np.isnan(value[k]):
                continue
            x0 = corner[sp, 0] + (pos & 1) * half
            y0 = corner[sp, 1] + ((pos >> 1) & 1) * half
            z0 = corner[sp, 2] + ((pos >> 2) & 1) * half
            if (x0 > kmax[0] or x0 + half - 1 < kmin[0] or y0 > kmax[1] or y0 + half - 1 < kmin[1]
                    or z0 > kmax[2] or z0 + half - 1 < kmin[2]):
                continue
            d = sp + 1
            is_leaf = child[k] < 0 or d == max_depth
            if is_leaf or not leaves_only:
                if not count_only:
                    out_key[m, 0] = x0
                    out_key[m, 1] = y0
                    out_key[m, 2] = z0
                    out_depth[m] = d
                    out_value[m] = value[k]
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
def cast_rays(value, child, origins, directions, res, max_range, ignore_unknown, occ):
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
        _cast_span(value, child, origins, directions, res, max_range, ignore_unknown, occ,
                   k * span, min(n, (k + 1) * span), hit, ends)
    return hit, ends


@kernel
def _cast_span(value, child, origins, directions, res, max_range, ignore_unknown, occ, start, stop, hit, ends):
    """:func:`cast_rays` for rays ``start..stop-1``, into ``hit`` and ``ends``."""
    inv_res = 1.0 / res
    n = hit.shape[0]
    path = np.zeros(DEPTH + 1, np.int64)
    known = -1
    px = py = pz = 0
    max_range_sq = max_range * max_range
    reach = 0.87 * res + 1e-3  # half a voxel diagonal, and then some for float32 rounding
    near = max_range - reach if max_range > 0.0 else np.inf
    big = np.finfo(np.float64).max
    for r in range(start, stop):
        o = origins[r] if origins.shape[0] == n else origins[0]
        ox, oy, oz = o[0], o[1], o[2]
        kx, ky, kz = coord_to_key(ox, inv_res), coord_to_key(oy, inv_res), coord_to_key(oz, inv_res)
        if not (0 <= kx <= MAX_KEY and 0 <= ky <= MAX_KEY and 0 <= kz <= MAX_KEY):
            continue
        q = directions[r] if directions.shape[0] == n else directions[0]
        dx, dy, dz = q[0], q[1], q[2]
        norm = np.float32(math.sqrt(np.float64(dx * dx + dy * dy + dz * dz)))
        if norm > 0:
            dx, dy, dz = dx / norm, dy / norm, dz / norm
        sx = 1 if dx > 0 else (-1 if dx < 0 else 0)
        sy = 1 if dy > 0 else (-1 if dy < 0 else 0)
        sz = 1 if dz > 0 else (-1 if dz < 0 else 0)
        tx = ty = tz = gx = gy = gz = big
        if sx != 0:
            tx = (key_to_coord(kx, res) + sx * res * 0.5 - np.float64(ox)) / np.float64(dx)
            gx = res / abs(np.float64(dx))
        if sy != 0:
            ty = (key_to_coord(ky, res) + sy * res * 0.5 - np.float64(oy)) / np.float64(dy)
            gy = res / abs(np.float64(dy))
        if sz != 0:
            tz = (key_to_coord(kz, res) + sz * res * 0.5 - np.float64(oz)) / np.float64(dz)
            gz = res / abs(np.float64(dz))
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
                if d == 0 and np.isnan(value[0]):
                    node = -1
                while node >= 0 and d < DEPTH and child[node] >= 0:
                    nxt = child[node] + child_pos(kx, ky, kz, d)
                    if np.isnan(value[nxt]):
                        node = -1
                    else:
                        node = nxt
                        d += 1
                        path[d] = node
                known = d  # path[0..d] holds existing nodes whether or not the search found one
                # a leaf at depth d covers its whole cube; an unknown child of path[d] the cube one level down
                span = DEPTH - d if node >= 0 else DEPTH - 1 - d
                stop_here = value[node] >= occ if node >= 0 else not ignore_unknown
            if stop_here:
                hit[r] = node >= 0
                break
            if first:
                first = False
                if sx == 0 and sy == 0 and sz == 0:
                    cast = False
                    break
            # ---- next voxel (OctoMap's tie-breaks), unless the ray leaves the tree or passes max_range
            # (the axis that steps had the smallest t: min(t) reaches `near` only on a step whose
            # own t does)
            if tx < ty and tx < tz:
                if kx == lim_x:
                    break
                kx += sx
                tx += gx
                far = tx >= near
            elif ty <= tx and ty < tz:
                if ky == lim_y:
                    break
                ky += sy
                ty += gy
                far = ty >= near
            else:
                if kz == lim_z:
                    break
                kz += sz
                tz += gz
                far = tz >= near
            # OctoMap's range test (float32 voxel centre) only near max_range: the centre lies within
            # half a diagonal of the point where the ray leaves the voxel, min(t) from the origin
            if far and min(tx, ty, tz) >= near:
                ex = np.float32(key_to_coord(kx, res))
                ey = np.float32(key_to_coord(ky, res))
                ez = np.float32(key_to_coord(kz, res))
                dist_sq = (np.float64((ex - ox) * (ex - ox)) + np.float64((ey - oy) * (ey - oy))
                           + np.float64((ez - oz) * (ez - oz)))
                if dist_sq > max_range_sq:
                    break
        if cast:
            ends[r, 0] = key_to_coord(kx, res)
            ends[r, 1] = key_to_coord(ky, res)
            ends[r, 2] = key_to_coord(kz, res)
