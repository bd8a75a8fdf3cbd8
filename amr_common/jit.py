"""The one switch for the project's compiled loops: numba where installed, else plain Python.

The loops are the LiDAR and wall contacts of amr_sim and the wall follower's perception:
numba's njit, cached on disk, where numba is installed (a pinned dependency); the plain Python
function otherwise. No rclpy import.
"""
from __future__ import annotations

try:
    import numba

    HAVE_NUMBA = True
except ImportError:  # pragma: no cover - numba is a pinned dependency
    HAVE_NUMBA = False


def jit(function):
    """numba.njit(cache=True, nogil=True, error_model="numpy") if numba is there, else `function`.

    error_model="numpy": x/0 gives inf/nan instead of raising, as numpy does.
    """
    if not HAVE_NUMBA:
        return function
    return numba.njit(cache=True, nogil=True, error_model="numpy")(function)


def prefetch(array, index) -> None:
    """Ask the CPU to bring array.flat[index] into its caches; returns at once.

    In compiled kernels it is llvm.prefetch (a hint: never faults, even off the array); called
    from plain Python it does nothing. For loops over memory too large for the caches, where
    the address of a later iteration is known early (beam_model's global search).
    """


if HAVE_NUMBA:
    from llvmlite import ir
    from numba import types
    from numba.core import cgutils
    from numba.extending import intrinsic, overload

    @intrinsic
    def _llvm_prefetch(typingctx, array, index):
        def codegen(context, builder, signature, args):
            data = context.make_array(signature.args[0])(context, builder, args[0]).data
            byte_pointer = ir.IntType(8).as_pointer()
            int32 = ir.IntType(32)
            signature_ir = ir.FunctionType(ir.VoidType(), [byte_pointer, int32, int32, int32])
            function = cgutils.get_or_insert_function(builder.module, signature_ir,
                                                      "llvm.prefetch.p0i8")
            # read (0), keep in all cache levels (3), data cache (1)
            builder.call(function, [builder.bitcast(builder.gep(data, [args[1]]), byte_pointer),
                                    int32(0), int32(3), int32(1)])
            return context.get_dummy_value()
        return types.void(array, index), codegen

    @overload(prefetch, jit_options={"cache": True})
    def _prefetch_compiled(array, index):
        def implementation(array, index):
            _llvm_prefetch(array, index)
        return implementation
