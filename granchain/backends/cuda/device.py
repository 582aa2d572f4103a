"""The GPU kernels' device functions: the contact force, the quintic Hermite dense output and the root
search on it, and the small rules the step loop shares with the CPU kernels (``kernels.dense``,
``kernels.window``), written for CUDA because a GPU kernel cannot call the CPU's compiled functions.

Each is the CPU kernels' function of the same name, to rounding (``tests/test_cuda.py`` holds them to the
CPU's numbers in Numba's simulator); ``hermite_max_estimate`` is the CPU's own source compiled for the GPU.
"""

from __future__ import annotations

import math
import types

from numba import cuda, int32, int64

from ..kernels import dense as _dense
from ..kernels import forces as _forces
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


def cpu_source(func, **callees):
    """The CPU kernels' function ``func`` (a Numba dispatcher) compiled for the GPU from its own source, the
    functions it calls (``callees``, by name) bound to their GPU versions: one text for both targets."""
    py = func.py_func
    scope = dict(py.__globals__, **callees)
    return cuda.jit(device=True)(types.FunctionType(py.__code__, scope, py.__name__, py.__defaults__, py.__closure__))


# -- Contacts that yield (C. Thornton, J. Appl. Mech. 64, 383 (1997): ``granchain.model.contacts.ElasticPlastic``) --
# ``yld`` is the (2, M) array of the contacts' yield overlaps delta_y,j (row 0) and histories, their largest
# overlaps so far (row 1), or None in a kernel compiled for contacts without memory (pruned as ``pre`` is, below).

#: ``kernels.forces.unloading_curve``, ``plastic_force`` and ``plastic_work``: the CPU's own functions.
unloading_curve = cpu_source(_forces.unloading_curve)
plastic_force = cpu_source(_forces.plastic_force, unloading_curve=unloading_curve)
plastic_work = cpu_source(_forces.plastic_work)


@cuda.jit(device=True)
def elastic_force(d, j, c, n, yld):
    """The force of contact j (prefactor ``c``) at compression ``d`` by a law of the positions alone: c d^(n-1)
    (Eq. motion_rescaled), or with ``yld`` Thornton's force from the contact's history (``plastic_force``)."""
    if yld is None:
        return contact_force(d, c, n)
    return plastic_force(d, yld[1, j], c, yld[0, j])


# -- A precompressed chain (``kernels.forces``: displacements from the static state) -------------------------
# ``pre`` is the (2, M) array of the contacts' static overlaps delta0_j (row 0) and static forces f0_j (row 1),
# or None in a kernel compiled for unloaded chains: Numba prunes the ``pre is None`` branches at compile time
# (the argument's type is NoneType), so those kernels hold the same machine code as before precompression.

@cuda.jit(device=True)
def compression(D, j, pre):
    """Contact j's compression from the relative displacement ``D`` = x_j - x_{j+1}: delta0_j + D in a
    precompressed chain (``kernels.forces.accelerations``: the static overlap included), else D."""
    if pre is None:
        return D
    return pre[0, j] + D


@cuda.jit(device=True)
def dynamic(f, j, pre):
    """Contact j's dynamic force: its force ``f`` less its static force f0_j (exactly 0 in the static state, so
    granules ahead of the pulse stay exactly at rest), else ``f``."""
    if pre is None:
        return f
    return f - pre[1, j]


