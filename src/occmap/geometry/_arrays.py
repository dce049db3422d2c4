"""Argument handling shared by the geometry functions: shape checks, broadcasting, and the error
messages that name the offending element.

Every public function follows one pattern: convert its arguments to C-contiguous float64 arrays
(no copy when they already are), check their trailing shapes, allocate the output in its final
shape, and call a Numba kernel that fills it. A kernel raises ``Rejected(i)`` at the first bad
element; :func:`reject` then works out which argument was at fault and why. An argument whose
leading shape is ``()`` is broadcast inside the kernel (stride 0), so one pose applied to a
million points is never copied a million times.
"""

from __future__ import annotations

import functools

import numpy as np
from numba import carray, get_num_threads, njit, types
from numba.core.caching import FunctionCache
from numba.core.ccallback import CFunc

from ..errors import InvalidArgumentError, NonFiniteError, NotARotationError, NotUnitQuaternionError, ShapeError
from ._kernels import UNIT_TOL, Rejected
from ._single import SingleCall

_F64 = np.dtype(np.float64)

#: Largest accepted Frobenius norm of RᵀR − I for a rotation matrix.
ROTATION_TOL = 1e-6

__all__ = ["ROTATION_TOL", "UNIT_TOL", "Rejected", "batch", "broadcast", "entry", "index_batch", "public", "reject", "run", "unstack", "where"]


def batch(x, trailing: tuple[int, ...], name: str) -> tuple[np.ndarray, tuple[int, ...]]:
    """Return ``x`` as a C-contiguous float64 array whose shape ends in ``trailing``, and its leading shape."""
    a = np.asarray(x, dtype=_F64, order="C")
    if a.shape == trailing:  # one element: the common single call, kept to one comparison
        return a, ()
    return a, _leading(a.shape, trailing, name)


def _leading(shape: tuple[int, ...], trailing: tuple[int, ...], name: str) -> tuple[int, ...]:
    """The leading part of ``shape``, which must end in ``trailing``."""
    cut = len(shape) - len(trailing)
    if cut < 0 or shape[cut:] != trailing:
        want = "(..., " + ", ".join(map(str, trailing)) + ")" if trailing else "a number or array of numbers"
        raise ShapeError(f"{name} must have shape {want}, got {shape}")
    return shape[:cut]


def broadcast(*args) -> tuple[list[np.ndarray], tuple[int, ...]]:
    """Bring several ``(value, trailing, name, ...)`` arguments to a common leading shape.

    Arguments whose leading shape equals the result's, or is ``()``, are returned as they are (the
    kernels broadcast single elements with stride 0); others are copied to the broadcast shape.
    Arrays are made C-contiguous, except 1-D arrays of scalars, which the kernels read strided.
    """
    arrays = []
    single = True
    for arg in args:
        a = np.asarray(arg[0], dtype=_F64)
        if not a.flags.c_contiguous and (arg[1] or a.ndim != 1):  # scalars' 1-D columns are read in place
            a = np.ascontiguousarray(a)
        arrays.append(a)
        single = single and a.shape == arg[1]
    if single:
        return arrays, ()
    leads = [_leading(a.shape, arg[1], arg[2]) for a, arg in zip(arrays, args)]
    shape = max(leads, key=len)
    if all(lead == shape or not lead for lead in leads):
        return arrays, shape
    try:
        shape = np.broadcast_shapes(*leads)
    except ValueError:
        names = ", ".join(f"{arg[2]} {lead}" for arg, lead in zip(args, leads))
        raise ShapeError(f"leading shapes do not broadcast: {names}") from None
    out = []
    for a, lead, arg in zip(arrays, leads, args):
        if lead and lead != shape:
            a = np.ascontiguousarray(np.broadcast_to(a, shape + arg[1]))
        out.append(a)
    return out, shape


