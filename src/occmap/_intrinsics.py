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