@cuda.jit(device=True)
def static_state(c, load, law):
    """``kernels.forces.static_state``: (delta0, f0) of a contact of prefactor ``c`` in a chain precompressed by
    F0 = ``load``: delta0 = (F0 / c)^(1/(n-1)) (V. F. Nesterenko, *Dynamics of Heterogeneous Materials*, Springer
    2001, Sec. 1.1) and f0 its force by the kernels' own law and arithmetic (at rest: w = 0), F0 to rounding;
    (0, 0) for no contact (c = 0)."""
    if load <= 0.0 or c <= 0.0:
        return 0.0, 0.0
    d0 = (load / c) ** (1.0 / (law[0] - 1.0))
    if law[1] > 0.0:
        return d0, law_force(d0, 0.0, c, law)
    return d0, contact_force(d0, c, law[0])


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
def dense_compression(k, hx0, hv0, ha0, hx1, hv1, ha1, h, t, pre):
    """``kernels.dense.dense_compression``: contact k's compression at theta = t on the dense output, its static
    overlap included (``pre``: the static state of a precompressed chain, or None)."""
    return compression(dense_x(k, hx0, hv0, ha0, hx1, hv1, ha1, h, t) - dense_x(k + 1, hx0, hv0, ha0, hx1, hv1, ha1, h, t),
                       k, pre)


@cuda.jit(device=True)
def dense_acceleration(k, M, hx0, hv0, ha0, hx1, hv1, ha1, h, t, c_left, c_right, inv_m, n, pre, yld):
    """Acceleration of granule k from the dense-output positions of it and its neighbours (``pre``: the static
    state of a precompressed chain, or None; ``yld``: yielding contacts' state, or None)."""
    xk = dense_x(k, hx0, hv0, ha0, hx1, hv1, ha1, h, t)
    left = 0.0
    right = 0.0
    if k > 0:
        left = dynamic(elastic_force(compression(dense_x(k - 1, hx0, hv0, ha0, hx1, hv1, ha1, h, t) - xk, k - 1, pre),
                                     k - 1, c_left, n, yld), k - 1, pre)
    if k < M - 1:
        right = dynamic(elastic_force(compression(xk - dense_x(k + 1, hx0, hv0, ha0, hx1, hv1, ha1, h, t), k, pre),
                                      k, c_right, n, yld), k, pre)
    return (left - right) * inv_m


@cuda.jit(device=True)
def bracket_theta(lo, hi, f_lo, f_hi):
    """The next trial of :func:`root`'s search in the bracket [lo, hi] (values f_lo > 0, f_hi <= 0): regula
    falsi while f_hi < 0, else (an exact zero at hi: a contact that opened) bisection."""
    if f_hi < 0.0:
        theta = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
        if not (lo < theta < hi):
            theta = 0.5 * (lo + hi)
        return theta
    return 0.5 * (lo + hi)


@cuda.jit(device=True)
def bracket_update(f, theta, lo, hi, f_lo, f_hi, side):
    """The bracket after the trial ``theta`` gave ``f`` (Illinois: the end kept twice has its value halved)."""
    if f > 0.0:
        if side == -1:
            f_hi *= 0.5
        return theta, hi, f, f_hi, -1
    if side == 1:
        f_lo *= 0.5
    return lo, theta, f_lo, f, 1


# -- Contacts that dissipate (DP5 only: their forces read the velocities) -----------------------------------
# ``law`` is the tuple (n, gamma, viscous, clamp) of floats: the exponent, the damping constant, 1.0 for the
# viscous law of Rosas et al. (else Kuwabara-Kono's) and 1.0 where the force is clamped at 0 (``records.Params``).

@cuda.jit(device=True)
def law_force(d, w, c, law):
    """``kernels.forces.law_force`` of a damped law: for compression ``d`` > 0 closing at the rate ``w``, Kuwabara
    & Kono's c d^(n-2) (d + gamma w) or the viscous c d^(n-1) + gamma w of Rosas et al., clamped at 0 when
    ``clamp``; 0 for d <= 0 and for a contact of stiffness 0 (none: the edge of the trailing window)."""
    n = law[0]
    gamma = law[1]
    if d <= 0.0 or c == 0.0:
        return 0.0
    if law[2] > 0.0:
        f = contact_force(d, c, n) + gamma * w
    elif n == 2.5:
        f = c * math.sqrt(d) * (d + gamma * w)
    elif n == 2.0:
        f = c * (d + gamma * w)
    else:
        f = c * d ** (n - 2.0) * (d + gamma * w)
    if law[3] > 0.0:
        return max(f, 0.0)
    return f


