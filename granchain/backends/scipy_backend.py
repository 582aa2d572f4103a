"""The SciPy backend: SciPy's DOP853 on the same problem, the independent reference integrator.

Everything here is plain NumPy/SciPy, sharing no numerical code with the
compiled kernels: the right-hand side of Eq. (motion_rescaled) is vectorised
over the whole chain (no active window), steps are SciPy's DOP853 (order 8,
its own error norm and controller), peaks are roots of the acceleration on
SciPy's order-7 dense output found with ``scipy.optimize.brentq``, and so are the
compression maxima of every contact (roots of v_k - v_{k+1}; force c_k delta^(n-1)
there). Only the stopping rule (and the tie rule of peaks) is the same, so both
integrators stop at the same physical event. A wall (last mass infinite) needs no
special code beyond that rule: its acceleration F / inf is 0. The real contacts follow
the same equations in their own NumPy code: the viscoelastic law (its dissipated
energy one more component of the state, its force peaks roots of the force's rate) and
the precompressed chain in displacements from its static state. A law with memory (Thornton's
elastic-plastic contact, ``ElasticPlastic``) carries each contact's largest overlap; every switch of
its branches (first yield, the turn from loading to unloading, reloading past the history) is located
as an event on the dense output and the integration restarts there, so no step straddles one.
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import DOP853 as _SciPyDOP853
from scipy.optimize import brentq

from .._status import MAX_STEPS, NONFINITE, STEP_UNDERFLOW, SUCCESS, T_MAX
from ..model.contacts import PowerLaw, Precompression
from . import Backend
from .kernels.peaks import write_info
from .kernels.records import INFO_SIZE
from .kernels.stop import RATTLER_MASS_RATIO


def chain_rhs(masses: np.ndarray, stiffness: np.ndarray, n: float, law=None, static_force: float = 0.0, history=None,
              yield_overlap=None):
    """f(t, y) for y = (x, v) (and, for a viscoelastic law, the dissipated energy as a last component),
    Eq. (motion_rescaled), vectorised with NumPy; returns (rhs, forces) with forces(x, v) the contacts'
    total forces (static load included).

    ``law`` is the chain's contact law (any ``granchain.model.contacts.ContactLaw``: its NumPy ``force``);
    ``static_force`` F0 > 0 precompresses the chain: x are displacements from the
    static state, each contact has the overlap delta0 = (F0 / c)^(1/(n-1)) and the accelerations come
    from the forces less their static values (the external load balances them at the ends). ``history``: for
    a law with memory (``law.history``), each contact's largest overlap so far, read at every call (the caller
    moves it between steps), and ``yield_overlap`` each contact's yield overlap (None: one material)."""
    M = masses.size
    law = PowerLaw(n) if law is None else law
    damped = law.dissipates and not law.history  # a rate-dependent law: its dissipated energy is integrated
    with np.errstate(divide="ignore"):
        d0 = Precompression(static_force).overlaps(stiffness, n)  # the static state, declared by the load
    f0 = law.elastic_force(d0, stiffness)

    def forces(x, v=None):
        d = d0 + (x[:-1] - x[1:])
        if law.history:
            return law.force(d, stiffness, history=history, yield_overlap=yield_overlap)
        if damped:
            return law.force(d, stiffness, v[:-1] - v[1:])
        return law.force(d, stiffness)

    def rhs(t, y):
        x, v = y[:M], y[M:2 * M]
        F = forces(x, v)
        G = F - f0
        a = np.zeros(M)
        a[1:] += G
        a[:-1] -= G
        if damped:  # the power taken from the motion: (F - F_elastic) w
            d = d0 + (x[:-1] - x[1:])
            el = law.elastic_force(d, stiffness)
            power = np.sum(np.where(d > 0.0, (F - el) * (v[:-1] - v[1:]), 0.0))
            return np.concatenate((v, a / masses, [power]))
        return np.concatenate((v, a / masses))

    return rhs, forces


def _first_nonpositive(f, t0, t1):
    """First time in [t0, t1] where f (positive at t0) reaches <= 0.

    brentq for a sign change; bisection when f(t1) is exactly zero (an opened
    contact: the acceleration is zero on an interval and its start is wanted).
    """
    if f(t1) < 0.0:
        return brentq(f, t0, t1, xtol=1e-15, rtol=1e-15)
    for _ in range(200):
        tm = 0.5 * (t0 + t1)
        if f(tm) > 0.0:
            t0 = tm
        else:
            t1 = tm
        if t1 - t0 < 1e-14 * max(1.0, abs(t1)):
            break
    return t1


