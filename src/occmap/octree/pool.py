"""The octree's node pool (OctoMap's ``OcTreeBaseImpl`` storage, in arrays): slots, growth, the
free list, and settling inner nodes (maximum of the children, pruning).

Storage. Nodes live in *slots*; the children of an inner node occupy one *block* of 8 consecutive
slots (child ``i`` at ``block + i``, ``i = x-bit + 2·y-bit + 4·z-bit`` as in OctoMap). A slot is
one record of :data:`SLOT` (8 bytes; kernels read ``slots[i].value``, ``slots[i].child``):

- ``value`` (float32): the log-odds; NaN marks a slot whose node does not exist (unknown space);
- ``child`` (int32): first slot of the node's child block, −1 for a leaf; a freed block links the
  free list through the ``child`` of its first slot.

The two side by side, not in two arrays, because a step down the tree reads both fields of one
slot: a block (64 bytes) is one cache line, so a step costs one line from memory, not two (on a
drive's updates, 1.2 – 1.3× faster than two arrays).

Slot 0 is the root; block 0 holds only it, real blocks start at slot 8. ``meta`` (int64) holds the
allocator and counters: ``meta[TOP]`` the next never-used slot, ``meta[FREE]`` the free-list head
(−1: empty), ``meta[SIZE]`` the number of nodes (OctoMap's ``size()``), ``meta[SPARE]`` the head of
a second free list: the blocks the second thread of a two-thread update freed, which it takes
first the next time (:func:`.insertion._apply_runs`; a one-thread update joins it to the first,
:func:`merge_spare`).
"""

from __future__ import annotations

import mmap
import sys

import numpy as np

from .._jit import inline_kernel, kernel
from ..errors import OccmapError
from .keys import DEPTH, child_index, unpack

TOP, FREE, SIZE, SPARE = 0, 1, 2, 3
#: A slot: a node's log-odds and the first slot of its children's block.
SLOT = np.dtype([("value", np.float32), ("child", np.int32)], align=True)


@inline_kernel
def settle(slots, meta, node, set_max, prune):
    """Make inner ``node`` agree with its children: collapse it into a leaf if its eight
    children are leaves with one value (``prune``), else set it to their maximum (``set_max``).
    Returns True when it was pruned."""
    c = slots[node].child
    first = slots[c].value
    m = np.float32(-np.inf)  # (float32, as the values: no conversions)
    leaves = alike = True  # (no early exit: the eight are one cache line, branches cost more)
    for j in range(c, c + 8):
        v = slots[j].value
        m = max(m, v) if v == v else m  # missing children (NaN) do not count
        leaves &= slots[j].child < 0
        alike &= v == first  # NaN (no child) never equals
    if prune and leaves and alike:
        slots[node].value = first
        slots[node].child = -1
        free_block(slots, meta, c)
        meta[SIZE] -= 8
        return True
    if set_max:
        slots[node].value = m
    return False


@inline_kernel
def fill_block(slots, c, value):
    """The eight slots of block ``c`` set to ``value`` (float32; NaN: no node) with no children."""
    for j in range(c, c + 8):
        slots[j].value = value
        slots[j].child = -1


@inline_kernel
def free_block(slots, meta, c):
    """Block ``c`` made empty slots (NaN, no children) and put at the head of ``meta``'s free list
    (linked through its first slot's ``child``)."""
    fill_block(slots, c, np.float32(np.nan))
    slots[c].child = meta[FREE]
    meta[FREE] = c


@kernel
def path_to(slots, key, depth):
    """The nodes from the root down to ``depth`` on the way to the voxel with packed key ``key``
    when each of them exists and has its block of children, else an empty array."""
    kx, ky, kz = unpack(key)
    path = np.empty(depth + 1, np.int64)
    node = 0
    for d in range(depth + 1):
        if np.isnan(slots[node].value) or slots[node].child < 0:
            return path[:0]
        path[d] = node
        node = slots[node].child + child_index(kx, ky, kz, d)
    return path


@kernel
def free_slots(slots, head, limit):
    """Slots on the free list that starts at block ``head``, counted up to ``limit`` (or a block
    more)."""
    n = 0
    c = head
    while c >= 0 and n < limit:
        n += 8
        c = slots[c].child
    return n