@cuda.jit(device=True)
def force_rate(d, w, dw, c, law):
    """``kernels.forces.force_rate``: d/dt of :func:`law_force` (``dw`` the relative acceleration), where it falls
    from + to - the force peaks; 0 where the force is <= 0."""
    if d <= 0.0 or law_force(d, w, c, law) <= 0.0:
        return 0.0
    n = law[0]
    g = law[1]
    if law[2] > 0.0:
        if n == 2.5:
            return c * 1.5 * math.sqrt(d) * w + g * dw
        return c * (n - 1.0) * d ** (n - 2.0) * w + g * dw
    if n == 2.5:
        r = math.sqrt(d)
        return c * (1.5 * r * w + g * (0.5 * w * w / r + r * dw))
    return c * ((n - 1.0) * d ** (n - 2.0) * w + g * ((n - 2.0) * d ** (n - 3.0) * w * w + d ** (n - 2.0) * dw))


@cuda.jit(device=True)
def law_power(d, w, f, c, law):
    """The power a damped contact takes from the motion, (F - F_elastic) w for d > 0 (``forces.accelerations``)."""
    if d > 0.0:
        return (f - contact_force(d, c, law[0])) * w
    return 0.0


@cuda.jit(device=True)
def dense_law_force(k, hx0, hv0, ha0, hx1, hv1, ha1, h, t, c, law, pre):
    """``kernels.dense.dense_force`` of a damped law: contact k's force (stiffness ``c``) at theta = t, from the
    dense output's compression (its static overlap included) and its rate."""
    d = dense_compression(k, hx0, hv0, ha0, hx1, hv1, ha1, h, t, pre)
    return law_force(d, dense_v(k, hx0, hv0, ha0, hx1, hv1, ha1, h, t) - dense_v(k + 1, hx0, hv0, ha0, hx1, hv1, ha1, h, t),
                     c, law)


@cuda.jit(device=True)
def damped_acceleration(k, M, hx0, hv0, ha0, hx1, hv1, ha1, h, t, c_left, c_right, inv_m, law, pre):
    """:func:`dense_acceleration` by a damped law: the forces read the dense-output velocities too."""
    xk = dense_x(k, hx0, hv0, ha0, hx1, hv1, ha1, h, t)
    vk = dense_v(k, hx0, hv0, ha0, hx1, hv1, ha1, h, t)
    left = 0.0
    right = 0.0
    if k > 0:
        left = dynamic(law_force(compression(dense_x(k - 1, hx0, hv0, ha0, hx1, hv1, ha1, h, t) - xk, k - 1, pre),
                                 dense_v(k - 1, hx0, hv0, ha0, hx1, hv1, ha1, h, t) - vk, c_left, law), k - 1, pre)
    if k < M - 1:
        right = dynamic(law_force(compression(xk - dense_x(k + 1, hx0, hv0, ha0, hx1, hv1, ha1, h, t), k, pre),
                                  vk - dense_v(k + 1, hx0, hv0, ha0, hx1, hv1, ha1, h, t), c_right, law), k, pre)
    return (left - right) * inv_m


@cuda.jit(device=True)
def dense_force_rate(k, M, hx0, hv0, ha0, hx1, hv1, ha1, h, t, c_before, c_k, c_after, inv_m0, inv_m1, law, pre):
    """``kernels.dense.dense_force_rate``: the rate of contact k's force on the dense output, from the damped
    accelerations of granules k and k + 1 (``c_before``: contact k - 1's stiffness, 0 at the window's edge;
    ``c_after``: contact k + 1's, 0 past the chain)."""
    dw = (damped_acceleration(k, M, hx0, hv0, ha0, hx1, hv1, ha1, h, t, c_before, c_k, inv_m0, law, pre)
          - damped_acceleration(k + 1, M, hx0, hv0, ha0, hx1, hv1, ha1, h, t, c_k, c_after, inv_m1, law, pre))
    d = dense_compression(k, hx0, hv0, ha0, hx1, hv1, ha1, h, t, pre)
    w = dense_v(k, hx0, hv0, ha0, hx1, hv1, ha1, h, t) - dense_v(k + 1, hx0, hv0, ha0, hx1, hv1, ha1, h, t)
    return force_rate(d, w, dw, c_k, law)