def _pulse_has_left(x, v, m, gap=0.0) -> bool:
    """Same rule as the kernels' ``stop.pulse_is_out`` (wall_released with a wall, else pulse_has_left); ``gap``
    the compression at or below which the last contact is open (a yielded contact's plastic overlap, else 0)."""
    if np.isinf(m[-1]):  # a wall: its contact open and the granule next to it moving away
        return bool(x[-2] - x[-1] <= gap and v[-2] < 0.0)
    if x[-2] - x[-1] > gap:
        return False
    heavy = m[:-1] >= RATTLER_MASS_RATIO * m[-1]
    return v[-1] > 0.0 and v[-2] < v[-1] and bool(np.all(v[:-1][heavy] < v[-1]))


def _history_event(dense, y_old, y, t0, t1, history, d0, tol, M):
    """The first time in (t0, t1] where a contact of a law with memory switches branch, or None: where a
    contact below its history (on its unloading curve) reaches it again (reloading; the first yield is the
    reloading of a virgin contact past its yield overlap), or where a contact on the loading branch turns back
    (its relative velocity falls through 0 beyond the history: the unloading starts there). Excursions past
    the history by less than ``tol`` (per contact) are no events: the history takes them after the step."""
    def compression(s, j):
        z = dense(s)
        return d0[j] + z[j] - z[j + 1]

    def approach(s, j):
        z = dense(s)
        return z[M + j] - z[M + j + 1]

    dA = d0 + y_old[:M - 1] - y_old[1:M]
    dB = d0 + y[:M - 1] - y[1:M]
    wA = y_old[M:2 * M - 1] - y_old[M + 1:2 * M]
    wB = y[M:2 * M - 1] - y[M + 1:2 * M]
    turns = (wA > 0.0) & (wB <= 0.0)
    first = None
    for j in np.flatnonzero(turns | (np.maximum(dA, dB) > history + tol)):
        end, top = t1, max(dA[j], dB[j])
        if turns[j]:
            end = _first_nonpositive(lambda s, j=j: approach(s, j), t0, t1)
            top = max(top, compression(end, j))
        if top <= history[j] + tol[j]:
            continue
        if dA[j] < history[j] - tol[j]:  # reloading: the crossing of the history
            te = brentq(lambda s, j=j: compression(s, j) - history[j], t0, end, xtol=1e-15, rtol=1e-15)
        elif turns[j]:  # on the loading branch, turning back
            te = end
        else:  # loading through the whole step
            continue
        first = te if first is None else min(first, te)
    return first


