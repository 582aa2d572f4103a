"""What an accepted Runge-Kutta step records, located on its dense output over [t, t + h]: the
observed granules' velocity maxima, the contacts' force maxima and the velocities (and a wall's
force) at the grid times inside the step. The step loop (``rkloop``) calls these in turn after
every accepted step; they are inlined into it, so splitting them out costs nothing per step.

``step`` is the step's ``records.Dense`` (state at its start and stage slots, as views from the
window's first granule ``lo`` on), ``hw`` the window's width and ``hp`` its padded width
(``rkloop.padded_width``), ``fm`` the step's ``records.Forces``, ``Q``/``QV`` scratch for the
position and velocity weights of the dense output (``dense.weights``).
"""

from __future__ import annotations

from numba import njit

from .dense import (
    ROOT_ACCELERATION,
    ROOT_APPROACH,
    dense_compression,
    dense_value,
    falls,
    first_root,
    hermite_max_estimate,
    weights,
)
from .forces import contact_force
from .jit import JIT_INLINE
from .peaks import is_new_peak

#: Contact-force screen: the root of a compression maximum is searched only if the Hermite
#: estimate of that maximum reaches this fraction of the contact's recorded peak compression.
SCREEN = 0.9


@njit(**JIT_INLINE)
def velocity_peaks(method, step, hw, hp, lo, t, fm, Q, QV, run, out, front):
    """Velocity maxima of the observed granules inside the step (their acceleration goes from + to
    -: a root of the dense output's acceleration), kept in ``out.peak_v``/``out.peak_t`` by the tie
    rule ``peaks.is_new_peak``. Returns the front: the most advanced observed granule (index into
    ``run.observed``) whose maximum has been located, never moving backwards from ``front``.

    A vectorised count over every granule of the window (zeros past it) first; the loop over the
    observed granules runs only when it finds one (1.6 % of the steps of an N = 26 decorated chain
    have one there)."""
    V, Kv, h = step.v, step.Kv, step.h
    obs = run.observed
    n_candidates = 0
    for i in range(hp):
        n_candidates += falls(Kv[0, i], Kv[6, i])
    for q in range(obs.shape[0] if n_candidates > 0 else 0):
        k = obs[q] - lo
        if k < 0 or k >= hw:
            continue
        a0 = Kv[0, k]
        a1 = Kv[6, k]
        if falls(a0, a1):
            theta = first_root(method, ROOT_ACCELERATION, k, (a0, a1), step, fm, Q, QV)
            weights(method, theta, Q, QV)
            vpk = dense_value(V[k], Kv, k, h, QV)
            if is_new_peak(vpk, out.peak_v[q], run.peak_rtol):
                out.peak_v[q] = vpk
                out.peak_t[q] = t + theta * h
            front = max(front, q)
    return front


@njit(**JIT_INLINE)
def force_peaks(method, step, XS, hw, hp, lo, t, fm, Q, QV, run, out, peak_d):
    """Force maxima of the window's contacts inside the step: compression maxima, where v_j - v_{j+1}
    goes from + to -, with the force c_j delta^(n-1) there (Eq. motion_rescaled) kept in
    ``out.peak_f``/``out.peak_ft`` by the tie rule and its compression in ``peak_d`` (indices from
    the chain's first contact). ``XS`` is the state at the step's end.

    The same vectorised count first (~80 % of the steps of an N = 26 decorated chain have no
    candidate; the contacts past the window, resting or padding, are never one, except the
    padding's with the last granule, which only lets the loop run). Then a screen: the cubic
    Hermite estimate of the compression maximum from the step's ends (error O(h^4), far below the
    margin) that cannot beat the recorded peak skips the root. (One rarely taken branch per
    contact: a test of w0 > 0 alone would be a coin flip.)"""
    X, Kx, h = step.x, step.Kx, step.h
    n_candidates = 0
    for j in range(hp):
        n_candidates += falls(Kx[0, j] - Kx[0, j + 1], Kx[6, j] - Kx[6, j + 1])
    for j in range(hw - 1 if n_candidates > 0 else 0):
        w0 = Kx[0, j] - Kx[0, j + 1]
        w1 = Kx[6, j] - Kx[6, j + 1]
        if falls(w0, w1):
            d0 = X[j] - X[j + 1]
            d1 = XS[j] - XS[j + 1]
            if hermite_max_estimate(d0, w0, d1, w1, h) < SCREEN * peak_d[lo + j]:
                continue
            theta = first_root(method, ROOT_APPROACH, j, (w0, w1), step, fm, Q, QV)
            weights(method, theta, Q, QV)
            dp = dense_compression(j, X, Kx, h, Q)
            fp = contact_force(dp, fm.stiffness[j], fm.params)  # Eq. (motion_rescaled): c_j delta^(n-1)
            if fp > 0.0 and is_new_peak(fp, out.peak_f[lo + j], run.peak_rtol):
                out.peak_f[lo + j] = fp
                out.peak_ft[lo + j] = t + theta * h
                peak_d[lo + j] = dp


@njit(**JIT_INLINE)
def grid_samples(method, step, hw, hi, lo, M, t, g, Q, QV, v, fm, run, out):
    """The observed granules' velocities (and, with a wall, the wall force) at the grid times
    ``run.t_grid[g:]`` inside the step, into ``out.grid_v``/``out.grid_f``; a granule behind the
    window (a trailing-window cut) keeps the velocity it left with (``v``, the whole chain's
    velocities), one ahead of it is at rest. Returns the next grid index."""
    X, V, Kx, Kv, h = step.x, step.v, step.Kx, step.Kv, step.h
    obs, t_grid = run.observed, run.t_grid
    while g < t_grid.shape[0] and t_grid[g] <= t + h:
        theta = (t_grid[g] - t) / h
        weights(method, theta, Q, QV)
        for q in range(obs.shape[0]):
            k = obs[q] - lo
            if k < 0:  # behind the window: the velocity it left with
                out.grid_v[g, q] = v[obs[q]]
            else:
                out.grid_v[g, q] = dense_value(V[k], Kv, k, h, QV) if k < hw else 0.0
        if fm.params.wall:
            out.grid_f[g] = (contact_force(dense_compression(M - 2 - lo, X, Kx, h, Q), fm.stiffness[M - 2 - lo], fm.params)
                             if M - 2 < hi else 0.0)
        g += 1
    return g
