"""Dormand-Prince 5(4) for one chain: PI step control, max-norm error, dense output.

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
method, so peak times are not tied to the step grid.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._common import (
    MAX_STEPS,
    NONFINITE,
    STEP_UNDERFLOW,
    SUCCESS,
    T_MAX,
    accelerations,
    advance_window,
    contact_force,
    final_peaks,
    is_new_peak,
    initial_window,
    is_finite_window,
    pulse_has_left,
)
from ._jit import JIT

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
BETA = 0.04  # PI controller (Hairer's DOPRI5)
ALPHA = 0.2 - 0.75 * BETA
MIN_FACTOR = 0.2
MAX_FACTOR = 10.0


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
def _dense_accel(theta, k, x, Kx, h, c, inv_m, n, pw, Q):
    """Acceleration of granule k at t + theta h from the dense-output positions."""
    M = x.shape[0]
    dense_weights(theta, Q)
    xk = dense_value(x[k], Kx, k, h, Q)
    left = 0.0
    right = 0.0
    if k > 0:
        left = contact_force(dense_value(x[k - 1], Kx, k - 1, h, Q) - xk, c[k - 1], n, pw)
    if k < M - 1:
        right = contact_force(xk - dense_value(x[k + 1], Kx, k + 1, h, Q), c[k], n, pw)
    return (left - right) * inv_m[k]


@njit(**JIT)
def _acceleration_root(k, a0, a1, x, Kx, h, c, inv_m, n, pw, Q):
    """First theta in [0, 1] where the acceleration of k stops being positive.

    Illinois (modified regula falsi) while the bracket has a strictly negative
    end; bisection while it ends on an exact zero (a contact that opened: the
    acceleration is then zero on a whole interval and the first zero is wanted).
    """
    lo, hi = 0.0, 1.0
    f_lo, f_hi = a0, a1
    theta = 0.0
    side = 0
    for _ in range(200):
        if f_hi < 0.0:
            theta = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
            if not (lo < theta < hi):
                theta = 0.5 * (lo + hi)
        else:
            theta = 0.5 * (lo + hi)
        f = _dense_accel(theta, k, x, Kx, h, c, inv_m, n, pw, Q)
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


@njit(**JIT)
def dp5_integrate(m, c, n, pw, obs, rtol, atol, h_init, h_fixed, t_max, stop_at_exit, exit_margin, max_steps, peak_rtol, t_grid, x, v, peak_v, peak_t, grid_v, info):
    """Integrate one chain from the state (x, v) at t = 0.

    ``x``, ``v`` (length M) hold the initial state and receive the final one.
    For each observed granule q (0-based index obs[q]) the kernel writes the
    maximum velocity ``peak_v[q]`` and its time ``peak_t[q]`` (see
    ``granchain._kernels._common.is_new_peak`` for ties), and the velocity
    at each time of ``t_grid`` into ``grid_v[q, :]``. ``h_fixed > 0`` turns
    step control off (fixed steps of h_fixed). With ``stop_at_exit`` the run
    ends ``exit_margin`` after the pulse has left the last granule (and not
    before t_grid[-1]); otherwise at ``t_max``.

    info receives [t_end, accepted steps, rejected steps, exit time, force evaluations].
    Returns the status code (granchain._kernels._common).
    """
    M = m.shape[0]
    n_obs = obs.shape[0]
    n_grid = t_grid.shape[0]
    inv_m = 1.0 / m
    Kx = np.zeros((7, M))  # stage derivatives of x (= stage velocities)
    Kv = np.zeros((7, M))  # stage derivatives of v (= stage accelerations)
    xs = np.zeros(M)
    vs = np.zeros(M)
    F = np.zeros(M)
    Q = np.zeros(7)

    hi = initial_window(x, v)
    accelerations(x, c, inv_m, n, pw, hi, F, Kv[0])
    for i in range(hi):
        Kx[0, i] = v[i]
    n_eval = 1

    t = 0.0
    for q in range(n_obs):
        peak_v[q] = v[obs[q]]
        peak_t[q] = 0.0
    g = 0
    while g < n_grid and t_grid[g] <= 0.0:
        for q in range(n_obs):
            grid_v[q, g] = v[obs[q]]
        g += 1
    t_needed = t_grid[n_grid - 1] if n_grid > 0 else 0.0

    h = h_fixed if h_fixed > 0.0 else h_init
    err_old = 1e-4
    exit_since = -1.0
    n_acc = 0
    n_rej = 0
    status = -1
    while status < 0:
        if n_acc + n_rej >= max_steps:
            status = MAX_STEPS
            break
        last = False
        if t + h >= t_max:
            h = t_max - t
            last = True
        # Stages 2..7 (stage 7 is the new solution, reused as stage 1 next step).
        for s in range(1, 7):
            for i in range(hi):
                ax = 0.0
                av = 0.0
                for j in range(s):
                    ax += A[s, j] * Kx[j, i]
                    av += A[s, j] * Kv[j, i]
                xs[i] = x[i] + h * ax
                vs[i] = v[i] + h * av
                Kx[s, i] = vs[i]
            accelerations(xs, c, inv_m, n, pw, hi, F, Kv[s])
        n_eval += 6
        # xs, vs now hold the 5th-order solution at t + h.
        accept = True
        err = 0.0
        if h_fixed <= 0.0:
            for i in range(hi):
                ex = 0.0
                ev = 0.0
                for s in range(7):
                    ex += E[s] * Kx[s, i]
                    ev += E[s] * Kv[s, i]
                sx = atol + rtol * max(abs(x[i]), abs(xs[i]))
                sv = atol + rtol * max(abs(v[i]), abs(vs[i]))
                err = max(err, abs(h * ex) / sx, abs(h * ev) / sv)
            accept = err <= 1.0
            if not math.isfinite(err):
                accept = False
                err = 1e10
        if not accept:
            n_rej += 1
            h *= max(MIN_FACTOR, SAFETY * err**-ALPHA)
            if h < 1e-14 * max(1.0, t):
                status = STEP_UNDERFLOW
            continue

        # Accepted: peaks and grid samples from the dense output over [t, t + h].
        for q in range(n_obs):
            k = obs[q]
            if k >= hi:
                continue
            a0 = Kv[0, k]
            a1 = Kv[6, k]
            if a0 > 0.0 and a1 <= 0.0:
                theta = _acceleration_root(k, a0, a1, x, Kx, h, c, inv_m, n, pw, Q)
                dense_weights(theta, Q)
                vp = dense_value(v[k], Kv, k, h, Q)
                if is_new_peak(vp, peak_v[q], peak_rtol):
                    peak_v[q] = vp
                    peak_t[q] = t + theta * h
        while g < n_grid and t_grid[g] <= t + h:
            dense_weights((t_grid[g] - t) / h, Q)
            for q in range(n_obs):
                k = obs[q]
                grid_v[q, g] = dense_value(v[k], Kv, k, h, Q) if k < hi else 0.0
            g += 1

        for i in range(hi):
            x[i] = xs[i]
            v[i] = vs[i]
            Kx[0, i] = Kx[6, i]
            Kv[0, i] = Kv[6, i]
        t = t + h if not last else t_max
        n_acc += 1
        if not is_finite_window(x, v, hi):
            status = NONFINITE
            break
        new_hi = advance_window(x, v, hi)
        if new_hi > hi:
            hi = new_hi
            accelerations(x, c, inv_m, n, pw, hi, F, Kv[0])
            for i in range(hi):
                Kx[0, i] = v[i]
            n_eval += 1

        if stop_at_exit:
            if hi == M and pulse_has_left(x, v):
                if exit_since < 0.0:
                    exit_since = t
                if t - exit_since >= exit_margin and t >= t_needed:
                    status = SUCCESS
                    break
            else:
                exit_since = -1.0
        if last:
            status = T_MAX if stop_at_exit else SUCCESS
            break

        if h_fixed <= 0.0:
            fac = SAFETY * max(err, 1e-10) ** -ALPHA * err_old**BETA
            fac = min(MAX_FACTOR, max(MIN_FACTOR, fac))
            h *= fac
            err_old = max(err, 1e-4)

    final_peaks(obs, v, t, peak_rtol, peak_v, peak_t)
    info[0] = t
    info[1] = n_acc
    info[2] = n_rej
    info[3] = exit_since
    info[4] = n_eval
    return status
