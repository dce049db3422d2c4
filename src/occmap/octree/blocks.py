"""A scan's marked voxels as blocks of bits (Bonxai's ``VoxelGrid`` layout): storage and its hash
(the accessor's lookups), merging, and listing the voxels in Morton order.

A *block* is the 8×8×8 voxels of one depth-13 node, known by its code (:func:`.keys.block_code`);
it holds two 512-bit masks, hits and frees (int64 words; bit ``lx + 8·ly + 64·lz`` = the voxel at
local coordinates (lx, ly, lz), :func:`.keys.in_block`). *Block storage* is the tuple
``(table, slots, codes, hits, frees, count)``: an open-addressing hash from code to block index
(``table`` holds codes, 0 = empty, ``slots`` the indices; at least twice as many entries as
blocks), the blocks' codes and masks in the order they were added, and their number
``count[0]``.

Lookups probe linearly from :func:`home`. The one walk that looks blocks up,
:func:`.marking.mark_scan`, does it through the *block accessor* (Bonxai's
``VoxelGrid::Accessor``): a ray's voxels lie mostly in the block of the voxel before, so it keeps
the last block's code and index and probes only when the code changes; a voxel in the same block
costs an array index, not a hash lookup. The accessor is written inside that walk's loop: as a
Numba function taking the storage's arrays (inlined or not) it made the walk twice as slow.
"""

from __future__ import annotations

import numpy as np

from .._intrinsics import bit_length, popcount, prefetch, trailing_zeros
from .._jit import inline_kernel, kernel
from .keys import block_key, morton, pack, unpack

_FIBONACCI = 0x9E3779B97F4A7C15  # 2^64 / golden ratio


@kernel
def new_blocks(capacity):
    """Empty block storage with room for ``capacity`` blocks."""
    size = 16
    while size < 2 * capacity:
        size *= 2
    return (np.zeros(size, np.int64), np.zeros(size, np.int64), np.zeros(capacity, np.int64),
            np.zeros((capacity, 8), np.int64), np.zeros((capacity, 8), np.int64), np.zeros(1, np.int64))


@kernel
def empty_blocks(table, slots, codes, hits, frees, count):
    """Block storage emptied for reuse, as :func:`new_blocks` leaves it: the table and the masks
    of the blocks it held zeroed (the codes and slots are read only where the table holds one)."""
    n = count[0]
    table[:] = 0
    hits[:n] = 0
    frees[:n] = 0
    count[0] = 0


@kernel
def home(code, mask):
    """Hash slot where a probe for ``code`` starts (Fibonacci hashing: the top bits of the product,
    which depend on every bit of the code)."""
    return np.int64((np.uint64(code) * np.uint64(_FIBONACCI)) >> np.uint64(64 - bit_length(mask)))


@kernel
def grow_blocks(table, slots, codes, hits, frees, count):
    """The block storage at twice the capacity, rehashed."""
    n = count[0]
    t2, s2, c2, h2, f2, n2 = new_blocks(2 * codes.shape[0])
    h2[:n] = hits[:n]
    f2[:n] = frees[:n]
    c2[:n] = codes[:n]
    n2[0] = n
    mask = t2.shape[0] - 1
    for b in range(n):  # (each code once: the first empty entry of its probe sequence)
        h = home(codes[b], mask)
        while t2[h] != 0:
            h = (h + 1) & mask
        t2[h] = codes[b]
        s2[h] = b
    return t2, s2, c2, h2, f2, n2


#: Bits below a block's Morton code in the keys :func:`morton_order` sorts (its index): its 39
#: bits (13 an axis) and these fill an int64 short of the sign.
_INDEX_BITS = 24


@kernel
def _morton_keys(codes, index_bits):
    """Per block, the Morton code of its block key, shifted up by ``index_bits`` with the block's
    index below."""
    n = codes.shape[0]
    keys = np.empty(n, np.int64)
    for b in range(n):
        kx, ky, kz = unpack(block_key(codes[b]))
        keys[b] = (morton(kx >> 3, ky >> 3, kz >> 3, 13) << index_bits) | b
    return keys


def morton_order(codes) -> np.ndarray:
    """Order of the blocks by the Morton code of their block keys (the octree's DFS order): one
    sort of the codes with the indices below them (NumPy's sort of int64 is vectorised: 38,000
    blocks in 0.5 ms, Numba's argsort of their codes 3.2 ms), or an argsort of the codes for
    more blocks than the index bits hold."""
    if len(codes) < 1 << _INDEX_BITS:
        return np.sort(_morton_keys(codes, _INDEX_BITS)) & ((1 << _INDEX_BITS) - 1)
    return np.argsort(_morton_keys(codes, 0))


