"""The ensemble's work queue: each thread of the parallel loop takes the next realisation when it is free.

Numba's ``prange`` splits its iterations into one contiguous block per thread, whatever
``numba.parallel_chunksize`` says (measured with Numba 0.68 under its OpenMP and workqueue layers: a loop
whose first half costs 100x its second ran no faster on two threads than on one, with a chunk size of 1
or 4 as without). A batch of realisations of very different cost then leaves threads idle: the paper's
decorated N = 26 chains, split so over 16 threads, keep them busy 81 % of a 500-realisation chunk
(computed from 4,000 realisations' step counts), against 95 % taken one at a time in index order and
99 % taken longest first (``backends.longest_first``). So the loop runs one iteration per thread, and each
thread takes rows from a shared counter, incremented atomically (LLVM's ``atomicrmw add``), until none is
left.
"""

from __future__ import annotations

from numba import types
from numba.extending import intrinsic, overload

from .jit import JIT


@intrinsic
def _fetch_add_one(typingctx, counter):
    """counter[0] += 1 atomically (sequentially consistent); the value before."""
    if not (isinstance(counter, types.Array) and counter.dtype == types.int64):
        return None
    sig = types.int64(counter)

    def codegen(context, builder, signature, args):
        data = context.make_array(signature.args[0])(context, builder, args[0]).data
        return builder.atomic_rmw("add", data, context.get_constant(types.int64, 1), "seq_cst")

    return sig, codegen


def take(counter):
    """The next row of the queue whose count of rows taken is ``counter[0]`` (an int64 array, from 0): that
    count, incremented atomically, so that two threads never take the same row. Plain Python
    (``NUMBA_DISABLE_JIT``, no threads): the same, without atomicity."""
    j = int(counter[0])
    counter[0] = j + 1
    return j


@overload(take, jit_options=JIT)
def _take_compiled(counter):
    def impl(counter):
        return _fetch_add_one(counter)

    return impl
