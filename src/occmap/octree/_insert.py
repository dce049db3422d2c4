"""Numba kernels that insert one scan into the octree, as OctoMap's ``insertPointCloud`` does.

OctoMap collects the scan's free and occupied voxels in two hash sets of keys, then updates each
voxel once (occupied ones only as hits) with a walk from the root. Here the two sets are bit masks
over 8×8×8-voxel *blocks* (a block = one depth-13 node; bit ``m`` = the voxel whose local
coordinates interleave to ``m``, x lowest, so bit order is the octree's child order):

1. :func:`mark_scan` traverses the rays (OctoMap's ``computeRayKeys`` to the bit, float32
   arithmetic included) and sets the bits; a hash of block keys with the last block cached keeps
   this a few nanoseconds per voxel. Disjoint ranges of rays can be marked in parallel threads and
   merged (:func:`merge_blocks`).
2. :func:`apply_blocks` visits the marked voxels in Morton order (blocks sorted by their Morton
   code), so consecutive voxels share their path from the root except the last level or two. Each
   voxel gets one update, a hit if its hit bit is set: log-odds added in float32 and clamped, a
   pruned leaf expanded into eight copies before one changes, and nothing done where OctoMap's
   early abort does nothing (a pruned leaf, or a leaf, already at the clamp the update pushes
   toward). An inner node is settled (max of children, or pruned) as soon as the visit leaves its
   subtree, when it saw a change — exactly the nodes OctoMap's eager updates settle, so the tree
   after each scan is node for node OctoMap's.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import kernel
from ._kernels import DEPTH, FREE, SIZE, TOP, coord_to_key, key_to_coord, settle

#: Slots one block of marked voxels may need at most: 13 ancestors' blocks above the depth-13
#: node, plus 1 + 8 + 64 blocks below it.
_BLOCK_ROOM = 8 * (13 + 1 + 8 + 64)

# Bit index of local coordinate (x, y, z) in a block's mask: interleave 3-bit values, x lowest.
_SPREAD = np.array([0, 1, 8, 9, 64, 65, 72, 73], np.int64)


@kernel
def ray_ends(points, origin, max_range):
    """End of every ray as ``computeUpdate`` takes it (float32): the point itself when within
    ``max_range`` (< 0: unlimited), else the point ``max_range`` along the ray; and whether the
    point is within range (its voxel is then a hit)."""
    n = points.shape[0]
    ends = np.empty((n, 3), np.float32)
    hit = np.empty(n, np.bool_)
    ox, oy, oz = origin[0], origin[1], origin[2]
    mr = np.float32(max_range)
    for i in range(n):
        dx = points[i, 0] - ox
        dy = points[i, 1] - oy
        dz = points[i, 2] - oz
        norm = math.sqrt(np.float64(dx * dx + dy * dy + dz * dz))
        hit[i] = max_range < 0.0 or norm <= max_range
        if hit[i]:
            ends[i, 0] = points[i, 0]
            ends[i, 1] = points[i, 1]
            ends[i, 2] = points[i, 2]
        else:
            s = np.float32(norm)
            ends[i, 0] = ox + (dx / s) * mr
            ends[i, 1] = oy + (dy / s) * mr
            ends[i, 2] = oz + (dz / s) * mr
    return ends, hit


@kernel
def _ray_init(ox, oy, oz, ex, ey, ez, okx, oky, okz, res):
    """OctoMap's DDA set-up: float32 direction and length, float64 tMax and tDelta."""
    dx = ex - ox
    dy = ey - oy
    dz = ez - oz
    length = np.float32(math.sqrt(np.float64(dx * dx + dy * dy + dz * dz)))
    dx = dx / length
    dy = dy / length
    dz = dz / length
    sx = 1 if dx > 0 else (-1 if dx < 0 else 0)
    sy = 1 if dy > 0 else (-1 if dy < 0 else 0)
    sz = 1 if dz > 0 else (-1 if dz < 0 else 0)
    big = np.finfo(np.float64).max
    tx = ty = tz = big
    gx = gy = gz = big
    if sx != 0:
        tx = (key_to_coord(okx, res) + np.float64(np.float32(sx * res * 0.5)) - np.float64(ox)) / np.float64(dx)
        gx = res / abs(np.float64(dx))
    if sy != 0:
        ty = (key_to_coord(oky, res) + np.float64(np.float32(sy * res * 0.5)) - np.float64(oy)) / np.float64(dy)
        gy = res / abs(np.float64(dy))
    if sz != 0:
        tz = (key_to_coord(okz, res) + np.float64(np.float32(sz * res * 0.5)) - np.float64(oz)) / np.float64(dz)
        gz = res / abs(np.float64(dz))
    return np.float64(length), sx, sy, sz, tx, ty, tz, gx, gy, gz