def merge_blocks(codes, hits, frees):
    """Blocks of several markings concatenated → each block once, masks OR-ed, Morton-sorted."""
    return _merge_in_order(codes, hits, frees, morton_order(codes))


#: Blocks ahead whose masks :func:`_merge_in_order` asks the CPU for.
_AHEAD = 16


@kernel
def _merge_in_order(codes, hits, frees, order):
    """:func:`merge_blocks` of blocks in ``order``: runs of one code merged into one block."""
    n = codes.shape[0]
    c2 = np.empty(n, np.int64)
    h2 = np.empty((n, 8), np.int64)
    f2 = np.empty((n, 8), np.int64)
    m = -1
    for j in range(n):
        if j + _AHEAD < n:  # (the blocks lie in the order they were marked: a load from memory each)
            a = 8 * order[j + _AHEAD]
            prefetch(hits, a)
            prefetch(hits, a + 7)
            prefetch(frees, a)
            prefetch(frees, a + 7)
        b = order[j]
        if m < 0 or codes[b] != c2[m]:
            m += 1
            c2[m] = codes[b]
            for w in range(8):
                h2[m, w] = hits[b, w]
                f2[m, w] = frees[b, w]
        else:
            for w in range(8):
                h2[m, w] |= hits[b, w]
                f2[m, w] |= frees[b, w]
    return c2[:m + 1], h2[:m + 1], f2[:m + 1]


#: A block's voxels in Morton order: the ``z``-th lies ``_MORTON_OFFSET[z]`` (a packed key) from the
#: block's first voxel.
_MORTON_OFFSET = np.array([pack.py_func(i & 7, (i >> 3) & 7, i >> 6)
                           for i in np.argsort([morton.py_func(i & 7, (i >> 3) & 7, i >> 6, 3) for i in range(512)])],
                          np.int64)


def _bits(test) -> np.int64:
    """The int64 word whose bit ``p`` (0..63) is set where ``test(p)``."""
    return np.array(sum(1 << p for p in range(64) if test(p)), np.uint64).view(np.int64)[()]


#: Bits of a plane of a block (bit ``x + 8·y``, bits of its index x0 x1 x2 y0 y1 y2) that trade
#: places with the bit 6 above (index bits 1 and 3 swapped: x1 and y0).
_SWAP = _bits(lambda p: p & 2 and not p & 8)
#: The bits of a word whose index bits 2 and 5 are ``q & 1`` and ``q >> 1``.
_QUARTERS = np.array([_bits(lambda p, q=q: (p >> 2 & 1) == q & 1 and (p >> 5 & 1) == q >> 1) for q in range(4)],
                     np.int64)


@kernel
def morton_words(words, out):
    """A block's eight mask words (word ``lz``, bit ``lx + 8·ly``) re-laid in Morton order into
    ``out``: voxel ``m`` (:func:`.keys.morton` of lx, ly, lz over 3 bits) at bit ``m & 63`` of
    word ``m >> 6``. Per plane, without a loop over its bits: swapping index bits x1 and y0 (a
    delta swap) leaves x0 y0 . x1 y1 . at bits 0, 1, 3, 4 of the index, so each quarter of the
    plane (x2, y2) is its Morton bits at once, moved to word x2 + 2·y2 + 4·z2 with z0 and z1 at
    index bits 2 and 5 instead of x2 and y2."""
    out[:] = 0
    for z in range(8):
        w = words[z]
        t = (w ^ (w >> 6)) & _SWAP  # (bits 6 above those of _SWAP, none of them the sign)
        w ^= t ^ (t << 6)
        z01 = (z & 1) + 2 * ((z >> 1) & 1)
        for q in range(4):
            d = 4 * ((z01 & 1) - (q & 1)) + 32 * ((z01 >> 1) - (q >> 1))
            v = w & _QUARTERS[q]
            v = v << d if d >= 0 else v >> -d
            out[q + 4 * (z >> 2)] |= v & _QUARTERS[z01]


@kernel
def _inside(kbox, key, size):
    """Whether the cube of ``size`` voxels a side from packed key ``key`` lies in ``kbox``
    ((0, 3): everywhere)."""
    if kbox.shape[0] == 0:
        return True
    kx, ky, kz = unpack(key)
    return (kbox[0, 0] <= kx and kx + size - 1 <= kbox[1, 0] and kbox[0, 1] <= ky and ky + size - 1 <= kbox[1, 1]
            and kbox[0, 2] <= kz and kz + size - 1 <= kbox[1, 2])


@inline_kernel
def uniform(marked, hit, size):
    """Whether ``size`` (1, 8, 64) voxels' bits of ``marked`` are all set and their ``hit`` bits
    all alike (bits from 0; words of int64): a node's voxels, one update."""
    full = np.int64(-1) if size == 64 else (np.int64(1) << size) - 1
    return marked & full == full and (hit & full == 0 or hit & full == full)


