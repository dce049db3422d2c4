"""Joining tiles into one octree: each tile's subtree grafted into a node pool at its place, the
nodes above the tiles settled as OctoMap keeps them (maximum of the children, eight equal leaves
pruned), so the result is the tree one process would have built. Numba kernels on the slot
arrays of :mod:`occmap.octree.pool`."""

from __future__ import annotations

import numpy as np

from .._jit import kernel
from ..octree.keys import DEPTH, child_index
from ..octree.pool import SIZE, alloc_block


@kernel
def subtree_slots(value, child, node):
    """Slots the subtree under ``node`` takes (its blocks of eight, and one for the node)."""
    n = 1
    stack = np.empty(8 * DEPTH + 8, np.int64)
    sp = 0
    if child[node] >= 0:
        stack[0] = child[node]
        sp = 1
    while sp > 0:
        sp -= 1
        c = stack[sp]
        n += 8
        for j in range(c, c + 8):
            if not np.isnan(value[j]) and child[j] >= 0:
                stack[sp] = child[j]
                sp += 1
    return n


@kernel
def graft(value, child, meta, src_value, src_child, src_node, kx, ky, kz, depth):
    """Copy the subtree under ``src_node`` of another pool to the node at ``depth`` holding key
    (kx, ky, kz) of this one, making the nodes on the way (value 0 until settled; the caller has
    made room). Returns the number of nodes added."""
    if np.isnan(value[0]):
        value[0] = 0.0
        child[0] = -1
        meta[SIZE] += 1
    added = 0
    node = 0
    for d in range(depth):
        if child[node] < 0:
            child[node] = alloc_block(value, child, meta, np.nan)
        nxt = child[node] + child_index(kx, ky, kz, d)
        if np.isnan(value[nxt]):
            value[nxt] = 0.0
            child[nxt] = -1
            added += 1
        node = nxt
    # the subtree, block by block: (source block, target block) pairs
    value[node] = src_value[src_node]
    src_stack = np.empty(8 * DEPTH + 8, np.int64)
    dst_stack = np.empty(8 * DEPTH + 8, np.int64)
    sp = 0
    if src_child[src_node] >= 0:
        child[node] = alloc_block(value, child, meta, np.nan)
        src_stack[0], dst_stack[0] = src_child[src_node], child[node]
        sp = 1
    while sp > 0:
        sp -= 1
        s, t = src_stack[sp], dst_stack[sp]
        for j in range(8):
            v = src_value[s + j]
            if np.isnan(v):
                continue
            value[t + j] = v
            added += 1
            if src_child[s + j] >= 0:
                c = alloc_block(value, child, meta, np.nan)
                child[t + j] = c
                src_stack[sp], dst_stack[sp] = src_child[s + j], c
                sp += 1
    meta[SIZE] += added
    return added


def new_pool(slots: int):
    """Empty slot arrays with room for ``slots`` slots (whole blocks) and their ``meta``."""
    n = 8 * (slots // 8 + 2)
    value = np.full(n, np.nan, np.float32)
    child = np.full(n, -1, np.int32)
    return value, child, np.array([8, -1, 0], np.int64)

