"""Argument checks: the one rule for what a number, a resolution, a probability or a count may be.

A *real number* is a Python ``int`` or ``float``, a NumPy integer or floating scalar (``np.int64``,
``np.float32``, …) or a 0-d integer/floating array. It is taken at its exact value:
``np.float32(0.1)`` is accepted and is 0.10000000149011612, not 0.1. Booleans are not numbers here
(``True`` as a resolution is a mistake, not 1 m), nor are strings, ``None``, sequences or arrays with
elements. NaN and ±inf are rejected wherever a function asks for a finite number, which is every
check below.

A *count* is a Python ``int`` or a NumPy integer (not a bool, not a float such as ``2.0``).

Every check returns the value converted (``float`` or ``int``) and raises
:class:`~occmap.errors.InvalidArgumentError` with a message naming the argument and the value it
got, e.g. ``resolution must be a positive finite number of metres, got nan``.
"""

from __future__ import annotations

import math
import numbers

import numpy as np

from .errors import InvalidArgumentError

__all__ = ["count", "finite", "fraction", "non_negative", "positive", "probability", "resolution"]


def _real(name: str, value, what: str) -> float:
    """``value`` as a finite float, or InvalidArgumentError ``{name} must be {what}, got …``."""
    if isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "iuf":
        value = value[()]
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise InvalidArgumentError(f"{name} must be {what}, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise InvalidArgumentError(f"{name} must be {what}, got {value!r}")
    return v


def finite(name: str, value) -> float:
    """A finite real number."""
    return _real(name, value, "a finite number")


def positive(name: str, value, unit: str = "") -> float:
    """A finite real number > 0; ``unit`` (e.g. ``"metres"``) only words the message."""
    what = f"a positive finite number{' of ' + unit if unit else ''}"
    v = _real(name, value, what)
    if not v > 0.0:
        raise InvalidArgumentError(f"{name} must be {what}, got {value!r}")
    return v


def non_negative(name: str, value, unit: str = "") -> float:
    """A finite real number ≥ 0; ``unit`` only words the message."""
    what = f"a non-negative finite number{' of ' + unit if unit else ''}"
    v = _real(name, value, what)
    if not v >= 0.0:
        raise InvalidArgumentError(f"{name} must be {what}, got {value!r}")
    return v


def resolution(value, name: str = "resolution") -> float:
    """A cell or voxel size: a positive finite number of metres."""
    return positive(name, value, "metres")


def probability(name: str, value) -> float:
    """A probability strictly between 0 and 1 (its log-odds is finite)."""
    what = "a probability strictly between 0 and 1"
    v = _real(name, value, what)
    if not 0.0 < v < 1.0:
        raise InvalidArgumentError(f"{name} must be {what}, got {value!r}")
    return v


def probability_on_side(name: str, value, occupied: bool) -> float:
    """A probability on the occupied side of 0.5 (``occupied``: in (0.5, 1)) or on the free side
    (in (0, 0.5)): what a sensor model's hit and miss must be, so that a hit makes a cell more
    likely occupied and a miss less."""
    v = probability(name, value)
    if occupied and not v > 0.5:
        raise InvalidArgumentError(f"{name} must be in (0.5, 1), got {value!r}")
    if not occupied and not v < 0.5:
        raise InvalidArgumentError(f"{name} must be in (0, 0.5), got {value!r}")
    return v


def fraction(name: str, value, *, zero: bool = True) -> float:
    """A share in ``[0, 1]`` (in ``(0, 1]`` when ``zero`` is false)."""
    what = "a fraction in [0, 1]" if zero else "a fraction in (0, 1]"
    v = _real(name, value, what)
    if not (0.0 <= v <= 1.0 and (zero or v > 0.0)):
        raise InvalidArgumentError(f"{name} must be {what}, got {value!r}")
    return v


def count(name: str, value, minimum: int = 1) -> int:
    """An integer ≥ ``minimum``."""
    what = f"an integer ≥ {minimum}"
    if isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "iu":
        value = value[()]
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        raise InvalidArgumentError(f"{name} must be {what}, got {value!r}")
    v = int(value)
    if v < minimum:
        raise InvalidArgumentError(f"{name} must be {what}, got {value!r}")
    return v
