"""The *aligned* pulse: each realisation's velocity at granule k on times relative to its own peak.

For lags tau_l the kernel adds round(v_k(t_peak[k] + tau_l) * scale) and its square into
int64 sums, like the averaged pulse <v_k(t)> (``_ensemble.accumulate_fixed_point``): the
aligned mean <v_k(t_k^peak + tau)> is then bitwise independent of threads, chunks and workers.
It is the pulse shape without the dephasing of realisations (level 1 of the
averaged-pulse decay; see :mod:`granchain.paper.dephasing`).

v_k(t_peak + tau) is interpolated from the realisation's velocities on the ensemble's time
grid (``grid_v`` (T, K), which the batch kernel has anyway) by the cubic Lagrange polynomial
through the four surrounding grid samples (linear on the first and last interval). Outside the
grid the velocity counts as 0: before t = 0 every observed granule but the struck one is at rest,
and after the integration stopped the grid holds zeros (the averaged pulse sees the same zeros).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .jit import JIT, JIT_INTERNAL


@njit(**JIT_INTERNAL)
def grid_value(t_grid, grid_v, q, t):
    """v_q(t) interpolated from grid_v[:, q] (cubic Lagrange on uniform or non-uniform grids)."""
    T = t_grid.shape[0]
    if T == 0 or t < t_grid[0] or t > t_grid[T - 1]:
        return 0.0
    if T == 1:
        return grid_v[0, q]
    # i: last grid index with t_grid[i] <= t (binary search), clipped to [0, T-2]
    lo, hi = 0, T - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if t_grid[mid] <= t:
            lo = mid
        else:
            hi = mid
    i = lo
    if i < 1 or i > T - 3:  # linear on the edge intervals
        j = min(i, T - 2)
        f = (t - t_grid[j]) / (t_grid[j + 1] - t_grid[j])
        return grid_v[j, q] + f * (grid_v[j + 1, q] - grid_v[j, q])
    x0, x1, x2, x3 = t_grid[i - 1], t_grid[i], t_grid[i + 1], t_grid[i + 2]
    y0, y1, y2, y3 = grid_v[i - 1, q], grid_v[i, q], grid_v[i + 1, q], grid_v[i + 2, q]
    l0 = (t - x1) * (t - x2) * (t - x3) / ((x0 - x1) * (x0 - x2) * (x0 - x3))
    l1 = (t - x0) * (t - x2) * (t - x3) / ((x1 - x0) * (x1 - x2) * (x1 - x3))
    l2 = (t - x0) * (t - x1) * (t - x3) / ((x2 - x0) * (x2 - x1) * (x2 - x3))
    l3 = (t - x0) * (t - x1) * (t - x2) / ((x3 - x0) * (x3 - x1) * (x3 - x2))
    return l0 * y0 + l1 * y1 + l2 * y2 + l3 * y3


@njit(**JIT)
def accumulate_aligned(t_grid, grid_v, peak_t, lags, scale, acc1, acc2):
    """acc1[l, q] += round(v_q(peak_t[q] + lags[l]) * scale), acc2 likewise with v^2 (int64, (L, K)).

    Does nothing for an empty ``lags`` (ensembles without the aligned pulse)."""
    L = lags.shape[0]
    K = grid_v.shape[1]
    for q in range(K):
        for l in range(L):
            w = grid_value(t_grid, grid_v, q, peak_t[q] + lags[l])
            if w != 0.0:
                acc1[l, q] += np.int64(np.rint(w * scale))
                acc2[l, q] += np.int64(np.rint(w * w * scale))
