"""Numba kernels that turn one scan into its voxels, as OctoMap's ``insertPointCloud`` does.

OctoMap collects the scan's free and occupied voxels in two hash sets of keys, then updates each
voxel once (occupied ones only as hits) with a walk from the root. Here the two sets are the bit
masks of :mod:`.blocks`:

Keys here are *local*: OctoMap's key less a ``shift`` (int64 (3,), a multiple of 8 per axis; zeros
for an :class:`~occmap.octree.OcTree`), so that a tiled map (:mod:`occmap.world`) can mark scans
anywhere in a 64-bit key space with the same 16-bit machinery. The walk itself always computes
with the unshifted key, so its voxels are OctoMap's to the bit wherever the scan lies.

1. :func:`mark_scan` walks the rays (:mod:`.raywalk`: OctoMap's ``computeRayKeys`` to the bit,
   float32 arithmetic included) and sets the bits through the block accessor (:mod:`.blocks`),
   a few nanoseconds per voxel. Around the sensor, where every voxel is crossed by many rays
   (at 0.2 m most of a scan's steps lie within ±64 voxels of it), the bits go to a dense cube
   instead, placed where the scan's steps are (:func:`cube_corner`) and turned into blocks at
   the end (:func:`cube_blocks`). Disjoint ranges of rays can be marked in parallel threads and
   merged (:func:`.blocks.merge_blocks`).
2. :func:`.blocks.block_voxels` lists the marked voxels in Morton order — a node whose voxels are
   all marked alike as one update — and :func:`.update.apply_voxels` applies them in that order.

:func:`ray_voxels` is the plain form for OctoMap's ``insertRay``: every ray's voxels in turn, no
merging.
"""

from __future__ import annotations

import math

import numpy as np

from .._intrinsics import add_if_le, add_if_lt
from .._jit import inline_kernel, kernel
from . import raywalk
from .blocks import home
from .keys import MAX_KEY, block_code, coord_to_key, field, in_block, key_in_range, key_to_coord, pack, unpack


@kernel
def prepare_rays(points, origins, max_range, res, box, shift):
    """The rays of a scan as ``computeUpdate`` takes them, in one pass over float64 ``points``
    (N, 3) from float32 ``origins`` (N, 3), or (1, 3) for all: each end (float32, as OctoMap's
    ``point3d``) is the point itself when within ``max_range`` (< 0: unlimited) of its origin,
    else the point ``max_range`` along the ray; ``hit`` says which (the end voxel is then
    occupied). With a bounding box ``box`` (float32 (2, 3): min, max; (0, 3) for none) a point
    outside it is no hit. Dropped: points with NaN/inf, and — OctoMap's rule: ``computeRayKeys``
    fails, the ray is skipped — rays whose end's local key (OctoMap's less ``shift``) lies outside
    0 .. 65535 or whose float32 length overflows. Returns (ends, hit, the indices of the points
    kept, non-finite points dropped, rays dropped outside the key range)."""
    n = points.shape[0]
    ends = np.empty((n, 3), np.float32)
    hit = np.empty(n, np.bool_)
    kept = np.empty(n, np.int64)
    m, non_finite, outside = prepare_rays_into(points, origins, max_range, res, box, shift, ends, hit, kept)
    return ends[:m], hit[:m], kept[:m], non_finite, outside


