"""The GPU kernels' device functions: the contact force, the quintic Hermite dense output and the root
search on it, and the small rules the step loop shares with the CPU kernels (``kernels.dense``,
``kernels.window``), written for CUDA because a GPU kernel cannot call the CPU's compiled functions.

Each is the CPU kernels' function of the same name, to rounding (``tests/test_cuda.py`` holds them to the
CPU's numbers in Numba's simulator); ``hermite_max_estimate`` is the CPU's own source compiled for the GPU.
"""

from __future__ import annotations

import math

from numba import cuda, int32, int64

from ..kernels import dense as _dense
from ..kernels import verlet as _verlet

FULL_MASK = 0xFFFFFFFF  # every lane of a warp (the shuffle exchange)

@cuda.jit(device=True)
def contact_force(d, c, n):
    """c d^(n-1) for d > 0, else 0 (Eq. motion_rescaled; Hertz's power by a square root)."""
    if d <= 0.0:
        return 0.0
    if n == 2.5:
        return c * d * math.sqrt(d)
    if n == 2.0:
        return c * d
    return c * d ** (n - 1.0)


@cuda.jit(device=True)
def hermite_x(x0, v0, a0, x1, v1, a1, h, t):
    """Position at theta = t on the quintic Hermite interpolant through (x, v, a) at both ends of a step
    (``kernels.rkn4.weights``)."""
    t2 = t * t
    t3 = t2 * t
    t4 = t3 * t
    t5 = t4 * t
    q0 = t - 6 * t3 + 8 * t4 - 3 * t5
    q1 = 10 * t3 - 15 * t4 + 6 * t5
    q2 = 0.5 * t2 - 1.5 * t3 + 1.5 * t4 - 0.5 * t5
    q3 = 0.5 * t3 - t4 + 0.5 * t5
    q6 = -4 * t3 + 7 * t4 - 3 * t5
    return x0 + h * (v0 * q0 + (x1 - x0) / h * q1 + h * a0 * q2 + h * a1 * q3 + v1 * q6)


@cuda.jit(device=True)
def hermite_v(x0, v0, a0, x1, v1, a1, h, t):
    """Velocity (the derivative of :func:`hermite_x`) at theta = t."""
    t2 = t * t
    t3 = t2 * t
    t4 = t3 * t
    q0 = t - 4.5 * t2 + 6 * t3 - 2.5 * t4
    q1 = 30 * t2 - 60 * t3 + 30 * t4
    q2 = -18 * t2 + 32 * t3 - 15 * t4
    q3 = -12 * t2 + 28 * t3 - 15 * t4
    q6 = 1.5 * t2 - 4 * t3 + 2.5 * t4
    return v0 + h * (a0 * q0 + (x1 - x0) / (h * h) * q1 + v0 / h * q2 + v1 / h * q3 + a1 * q6)


@cuda.jit(device=True)
def dense_x(k, hx0, hv0, ha0, hx1, hv1, ha1, h, t):
    return hermite_x(hx0[k], hv0[k], ha0[k], hx1[k], hv1[k], ha1[k], h, t)


@cuda.jit(device=True)
def dense_v(k, hx0, hv0, ha0, hx1, hv1, ha1, h, t):
    return hermite_v(hx0[k], hv0[k], ha0[k], hx1[k], hv1[k], ha1[k], h, t)


@cuda.jit(device=True)
def dense_acceleration(k, M, hx0, hv0, ha0, hx1, hv1, ha1, h, t, c_left, c_right, inv_m, n):
    """Acceleration of granule k from the dense-output positions of it and its neighbours."""
    xk = dense_x(k, hx0, hv0, ha0, hx1, hv1, ha1, h, t)
    left = 0.0
    right = 0.0
    if k > 0:
        left = contact_force(dense_x(k - 1, hx0, hv0, ha0, hx1, hv1, ha1, h, t) - xk, c_left, n)
    if k < M - 1:
        right = contact_force(xk - dense_x(k + 1, hx0, hv0, ha0, hx1, hv1, ha1, h, t), c_right, n)
    return (left - right) * inv_m


