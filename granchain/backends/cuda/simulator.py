"""Warp shuffles for Numba's CUDA simulator (``NUMBA_ENABLE_CUDASIM=1``), which has none.

The GPU kernels exchange neighbours' positions and reduce the error norm with ``cuda.shfl_*_sync``; the
simulator, which runs a kernel's threads as Python threads, lacks those intrinsics. :func:`install`
adds them to its fake ``cuda`` module, each a block-wide exchange between two barriers (the kernels
that shuffle run one warp per block, so block and warp coincide): slow, but the same code as on the GPU,
so that machines without one (CI) test the shuffle path too. Nothing happens outside the simulator.
"""

from __future__ import annotations

import threading


def _exchange(module, value, source_lane):
    """Every thread of the block offers ``value`` and receives the value of ``source_lane(lane)`` in its warp."""
    thread = threading.current_thread()
    tid = thread.thread_id
    lane = tid % 32
    slots = module.__dict__.setdefault("_granchain_shuffle", {})
    thread.syncthreads()
    slots[tid] = value
    thread.syncthreads()
    got = slots[tid - lane + source_lane(lane)]
    return got


def install() -> None:
    """Add ``shfl_sync``, ``shfl_up_sync``, ``shfl_down_sync`` and ``shfl_xor_sync`` to the simulator's
    fake ``cuda`` module (once; a no-op outside the simulator, or where it has them)."""
    from numba import config

    if not config.ENABLE_CUDASIM:
        return
    from numba.cuda.simulator import kernelapi

    module = kernelapi.FakeCUDAModule
    if hasattr(module, "shfl_sync"):
        return
    module.shfl_sync = lambda self, mask, value, src: _exchange(self, value, lambda lane: src)
    module.shfl_up_sync = lambda self, mask, value, delta: _exchange(
        self, value, lambda lane: lane - delta if lane >= delta else lane)
    module.shfl_down_sync = lambda self, mask, value, delta: _exchange(
        self, value, lambda lane: lane + delta if lane + delta < 32 else lane)
    module.shfl_xor_sync = lambda self, mask, value, bits: _exchange(self, value, lambda lane: lane ^ bits)
