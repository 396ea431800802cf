"""Code-generation hints for the numba kernels: a software prefetch (LLVM's ``llvm.prefetch``)
and an opaque copy of a float that keeps a computation where it is written.

On a grid larger than the core's cache, the general Monte Carlo kernel waits mostly on
memory: the deposit's read-modify-write of ``acc[j]`` and the look-ups of the voxel's
medium and safety distance land on lines that are rarely cached. The kernel asks for
those lines one interaction ahead (:mod:`mcmatlab_py.monte_carlo._kernel`,
:func:`deposit_late`), so that the wait overlaps the work of the next free path.
"""

import platform

import llvmlite
import numba
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

_NAME = ("llvm.prefetch.p0i8" if getattr(llvmlite, "ir_layer_typed_pointers_enabled", True)
         else "llvm.prefetch.p0")


@intrinsic
def prefetch(typingctx, arr, idx):
    """Prefetch the cache line of ``arr[idx]`` (1-D array, no bounds check: a prefetch of
    any address is harmless) for writing, to be kept in all cache levels."""
    sig = types.void(arr, idx)

    def codegen(context, builder, signature, args):
        aryty = signature.args[0]
        ary = context.make_array(aryty)(context, builder, args[0])
        ptr = cgutils.get_item_pointer(context, builder, aryty, ary, [args[1]],
                                       wraparound=False)
        i8p = ir.IntType(8).as_pointer()
        i32 = ir.IntType(32)
        fnty = ir.FunctionType(ir.VoidType(), [i8p, i32, i32, i32])
        fn = cgutils.get_or_insert_function(builder.module, fnty, _NAME)
        # (address, 1: for writing, 3: keep in all levels, 1: data)
        builder.call(fn, [builder.bitcast(ptr, i8p), i32(1), i32(3), i32(1)])
        return context.get_dummy_value()

    return sig, codegen


@numba.njit(cache=True, inline="always")
def deposit_late(acc, M, safe, pj, pdep, j, dep):
    """Add the pending deposit ``pdep`` to ``acc[pj]`` and make ``dep`` in voxel ``j`` the
    pending one: ``(j, dep)``. Its line of ``acc``, and those the next move's look-ups may
    read in voxel ``j``, are fetched meanwhile (:func:`prefetch`)."""
    acc[pj] += pdep
    prefetch(acc, j)
    prefetch(M, j)
    prefetch(safe, j)
    return j, dep


#: an inline-asm register constraint for a float: SSE on x86-64, SIMD on AArch64 (elsewhere
#: a general-purpose register, which costs two moves)
_FLOAT_REG = {"x86_64": "x", "AMD64": "x", "aarch64": "w", "arm64": "w"}.get(platform.machine(),
                                                                            "r")


@intrinsic
def opaque(typingctx, x):
    """``x`` (float64) unchanged, through an empty inline assembly statement that the
    optimiser cannot see through, move or remove. What is computed from it stays in the
    branch where it is written: LLVM would otherwise hoist a speculatable division by a
    direction component (fast-math's reciprocal) out of the transport loop, to be paid at
    every change of direction instead of where it is used
    (:func:`mcmatlab_py.monte_carlo._steps._reciprocals`)."""
    if x != types.float64:
        return None
    sig = types.float64(types.float64)

    def codegen(context, builder, signature, args):
        fnty = ir.FunctionType(ir.DoubleType(), [ir.DoubleType()])
        return builder.asm(fnty, "", f"={_FLOAT_REG},0", [args[0]], side_effect=True)

    return sig, codegen
