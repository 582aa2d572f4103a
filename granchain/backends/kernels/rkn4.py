"""Runge-Kutta-Nystrom 4(3) for x'' = f(x): the stages, error estimate and dense output of the
embedded pair "RKN4(3)4FM" of J. R. Dormand, M. E. A. El-Mikkawy and P. J. Prince, IMA J. Numer.
Anal. 7, 235 (1987) (the same tables as ``DPRKN4`` of Julia's OrdinaryDiffEq). The step loop,
peaks, window and records are DP5's (``rkloop``, specialised on this module's scheme: ``schemes``);
this module only supplies what differs.

Why a Nystrom pair for granular chains: the equation of motion (Eq. motion_rescaled) is second
order with forces that do not depend on velocities, and a decorated chain's step is limited by the
oscillation of its light granules between heavy ones, i.e. by how far along the imaginary axis a
method stays stable and accurate per force evaluation, not by the tolerance. Four stages of which
the last is the force at the new position (reused as the first of the next step: three evaluations
per step, DP5 has six), and a periodicity interval h omega <= 3.77 in which the step matrix of
x'' = -omega^2 x has spectral radius exactly 1: a granule trapped between two heavy ones and
oscillating for thousands of steps neither grows nor decays. (DP5 grows by 3e-4 per step at
h omega = 1.2; the pair RKN6(4)6FM, tried first, grows slowly from h omega ~ 0.6, 4e-5 per step at
2, which its error estimate does not see: light granules blew up in ~1 % of the paper's N = 6
realisations.)

Stage s (0-based, c_0 = 0): x_s = x + c_s h v + h^2 sum_{j<s} a_sj f_j, f_s = f(x_s); the new state
x' = x + h v + h^2 sum b_s f_s (= x_3, so f_3 = f(x')), v' = v + h sum bp_s f_s.

Dense output: the quintic Hermite interpolant of the positions through (x, v, f) at both ends of
the step (positions to O(h^6), velocities, its derivative, to O(h^5); the method itself is of
order 4). It is stored in the slots of DP5's stage arrays so that the shared routines evaluate both
methods as y + h sum_s K[s] Q[s] (``dense.dense_value``), with separate weights for positions (``Qx``,
with ``Kx``) and velocities (``Qv``, with ``Kv``): see :func:`dense_data`.
"""

from __future__ import annotations

from numba import njit

from .forces import accelerations
from .jit import JIT_INLINE, JIT_INTERNAL

# The scheme's constants (``schemes.Scheme``: what the generic step loop ``rkloop`` is specialised on).
ORDER = 4
#: The embedded error estimate is O(h^4) (4th- minus 3rd-order solution): the PI controller's exponent.
ERROR_ORDER = 4
#: Force evaluations per step (stages 1..3; the last is the next step's first).
EVALUATIONS = 3
#: The dense output is laid out (:func:`dense_data`) only for the steps that read it.
LAZY_DENSE = True
#: Positions and velocities have their own dense-output weights (:func:`weights`).
SEPARATE_VELOCITY_WEIGHTS = True
#: The step's end velocities are in ``vs`` (copied into Kx[6] only with the dense output).
END_IN_STAGE = False
#: A method for x'' = f(x): the forces may not read velocities, and nothing is dissipated.
VELOCITY_FORCES = False

# Nodes and coupling (a_sj) of stages 1 and 2; stage 3 uses the position weights (c_3 = 1).
C1, C2 = 1 / 4, 7 / 10
A10 = 1 / 32
A20, A21 = 7 / 1000, 119 / 500
# Position weights b (b_3 = 0) and velocity weights bp of the 4th-order solution.
B0, B1, B2 = 1 / 14, 8 / 27, 25 / 189
P0, P1, P2, P3 = 1 / 14, 32 / 81, 250 / 567, 5 / 54
# Error weights: 4th-order minus 3rd-order weights (positions, velocities).
EB0, EB1, EB2, EB3 = 1 / 14 + 7 / 150, 8 / 27 - 67 / 150, 25 / 189 - 3 / 20, 1 / 20
EP0, EP1, EP2, EP3 = 1 / 14 - 13 / 21, 32 / 81 + 20 / 27, 250 / 567 - 275 / 189, 5 / 54 + 1 / 3
#: The stage that holds the force at the new position.
LAST = 3


@njit(**JIT_INLINE)
def stages(x, v, Kx, Kv, xs, vs, h, hi, fm, F, Pd, general):
    """Stages 1..3 of one step over granules 0..hi-1 (``Kv[0]`` holds f(x)); on return ``xs``, ``vs``
    hold the new state and ``Kv[3]`` the force per mass there (three force evaluations), also copied
    to ``Kv[6]``, where the step loop reads a step's end (as DP5's last stage; slot 3 is then free for
    the dense output, which :func:`dense_data` lays out only for the steps that need it). ``Kx`` and
    ``Pd`` are not read (every scheme's stages take the same arguments: ``schemes``)."""
    h2 = h * h
    for s in range(1, 4):  # one call of the force routine below, so that it is inlined once
        if s == 1:
            for i in range(hi):
                xs[i] = x[i] + h * (C1 * v[i]) + h2 * (A10 * Kv[0, i])
        elif s == 2:
            for i in range(hi):
                xs[i] = x[i] + h * (C2 * v[i]) + h2 * (A20 * Kv[0, i] + A21 * Kv[1, i])
        else:
            for i in range(hi):
                xs[i] = x[i] + h * v[i] + h2 * (B0 * Kv[0, i] + B1 * Kv[1, i] + B2 * Kv[2, i])
        accelerations(xs, v, fm, hi, F, Kv[s], general)  # forces of positions only: v unread
    for i in range(hi):
        vs[i] = v[i] + h * (P0 * Kv[0, i] + P1 * Kv[1, i] + P2 * Kv[2, i] + P3 * Kv[3, i])
        Kv[6, i] = Kv[3, i]  # the step's end, where the step loop reads it (slot 3 is the dense output's)


