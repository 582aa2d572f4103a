"""A multirate prototype for the light granules behind the pulse (used by bench_multirate.py; not part of granchain).

RKN4(3) with the relaxed zone of ``RKN4.relaxed()``, on a whole decorated chain, landing on the grid
times and recording the observed granules' velocities there (no peaks, window or records: the
single-rate and the multirate runs below are the same code, so their cost ratio is what multirate
buys). With ``fast_mass`` > 0, a small granule lighter than it becomes *fast* once it is in the
relaxed zone (behind the pulse, where it rattles):

- the macro step drops it (its inverse mass and its two contacts are zero in the macro arrays, so
  the macro stages move it ballistically and its error does not limit the step);
- after each accepted macro step [t, t + H], the granule is integrated alone by RKN4(3) micro-steps
  with their own step control (relaxed tolerances), its two neighbours' positions read from the
  quintic Hermite interpolant of the macro step (positions, velocities, accelerations at both ends);
- the contact forces it exerted on its neighbours over the step are added to them as an external
  forcing: v += J / M and x += (integral of J) / M, J the impulse so far (the micro-steps'
  velocity and position weights integrate it), and their accelerations at t + H recomputed.

The coupling is explicit (the neighbours' trajectories inside a macro step do not see the fast
granule's pushes of that step): its error is of the order of the pushes' momentum, a fraction
m_fast / M = r^3 of a large granule's (2e-6 at r = 0.012, 1e-3 at 0.1) per macro step, inside the
relaxed zone only (granules the pulse has left).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from granchain.backends.kernels import rkn4 as _rkn
from granchain.backends.kernels.forces import POW_HERTZ, accelerations, contact_force
from granchain.backends.kernels.records import Forces, Params
from granchain.backends.kernels.rkloop import BETA, MAX_FACTOR, MIN_FACTOR, SAFETY, pi_exponent
from granchain.backends.kernels.schemes import RKN4

ALPHA = pi_exponent(RKN4)  # RKN4(3)'s PI exponent, as in the step loop

N = 2.5  # Hertz contacts, Eq. (motion_rescaled)
#: The kernels' model record of an elastic, unloaded Hertz chain without a wall (records.Params).
HERTZ_PARAMS = Params(N, POW_HERTZ, False, 0.0, 0.0)


@njit(cache=True)
def _forces(c, inv_m):
    """The kernels' force record of an elastic, unloaded chain (no static overlaps or forces)."""
    zeros = np.zeros(c.shape[0])
    return Forces(c, inv_m, HERTZ_PARAMS, zeros, zeros)


@njit(cache=True)
def _accepted_factor(err, err_old):
    """Step factor after an accepted step: the step loop's PI controller (``_dp5``) with RKN4's exponent."""
    return min(MAX_FACTOR, max(MIN_FACTOR, SAFETY * err ** -ALPHA * err_old ** BETA)) if err > 0.0 else MAX_FACTOR


@njit(cache=True)
def _rejected_factor(err):
    return min(1.0, max(MIN_FACTOR, SAFETY * err ** -ALPHA))


@njit(cache=True)
def _local_accelerations(x, c, inv_m, a, lo, hi):
    """a[lo..hi-1] (their contacts only)."""
    M = x.shape[0]
    for k in range(max(lo, 0), min(hi, M)):
        left = contact_force(x[k - 1] - x[k], c[k - 1], HERTZ_PARAMS) if k > 0 else 0.0
        right = contact_force(x[k] - x[k + 1], c[k], HERTZ_PARAMS) if k < M - 1 else 0.0
        a[k] = (left - right) * inv_m[k]


@njit(cache=True)
def _quintic(p0, v0, a0, p1, v1, a1, H, out):
    """Coefficients (in theta = tau / H) of the quintic Hermite interpolant through both ends."""
    d = p1 - p0
    hv0, hv1, ha0, ha1 = H * v0, H * v1, H * H * a0, H * H * a1
    out[0] = p0
    out[1] = hv0
    out[2] = 0.5 * ha0
    out[3] = 10 * d - 6 * hv0 - 4 * hv1 - 1.5 * ha0 + 0.5 * ha1
    out[4] = -15 * d + 8 * hv0 + 7 * hv1 + 1.5 * ha0 - ha1
    out[5] = 6 * d - 3 * hv0 - 3 * hv1 - 0.5 * ha0 + 0.5 * ha1


@njit(cache=True)
def _poly(q, th):
    return q[0] + th * (q[1] + th * (q[2] + th * (q[3] + th * (q[4] + th * q[5]))))


@njit(cache=True)
def _fast_forces(y, th, ql, qr, cl, cr):
    """(force of the left contact on the fast granule, force of the right contact on the right neighbour)."""
    return contact_force(_poly(ql, th) - y, cl, HERTZ_PARAMS), contact_force(y - _poly(qr, th), cr, HERTZ_PARAMS)


