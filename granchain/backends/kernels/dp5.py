"""Dormand-Prince 5(4): the tableau, the stages, the error estimate and the dense output.

Coefficients: J. R. Dormand and P. J. Prince, J. Comput. Appl. Math. 6, 19 (1980); continuous
extension of order 4 from L. F. Shampine, Math. Comp. 46, 135 (1986) (the same tables as
``scipy.integrate.RK45``). The step loop that runs them is ``rkloop``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .forces import accelerations
from .jit import JIT_INLINE, JIT_INTERNAL

# The scheme's constants (``schemes.Scheme``: what the generic step loop ``rkloop`` is specialised on).
ORDER = 5
#: The embedded error estimate is O(h^5) (5th- minus 4th-order solution): the PI controller's exponent.
ERROR_ORDER = 5
#: Force evaluations per step (stages 2..7; the 7th is the next step's first, FSAL).
EVALUATIONS = 6
#: The dense output is the stages themselves: nothing to lay out before it is read.
LAZY_DENSE = False
#: One set of dense-output weights for positions and velocities.
SEPARATE_VELOCITY_WEIGHTS = False
#: The step's end velocities are the last stage's, Kx[6] (FSAL).
END_IN_STAGE = True
#: The stages pass their velocities to the forces (damping laws) and report the dissipated power.
VELOCITY_FORCES = True

# Butcher tableau (rows: stages 2..6; stage 7 is the solution, FSAL).
A = np.array(
    [
        [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [1 / 5, 0.0, 0.0, 0.0, 0.0, 0.0],
        [3 / 40, 9 / 40, 0.0, 0.0, 0.0, 0.0],
        [44 / 45, -56 / 15, 32 / 9, 0.0, 0.0, 0.0],
        [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729, 0.0, 0.0],
        [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656, 0.0],
        [35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84],
    ]
)
# Error weights: (5th-order - 4th-order embedded) solution, over stages 1..7.
E = np.array([-71 / 57600, 0.0, 71 / 16695, -71 / 1920, 17253 / 339200, -22 / 525, 1 / 40])
# Dense output: y(t + theta h) = y + h sum_s K_s sum_p P[s, p] theta^(p+1).
P = np.array(
    [
        [1.0, -8048581381 / 2820520608, 8663915743 / 2820520608, -12715105075 / 11282082432],
        [0.0, 0.0, 0.0, 0.0],
        [0.0, 131558114200 / 32700410799, -68118460800 / 10900136933, 87487479700 / 32700410799],
        [0.0, -1754552775 / 470086768, 14199869525 / 1410260304, -10690763975 / 1880347072],
        [0.0, 127303824393 / 49829197408, -318862633887 / 49829197408, 701980252875 / 199316789632],
        [0.0, -282668133 / 205662961, 2019193451 / 616988883, -1453857185 / 822651844],
        [0.0, 40617522 / 29380423, -110615467 / 29380423, 69997945 / 29380423],
    ]
)


@njit(**JIT_INTERNAL)
def dense_weights(theta, Q):
    """Q[s] = sum_p P[s, p] theta^(p+1), so that y(theta) = y + h sum_s K_s Q[s]."""
    for s in range(7):
        Q[s] = theta * (P[s, 0] + theta * (P[s, 1] + theta * (P[s, 2] + theta * P[s, 3])))


@njit(**JIT_INLINE)
def weights(theta, Qx, Qv):
    """The scheme's dense-output weights (``schemes``): one set, in ``Qx`` (``Qv`` is ``Qx`` where the
    step loop reads velocities: ``SEPARATE_VELOCITY_WEIGHTS`` False)."""
    dense_weights(theta, Qx)


@njit(**JIT_INLINE)
def dense_data(x, v, xs, vs, Kx, Kv, h, hi):
    """Nothing to lay out: DP5's dense output is its stages (``LAZY_DENSE`` False; the step loop never
    calls this, which exists so that every scheme has the same functions)."""


# Coefficients as scalars so that Numba folds them into the unrolled stages.
A21 = A[1, 0]
A31, A32 = A[2, 0], A[2, 1]
A41, A42, A43 = A[3, 0], A[3, 1], A[3, 2]
A51, A52, A53, A54 = A[4, 0], A[4, 1], A[4, 2], A[4, 3]
A61, A62, A63, A64, A65 = A[5, 0], A[5, 1], A[5, 2], A[5, 3], A[5, 4]
B1, B3, B4, B5, B6 = A[6, 0], A[6, 2], A[6, 3], A[6, 4], A[6, 5]
E1, E3, E4, E5, E6, E7 = E[0], E[2], E[3], E[4], E[5], E[6]


@njit(**JIT_INLINE)
def stages(x, v, Kx, Kv, xs, vs, h, hi, fm, F, Pd, general):
    """Stages 2..7 of one step over granules 0..hi-1 (each stage's arithmetic written out, so that it
    vectorises with its coefficients folded).

    Kx[s] are the stage velocities (dx/dt), Kv[s] the stage accelerations, Pd[s] the power the
    contacts dissipate at the stage (0 for elastic contacts; a viscoelastic force reads the stage
    velocities Kx[s]); ``fm``: the forces' parameters (``records.Forces``). On return xs, vs hold the
    5th-order solution and Kx[6], Kv[6], Pd[6] its derivative. ``general``: see ``forces.accelerations``;
    the paper's chain (``general`` False) reads no velocities and dissipates nothing, so it gets ``v``
    rather than a view of the stage velocities and writes no power: its compiled stages are those of
    DP5 before real contacts.
    """
    for s in range(1, 7):  # one call of the force routine below, so that it is inlined once
        if s == 1:
            for i in range(hi):
                xs[i] = x[i] + h * (A21 * Kx[0, i])
                Kx[1, i] = v[i] + h * (A21 * Kv[0, i])
        elif s == 2:
            for i in range(hi):
                xs[i] = x[i] + h * (A31 * Kx[0, i] + A32 * Kx[1, i])
                Kx[2, i] = v[i] + h * (A31 * Kv[0, i] + A32 * Kv[1, i])
        elif s == 3:
            for i in range(hi):
                xs[i] = x[i] + h * (A41 * Kx[0, i] + A42 * Kx[1, i] + A43 * Kx[2, i])
                Kx[3, i] = v[i] + h * (A41 * Kv[0, i] + A42 * Kv[1, i] + A43 * Kv[2, i])
        elif s == 4:
            for i in range(hi):
                xs[i] = x[i] + h * (A51 * Kx[0, i] + A52 * Kx[1, i] + A53 * Kx[2, i] + A54 * Kx[3, i])
                Kx[4, i] = v[i] + h * (A51 * Kv[0, i] + A52 * Kv[1, i] + A53 * Kv[2, i] + A54 * Kv[3, i])
        elif s == 5:
            for i in range(hi):
                xs[i] = x[i] + h * (A61 * Kx[0, i] + A62 * Kx[1, i] + A63 * Kx[2, i] + A64 * Kx[3, i] + A65 * Kx[4, i])
                Kx[5, i] = v[i] + h * (A61 * Kv[0, i] + A62 * Kv[1, i] + A63 * Kv[2, i] + A64 * Kv[3, i] + A65 * Kv[4, i])
        else:
            for i in range(hi):
                xs[i] = x[i] + h * (B1 * Kx[0, i] + B3 * Kx[2, i] + B4 * Kx[3, i] + B5 * Kx[4, i] + B6 * Kx[5, i])
                vs[i] = v[i] + h * (B1 * Kv[0, i] + B3 * Kv[2, i] + B4 * Kv[3, i] + B5 * Kv[4, i] + B6 * Kv[5, i])
                Kx[6, i] = vs[i]
        power = accelerations(xs, Kx[s] if general else v, fm, hi, F, Kv[s], general)
        if general:
            Pd[s] = power


@njit(**JIT_INLINE)
def dissipated(Pd, h):
    """The energy dissipated over a step, by the 5th-order quadrature of the stages' powers (the
    weights of the solution): the dissipated energy is one more component of the state, integrated
    with it (its error is then of the method's order, and the energy balance checks it)."""
    return h * (B1 * Pd[0] + B3 * Pd[2] + B4 * Pd[3] + B5 * Pd[4] + B6 * Pd[5])


@njit(**JIT_INLINE)
def dissipated_error_ratio(Pd, h, e, rtol, atol):
    """The embedded error of :func:`dissipated` over tolerance, as for every other component: the
    dissipated energy is a component of the state, and its error must steer the step too. Without it a
    contact whose force is clamped at 0 (the spheres separate, nothing accelerates) lets the steps grow
    while the power c delta^(n-1) |d(delta)/dt| it dissipates runs to 0 with a kink where the contact
    opens, and the quadrature misses it (measured: 3e-4 of the dissipated energy of one collision,
    whatever the tolerance)."""
    return over_tolerance(dissipated_error(Pd, h), e, rtol, atol)


@njit(**JIT_INLINE)
def over_tolerance(error, e, rtol, atol):
    """|``error``| over the tolerance atol + rtol |e| of a component of value ``e`` (the GPU kernels call it with the
    dissipated energy's error summed over a chain's threads)."""
    return abs(error) / (atol + rtol * abs(e))


@njit(**JIT_INLINE)
def dissipated_error(Pd, h):
    """The embedded error of :func:`dissipated` (5th- minus 4th-order quadrature of the stages' powers)."""
    return h * (E1 * Pd[0] + E3 * Pd[2] + E4 * Pd[3] + E5 * Pd[4] + E6 * Pd[5] + E7 * Pd[6])


@njit(**JIT_INLINE)
def error_ratios(x, v, xs, vs, Kx, Kv, h, hi, relaxed, factor, rtol, atol, ratio):
    """DP5's error ratios of positions (ratio[0:hi]) and velocities (ratio[hi:2 hi]), see ``rkloop.max_ratio``."""
    for i in range(hi):  # positions, then velocities: two loops of few streams each vectorise
        w = factor if i < relaxed else 1.0
        ex = h * (E1 * Kx[0, i] + E3 * Kx[2, i] + E4 * Kx[3, i] + E5 * Kx[4, i] + E6 * Kx[5, i] + E7 * Kx[6, i])
        ratio[i] = abs(ex) / ((atol + rtol * max(abs(x[i]), abs(xs[i]))) * w)
    rv = ratio[hi:]
    for i in range(hi):
        w = factor if i < relaxed else 1.0
        ev = h * (E1 * Kv[0, i] + E3 * Kv[2, i] + E4 * Kv[3, i] + E5 * Kv[4, i] + E6 * Kv[5, i] + E7 * Kv[6, i])
        rv[i] = abs(ev) / ((atol + rtol * max(abs(v[i]), abs(vs[i]))) * w)