@kernel
def free_range(slots, meta, lo, hi):
    """The unused blocks of slots ``lo .. hi`` (a thread's slot chunk it did not fill, see
    :func:`.insertion._apply_runs`) made empty slots, as freed blocks are, and put on ``meta``'s
    free list."""
    for c in range(lo, hi, 8):
        free_block(slots, meta, c)


@kernel
def merge_spare(slots, meta):
    """The spare list (see the module's description) joined to the free list, for a one-thread update:
    walks the spare list once, to its end."""
    c = meta[SPARE]
    if c < 0:
        return
    while slots[c].child >= 0:
        c = slots[c].child
    slots[c].child = meta[FREE]
    meta[FREE] = meta[SPARE]
    meta[SPARE] = -1


def new_meta(top: int = 8, size: int = 0) -> np.ndarray:
    """A pool's ``meta`` (see the module's description) with both free lists empty."""
    return np.array([top, -1, size, -1], dtype=np.int64)


@kernel
def settle_path(slots, meta, path):
    """Settle (see :func:`settle`: maximum of the children, or pruned) the nodes of ``path``,
    deepest first."""
    for d in range(path.shape[0] - 1, -1, -1):
        settle(slots, meta, path[d], True, True)


@kernel
def settle_tree(slots, meta, depth, set_max, prune):
    """Post-order walk settling (see :func:`settle`) every inner node (``depth`` < 0: OctoMap's
    ``updateInnerOccupancy`` with ``set_max``) or only those at ``depth`` (one level of OctoMap's
    ``prune``). Returns how many nodes were pruned."""
    if np.isnan(slots[0].value) or slots[0].child < 0:
        return 0
    nodes = np.empty(DEPTH + 1, np.int64)
    next_child = np.zeros(DEPTH + 1, np.int64)
    nodes[0] = 0
    sp = 0
    pruned = 0
    while sp >= 0:
        node = nodes[sp]
        if sp != depth:
            c = slots[node].child
            i = next_child[sp]
            while i < 8 and slots[c + i].child < 0:
                i += 1
            if i < 8:
                next_child[sp] = i + 1
                sp += 1
                nodes[sp] = c + i
                next_child[sp] = 0
                continue
        if (depth < 0 or sp == depth) and settle(slots, meta, node, set_max, prune):
            pruned += 1
        sp -= 1
    return pruned


@inline_kernel
def alloc_block(slots, meta, fill):
    """First slot of a free block of 8 (from the free list, else the unused top), each slot set to
    ``fill`` with no children. The caller has checked there is room."""
    c = meta[FREE]
    if c >= 0:
        meta[FREE] = slots[c].child
    else:
        c = meta[TOP]
        meta[TOP] = c + 8
    fill_block(slots, c, fill)
    return c


@kernel
def expand_all(slots, meta):
    """Expand every pruned leaf down to depth 16 (OctoMap's ``expand``); the slots must have room
    for the new blocks (see ``OcTree.expand``)."""
    if np.isnan(slots[0].value):
        return
    nodes = np.empty(DEPTH + 1, np.int64)
    next_child = np.zeros(DEPTH + 1, np.int64)
    nodes[0] = 0
    sp = 0
    while sp >= 0:
        node = nodes[sp]
        if sp < DEPTH and slots[node].child < 0:
            slots[node].child = alloc_block(slots, meta, slots[node].value)
            meta[SIZE] += 8
        i = next_child[sp]
        if sp == DEPTH or i == 8:
            sp -= 1
            continue
        next_child[sp] = i + 1
        k = slots[node].child + i
        if not np.isnan(slots[k].value):
            sp += 1
            nodes[sp] = k
            next_child[sp] = 0


@kernel
def to_max_likelihood(slots, occ, lo, hi):
    """Every node's value to the clamping bound of its class (OctoMap's ``toMaxLikelihood``)."""
    for i in range(slots.shape[0]):
        v = slots[i].value
        if not np.isnan(v):
            slots[i].value = hi if v >= occ else lo


def new_slots(n: int) -> np.ndarray:
    """``n`` empty slots: no node in any (value NaN, no children)."""
    slots = np.empty(n, SLOT)
    slots["value"] = np.nan
    slots["child"] = -1
    return slots