@njit(cache=True)
def _micro(y, w, H, ql, qr, cl, cr, inv_mj, rtol, atol, hstart, out):
    """The fast granule over [0, H]: RKN4(3) micro-steps from the step ``hstart``. out = (y, w, impulse
    on the left neighbour, its integral, the same for the right one, micro-steps, the next step)."""
    tau = 0.0
    h = hstart
    fl, fr = _fast_forces(y, 0.0, ql, qr, cl, cr)
    f0 = (fl - fr) * inv_mj
    Jl = 0.0  # impulse on the left neighbour so far (it is pushed by -fl)
    Jr = 0.0
    IJl = 0.0  # integral over [0, H] of the impulse history: (H - tau) weighted force
    IJr = 0.0
    steps = 0
    err_old = 1e-4
    proposed = h  # the controller's step, kept for the next macro step when the last one is cut short
    while tau < H:
        h = proposed
        if tau + h >= H:
            h = H - tau
        h2 = h * h
        y1 = y + h * (_rkn.C1 * w) + h2 * (_rkn.A10 * f0)
        gl1, gr1 = _fast_forces(y1, (tau + _rkn.C1 * h) / H, ql, qr, cl, cr)
        f1 = (gl1 - gr1) * inv_mj
        y2 = y + h * (_rkn.C2 * w) + h2 * (_rkn.A20 * f0 + _rkn.A21 * f1)
        gl2, gr2 = _fast_forces(y2, (tau + _rkn.C2 * h) / H, ql, qr, cl, cr)
        f2 = (gl2 - gr2) * inv_mj
        y3 = y + h * w + h2 * (_rkn.B0 * f0 + _rkn.B1 * f1 + _rkn.B2 * f2)
        gl3, gr3 = _fast_forces(y3, (tau + h) / H, ql, qr, cl, cr)
        f3 = (gl3 - gr3) * inv_mj
        w3 = w + h * (_rkn.P0 * f0 + _rkn.P1 * f1 + _rkn.P2 * f2 + _rkn.P3 * f3)
        ex = h2 * (_rkn.EB0 * f0 + _rkn.EB1 * f1 + _rkn.EB2 * f2 + _rkn.EB3 * f3)
        ev = h * (_rkn.EP0 * f0 + _rkn.EP1 * f1 + _rkn.EP2 * f2 + _rkn.EP3 * f3)
        err = max(abs(ex) / (atol + rtol * max(abs(y), abs(y3))), abs(ev) / (atol + rtol * max(abs(w), abs(w3))))
        steps += 1
        if err <= 1.0:
            # the forces on the neighbours over this micro-step, integrated with the method's weights
            jl = h * (_rkn.P0 * fl + _rkn.P1 * gl1 + _rkn.P2 * gl2 + _rkn.P3 * gl3)
            jr = h * (_rkn.P0 * fr + _rkn.P1 * gr1 + _rkn.P2 * gr2 + _rkn.P3 * gr3)
            kl = h2 * (_rkn.B0 * fl + _rkn.B1 * gl1 + _rkn.B2 * gl2)
            kr = h2 * (_rkn.B0 * fr + _rkn.B1 * gr1 + _rkn.B2 * gr2)
            rest = H - tau - h
            IJl -= rest * jl + kl
            IJr += rest * jr + kr
            Jl -= jl
            Jr += jr
            y, w, f0, fl, fr = y3, w3, f3, gl3, gr3
            tau += h
            factor = _accepted_factor(err, err_old)
            err_old = max(err, 1e-4)
            if h == proposed or factor < 1.0:  # a step cut short at H keeps the proposal
                proposed = h * factor
        else:
            proposed = h * _rejected_factor(err)
    out[0], out[1], out[2], out[3], out[4], out[5], out[6], out[7] = y, w, Jl, IJl, Jr, IJr, steps, proposed


