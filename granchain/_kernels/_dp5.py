"""Dormand-Prince 5(4) for one chain: PI step control, max-norm error, dense output. The same step
loop runs the Runge-Kutta-Nystrom pair RKN4(3) (``_rkn``: its stages, error and dense output).

Coefficients: J. R. Dormand and P. J. Prince, J. Comput. Appl. Math. 6, 19
(1980); continuous extension of order 4 from L. F. Shampine, Math. Comp. 46, 135
(1986) (the same tables as ``scipy.integrate.RK45``). Step control: the PI
controller of Hairer, Norsett & Wanner, *Solving ODEs I*, Sec. II.4 (DOPRI5,
beta = 0.04). The error norm is the maximum over components: the pulse is
localised, and a root-mean-square norm would dilute its error over the resting
granules.

Peaks of the observed granules are located between steps: a local maximum of
v_k lies where its acceleration changes sign from + to -, and the root of the
acceleration computed from the dense-output positions is found by the Illinois
method, so peak times are not tied to the step grid. Peak contact forces the same
way: contact j's compression peaks where the dense-output relative velocity
v_j - v_{j+1} changes sign from + to - (checked only for contacts in the active
window, and the root searched only when the step ends show a sign change); the
force there is c_j delta^(n-1) of the dense-output positions.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._common import (
    MAX_STEPS,
    NONFINITE,
    STEP_UNDERFLOW,
    accelerations,
    add_potential,
    advance_window,
    borrowed,
    contact_force,
    final_peaks,
    is_new_peak,
    initial_force_records,
    initial_records,
    initial_window,
    keep_alive,
    is_finite_window,
    end_of_step,
    final_force_peaks,
    has_wall,
    stop_time,
    write_info,
)
from ._jit import JIT, JIT_INLINE
from . import _rkn

ORDER = 5

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

SAFETY = 0.9
#: Contact-force screen: the root of a compression maximum is searched only if the Hermite
#: estimate of that maximum reaches this fraction of the contact's recorded peak compression.
SCREEN = 0.9
BETA = 0.08  # PI controller: Gustafsson's value, few rejections when stability limits the step
ALPHA = 0.2 - 0.75 * BETA  # error estimate O(h^5)
ALPHA_RKN4 = 0.25 - 0.75 * BETA  # RKN4(3): error estimate O(h^4)
MIN_FACTOR = 0.2
MAX_FACTOR = 10.0
#: Bit masks of a float64 (``_error_norm``): all but the sign; the exponent of inf and NaN.
SIGN_CLEAR = 0x7FFF_FFFF_FFFF_FFFF
EXPONENT_ALL_ONES = 0x7FF0_0000_0000_0000
#: The padded layout: the loops over the window (stages, error norm, update) run
#: to the next multiple of LANES past its end. LLVM vectorises them LANES doubles wide (AVX-512) and
#: finishes a loop whose length is not a multiple of that one element at a time, which cost a step
#: as much as the vector part (the six stages: ~460 ns for a window of 31 granules, ~290 ns for 32).
#: The granules between the window's end and that multiple are exactly at rest and uncompressed
#: (``_common.WINDOW_MARGIN``) or padding past the chain's end (zero stiffness, zero inverse mass):
#: every stage gives them exact zeros, so the results are bitwise those of the unpadded loops.
LANES = 8


#: The methods the step loop runs (``rk_integrate``'s ``method``): DP5 (this module's tables) or
#: the Runge-Kutta-Nystrom pair RKN4(3) (``_rkn``), which shares everything but the stages, the error
#: estimate and the dense output.
METHOD_DP5 = 0
METHOD_RKN4 = 1


@njit(**JIT_INLINE)
def padded_width(hw):
    """The loop length for a window of ``hw`` granules: ``hw`` rounded up to a multiple of LANES."""
    return (hw + LANES - 1) // LANES * LANES


@njit(**JIT)
def dense_weights(theta, Q):
    """Q[s] = sum_p P[s, p] theta^(p+1), so that y(theta) = y + h sum_s K_s Q[s]."""
    for s in range(7):
        Q[s] = theta * (P[s, 0] + theta * (P[s, 1] + theta * (P[s, 2] + theta * P[s, 3])))


@njit(**JIT)
def dense_value(y0, K, k, h, Q):
    acc = 0.0
    for s in range(7):
        acc += K[s, k] * Q[s]
    return y0 + h * acc


@njit(**JIT)
def weights(method, theta, Qx, Qv):
    """Dense-output weights at t + theta h: positions x + h sum_s Kx[s] Qx[s], velocities
    v + h sum_s Kv[s] Qv[s]. DP5 has one set (``Qv`` is ``Qx``: filled once); RKN4 its Hermite pair
    (``_rkn.hermite_weights``)."""
    if method == METHOD_RKN4:
        _rkn.hermite_weights(theta, Qx, Qv)
    else:
        dense_weights(theta, Qx)


@njit(**JIT)
def _dense_accel(method, theta, k, x, Kx, h, c, inv_m, n, pw, Q, Qv):
    """Acceleration of granule k at t + theta h from the dense-output positions."""
    M = x.shape[0]
    weights(method, theta, Q, Qv)
    xk = dense_value(x[k], Kx, k, h, Q)
    left = 0.0
    right = 0.0
    if k > 0:
        left = contact_force(dense_value(x[k - 1], Kx, k - 1, h, Q) - xk, c[k - 1], n, pw)
    if k < M - 1:
        right = contact_force(xk - dense_value(x[k + 1], Kx, k + 1, h, Q), c[k], n, pw)
    return (left - right) * inv_m[k]


#: What :func:`_first_root` follows across a step: the acceleration of a granule (its velocity
#: maximum) or the relative velocity of a contact (its compression, i.e. force, maximum).
ROOT_ACCELERATION = 0
ROOT_APPROACH = 1


@njit(**JIT)
def _root_function(method, what, i, theta, x, v, Kx, Kv, h, c, inv_m, n, pw, Q, Qv):
    """The followed function at t + theta h on the dense output (weights ``Q`` for positions, ``Qv``
    for velocities, see :func:`weights`): the acceleration of granule i, or the relative velocity
    v_i - v_{i+1} of contact i."""
    if what == ROOT_ACCELERATION:
        return _dense_accel(method, theta, i, x, Kx, h, c, inv_m, n, pw, Q, Qv)
    weights(method, theta, Q, Qv)
    return dense_value(v[i], Kv, i, h, Qv) - dense_value(v[i + 1], Kv, i + 1, h, Qv)


@njit(**JIT)
def _first_root(method, what, i, f0, f1, x, v, Kx, Kv, h, c, inv_m, n, pw, Q, Qv):
    """First theta in [0, 1] where the followed function (+ at 0, <= 0 at 1) stops being positive:
    a granule's velocity maximum (``ROOT_ACCELERATION``) or a contact's compression maximum
    (``ROOT_APPROACH``).

    Illinois (modified regula falsi) while the bracket has a strictly negative end; bisection
    while it ends on an exact zero (a contact that opened: the acceleration is then zero on a
    whole interval and the first zero is wanted).
    """
    lo, hi = 0.0, 1.0
    f_lo, f_hi = f0, f1
    theta = 0.0
    side = 0
    for _ in range(200):
        if f_hi < 0.0:
            theta = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
            if not (lo < theta < hi):
                theta = 0.5 * (lo + hi)
        else:
            theta = 0.5 * (lo + hi)
        f = _root_function(method, what, i, theta, x, v, Kx, Kv, h, c, inv_m, n, pw, Q, Qv)
        if f > 0.0:
            lo, f_lo = theta, f
            if side == -1:
                f_hi *= 0.5
            side = -1
        else:
            hi, f_hi = theta, f
            if side == 1:
                f_lo *= 0.5
            side = 1
        if hi - lo < 1e-14:
            break
    return hi


@njit(**JIT_INLINE)
def falls(f0, f1):
    """A function followed over a step is + at its start and <= 0 at its end: a maximum of what it
    is the derivative of lies inside (:func:`_first_root`). Branch-free, so that the candidate
    counts of the step loop vectorise; the same test in the counts and in the loops they guard."""
    return (f0 > 0.0) & (f1 <= 0.0)


@njit(**JIT)
def hermite_max_estimate(d0, w0, d1, w1, h):
    """The cubic Hermite interpolant of the compression through (d0, w0) and (d1, w1) over a step h,
    at the zero of the linearly interpolated relative velocity w (w0 > 0 >= w1): an estimate of the
    compression maximum, used only to skip hopeless root searches (:data:`SCREEN`)."""
    theta = w0 / (w0 - w1)
    t2 = theta * theta
    t3 = t2 * theta
    return (2 * t3 - 3 * t2 + 1) * d0 + (t3 - 2 * t2 + theta) * h * w0 + (-2 * t3 + 3 * t2) * d1 + (t3 - t2) * h * w1


@njit(**JIT)
def _dense_compression(j, x, Kx, h, Q):
    """Compression x_j - x_{j+1} of contact j from the dense-output positions at the time whose
    weights ``Q`` holds (``weights(method, theta, Q, Qv)`` already called)."""
    return dense_value(x[j], Kx, j, h, Q) - dense_value(x[j + 1], Kx, j + 1, h, Q)


# Coefficients as scalars so that Numba folds them into the unrolled stages.
A21 = A[1, 0]
A31, A32 = A[2, 0], A[2, 1]
A41, A42, A43 = A[3, 0], A[3, 1], A[3, 2]
A51, A52, A53, A54 = A[4, 0], A[4, 1], A[4, 2], A[4, 3]
A61, A62, A63, A64, A65 = A[5, 0], A[5, 1], A[5, 2], A[5, 3], A[5, 4]
B1, B3, B4, B5, B6 = A[6, 0], A[6, 2], A[6, 3], A[6, 4], A[6, 5]
E1, E3, E4, E5, E6, E7 = E[0], E[2], E[3], E[4], E[5], E[6]


@njit(**JIT_INLINE)
def _stages(x, v, Kx, Kv, xs, vs, h, hi, c, inv_m, n, pw, F):
    """Stages 2..7 of one step over granules 0..hi-1, unrolled.

    Kx[s] are the stage velocities (dx/dt), Kv[s] the stage accelerations;
    on return xs, vs hold the 5th-order solution and Kx[6], Kv[6] its derivative.
    """
    for i in range(hi):
        xs[i] = x[i] + h * (A21 * Kx[0, i])
        Kx[1, i] = v[i] + h * (A21 * Kv[0, i])
    accelerations(xs, c, inv_m, n, pw, hi, F, Kv[1])
    for i in range(hi):
        xs[i] = x[i] + h * (A31 * Kx[0, i] + A32 * Kx[1, i])
        Kx[2, i] = v[i] + h * (A31 * Kv[0, i] + A32 * Kv[1, i])
    accelerations(xs, c, inv_m, n, pw, hi, F, Kv[2])
    for i in range(hi):
        xs[i] = x[i] + h * (A41 * Kx[0, i] + A42 * Kx[1, i] + A43 * Kx[2, i])
        Kx[3, i] = v[i] + h * (A41 * Kv[0, i] + A42 * Kv[1, i] + A43 * Kv[2, i])
    accelerations(xs, c, inv_m, n, pw, hi, F, Kv[3])
    for i in range(hi):
        xs[i] = x[i] + h * (A51 * Kx[0, i] + A52 * Kx[1, i] + A53 * Kx[2, i] + A54 * Kx[3, i])
        Kx[4, i] = v[i] + h * (A51 * Kv[0, i] + A52 * Kv[1, i] + A53 * Kv[2, i] + A54 * Kv[3, i])
    accelerations(xs, c, inv_m, n, pw, hi, F, Kv[4])
    for i in range(hi):
        xs[i] = x[i] + h * (A61 * Kx[0, i] + A62 * Kx[1, i] + A63 * Kx[2, i] + A64 * Kx[3, i] + A65 * Kx[4, i])
        Kx[5, i] = v[i] + h * (A61 * Kv[0, i] + A62 * Kv[1, i] + A63 * Kv[2, i] + A64 * Kv[3, i] + A65 * Kv[4, i])
    accelerations(xs, c, inv_m, n, pw, hi, F, Kv[5])
    for i in range(hi):
        xs[i] = x[i] + h * (B1 * Kx[0, i] + B3 * Kx[2, i] + B4 * Kx[3, i] + B5 * Kx[4, i] + B6 * Kx[5, i])
        vs[i] = v[i] + h * (B1 * Kv[0, i] + B3 * Kv[2, i] + B4 * Kv[3, i] + B5 * Kv[4, i] + B6 * Kv[5, i])
        Kx[6, i] = vs[i]
    accelerations(xs, c, inv_m, n, pw, hi, F, Kv[6])


@njit(**JIT_INLINE)
def _error_norm(method, x, v, xs, vs, Kx, Kv, h, hi, relaxed, factor, rtol, atol, ratio):
    """Max over components of |embedded error| / (w_i (atol + rtol max(|y|, |y_new|))); inf if the new
    state is not finite. w_i = ``factor`` for the granules of the relaxed zone (0..relaxed-1), else 1
    (multiplying by 1 is exact: without a relaxed zone the norm is bitwise the plain one). RKN4's
    ratios come from ``_rkn.error_ratios``.

    The ratios go through the scratch array ``ratio`` so that the division loop vectorises; their
    maximum is then an integer maximum of their bit patterns (below; ``ratio[0]`` is overwritten with
    it). A NaN ratio (a non-finite state) is never lost to a later finite one: its pattern is above
    every finite one.
    """
    if method == METHOD_RKN4:
        _rkn.error_ratios(x, v, xs, vs, Kv, h, hi, relaxed, factor, rtol, atol, ratio)
    else:
        _dp5_error_ratios(x, v, xs, vs, Kx, Kv, h, hi, relaxed, factor, rtol, atol, ratio)
    # The maximum of the bit patterns (sign cleared): for non-negative doubles their order is the
    # order of the numbers, inf and NaN above every finite one, and an integer maximum can vectorise
    # (a floating-point one cannot without fast-math; measured, no faster than the float loop it
    # replaced, but simpler). Bitwise the same maximum.
    bits = ratio.view(np.int64)
    top = 0
    for i in range(2 * hi):
        top = max(top, bits[i] & SIGN_CLEAR)
    if top >= EXPONENT_ALL_ONES:  # inf or NaN
        return math.inf
    bits[0] = top
    return ratio[0]


@njit(**JIT_INLINE)
def _dp5_error_ratios(x, v, xs, vs, Kx, Kv, h, hi, relaxed, factor, rtol, atol, ratio):
    """DP5's error ratios of positions (ratio[0:hi]) and velocities (ratio[hi:2 hi]), see :func:`_error_norm`."""
    for i in range(hi):  # positions, then velocities: two loops of few streams each vectorise
        w = factor if i < relaxed else 1.0
        ex = h * (E1 * Kx[0, i] + E3 * Kx[2, i] + E4 * Kx[3, i] + E5 * Kx[4, i] + E6 * Kx[5, i] + E7 * Kx[6, i])
        ratio[i] = abs(ex) / ((atol + rtol * max(abs(x[i]), abs(xs[i]))) * w)
    rv = ratio[hi:]
    for i in range(hi):
        w = factor if i < relaxed else 1.0
        ev = h * (E1 * Kv[0, i] + E3 * Kv[2, i] + E4 * Kv[3, i] + E5 * Kv[4, i] + E6 * Kv[5, i] + E7 * Kv[6, i])
        rv[i] = abs(ev) / ((atol + rtol * max(abs(v[i]), abs(vs[i]))) * w)


