"""A software prefetch for the numba kernels (LLVM's ``llvm.prefetch``).

On a grid larger than the core's cache, the general Monte Carlo kernel waits mostly on
memory: the deposit's read-modify-write of ``acc[j]`` and the look-ups of the voxel's
medium and safety distance land on lines that are rarely cached. The kernel asks for
those lines one interaction ahead (:mod:`mcmatlab_py.monte_carlo._kernel`,
:func:`deposit_late`), so that the wait overlaps the work of the next free path.
"""

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
