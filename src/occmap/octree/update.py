"""The probabilistic update (OctoMap's ``OccupancyOcTreeBase::updateNode``): the log-odds rule,
and applying a list of voxel updates to the node pool of :mod:`.pool`.

The rule: a hit adds ``l_hit``, a miss ``l_miss`` (float32, as OctoMap stores log-odds), and the
result is clamped to ``[lo, hi]``; a value already at the clamp the update pushes toward is left
alone — and so is a pruned leaf there, without expanding it (OctoMap's early abort).
"""

from __future__ import annotations

import numpy as np

from .._intrinsics import prefetch, trailing_zeros
from .._jit import inline_kernel, kernel, kernel_without_refcounts
from .blocks import block_marks, uniform, uniform_block
from .keys import DEPTH, block_key, child_index, pack, shared_depth, unpack
from .pool import FREE, SIZE, TOP, alloc_block, free_slots, settle

#: Slots one voxel update may allocate at most: a new block at every level.
ROOM = 8 * DEPTH
#: Depth of a block's node (8×8×8 voxels: :mod:`.blocks`).
BLOCK_DEPTH = DEPTH - 3
#: Slots one block's updates may allocate at most: a new block at every level down to the
#: block's node, and every block of children below it.
BLOCK_ROOM = 8 * (BLOCK_DEPTH + 1 + 8 + 64)
#: Bits of a packed key that siblings (voxels of one parent) share: all but each axis's lowest.
_SIBLINGS = ~pack.py_func(1, 1, 1)


def new_work() -> np.ndarray:
    """Scratch for :func:`apply_voxels` and :func:`apply_blocks`, which allocate nothing (they run
    without reference counting: :data:`.._jit.kernel_without_refcounts`): int64 (8, 17), rows
    0 the walk's path, 1-3 :func:`update_subtree`'s, 4-6 :func:`apply_blocks`' flags and child
    bits per depth, 7 a block's masks. A thread's own: kernels running side by side each take one."""
    return np.zeros((8, DEPTH + 1), np.int64)


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


@inline_kernel
def update_leaf(slots, node, made, hit, l_hit, l_miss, lo, hi):
    """Leaf ``node`` takes a hit (``hit``) or a miss: a new one (NaN, or ``made`` just now by the
    caller) from log-odds 0, as a node OctoMap has just made takes it (clamped: where 0 lies
    outside the clamping bounds, to the nearer one), an existing one unless it is saturated
    (OctoMap's early abort). Returns whether its value changed."""
    v = slots[node].value
    if saturated(v, hit, lo, hi) and not made:  # (NaN never is)
        return False
    slots[node].value = updated(np.float32(0.0) if made or np.isnan(v) else v, hit, l_hit, l_miss, lo, hi)
    return True


@inline_kernel
def resume(slots, meta, path, known, dirty, key, previous, settle_nodes, spines):
    """Where a walk down to packed key ``key`` starts, after one to ``previous`` whose nodes
    ``path[0..known]`` are kept (``known`` < 0: none) and ``path[0..dirty]`` saw a change: it
    leaves that path up to the node both share, settling the nodes it leaves (with
    ``settle_nodes``; see :func:`leave`). Returns (the depth of the node to start from, ``dirty``
    now)."""
    if known < 0:
        return 0, dirty
    shared = shared_depth(key, previous)
    if settle_nodes:
        leave(slots, meta, path, min(dirty, known - 1), shared, spines)
        dirty = min(dirty, shared)
    return min(shared, known), dirty


@inline_kernel
def leave(slots, meta, path, deepest, shared, spines):
    """Settle the nodes ``path[deepest]`` up to ``path[shared + 1]``, deepest first (a walk
    leaving them), but those of ``spines`` (see :func:`apply_voxels`)."""
    for s in range(deepest, shared, -1):
        if path[s] != spines[0, s] and path[s] != spines[1, s]:
            settle(slots, meta, path[s], True, True)