@njit(**JIT)
def _open_contact_behind(x, lo, target):
    """The window start for a cut just behind granule ``target`` (0-based, in the chain): j + 1 for
    the last contact j < target that is open now (x_j <= x_{j+1}; ``x`` holds the granules lo..),
    or ``lo`` (no cut) if every contact between lo and target is closed."""
    for j in range(target - 1, lo - 1, -1):
        if x[j - lo] - x[j + 1 - lo] <= 0.0:
            return j + 1
    return lo


@njit(**JIT)
def rk_integrate(method, m, c, n, pw, obs, rtol, atol, h_init, h_fixed, relax_lag, relax_factor, window_lag, t_max,
                 stop_at_exit, exit_margin, max_steps, peak_rtol, t_grid, x, v, peak_v, peak_t, grid_v, peak_f, peak_ft,
                 grid_f, info):
    """Integrate one chain from the state (x, v) at t = 0 with ``method`` (:data:`METHOD_DP5`, or
    :data:`METHOD_RKN4`: the Runge-Kutta-Nystrom pair of ``_rkn``, same loop, step control and records).

    ``x``, ``v`` (length M) hold the initial state and receive the final one.
    For each observed granule q (0-based index obs[q]) the kernel writes the
    maximum velocity ``peak_v[q]`` and its time ``peak_t[q]`` (see
    ``granchain._kernels._common.is_new_peak`` for ties), and the velocity
    at each time t_grid[g] into ``grid_v[g, q]`` (time-major: one
    contiguous row per grid time). For each contact j (0-based, M-1 of them) it
    writes the maximum contact force ``peak_f[j]`` and its time ``peak_ft[j]`` (0 at
    t = 0 for a contact that never closed; same tie rule as the velocities); with
    a wall (m[M-1] = inf) ``grid_f[g]`` receives the wall force at t_grid[g]
    (untouched otherwise). ``h_fixed > 0`` turns
    step control off (fixed steps of h_fixed). With ``stop_at_exit`` the run
    ends ``exit_margin`` after the pulse has left the last granule (and not
    before t_grid[-1]); otherwise at ``t_max``.

    Goal-oriented error control (``granchain.DP5``; both off when <= 0, and always off
    for a chain ending in a wall, whose pulse comes back). The *front* is the most advanced
    observed granule whose velocity maximum has been located; it never moves backwards.
    - ``relax_lag`` > 0: granules behind observed granule front - relax_lag enter the error norm
      with tolerances ``relax_factor`` times looser (the relaxed zone).
    - ``window_lag`` > 0: granules behind observed granule front - window_lag, cut across the
      last contact behind it that is open at that moment, leave the integration (the trailing
      window): they keep their velocity (positions continue ballistically), their peaks are final,
      and the contact at the window's edge is dropped. Granules lo..M-1 stay integrated, so the
      work per step is bounded by the window, not the chain.

    info receives the INFO_* slots of ``_common`` (t_end, steps, rejected, exit time, force
    evaluations, window start, potential energy of the frozen contacts).
    Returns the status code (granchain._kernels._common).
    """
    M = m.shape[0]
    # The padded layout (see LANES): state, stiffness and inverse masses of the M granules followed
    # by LANES padding granules with zero stiffness and zero inverse mass, which stay exactly at rest.
    Mp = M + LANES
    xp = np.zeros(Mp)
    vp = np.zeros(Mp)
    cp = np.zeros(Mp)
    inv_m = np.zeros(Mp)
    xp[:M] = x
    vp[:M] = v
    cp[:M - 1] = c
    inv_m[:M] = 1.0 / m
    Kx = np.zeros((7, Mp))  # stage derivatives of x (= stage velocities), window-local index
    Kv = np.zeros((7, Mp))  # stage derivatives of v (= stage accelerations), window-local index
    xs = np.zeros(Mp)
    vs = np.zeros(Mp)
    F = np.zeros(Mp + 1)  # contact forces, F[j + 1] for contact j (see _common.accelerations)
    Q = np.zeros(7)
    Qv = np.zeros(7)  # RKN4's velocity weights (DP5 uses Q for both)
    ratio = np.zeros(2 * Mp)
    peak_d = np.zeros(M)  # compression at each contact's recorded peak force (for the screen)
    t_frozen = np.zeros(M)  # time each granule left the trailing window
    # The step loop works on borrowed views (see _common.borrowed): the arguments are held by
    # our caller, the scratch arrays above by the keep_alive call after the loop.
    bm, bc, bobs, bt, bx, bv = borrowed(m), borrowed(cp), borrowed(obs), borrowed(t_grid), borrowed(xp), borrowed(vp)
    bpv, bpt, bgv, bpf, bpft = borrowed(peak_v), borrowed(peak_t), borrowed(grid_v), borrowed(peak_f), borrowed(peak_ft)
    bgf, binfo = borrowed(grid_f), borrowed(info)
    scratch = (borrowed(inv_m), borrowed(Kx), borrowed(Kv), borrowed(xs), borrowed(vs), borrowed(F), borrowed(Q),
               borrowed(Qv), borrowed(ratio), borrowed(peak_d), borrowed(t_frozen))
    if method == METHOD_RKN4:
        status = _rkn4_loop(bm, bc, n, pw, bobs, rtol, atol, h_init, h_fixed, relax_lag, relax_factor, window_lag,
                            t_max, stop_at_exit, exit_margin, max_steps, peak_rtol, bt, bx, bv, bpv, bpt, bgv, bpf,
                            bpft, bgf, binfo, scratch)
    else:
        status = _dp5_loop(bm, bc, n, pw, bobs, rtol, atol, h_init, h_fixed, relax_lag, relax_factor, window_lag,
                           t_max, stop_at_exit, exit_margin, max_steps, peak_rtol, bt, bx, bv, bpv, bpt, bgv, bpf,
                           bpft, bgf, binfo, scratch)
    keep_alive(xp, vp, cp, inv_m, Kx, Kv, xs, vs, F, Q, Qv, ratio, peak_d, t_frozen)
    x[:] = xp[:M]
    v[:] = vp[:M]
    return status