@kernel
def prepare_rays_into(points, origins, max_range, res, box, shift, ends, hit, kept):
    """:func:`prepare_rays` into the first rows of given arrays (each of N rows at least; ``kept``
    may be empty: the indices are then not written), so that a caller can keep them from scan to
    scan: fresh arrays as large as a scan cost a page fault every 4 KiB written (a fifth of
    this pass for 80,000 points). Returns (the number of rays, non-finite points dropped, rays
    dropped outside the key range)."""
    n = points.shape[0]
    inv_res = 1.0 / res
    with_kept = kept.shape[0] > 0
    mr = np.float32(max_range)
    m = 0
    non_finite = 0
    for i in range(n):
        if not (np.isfinite(points[i, 0]) and np.isfinite(points[i, 1]) and np.isfinite(points[i, 2])):
            non_finite += 1
            continue
        j = i if origins.shape[0] > 1 else 0
        ox, oy, oz = origins[j, 0], origins[j, 1], origins[j, 2]
        px, py, pz = np.float32(points[i, 0]), np.float32(points[i, 1]), np.float32(points[i, 2])
        dx, dy, dz = px - ox, py - oy, pz - oz
        square = np.float64(dx * dx + dy * dy + dz * dz)  # (its root only where a max range asks)
        is_hit = max_range < 0.0 or math.sqrt(square) <= max_range
        if not is_hit:
            s = np.float32(math.sqrt(square))
            px, py, pz = ox + (dx / s) * mr, oy + (dy / s) * mr, oz + (dz / s) * mr
        if not (square < np.inf and key_in_range(coord_to_key(px, inv_res) - shift[0])
                and key_in_range(coord_to_key(py, inv_res) - shift[1])
                and key_in_range(coord_to_key(pz, inv_res) - shift[2])):
            continue  # (an overflowing length only where a resolution of 1e34 m or more puts such ends in range)
        if is_hit and box.shape[0]:
            is_hit = (box[0, 0] <= px <= box[1, 0] and box[0, 1] <= py <= box[1, 1]
                      and box[0, 2] <= pz <= box[1, 2])
        ends[m, 0], ends[m, 1], ends[m, 2] = px, py, pz
        hit[m] = is_hit
        if with_kept:
            kept[m] = i
        m += 1
    return m, non_finite, n - non_finite - m


@kernel
def voxel_centres(points, res, shift):
    """The points of OctoMap's ``computeDiscreteUpdate``: the centre of each voxel that holds
    points of float64 ``points`` (N, 3) (each taken as float32, as OctoMap's ``point3d``), once, in
    the order of the voxels' first points. Points with NaN/inf are dropped, and so are points whose
    local key (OctoMap's less ``shift``) lies outside 0 .. 65535 (OctoMap's unchecked key wraps
    around there and marks a voxel far away). Returns (centres float64 (M, 3), non-finite points
    dropped, points dropped outside the key range)."""
    n = points.shape[0]
    inv_res = 1.0 / res
    size = 16
    while size < 2 * n:
        size *= 2
    mask = size - 1
    table = np.full(size, -1, np.int64)  # packed local keys of the voxels seen, open addressing
    centres = np.empty((n, 3), np.float64)
    m = 0
    non_finite = outside = 0
    for i in range(n):
        if not (np.isfinite(points[i, 0]) and np.isfinite(points[i, 1]) and np.isfinite(points[i, 2])):
            non_finite += 1
            continue
        kx = coord_to_key(np.float32(points[i, 0]), inv_res)
        ky = coord_to_key(np.float32(points[i, 1]), inv_res)
        kz = coord_to_key(np.float32(points[i, 2]), inv_res)
        if not (key_in_range(kx - shift[0]) and key_in_range(ky - shift[1]) and key_in_range(kz - shift[2])):
            outside += 1
            continue
        code = pack(kx - shift[0], ky - shift[1], kz - shift[2])
        h = home(code, mask)
        while table[h] != -1 and table[h] != code:
            h = (h + 1) & mask
        if table[h] == -1:
            table[h] = code
            centres[m, 0], centres[m, 1], centres[m, 2] = key_to_coord(kx, res), key_to_coord(ky, res), key_to_coord(kz, res)
            m += 1
    return centres[:m], non_finite, outside


@inline_kernel
def _walk_start(ox, oy, oz, ex, ey, ez, okx, oky, okz, res):
    """``computeRayKeys``' walk state of the ray from float32 ``o`` (in voxel ``ok``) to ``e``:
    its float32 length (as float64) and :func:`.raywalk.start`'s state."""
    length, ux, uy, uz = raywalk.direction(ex - ox, ey - oy, ez - oz)
    return (length,) + raywalk.start(ox, oy, oz, ux, uy, uz, okx, oky, okz, res, True)


