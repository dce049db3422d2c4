"""What the immutable batched wrappers (:class:`SO2`, :class:`SE2`, :class:`SO3`, :class:`SE3`)
share: one read-only float64 array whose trailing axes hold one element (``_ELEMENT``, e.g.
(3, 3) for a rotation matrix) and whose leading axes are the batch, with the batch's shape,
``len`` and indexing, and for the matrix groups (SO3, SE3) composition with ``@``.

A wrapper is built from checked input (``_checked``: by default rigid-body matrices validated by
the kernel ``_CHECK``, whose rejections name the element) or, by the package's own code holding
values it made itself, with ``_trusted=True``, which takes the array as it is.
"""

from __future__ import annotations

import numpy as np

from ._arrays import Rejected, batch, index_batch, reject


class Batch:
    __slots__ = ("_a",)

    _ELEMENT: tuple[int, ...]  # shape of one element
    _CHECK = None  # staticmethod: kernel raising Rejected(i) at the first bad matrix
    _KIND = ""  # what an element must be, as in _arrays.reject
    _COMPOSE = None  # staticmethod: the product of two matrix batches (SO3 and SE3: renormalised)

    def __init__(self, array, *, _trusted: bool = False):
        a = np.asarray(array) if _trusted else self._checked(array)
        a.flags.writeable = False
        self._a = a

    def _checked(self, matrix) -> np.ndarray:
        """A float64 copy of ``matrix`` (..., *_ELEMENT), every element checked by ``_CHECK``."""
        m, lead = batch(np.array(matrix, dtype=np.float64), self._ELEMENT, "matrix")
        try:
            self._CHECK(m)
        except Rejected as e:
            reject(e.args[0], lead, (m, self._ELEMENT, "matrix", self._KIND))
        return m

    @property
    def shape(self) -> tuple[int, ...]:
        return self._a.shape[: self._a.ndim - len(self._ELEMENT)]

    def __len__(self) -> int:
        if not self.shape:
            raise TypeError(f"a single {type(self).__name__} has no len()")
        return self.shape[0]

    def __getitem__(self, index):
        return type(self)(index_batch(self._a, len(self._ELEMENT), index), _trusted=True)

    def __matmul__(self, other):
        """``self @ other``: apply ``other`` first (leading shapes broadcast)."""
        if not isinstance(other, type(self)):
            return NotImplemented
        return type(self)(self._COMPOSE(self._a, other._a), _trusted=True)
