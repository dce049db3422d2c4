"""LLVM intrinsics the kernels need and Numba does not expose."""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.extending import intrinsic


@intrinsic
def bit_length(typingctx, x):
    """Number of bits needed to write the non-negative integer ``x`` (0 for 0): Python's
    ``int.bit_length``, one ``lzcnt`` instead of a loop."""
    if not isinstance(x, types.Integer):
        return None

    def codegen(context, builder, signature, args):
        ty = args[0].type
        fnty = ir.FunctionType(ty, [ty, ir.IntType(1)])
        fn = builder.module.declare_intrinsic("llvm.ctlz", (ty,), fnty)
        zeros = builder.call(fn, [args[0], ir.Constant(ir.IntType(1), 0)])  # defined for 0: the width
        return builder.sub(ir.Constant(ty, ty.width), zeros)

    return x(x), codegen


def _add_if(op: str, doc: str):
    @intrinsic
    def add_if(typingctx, t, bound, g):
        if not (t == types.float64 and bound == types.float64 and g == types.float64):
            return None

        def codegen(context, builder, signature, args):
            t, bound, g = args
            step = builder.select(builder.fcmp_ordered(op, t, bound), g, ir.Constant(ir.DoubleType(), 0.0))
            return builder.fadd(t, step)

        return types.float64(t, bound, g), codegen

    add_if.__doc__ = doc
    return add_if


# The compare and the select in one basic block let LLVM emit a compare mask and an ``and``
# (cmplesd/andpd); written in Python, the same select becomes a branch.
add_if_le = _add_if("<=", "``t + g`` where ``t <= bound``, else ``t``: no branch.")
add_if_lt = _add_if("<", "``t + g`` where ``t < bound``, else ``t``: no branch.")