@kernel
def ray_voxels(origins, ends, with_end, res):
    """The voxels OctoMap's ``insertRay`` updates, ray after ray: each ray's free voxels (from
    ``computeRayKeys``: the origin's voxel included, the end's excluded) then, where ``with_end``,
    its end voxel as a hit. Returns packed keys (:func:`.keys.pack`) and hit flags."""
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
            end_key = pack(coord_to_key(ex, inv_res), coord_to_key(ey, inv_res), coord_to_key(ez, inv_res))
            key = pack(okx, oky, okz)
            if key != end_key:
                length, sx, sy, sz, tx, ty, tz, gx, gy, gz = _walk_start(ox, oy, oz, ex, ey, ez, okx, oky, okz, res)
                dk = (pack(sx, 0, 0), pack(0, sy, 0), pack(0, 0, sz))  # a step per axis, packed
                while True:
                    if not count_only:
                        keys[m] = key
                        is_hit[m] = False
                    m += 1
                    axis, tx, ty, tz = raywalk.step(tx, ty, tz, gx, gy, gz)
                    key += dk[axis]
                    if key == end_key or min(tx, ty, tz) > length:
                        break
            if with_end[r]:
                if not count_only:
                    keys[m] = end_key
                    is_hit[m] = True
                m += 1
        total = m
    return keys, is_hit


# ---------------------------------------------------------------------------- marking

#: The dense cube marked around the sensor: CUBE³ voxels (a multiple of 8) that hold the
#: sensor's voxel; voxel ``x + CUBE·y + CUBE²·z`` is a byte of the free cube (a plain store marks
#: it, so marks of one voxel or one word never wait for each other) and a bit of the hit cube
#: (int64 words). Near the sensor every voxel is crossed by many rays; there a step marks at an
#: index that moves with it, with no block to look up.
CUBE = 128
_CUBE_WORDS = CUBE ** 3 // 64
#: Bits of ``key − corner`` (packed keys) that are set when the voxel lies outside the cube.
_OUTSIDE = ~pack.py_func(CUBE - 1, CUBE - 1, CUBE - 1)


@kernel
def new_cube():
    """Dense hit bits and free bytes of a cube (zeroed), and the box its marks lie in (int64
    (2, 3): least and greatest cube coordinates per axis; empty)."""
    box = np.empty((2, 3), np.int64)
    box[0] = CUBE
    box[1] = -1
    return np.zeros(_CUBE_WORDS, np.int64), np.zeros(CUBE ** 3, np.uint8), box


#: Rays sampled (evenly over the scan) to place the cube, and points taken along each.
PLACE_RAYS = 256
_PLACE_POINTS = 4
#: Placements of the cube along one axis that keep a given voxel inside: 16, one per block.
_PLACES = CUBE // 8


