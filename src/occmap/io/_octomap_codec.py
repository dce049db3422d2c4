"""Numba kernels that encode and decode the octree's node pool as OctoMap's file bodies.

Both formats list the nodes depth first, children in order 0..7 (pre-order), starting at the root:

- ``.bt`` (binary, maximum likelihood): per *inner* node 2 bytes, byte 1 for children 0–3 and
  byte 2 for children 4–7, two bits per child at bits 2i and 2i+1 (i = child index mod 4):
  ``00`` absent, ``01`` (low bit set) free leaf, ``10`` (high bit) occupied leaf, ``11`` inner
  node — whose own two bytes follow, after those of the inner children before it. Leaves carry no
  other data: a reader gives free leaves the lower clamping bound, occupied ones the upper.
- ``.ot`` (full values): per node 5 bytes, the float32 log-odds (little-endian) and a byte with
  bit i set when child i exists.

The kernels take and return plain arrays (the slot layout of :class:`occmap.octree.Nodes`); the
headers and the error messages are :mod:`.octomap`'s business. Decoders return an error code and the byte offset
where the data stopped making sense instead of raising; allocation is bounded by the number of
bytes present, and every step consumes bytes or finishes a node, so no input can make them hang.
"""

from __future__ import annotations

import numpy as np

from .._jit import inline_kernel, kernel
from ..octree.keys import DEPTH
from ..octree.pool import SLOT

# Error codes of the decoders (octomap.py turns them into messages).
OK = 0
TRUNCATED = 1  # the data ends inside a node
TOO_DEEP = 2  # a node below depth 16
LEFTOVER = 3  # bytes after the last node
EMPTY_INNER = 4  # .bt: a node marked inner (11) has no children
NAN_VALUE = 5  # .ot: a node's log-odds is NaN

_PENDING = -2  # the child of a node whose record has not been read yet

# Bit tables indexed by a child mask (bit i = child i).
_CTZ = np.array([0] + [(m & -m).bit_length() - 1 for m in range(1, 256)], np.int64)  # lowest child
_SPREAD = np.array([sum(((m >> i) & 1) << (2 * i) for i in range(8)) for m in range(256)], np.int64)  # bit i → 2i
_POPCOUNT = np.array([bin(m).count("1") for m in range(256)], np.int64)
_FLT_MAX = 3.4028234663852886e38


@inline_kernel
def _take_lowest(rem, sp):
    """The lowest child index in the mask ``rem[sp]``, taken out of it."""
    r = rem[sp]
    rem[sp] = r & (r - 1)
    return _CTZ[r]


@inline_kernel
def _next_in_preorder(blk, rem, sp):
    """The step of every pre-order walk here: up from level ``sp`` past the levels whose children
    are all taken, then the lowest child left at the deepest other level. ``blk[l]`` is the first
    slot of level l's child block, ``rem[l]`` the mask of its children not yet taken. Returns
    ``(level, slot)`` of that child; level −1 when the walk is over."""
    while sp >= 0 and rem[sp] == 0:
        sp -= 1
    if sp < 0:
        return sp, 0
    return sp, blk[sp] + _take_lowest(rem, sp)


@kernel
def _block_masks(slots, top, occ):
    """Per block of 8 slots (index ``slot >> 3``): which children exist, which are inner nodes and
    which are leaves with log-odds ≥ ``occ``, as 8-bit masks; and every slot's ``child`` in an
    array of its own; one linear pass over the pool. (The walks that follow read only the
    children: from the slots, whose blocks are a cache line each, a walk over fr_079.bt's took
    three times as long as from this array, half the bytes.)"""
    nb = top >> 3
    ex = np.zeros(nb, np.int64)
    inner = np.zeros(nb, np.int64)
    occupied = np.zeros(nb, np.int64)
    child = np.empty(top, np.int32)
    child[:8] = -1  # block 0 holds only the root
    child[0] = slots[0].child
    for b in range(1, nb):
        e = 0
        n = 0
        o = 0
        for i in range(8):
            s = 8 * b + i
            v = slots[s].value
            c = slots[s].child
            child[s] = c
            e |= np.int64(v == v) << i  # False for NaN: no node
            n |= np.int64(c >= 0) << i
            o |= np.int64(v >= occ) << i
        ex[b] = e
        inner[b] = n & e  # a freed block's first slot links the free list: not a child
        occupied[b] = o & ~n
    return ex, inner, occupied, child


# ------------------------------------------------------------------------------ .bt