@inline_kernel
def update_children(slots, meta, node, new, marked, hit, l_hit, l_miss, lo, hi, settle_nodes):
    """Each voxel child ``k`` of ``node`` (depth 15) whose bit is set in ``marked`` takes a hit
    (bit ``k`` of ``hit``) or a miss, as :func:`apply_blocks` updates a voxel: a missing child
    (NaN) becomes a new leaf; a pruned ``node`` (no children, not ``new``) is expanded into eight
    copies of its value unless each update leaves that value as it is (OctoMap's early abort).
    Then ``node`` is settled, with ``settle_nodes``, if any value changed. Returns (whether any
    did, the slots taken: 8 or 0)."""
    c = slots[node].child
    taken = 0
    if c < 0:
        if not new:
            v = slots[node].value
            if (marked & ~hit == 0 or v <= lo) and (marked & hit == 0 or v >= hi):
                return False, 0
        taken = 8
        c = alloc_block(slots, meta, np.float32(np.nan) if new else slots[node].value)
        if not new:
            meta[SIZE] += 8
        slots[node].child = c
    changed = False
    fresh = 0
    while marked != 0:
        k = trailing_zeros(marked)
        marked &= marked - 1
        fresh += np.isnan(slots[c + k].value)
        changed |= update_leaf(slots, c + k, False, (hit >> k) & 1 != 0, l_hit, l_miss, lo, hi)
    meta[SIZE] += fresh
    if changed and settle_nodes:
        settle(slots, meta, node, True, True)
    return changed, taken


@inline_kernel
def _places(at, sp, first, i):
    """The places among the nodes at depth 15 (see :func:`update_subtree`'s Returns) of the node
    at depth ``at``, child ``i`` of the node ``sp`` levels below the subtree's, ``first`` the
    subtree's child on the way: the node itself at depth 15; the eight it stands for, a leaf at
    depth 14 below a node at 13; else none."""
    if at == DEPTH - 1:
        return np.int64(1) << (8 * first + i if sp == 1 else i)
    return np.int64(0xFF) << 8 * i if at == DEPTH - 2 and sp == 0 else np.int64(0)


@kernel_without_refcounts
def update_subtree(slots, meta, node, depth, hit, l_hit, l_miss, lo, hi, settle_nodes, scratch):
    """Every voxel below inner ``node`` (at ``depth``) takes one hit (``hit``) or miss, leaving
    what OctoMap's ``updateNode`` on each of them, in any order, leaves: a leaf below it (a pruned
    one too: expanded, updated and pruned again it is itself updated) takes the update unless
    saturated (the early abort); a child missing below an inner node (unknown space) becomes a
    leaf with the update of a new node; nodes with a change below them are settled, deepest first
    (pruned where their children came out alike). Allocates nothing; ``scratch`` is int64
    (3, 17) of the caller's. Returns (whether any value changed, the nodes at depth 15 with a
    change at or below them, or where a leaf above them changed: for ``node`` at depth 13 bit
    ``8·a + b`` its child ``a``'s child ``b``, at depth 14 bit ``b``; as :func:`apply_blocks`
    reports a block's changes)."""
    voxels_hit = 0xFF if hit else 0
    if depth == DEPTH - 1:
        return update_children(slots, meta, node, False, 0xFF, voxels_hit, l_hit, l_miss, lo, hi, settle_nodes)[0], 1
    stack, next_child, below = scratch[0], scratch[1], scratch[2]  # below[s]: a value changed below stack[s]
    stack[0] = node
    next_child[0] = 0
    below[0] = 0
    sp = 0
    positions = np.int64(0)
    while True:
        c = slots[stack[sp]].child
        i = next_child[sp]
        if i < 8:
            next_child[sp] = i + 1
            j = c + i
            if slots[j].child >= 0 and depth + sp + 1 == DEPTH - 1:  # its children are voxels
                if update_children(slots, meta, j, False, 0xFF, voxels_hit, l_hit, l_miss, lo, hi, settle_nodes)[0]:
                    below[sp] = 1
                    positions |= _places(depth + sp + 1, sp, next_child[0] - 1, i)
                continue
            if slots[j].child >= 0:
                sp += 1
                stack[sp] = j
                next_child[sp] = 0
                below[sp] = 0
                continue
            meta[SIZE] += np.isnan(slots[j].value)  # (a slot of a child block with no node in it)
            if update_leaf(slots, j, False, hit, l_hit, l_miss, lo, hi):
                below[sp] = 1
                positions |= _places(depth + sp + 1, sp, next_child[0] - 1, i)
            continue
        if below[sp] and settle_nodes:
            settle(slots, meta, stack[sp], True, True)
        if sp == 0:
            return below[0] != 0, positions
        below[sp - 1] |= below[sp]
        sp -= 1