@kernel
def cube_corner(origin, ends, res, shift):
    """Packed key of the corner of the cube for the rays from ``origin`` to ``ends``, or −1
    where no cube around the sensor's voxel fits the key range. The cube is block-aligned and
    holds the sensor's voxel; of the 16 such placements per axis it takes those that hold the
    most of the rays' steps, estimated from a sample: a walk's steps are spread evenly over its
    length, so points evenly spread along a ray, weighted by its number of steps, stand for them.
    The axes are placed one at a time, the other two held, twice over, from the centred cube (a
    sensor at one side of its scan gets a cube shifted to that side). Keys local (``shift``)."""
    inv_res = 1.0 / res
    ok = np.empty(3, np.int64)
    for a in range(3):
        ok[a] = coord_to_key(origin[a], inv_res) - shift[a]
    lo = np.empty(3, np.int64)  # allowed shifts k: corner block = sensor's block − k
    hi = np.empty(3, np.int64)
    for a in range(3):
        b = ok[a] >> 3
        lo[a] = max(0, b + _PLACES - (MAX_KEY + 1) // 8)
        hi[a] = min(_PLACES - 1, b)
        if lo[a] > hi[a]:
            return -1
    n = ends.shape[0]
    step = max(1, n // PLACE_RAYS)
    m = (n + step - 1) // step * _PLACE_POINTS
    rel = np.empty((m, 3), np.int64)  # a point's block relative to the sensor's, per axis
    w = np.empty(m)
    j = 0
    for i in range(0, n, step):
        n_steps = 0
        for a in range(3):
            n_steps += abs(coord_to_key(ends[i, a], inv_res) - shift[a] - ok[a])
        for p in range(_PLACE_POINTS):
            f = (p + 0.5) / _PLACE_POINTS
            for a in range(3):
                c = np.float64(origin[a]) + f * (np.float64(ends[i, a]) - np.float64(origin[a]))
                rel[j, a] = ((coord_to_key(c, inv_res) - shift[a]) >> 3) - (ok[a] >> 3)
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
    return pack(cx, cy, cz)


@kernel
def _cube_index(key, corner):
    """Index of the voxel with packed key ``key`` in the cube at ``corner``."""
    lx, ly, lz = unpack(key - corner)
    return lx + ly * CUBE + lz * (CUBE * CUBE)


@kernel
def _cube_key(idx, corner):
    """Packed key of the voxel at index ``idx`` of the cube at ``corner`` (:func:`_cube_index`
    undone)."""
    return corner + pack(idx % CUBE, idx // CUBE % CUBE, idx // (CUBE * CUBE))


#: A ray is walked in slabs (:func:`_cube_slabs`) when its two other axes cross voxel borders
#: at least this much more sparsely than its major axis: then, in floating point too, each of them
#: steps at most once between two steps of the major axis.
_SLAB_MARGIN = 1.0 + 1e-9


@kernel
def _cube_slabs(frees, idx, n, tM, tA, tB, gM, gA, gB, dM, dA, dB, tie_a, tie_b):
    """``n`` slabs of OctoMap's DDA in the free cube, from a voxel the walk has just entered along
    its major axis M, or the sensor's voxel where each minor axis crosses a border at most once
    before M does (``t``, ``g``, index step ``d`` per axis; minor axes A and B). In a slab the
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


@inline_kernel
def _room(local, step):
    """Steps of one voxel in direction ``step`` that keep cube coordinate ``local`` in the cube
    (unlimited for an axis that does not move)."""
    return CUBE if step == 0 else (CUBE - 1 - local if step > 0 else local)


@inline_kernel
def _slab_count(key, corner, end_key, major, sx, sy, sz, tx, ty, tz, gx, gy, gz, length):
    """How many slabs (:func:`_cube_slabs`) a walk at the start of a slab (just past a major-axis
    step, or in the sensor's voxel) can take without checks: every voxel of them, and the one
    after, stays in the cube (:func:`_slabs_in_room`); every voxel of them lies short of the end
    voxel's major coordinate (so none is the end voxel) and before the major axis's crossing at
    the start of the last slab, which lies within ``length`` (so the walk's range test cannot stop
    them). The voxel after them may be the end voxel or beyond the range: the walk tests it as it
    tests a step's. (Selects, no branch: it runs in :func:`mark_scan`'s vectorised loop too.)"""
    lx, ly, lz = unpack(key - corner)
    t = tx if major == 0 else (ty if major == 1 else tz)
    per_g = 1.0 / (gx if major == 0 else (gy if major == 1 else gz))  # (one division, not four)
    n = min(_slabs_in_room(_room(lx, sx), tx, gx, t, per_g, major == 0),
            _slabs_in_room(_room(ly, sy), ty, gy, t, per_g, major == 1),
            _slabs_in_room(_room(lz, sz), tz, gz, t, per_g, major == 2),
            np.float64(abs(field(end_key, major) - field(key, major))), _slabs_before(length, t, per_g))
    return np.int64(n) if t < length else 0


#: Slabs given up to rounding: of the sums of ``t`` (the walk's, against the products that bound
#: them) and of the bounds' own arithmetic, a few ulps a step, far below this.
_ROUNDING = 1e-6


@inline_kernel
def _slabs_before(bound, t, per_g):
    """Slabs (a float) whose major-axis crossings at their ends, ``t``, ``t + g``, …, all lie
    below ``bound``, by :data:`_ROUNDING` of a slab at least (``per_g`` = 1 / g)."""
    return (bound - t) * per_g + 1.0 - _ROUNDING


@inline_kernel
def _slabs_in_room(room, ta, ga, t, per_g, is_major):
    """Slabs that keep an axis with ``room`` steps left in the cube (:func:`_room`), as a float:
    the major axis steps once a slab; a minor axis, whose borders lie at ``ta``, ``ta + ga``, …,
    steps at most once a slab, when its next border comes first: at most ``room`` times while the
    slabs' major-axis crossings lie before ``ta + room·ga`` (infinite for an axis that does not
    move)."""
    return np.float64(room) if is_major else _slabs_before(ta + room * ga, t, per_g)


@inline_kernel
def _slab_plan(key, corner, end_key, sx, sy, sz, tx, ty, tz, gx, gy, gz, length):
    """How a ray from the sensor's voxel ``key`` takes the cube in slabs (:func:`_cube_slabs`):
    ``(major, n, later)``, its major axis (the one whose borders lie closest together), the slabs
    it takes from the sensor's voxel on (0: none), and whether it takes them from its first
    major-axis step on instead (a minor axis crosses twice before the major axis first does).
    Slabs need the minor axes' borders sparser than the major's by :data:`_SLAB_MARGIN`."""
    major = 0 if gx <= min(gy, gz) else (1 if gy <= gz else 2)
    slabs = min(max(gx, gy), max(gy, gz), max(gx, gz)) >= min(gx, gy, gz) * _SLAB_MARGIN
    t = tx if major == 0 else (ty if major == 1 else tz)
    once = ((major == 0) | (tx + gx > t)) & ((major == 1) | (ty + gy > t)) & ((major == 2) | (tz + gz > t))
    n = _slab_count(key, corner, end_key, major, sx, sy, sz, tx, ty, tz, gx, gy, gz, length)
    return major, max(n, 0) if slabs & once else 0, slabs & (not once)


@inline_kernel
def _widen(lo, hi, idx):
    """Widen the box ``lo``..``hi`` (cube coordinates per axis) to hold cube index ``idx``."""
    x, y, z = idx % CUBE, idx // CUBE % CUBE, idx // (CUBE * CUBE)
    lo[0], lo[1], lo[2] = min(lo[0], x), min(lo[1], y), min(lo[2], z)
    hi[0], hi[1], hi[2] = max(hi[0], x), max(hi[1], y), max(hi[2], z)


#: Rays whose walk states :func:`mark_scan` computes in one vectorised loop.
_RUN = 256


@kernel
def mark_scan(origin, ends, hit, res, shift, rays, start, stop, table, slots, codes, hits, frees, count,
              cube_hits, cube_frees, cube_box, corner):
    """Set the hit bit of each in-range end voxel and the free bits of every ray's voxels, for rays
    ``start..stop-1`` (only the hits when ``rays`` is false). Returns ``stop``, or the ray at which
    the block storage filled up (marking is idempotent, so the caller grows it and resumes there).
    Within a block, bit ``lx + 8·ly + 64·lz`` stands for the voxel at local coordinates
    (lx, ly, lz). Voxels in the cube at ``corner`` (from :func:`cube_corner`; −1: none) are
    marked in ``cube_hits`` and ``cube_frees`` instead (see :func:`cube_blocks`), ``cube_box``
    widened to hold them: a walk moves each key one way, so the box of the sensor's voxel and the
    rays' ends, clamped to the cube, holds all they mark there (widened a run of rays at a time,
    in the loop that computes their walk states, not a ray at a time). Keys are local: OctoMap's
    less ``shift``."""
    inv_res = 1.0 / res
    ox, oy, oz = origin[0], origin[1], origin[2]
    okx = coord_to_key(ox, inv_res)  # (the walk starts from the unshifted key)
    oky = coord_to_key(oy, inv_res)
    okz = coord_to_key(oz, inv_res)
    origin_key = pack(okx - shift[0], oky - shift[1], okz - shift[2])
    last_code = 0  # the block accessor's cache: the last block's code and index
    last = -1
    # the rays' end keys and walk states, a run of rays at a time, in a loop of its own over
    # coordinates laid out per axis: the compiler vectorises it (a ray's nine divisions then cost
    # about a fifth as much); the walks read them
    e = np.empty((3, _RUN), np.float32)
    ints = np.empty((7, _RUN), np.int64)  # end key, sx, sy, sz, major axis, slabs from the sensor, later
    floats = np.empty((7, _RUN))  # length, tx, ty, tz, gx, gy, gz
    s0, s1, s2 = shift[0], shift[1], shift[2]
    lo = np.empty(3, np.int64)  # the cube box, kept here and written back on return
    hi = np.empty(3, np.int64)
    lo[:] = cube_box[0]
    hi[:] = cube_box[1]
    cx, cy, cz = unpack(corner)
    if corner >= 0:
        _widen(lo, hi, _cube_index(origin_key, corner))
    for i in range(start, stop):
        r = (i - start) % _RUN
        if r == 0:
            m = min(_RUN, stop - i)
            for j in range(m):
                e[0, j], e[1, j], e[2, j] = ends[i + j, 0], ends[i + j, 1], ends[i + j, 2]
            # the box of the cube's marks: the sensor's voxel and the ends, clamped to the cube
            # (a walk moves each key one way)
            b0, b1, b2, b3, b4, b5 = CUBE, CUBE, CUBE, -1, -1, -1
            for j in range(m):
                ex, ey, ez = e[0, j], e[1, j], e[2, j]
                kx, ky, kz = coord_to_key(ex, inv_res) - s0, coord_to_key(ey, inv_res) - s1, coord_to_key(ez, inv_res) - s2
                ek = pack(kx, ky, kz)
                x, y, z = min(max(kx - cx, 0), CUBE - 1), min(max(ky - cy, 0), CUBE - 1), min(max(kz - cz, 0), CUBE - 1)
                b0, b1, b2, b3, b4, b5 = min(b0, x), min(b1, y), min(b2, z), max(b3, x), max(b4, y), max(b5, z)
                length, sx, sy, sz, tx, ty, tz, gx, gy, gz = _walk_start(ox, oy, oz, ex, ey, ez, okx, oky, okz, res)
                ints[0, j], ints[1, j], ints[2, j], ints[3, j] = ek, sx, sy, sz
                floats[0, j], floats[1, j], floats[2, j], floats[3, j] = length, tx, ty, tz
                floats[4, j], floats[5, j], floats[6, j] = gx, gy, gz
                ints[4, j], ints[5, j], ints[6, j] = _slab_plan(origin_key, corner, ek, sx, sy, sz, tx, ty, tz,
                                                                gx, gy, gz, length)
            if corner >= 0:
                lo[0], lo[1], lo[2] = min(lo[0], b0), min(lo[1], b1), min(lo[2], b2)
                hi[0], hi[1], hi[2] = max(hi[0], b3), max(hi[1], b4), max(hi[2], b5)
        end_key = ints[0, r]
        ray = rays and end_key != origin_key
        if ray:
            length, sx, sy, sz = floats[0, r], ints[1, r], ints[2, r], ints[3, r]
            tx, ty, tz, gx, gy, gz = floats[1, r], floats[2, r], floats[3, r], floats[4, r], floats[5, r], floats[6, r]
            key = origin_key
            done = False
        else:
            key = end_key
            sx = sy = sz = 1
            done = True
        dk = (pack(sx, 0, 0), pack(0, sy, 0), pack(0, 0, sz))  # a step per axis, packed
        if ray and corner >= 0:
            # the cube phase (the sensor's voxel lies in the cube): the walk's key and the cube
            # index move together, no block to look up; in slabs where the ray allows
            # (_slab_plan), from the sensor's voxel (nearly always) or from the first step along
            # the major axis on
            idx = _cube_index(key, corner)
            di = (sx, sy * CUBE, sz * CUBE * CUBE)
            major, n, later = ints[4, r], ints[5, r], ints[6, r] != 0
            while True:
                if n > 0:
                    if major == 0:
                        idx, tx, ty, tz = _cube_slabs(cube_frees, idx, n, tx, ty, tz, gx, gy, gz, sx, di[1], di[2],
                                                      True, True)
                    elif major == 1:
                        idx, ty, tx, tz = _cube_slabs(cube_frees, idx, n, ty, tx, tz, gy, gx, gz, di[1], sx, di[2],
                                                      False, True)
                    else:
                        idx, tz, tx, ty = _cube_slabs(cube_frees, idx, n, tz, tx, ty, gz, gx, gy, di[2], sx, di[1],
                                                      False, False)
                    key = _cube_key(idx, corner)
                    n = 0
                    axis = major  # (the slabs' last step)
                    if key == end_key or min(tx, ty, tz) > length:
                        key = end_key
                        done = True
                        break
                cube_frees[np.uint64(idx)] = 1  # (unsigned: no wrap-around test)
                axis, tx, ty, tz = raywalk.step(tx, ty, tz, gx, gy, gz)
                key += dk[axis]
                idx += di[axis]
                if key == end_key or min(tx, ty, tz) > length:
                    key = end_key  # (the range test may stop the walk short of it)
                    done = True
                    break
                if (key - corner) & _OUTSIDE:
                    break
                if later and axis == major:
                    later = False
                    n = _slab_count(key, corner, end_key, major, sx, sy, sz, tx, ty, tz, gx, gy, gz, length)
        is_hit = done  # the end voxel comes last, after the ray's free voxels
        if is_hit and hit[i] and corner >= 0 and not ((end_key - corner) & _OUTSIDE):
            j = _cube_index(end_key, corner)
            cube_hits[j >> 6] |= np.int64(1) << (j & 63)
            continue
        # the block phase: local coordinates on entering a block, per axis
        wx, wy, wz = 0 if sx > 0 else 7, 0 if sy > 0 else 7, 0 if sz > 0 else 7
        dkx, dky, dkz = dk
        lookup = True
        while True:
            if is_hit and not hit[i]:
                break
            if lookup:  # the voxel may lie in another block
                code = block_code(key)
                if code != last_code:  # the block accessor (see occmap.octree.blocks): find or add
                    mask = table.shape[0] - 1
                    h = home(code, mask)
                    while table[h] != 0 and table[h] != code:
                        h = (h + 1) & mask
                    if table[h] == 0:
                        if count[0] == codes.shape[0]:
                            cube_box[0] = lo
                            cube_box[1] = hi
                            return i
                        table[h] = code
                        slots[h] = count[0]
                        codes[count[0]] = code
                        count[0] += 1
                    last = slots[h]
                    last_code = code
                lookup = False
            m = in_block(key)
            if is_hit:
                hits[last, m >> 6] |= np.int64(1) << (m & 63)
                break
            frees[np.uint64(last), np.uint64(m >> 6)] |= np.int64(1) << (m & 63)
            # (branches on the axis, not a tuple indexed by it: a few times faster here)
            axis, tx, ty, tz = raywalk.step(tx, ty, tz, gx, gy, gz)
            if axis == 0:
                key += dkx
                lookup = (field(key, 0) & 7) == wx  # entered another block
            elif axis == 1:
                key += dky
                lookup = (field(key, 1) & 7) == wy
            else:
                key += dkz
                lookup = (field(key, 2) & 7) == wz
            if key == end_key or min(tx, ty, tz) > length:
                key = end_key
                is_hit = True
                lookup = True
    cube_box[0] = lo
    cube_box[1] = hi
    return stop


#: Multiplier that gathers the low bits of a word's eight bytes into its top byte's bits
#: 49..56 (byte i's bit lands on bit 49 + i, no two products overlap, so nothing carries).
_GATHER = 0x0002040810204081


@kernel
def cube_blocks(cube_hits, cube_frees, cube_box, corner):
    """The cube's marked voxels as blocks: codes, hit masks, free masks (the blocks that have any;
    :func:`merge_blocks` ors them with the same blocks marked elsewhere); only the blocks within
    ``cube_box`` are read. Leaves the cube zeroed and its box empty, as :func:`new_cube` makes
    them, for the next scan."""
    nb = CUBE // 8
    w_row = CUBE // 64  # words of hit bits per row of the cube
    free_rows = cube_frees.view(np.uint64)  # eight voxels' free bytes per word
    codes = np.empty(nb ** 3, np.int64)
    hits = np.empty((nb ** 3, 8), np.int64)
    frees = np.empty((nb ** 3, 8), np.int64)
    n = 0
    for bz in range(cube_box[0, 2] >> 3, (cube_box[1, 2] >> 3) + 1):
        for by in range(cube_box[0, 1] >> 3, (cube_box[1, 1] >> 3) + 1):
            for bx in range(cube_box[0, 0] >> 3, (cube_box[1, 0] >> 3) + 1):
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
                        r = row0 + (lz * CUBE + ly) * (CUBE // 8)
                        f = free_rows[r]
                        if f != 0:
                            free_rows[r] = 0
                        fw |= np.int64(((f * np.uint64(_GATHER)) >> np.uint64(49)) & np.uint64(0xFF)) << (8 * ly)
                    hits[n, lz] = hw
                    frees[n, lz] = fw
                    any_bits |= hw | fw
                if any_bits != 0:
                    codes[n] = block_code(corner + pack(bx * 8, by * 8, bz * 8))
                    n += 1
    cube_hits[:] = 0
    cube_box[0] = CUBE
    cube_box[1] = -1
    return codes[:n], hits[:n], frees[:n]


# ---------------------------------------------------------------------------- applying

