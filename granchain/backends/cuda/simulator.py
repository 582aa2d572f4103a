"""Warp shuffles and votes for Numba's CUDA simulator (``NUMBA_ENABLE_CUDASIM=1``), which has none.

The GPU kernels exchange neighbours' positions and reduce the error norm with ``cuda.shfl_*_sync``, and
take the step's integer decisions with ``cuda.ballot_sync``; the simulator, which runs a kernel's threads
as Python threads, lacks those intrinsics. :func:`install` adds them to its fake ``cuda`` module, each a
block-wide exchange between two barriers (the kernels that shuffle run one warp per block, so block and
warp coincide): slow, but the same code as on the GPU, so that machines without one (CI) test the
shuffle path too. Nothing happens outside the simulator.
"""

from __future__ import annotations

import threading


def _offer(module, value):
    """Every thread of the block offers ``value`` between two barriers (one warp per block: block and warp
    coincide); returns (what the threads offered, by thread id, this thread's warp's first id, its lane)."""
    thread = threading.current_thread()
    tid = thread.thread_id
    slots = module.__dict__.setdefault("_granchain_warp", {})
    thread.syncthreads()
    slots[tid] = value
    thread.syncthreads()
    return slots, tid - tid % 32, tid % 32


def _exchange(module, value, source_lane):
    """Every thread of the block offers ``value`` and receives the value of ``source_lane(lane)`` in its warp."""
    slots, base, lane = _offer(module, value)
    return slots[base + source_lane(lane)]


def _ballot(module, predicate):
    """The bits of the warp's lanes whose ``predicate`` holds (an unsigned 32-bit value, lane l at bit l)."""
    slots, base, _ = _offer(module, bool(predicate))
    return sum(1 << lane for lane in range(32) if slots.get(base + lane, False))


def install() -> None:
    """Add ``shfl_sync``, ``shfl_up_sync``, ``shfl_down_sync``, ``shfl_xor_sync`` and ``ballot_sync`` to the
    simulator's fake ``cuda`` module (those it lacks; a no-op outside the simulator)."""
    from numba import config

    if not config.ENABLE_CUDASIM:
        return
    from numba.cuda.simulator import kernelapi

    module = kernelapi.FakeCUDAModule
    emulations = {
        "shfl_sync": lambda self, mask, value, src: _exchange(self, value, lambda lane: src),
        "shfl_up_sync": lambda self, mask, value, delta: _exchange(
            self, value, lambda lane: lane - delta if lane >= delta else lane),
        "shfl_down_sync": lambda self, mask, value, delta: _exchange(
            self, value, lambda lane: lane + delta if lane + delta < 32 else lane),
        "shfl_xor_sync": lambda self, mask, value, bits: _exchange(self, value, lambda lane: lane ^ bits),
        "ballot_sync": lambda self, mask, predicate: _ballot(self, predicate),
    }
    for name, emulation in emulations.items():
        if not hasattr(module, name):  # a simulator that has one keeps its own
            setattr(module, name, emulation)