# -- The root search on the dense output --------------------------------------------------------------------

#: What :func:`root` follows across a step (``kernels.dense``'s ROOT_*): a granule's acceleration (its velocity
#: maximum), a contact's relative velocity (its compression maximum), a granule's acceleration by a damped law,
#: or the rate of a damped contact's force (which peaks before the compression does).
ROOT_ACCELERATION = 0
ROOT_APPROACH = 1
ROOT_DAMPED_ACCELERATION = 2
ROOT_FORCE_RATE = 3


@cuda.jit(device=True)
def root(what, k, M, f_lo, f_hi, hx0, hv0, ha0, hx1, hv1, ha1, h, c_before, c_k, c_after, inv_m0, inv_m1, law, pre, yld):
    """First theta in [0, 1] where the followed function ``what`` (the ROOT_* above; f_lo > 0 its value at 0,
    f_hi <= 0 at 1) stops being positive, on the dense output (``kernels.dense.first_root``: Illinois while the
    bracket has a strictly negative end, bisection while it ends on an exact zero). For granule k:
    ``c_before``, ``c_k`` its left and right contacts' stiffness (0 for none), ``inv_m0`` its inverse mass; for
    the rate of contact k's force also ``c_after`` (contact k + 1's) and ``inv_m1`` (granule k + 1's); ``law``
    the contacts' (n, gamma, viscous, clamp), ``pre`` the static state of a precompressed chain (or None), ``yld``
    the yielding contacts' yield overlaps and histories (or None)."""
    lo = 0.0
    hi = 1.0
    side = 0
    for _ in range(200):
        theta = bracket_theta(lo, hi, f_lo, f_hi)
        if what == ROOT_ACCELERATION:
            f = dense_acceleration(k, M, hx0, hv0, ha0, hx1, hv1, ha1, h, theta, c_before, c_k, inv_m0, law[0], pre, yld)
        elif what == ROOT_APPROACH:
            f = (dense_v(k, hx0, hv0, ha0, hx1, hv1, ha1, h, theta)
                 - dense_v(k + 1, hx0, hv0, ha0, hx1, hv1, ha1, h, theta))
        elif what == ROOT_DAMPED_ACCELERATION:
            f = damped_acceleration(k, M, hx0, hv0, ha0, hx1, hv1, ha1, h, theta, c_before, c_k, inv_m0, law, pre)
        else:
            f = dense_force_rate(k, M, hx0, hv0, ha0, hx1, hv1, ha1, h, theta, c_before, c_k, c_after, inv_m0, inv_m1,
                                 law, pre)
        lo, hi, f_lo, f_hi, side = bracket_update(f, theta, lo, hi, f_lo, f_hi, side)
        if hi - lo < 1e-14:
            break
    return hi


@cuda.jit(device=True)
def falls(f0, f1):
    return f0 > 0.0 and f1 <= 0.0


#: ``kernels.dense.hermite_max_estimate`` (plain arithmetic): the CPU's own function compiled for the GPU.
hermite_max_estimate = cpu_source(_dense.hermite_max_estimate)
#: ``kernels.verlet.hermite``, the cubic Hermite interpolant through (y, y') at a step's ends that Verlet's
#: peaks and grid samples are read on: the CPU's own function compiled for the GPU.
hermite3 = cpu_source(_verlet.hermite)


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
