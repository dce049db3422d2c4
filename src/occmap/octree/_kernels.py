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

from .._jit import kernel

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
def grow(value, child):
    """The slot arrays at twice the capacity, contents kept, new slots unused."""
    n = value.shape[0]
    v = np.empty(2 * n, np.float32)
    c = np.empty(2 * n, np.int32)
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


@kernel
def settle(value, child, meta, node, set_max, prune):
    """Make inner ``node`` agree with its children: collapse it into a leaf if its eight
    children are leaves with one value (``prune``), else set it to their maximum (``set_max``).
    Returns True when it was pruned."""
    c = child[node]
    collapsible = prune and child[c] < 0 and not np.isnan(value[c])
    i = 1
    while collapsible and i < 8:
        collapsible = child[c + i] < 0 and value[c + i] == value[c]  # NaN (no child) never equals
        i += 1
    if collapsible:
        value[node] = value[c]
        child[node] = -1
        for j in range(c, c + 8):
            value[j] = np.nan
            child[j] = -1
        child[c] = meta[FREE]  # the block joins the free list
        meta[FREE] = c
        meta[SIZE] -= 8
        return True
    if set_max:
        m = -np.inf
        for j in range(c, c + 8):
            if value[j] > m:  # false for NaN: missing children do not count
                m = value[j]
        value[node] = m
    return False


@kernel
def settle_all(value, child, meta, set_max, prune):
    """Post-order pass over every inner node: :func:`settle` each after its children (OctoMap's
    ``updateInnerOccupancy`` with ``set_max``, ``prune`` with ``prune``)."""
    if np.isnan(value[0]) or child[0] < 0:
        return
    nodes = np.empty(DEPTH + 1, np.int64)
    next_child = np.zeros(DEPTH + 1, np.int64)
    nodes[0] = 0
    sp = 0
    while sp >= 0:
        c = child[nodes[sp]]
        i = next_child[sp]
        while i < 8 and child[c + i] < 0:
            i += 1
        if i < 8:
            next_child[sp] = i + 1
            sp += 1
            nodes[sp] = c + i
            next_child[sp] = 0
        else:
            settle(value, child, meta, nodes[sp], set_max, prune)
            sp -= 1


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