@kernel_without_refcounts
def apply_voxels(slots, meta, keys, depths, is_hit, start, l_hit, l_miss, lo, hi, settle_nodes, limit, spines, work):
    """Apply updates ``start..`` in order, each as OctoMap's ``updateNode`` with a hit or a miss on
    every voxel of the node at ``depths[i]`` (int8; (0,): all 16, voxels) whose first voxel has
    packed key ``keys[i]``. Returns (the number of updates, or the one at which the slots below
    ``limit`` ran out — nothing of it applied yet: the caller makes room and resumes there;
    whether any value changed). With ``settle_nodes`` false (OctoMap's lazy evaluation) inner
    nodes are neither updated nor pruned (give voxels then: a node update settles its subtree).
    The nodes of ``spines`` (int64 (2, 17): two paths from the root down, ``spines[k, d]`` the
    node at depth d or -1) are only passed through, never settled: threads can update runs of
    items side by side, the nodes a run's paths share with the runs on either side being those
    (see :func:`.insertion.apply`). ``work``: scratch (:func:`new_work`).

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
    work[:] = 0
    path = work[0]  # path[d]: node at depth d on the last walk
    scratch = work[1:4]  # for update_subtree
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
                leave(slots, meta, path, min(dirty, known - 1), -1, spines)
            return i, changed
        key = keys[i]
        kx, ky, kz = unpack(key)
        hit = is_hit[i]
        target = depths[i] if depths.shape[0] else DEPTH
        d = 0
        if known >= 0:
            shared = shared_depth(key, previous)
            if settle_nodes:
                for s in range(min(dirty, known - 1), shared, -1):
                    if path[s] != spines[0, s] and path[s] != spines[1, s]:
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
            if update_subtree(slots, meta, node, d, hit, l_hit, l_miss, lo, hi, settle_nodes, scratch)[0]:
                dirty = DEPTH
                changed = True
            continue
        if update_leaf(slots, node, created, hit, l_hit, l_miss, lo, hi):
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
            meta[SIZE] += np.isnan(slots[node].value)
            if update_leaf(slots, node, False, is_hit[j], l_hit, l_miss, lo, hi):
                dirty = DEPTH
                changed = True
            j += 1
        path[DEPTH] = node
        done = j
    if settle_nodes and known >= 0:
        leave(slots, meta, path, min(dirty, known - 1), -1, spines)
    return n, changed


@kernel_without_refcounts
def apply_blocks(slots, meta, codes, hits, frees, kbox, start, l_hit, l_miss, lo, hi, settle_nodes, merge, limit,
                 spines, work, changes):
    """The updates of a scan's marked blocks (:mod:`.blocks`: codes and hit and free masks,
    Morton-sorted, each block once) from block ``start`` on, only voxels within the key box
    ``kbox`` ((0, 3): everywhere): each marked voxel once, a hit where hit (a voxel both hit and
    crossed is a hit), else a miss; with ``merge``, a node of a block whose voxels are all marked
    alike as one update of the node. The same updates, in the same (Morton) order, as
    :func:`apply_voxels` of :func:`.blocks.block_voxels`, and the same tree, with no list between.
    Returns (the number of blocks, or the one at which the slots below ``limit`` ran out — nothing
    of it applied yet; whether any value changed); ``settle_nodes``, ``spines``, ``work`` as for
    :func:`apply_voxels`. ``changes`` (int64 (n,), zeros; (0,): none wanted) takes each block's
    nodes with a value changed at or below them, for :func:`settle_blocks` (with ``settle_nodes``
    false): bit ``8·w + k`` the block's node's grandchild ``k`` below its child ``w`` (depth 15),
    set too where the change is above it (a leaf holding it took the update).

    One loop takes every step down: to the block's node, then through the block's masks (Morton
    words: a word a child of the block's node, a byte a grandchild, a bit a voxel). At a node it
    takes the next child with marked voxels below it (on the way to the block's node, the one
    child on the way), made (a new node's empty block of children, a pruned leaf's eight copies)
    unless every update below leaves that pruned leaf as it is (OctoMap's early abort); a child
    whose voxels are one update takes it, another is gone down into; the voxels below a node at
    depth 15 are updated together (:func:`update_children`: the byte of their bits at once, not a
    step of this loop each: an eighth less time applying a scan). A node within the block is
    settled when its children are done, if anything below it changed; the nodes above, when a
    later block's walk leaves them (as :func:`apply_voxels` settles its path)."""
    n = codes.shape[0]
    changed = False
    work[:] = 0
    path = work[0]  # path[d]: node at depth d on the walk
    scratch = work[1:4]  # for update_subtree
    new = work[4]  # new[d]: path[d] was made on this walk (no children yet)
    todo = work[5]  # within the block: children of path[d] still to visit (bits)
    below = work[6]  # within the block: a value changed below path[d]
    known = -1  # deepest entry of path kept between blocks (at most the block's node's depth)
    dirty = -1  # path[0..dirty] saw a change since the walk entered them
    previous = 0
    marked = work[7, :8]
    hit = work[7, 8:16]
    room = 0  # slots sure to be there for the blocks to come: those counted, less those taken since
    for b in range(start, n):
        if room < BLOCK_ROOM:  # (the free list is counted only when the top runs short)
            room = limit - meta[TOP]
            if room < BLOCK_ROOM and meta[FREE] >= 0:
                room += free_slots(slots, meta[FREE], 16 * BLOCK_ROOM)
            if room < BLOCK_ROOM:
                if settle_nodes:
                    leave(slots, meta, path, min(dirty, known - 1), -1, spines)
                return b, changed
        base = block_key(codes[b])
        if not block_marks(hits[b], frees[b], base, kbox, marked, hit):
            continue
        kx, ky, kz = unpack(base)
        any_hit = any_free = False
        for w in range(8):
            any_hit |= hit[w] != 0
            any_free |= marked[w] & ~hit[w] != 0
        whole = merge and uniform_block(marked, hit)
        below_nodes = np.int64(0)  # the block's changes (see changes)
        d, dirty = resume(slots, meta, path, known, dirty, base, previous, settle_nodes, spines)
        previous = base
        new[d] = False
        if d == 0 and np.isnan(slots[0].value):
            slots[0].value = 0.0
            slots[0].child = -1
            meta[SIZE] += 1
            new[0] = True
        # ---- the walk
        level = d
        word = 0  # within the block: the word of the block's child gone down into
        while True:
            if level < BLOCK_DEPTH:  # the one child on the way, for all of the block's updates
                i = child_index(kx, ky, kz, level)
                m, h, width = np.int64(0), np.int64(any_hit), 1
                f = any_free
            else:
                t = todo[level]
                if t == 0:  # this node's children are done
                    if below[level] and settle_nodes:
                        settle(slots, meta, path[level], True, True)
                    if level == BLOCK_DEPTH:
                        break
                    below[level - 1] |= below[level]
                    level -= 1
                    continue
                i = trailing_zeros(t)
                todo[level] = t & (t - 1)
                if level == BLOCK_DEPTH:
                    m, h, width = marked[i], hit[i], 64
                else:
                    m, h, width = (marked[word] >> (8 * i)) & 0xFF, (hit[word] >> (8 * i)) & 0xFF, 8
                f = m & ~h != 0
            node = path[level]
            c = slots[node].child
            if c < 0:
                if not new[level]:
                    v = slots[node].value
                    if (not f or v <= lo) and (h == 0 or v >= hi):  # OctoMap's early abort, for all of them
                        if level < BLOCK_DEPTH:
                            break
                        continue
                c = alloc_block(slots, meta, np.float32(np.nan) if new[level] else slots[node].value)
                room -= 8
                if not new[level]:
                    meta[SIZE] += 8
                slots[node].child = c
            child = c + i
            fresh = np.isnan(slots[child].value)
            if fresh:
                slots[child].value = 0.0
                meta[SIZE] += 1
            if (level == BLOCK_DEPTH - 1 and whole) or (level >= BLOCK_DEPTH and merge and uniform(m, h, width)):
                # the child's voxels are one update: a leaf takes it as one voxel, an inner node
                # passes it to its subtree
                if slots[child].child >= 0:
                    ch, places = update_subtree(slots, meta, child, level + 1, h != 0, l_hit, l_miss, lo, hi,
                                                settle_nodes, scratch)
                else:  # (a leaf: nothing below it to settle)
                    ch, places = update_leaf(slots, child, fresh, h != 0, l_hit, l_miss, lo, hi), np.int64(-1)
                if level < BLOCK_DEPTH:  # (the whole block)
                    level += 1
                    path[level] = child
                    below[level] = ch
                    below_nodes = places if ch else below_nodes
                    break
                below[level] |= ch
                if ch:
                    below_nodes |= (places & 0xFF) << 8 * i if level == BLOCK_DEPTH else np.int64(1) << 8 * word + i
                continue
            if level == DEPTH - 2:  # the child's children are voxels: all of them at once
                ch, taken = update_children(slots, meta, child, fresh, m, h, l_hit, l_miss, lo, hi, settle_nodes)
                room -= taken
                below[level] |= ch
                if ch:
                    below_nodes |= np.int64(1) << 8 * word + i
                continue
            level += 1
            path[level] = child
            new[level] = fresh
            if level == BLOCK_DEPTH:
                t = 0
                for w in range(8):
                    if marked[w] != 0:
                        t |= 1 << w
                g = slots[child].child
                if g >= 0:  # the blocks of children of its children with marks below, side by side
                    for w in range(8):
                        if marked[w] != 0:
                            prefetch(slots, max(slots[g + w].child, 0))
            elif level == BLOCK_DEPTH + 1:
                word = i
                t = 0
                for k in range(8):
                    if (m >> (8 * k)) & 0xFF != 0:
                        t |= 1 << k
                g = slots[child].child
                if g >= 0:  # the voxels below this node's children are fetched from memory side by side
                    for j in range(g, g + 8):
                        prefetch(slots, max(slots[j].child, 0))  # (a leaf's -1: the root, cached)
            else:
                continue
            todo[level] = t
            below[level] = False
        if level >= BLOCK_DEPTH and below[BLOCK_DEPTH]:
            dirty = DEPTH
            changed = True
        if changes.shape[0]:
            changes[b] = below_nodes
        known = min(level, BLOCK_DEPTH)
    if settle_nodes and known >= 0:
        leave(slots, meta, path, min(dirty, known - 1), -1, spines)
    return n, changed


@kernel_without_refcounts
def settle_blocks(slots, meta, codes, changes, start, spines, work):
    """Settle, once, every node that updates applied without settling (:func:`apply_blocks` with
    ``settle_nodes`` false) changed a value at or below: ``codes`` the blocks (Morton-sorted, each
    once) and ``changes`` their nodes with changes below (as :func:`apply_blocks` gives them, OR-ed
    over the updates), from block ``start`` on. Deepest first: within a block, then the nodes
    above it as the walk leaves them; each from its children as they are now, as an eager update
    leaves a node after the last change below it. Nodes with no change below are left as they are
    (a tree built with lazy updates keeps its unpruned nodes there, as OctoMap's does); so are
    those of ``spines`` (see :func:`apply_voxels`: runs of blocks settled side by side). Returns
    (the number of blocks, True), as :func:`apply_blocks` would (it allocates nothing).
    ``work``: scratch (:func:`new_work`)."""
    work[:] = 0
    path = work[0]
    known = -1  # deepest entry of path the last block's walk reached
    previous = 0
    for b in range(start, codes.shape[0]):
        mask = changes[b]
        if mask == 0:
            continue
        base = block_key(codes[b])
        kx, ky, kz = unpack(base)
        d = resume(slots, meta, path, known, DEPTH, base, previous, True, spines)[0]  # (every block changed)
        previous = base
        node = path[d]
        while d < BLOCK_DEPTH and slots[node].child >= 0:  # (a leaf above the block took its update)
            node = slots[node].child + child_index(kx, ky, kz, d)
            d += 1
            path[d] = node
        known = d
        if d < BLOCK_DEPTH or slots[node].child < 0:
            continue
        c = slots[node].child
        for w in range(8):  # the nodes to settle, and their children, fetched from memory side by side
            g = slots[c + w].child
            if (mask >> 8 * w) & 0xFF != 0 and g >= 0:
                prefetch(slots, g)
        for w in range(8):
            g = slots[c + w].child
            nodes = (mask >> 8 * w) & 0xFF
            if nodes == 0 or g < 0:
                continue
            t = nodes
            while t != 0:
                k = trailing_zeros(t)
                t &= t - 1
                prefetch(slots, max(slots[g + k].child, 0))
            while nodes != 0:
                k = trailing_zeros(nodes)
                nodes &= nodes - 1
                if slots[g + k].child >= 0:
                    settle(slots, meta, g + k, True, True)
            settle(slots, meta, c + w, True, True)
        settle(slots, meta, node, True, True)
    if known >= 0:
        leave(slots, meta, path, known - 1, -1, spines)
    return codes.shape[0], True
