"""Circular-buffer index maths, written once (ANYbotics grid_map's ``wrapIndexToRange`` and
``getBufferIndexFromIndex`` are the model).

A ring of ``n`` slots stores a window of ``n`` indices: window index ``i`` (0 at the window's
start) lives in slot ``(i + start) mod n``. Moving the window by ``k`` moves ``start`` by ``k``
(:func:`wrap`) and only the slots that left need clearing; nothing is copied. A 2D window is one
ring per axis (rows and columns; grid conventions in :mod:`occmap.raster`).

Every function takes and returns integers (Numba kernels, callable from Python too).
"""

from __future__ import annotations

from .._jit import kernel

__all__ = ["wrap", "slot", "wrap_point", "run_of"]


@kernel
def wrap(i, n):
    """``i mod n`` in ``[0, n)`` for any integer ``i`` (negative or many times ``n`` away), ``n > 0``.
    The usual cases (already in range, or one ring away) cost a compare and an add."""
    if i < n:
        if i >= 0:
            return i
        if i >= -n:
            return i + n
    elif i < 2 * n:
        return i - n
    return i % n  # Python's modulo: the sign of n


@kernel
def slot(i, start, n):
    """The slot holding window index ``i`` of a ring of ``n`` slots whose window starts at slot
    ``start`` (``0 ≤ start < n``; ``i`` may lie outside ``[0, n)``)."""
    return wrap(i + start, n)


@kernel
def wrap_point(start, n):
    """The first window index whose slot has wrapped round to the ring's beginning (``n`` when
    ``start`` is 0): window indices ``[0, p)`` live in slots ``i + start``, ``[p, n)`` in slots
    ``i + start − n``. A window range therefore lies in at most two runs of slots."""
    return n - start


@kernel
def run_of(k, start, n):
    """Run ``k`` (0 or 1) of a window of ``n`` indices in a ring that starts at slot ``start``
    (:func:`wrap_point`): ``(first, end, offset)``, window indices ``[first, end)`` living in
    slots ``i + offset``. Loops over the two runs have no wrap test per index (they vectorise)."""
    p = n - start
    if k == 0:
        return 0, p, start
    return p, n, -p
