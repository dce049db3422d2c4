"""LLVM intrinsics the kernels need and Numba does not expose."""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.extending import intrinsic


def _bit_count(name: str, doc: str):
    """An intrinsic on one integer that counts bits with LLVM's ``llvm.NAME`` (one instruction
    on x86-64): ``cttz`` trailing zeros, ``ctpop`` set bits, ``bit_length`` its width less
    ``ctlz``'s leading zeros. Zero is defined: ``cttz`` and ``ctlz`` give the width."""

    @intrinsic
    def count(typingctx, x):
        if not isinstance(x, types.Integer):
            return None

        def codegen(context, builder, signature, args):
            ty = args[0].type
            llvm = "ctlz" if name == "bit_length" else name
            if llvm == "ctpop":
                fn = builder.module.declare_intrinsic("llvm.ctpop", (ty,), ir.FunctionType(ty, [ty]))
                return builder.call(fn, [args[0]])
            fn = builder.module.declare_intrinsic(f"llvm.{llvm}", (ty,), ir.FunctionType(ty, [ty, ir.IntType(1)]))
            n = builder.call(fn, [args[0], ir.Constant(ir.IntType(1), 0)])
            return builder.sub(ir.Constant(ty, ty.width), n) if name == "bit_length" else n

        return x(x), codegen

    count.__doc__ = doc
    return count


bit_length = _bit_count("bit_length", "Number of bits needed to write the non-negative integer ``x`` (0 for 0): "
                                      "Python's ``int.bit_length``, one ``lzcnt`` instead of a loop.")
trailing_zeros = _bit_count("cttz", "Index of the lowest set bit of ``x`` (its width for 0).")
popcount = _bit_count("ctpop", "Number of set bits of ``x``.")


def _add_if(op: str, doc: str):
    @intrinsic
    def add_if(typingctx, t, bound, g):
        if not (t == types.float64 and bound == types.float64 and g == types.float64):
            return None

        def codegen(context, builder, signature, args):
            t, bound, g = args
            return builder.select(builder.fcmp_ordered(op, t, bound), builder.fadd(t, g), t)

        return types.float64(t, bound, g), codegen

    add_if.__doc__ = doc
    return add_if


# The compare and the select in one basic block let LLVM emit a compare mask and a masked move
# of t + g over t (the sum does not wait for the compare); written in Python, the same select
# becomes a branch.
add_if_le = _add_if("<=", "``t + g`` where ``t <= bound``, else ``t``: no branch.")
add_if_lt = _add_if("<", "``t + g`` where ``t < bound``, else ``t``: no branch.")


@intrinsic
def load_at(typingctx, buf, at, kind, swap):
    """The number of NumPy type ``kind`` (``np.float32``, ..., or an array's ``dtype``) whose
    bytes start at byte ``at`` of the uint8 array ``buf``, at any alignment (a message's fields lie
    where its bag put them), in the machine's byte order or, when ``swap``, the other: one
    unaligned load (and a byte swap), where copying the bytes to an aligned place first cost
    seven times as much."""
    if not (isinstance(buf, types.Array) and buf.dtype == types.uint8
            and isinstance(kind, (types.NumberClass, types.DType))):
        return None
    dtype = kind.dtype

    def codegen(context, builder, signature, args):
        data = context.make_array(signature.args[0])(context, builder, args[0]).data
        bits = ir.IntType(context.get_abi_sizeof(context.get_data_type(dtype)) * 8)
        raw = builder.load(builder.bitcast(builder.gep(data, [args[1]]), bits.as_pointer()), align=1)
        value = builder.select(args[3], builder.bswap(raw), raw) if bits.width > 8 else raw
        return builder.bitcast(value, context.get_value_type(dtype))

    return dtype(buf, types.intp, kind, types.boolean), codegen


@intrinsic
def prefetch(typingctx, arr, i):
    """Ask the CPU to bring element ``i`` of the C-contiguous array ``arr`` into its caches
    (LLVM's ``llvm.prefetch``, a read with temporal locality): a hint, which neither faults nor
    changes anything, so that a load a few steps later need not wait for memory."""
    if not (isinstance(arr, types.Array) and arr.layout == "C" and isinstance(i, types.Integer)):
        return None

    def codegen(context, builder, signature, args):
        data = context.make_array(signature.args[0])(context, builder, args[0]).data
        size = context.get_abi_sizeof(context.get_data_type(signature.args[0].dtype))
        byte = ir.IntType(8).as_pointer()
        offset = builder.mul(args[1], ir.Constant(args[1].type, size))
        at = builder.gep(builder.bitcast(data, byte), [offset])
        i32 = ir.IntType(32)
        fn = builder.module.declare_intrinsic("llvm.prefetch", (byte,), ir.FunctionType(ir.VoidType(), [byte] + [i32] * 3))
        builder.call(fn, [at, i32(0), i32(3), i32(1)])
        return context.get_dummy_value()

    return types.none(arr, i), codegen