@njit(cache=True)
def integrate(m, c, obs, x0, v0, t_grid, rtol, atol, relax_lag, factor, fast_mass, grid_v, counts):
    """Integrate the chain from (x0, v0) to t_grid[-1]; grid_v[g, q] = v_obs[q](t_grid[g]).
    counts = (macro steps, rejected macro steps, micro-steps, fast granules)."""
    M = m.shape[0]
    n_obs = obs.shape[0]
    x = x0.copy()
    v = v0.copy()
    inv_m = 1.0 / m
    cm = c.copy()  # the macro system's stiffness and inverse masses (fast granules cut out)
    im = inv_m.copy()
    fast = np.zeros(M, np.bool_)
    hmicro = np.full(M, 1e-3)
    F = np.zeros(M + 1)  # contact forces (scratch of _common.accelerations)
    a = np.zeros(M)
    f1 = np.zeros(M)
    f2 = np.zeros(M)
    f3 = np.zeros(M)
    xs = np.zeros(M)
    vs = np.zeros(M)
    ql = np.zeros(6)
    qr = np.zeros(6)
    out = np.zeros(8)
    push_x = np.zeros(M)  # the fast granules' pushes on their neighbours over a macro step
    push_v = np.zeros(M)
    vprev = np.zeros(n_obs)
    peaked = np.zeros(n_obs, np.bool_)
    fm = _forces(cm, im)
    accelerations(x, v, fm, M, F, a, False)
    front = -1
    relaxed = 0
    for q in range(n_obs):
        grid_v[0, q] = v[obs[q]]
        vprev[q] = v[obs[q]]
    g = 1
    t = 0.0
    h = 1e-3
    err_old = 1e-4
    steps = 0
    rejected = 0
    micro = 0
    while g < t_grid.shape[0]:
        land = t + h >= t_grid[g]
        if land:
            h = t_grid[g] - t
        h2 = h * h
        for i in range(M):
            xs[i] = x[i] + h * (_rkn.C1 * v[i]) + h2 * (_rkn.A10 * a[i])
        accelerations(xs, v, fm, M, F, f1, False)
        for i in range(M):
            xs[i] = x[i] + h * (_rkn.C2 * v[i]) + h2 * (_rkn.A20 * a[i] + _rkn.A21 * f1[i])
        accelerations(xs, v, fm, M, F, f2, False)
        for i in range(M):
            xs[i] = x[i] + h * v[i] + h2 * (_rkn.B0 * a[i] + _rkn.B1 * f1[i] + _rkn.B2 * f2[i])
        accelerations(xs, v, fm, M, F, f3, False)
        err = 0.0
        for i in range(M):
            vs[i] = v[i] + h * (_rkn.P0 * a[i] + _rkn.P1 * f1[i] + _rkn.P2 * f2[i] + _rkn.P3 * f3[i])
            w = factor if i < relaxed else 1.0
            ex = h2 * (_rkn.EB0 * a[i] + _rkn.EB1 * f1[i] + _rkn.EB2 * f2[i] + _rkn.EB3 * f3[i])
            ev = h * (_rkn.EP0 * a[i] + _rkn.EP1 * f1[i] + _rkn.EP2 * f2[i] + _rkn.EP3 * f3[i])
            err = max(err, abs(ex) / ((atol + rtol * max(abs(x[i]), abs(xs[i]))) * w),
                      abs(ev) / ((atol + rtol * max(abs(v[i]), abs(vs[i]))) * w))
        if not err <= 1.0:
            rejected += 1
            h *= _rejected_factor(err)
            continue
        steps += 1
        # the fast granules over [t, t + h] (all on the macro step's trajectories of their
        # neighbours), then their pushes on their neighbours
        n_fast = 0
        for j in range(1, M - 1):
            if fast[j]:
                n_fast += 1
                _quintic(x[j - 1], v[j - 1], a[j - 1], xs[j - 1], vs[j - 1], f3[j - 1], h, ql)
                _quintic(x[j + 1], v[j + 1], a[j + 1], xs[j + 1], vs[j + 1], f3[j + 1], h, qr)
                _micro(x[j], v[j], h, ql, qr, c[j - 1], c[j], inv_m[j], rtol * factor, atol * factor, hmicro[j], out)
                xs[j], vs[j] = out[0], out[1]
                push_v[j - 1] += out[2] * inv_m[j - 1]
                push_x[j - 1] += out[3] * inv_m[j - 1]
                push_v[j + 1] += out[4] * inv_m[j + 1]
                push_x[j + 1] += out[5] * inv_m[j + 1]
                micro += int(out[6])
                hmicro[j] = out[7]
        if n_fast > 0:
            for i in range(M):
                xs[i] += push_x[i]
                vs[i] += push_v[i]
                push_x[i] = 0.0
                push_v[i] = 0.0
        for i in range(M):
            x[i] = xs[i]
            v[i] = vs[i]
            a[i] = f3[i]
        for j in range(1, M - 1):
            if fast[j]:
                _local_accelerations(x, cm, im, a, j - 2, j + 3)
        t += h
        if land:
            for q in range(n_obs):
                grid_v[g, q] = v[obs[q]]
            g += 1
        # the front: the most advanced observed granule whose velocity has stopped rising (as the kernel:
        # its acceleration went from + to <= 0; a free end granule ends on a plateau)
        for q in range(n_obs):
            vq = v[obs[q]]
            if not peaked[q] and vq <= vprev[q] and vq > 0.0:
                peaked[q] = True
                front = max(front, q)
            vprev[q] = vq
        if front >= relax_lag:
            relaxed = obs[front - relax_lag]
            if fast_mass > 0.0:
                for j in range(1, relaxed):
                    if not fast[j] and m[j] < fast_mass and j < M - 1:
                        fast[j] = True
                        im[j] = 0.0
                        cm[j - 1] = 0.0
                        cm[j] = 0.0
                        _local_accelerations(x, cm, im, a, j - 2, j + 3)
        h *= _accepted_factor(err, err_old)
        err_old = max(err, 1e-4)
    counts[0], counts[1], counts[2] = steps, rejected, micro
    counts[3] = int(fast.sum())