@kernel
def encode_bt(slots, top, occ, lo, hi):
    """The body of OctoMap's ``writeBinary`` for this tree, without changing the tree.

    OctoMap first converts every node to maximum likelihood (``hi`` when its log-odds ≥ ``occ``,
    else ``lo``) and calls ``prune()``, which collapses the nodes at depth 15, then 14, ... down to
    1 (never the root) whose eight children are leaves of one value — and stops at the first depth
    where nothing collapsed. Pass 1 (post-order) finds what a complete bottom-up prune collapses
    and counts it per depth; the first depth from 15 upward with no collapse is where OctoMap stops,
    so only collapses below it count. Pass 2 (pre-order) writes the bytes.

    Returns ``(data, nodes)``: the body as uint8 and the node count of the tree as written (−1 if
    the pool holds a node below depth 16).
    """
    if top <= 0 or np.isnan(slots[0].value):
        return np.empty(0, np.uint8), 0
    if slots[0].child < 0:  # the root alone: no children, two zero bytes
        return np.zeros(2, np.uint8), 1
    # the leaf code OctoMap writes for each class after conversion (it tests the converted value
    # against the threshold again): 1 = free, 2 = occupied
    code_free = 2 if lo >= occ else 1
    code_occ = 2 if hi >= occ else 1
    ex, inner, occupied, child = _block_masks(slots, top, occ)
    nb = top >> 3
    # per block: which children a complete prune collapses, and which of those are occupied
    col = np.zeros(nb, np.int64)
    col_occ = np.zeros(nb, np.int64)
    count = np.zeros(DEPTH + 1, np.int64)
    blk = np.empty(DEPTH + 1, np.int64)
    rem = np.empty(DEPTH + 1, np.int64)
    acc = np.empty(DEPTH + 1, np.int64)
    acc_occ = np.empty(DEPTH + 1, np.int64)
    pos = np.empty(DEPTH + 1, np.int64)
    n_inner = 1
    sp = 0
    blk[0] = child[0]
    rem[0] = inner[child[0] >> 3]
    acc[0] = 0
    acc_occ[0] = 0
    while sp >= 0:
        if rem[sp] != 0:  # descend into the next inner child
            i = _take_lowest(rem, sp)
            if sp + 1 >= DEPTH:  # a node with children at depth 16: not a valid pool
                return np.empty(0, np.uint8), -1
            c = child[blk[sp] + i]
            sp += 1
            blk[sp] = c
            rem[sp] = inner[c >> 3]
            acc[sp] = 0
            acc_occ[sp] = 0
            pos[sp] = i
            n_inner += 1
            continue
        b = blk[sp] >> 3
        col[b] = acc[sp]
        col_occ[b] = acc_occ[sp]
        if sp >= 1 and sp <= DEPTH - 1 and ex[b] == 255 and (inner[b] & ~acc[sp]) == 0:
            o = occupied[b] | acc_occ[sp]
            if o == 0 or o == 255:  # eight leaves of one class: collapsible
                count[sp] += 1
                acc[sp - 1] |= 1 << pos[sp]
                if o == 255:
                    acc_occ[sp - 1] |= 1 << pos[sp]
        sp -= 1
    stop = 0
    for d in range(DEPTH - 1, 0, -1):
        if count[d] == 0:
            stop = d
            break
    # pass 2: pre-order, two bytes per inner node of the pruned tree
    out = np.empty(2 * n_inner, np.uint8)
    p = 0
    n_nodes = 1
    sp = 0
    blk[0] = child[0]
    while True:
        # emit the node whose child block is blk[sp] (its children lie at depth sp + 1)
        b = blk[sp] >> 3
        eff = col[b] if sp + 1 > stop else 0
        inn = inner[b] & ~eff
        occ_leaf = occupied[b] | (col_occ[b] & eff)
        free_leaf = ex[b] & ~inn & ~occ_leaf
        bits = _SPREAD[free_leaf] * code_free | _SPREAD[occ_leaf] * code_occ | _SPREAD[inn] * 3
        out[p] = bits & 0xFF
        out[p + 1] = bits >> 8
        p += 2
        n_nodes += _POPCOUNT[ex[b]]
        rem[sp] = inn
        sp, k = _next_in_preorder(blk, rem, sp)
        if sp < 0:
            break
        sp += 1
        blk[sp] = child[k]
    return out[:p], n_nodes


