"""The probabilistic update (OctoMap's ``OccupancyOcTreeBase::updateNode``): the log-odds rule,
and applying a list of voxel updates to the node pool of :mod:`.pool`.

The rule: a hit adds ``l_hit``, a miss ``l_miss`` (float32, as OctoMap stores log-odds), and the
result is clamped to ``[lo, hi]``; a value already at the clamp the update pushes toward is left
alone — and so is a pruned leaf there, without expanding it (OctoMap's early abort).
"""

from __future__ import annotations

import numpy as np

from .._intrinsics import prefetch
from .._jit import kernel
from .keys import DEPTH, child_index, pack, shared_depth, unpack
from .pool import FREE, SIZE, TOP, alloc_block, free_slots, settle

#: Slots one voxel update may allocate at most: a new block at every level.
ROOM = 8 * DEPTH
#: Bits of a packed key that siblings (voxels of one parent) share: all but each axis's lowest.
_SIBLINGS = ~pack.py_func(1, 1, 1)


@kernel
def saturated(v, hit, lo, hi):
    """Whether an update (a hit when ``hit``, else a miss) leaves log-odds ``v`` as it is: it is
    already at the clamp the update pushes toward."""
    return v >= hi if hit else v <= lo


@kernel
def updated(v, hit, l_hit, l_miss, lo, hi):
    """Log-odds ``v`` after a hit (``hit``) or a miss, clamped to [lo, hi]."""
    v = v + (l_hit if hit else l_miss)
    return lo if v < lo else (hi if v > hi else v)


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
def update_subtree(slots, meta, node, hit, l_hit, l_miss, lo, hi, settle_nodes):
    """Every voxel below inner ``node`` takes one hit (``hit``) or miss, leaving what OctoMap's
    ``updateNode`` on each of them, in any order, leaves: a leaf below it (a pruned one too:
    expanded, updated and pruned again it is itself updated) takes the update unless saturated
    (the early abort); a child missing below an inner node (unknown space) becomes a leaf with the
    update of a new node; nodes with a change below them are settled, deepest first (pruned where
    their children came out alike). Allocates nothing. Returns whether any value changed."""
    stack = np.empty(DEPTH + 1, np.int64)
    next_child = np.zeros(DEPTH + 1, np.int64)
    below = np.zeros(DEPTH + 1, np.bool_)  # below[s]: a value changed below stack[s]
    stack[0] = node
    sp = 0
    while True:
        c = slots[stack[sp]].child
        i = next_child[sp]
        if i < 8:
            next_child[sp] = i + 1
            j = c + i
            if slots[j].child >= 0:
                sp += 1
                stack[sp] = j
                next_child[sp] = 0
                below[sp] = False
                continue
            if np.isnan(slots[j].value):  # (a slot of a child block with no node in it)
                slots[j].value = 0.0
                meta[SIZE] += 1
            if not saturated(slots[j].value, hit, lo, hi):
                slots[j].value = updated(slots[j].value, hit, l_hit, l_miss, lo, hi)
                below[sp] = True
            continue
        if below[sp] and settle_nodes:
            settle(slots, meta, stack[sp], True, True)
        if sp == 0:
            return below[0]
        below[sp - 1] |= below[sp]
        sp -= 1