@njit(**JIT_INLINE)
def error_ratios(x, v, xs, vs, Kx, Kv, h, hi, relaxed, factor, rtol, atol, ratio):
    """|embedded error| / (w_i (atol + rtol max(|y|, |y_new|))) of positions (ratio[0:hi]) and
    velocities (ratio[hi:2 hi]), w_i = ``factor`` in the relaxed zone (granules 0..relaxed-1), else 1
    (as ``dp5.error_ratios``; ``rkloop.max_ratio`` takes their maximum). ``Kx`` is not read."""
    h2 = h * h
    for i in range(hi):
        w = factor if i < relaxed else 1.0
        ex = h2 * (EB0 * Kv[0, i] + EB1 * Kv[1, i] + EB2 * Kv[2, i] + EB3 * Kv[3, i])
        ratio[i] = abs(ex) / ((atol + rtol * max(abs(x[i]), abs(xs[i]))) * w)
    rv = ratio[hi:]
    for i in range(hi):
        w = factor if i < relaxed else 1.0
        ev = h * (EP0 * Kv[0, i] + EP1 * Kv[1, i] + EP2 * Kv[2, i] + EP3 * Kv[3, i])
        rv[i] = abs(ev) / ((atol + rtol * max(abs(v[i]), abs(vs[i]))) * w)


@njit(**JIT_INLINE)
def dense_data(x, v, xs, vs, Kx, Kv, h, hi):
    """After an accepted step that needs its dense output (a root or a grid sample in it): the quintic
    Hermite interpolant through (x, v, a = Kv[0]) and (xs, vs, a' = Kv[3]) in the slots of the stage
    arrays, for :func:`weights`:

    Kx = [v, (x' - x)/h, h a, h a', 0, 0, v'], so that x(t + theta h) = x + h sum_s Kx[s] Qx[s];
    Kv = [a, (x' - x)/h^2, v/h, v'/h, *, *, a'], so that v(t + theta h) = v + h sum_s Kv[s] Qv[s].

    Slot 6 holds v' and a' as in DP5 (a' is already there: :func:`stages`). Not written: Kx[0], which
    already holds v (the step loop keeps it so), Kv[6], and slots 4 and 5, whose weights are exactly 0
    (Kx[4], Kx[5] are never written by RKN4: zeros; Kv[4], Kv[5] are never written by it either).
    Kv[3] (a') is read before slot 3 is overwritten. The step loop reads v' from ``vs``, not Kx[6],
    for the steps without it (the same numbers)."""
    ih = 1.0 / h
    for i in range(hi):
        a1 = Kv[LAST, i]
        dx = xs[i] - x[i]
        Kx[1, i] = dx * ih
        Kx[2, i] = h * Kv[0, i]
        Kx[3, i] = h * a1
        Kx[6, i] = vs[i]
        Kv[1, i] = dx * ih * ih
        Kv[2, i] = v[i] * ih
        Kv[3, i] = vs[i] * ih


@njit(**JIT_INTERNAL)
def weights(theta, Qx, Qv):
    """Weights of :func:`dense_data` at t + theta h: the quintic Hermite basis (value at 0 and at 1,
    slope at 0 and at 1, curvature at 0 and at 1) and its derivative."""
    t = theta
    t2 = t * t
    t3 = t2 * t
    t4 = t3 * t
    t5 = t4 * t
    Qx[0] = t - 6 * t3 + 8 * t4 - 3 * t5  # slope at 0
    Qx[1] = 10 * t3 - 15 * t4 + 6 * t5  # value at 1 (value at 0 is 1 minus it)
    Qx[2] = 0.5 * t2 - 1.5 * t3 + 1.5 * t4 - 0.5 * t5  # curvature at 0
    Qx[3] = 0.5 * t3 - t4 + 0.5 * t5  # curvature at 1
    Qx[4] = 0.0
    Qx[5] = 0.0
    Qx[6] = -4 * t3 + 7 * t4 - 3 * t5  # slope at 1
    Qv[0] = t - 4.5 * t2 + 6 * t3 - 2.5 * t4
    Qv[1] = 30 * t2 - 60 * t3 + 30 * t4
    Qv[2] = -18 * t2 + 32 * t3 - 15 * t4  # (slope-at-0 basis)' minus 1: v is added separately
    Qv[3] = -12 * t2 + 28 * t3 - 15 * t4
    Qv[4] = 0.0
    Qv[5] = 0.0
    Qv[6] = 1.5 * t2 - 4 * t3 + 2.5 * t4