class Pool:
    """The slots of one tree and their ``meta`` as described above (kernels take them as plain
    arrays), and their growth. A new pool is empty: no root."""

    INITIAL_SLOTS = 1 << 12
    #: Slots a child index (int32) can name: a pool's most.
    MAX_SLOTS = 1 << 31
    #: A pool growing to this many bytes moves, once, into address room of its own (see
    #: :meth:`grow`); smaller ones live in arrays as NumPy allocates them.
    ROOM_FROM_BYTES = 1 << 20

    def __init__(self):
        self.slots = new_slots(self.INITIAL_SLOTS)
        self.meta = new_meta()
        self._room = None  # the reserved address range a large pool lives at the start of

    def grow(self, capacity: int) -> None:
        """Room for at least ``capacity`` slots (at least twice the present room), contents kept.
        The new slots are left as they come (:func:`alloc_block` sets a block when it hands it
        out, and nothing reads past ``meta[TOP]``), so the memory they take is only reserved: the
        process's resident memory follows the slots in use, not the room.

        A large pool lives at the start of a private, anonymous range of addresses reserved for
        :data:`MAX_SLOTS` (16 GiB of addresses, no memory: the system gives a page when it is
        first written), and grows by taking more of it: no copy, and the slots never move
        (a copy writes every slot into memory never touched before: on a virtual machine 2 ms a
        MiB, a quarter of the time inserting a dense pair of scans at 0.05 m; a range grown by
        remapping instead moved, and two threads then inserted a quarter slower). Where no such
        range can be had (a limit on the process's addresses, strict overcommit) it grows by
        copies, as a small pool does."""
        n = self.slots.shape[0]
        if capacity > self.MAX_SLOTS:
            raise OccmapError(f"an octree holds at most {self.MAX_SLOTS:,} slots (int32 child indices); "
                              f"{int(capacity):,} asked for")
        m = min(max(2 * n, int(capacity)), self.MAX_SLOTS)
        if self._room is None and m * SLOT.itemsize >= self.ROOM_FROM_BYTES:
            self._room = _reserve(self.MAX_SLOTS * SLOT.itemsize)
            if self._room is not None:
                np.frombuffer(self._room, SLOT, count=n)[:] = self.slots
        if self._room is not None:
            self.slots = np.frombuffer(self._room, SLOT, count=m)
            return
        slots = np.empty(m, SLOT)
        slots[:n] = self.slots
        self.slots = slots


#: Linux's flag for a map whose pages are not counted against the memory the system promises
#: (Python's mmap module names it from 3.13 on). Without it each room would count in full: a fork
#: of a process holding a dozen rooms fails (ENOMEM). None elsewhere: no room, copies.
_MAP_NORESERVE = getattr(mmap, "MAP_NORESERVE", 0x4000 if sys.platform.startswith("linux") else None)


def _reserve(size: int) -> mmap.mmap | None:
    """``size`` bytes of private, anonymous addresses with no memory behind them until written
    (``MAP_NORESERVE``), in small pages, or None where the system refuses. Private: a process made
    by ``fork`` writes to its own copy (a shared map would be the parent's too).

    Small pages, not the huge ones NumPy asks for its large arrays: a growing tree writes memory
    the process has not had before, and on a virtual machine whose host takes back the memory a
    guest frees, a huge page written first costs 1.5 – 2.4 ms a MiB (the host backs its 2 MiB
    as they are cleared), a small page 0.4 – 0.6 (measured here, 400 MiB after a pause of 6 s;
    huge pages the host still backs: 0.1). A simulated drive at 0.05 m, a tree of 370 MiB, was
    inserted 1.17× faster on one core and 1.22× on two (0.1 m: 1.12×, 1.16×; 0.2 m within
    noise), with fewer TLB hits the one cost (3 % more user time)."""
    if _MAP_NORESERVE is None:
        return None
    try:
        room = mmap.mmap(-1, size, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS | _MAP_NORESERVE)
    except (OSError, OverflowError, ValueError):
        return None
    if hasattr(mmap, "MADV_NOHUGEPAGE"):  # (where the system gives huge pages unasked too)
        room.madvise(mmap.MADV_NOHUGEPAGE)
    return room