def index_batch(m: np.ndarray, trailing: int, index) -> np.ndarray:
    """``m[index]`` with ``index`` addressing only the leading (batch) axes of ``m``, never the
    ``trailing`` axes that hold one element; any NumPy index works (ints, slices, masks, arrays)."""
    lead = m.shape[: m.ndim - trailing]
    if not lead:
        raise IndexError("a single element cannot be indexed")
    rows = np.arange(m.size // max(1, int(np.prod(m.shape[len(lead):])))).reshape(lead)[index]
    return m.reshape((-1,) + m.shape[len(lead):])[rows]


def unstack(out: np.ndarray) -> tuple:
    """Split the last axis of ``out`` into a tuple of arrays (Python floats for a 1-D ``out``)."""
    if out.ndim == 1:
        return tuple(out.tolist())
    return tuple(out.T) if out.ndim == 2 else tuple(np.moveaxis(out, -1, 0))


def run(kernel, out_trailing: tuple[int, ...], *operands: tuple, args: tuple = ()) -> np.ndarray:
    """The whole calling convention in one place: broadcast ``operands`` — each
    ``(value, trailing, name, kind)`` with ``kind`` as in :func:`reject` — allocate the output
    (leading shape + ``out_trailing``), call ``kernel(*args, *arrays, out)`` and turn a
    ``Rejected`` into the error that names the bad argument and element. :func:`entry` builds
    the faster path single elements take before they come here."""
    arrays, lead = broadcast(*operands)
    flat = [a.reshape(-1) if a.ndim > 1 and not op[1] else a for a, op in zip(arrays, operands)]  # scalars: 1-D
    out = np.empty(lead + out_trailing)
    try:
        kernel(*args, *flat, out)
    except Rejected as e:
        reject(e.args[0], lead, *[(a, op[1], op[2], op[3]) for a, op in zip(arrays, operands)])
    return out


#: The C signature of a single-element kernel (:class:`._single.SingleCall`): the operands' data
#: pointers (a scalar's: one double), the output's; 0 when the output is filled, 1 when rejected.
_SINGLE_SIGNATURE = ((types.CPointer(types.CPointer(types.float64)), types.CPointer(types.float64)), types.int32)


class _NamedCache(FunctionCache):
    """Numba's disk cache for the single-element cfuncs, keyed by a name for what each holds.

    They are one closure (:func:`_single_kernel`) over a kernel and its shapes; Numba keys a
    closure by its pickled cells, and a kernel pickles with an id drawn anew in each process, so
    each process would compile them again (~0.5 s each). The package's cache folder is already
    one per version of its sources (:mod:`occmap._jit`): within it, the name is key enough."""

    def __init__(self, py_func, name: str):
        super().__init__(py_func)
        self._name = name

    def _index_key(self, sig, codegen):
        return (sig, codegen.magic_tuple(), self._name)


def _element_call(kernel, shapes: tuple, out_trailing: tuple[int, ...], args: tuple, one):
    """``call(ops, o)``, inlined into the cfunc: one element through ``one(*operands, o)``
    (scalars as floats) or, without it, ``kernel(*args, *operands, o)`` (scalars as one-element
    arrays, as :func:`run` passes a batch's), the operands read in place from their data
    pointers ``ops``. ``args`` holds at most one constant."""
    s0, s1, s2 = [shape or (1,) for shape in shapes] + [(1,)] * (3 - len(shapes))
    if one is not None and not shapes[0]:  # Euler angles, a planar pose
        call = lambda ops, o: one(ops[0][0], ops[1][0], ops[2][0], o)  # noqa: E731
    elif one is not None and len(shapes) == 3:  # two arrays and a float (slerp)
        call = lambda ops, o: one(carray(ops[0], s0), carray(ops[1], s1), ops[2][0], o)  # noqa: E731
    elif one is not None:
        call = lambda ops, o: one(carray(ops[0], s0), carray(ops[1], s1), o)  # noqa: E731
    elif args:
        arg = args[0]
        call = {1: lambda ops, o: kernel(arg, carray(ops[0], s0), o),
                3: lambda ops, o: kernel(arg, carray(ops[0], s0), carray(ops[1], s1), carray(ops[2], s2), o)}[len(shapes)]
    else:
        call = {1: lambda ops, o: kernel(carray(ops[0], s0), o),
                2: lambda ops, o: kernel(carray(ops[0], s0), carray(ops[1], s1), o),
                3: lambda ops, o: kernel(carray(ops[0], s0), carray(ops[1], s1), carray(ops[2], s2), o)}[len(shapes)]
    return njit(inline="always", error_model="numpy")(call)


def _single_kernel(kernel, shapes: tuple, out_trailing: tuple[int, ...], args: tuple, one) -> CFunc:
    """The cfunc :class:`._single.SingleCall` calls for one element (:func:`_element_call`), with
    its C signature: 0 when the output is filled, 1 when the kernel rejected the element (any
    exception). Each arity's call is a closure of its own: one closure branching over all of them
    made Numba's untyped passes take ~1 s a cfunc instead of ~0.15 s."""
    call = _element_call(kernel, shapes, out_trailing, args, one)

    def single(ops, out):
        try:
            call(ops, carray(out, out_trailing))
        except Exception:  # noqa: BLE001 - the Python path raises the error that names the element
            return 1
        return 0

    which = one or kernel
    name = f"{which.py_func.__module__}.{which.__name__}{args}{shapes}->{out_trailing}"
    compiled = CFunc(single, _SINGLE_SIGNATURE, locals={}, options={"nopython": True, "error_model": "numpy"})
    compiled._cache = _NamedCache(single, name)
    get_num_threads()  # starts Numba's threading layer, which kernels with a parallel pass link to
    compiled.compile()
    return compiled


def entry(kernel, out_trailing: tuple[int, ...], *operands: tuple, args: tuple = (), otherwise=None, one=None):
    """The Python face of ``kernel``: a function of the operand values, each operand described by
    ``(trailing, name, kind)`` as in :func:`run`.

    A single element — every operand a C-contiguous float64 array of exactly its trailing shape,
    a scalar a Python or NumPy float — is handled in C (:class:`._single.SingleCall`: ~40 ns),
    which calls the kernel compiled for one element (:func:`_single_kernel`, compiled or loaded
    from the disk cache at the function's first call). ``one``, when given, is the kernel's
    single-element form, which that path calls instead, without ``args`` and with floats for
    scalars: no loop over rows, no parallel pass to decide against (a quaternion product through
    ``quat_multiply_one`` 0.10 µs, through ``quat_multiply`` 0.26 µs). Anything else — batches,
    other types, rejected input — goes to ``otherwise`` (by default :func:`run`, which names what
    is wrong).
    """

    def general(*values):
        return run(kernel, out_trailing, *[(v, *op) for v, op in zip(values, operands)], args=args)

    otherwise = otherwise or general
    shapes = tuple(op[0] for op in operands)

    def first(*values, **named):
        if named or len(values) != len(operands):  # the public function's own signature sorts them out
            return call.__wrapped__(*values, **named)
        if not call.bound:
            compiled = _single_kernel(kernel, shapes, out_trailing, args, one)
            call.bind(compiled.address, compiled)
        return otherwise(*values)

    call = SingleCall(shapes, out_trailing, first)
    return call


def public(call: SingleCall):
    """Decorator: the function it decorates is published as ``call`` itself (its single path then
    has no Python frame in front, ~40 ns of a ~140 ns call) wearing the function's name, docstring
    and signature (``functools.wraps``). The function stays the one that takes keyword arguments,
    defaults and any other number of arguments: it calls ``call`` with the operands in order."""

    def publish(f):
        return functools.update_wrapper(call, f)

    return publish


def where(index: int, lead: tuple[int, ...]) -> str:
    """Format a flat element index as a subscript of the leading shape, e.g. ``[2, 0]``."""
    if not lead:
        return ""
    return "[" + ", ".join(str(int(i)) for i in np.unravel_index(index, lead)) + "]"


def reject(bad: int, lead: tuple[int, ...], *operands: tuple[np.ndarray, tuple[int, ...], str, str]):
    """Raise the error explaining why a kernel rejected broadcast element ``bad``.

    ``operands`` are ``(array, trailing, name, kind)`` in the order to blame them; ``kind`` is what
    each element must be: ``"finite"``, ``"nonzero"``, ``"unit"`` (quaternion), ``"rotation"``
    (3×3), ``"rotation2"`` (2×2), ``"rigid"`` (4×4) or ``"rigid2"`` (3×3 planar). The checks are
    the kernels' own predicates, so the verdict agrees with the kernel's.
    """
    from . import _kernels as K

    for array, trailing, name, kind in operands:
        own = array.shape[: array.ndim - len(trailing)]
        flat = array.reshape((-1,) + trailing)
        i, sub = (bad, lead) if own else (0, ())
        x = flat[i]
        at = f"{name}{where(i, sub)}"
        if not np.isfinite(x).all():
            raise NonFiniteError(f"{at} = {_show(x)} is not finite")
        if kind in ("nonzero", "unit") and not x.any():
            if x.shape == (4,):
                raise NotUnitQuaternionError(f"{at} is the zero quaternion, which is no rotation")
            raise InvalidArgumentError(f"{at} is the zero vector")
        if kind == "unit" and not K._unit_ok(flat, i):
            raise NotUnitQuaternionError(
                f"{at} = {_show(x)} has norm {np.sqrt(x @ x):.9g}, expected 1 (|‖q‖² − 1| ≤ {UNIT_TOL:g}); "
                "call quat_normalize first if it is meant as a rotation"
            )
        if kind == "rotation" and not K._rotation_error_sq(flat, i) <= ROTATION_TOL**2:
            _explain_rotation(x, at)
        if kind == "rotation2" and not K._rot2_ok(flat, i):
            _explain_rotation(x, at)
        if kind == "rigid" and not K._rigid_ok(flat, i):
            _explain_rigid(x, at)
        if kind == "rigid2" and not K._rigid2_ok(flat, i):
            _explain_rigid(x, at)
    names = ", ".join(op[2] for op in operands)
    raise InvalidArgumentError(f"{names}: element {bad} was rejected")


def _explain_rigid(m: np.ndarray, at: str):
    expect = np.zeros(m.shape[-1])
    expect[-1] = 1.0
    if np.abs(m[-1] - expect).max() > UNIT_TOL:
        raise NotARotationError(f"{at} has last row {m[-1].tolist()}, expected {expect.tolist()} for a rigid transform")
    _explain_rotation(m[:-1, :-1], at)


def _explain_rotation(r: np.ndarray, at: str):
    det = float(np.linalg.det(r))
    if det <= 0:
        raise NotARotationError(f"{at} has determinant {det:.9g}: a reflection or singular, not a rotation")
    err = float(np.linalg.norm(r.T @ r - np.eye(r.shape[0])))
    raise NotARotationError(
        f"{at} is not orthonormal: ‖RᵀR − I‖ = {err:.3g} > {ROTATION_TOL:g} "
        "(use nearest_rotation or from_matrix(..., project=True) to project it)"
    )


def _show(x: np.ndarray) -> str:
    return np.array2string(x, precision=9, separator=", ")
