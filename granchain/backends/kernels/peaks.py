"""The records of a run: velocity and force peaks, grid samples at t = 0, the ``info`` slots.

Peak candidates are the local maxima of v_k(t) (acceleration + to -, located between steps by each
integrator), the velocity at t = 0 and at the end; contact forces likewise at the compression
maxima (relative velocity v_k - v_{k+1} + to -).
"""

from __future__ import annotations

from numba import njit

from .forces import law_force, static_state
from .jit import JIT, JIT_INTERNAL
from .records import (
    INFO_DISSIPATED,
    INFO_EVALUATIONS,
    INFO_EXIT,
    INFO_FROZEN_POTENTIAL,
    INFO_REJECTED,
    INFO_STEPS,
    INFO_T_END,
    INFO_WINDOW_START,
)


@njit(**JIT_INTERNAL)
def initial_records(obs, v, t_grid, peak_v, peak_t, grid_v):
    """The state at t = 0 is the first peak candidate and fills grid times <= 0; returns the next grid index."""
    n_obs = obs.shape[0]
    for q in range(n_obs):
        peak_v[q] = v[obs[q]]
        peak_t[q] = 0.0
    g = 0
    while g < t_grid.shape[0] and t_grid[g] <= 0.0:
        for q in range(n_obs):
            grid_v[g, q] = v[obs[q]]
        g += 1
    return g


@njit(**JIT_INTERNAL)
def initial_force_records(x, v, model, g, out, contacts):
    """The contact forces at t = 0 (the state (x, v)) are the first peak candidates, at time 0: 0 for an
    unloaded chain, the static load of a precompressed one (the floor its peaks rise from); with a wall,
    its force at the ``g`` grid times <= 0 into ``out.grid_f``, and the recorded ``contacts``'
    (``Run.contacts``) into ``out.grid_c``."""
    M = x.shape[0]
    p = model.params
    c = model.stiffness
    for j in range(M - 1):
        d0, _ = static_state(c[j], p)
        out.peak_f[j] = law_force(d0 + (x[j] - x[j + 1]), v[j] - v[j + 1], c[j], p)
        out.peak_ft[j] = 0.0
    if p.wall:
        for gg in range(g):
            out.grid_f[gg] = out.peak_f[M - 2]
    for s in range(out.grid_c.shape[1]):
        for gg in range(g):
            out.grid_c[gg, s] = out.peak_f[contacts[s]]


@njit(**JIT_INTERNAL)
def is_new_peak(candidate, current, peak_rtol):
    """Does a local maximum ``candidate`` replace the recorded peak ``current``?

    Candidates are the local maxima of v_k(t) (acceleration + to -), the
    velocity at t = 0 and at the end. A later maximum wins only if it is higher
    by more than ``peak_rtol`` (relative): maxima equal within the integration
    error are a tie, and the earliest is kept, so that the peak time does not
    jump between two humps (or to the plateau of a free end) on round-off.
    """
    return candidate > current + peak_rtol * abs(current)


@njit(**JIT_INTERNAL)
def final_peaks(obs, lo, v, a, t, peak_rtol, peak_v, peak_t):
    """The velocity at the end of the run is a candidate if the granule is still speeding up
    (a > 0). A granule in free flight (a = 0) had its maximum located where its contact
    opened; its end velocity carries the error of the step across that kink of the force,
    so it must not displace the located maximum.

    ``v``, ``a`` hold the integrated granules lo.. (index k - lo for granule k); granules
    behind a trailing window (k < lo) left it with their peaks final."""
    for q in range(obs.shape[0]):
        k = obs[q] - lo
        if k >= 0 and a[k] > 0.0 and is_new_peak(v[k], peak_v[q], peak_rtol):
            peak_v[q] = v[k]
            peak_t[q] = t


@njit(**JIT_INTERNAL)
def final_force_peaks(x, v, c, p, lo, t, peak_rtol, peak_f, peak_ft):
    """The force at the end of the run is a candidate for contacts still compressing
    (delta > 0 and v_k - v_{k+1} > 0): their maximum lies beyond the run.

    ``x``, ``v``, ``c`` hold the integrated granules lo.. and their contacts (contact j of the
    chain is entry j - lo); the contacts behind a trailing window have final peaks."""
    for j in range(x.shape[0] - 1):
        w = v[j] - v[j + 1]
        if w > 0.0:
            d0, _ = static_state(c[j], p)
            f = law_force(d0 + (x[j] - x[j + 1]), w, c[j], p)
            if f > 0.0 and is_new_peak(f, peak_f[lo + j], peak_rtol):
                peak_f[lo + j] = f
                peak_ft[lo + j] = t


@njit(**JIT)
def write_info(info, t, n_acc, n_rej, exit_since, n_eval, lo, frozen_potential, dissipated):
    """Fill the ``info`` record of a finished run (slots INFO_*)."""
    info[INFO_T_END] = t
    info[INFO_STEPS] = n_acc
    info[INFO_REJECTED] = n_rej
    info[INFO_EXIT] = exit_since
    info[INFO_EVALUATIONS] = n_eval
    info[INFO_WINDOW_START] = lo
    info[INFO_FROZEN_POTENTIAL] = frozen_potential
    info[INFO_DISSIPATED] = dissipated
