"""Borrowed array views: passing arrays between compiled functions without reference counting."""

from __future__ import annotations

import numba
from numba import njit, types
from numba.core import errors
from numba.extending import intrinsic, overload

from .jit import JIT, JIT_INTERNAL


@intrinsic
def _data_pointer(typingctx, arr):
    """The data pointer of an array (for :func:`borrowed`)."""
    sig = types.CPointer(arr.dtype)(arr)

    def codegen(context, builder, signature, args):
        return context.make_array(signature.args[0])(context, builder, args[0]).data

    return sig, codegen


def borrowed(a):
    """A view of ``a`` that does not own its memory (compiled: ``numba.carray`` on its data pointer), so
    that passing it to a function costs no reference counting. Numba passes every owning array with an
    atomic increment and decrement of its reference count (NRT); in DP5's step loop, whose helpers see a
    dozen arrays every step, that was half of the run time (profiled with perf).

    The caller must keep ``a`` alive for as long as the view is used (:func:`keep_alive`); the
    arguments of a function are kept alive by its caller. Plain Python (``NUMBA_DISABLE_JIT``): ``a``."""
    return a


@overload(borrowed, jit_options=JIT)
def _borrowed_compiled(a):
    if not (isinstance(a, types.Array) and a.layout == "C"):  # carray assumes C order
        raise errors.TypingError(f"borrowed() takes a C-contiguous array, got {a}")

    def impl(a):
        return numba.carray(_data_pointer(a), a.shape)

    return impl


@njit(**JIT_INTERNAL)
def keep_alive(*arrays):
    """Does nothing: a use of ``arrays`` after the last use of their :func:`borrowed` views, so that
    Numba releases them only after that."""
    return None