def dop853_integrate(masses, stiffness, n, obs, x0, v0, *, rtol, atol, t_max, stop_at_exit, exit_margin, max_steps, peak_rtol,
                     t_grid, law=None, static_force=0.0, sensed=(), history=None):
    """Same contract as the compiled kernels; returns (status, info, peak_v, peak_t, grid_v, x, v, peak_f, peak_ft,
    grid_f, grid_c). ``history`` (M-1,): a law with memory's per-contact state: on entry the virgin contacts'
    yield overlaps (``kernels.records.State``; None: granules of one material), the largest overlaps on return."""
    M = masses.size
    law = PowerLaw(n) if law is None else law
    hist = dy = None
    if law.history:
        # a virgin contact: Hertz up to its yield overlap, where its history starts
        dy = law.yield_overlaps(stiffness) if history is None else np.array(history, dtype=float)
        hist = dy.copy()
        tol = 1e-10 * dy
    rhs, law_forces = chain_rhs(masses, stiffness, n, law, static_force, history=hist, yield_overlap=dy)
    damped = law.dissipates and not law.history
    sensed = np.asarray(sensed, dtype=np.int64)
    wall = bool(np.isinf(masses[-1]))
    y0 = np.concatenate((x0, v0, [0.0])) if damped else np.concatenate((x0, v0))
    solver = _SciPyDOP853(rhs, 0.0, y0, t_bound=t_max, rtol=rtol, atol=atol)
    evaluations = 0
    accel = lambda y: rhs(0.0, y)[M:2 * M]  # noqa: E731

    def forces(z):  # total contact forces of a state z = (x, v, ...)
        return law_forces(z[:M], z[M:2 * M])

    d0 = Precompression(static_force).overlaps(stiffness, n)
    peak_v = v0[obs].astype(float)
    peak_t = np.zeros(obs.size)
    grid_v = np.zeros((t_grid.size, obs.size))  # time-major, as the kernels
    g = int(np.searchsorted(t_grid, 0.0, side="right"))
    grid_v[:g] = v0[obs]
    peak_f = np.array(forces(y0), dtype=float)  # the forces at t = 0: 0, or the static load (as the kernels)
    peak_ft = np.zeros(M - 1)
    grid_f = np.zeros(t_grid.size)
    grid_c = np.zeros((t_grid.size, sensed.size))
    if wall:
        grid_f[:g] = forces(y0)[-1]
    grid_c[:g] = forces(y0)[sensed]
    t_needed = t_grid[-1] if t_grid.size else 0.0
    a_old = accel(y0)
    v_old = v0.astype(float)
    y_old = y0.copy()
    exit_since = -1.0
    n_steps = 0
    status = None
    while status is None:
        if n_steps >= max_steps:
            status = MAX_STEPS
            break
        message = solver.step()
        if solver.status == "failed":
            status = STEP_UNDERFLOW if "step size" in str(message) else NONFINITE
            break
        n_steps += 1
        y = solver.y
        if not np.all(np.isfinite(y)):
            status = NONFINITE
            break
        a_new = accel(y)
        dense = solver.dense_output()
        t0, t1 = solver.t_old, solver.t
        restart = False
        if hist is not None:  # a branch switch inside the step: the step ends there, the integration restarts
            t_event = _history_event(dense, y_old, y, t0, t1, hist, d0, tol, M)
            if t_event is not None and t_event < t1:
                t1, y, restart = t_event, dense(t_event), True
                a_new = accel(y)
        for q, k in enumerate(obs):
            if a_old[k] > 0.0 and a_new[k] <= 0.0:
                tp = _first_nonpositive(lambda s: accel(dense(s))[k], t0, t1)
                vp = dense(tp)[M + k]
                if vp > peak_v[q] + peak_rtol * abs(peak_v[q]):  # same tie rule as the kernels
                    peak_v[q], peak_t[q] = vp, tp
        w_old, w_new = v_old[:-1] - v_old[1:], y[M:2 * M - 1] - y[M + 1:2 * M]
        if damped:  # the force peaks where its rate falls through 0 (before the compression peaks)
            def rate(s, j):
                z = dense(s)
                a = accel(z)
                return law.force_rate(d0[j] + z[j] - z[j + 1], z[M + j] - z[M + j + 1], a[j] - a[j + 1], stiffness[j])

            for j in range(M - 1):
                r0 = law.force_rate(d0[j] + y_old[j] - y_old[j + 1], v_old[j] - v_old[j + 1], a_old[j] - a_old[j + 1],
                                    stiffness[j])
                r1 = law.force_rate(d0[j] + y[j] - y[j + 1], w_new[j], a_new[j] - a_new[j + 1], stiffness[j])
                if r0 > 0.0 and r1 <= 0.0:
                    tp = _first_nonpositive(lambda s, j=j: rate(s, j), t0, t1)
                    fp = forces(dense(tp))[j]
                    if fp > 0.0 and fp > peak_f[j] + peak_rtol * abs(peak_f[j]):
                        peak_f[j], peak_ft[j] = fp, tp
        else:
            for j in np.flatnonzero((w_old > 0.0) & (w_new <= 0.0)):  # compression maxima
                def approach(s, j=j):  # relative velocity v_j - v_{j+1} on the dense output
                    z = dense(s)
                    return z[M + j] - z[M + j + 1]

                tp = _first_nonpositive(approach, t0, t1)
                z = dense(tp)
                d = d0[j] + z[j] - z[j + 1]
                if hist is not None:
                    fp = float(law.force(d, stiffness[j], history=hist[j], yield_overlap=dy[j]))
                else:
                    fp = stiffness[j] * d ** (n - 1.0) if d > 0.0 else 0.0
                if fp > 0.0 and fp > peak_f[j] + peak_rtol * abs(peak_f[j]):
                    peak_f[j], peak_ft[j] = fp, tp
        g_end = int(np.searchsorted(t_grid, t1, side="right"))
        if g_end > g:
            yg = dense(t_grid[g:g_end])
            grid_v[g:g_end] = yg[M + obs].T
            fg = np.array([forces(z) for z in yg.T]) if (wall or sensed.size) else None
            if wall:
                grid_f[g:g_end] = fg[:, -1]
            if sensed.size:
                grid_c[g:g_end] = fg[:, sensed]
            g = g_end
        a_old = a_new
        v_old = y[M:2 * M].copy()
        y_old = y.copy()
        if hist is not None:
            np.maximum(hist, d0 + y[:M - 1] - y[1:M], out=hist)  # the loading branch moves the history
            if restart:
                evaluations += solver.nfev
                solver = _SciPyDOP853(rhs, t1, y, t_bound=solver.t_bound, rtol=rtol, atol=atol)
        if stop_at_exit:
            gap = 0.0
            if hist is not None:  # a yielded last contact opens at its plastic overlap (the dent it keeps)
                gap = float(law.plastic_overlap(hist[-1], stiffness[-1], dy[-1])) - d0[-1]
            if _pulse_has_left(y[:M], y[M:2 * M], masses, gap):
                if exit_since < 0.0:
                    exit_since = t1
                if t1 >= max(exit_since + exit_margin, t_needed):
                    status = SUCCESS
                    break
                solver.t_bound = min(t_max, max(exit_since + exit_margin, t_needed))  # land on the stop time
            else:
                exit_since = -1.0
                solver.t_bound = t_max
        if solver.status == "finished":
            if solver.t < t_max:  # reached a provisional exit stop whose condition no longer holds
                solver.status = "running"
            else:
                status = T_MAX if stop_at_exit else SUCCESS
    a_end = accel(solver.y)
    for q, k in enumerate(obs):
        if a_end[k] > 0.0 and solver.y[M + k] > peak_v[q] + peak_rtol * abs(peak_v[q]):  # as final_peaks
            peak_v[q], peak_t[q] = solver.y[M + k], solver.t
    x_end, v_end = solver.y[:M], solver.y[M:2 * M]
    f_end = forces(solver.y)
    for j in range(M - 1):  # as final_force_peaks
        if v_end[j] - v_end[j + 1] > 0.0 and f_end[j] > 0.0 and f_end[j] > peak_f[j] + peak_rtol * abs(peak_f[j]):
            peak_f[j], peak_ft[j] = f_end[j], solver.t
    info = np.zeros(INFO_SIZE)
    dissipated = float(solver.y[2 * M]) if damped else 0.0
    if hist is not None:  # the plastic work, a function of each contact's history
        dissipated = float(np.sum(law.plastic_work(hist, stiffness, dy)))
        if history is not None:
            history[:] = hist
    write_info(info, solver.t, n_steps, 0, exit_since, evaluations + solver.nfev, 0, 0.0, dissipated)  # no rejections counted, no window
    return (status, info, peak_v, peak_t, grid_v, x_end.copy(), v_end.copy(), peak_f, peak_ft, grid_f, grid_c)


