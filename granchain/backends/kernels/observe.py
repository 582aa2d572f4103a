"""What the adaptive Runge-Kutta step loop (``rkloop.rk_kernel``) records in an accepted step: the velocity
maxima of the observed granules (:func:`velocity_peaks`), the contact-force maxima (:func:`force_peaks`), the
grid samples of the averaged pulse, the wall's force and the sensed contacts' forces (:func:`sample_grid`), and
the turn of a yielding contact that retakes the step (:func:`yield_turn`). A run's first and last instants are
recorded by ``peaks``; the GPU's step loop records the same through ``granchain.backends.cuda.observe``.

Each block is a function of its own inlined into the loop at Numba-IR level (``JIT_INLINE``: the same code as
written out there, no call and no reference counting). They call the scheme's functions (``SCHEME.weights``,
``SCHEME.dense_data``), so the step loop compiles each once per scheme, with ``SCHEME`` bound as in the
kernel (``rkloop._specialised`` reads it as ``_scheme_<name>``, a global of this module that it sets); each
returns the loop state it moves. A lazy scheme (RKN4) lays its dense output into the stage arrays only when a
block needs it (``dense_ready``; laid out every step, it cost RKN4 16 % of an N = 26 decorated chain's time);
until then its step's end is in Kv[6] and VS. DP5's dense output is its stages. Moving the blocks here from the
step loop's module changed none of its machine code.
"""

from __future__ import annotations

import math

from .dense import (
    ROOT_APPROACH,
    ROOT_FORCE_RATE,
    dense_compression,
    dense_force,
    dense_value,
    falls,
    first_root,
    hermite_max_estimate,
    law_dense_force,
)
from .forces import contact_force, force_rate, plastic_force
from .peaks import is_new_peak

#: Contact-force screen: the root of a compression maximum is searched only if the Hermite
#: estimate of that maximum reaches this fraction of the contact's recorded peak compression.
SCREEN = 0.9
#: Thornton's elastic-plastic contacts (``forces.plastic_force``): a contact on its loading branch turns back in
#: a step where its compression peaks beyond its history by more than HISTORY_RTOL of its yield overlap
#: (:func:`yield_turn`; the step loop then retakes the step to end at the turn, ``rkloop.TURN_SLACK``).
HISTORY_RTOL = 1e-10


def yield_turn(kind, step, VE, hw, fm, Q, QV):
    """Thornton's contacts: the fraction theta of the step ``step`` (``records.Dense``; VE the velocities at
    its end) at which the first contact turns from loading to unloading beyond its history (1: none). The
    stages past such a turn used the loading line, so the step is retaken to end there; the turn is located
    on this step's dense output, exact up to the turn (the loading line continues smoothly past it)."""
    X, V, Kx, Kv, h = step
    OP, H, DY = fm.overlap, fm.history, fm.yield_overlap
    turn = 1.0
    for j in range(hw - 1):
        w0 = Kx[0, j] - Kx[0, j + 1]
        w1 = VE[j] - VE[j + 1]
        if falls(w0, w1):
            theta = first_root(kind, ROOT_APPROACH, j, (w0, w1), step, fm, Q, QV)
            SCHEME.weights(theta, Q, QV)
            top = OP[j] + dense_compression(j, X, Kx, h, Q)
            if top > H[j] + HISTORY_RTOL * DY[j] and theta < turn:
                turn = theta
    return turn


def velocity_peaks(kind, what, dense_ready, step, XS, VS, hp, fm, Q, QV, obs, q_lo, q_hi, lo, t, peak_v, peak_t,
                   peak_rtol, front):
    """Velocity maxima of the observed granules obs[q_lo..q_hi-1] in the step ``step`` (``records.Dense``,
    from t; the granules from ``lo`` on), where an acceleration goes from + to -: each root located on the
    dense output (``what``: the acceleration followed, ``dense.ROOT_ACCELERATION`` or, on the paper's chain,
    ``ROOT_ELASTIC_ACCELERATION``) and recorded if it is a new peak (``peaks.is_new_peak``). Returns (front, dense_ready):
    the most advanced observed granule whose maximum has been located, and whether the dense output is laid
    out. A vectorised count over every granule of the window (zeros past it) comes first; the loop over the
    observed granules runs only when it finds one (1.6 % of the steps of an N = 26 decorated chain)."""
    X, V, Kx, Kv, h = step
    n_candidates = 0
    for i in range(hp):
        n_candidates += falls(Kv[0, i], Kv[6, i])
    for q in range(q_lo, q_hi if n_candidates > 0 else q_lo):
        k = obs[q] - lo
        a0 = Kv[0, k]
        a1 = Kv[6, k]
        if falls(a0, a1):
            if not dense_ready:
                SCHEME.dense_data(X, V, XS, VS, Kx, Kv, h, hp)
                dense_ready = True
            theta = first_root(kind, what, k, (a0, a1), step, fm, Q, QV)
            SCHEME.weights(theta, Q, QV)
            vpk = dense_value(V[k], Kv, k, h, QV)
            if is_new_peak(vpk, peak_v[q], peak_rtol):
                peak_v[q] = vpk
                peak_t[q] = t + theta * h
            front = max(front, q)
    return front, dense_ready


