"""The one compiled entry point for a single chain: a :data:`~.records.Method` picks the kernel.

``simulate`` and the ensemble kernel (``batch``) both call :func:`integrate_chain`, so a
realisation of an ensemble is integrated by exactly the code (and to the bit) that ``simulate``
uses. A new compiled method adds its kind (``records.KIND_*``), a branch here and its binding in
``granchain.backends.numba_backend``. (A kernel factory closing over the single-chain function would
be tidier, but Numba cannot cache closures across processes: every Dask worker and CLI start would
recompile the parallel kernel.)

The common contract of every single-chain kernel: integrate ``model`` from ``state`` at t = 0,
record the observed granules' peaks, their velocities on the grid, every contact's peak force, the
wall force on the grid when the chain ends in a wall, fill ``info`` (``records.INFO_*``) and return a
status code (``granchain._status``).
"""

from __future__ import annotations

from numba import njit

from .jit import JIT
from .records import KIND_DP5, KIND_RKN4, KIND_VERLET, Steps
from .rkloop import rk_integrate
from .verlet import verlet_integrate

#: Returned for a kind that names no kernel (the Python layer never passes one).
UNKNOWN_KIND = -2


@njit(**JIT)
def integrate_chain(method, model, run, state, out):
    """Integrate one chain with ``method`` (``records.Method``; the other records: see ``records``).

    DP5 and RKN4 (one step loop, ``rkloop.rk_integrate``): params = [rtol, atol, first_step,
    fixed_step (0: adaptive), relaxed_lag, relaxed_factor, window_lag (lags 0: off)]; Verlet:
    params = [dt].
    """
    kind, params = method
    if kind == KIND_DP5 or kind == KIND_RKN4:
        steps = Steps(params[0], params[1], params[2], params[3], int(params[4]), params[5], int(params[6]))
        return rk_integrate(kind, steps, model, run, state, out)
    if kind == KIND_VERLET:
        return verlet_integrate(params[0], model, run, state, out)
    return UNKNOWN_KIND