@cuda.jit(device=True)
def root(what, k, M, f_lo, f_hi, hx0, hv0, ha0, hx1, hv1, ha1, h, c_left, c_right, inv_m, n):
    """First theta in [0, 1] where the followed function stops being positive (``kernels.dense.first_root``:
    Illinois while the bracket has a strictly negative end, bisection while it ends on an exact zero):
    ``what`` 0, granule k's acceleration (its velocity maximum); 1, contact k's relative velocity (its
    compression maximum)."""
    lo = 0.0
    hi = 1.0
    side = 0
    for _ in range(200):
        if f_hi < 0.0:
            theta = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
            if not (lo < theta < hi):
                theta = 0.5 * (lo + hi)
        else:
            theta = 0.5 * (lo + hi)
        if what == 0:
            f = dense_acceleration(k, M, hx0, hv0, ha0, hx1, hv1, ha1, h, theta, c_left, c_right, inv_m, n)
        else:
            f = (dense_v(k, hx0, hv0, ha0, hx1, hv1, ha1, h, theta)
                 - dense_v(k + 1, hx0, hv0, ha0, hx1, hv1, ha1, h, theta))
        if f > 0.0:
            lo = theta
            f_lo = f
            if side == -1:
                f_hi *= 0.5
            side = -1
        else:
            hi = theta
            f_hi = f
            if side == 1:
                f_lo *= 0.5
            side = 1
        if hi - lo < 1e-14:
            break
    return hi


@cuda.jit(device=True)
def falls(f0, f1):
    return f0 > 0.0 and f1 <= 0.0


#: ``kernels.dense.hermite_max_estimate`` (plain arithmetic): the CPU's own function compiled for the GPU.
hermite_max_estimate = cuda.jit(device=True)(_dense.hermite_max_estimate.py_func)
#: ``kernels.verlet.hermite``, the cubic Hermite interpolant through (y, y') at a step's ends that Verlet's
#: peaks and grid samples are read on: the CPU's own function compiled for the GPU.
hermite3 = cuda.jit(device=True)(_verlet.hermite.py_func)


@cuda.jit(device=True)
def rint(x):
    """Round half to even (NumPy's ``rint``, which the CPU kernels' fixed-point sums use)."""
    f = math.floor(x)
    d = x - f
    if d > 0.5 or (d == 0.5 and f - 2.0 * math.floor(0.5 * f) != 0.0):
        f += 1.0
    return f


@cuda.jit(device=True)
def cut_target(front, window_lag, windows, q_open, obs):
    """The granule the trailing window may cut behind: observed granule front - window_lag, never past
    one whose averaged-pulse window is still open (``q_open``); -1 while there is none."""
    if window_lag <= 0 or front < window_lag:
        return int64(-1)
    target = front - window_lag
    if windows:
        target = min(target, q_open)
    return obs[target]


@cuda.jit(device=True)
def warp_any(flag):
    """1 where ``flag`` is nonzero on any lane of the warp, else 0 (every lane gets it): one vote."""
    return int64(1) if cuda.ballot_sync(FULL_MASK, flag != 0) != 0 else int64(0)


@cuda.jit(device=True)
def warp_last(value):
    """The warp's maximum of ``value`` where it is -1 or grows with the lane (lane l's value is below lane
    l + 1's wherever both are >= 0): the value of the last lane that has one, or -1. One vote and one 32-bit
    shuffle (values below 2^31), against five rounds of 64-bit shuffles for a general maximum."""
    bits = cuda.ballot_sync(FULL_MASK, value >= 0)
    if bits == 0:
        return int64(-1)
    return int64(cuda.shfl_sync(FULL_MASK, int32(value), 31 - cuda.clz(bits)))