def force_peaks(kind, dense_ready, damped, plastic, step, XS, VS, VE, hw, hp, fm, Q, QV, lo, t, peak_f, peak_ft, peak_d,
                peak_rtol):
    """Contact-force maxima of the window's contacts in the step ``step`` (``records.Dense``, from t; VE the
    velocities at its end), recorded into ``peak_f``, ``peak_ft`` (and the compression at each into
    ``peak_d``) of the chain's contacts from ``lo`` on. Elastic and yielding contacts: where v_j - v_{j+1}
    goes from + to - (the compression peaks), after the same vectorised count as the velocities' (~80 % of
    the steps of an N = 26 decorated chain have no candidate; the contacts past the window, resting or
    padding, are never one, except the padding's with the last granule, which only lets the loop run) and a
    screen that skips a root the recorded peak beats. ``damped`` (viscoelastic): where the force's rate
    falls, before the compression peaks. Returns whether the dense output is laid out."""
    X, V, Kx, Kv, h = step
    C, _, p, OP, _, H, DY = fm
    n_candidates = 0
    if damped:  # a viscoelastic force peaks before its compression does: follow its rate
        for j in range(hw - 1):
            r0 = force_rate(OP[j] + (X[j] - X[j + 1]), Kx[0, j] - Kx[0, j + 1], Kv[0, j] - Kv[0, j + 1], C[j], p)
            r1 = force_rate(OP[j] + (XS[j] - XS[j + 1]), Kx[6, j] - Kx[6, j + 1], Kv[6, j] - Kv[6, j + 1], C[j], p)
            if falls(r0, r1):
                theta = first_root(kind, ROOT_FORCE_RATE, j, (r0, r1), step, fm, Q, QV)
                SCHEME.weights(theta, Q, QV)
                fp = dense_force(j, step, fm, Q, QV)
                if fp > 0.0 and is_new_peak(fp, peak_f[lo + j], peak_rtol):
                    peak_f[lo + j] = fp
                    peak_ft[lo + j] = t + theta * h
    else:
        # (One rarely taken branch per contact: a test of w0 > 0 alone would be a coin flip.)
        for j in range(hp):
            n_candidates += falls(Kx[0, j] - Kx[0, j + 1], VE[j] - VE[j + 1])
    for j in range(hw - 1 if n_candidates > 0 else 0):
        w0 = Kx[0, j] - Kx[0, j + 1]
        w1 = VE[j] - VE[j + 1]
        if falls(w0, w1):
            # Screen: the cubic Hermite estimate of the compression maximum from the step ends
            # (error O(h^4), far below the margin) cannot beat the recorded peak: skip the root.
            d0 = OP[j] + (X[j] - X[j + 1])
            d1 = OP[j] + (XS[j] - XS[j + 1])
            if hermite_max_estimate(d0, w0, d1, w1, h) < SCREEN * peak_d[lo + j]:
                continue
            if not dense_ready:
                SCHEME.dense_data(X, V, XS, VS, Kx, Kv, h, hp)
                dense_ready = True
            theta = first_root(kind, ROOT_APPROACH, j, (w0, w1), step, fm, Q, QV)
            SCHEME.weights(theta, Q, QV)
            dp = OP[j] + dense_compression(j, X, Kx, h, Q)  # the static overlap included
            if plastic:  # Thornton's force: the history moved by this step is not yet in H
                fp = plastic_force(dp, H[j], C[j], DY[j])
            else:
                fp = contact_force(dp, C[j], p)  # Eq. (motion_rescaled): c_j delta^(n-1)
            if fp > 0.0 and is_new_peak(fp, peak_f[lo + j], peak_rtol):
                peak_f[lo + j] = fp
                peak_ft[lo + j] = t + theta * h
                peak_d[lo + j] = dp
    return dense_ready


def sample_grid(general, dense_ready, g, step, XS, VS, hp, fm, Q, QV, lo, hi, M, t, run, out, v, f0):
    """The grid samples run.t_grid[g..] that fall in the step ``step`` (``records.Dense``, from t; the
    granules lo..hi-1 integrated, of M): each observed granule's velocity into ``out.grid_v`` (the velocity
    it left the window with behind it; 0 past its averaged-pulse window, ``run.pulse_end``), the wall's
    total force into ``out.grid_f`` and each sensed contact's into ``out.grid_c`` (by the chain's law;
    ``general`` False: the paper's). Returns the next g."""
    X, V, Kx, Kv, h = step
    p = fm.params
    obs, t_grid, pulse_end, sensed = run.observed, run.t_grid, run.pulse_end, run.contacts
    n_obs, n_grid, n_sensed = obs.shape[0], t_grid.shape[0], sensed.shape[0]
    windows = pulse_end.shape[0] > 0
    hw = hi - lo
    if not dense_ready:
        SCHEME.dense_data(X, V, XS, VS, Kx, Kv, h, hp)
    while g < n_grid and t_grid[g] <= t + h:
        theta = (t_grid[g] - t) / h
        SCHEME.weights(theta, Q, QV)
        for q in range(n_obs):
            k = obs[q] - lo
            if windows and t_grid[g] > pulse_end[q]:  # past its averaged-pulse window: not recorded
                out.grid_v[g, q] = 0.0
            elif k < 0:  # behind the window: the velocity it left with
                out.grid_v[g, q] = v[obs[q]]
            else:
                out.grid_v[g, q] = dense_value(V[k], Kv, k, h, QV) if k < hw else 0.0
        if p.wall:  # the total force on the wall (the static load included; only that until the pulse is near)
            out.grid_f[g] = law_dense_force(general, M - 2 - lo, step, fm, Q, QV) if M - 2 < hi else f0[M - 2]
        for s in range(n_sensed):  # granules past the window are at rest: the force is exact there too
            j = sensed[s] - lo
            out.grid_c[g, s] = law_dense_force(general, j, step, fm, Q, QV) if j >= 0 else math.nan
        g += 1
    return g


