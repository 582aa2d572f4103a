"""Velocity Verlet (symplectic, second order) with fixed step, for one chain.

x_{n+1} = x_n + h v_n + h^2 a_n / 2,  v_{n+1} = v_n + h (a_n + a_{n+1}) / 2.

Peaks are located between steps with the cubic Hermite interpolant of (v, a)
at the step ends, the peak time from the zero of the linearly interpolated
acceleration; grid samples use the same Hermite cubic. Peak contact forces: the
compression maximum of contact j at the zero of the linearly interpolated relative
velocity v_j - v_{j+1}, the force there from the cubic Hermite interpolant of the
positions through (x, v) at the step ends. These are accurate to the method's own
second order, with one exception: where a granule's acceleration drops to exactly zero
at a step's end (the last granule of a free chain, when its contact opens), the zero of
the linear interpolant is that step end, so its peak time is known only to within one
step (measured on monodisperse(8): errors 8.7e-4, 3.7e-4, 1.2e-4 at dt = 1e-3, 5e-4,
2.5e-4, against DOP853).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..._status import MAX_STEPS, NONFINITE
from .forces import accelerations, contact_force, static_state
from .jit import JIT_INLINE, JIT_INTERNAL
from .peaks import (
    final_force_peaks,
    final_peaks,
    initial_force_records,
    initial_records,
    is_new_peak,
    write_info,
)
from .records import Forces
from .stop import end_of_step, stop_time
from .window import advance_window, initial_window, margin

ORDER = 2


@njit(**JIT_INTERNAL)
def hermite(y0, dy0, y1, dy1, h, theta):
    """Cubic Hermite interpolant of y through (y0, y0') and (y1, y1') at the step ends, at t + theta h:
    the velocity from (v, a), the position from (x, v)."""
    t2 = theta * theta
    t3 = t2 * theta
    return (2 * t3 - 3 * t2 + 1) * y0 + (t3 - 2 * t2 + theta) * h * dy0 + (-2 * t3 + 3 * t2) * y1 + (t3 - t2) * h * dy1


@njit(**JIT_INTERNAL)
def _hermite_force(j, x_old, v_old, x, v, h, theta, c, p, o):
    """Contact force of contact j at t + theta h from the Hermite positions (Eq. motion_rescaled), its
    static overlap ``o[j]`` included (a precompressed chain)."""
    d = hermite(x_old[j], v_old[j], x[j], v[j], h, theta) - hermite(x_old[j + 1], v_old[j + 1], x[j + 1], v[j + 1], h, theta)
    return contact_force(o[j] + d, c[j], p)


@njit(**JIT_INLINE)
def verlet_integrate(general, h, model, run, state, out):
    """Fixed-step velocity Verlet with step ``h``; the contract of the entry points of ``dispatch`` (``model``,
    ``run``, ``state``, ``out``: the records of ``records``).

    ``general`` is a compile-time constant of the entry point that inlines this (``dispatch.verlet_chain``
    for the paper's chain, ``verlet_chain_general`` for a static load), as in ``rkloop``: with the model
    class a run-time value, the paper's chain paid ~45 ns per step of 51 granules (~25 %) for code it
    never runs (same-process timing, ``benchmarks/bench_verlet.py``)."""
    m, c, p = model.masses, model.stiffness, model.params
    x_end, v_end, _ = state  # (no per-contact history: Verlet refuses the laws with memory, as not conservative)
    x, v = x_end, v_end
    obs, t_grid, peak_rtol = run.observed, run.t_grid, run.peak_rtol
    peak_v, peak_t, grid_v, peak_f, peak_ft, grid_f = out.peak_v, out.peak_t, out.grid_v, out.peak_f, out.peak_ft, out.grid_f
    M = m.shape[0]
    n_obs = obs.shape[0]
    n_grid = t_grid.shape[0]
    inv_m = 1.0 / m
    o = np.zeros(M)  # static overlaps and forces of a precompressed chain (forces.static_state)
    f0 = np.zeros(M)
    if p.static_force > 0.0:
        for j in range(M - 1):
            o[j], f0[j] = static_state(c[j], p)
    fm = Forces(c, inv_m, p, o, f0, o, o)
    a = np.zeros(M)
    a_new = np.zeros(M)
    v_old = v.copy()  # the other pair of buffers (see the step loop)
    x_old = x.copy()
    F = np.zeros(M + 1)  # contact forces, F[j + 1] for contact j (see forces.accelerations)
    ahead = margin(p)
    hi = initial_window(x, v, ahead)
    accelerations(x, v, fm, hi, F, a, general)
    n_eval = 1
    t = 0.0
    g = initial_records(obs, v, t_grid, peak_v, peak_t, grid_v)
    t_needed = t_grid[n_grid - 1] if n_grid > 0 else 0.0
    initial_force_records(x, v, model, g, out, run.contacts)
    exit_since = -1.0
    n_acc = 0
    status = -1
    while status < 0:
        if n_acc >= run.max_steps:
            status = MAX_STEPS
            break
        dt = h
        t_stop = stop_time(run, exit_since, t_needed)
        last = False
        if t + dt >= t_stop:
            dt = t_stop - t
            last = True
        # The step's start (x_old, v_old) and end (x, v) are two pairs of buffers that trade places:
        # no copy per step. Granules past the window rest (0) in both.
        x_old, x = x, x_old
        v_old, v = v, v_old
        finite = True  # (is_finite_window, fused into the updates: one pass less per step)
        for i in range(hi):
            x[i] = x_old[i] + (dt * v_old[i] + 0.5 * dt * dt * a[i])
            finite &= abs(x[i]) < math.inf
        accelerations(x, v, fm, hi, F, a_new, general)  # forces of positions only (Verlet refuses others): v unread
        n_eval += 1
        for i in range(hi):
            v[i] = v_old[i] + 0.5 * dt * (a[i] + a_new[i])
            finite &= abs(v[i]) < math.inf
        for q in range(n_obs):
            k = obs[q]
            if k >= hi:
                continue
            if a[k] > 0.0 and a_new[k] <= 0.0:
                theta = a[k] / (a[k] - a_new[k])
                vp = hermite(v_old[k], a[k], v[k], a_new[k], dt, theta)
                if is_new_peak(vp, peak_v[q], peak_rtol):
                    peak_v[q] = vp
                    peak_t[q] = t + theta * dt
        # A compression maximum (the relative velocity of a contact turns from closing to opening) is
        # rare: a branch-free pass that vectorises finds whether one happened in this step, and only
        # then the contacts are searched for it.
        turned = False
        for j in range(hi - 1):
            turned |= (v_old[j] - v_old[j + 1] > 0.0) & (v[j] - v[j + 1] <= 0.0)
        for j in range(hi - 1 if turned else 0):
            w0 = v_old[j] - v_old[j + 1]
            w1 = v[j] - v[j + 1]
            if (w0 > 0.0) & (w1 <= 0.0):
                theta = w0 / (w0 - w1)
                fp = _hermite_force(j, x_old, v_old, x, v, dt, theta, c, p, o)
                if fp > 0.0 and is_new_peak(fp, peak_f[j], peak_rtol):
                    peak_f[j] = fp
                    peak_ft[j] = t + theta * dt
        while g < n_grid and t_grid[g] <= t + dt:
            theta = (t_grid[g] - t) / dt
            for q in range(n_obs):
                k = obs[q]
                grid_v[g, q] = hermite(v_old[k], a[k], v[k], a_new[k], dt, theta) if k < hi else 0.0
            if p.wall:
                grid_f[g] = _hermite_force(M - 2, x_old, v_old, x, v, dt, theta, c, p, o) if M - 2 < hi else f0[M - 2]
            for s in range(run.contacts.shape[0]):  # granules past the window are at rest: exact there too
                out.grid_c[g, s] = _hermite_force(run.contacts[s], x_old, v_old, x, v, dt, theta, c, p, o)
            g += 1
        a, a_new = a_new, a
        t = t + dt if not last else t_stop
        n_acc += 1
        if not finite:
            status = NONFINITE
            break
        new_hi = advance_window(x, v, hi, ahead)
        if new_hi > hi:
            hi = new_hi
            accelerations(x, v, fm, hi, F, a, general)
            n_eval += 1
        status, exit_since = end_of_step(x, v, m, p.wall, hi, t, run, exit_since, t_needed)
        if status >= 0:
            break
    x_end[:] = x  # the final state, in whichever pair of buffers the last step ended
    v_end[:] = v
    final_peaks(obs, 0, v, a, t, peak_rtol, peak_v, peak_t)
    final_force_peaks(x, v, c, p, 0, t, peak_rtol, peak_f, peak_ft)
    write_info(out.info, t, n_acc, 0, exit_since, n_eval, 0, 0.0, 0.0)
    return status