@njit(**JIT)
def _dp5_loop(m, c, n, pw, obs, rtol, atol, h_init, h_fixed, relax_lag, relax_factor, window_lag, t_max, stop_at_exit,
              exit_margin, max_steps, peak_rtol, t_grid, x, v, peak_v, peak_t, grid_v, peak_f, peak_ft, grid_f, info,
              scratch):
    """:func:`_rk_loop` with DP5."""
    return _rk_loop(METHOD_DP5, m, c, n, pw, obs, rtol, atol, h_init, h_fixed, relax_lag, relax_factor, window_lag,
                    t_max, stop_at_exit, exit_margin, max_steps, peak_rtol, t_grid, x, v, peak_v, peak_t, grid_v,
                    peak_f, peak_ft, grid_f, info, scratch)


@njit(**JIT)
def _rkn4_loop(m, c, n, pw, obs, rtol, atol, h_init, h_fixed, relax_lag, relax_factor, window_lag, t_max, stop_at_exit,
               exit_margin, max_steps, peak_rtol, t_grid, x, v, peak_v, peak_t, grid_v, peak_f, peak_ft, grid_f, info,
               scratch):
    """:func:`_rk_loop` with RKN4(3)."""
    return _rk_loop(METHOD_RKN4, m, c, n, pw, obs, rtol, atol, h_init, h_fixed, relax_lag, relax_factor, window_lag,
                    t_max, stop_at_exit, exit_margin, max_steps, peak_rtol, t_grid, x, v, peak_v, peak_t, grid_v,
                    peak_f, peak_ft, grid_f, info, scratch)