@kernel
def ray_keys(origin, end, res):
    """Keys (M, 3) of the voxels ``computeRayKeys`` reports for one ray: the origin's voxel
    included, the end's excluded (none when both are in one voxel)."""
    inv_res = 1.0 / res
    ox, oy, oz = origin[0], origin[1], origin[2]
    okx, oky, okz = coord_to_key(ox, inv_res), coord_to_key(oy, inv_res), coord_to_key(oz, inv_res)
    ekx, eky, ekz = coord_to_key(end[0], inv_res), coord_to_key(end[1], inv_res), coord_to_key(end[2], inv_res)
    out = np.empty((16, 3), np.int64)
    m = 0
    if ekx == okx and eky == oky and ekz == okz:
        return out[:0]
    length, sx, sy, sz, tx, ty, tz, gx, gy, gz = _ray_init(ox, oy, oz, end[0], end[1], end[2], okx, oky, okz, res)
    kx, ky, kz = okx, oky, okz
    while True:
        if m == out.shape[0]:
            bigger = np.empty((2 * m, 3), np.int64)
            bigger[:m] = out
            out = bigger
        out[m, 0] = kx
        out[m, 1] = ky
        out[m, 2] = kz
        m += 1
        if tx < ty:
            if tx < tz:
                kx += sx
                tx += gx
            else:
                kz += sz
                tz += gz
        elif ty < tz:
            ky += sy
            ty += gy
        else:
            kz += sz
            tz += gz
        if (kx == ekx and ky == eky and kz == ekz) or min(tx, ty, tz) > length:
            return out[:m]


# ---------------------------------------------------------------------------- marking

@kernel
def _block_code(kx, ky, kz):
    """Packed key of the block holding voxel (kx, ky, kz), plus one (0 marks an empty slot)."""
    return (((kx >> 3) << 26) | ((ky >> 3) << 13) | (kz >> 3)) + 1


@kernel
def new_blocks(capacity):
    """Empty block storage for ``capacity`` blocks: hash table (twice as many slots), block codes,
    hit masks, free masks, and the count."""
    size = 16
    while size < 2 * capacity:
        size *= 2
    return (np.zeros(size, np.int64), np.zeros(capacity, np.int64), np.zeros((capacity, 8), np.int64),
            np.zeros((capacity, 8), np.int64), np.zeros(1, np.int64))


@kernel
def grow_blocks(table, codes, hits, frees, count):
    """The block storage at twice the capacity, rehashed."""
    n = count[0]
    t2, c2, h2, f2, n2 = new_blocks(2 * codes.shape[0])
    c2[:n] = codes[:n]
    h2[:n] = hits[:n]
    f2[:n] = frees[:n]
    n2[0] = n
    mask = t2.shape[0] - 1
    for b in range(n):
        h = (codes[b] * 0x5851F42D4C957F2D >> 20) & mask
        while t2[h] != 0:
            h = (h + 1) & mask
        t2[h] = b + 1
    return t2, c2, h2, f2, n2


