"""LLVM intrinsics the kernels need and Numba does not expose."""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.extending import intrinsic


@intrinsic
def prefetch_write(typingctx, arr, idx):
    """Ask the CPU to bring the cache line of ``arr[idx]`` in, for writing (x86 ``prefetchw``).
    A hint only: no bounds check, and an address outside the array never faults."""
    if not isinstance(arr, types.Array) or not isinstance(idx, types.Integer):
        return None

    def codegen(context, builder, signature, args):
        ary = context.make_array(signature.args[0])(context, builder, args[0])
        i8p = ir.IntType(8).as_pointer()
        i32 = ir.IntType(32)
        fnty = ir.FunctionType(ir.VoidType(), [i8p, i32, i32, i32])
        fn = builder.module.declare_intrinsic("llvm.prefetch", (i8p,), fnty)
        ptr = builder.bitcast(builder.gep(ary.data, [args[1]]), i8p)
        builder.call(fn, [ptr, ir.Constant(i32, 1), ir.Constant(i32, 3), ir.Constant(i32, 1)])  # write, keep, data
        return context.get_dummy_value()

    return types.void(arr, idx), codegen


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