# Inlined into the two loops above, each with its method a constant, so that the compiler drops the
# other method's branches (compiled once with the method a run-time value, the loop cost DP5 ~6 %
# more per realisation, same-process timing at N = 26).
@njit(**JIT_INLINE)
def _rk_loop(method, m, c, n, pw, obs, rtol, atol, h_init, h_fixed, relax_lag, relax_factor, window_lag, t_max,
             stop_at_exit, exit_margin, max_steps, peak_rtol, t_grid, x, v, peak_v, peak_t, grid_v, peak_f, peak_ft,
             grid_f, info, scratch):
    """The step loop of :func:`rk_integrate`, on borrowed arrays (``_common.borrowed``: no reference
    counting in the loop): its arguments, with the state ``x``, ``v``, the stiffness ``c`` and the
    inverse masses ``inv_m`` = 1 / m in the padded layout (length Mp = M + LANES, see :data:`LANES`),
    and the zeroed scratch arrays (stage derivatives ``Kx``, ``Kv`` (7, Mp); ``xs``, ``vs`` (Mp);
    ``peak_d``, ``t_frozen`` (M); contact forces ``F`` (Mp + 1); dense-output weights ``Q``, ``Qv``
    (7); error ratios ``ratio`` (2 Mp)) in the tuple ``scratch``. (One tuple: CPython passes a call of
    more than 30 arguments as ``f(*args)``, which Numba cannot inline.)"""
    inv_m, Kx, Kv, xs, vs, F, Q, Qv, ratio, peak_d, t_frozen = scratch
    M = m.shape[0]
    Mp = x.shape[0]
    n_obs = obs.shape[0]
    n_grid = t_grid.shape[0]

    # The window: granules lo..hi-1 are integrated (lo = 0 until a trailing-window cut). Kx, Kv are
    # window-local (shifted to start at lo at each cut); the other arrays are read through views from
    # granule lo on, taken in the step loop below.
    wall = has_wall(m)
    QV = Qv if method == METHOD_RKN4 else Q  # velocity weights (see weights)
    alpha = ALPHA_RKN4 if method == METHOD_RKN4 else ALPHA  # PI controller exponent of the error estimate
    goal = (relax_lag > 0 or window_lag > 0) and not wall
    lo = 0
    hi = initial_window(x[:M], v[:M])
    accelerations(x, c, inv_m, n, pw, hi, F, Kv[0])
    for i in range(hi):
        Kx[0, i] = v[i]
    n_eval = 1
    front = -1  # observed granule (index into obs) of the front
    relaxed = 0  # granules lo..lo+relaxed-1 are in the relaxed zone
    frozen_potential = 0.0

    t = 0.0
    g = initial_records(obs, v, t_grid, peak_v, peak_t, grid_v)
    t_needed = t_grid[n_grid - 1] if n_grid > 0 else 0.0
    initial_force_records(x[:M], m, c[:M - 1], n, pw, g, peak_f, peak_ft, grid_f)

    h = h_fixed if h_fixed > 0.0 else h_init
    err_old = 1e-4
    exit_since = -1.0
    n_acc = 0
    n_rej = 0
    status = -1
    # Two loops: the outer one takes views of the window (from granule lo on) that the steps of the
    # inner one do not move; a trailing-window cut ends the inner loop after its step. Views that
    # stay put through the step loop are loop invariants to the compiler: when they were moved
    # inside it, a step cost 15-20 % more on N = 6 and 10-15 % more on N = 26 decorated chains
    # (~410 -> ~350 ns and ~750 -> ~670 ns, exact DP5, same-process timings), window or not.
    while status < 0:
        # Views from granule lo on (contiguous, so the stage loops vectorise): X, V, C, IM, XS, VS
        # through the padding (the loops over the window), XM, VM, MM to the chain's end (the
        # routines that look for its last granule).
        X, V, C, IM = x[lo:], v[lo:], c[lo:], inv_m[lo:]
        XS, VS = xs[lo:], vs[lo:]
        XM, VM, MM = x[lo:M], v[lo:M], m[lo:]
        while status < 0:
            if n_acc + n_rej >= max_steps:
                status = MAX_STEPS
                break
            # Land exactly on the end: t_max, or exit_margin after the pulse left (not before t_grid[-1]).
            t_stop = stop_time(t_max, exit_since, exit_margin, t_needed)
            last = False
            if t + h >= t_stop:
                h = t_stop - t
                last = True
            hw = hi - lo
            hp = padded_width(hw)
            # The stages (DP5: 2..7, RKN4: 1..3; the last is the new solution's, reused as the first
            # next step).
            if method == METHOD_RKN4:
                _rkn.stages(X, V, Kv, XS, VS, h, hp, C, IM, n, pw, F)
                n_eval += 3
            else:
                _stages(X, V, Kx, Kv, XS, VS, h, hp, C, IM, n, pw, F)
                n_eval += 6
            # xs, vs now hold the new solution at t + h (DP5: 5th order; RKN4: 4th order).
            accept = True
            err = 0.0
            if h_fixed <= 0.0:
                err = _error_norm(method, X, V, XS, VS, Kx, Kv, h, hp, relaxed, relax_factor, rtol, atol, ratio)
                if not math.isfinite(err):
                    status = NONFINITE
                    break
                accept = err <= 1.0
            if not accept:
                n_rej += 1
                h *= max(MIN_FACTOR, SAFETY * err**-alpha)
                if h < 1e-14 * max(1.0, t):
                    status = STEP_UNDERFLOW
                continue

            # Accepted: peaks and grid samples from the dense output over [t, t + h].
            if method == METHOD_RKN4:
                _rkn.dense_data(X, V, XS, VS, Kx, Kv, h, hp)
            # Velocity maxima where an acceleration goes from + to -: a vectorised count over every
            # granule of the window (zeros past it) first; the loop over the observed granules runs
            # only when it finds one (1.6 % of the steps of an N = 26 decorated chain have one there).
            n_candidates = 0
            for i in range(hp):
                n_candidates += falls(Kv[0, i], Kv[6, i])
            for q in range(n_obs if n_candidates > 0 else 0):
                k = obs[q] - lo
                if k < 0 or k >= hw:
                    continue
                a0 = Kv[0, k]
                a1 = Kv[6, k]
                if falls(a0, a1):
                    theta = _first_root(method, ROOT_ACCELERATION, k, a0, a1, X, V, Kx, Kv, h, C, IM, n, pw, Q, QV)
                    weights(method, theta, Q, QV)
                    vp = dense_value(V[k], Kv, k, h, QV)
                    if is_new_peak(vp, peak_v[q], peak_rtol):
                        peak_v[q] = vp
                        peak_t[q] = t + theta * h
                    front = max(front, q)
            # Contact forces: compression maxima where v_j - v_{j+1} goes from + to -. The same
            # vectorised count first (~80 % of the steps of an N = 26 decorated chain have no
            # candidate; the contacts past the window, resting or padding, are never one, except the
            # padding's with the last granule, which only lets the loop run).
            # (One rarely taken branch per contact: a test of w0 > 0 alone would be a coin flip.)
            n_candidates = 0
            for j in range(hp):
                n_candidates += falls(Kx[0, j] - Kx[0, j + 1], Kx[6, j] - Kx[6, j + 1])
            for j in range(hw - 1 if n_candidates > 0 else 0):
                w0 = Kx[0, j] - Kx[0, j + 1]
                w1 = Kx[6, j] - Kx[6, j + 1]
                if falls(w0, w1):
                    # Screen: the cubic Hermite estimate of the compression maximum from the step ends
                    # (error O(h^4), far below the margin) cannot beat the recorded peak: skip the root.
                    d0 = X[j] - X[j + 1]
                    d1 = XS[j] - XS[j + 1]
                    if hermite_max_estimate(d0, w0, d1, w1, h) < SCREEN * peak_d[lo + j]:
                        continue
                    theta = _first_root(method, ROOT_APPROACH, j, w0, w1, X, V, Kx, Kv, h, C, IM, n, pw, Q, QV)
                    weights(method, theta, Q, QV)
                    dp = _dense_compression(j, X, Kx, h, Q)
                    fp = contact_force(dp, C[j], n, pw)  # Eq. (motion_rescaled): c_j delta^(n-1)
                    if fp > 0.0 and is_new_peak(fp, peak_f[lo + j], peak_rtol):
                        peak_f[lo + j] = fp
                        peak_ft[lo + j] = t + theta * h
                        peak_d[lo + j] = dp
            while g < n_grid and t_grid[g] <= t + h:
                theta = (t_grid[g] - t) / h
                weights(method, theta, Q, QV)
                for q in range(n_obs):
                    k = obs[q] - lo
                    if k < 0:  # behind the window: the velocity it left with
                        grid_v[g, q] = v[obs[q]]
                    else:
                        grid_v[g, q] = dense_value(V[k], Kv, k, h, QV) if k < hw else 0.0
                if wall:
                    grid_f[g] = contact_force(_dense_compression(M - 2 - lo, X, Kx, h, Q), C[M - 2 - lo], n, pw) if M - 2 < hi else 0.0
                g += 1

            for i in range(hp):
                X[i] = XS[i]
                V[i] = VS[i]
                Kx[0, i] = Kx[6, i]
                Kv[0, i] = Kv[6, i]
            t = t + h if not last else t_stop
            n_acc += 1
            if h_fixed > 0.0 and not is_finite_window(X, V, hw):  # adaptive: checked in the error norm
                status = NONFINITE
                break
            if hi < M:
                new_hi = lo + advance_window(XM, VM, hw)
                if new_hi > hi:
                    hi = new_hi
                    accelerations(X, C, IM, n, pw, hi - lo, F, Kv[0])
                    for i in range(hi - lo):
                        Kx[0, i] = V[i]
                    n_eval += 1
            cut = False
            if goal and front >= 0:
                if window_lag > 0 and front >= window_lag:
                    new_lo = _open_contact_behind(X, lo, obs[front - window_lag])
                    if new_lo > lo:
                        # Granules lo..new_lo-1 leave: keep their velocities, the potential of the
                        # contacts among them (the contact at the new edge is open), their exit time.
                        d = new_lo - lo
                        frozen_potential = add_potential(frozen_potential, X, C, n, 0, d - 1)
                        for i in range(d):
                            t_frozen[lo + i] = t
                        for s in range(7):  # the whole padded width: zeros follow the window
                            for i in range(Mp - new_lo):
                                Kx[s, i] = Kx[s, i + d]
                                Kv[s, i] = Kv[s, i + d]
                        lo = new_lo
                        cut = True
                if relax_lag > 0 and front >= relax_lag:
                    relaxed = max(0, obs[front - relax_lag] - lo)

            if cut:  # XM, VM, MM still start at the old window start
                status, exit_since = end_of_step(x[lo:M], v[lo:M], m[lo:], hi - lo, t, t_max, stop_at_exit, exit_since,
                                                 exit_margin, t_needed)
            else:
                status, exit_since = end_of_step(XM, VM, MM, hi - lo, t, t_max, stop_at_exit, exit_since, exit_margin,
                                                 t_needed)
            if status >= 0:
                break

            if h_fixed <= 0.0:
                fac = SAFETY * max(err, 1e-10) ** -alpha * err_old**BETA
                fac = min(MAX_FACTOR, max(MIN_FACTOR, fac))
                h *= fac
                err_old = max(err, 1e-4)
            if cut:  # new views from the new window start
                break
    X, V, C = x[lo:M], v[lo:M], c[lo:M - 1]  # the chain without padding (a cut in the last step left the views behind)
    final_peaks(obs, lo, V, Kv[0], t, peak_rtol, peak_v, peak_t)
    final_force_peaks(X, V, C, n, pw, lo, t, peak_rtol, peak_f, peak_ft)
    for k in range(lo):  # the granules behind the window continued ballistically
        x[k] += v[k] * (t - t_frozen[k])
    write_info(info, t, n_acc, n_rej, exit_since, n_eval, lo, frozen_potential)
    return status