@kernel
def apply_voxels(slots, meta, keys, depths, is_hit, start, l_hit, l_miss, lo, hi, settle_nodes, limit, top):
    """Apply updates ``start..`` in order, each as OctoMap's ``updateNode`` with a hit or a miss on
    every voxel of the node at ``depths[i]`` (int8; (0,): all 16, voxels) whose first voxel has
    packed key ``keys[i]``. Returns (the number of updates, or the one at which the slots below
    ``limit`` ran out — nothing of it applied yet: the caller makes room and resumes there;
    whether any value changed). With ``settle_nodes`` false (OctoMap's lazy evaluation) inner
    nodes are neither updated nor pruned (give voxels then: a node update settles its subtree).
    Nodes above depth ``top`` are only passed through, never settled: two threads can update the
    subtrees below one node side by side (see :func:`.insertion.apply`).

    A node update is the updates of its voxels at once: a leaf (a new node, or a pruned one) takes
    it as one voxel would, since its voxels would come out alike and be pruned back into it; an
    inner node passes it to its subtree (:func:`update_subtree`).

    The walk to a voxel restarts from the deepest node shared with the previous voxel's path, so
    voxels in Morton order cost a level or two instead of sixteen; the voxels that follow a voxel
    and share its parent (about two in three of a scan's updates) cost no walk at all, only
    their slot in the parent's block of children. An inner node is settled once the walk leaves
    it, if anything below it changed. The walk is written inline here: a Numba call passing
    arrays costs more than the step itself."""
    n = keys.shape[0]
    cap = limit
    changed = False
    path = np.zeros(DEPTH + 1, np.int64)  # path[d]: node at depth d on the last walk
    known = -1  # deepest valid entry of path
    dirty = -1  # path[0..dirty] saw a change since the walk entered them
    previous = 0
    done = start  # updates before this one were applied with a sibling's
    for i in range(start, n):
        if i < done:
            continue
        # room for one update (ROOM slots at most): the top's, or free blocks (counted only
        # when the top's is short: a free list may be shorter than an update needs)
        short = meta[TOP] + ROOM > cap
        if short and (meta[FREE] < 0 or free_slots(slots, meta[FREE], ROOM) < ROOM - (cap - meta[TOP])):
            if settle_nodes:
                for d in range(min(dirty, known - 1), top - 1, -1):
                    settle(slots, meta, path[d], True, True)
            return i, changed
        key = keys[i]
        kx, ky, kz = unpack(key)
        hit = is_hit[i]
        target = depths[i] if depths.shape[0] else DEPTH
        # ---- leave the previous voxel's path up to the node both share
        d = 0
        if known >= 0:
            shared = shared_depth(key, previous)
            if settle_nodes:
                for s in range(min(dirty, known - 1), max(shared, top - 1), -1):
                    settle(slots, meta, path[s], True, True)
                dirty = min(dirty, shared)
            d = min(shared, known)
        previous = key
        # ---- walk down, creating or expanding nodes, unless the update cannot change anything
        node = path[d]
        created = False
        if d == 0 and np.isnan(slots[0].value):
            slots[0].value = 0.0
            slots[0].child = -1
            meta[SIZE] += 1
            created = True
        absorbed = False
        while d < target:
            c = slots[node].child
            if c < 0:
                if not created:
                    v = slots[node].value
                    absorbed = saturated(v, hit, lo, hi)  # OctoMap's early abort
                    if absorbed:
                        break
                # a new node gets an empty block; a pruned leaf is expanded into eight copies
                c = alloc_block(slots, meta, np.float32(np.nan) if created else slots[node].value)
                if not created:
                    meta[SIZE] += 8
                slots[node].child = c
            elif d == DEPTH - 2:
                # the voxels that follow in Morton order go down through this block's other
                # nodes: their blocks of children are fetched from memory side by side
                for j in range(c, c + 8):
                    prefetch(slots, max(slots[j].child, 0))  # (a leaf's -1: the root, cached)
            node = c + child_index(kx, ky, kz, d)
            created = np.isnan(slots[node].value)
            if created:
                slots[node].value = 0.0
                meta[SIZE] += 1
            d += 1
            path[d] = node
        known = d
        if absorbed:
            continue
        if slots[node].child >= 0:
            if update_subtree(slots, meta, node, hit, l_hit, l_miss, lo, hi, settle_nodes):
                dirty = DEPTH
                changed = True
            continue
        if not saturated(slots[node].value, hit, lo, hi):
            slots[node].value = updated(slots[node].value, hit, l_hit, l_miss, lo, hi)
            dirty = DEPTH
            changed = True
        if d < DEPTH:
            continue
        # ---- the voxel's siblings that follow (Morton order: next to it), from its parent's block
        # of children, with no walk: they exist or are empty slots there (the parent has children)
        c = slots[path[DEPTH - 1]].child
        j = i + 1
        while j < n and (keys[j] ^ key) & _SIBLINGS == 0 and (depths.shape[0] == 0 or depths[j] == DEPTH):
            previous = keys[j]
            node = c + child_index(*unpack(previous), DEPTH - 1)
            hit = is_hit[j]
            if np.isnan(slots[node].value):
                slots[node].value = 0.0
                meta[SIZE] += 1
            if not saturated(slots[node].value, hit, lo, hi):
                slots[node].value = updated(slots[node].value, hit, l_hit, l_miss, lo, hi)
                dirty = DEPTH
                changed = True
            j += 1
        path[DEPTH] = node
        done = j
    if settle_nodes and known >= 0:
        for d in range(min(dirty, known - 1), top - 1, -1):
            settle(slots, meta, path[d], True, True)
    return n, changed
