"""The one seam between integrator objects and compiled code: a kernel id picks the
single-chain kernel, and a float64 array carries its settings.

``granchain.DP5`` and ``granchain.Verlet`` name their kernel by id and pack their
settings with ``kernel_params()``; ``simulate`` and the ensemble kernel both call
:func:`integrate_chain`, so a realisation of an ensemble is integrated by exactly the
code (and to the bit) that ``simulate`` uses. A new compiled integrator adds its id and a
branch here, and its Python class; nothing else changes. (A kernel factory closing over the
single-chain function would be tidier, but Numba cannot cache closures across processes:
every Dask worker and CLI start would recompile the parallel kernel.)

The common contract of every single-chain kernel: integrate from (x, v) at t = 0, record the
observed granules' peaks (``peak_v``, ``peak_t``), their velocities on ``t_grid`` into
``grid_v`` (time-major), every contact's peak force (``peak_f``, ``peak_ft``, M-1 each), the
wall force on ``t_grid`` into ``grid_f`` when the last granule is a wall, fill ``info`` (slots ``INFO_*`` of ``_common``) and return a status
code (``granchain._status``).
"""

from __future__ import annotations

from numba import njit

from ._dp5 import METHOD_DP5, METHOD_RKN4, rk_integrate
from ._jit import JIT
from ._verlet import verlet_integrate

#: Kernel ids (``kernel_id`` of the integrator classes).
KERNEL_DP5 = 0
KERNEL_VERLET = 1
KERNEL_RKN4 = 2
KERNEL_IDS = (KERNEL_DP5, KERNEL_VERLET, KERNEL_RKN4)

#: Returned for a kernel id that names no kernel (the Python layer never passes one).
UNKNOWN_KERNEL = -2


@njit(**JIT)
def integrate_chain(kernel, params, m, c, n, pw, obs, t_max, stop_at_exit, exit_margin, max_steps, peak_rtol, t_grid,
                    x, v, peak_v, peak_t, grid_v, peak_f, peak_ft, grid_f, info):
    """Integrate one chain with kernel ``kernel`` and settings ``params`` (see the module doc).

    DP5 and RKN4 (one step loop, ``_dp5.rk_integrate``): params = [rtol, atol, first_step, fixed_step
    (0: adaptive), relaxed_lag, relaxed_factor, window_lag (lags 0: off)]; Verlet: params = [dt].
    """
    if kernel == KERNEL_DP5 or kernel == KERNEL_RKN4:
        method = METHOD_RKN4 if kernel == KERNEL_RKN4 else METHOD_DP5
        return rk_integrate(method, m, c, n, pw, obs, params[0], params[1], params[2], params[3], int(params[4]),
                            params[5], int(params[6]), t_max, stop_at_exit, exit_margin, max_steps, peak_rtol, t_grid,
                            x, v, peak_v, peak_t, grid_v, peak_f, peak_ft, grid_f, info)
    if kernel == KERNEL_VERLET:
        return verlet_integrate(m, c, n, pw, obs, params[0], t_max, stop_at_exit, exit_margin, max_steps, peak_rtol,
                                t_grid, x, v, peak_v, peak_t, grid_v, peak_f, peak_ft, grid_f, info)
    return UNKNOWN_KERNEL