@kernel
def mark_scan(origin, ends, hit, res, start, stop, table, codes, hits, frees, count):
    """Set the hit bit of each in-range end voxel and the free bits of every ray's voxels, for rays
    ``start..stop-1``. Returns ``stop``, or the ray at which the block storage filled up (marking
    is idempotent, so the caller grows it and resumes there)."""
    inv_res = 1.0 / res
    ox, oy, oz = origin[0], origin[1], origin[2]
    okx = coord_to_key(ox, inv_res)
    oky = coord_to_key(oy, inv_res)
    okz = coord_to_key(oz, inv_res)
    mask = table.shape[0] - 1
    cap = codes.shape[0]
    cur_code = 0
    cur = -1
    for i in range(start, stop):
        ex, ey, ez = ends[i, 0], ends[i, 1], ends[i, 2]
        ekx = coord_to_key(ex, inv_res)
        eky = coord_to_key(ey, inv_res)
        ekz = coord_to_key(ez, inv_res)
        ray = not (ekx == okx and eky == oky and ekz == okz)
        if ray:
            length, sx, sy, sz, tx, ty, tz, gx, gy, gz = _ray_init(ox, oy, oz, ex, ey, ez, okx, oky, okz, res)
            kx, ky, kz = okx, oky, okz
        else:
            kx, ky, kz = ekx, eky, ekz
        is_hit = not ray  # the end voxel comes last, after the ray's free voxels
        while True:
            if is_hit and not hit[i]:
                break
            code = _block_code(kx, ky, kz)
            if code != cur_code:  # find or add the block (the last one is cached)
                h = (code * 0x5851F42D4C957F2D >> 20) & mask
                while table[h] != 0 and codes[table[h] - 1] != code:
                    h = (h + 1) & mask
                if table[h] == 0:
                    if count[0] == cap:
                        return i
                    count[0] += 1
                    table[h] = count[0]
                    codes[count[0] - 1] = code
                cur = table[h] - 1
                cur_code = code
            m = _SPREAD[kx & 7] | (_SPREAD[ky & 7] << 1) | (_SPREAD[kz & 7] << 2)
            if is_hit:
                hits[cur, m >> 6] |= np.int64(1) << (m & 63)
                break
            frees[cur, m >> 6] |= np.int64(1) << (m & 63)
            if tx < ty:
                if tx < tz:
                    kx += sx
                    tx += gx
                else:
                    kz += sz
                    tz += gz
            elif ty < tz:
                ky += sy
                ty += gy
            else:
                kz += sz
                tz += gz
            if (kx == ekx and ky == eky and kz == ekz) or min(tx, ty, tz) > length:
                kx, ky, kz = ekx, eky, ekz
                is_hit = True
    return stop


@kernel
def morton_order(codes):
    """Order of the blocks by the Morton code of their block keys (the octree's DFS order)."""
    n = codes.shape[0]
    morton = np.empty(n, np.int64)
    for b in range(n):
        c = codes[b] - 1
        bx, by, bz = c >> 26, (c >> 13) & 8191, c & 8191
        m = 0
        for bit in range(13):
            m |= (((bx >> bit) & 1) << (3 * bit)) | (((by >> bit) & 1) << (3 * bit + 1)) | (((bz >> bit) & 1) << (3 * bit + 2))
        morton[b] = m
    return np.argsort(morton)


@kernel
def merge_blocks(codes, hits, frees):
    """Blocks of several markings concatenated → each block once, masks OR-ed, Morton-sorted."""
    order = morton_order(codes)
    n = codes.shape[0]
    c2 = np.empty(n, np.int64)
    h2 = np.empty((n, 8), np.int64)
    f2 = np.empty((n, 8), np.int64)
    m = -1
    for j in range(n):
        b = order[j]
        if m < 0 or codes[b] != c2[m]:
            m += 1
            c2[m] = codes[b]
            h2[m] = hits[b]
            f2[m] = frees[b]
        else:
            for w in range(8):
                h2[m, w] |= hits[b, w]
                f2[m, w] |= frees[b, w]
    return c2[:m + 1], h2[:m + 1], f2[:m + 1]


# ---------------------------------------------------------------------------- applying

_DEBRUIJN = np.array([
    0, 47, 1, 56, 48, 27, 2, 60, 57, 49, 41, 37, 28, 16, 3, 61, 54, 58, 35, 52, 50, 42, 21, 44,
    38, 32, 29, 23, 17, 11, 4, 62, 46, 55, 26, 59, 40, 36, 15, 53, 34, 51, 20, 43, 31, 22, 10, 45,
    25, 39, 14, 33, 19, 30, 9, 24, 13, 18, 8, 12, 7, 6, 5, 63], np.int64)


@kernel
def _lowest_bit(word):
    """Index of the lowest set bit of a nonzero int64 (de Bruijn multiplication)."""
    return _DEBRUIJN[(((word ^ (word - 1)) * 0x03F79D71B4CB0A89) >> 58) & 63]