@kernel
def decode_bt(data, start, lo, hi):
    """Decode the body of a ``.bt`` file, ``data[start:]``, as OctoMap's ``readBinaryNode`` does:
    free leaves get ``lo``, occupied leaves ``hi``, inner nodes the maximum of their children (the
    root too, where OctoMap leaves it at ``hi``); a root without children gets ``hi``, as in
    OctoMap.

    Returns ``(slots, top, nodes, error, offset)``; ``error`` is one of the module's codes
    and ``offset`` the byte where decoding stopped (the slots are then meaningless).
    """
    n = data.shape[0]
    cap = 8 + 8 * (max(n - start, 0) // 2)  # one block per two bytes: bounded by the file's size
    slots = np.empty(cap, SLOT)
    for s in range(8):
        slots[s].value = np.nan
        slots[s].child = -1
    slots[0].value = hi
    val = np.empty(4, np.float32)  # value by 2-bit code; inner nodes get theirs when done
    val[0] = np.nan
    val[1] = lo
    val[2] = hi
    val[3] = lo
    top = 8
    n_nodes = 1
    p = start
    slot = np.empty(DEPTH + 1, np.int64)
    blk = np.empty(DEPTH + 1, np.int64)
    rem = np.empty(DEPTH + 1, np.int64)
    any_hi = np.empty(DEPTH + 1, np.bool_)
    sp = 0
    slot[0] = 0
    while True:
        # read the two bytes of node slot[sp] (depth sp) and create its children
        if p + 2 > n:
            return slots, top, n_nodes, TRUNCATED, p
        bits = np.int64(data[p]) | (np.int64(data[p + 1]) << 8)
        if bits == 0:
            if sp == 0:  # a tree of one node
                p += 2
                break
            return slots, top, n_nodes, EMPTY_INNER, p
        c = top
        top += 8
        slots[slot[sp]].child = c
        inn = 0
        has_hi = False
        for i in range(8):
            code = (bits >> (2 * i)) & 3
            slots[c + i].value = val[code]
            slots[c + i].child = -1
            n_nodes += code != 0
            inn |= np.int64(code == 3) << i
            has_hi |= code == 2
        if inn != 0 and sp + 1 >= DEPTH:
            return slots, top, n_nodes, TOO_DEEP, p
        p += 2
        blk[sp] = c
        rem[sp] = inn
        any_hi[sp] = has_hi
        # finish nodes whose inner children are all read; then go to the next unread one
        while sp >= 0 and rem[sp] == 0:
            h = any_hi[sp]
            slots[slot[sp]].value = hi if h else lo  # max of the children (each lo or hi)
            sp -= 1
            if sp >= 0:
                any_hi[sp] |= h
        sp, k = _next_in_preorder(blk, rem, sp)
        if sp < 0:
            break
        sp += 1
        slot[sp] = k
    if p != n:
        return slots, top, n_nodes, LEFTOVER, p
    return slots, top, n_nodes, OK, p


# ------------------------------------------------------------------------------ .ot


@kernel
def encode_ot(slots, bits, top):
    """The body of OctoMap's ``write`` (``.ot``): per node in pre-order its float32 log-odds
    (``bits``: the slots viewed as uint32, a slot's value at ``2 · slot``, written little-endian)
    and its child mask.
    Returns ``(data, nodes)``; nodes is −1 if the pool is inconsistent."""
    if top <= 0 or np.isnan(slots[0].value):
        return np.empty(0, np.uint8), 0
    ex, inner, occupied, child = _block_masks(slots, top, slots[0].value)  # (occupancy unused here)
    n = 1
    for b in range(1, top >> 3):
        n += _POPCOUNT[ex[b]]
    out = np.empty(5 * n, np.uint8)
    blk = np.empty(DEPTH + 1, np.int64)
    rem = np.empty(DEPTH + 1, np.int64)
    sp = -1
    node = 0
    p = 0
    while True:
        # write node's record; descend into its children if it has any
        if p + 5 > out.shape[0]:
            return out[:0], -1
        w = bits[2 * node]
        out[p] = w & 0xFF
        out[p + 1] = (w >> 8) & 0xFF
        out[p + 2] = (w >> 16) & 0xFF
        out[p + 3] = w >> 24
        c = child[node]
        mask = 0
        if c >= 0:
            mask = ex[c >> 3]
        out[p + 4] = mask
        p += 5
        if mask != 0:
            if sp + 1 >= DEPTH:
                return out[:0], -1
            sp += 1
            blk[sp] = c
            rem[sp] = mask
        sp, node = _next_in_preorder(blk, rem, sp)
        if sp < 0:
            break
    return out[:p], p // 5


@kernel
def decode_ot(values, masks, start, n_bytes):
    """Decode the records of a ``.ot`` body: ``values`` (float32) and ``masks`` (uint8) of the
    ``len(masks)`` complete 5-byte records from byte ``start``; ``n_bytes`` is the whole file's
    length (a partial record at the end is left over). Values are kept as read, as OctoMap's
    ``readData`` does. Returns ``(slots, top, nodes, error, offset)``."""
    n_rec = masks.shape[0]
    n_blocks = 0
    for r in range(n_rec):
        n_blocks += masks[r] != 0
    cap = 8 + 8 * n_blocks  # bounded by the records present
    slots = np.empty(cap, SLOT)
    for s in range(8):
        slots[s].value = np.nan
        slots[s].child = -1
    top = 8
    r = 0
    blk = np.empty(DEPTH + 1, np.int64)
    rem = np.empty(DEPTH + 1, np.int64)
    sp = -1
    node = 0
    while True:
        # node's record is the next one
        if r >= n_rec:
            return slots, top, r, TRUNCATED, start + 5 * r
        v = values[r]
        if np.isnan(v):
            return slots, top, r, NAN_VALUE, start + 5 * r
        slots[node].value = v
        mask = np.int64(masks[r])
        if mask != 0:
            if sp + 1 >= DEPTH:
                return slots, top, r, TOO_DEEP, start + 5 * r
            c = top
            top += 8
            slots[node].child = c
            for i in range(8):
                slots[c + i].value = np.nan
                slots[c + i].child = -1
            sp += 1
            blk[sp] = c
            rem[sp] = mask
        else:
            slots[node].child = -1
        r += 1
        sp, node = _next_in_preorder(blk, rem, sp)
        if sp < 0:
            break
    if start + 5 * r != n_bytes:
        return slots, top, r, LEFTOVER, start + 5 * r
    return slots, top, r, OK, start + 5 * r