@kernel
def uniform_block(marked, hit):
    """Whether a block's voxels (Morton words, :func:`block_marks`) are all marked and all alike."""
    whole = True
    for w in range(8):
        whole = whole and uniform(marked[w], hit[w], 64) and hit[w] == hit[0]
    return whole


@kernel
def marked_before(hits, frees):
    """Voxels marked in the blocks before each block, and in all of them (int64 (n + 1,))."""
    n = hits.shape[0]
    counts = np.zeros(n + 1, np.int64)
    for b in range(n):
        c = 0
        for w in range(8):
            c += popcount(hits[b, w] | frees[b, w])
        counts[b + 1] = counts[b] + c
    return counts


@kernel
def block_marks(hits, frees, base, kbox, marked, hit):
    """One block's masks (``hits``, ``frees``: its 8 words each) as the updates of its voxels:
    into ``marked`` and ``hit`` (8 words each) the voxels marked and those hit (a voxel both hit
    and crossed is a hit), in Morton order (:func:`morton_words`: word ``w`` holds the 64 voxels
    of the block's child ``w``, byte ``k`` of it the 8 of that child's child ``k``, bit ``j`` of
    the byte that node's child ``j``, as :func:`.keys.child_index` numbers children), only those
    within the key box ``kbox`` ((0, 3): everywhere) of the block whose first voxel has packed
    key ``base``. Returns whether any voxel is marked. Allocates nothing."""
    any_hit = np.int64(0)
    for w in range(8):
        hit[w] = hits[w] | frees[w]  # (hit holds the voxels marked, in the masks' order, for a moment)
        any_hit |= hits[w]
    morton_words(hit, marked)
    if any_hit != 0:  # (most blocks hold free voxels only)
        morton_words(hits, hit)
    else:
        hit[:] = 0
    if not _inside(kbox, base, 8):  # a block across the box's edge: its voxels one by one
        for m in range(512):
            if (marked[m >> 6] >> (m & 63)) & 1 and not _inside(kbox, base + _MORTON_OFFSET[m], 1):
                marked[m >> 6] &= ~(np.int64(1) << (m & 63))
                hit[m >> 6] &= ~(np.int64(1) << (m & 63))
    any_marked = np.int64(0)
    for w in range(8):
        any_marked |= marked[w]
    return any_marked != 0


@kernel
def block_voxels(codes, hits, frees, kbox, merge):
    """The marked voxels of Morton-sorted blocks as updates in Morton order: packed keys
    (:func:`.keys.pack`) of their first voxels, depths, and a flag for the hits (a voxel both hit
    and crossed is a hit); only voxels within the key box ``kbox`` (int64 (2, 3): min, max;
    (0, 3) for none). With ``merge``, a node of a block (depth 13, 14 or 15) whose voxels are all
    marked alike is one update at its depth (see :func:`.update.apply_voxels`), else each voxel is
    one at depth 16."""
    n = 0
    for b in range(codes.shape[0]):
        for w in range(8):
            n += popcount(hits[b, w] | frees[b, w])
    keys = np.empty(n, np.int64)
    depths = np.empty(n, np.int8)
    is_hit = np.empty(n, np.bool_)
    marked = np.empty(8, np.int64)
    hit = np.empty(8, np.int64)
    n = 0
    for b in range(codes.shape[0]):
        base = block_key(codes[b])
        if not block_marks(hits[b], frees[b], base, kbox, marked, hit):
            continue
        if merge and uniform_block(marked, hit):
            keys[n], depths[n], is_hit[n] = base, 13, hit[0] != 0
            n += 1
            continue
        for w in range(8):
            first = base + _MORTON_OFFSET[w << 6]
            if merge and uniform(marked[w], hit[w], 64):
                keys[n], depths[n], is_hit[n] = first, 14, hit[w] != 0
                n += 1
                continue
            for byte in range(8):
                shift = 8 * byte
                m, hm = marked[w] >> shift, hit[w] >> shift
                node = base + _MORTON_OFFSET[(w << 6) | shift]
                if merge and uniform(m, hm, 8):
                    keys[n], depths[n], is_hit[n] = node, 15, hm & 1 != 0
                    n += 1
                    continue
                word = m & 0xFF
                while word != 0:
                    bit = trailing_zeros(word)
                    word &= word - 1
                    keys[n], depths[n], is_hit[n] = base + _MORTON_OFFSET[(w << 6) | (shift + bit)], 16, (hm >> bit) & 1 != 0
                    n += 1
    return keys[:n], depths[:n], is_hit[:n]
