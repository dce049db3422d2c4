"""Joining tiles into one octree: each tile's subtree grafted into a node pool at its place, the
nodes above the tiles settled as OctoMap keeps them (maximum of the children, eight equal leaves
pruned), so the result is the tree one process would have built. Numba kernels on the slots of
:mod:`occmap.octree.pool`."""

from __future__ import annotations

import numpy as np

from .._jit import kernel
from ..octree.keys import DEPTH, child_index
from ..octree.pool import SIZE, alloc_block, new_meta, new_slots


@kernel
def subtree_slots(slots, node):
    """Slots the subtree under ``node`` takes (its blocks of eight, and one for the node)."""
    n = 1
    stack = np.empty(8 * DEPTH + 8, np.int64)
    sp = 0
    if slots[node].child >= 0:
        stack[0] = slots[node].child
        sp = 1
    while sp > 0:
        sp -= 1
        c = stack[sp]
        n += 8
        for j in range(c, c + 8):
            if not np.isnan(slots[j].value) and slots[j].child >= 0:
                stack[sp] = slots[j].child
                sp += 1
    return n


@kernel
def graft(slots, meta, src, src_node, kx, ky, kz, depth):
    """Copy the subtree under ``src_node`` of another pool to the node at ``depth`` holding key
    (kx, ky, kz) of this one, making the nodes on the way (value 0 until settled; the caller has
    made room). Returns the number of nodes added."""
    if np.isnan(slots[0].value):
        slots[0].value = 0.0
        slots[0].child = -1
        meta[SIZE] += 1
    added = 0
    node = 0
    for d in range(depth):
        if slots[node].child < 0:
            slots[node].child = alloc_block(slots, meta, np.nan)
        nxt = slots[node].child + child_index(kx, ky, kz, d)
        if np.isnan(slots[nxt].value):
            slots[nxt].value = 0.0
            slots[nxt].child = -1
            added += 1
        node = nxt
    # the subtree, block by block: (source block, target block) pairs
    slots[node].value = src[src_node].value
    src_stack = np.empty(8 * DEPTH + 8, np.int64)
    dst_stack = np.empty(8 * DEPTH + 8, np.int64)
    sp = 0
    if src[src_node].child >= 0:
        slots[node].child = alloc_block(slots, meta, np.nan)
        src_stack[0], dst_stack[0] = src[src_node].child, slots[node].child
        sp = 1
    while sp > 0:
        sp -= 1
        s, t = src_stack[sp], dst_stack[sp]
        for j in range(8):
            v = src[s + j].value
            if np.isnan(v):
                continue
            slots[t + j].value = v
            added += 1
            if src[s + j].child >= 0:
                c = alloc_block(slots, meta, np.nan)
                slots[t + j].child = c
                src_stack[sp], dst_stack[sp] = src[s + j].child, c
                sp += 1
    meta[SIZE] += added
    return added


def new_pool(n: int):
    """Empty slots with room for ``n`` (whole blocks) and their ``meta``."""
    return new_slots(8 * (n // 8 + 2)), new_meta()