@kernel
def _compact(m):
    """Every third bit of m from bit 0, packed (undoes the interleave of one axis)."""
    return (m & 1) | ((m >> 2) & 2) | ((m >> 4) & 4)


@kernel
def apply_blocks(value, child, meta, codes, hits, frees, start, l_hit, l_miss, lo, hi, settle_nodes):
    """Update every marked voxel of blocks ``start..`` (Morton-sorted) once. Returns the number of
    blocks, or the block at which the node pool ran out of room (nothing of it applied yet: the
    caller grows the pool and resumes there). With ``settle_nodes`` false (OctoMap's lazy
    evaluation) inner nodes are neither updated nor pruned."""
    nb = codes.shape[0]
    cap = value.shape[0]
    path = np.zeros(DEPTH + 1, np.int64)  # path[d]: node at depth d on the last walk
    known = -1  # deepest valid entry of path
    dirty = -1  # path[0..dirty] saw a change since the walk entered them
    px = py = pz = 0
    for b in range(start, nb):
        if meta[FREE] < 0 and meta[TOP] + _BLOCK_ROOM > cap:
            if settle_nodes:
                for d in range(min(dirty, known - 1), -1, -1):
                    settle(value, child, meta, path[d], True, True)
            return b
        c0 = codes[b] - 1
        bx, by, bz = (c0 >> 26) << 3, ((c0 >> 13) & 8191) << 3, (c0 & 8191) << 3
        for w in range(8):
            word = hits[b, w] | frees[b, w]
            while word != 0:
                bit = _lowest_bit(word)
                word &= word - 1
                is_hit = (hits[b, w] >> bit) & 1 == 1
                m = (w << 6) | bit
                kx = bx | _compact(m)
                ky = by | _compact(m >> 1)
                kz = bz | _compact(m >> 2)
                # ---- leave the previous voxel's path down to the node both share
                d = 0
                if known >= 0:
                    diff = (kx ^ px) | (ky ^ py) | (kz ^ pz)
                    top = 0
                    while diff > 1:
                        diff >>= 1
                        top += 1
                    shared = DEPTH - 1 - top
                    if settle_nodes:
                        for s in range(min(dirty, known - 1), shared, -1):
                            settle(value, child, meta, path[s], True, True)
                        dirty = min(dirty, shared)
                    d = min(shared, known)
                px, py, pz = kx, ky, kz
                # ---- walk down, creating or expanding nodes, unless the update cannot change anything
                node = path[d]
                created = False
                if d == 0 and np.isnan(value[0]):
                    value[0] = 0.0
                    child[0] = -1
                    meta[SIZE] += 1
                    created = True
                absorbed = False
                while d < DEPTH:
                    c = child[node]
                    if c < 0:
                        if not created:
                            v = value[node]
                            absorbed = v >= hi if is_hit else v <= lo  # OctoMap's early abort
                            if absorbed:
                                break
                        c = meta[FREE]
                        if c >= 0:
                            meta[FREE] = child[c]
                        else:
                            c = meta[TOP]
                            meta[TOP] = c + 8
                        fill = np.float32(np.nan) if created else value[node]  # expansion: 8 copies
                        for j in range(c, c + 8):
                            value[j] = fill
                            child[j] = -1
                        if not created:
                            meta[SIZE] += 8
                        child[node] = c
                    shift = DEPTH - 1 - d
                    node = c + (((kx >> shift) & 1) | (((ky >> shift) & 1) << 1) | (((kz >> shift) & 1) << 2))
                    created = np.isnan(value[node])
                    if created:
                        value[node] = 0.0
                        meta[SIZE] += 1
                    d += 1
                    path[d] = node
                known = d
                if absorbed:
                    continue
                v = value[node]
                if is_hit:
                    if v >= hi:
                        continue
                    v = v + l_hit
                else:
                    if v <= lo:
                        continue
                    v = v + l_miss
                value[node] = lo if v < lo else (hi if v > hi else v)
                dirty = DEPTH
    if settle_nodes and known >= 0:
        for d in range(min(dirty, known - 1), -1, -1):
            settle(value, child, meta, path[d], True, True)
    return nb
