"""The averaged pulse's sums on the GPU: fixed-point integers added in realisation order.

One thread per (grid time, granule) adds round(v 2^bits) and round(v^2 2^bits) of the successful
realisations of a launch, in realisation order: integer sums, exact, so a run repeated gives the same
bits, and the same sums as the CPU kernels (``kernels.batch.accumulate_fixed_point``) for the same
velocities. No floating-point atomics. The aligned pulse's sums likewise, one thread per (lag, granule)
(``kernels.aligned``).
"""

from __future__ import annotations

from numba import cuda, int64

from ..._status import SUCCESS
from ..kernels import aligned as _aligned
from .device import cpu_source, rint

#: ``kernels.aligned.grid_value``, a realisation's velocity between its grid samples (cubic Lagrange): the CPU's
#: own function compiled for the GPU.
grid_value = cpu_source(_aligned.grid_value)

def make_sum_kernel():
    """The fixed-point sums of the averaged pulse over a batch: thread (g, q) adds round(v 2^bits) and
    round(v^2 2^bits) of the successful realisations, in realisation order (integers: exact, and the
    same sums as ``kernels.batch.accumulate_fixed_point``)."""

    @cuda.jit
    def sums(grid_v, status, scale, sum_v, sum_v2):
        T = grid_v.shape[1]
        K = grid_v.shape[2]
        idx = cuda.grid(1)
        if idx >= T * K:
            return
        g = idx // K
        q = idx - g * K
        s1 = int64(0)
        s2 = int64(0)
        for r in range(grid_v.shape[0]):
            if status[r] == SUCCESS:
                w = grid_v[r, g, q]
                if w != 0.0:
                    s1 += int64(rint(w * scale))
                    s2 += int64(rint(w * w * scale))
        sum_v[g, q] += s1
        sum_v2[g, q] += s2

    return sums


def make_wall_sum_kernel():
    """The wall force's fixed-point sum on the grid (``kernels.batch.accumulate_fixed_point_1d``)."""

    @cuda.jit
    def sums(grid_f, status, scale, sum_f):
        g = cuda.grid(1)
        if g >= grid_f.shape[1]:
            return
        s = int64(0)
        for r in range(grid_f.shape[0]):
            if status[r] == SUCCESS:
                w = grid_f[r, g]
                if w != 0.0:
                    s += int64(rint(w * scale))
        sum_f[g] += s

    return sums


def make_aligned_sum_kernel():
    """The aligned pulse's fixed-point sums over a batch (``kernels.aligned.accumulate_aligned``): thread (l, q)
    adds round(w 2^bits) and round(w^2 2^bits), w = v_q(t_q^peak + lags[l]) interpolated from the realisation's
    grid velocities, of the successful realisations (integers: exact, in any order of the rows)."""

    @cuda.jit
    def sums(grid_v, peak_t, status, t_grid, lags, scale, sum_a, sum_a2):
        K = grid_v.shape[2]
        idx = cuda.grid(1)
        if idx >= lags.shape[0] * K:
            return
        lag = idx // K
        q = idx - lag * K
        s1 = int64(0)
        s2 = int64(0)
        for r in range(grid_v.shape[0]):
            if status[r] == SUCCESS:
                w = grid_value(t_grid, grid_v[r], q, peak_t[r, q] + lags[lag])
                if w != 0.0:
                    s1 += int64(rint(w * scale))
                    s2 += int64(rint(w * w * scale))
        sum_a[lag, q] += s1
        sum_a2[lag, q] += s2

    return sums