class ScipyBackend(Backend):
    """Runs :class:`granchain.DOP853` (and any integrator that names this backend) with SciPy, in
    plain Python: slow, and sharing no numerical code with the compiled kernels, which is its point.
    Batches run realisation by realisation (:meth:`Backend.integrate_batch`)."""

    name = "scipy"

    #: Any contact law: the right-hand side and the force peaks are the law's own NumPy code
    #: (``ContactLaw.force``, ``force_rate``), nothing compiled.
    law_forms = None

    #: Carries a per-contact history for the laws that need one (``ContactLaw.history``).
    carries_history = True

    def integrate(self, integrator, chain, x, v, *, t_grid, t_max, stop_at_exit, controls, sensed=None, history=None):
        self.check(integrator, chain)
        status, info, peak_v, peak_t, grid_v, xf, vf, peak_f, peak_ft, grid_f, grid_c = dop853_integrate(
            chain.masses, chain.stiffness, chain.n, chain.observed, x.copy(), v.copy(),
            rtol=integrator.rtol, atol=integrator.atol, t_max=t_max, stop_at_exit=stop_at_exit,
            exit_margin=controls.exit_margin, max_steps=controls.max_steps, peak_rtol=controls.peak_rtol, t_grid=t_grid,
            law=chain.contact, static_force=chain.static_force, sensed=() if sensed is None else sensed, history=history,
        )
        x[:] = xf
        v[:] = vf
        return int(status), info, peak_v, peak_t, grid_v, peak_f, peak_ft, grid_f, grid_c
