"""Numba kernels that insert one scan into the octree, as OctoMap's ``insertPointCloud`` does.

OctoMap collects the scan's free and occupied voxels in two hash sets of keys, then updates each
voxel once (occupied ones only as hits) with a walk from the root. Here the two sets are bit masks
over 8×8×8-voxel *blocks* (a block = one depth-13 node; bit ``lx + 8·ly + 64·lz`` = the voxel at
local coordinates (lx, ly, lz)):

1. :func:`mark_scan` traverses the rays (OctoMap's ``computeRayKeys`` to the bit, float32
   arithmetic included) and sets the bits; a hash of block keys with the last block cached keeps
   this a few nanoseconds per voxel. Around the sensor, where every voxel is crossed by many rays
   (at 0.2 m most of a scan's steps lie within ±64 voxels of it), the bits go to a dense cube
   instead, placed where the scan's steps are (:func:`cube_corner`) and turned into blocks at
   the end (:func:`cube_blocks`). Disjoint ranges of rays can be marked in parallel threads and
   merged (:func:`merge_blocks`).
2. :func:`block_voxels` lists the marked voxels in Morton order (blocks sorted by their Morton
   code) and :func:`apply_voxels` updates them in that order, so consecutive voxels share their
   path from the root except the last level or two. Each
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

from .._intrinsics import add_if_le, add_if_lt, bit_length
from .._jit import kernel
from ._kernels import DEPTH, FREE, MAX_KEY, SIZE, TOP, alloc_block, coord_to_key, key_to_coord, settle

#: Slots one voxel update may allocate at most: a new block at every level.
_ROOM = 8 * DEPTH



@kernel
def prepare_rays(points, origins, max_range, res, box):
    """The rays of a scan as ``computeUpdate`` takes them, in one pass over float64 ``points``
    (N, 3) from float32 ``origins`` (N, 3), or (1, 3) for all: points with NaN/inf are dropped;
    each end (float32, as OctoMap's ``point3d``) is the point itself when within ``max_range``
    (< 0: unlimited) of its origin, else the point ``max_range`` along the ray; ``hit`` says which
    (the end voxel is then occupied). With a bounding box ``box`` (float32 (2, 3): min, max;
    (0, 3) for none) a point outside it is no hit. Returns (ends, hit, dropped, first point whose
    end lies outside the key range or −1)."""
    n = points.shape[0]
    inv_res = 1.0 / res
    ends = np.empty((n, 3), np.float32)
    hit = np.empty(n, np.bool_)
    mr = np.float32(max_range)
    m = 0
    bad = -1
    for i in range(n):
        if not (np.isfinite(points[i, 0]) and np.isfinite(points[i, 1]) and np.isfinite(points[i, 2])):
            continue
        j = i if origins.shape[0] > 1 else 0
        ox, oy, oz = origins[j, 0], origins[j, 1], origins[j, 2]
        px, py, pz = np.float32(points[i, 0]), np.float32(points[i, 1]), np.float32(points[i, 2])
        dx, dy, dz = px - ox, py - oy, pz - oz
        norm = math.sqrt(np.float64(dx * dx + dy * dy + dz * dz))
        hit[m] = max_range < 0.0 or norm <= max_range
        if not hit[m]:
            s = np.float32(norm)
            px, py, pz = ox + (dx / s) * mr, oy + (dy / s) * mr, oz + (dz / s) * mr
        ends[m, 0], ends[m, 1], ends[m, 2] = px, py, pz
        if hit[m] and box.shape[0]:
            hit[m] = (box[0, 0] <= px <= box[1, 0] and box[0, 1] <= py <= box[1, 1]
                      and box[0, 2] <= pz <= box[1, 2])
        if bad < 0:
            for c in (px, py, pz):
                k = coord_to_key(c, inv_res)
                if k < 0 or k > MAX_KEY:
                    bad = i
        m += 1
    return ends[:m], hit[:m], n - m, bad


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
def _step(kx, ky, kz, tx, ty, tz, sx, sy, sz, gx, gy, gz):
    """One DDA step: advance along the axis whose voxel border comes first (OctoMap's tie-breaks)."""
    if tx < ty:
        if tx < tz:
            return kx + sx, ky, kz, tx + gx, ty, tz
        return kx, ky, kz + sz, tx, ty, tz + gz
    if ty < tz:
        return kx, ky + sy, kz, tx, ty + gy, tz
    return kx, ky, kz + sz, tx, ty, tz + gz


@kernel
def ray_voxels(origins, ends, with_end, res):
    """The voxels OctoMap's ``insertRay`` updates, ray after ray: each ray's free voxels (from
    ``computeRayKeys``: the origin's voxel included, the end's excluded) then, where ``with_end``,
    its end voxel as a hit. Returns packed keys ``kx | ky << 16 | kz << 32`` and hit flags."""
    inv_res = 1.0 / res
    n_rays = ends.shape[0]
    total = 0
    for count_only in (True, False):
        if not count_only:
            keys = np.empty(total, np.int64)
            is_hit = np.empty(total, np.bool_)
        m = 0
        for r in range(n_rays):
            o = origins[r] if origins.shape[0] > 1 else origins[0]
            ox, oy, oz = o[0], o[1], o[2]
            ex, ey, ez = ends[r, 0], ends[r, 1], ends[r, 2]
            okx, oky, okz = coord_to_key(ox, inv_res), coord_to_key(oy, inv_res), coord_to_key(oz, inv_res)
            ekx, eky, ekz = coord_to_key(ex, inv_res), coord_to_key(ey, inv_res), coord_to_key(ez, inv_res)
            if not (ekx == okx and eky == oky and ekz == okz):
                length, sx, sy, sz, tx, ty, tz, gx, gy, gz = _ray_init(ox, oy, oz, ex, ey, ez, okx, oky, okz, res)
                kx, ky, kz = okx, oky, okz
                while True:
                    if not count_only:
                        keys[m] = kx | (ky << 16) | (kz << 32)
                        is_hit[m] = False
                    m += 1
                    kx, ky, kz, tx, ty, tz = _step(kx, ky, kz, tx, ty, tz, sx, sy, sz, gx, gy, gz)
                    if (kx == ekx and ky == eky and kz == ekz) or min(tx, ty, tz) > length:
                        break
            if with_end[r]:
                if not count_only:
                    keys[m] = ekx | (eky << 16) | (ekz << 32)
                    is_hit[m] = True
                m += 1
        total = m
    return keys, is_hit


# ---------------------------------------------------------------------------- marking

@kernel
def _block_code(kx, ky, kz):
    """Packed key of the block holding voxel (kx, ky, kz), plus one (0 marks an empty slot)."""
    return (((kx >> 3) << 26) | ((ky >> 3) << 13) | (kz >> 3)) + 1


@kernel
def new_blocks(capacity):
    """Empty block storage for ``capacity`` blocks: hash table (block codes and block indices, at
    least twice as many slots), block codes, hit masks, free masks, and the count."""
    size = 16
    while size < 2 * capacity:
        size *= 2
    return (np.zeros(size, np.int64), np.zeros(size, np.int64), np.zeros(capacity, np.int64),
            np.zeros((capacity, 8), np.int64), np.zeros((capacity, 8), np.int64), np.zeros(1, np.int64))


@kernel
def _hash(code, mask):
    return ((code * 0x5851F42D4C957F2D) >> 20) & mask


@kernel
def grow_blocks(table, slots, codes, hits, frees, count):
    """The block storage at twice the capacity, rehashed."""
    n = count[0]
    t2, s2, c2, h2, f2, n2 = new_blocks(2 * codes.shape[0])
    c2[:n] = codes[:n]
    h2[:n] = hits[:n]
    f2[:n] = frees[:n]
    n2[0] = n
    mask = t2.shape[0] - 1
    for b in range(n):
        h = _hash(codes[b], mask)
        while t2[h] != 0:
            h = (h + 1) & mask
        t2[h] = codes[b]
        s2[h] = b
    return t2, s2, c2, h2, f2, n2


#: The dense cube marked around the sensor: CUBE³ voxels (a multiple of 8) that hold the
#: sensor's voxel; voxel ``x + CUBE·y + CUBE²·z`` is a byte of the free cube (a plain store marks
#: it, so marks of one voxel or one word never wait for each other) and a bit of the hit cube
#: (int64 words). Near the sensor every voxel is crossed by many rays; there a step marks at an
#: index that moves with it, with no block to look up.
CUBE = 128
_CUBE_WORDS = CUBE ** 3 // 64
#: Packed keys in the cube phase: ``kx | ky << 20 | kz << 40``; a step past either end of the
#: key range cannot carry into the next field.
_KY, _KZ = 20, 40
_OUTSIDE = ~((CUBE - 1) | ((CUBE - 1) << _KY) | ((CUBE - 1) << _KZ))


@kernel
def new_cube():
    """Dense hit bits and free bytes of a cube (zeroed)."""
    return np.zeros(_CUBE_WORDS, np.int64), np.zeros(CUBE ** 3, np.uint8)


#: Rays sampled (evenly over the scan) to place the cube, and points taken along each.
_PLACE_RAYS = 256
_PLACE_POINTS = 4
#: Placements of the cube along one axis that keep a given voxel inside: 16, one per block.
_PLACES = CUBE // 8


@kernel
def cube_corner(origin, ends, res):
    """Packed key of the corner of the cube for the rays from ``origin`` to ``ends``, or −1
    where no cube around the sensor's voxel fits the key range. The cube is block-aligned and
    holds the sensor's voxel; of the 16 such placements per axis it takes those that hold the
    most of the rays' steps, estimated from a sample: a walk's steps are spread evenly over its
    length, so points evenly spread along a ray, weighted by its number of steps, stand for them.
    The axes are placed one at a time, the other two held, twice over, from the centred cube (a
    sensor at one side of its scan gets a cube shifted to that side)."""
    inv_res = 1.0 / res
    ok = np.empty(3, np.int64)
    for a in range(3):
        ok[a] = coord_to_key(origin[a], inv_res)
    lo = np.empty(3, np.int64)  # allowed shifts k: corner block = sensor's block − k
    hi = np.empty(3, np.int64)
    for a in range(3):
        b = ok[a] >> 3
        lo[a] = max(0, b + _PLACES - (MAX_KEY + 1) // 8)
        hi[a] = min(_PLACES - 1, b)
        if lo[a] > hi[a]:
            return -1
    n = ends.shape[0]
    step = max(1, n // _PLACE_RAYS)
    m = (n + step - 1) // step * _PLACE_POINTS
    rel = np.empty((m, 3), np.int64)  # a point's block relative to the sensor's, per axis
    w = np.empty(m)
    j = 0
    for i in range(0, n, step):
        n_steps = 0
        for a in range(3):
            n_steps += abs(coord_to_key(ends[i, a], inv_res) - ok[a])
        for p in range(_PLACE_POINTS):
            f = (p + 0.5) / _PLACE_POINTS
            for a in range(3):
                c = np.float64(origin[a]) + f * (np.float64(ends[i, a]) - np.float64(origin[a]))
                rel[j, a] = (coord_to_key(c, inv_res) >> 3) - (ok[a] >> 3)
            w[j] = n_steps
            j += 1
    k = np.empty(3, np.int64)
    for a in range(3):
        k[a] = min(max(_PLACES // 2, lo[a]), hi[a])
    hist = np.empty(2 * _PLACES)
    for _ in range(2):
        for a in range(3):
            b, c = (a + 1) % 3, (a + 2) % 3
            hist[:] = 0.0
            for q in range(m):
                r = rel[q, a]
                if (-_PLACES <= r < _PLACES and -k[b] <= rel[q, b] < _PLACES - k[b]
                        and -k[c] <= rel[q, c] < _PLACES - k[c]):
                    hist[r + _PLACES] += w[q]
            best, best_sum = k[a], -1.0
            for kk in range(lo[a], hi[a] + 1):  # blocks −kk .. 15 − kk
                total = hist[_PLACES - kk:2 * _PLACES - kk].sum()
                if total > best_sum or (total == best_sum and abs(kk - _PLACES // 2) < abs(best - _PLACES // 2)):
                    best, best_sum = kk, total
            k[a] = best
    cx = ((ok[0] >> 3) - k[0]) << 3
    cy = ((ok[1] >> 3) - k[1]) << 3
    cz = ((ok[2] >> 3) - k[2]) << 3
    return cx | (cy << _KY) | (cz << _KZ)


@kernel
def _cube_index(key, corner):
    """Index of the voxel with packed key ``key`` in the cube at ``corner``."""
    d = key - corner
    return (d & (CUBE - 1)) + ((d >> _KY) & (CUBE - 1)) * CUBE + (d >> _KZ) * (CUBE * CUBE)


@kernel
def _cube_key(idx, corner):
    """Packed key of the voxel at index ``idx`` of the cube at ``corner`` (:func:`_cube_index`
    undone)."""
    return corner + idx % CUBE + ((idx // CUBE % CUBE) << _KY) + ((idx // (CUBE * CUBE)) << _KZ)


#: A ray is walked in slabs (:func:`_cube_slabs`) when its two other axes cross voxel borders
#: at least this much more sparsely than its major axis: then, in floating point too, each of them
#: steps at most once between two steps of the major axis.
_SLAB_MARGIN = 1.0 + 1e-9


@kernel
def _cube_slabs(frees, idx, n, tM, tA, tB, gM, gA, gB, dM, dA, dB, tie_a, tie_b):
    """``n`` slabs of OctoMap's DDA in the free cube, from a voxel the walk has just entered along
    its major axis M (``t``, ``g``, index step ``d`` per axis; minor axes A and B). In a slab the
    minor axes step at most once each (see :data:`_SLAB_MARGIN`): A when ``tA < tM``, or equal
    and ``tie_a`` (OctoMap's tie-breaks prefer z over y over x; ``tie_a`` and ``tie_b`` are
    literals, so each form compiles to one compare), likewise B, A before B when ``tA < tB``; then
    M steps. So a slab is a fixed sequence of three marks at computed indices — its voxels,
    repeats marked twice — with no branch to mispredict. Returns the index and the three t."""
    for _ in range(n):
        uA = add_if_le(tA, tM, gA) if tie_a else add_if_lt(tA, tM, gA)
        uB = add_if_le(tB, tM, gB) if tie_b else add_if_lt(tB, tM, gB)
        sA = np.int64(uA != tA) * dA
        sB = np.int64(uB != tB) * dB
        a_first = np.int64(tA < tB)
        frees[np.uint64(idx)] = 1
        frees[np.uint64(idx + sB + a_first * (sA - sB))] = 1  # the first minor step's voxel (or a repeat)
        idx += sA + sB
        frees[np.uint64(idx)] = 1
        idx += dM
        tA = uA
        tB = uB
        tM += gM
    return idx, tM, tA, tB


@kernel
def _room(local, step):
    """Steps of one voxel in direction ``step`` that keep cube coordinate ``local`` in the cube
    (unlimited for an axis that does not move)."""
    if step == 0:
        return CUBE
    return CUBE - 1 - local if step > 0 else local


@kernel
def _slab_count(key, corner, end_key, major, sx, sy, sz, tx, ty, tz, gx, gy, gz, length):
    """How many slabs (:func:`_cube_slabs`) a walk just past a major-axis step can take without
    checks: every voxel of them, and the one after, stays in the cube (the minor axes step at most
    once a slab), short of the end voxel's major coordinate (so none is the end voxel) and with the
    major axis's next crossing within ``length`` (so the walk's range test cannot stop it; one slab
    of margin for the rounding of the sums)."""
    d = key - corner
    lx, ly, lz = d & (CUBE - 1), (d >> _KY) & (CUBE - 1), d >> _KZ
    n = min(_room(lx, sx), _room(ly, sy), _room(lz, sz))
    if major == 0:
        r, t, g = abs((end_key & 0xFFFFF) - (key & 0xFFFFF)), tx, gx
    elif major == 1:
        r, t, g = abs(((end_key >> _KY) & 0xFFFFF) - ((key >> _KY) & 0xFFFFF)), ty, gy
    else:
        r, t, g = abs((end_key >> _KZ) - (key >> _KZ)), tz, gz
    n = min(n, r - 1)
    if t < length:
        n = min(n, int((length - t) / g) - 1)
    else:
        n = 0
    return n


@kernel
def mark_scan(origin, ends, hit, res, rays, start, stop, table, slots, codes, hits, frees, count,
              cube_hits, cube_frees, corner):
    """Set the hit bit of each in-range end voxel and the free bits of every ray's voxels, for rays
    ``start..stop-1`` (only the hits when ``rays`` is false). Returns ``stop``, or the ray at which
    the block storage filled up (marking is idempotent, so the caller grows it and resumes there).
    Within a block, bit ``lx + 8·ly + 64·lz`` stands for the voxel at local coordinates
    (lx, ly, lz). Voxels in the cube at ``corner`` (from :func:`cube_corner`; −1: none) are
    marked in ``cube_hits`` and ``cube_frees`` instead (see :func:`cube_blocks`)."""
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
        end_key = ekx | (eky << _KY) | (ekz << _KZ)
        ray = rays and not (ekx == okx and eky == oky and ekz == okz)
        if ray:
            length, sx, sy, sz, tx, ty, tz, gx, gy, gz = _ray_init(ox, oy, oz, ex, ey, ez, okx, oky, okz, res)
            kx, ky, kz = okx, oky, okz
            done = False
        else:
            kx, ky, kz = ekx, eky, ekz
            sx = sy = sz = 1
            done = True
        if ray and corner >= 0:
            # the cube phase (the sensor's voxel lies in the cube): OctoMap's DDA step with the
            # packed key and the cube index moving together, no block to look up; from the first
            # step along the major axis on, in slabs where the ray allows (see _cube_slabs)
            key = kx | (ky << _KY) | (kz << _KZ)
            idx = _cube_index(key, corner)
            dky, dkz = sy << _KY, sz << _KZ
            diy, diz = sy * CUBE, sz * CUBE * CUBE
            major = 0 if gx <= min(gy, gz) else (1 if gy <= gz else 2)
            g_middle = min(max(gx, gy), max(gy, gz), max(gx, gz))
            slabs = g_middle >= min(gx, gy, gz) * _SLAB_MARGIN
            while True:
                cube_frees[np.uint64(idx)] = 1  # (unsigned: no wrap-around test)
                if tx < ty:
                    if tx < tz:
                        key += sx
                        idx += sx
                        tx += gx
                        axis = 0
                    else:
                        key += dkz
                        idx += diz
                        tz += gz
                        axis = 2
                elif ty < tz:
                    key += dky
                    idx += diy
                    ty += gy
                    axis = 1
                else:
                    key += dkz
                    idx += diz
                    tz += gz
                    axis = 2
                if key == end_key or min(tx, ty, tz) > length:
                    key = end_key  # (the range test may stop the walk short of it)
                    done = True
                    break
                if (key - corner) & _OUTSIDE:
                    break
                if slabs and axis == major:
                    slabs = False
                    n = _slab_count(key, corner, end_key, major, sx, sy, sz, tx, ty, tz, gx, gy, gz, length)
                    if n > 0:
                        if major == 0:
                            idx, tx, ty, tz = _cube_slabs(cube_frees, idx, n, tx, ty, tz, gx, gy, gz, sx, diy, diz,
                                                          True, True)
                        elif major == 1:
                            idx, ty, tx, tz = _cube_slabs(cube_frees, idx, n, ty, tx, tz, gy, gx, gz, diy, sx, diz,
                                                          False, True)
                        else:
                            idx, tz, tx, ty = _cube_slabs(cube_frees, idx, n, tz, tx, ty, gz, gx, gy, diz, sx, diy,
                                                          False, False)
                        key = _cube_key(idx, corner)
            kx, ky, kz = key & 0xFFFFF, (key >> _KY) & 0xFFFFF, key >> _KZ
        is_hit = done  # the end voxel comes last, after the ray's free voxels
        if is_hit and hit[i] and corner >= 0 and not ((end_key - corner) & _OUTSIDE):
            j = _cube_index(end_key, corner)
            cube_hits[j >> 6] |= np.int64(1) << (j & 63)
            continue
        wx, wy, wz = 0 if sx > 0 else 7, 0 if sy > 0 else 7, 0 if sz > 0 else 7  # local coordinate on entering a block
        lookup = True
        while True:
            if is_hit and not hit[i]:
                break
            if lookup:  # the voxel may lie in another block: find or add it (the last one is cached)
                code = _block_code(kx, ky, kz)
                if code != cur_code:
                    h = _hash(code, mask)
                    while table[h] != 0 and table[h] != code:
                        h = (h + 1) & mask
                    if table[h] == 0:
                        if count[0] == cap:
                            return i
                        table[h] = code
                        slots[h] = count[0]
                        codes[count[0]] = code
                        count[0] += 1
                    cur = slots[h]
                    cur_code = code
                lookup = False
            m = (kx & 7) | ((ky & 7) << 3) | ((kz & 7) << 6)
            if is_hit:
                hits[cur, m >> 6] |= np.int64(1) << (m & 63)
                break
            frees[np.uint64(cur), np.uint64(m >> 6)] |= np.int64(1) << (m & 63)
            # next voxel: OctoMap's DDA step, noting when it enters another block
            if tx < ty:
                if tx < tz:
                    kx += sx
                    tx += gx
                    lookup = (kx & 7) == wx
                else:
                    kz += sz
                    tz += gz
                    lookup = (kz & 7) == wz
            elif ty < tz:
                ky += sy
                ty += gy
                lookup = (ky & 7) == wy
            else:
                kz += sz
                tz += gz
                lookup = (kz & 7) == wz
            if (kx == ekx and ky == eky and kz == ekz) or min(tx, ty, tz) > length:
                kx, ky, kz = ekx, eky, ekz
                is_hit = True
                lookup = True
    return stop


#: Multiplier that gathers the low bits of a word's eight bytes into its top byte's bits
#: 49..56 (byte i's bit lands on bit 49 + i, no two products overlap, so nothing carries).
_GATHER = 0x0002040810204081


@kernel
def cube_blocks(cube_hits, cube_frees, corner):
    """The cube's marked voxels as blocks: codes, hit masks, free masks (the blocks that have any;
    :func:`merge_blocks` ors them with the same blocks marked elsewhere)."""
    cx, cy, cz = corner & 0xFFFFF, (corner >> _KY) & 0xFFFFF, corner >> _KZ
    nb = CUBE // 8
    w_row = CUBE // 64  # words of hit bits per row of the cube
    free_rows = cube_frees.view(np.uint64)  # eight voxels' free bytes per word
    codes = np.empty(nb ** 3, np.int64)
    hits = np.empty((nb ** 3, 8), np.int64)
    frees = np.empty((nb ** 3, 8), np.int64)
    n = 0
    for bz in range(nb):
        for by in range(nb):
            for bx in range(nb):
                # the block's 8×8×8 voxels: byte bx % 8 of one hit word, and one free word, per row (y, z)
                word0 = (bz * 8 * CUBE + by * 8) * w_row + (bx * 8) // 64
                shift = (bx * 8) % 64
                row0 = ((bz * 8 * CUBE + by * 8) * CUBE + bx * 8) // 8
                any_bits = np.int64(0)
                for lz in range(8):
                    hw = np.int64(0)
                    fw = np.int64(0)
                    for ly in range(8):
                        w = word0 + (lz * CUBE + ly) * w_row
                        hw |= ((cube_hits[w] >> shift) & 0xFF) << (8 * ly)
                        f = free_rows[row0 + (lz * CUBE + ly) * (CUBE // 8)]
                        fw |= np.int64(((f * np.uint64(_GATHER)) >> np.uint64(49)) & np.uint64(0xFF)) << (8 * ly)
                    hits[n, lz] = hw
                    frees[n, lz] = fw
                    any_bits |= hw | fw
                if any_bits != 0:
                    codes[n] = _block_code(cx + bx * 8, cy + by * 8, cz + bz * 8)
                    n += 1
    return codes[:n], hits[:n], frees[:n]


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
def _spread(v):
    """Bits 0..2 of v moved to bits 0, 3, 6 (one axis of a 9-bit Morton code)."""
    return (v & 1) | ((v & 2) << 2) | ((v & 4) << 4)


@kernel
def _compact(m):
    """Every third bit of m from bit 0, packed (undoes :func:`_spread`)."""
    return (m & 1) | ((m >> 2) & 2) | ((m >> 4) & 4)


@kernel
def block_voxels(codes, hits, frees, kbox):
    """The marked voxels of Morton-sorted blocks as packed keys ``kx | ky << 16 | kz << 32`` in
    Morton order, with a flag for the hit voxels (a voxel both hit and crossed is a hit); only
    those within the key box ``kbox`` (int64 (2, 3): min, max; (0, 3) for none)."""
    n = 0
    for b in range(codes.shape[0]):
        for w in range(8):
            word = hits[b, w] | frees[b, w]
            while word != 0:
                word &= word - 1
                n += 1
    keys = np.empty(n, np.int64)
    is_hit = np.empty(n, np.bool_)
    morton = np.empty(8, np.int64)  # the block's bits re-laid in Morton order
    n = 0
    for b in range(codes.shape[0]):
        morton[:] = 0
        for w in range(8):
            word = hits[b, w] | frees[b, w]
            while word != 0:
                bit = _lowest_bit(word)
                word &= word - 1
                m = (w << 6) | bit
                z = _spread(m & 7) | (_spread((m >> 3) & 7) << 1) | (_spread(m >> 6) << 2)
                morton[z >> 6] |= np.int64(1) << (z & 63)
        c0 = codes[b] - 1
        base = ((c0 >> 26) << 3) | ((((c0 >> 13) & 8191) << 3) << 16) | (((c0 & 8191) << 3) << 32)
        for w in range(8):
            word = morton[w]
            while word != 0:
                bit = _lowest_bit(word)
                word &= word - 1
                z = (w << 6) | bit
                lx, ly, lz = _compact(z), _compact(z >> 1), _compact(z >> 2)
                if kbox.shape[0]:
                    kx, ky, kz = (base & 0xFFFF) | lx, ((base >> 16) & 0xFFFF) | ly, (base >> 32) | lz
                    if not (kbox[0, 0] <= kx <= kbox[1, 0] and kbox[0, 1] <= ky <= kbox[1, 1]
                            and kbox[0, 2] <= kz <= kbox[1, 2]):
                        continue
                keys[n] = base | lx | (ly << 16) | (lz << 32)
                linear = lx | (ly << 3) | (lz << 6)
                is_hit[n] = (hits[b, linear >> 6] >> (linear & 63)) & 1 == 1
                n += 1
    return keys[:n], is_hit[:n]


@kernel
def shared_depth(a, b):
    """Depth of the deepest node on the paths to the voxels with packed keys ``a`` and ``b`` (16
    when they are the same voxel)."""
    d = a ^ b
    return DEPTH - bit_length((d | (d >> 16) | (d >> 32)) & 0xFFFF)


@kernel
def subtree_split(keys, depth, first):
    """Index in ``keys[first:]`` (packed, Morton order, all below one node at ``depth``) where one
    child subtree of that node ends and the next begins, nearest the middle."""
    n = keys.shape[0]
    best = first
    for i in range(first + 1, n):
        if shared_depth(keys[i - 1], keys[i]) == depth and abs(2 * i - n - first) < abs(2 * best - n - first):
            best = i
    return best


@kernel
def apply_voxels(value, child, meta, keys, is_hit, start, l_hit, l_miss, lo, hi, settle_nodes, limit, top):
    """Update voxels ``start..`` (packed keys) in order, each as OctoMap's ``updateNode`` with a hit
    or a miss. Returns (the number of voxels, or the one at which the slots below ``limit`` ran
    out — nothing of it applied yet: the caller makes room and resumes there; whether any value
    changed). With ``settle_nodes`` false (OctoMap's lazy evaluation) inner nodes are neither
    updated nor pruned. Nodes above depth ``top`` are only passed through, never settled: two
    threads can update the subtrees below one node side by side (see ``OcTree._apply``).

    The walk to a voxel restarts from the deepest node shared with the previous voxel's path, so
    voxels in Morton order cost a level or two instead of sixteen; an inner node is settled once
    the walk leaves it, if anything below it changed. The update step is written once and inline:
    a Numba call passing arrays costs more than the step itself."""
    n = keys.shape[0]
    cap = limit
    changed = False
    path = np.zeros(DEPTH + 1, np.int64)  # path[d]: node at depth d on the last walk
    known = -1  # deepest valid entry of path
    dirty = -1  # path[0..dirty] saw a change since the walk entered them
    previous = 0
    for i in range(start, n):
        if meta[FREE] < 0 and meta[TOP] + _ROOM > cap:
            if settle_nodes:
                for d in range(min(dirty, known - 1), top - 1, -1):
                    settle(value, child, meta, path[d], True, True)
            return i, changed
        key = keys[i]
        kx, ky, kz = key & 0xFFFF, (key >> 16) & 0xFFFF, key >> 32
        hit = is_hit[i]
        # ---- leave the previous voxel's path up to the node both share
        d = 0
        if known >= 0:
            shared = shared_depth(key, previous)
            if settle_nodes:
                for s in range(min(dirty, known - 1), max(shared, top - 1), -1):
                    settle(value, child, meta, path[s], True, True)
                dirty = min(dirty, shared)
            d = min(shared, known)
        previous = key
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
                    absorbed = v >= hi if hit else v <= lo  # OctoMap's early abort
                    if absorbed:
                        break
                # a new node gets an empty block; a pruned leaf is expanded into eight copies
                c = alloc_block(value, child, meta, np.float32(np.nan) if created else value[node])
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
        if hit:
            if v >= hi:
                continue
            v = v + l_hit
        else:
            if v <= lo:
                continue
            v = v + l_miss
        value[node] = lo if v < lo else (hi if v > hi else v)
        dirty = DEPTH
        changed = True
    if settle_nodes and known >= 0:
        for d in range(min(dirty, known - 1), top - 1, -1):
            settle(value, child, meta, path[d], True, True)
    return n, changed
