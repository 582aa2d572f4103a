"""A second backend, written here in plain NumPy/SciPy, enters through the public seam and passes the
conformance checks.

What is checked, and why: ``granchain.backends.Backend`` claims that an integrator can be run by any
code that implements ``integrate`` (and, through the base class's ``integrate_batch``, ensembles too),
passed as ``simulate(..., backend=...)`` or ``run_ensemble(..., backend=...)``, with no change to the
package. :class:`NumpyBackend` below is such code, sharing no numerical code with the package's
backends: its own Dormand-Prince 5(4) pair, step-size controller and quintic Hermite dense output,
vectorised over the chain, for elastic power-law contacts only. It imports from the package only the
seam (``Backend``), the status codes and the two helpers that lay out the ``info`` record.

1. Conformance: on every chain of ``test_backends.CHAINS`` it must give what SciPy's DOP853 at
   rtol 1e-11 gives, with the checks of ``test_backends.test_conformance_with_dop853`` (status, peak
   velocities and times at the in-order granules, grid velocities, energy, momentum or the wall's
   impulse, the exit event and t_end = exit + margin landed exactly), plus the contacts' peak forces
   and the wall force on the grid, which this backend computes in its own code too. It fails if the
   seam hands the backend something other than the contract says (state, grid, controls), if
   ``simulate`` reads the returned tuple or the ``info`` record otherwise than the contract describes,
   or if the second implementation is wrong (a peak rule, the stop rule, the landing on the stop time).
2. Ensembles: ``run_ensemble(backend=NumpyBackend())`` goes through the base class's batch loop and
   must give, per realisation, the peaks of the default CPU backend (SciPy's DOP853 here) within the
   accuracy contract, all statuses 0, and a store that names the backend that computed it. It fails
   if the batch loop assumes a compiled backend, or the store does not record a custom backend.
3. Refusal: ``simulate`` must refuse the backend, through its ``check`` and before integrating, on a
   dissipative chain, a precompressed one and a fixed-step method, with a message that says why. It
   fails if the seam skips ``check`` or the message does not name the reason.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import in_order
from scipy.optimize import brentq
from test_backends import CHAINS, EXIT_ATOL, EXIT_MARGIN, MOMENTUM_ATOL, T_GRID, Case, chain_named, reference_result

import granchain as gc
from granchain._status import MAX_STEPS, NONFINITE, STEP_UNDERFLOW, SUCCESS, T_MAX
from granchain.backends import Backend
from granchain.backends.kernels.peaks import write_info
from granchain.backends.kernels.records import INFO_SIZE

# -- the backend --------------------------------------------------------------------------------------
#: Dormand-Prince 5(4) (J. R. Dormand and P. J. Prince, J. Comput. Appl. Math. 6, 19 (1980)). The chain
#: is autonomous, so the nodes c_i are not needed. The last row is the 5th-order solution (FSAL: its
#: stage is the acceleration at the step's end, which the next step and the dense output reuse).
A = np.zeros((7, 7))
A[1, :1] = [1 / 5]
A[2, :2] = [3 / 40, 9 / 40]
A[3, :3] = [44 / 45, -56 / 15, 32 / 9]
A[4, :4] = [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729]
A[5, :5] = [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656]
A[6, :6] = [35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84]
#: 5th-order weights minus the embedded 4th-order ones: the local error estimate.
E = A[6] - [5179 / 57600, 0.0, 7571 / 16695, 393 / 640, -92097 / 339200, 187 / 2100, 1 / 40]
#: Same as the kernels' ``stop.RATTLER_MASS_RATIO`` (the stop rule must be the package's): granules
#: lighter than this fraction of the last one do not hold the pulse's exit.
RATTLER_MASS_RATIO = 0.1


def hermite(t0, h, x0, v0, a0, x1, v1, a1):
    """Dense output of one step: the quintic Hermite interpolant of the positions through
    (x, v = x', a = x'') at both ends (all known: the FSAL stages), and the velocities as its
    derivative, so that both stay consistent. Error O(h^6) in x and O(h^5) in v (DP5's own
    continuous extension is of order 4). Returns ``at(t) -> (x, v)``, t a scalar or an array (then rows are times)."""

    def at(t):
        s = (np.asarray(t, dtype=float)[..., None] - t0) / h
        s2, s3, s4, s5 = s ** 2, s ** 3, s ** 4, s ** 5
        x = ((1 - 10 * s3 + 15 * s4 - 6 * s5) * x0 + (s - 6 * s3 + 8 * s4 - 3 * s5) * h * v0
             + 0.5 * (s2 - 3 * s3 + 3 * s4 - s5) * h * h * a0 + (10 * s3 - 15 * s4 + 6 * s5) * x1
             + (-4 * s3 + 7 * s4 - 3 * s5) * h * v1 + 0.5 * (s3 - 2 * s4 + s5) * h * h * a1)
        v = ((-30 * s2 + 60 * s3 - 30 * s4) * x0 / h + (1 - 18 * s2 + 32 * s3 - 15 * s4) * v0
             + 0.5 * (2 * s - 9 * s2 + 12 * s3 - 5 * s4) * h * a0 + (30 * s2 - 60 * s3 + 30 * s4) * x1 / h
             + (-12 * s2 + 28 * s3 - 15 * s4) * v1 + 0.5 * (3 * s2 - 8 * s3 + 5 * s4) * h * a1)
        return x, v

    return at


def first_nonpositive(f, t0, t1):
    """The first time in (t0, t1] where f (> 0 at t0) reaches <= 0: brentq on a sign change; bisection
    when f(t1) is exactly 0 (a granule whose contacts opened: its acceleration is 0 on an interval,
    and the interval's start is wanted, which brentq would not find)."""
    if f(t1) < 0.0:
        return brentq(f, t0, t1, xtol=1e-15, rtol=1e-15)
    while t1 - t0 > 1e-14 * max(1.0, abs(t1)):
        tm = 0.5 * (t0 + t1)
        t0, t1 = (tm, t1) if f(tm) > 0.0 else (t0, tm)
    return t1


def pulse_has_left(x, v, m) -> bool:
    """The package's stop rule (``kernels.stop.pulse_is_out``), written again: with a wall, the wall
    contact open and the granule next to it moving away; else the last contact open and the last
    granule outrunning its neighbour and every granule that is not a light rattler."""
    if np.isinf(m[-1]):
        return bool(x[-2] - x[-1] <= 0.0 and v[-2] < 0.0)
    if x[-2] - x[-1] > 0.0 or v[-1] <= 0.0 or v[-2] >= v[-1]:
        return False
    heavy = m[:-1] >= RATTLER_MASS_RATIO * m[-1]
    return bool(np.all(v[:-1][heavy] < v[-1]))


class NumpyBackend(Backend):
    """Elastic power-law chains, F = c delta^(n-1) for delta > 0, with a Dormand-Prince 5(4) pair in
    NumPy: a second implementation of the backend contract, independent of the package's kernels.

    Whatever method the integrator names (DP5, DOP853, ...), this backend runs its own DP5(4) with
    the integrator's ``rtol`` and ``atol`` (an RMS norm over positions and velocities): the method
    name is ignored. No goal-oriented zones, no trailing window: every granule is integrated."""

    name = "numpy-test"
    law_forms = ("power-law",)

    def check(self, integrator, chain) -> None:
        """Refuse what this code does not integrate, saying what to use instead (before any step)."""
        if not chain.contact.conservative:
            raise ValueError(f"the {self.name} backend integrates elastic power-law contacts only (forces of "
                             f"positions alone); the contact law {chain.contact!r} dissipates: use DP5 or DOP853 on "
                             "the CPU backend")
        if chain.static_force != 0.0:
            raise ValueError(f"the {self.name} backend has no code for a precompressed chain (static force "
                             f"{chain.static_force!r}): use the CPU backend")
        if not hasattr(integrator, "rtol") or integrator.goal_oriented:
            raise ValueError(f"the {self.name} backend runs an adaptive method at the integrator's rtol and atol, on "
                             f"every granule: {integrator!r} has a fixed step or goal-oriented zones; use e.g. "
                             "DOP853() or DP5()")
        super().check(integrator, chain)

    def integrate(self, integrator, chain, x, v, *, t_grid, t_max, stop_at_exit, controls, sensed=None):
        self.check(integrator, chain)
        m, c, law, obs = chain.masses, chain.stiffness, chain.contact, chain.observed
        sensed = np.zeros(0, dtype=np.int64) if sensed is None else np.asarray(sensed, dtype=np.int64)
        rtol, atol, peak_rtol = integrator.rtol, integrator.atol, controls.peak_rtol
        wall = bool(np.isinf(m[-1]))

        def forces(x):  # contact forces, any leading shape (rows: times)
            return law.force(x[..., :-1] - x[..., 1:], c)

        def accel(x):  # a wall's infinite mass gives it acceleration 0, no special case
            F = forces(x)
            a = np.zeros_like(x)
            a[..., 1:] += F
            a[..., :-1] -= F
            return a / m

        def new_peak(value, old):  # the package's tie rule: a later maximum must be higher by peak_rtol
            return value > old + peak_rtol * abs(old)

        x_out, v_out = x, v  # the caller's arrays: they get the final state at the end
        x, v = x.astype(float), v.astype(float)
        a = accel(x)
        peak_v, peak_t = v[obs].copy(), np.zeros(obs.size)
        peak_f, peak_ft = forces(x), np.zeros(c.size)
        T = t_grid.size
        grid_v, grid_f, grid_c = np.zeros((T, obs.size)), np.zeros(T), np.zeros((T, sensed.size))
        g = int(np.searchsorted(t_grid, 0.0, side="right"))  # grid times already reached (t = 0)
        grid_v[:g], grid_f[:g], grid_c[:g] = v[obs], forces(x)[-1] if wall else 0.0, forces(x)[sensed]
        t_needed = float(t_grid[-1]) if t_grid.size else 0.0

        t, h = 0.0, 1e-3  # the controller grows a small first step within a few steps
        t_stop = t_max  # lowered to exit + margin once the pulse has left, so that the run lands on it
        exit_since = -1.0
        n_acc = n_rej = 0
        M = m.size
        y = np.concatenate((x, v))  # the state (x, v); its rate (v, a(x)) in the stage slots K
        K = np.empty((7, 2 * M))
        status = None
        while status is None:
            if n_acc >= controls.max_steps:
                status = MAX_STEPS
                break
            landing = t + h >= t_stop
            if landing:
                h = t_stop - t
            # one Dormand-Prince step, all granules at once
            K[0, :M], K[0, M:] = v, a
            for s in range(1, 7):
                ys = y + h * (A[s, :s] @ K[:s])
                K[s, :M], K[s, M:] = ys[M:], accel(ys[:M])
            x1, v1, a1 = ys[:M], ys[M:], K[6, M:].copy()  # (a copy: the stage slots are reused by the next step)
            # RMS norm of the error estimate, each component scaled by atol + rtol |y|
            e = h * (E @ K) / (atol + rtol * np.maximum(np.abs(y), np.abs(ys)))
            err = np.sqrt(np.mean(e * e))
            if not np.isfinite(err):  # (a non-finite state makes it NaN)
                status = NONFINITE
                break
            factor = min(5.0, max(0.2, 0.9 * err ** -0.2)) if err > 0.0 else 5.0  # the usual order-5 controller
            if err > 1.0:  # rejected: retry shorter
                n_rej += 1
                h *= min(factor, 0.9)
                if h < 1e-14 * max(1.0, t):
                    status = STEP_UNDERFLOW
                continue
            t1 = t_stop if landing else t + h  # land exactly on the stop time, not on t + h rounded
            dense = hermite(t, h, x, v, a, x1, v1, a1)

            # velocity peaks: the acceleration of an observed granule falls from > 0 to <= 0
            for q in np.flatnonzero((a[obs] > 0.0) & (a1[obs] <= 0.0)):
                k = obs[q]
                tp = first_nonpositive(lambda s, k=k: accel(dense(s)[0])[k], t, t1)
                vp = dense(tp)[1][k]
                if new_peak(vp, peak_v[q]):
                    peak_v[q], peak_t[q] = vp, tp
            # force peaks: compression maxima, where v_j - v_{j+1} falls through 0
            for j in np.flatnonzero((v[:-1] - v[1:] > 0.0) & (v1[:-1] - v1[1:] <= 0.0)):
                def approach(s, j=j):  # v_j - v_{j+1} on the dense output
                    vs = dense(s)[1]
                    return vs[j] - vs[j + 1]

                tp = first_nonpositive(approach, t, t1)
                fp = forces(dense(tp)[0])[j]
                if fp > 0.0 and new_peak(fp, peak_f[j]):
                    peak_f[j], peak_ft[j] = fp, tp
            # the grid times this step passed, from the dense output
            g_end = int(np.searchsorted(t_grid, t1, side="right"))
            if g_end > g:
                xg, vg = dense(t_grid[g:g_end])
                grid_v[g:g_end] = vg[:, obs]
                fg = forces(xg)
                grid_f[g:g_end] = fg[:, -1] if wall else 0.0
                grid_c[g:g_end] = fg[:, sensed]
                g = g_end

            t, y, x, v, a = t1, ys, x1, v1, a1
            n_acc += 1
            h *= factor
            if stop_at_exit and pulse_has_left(x, v, m):
                if exit_since < 0.0:
                    exit_since = t
                t_done = max(exit_since + controls.exit_margin, t_needed)  # not before the grid's end
                t_stop = min(t_max, t_done)
                if t >= t_done:
                    status = SUCCESS
                elif t >= t_max:
                    status = T_MAX
            else:
                exit_since, t_stop = -1.0, t_max  # not out (any more): a provisional stop no longer holds
                if t >= t_max:
                    status = T_MAX if stop_at_exit else SUCCESS

        # peaks still rising at the last instant (as the package's final_peaks and final force peaks)
        for q, k in enumerate(obs):
            if a[k] > 0.0 and new_peak(v[k], peak_v[q]):
                peak_v[q], peak_t[q] = v[k], t
        f_end = forces(x)
        for j in np.flatnonzero((v[:-1] - v[1:] > 0.0) & (f_end > 0.0)):
            if new_peak(f_end[j], peak_f[j]):
                peak_f[j], peak_ft[j] = f_end[j], t
        info = np.zeros(INFO_SIZE)
        # (t_end, accepted, rejected, exit time, force evaluations: 6 per try (FSAL), no window, nothing dissipated)
        write_info(info, t, n_acc, n_rej, exit_since, 6 * (n_acc + n_rej) + 1, 0, 0.0, 0.0)
        x_out[:], v_out[:] = x, v
        return int(status), info, peak_v, peak_t, grid_v, peak_f, peak_ft, grid_f, grid_c


# -- 1. conformance -----------------------------------------------------------------------------------
#: The integrator whose tolerances the backend runs at (its method, DOP853, is not what runs: see
#: NumpyBackend), and the tolerances against the reference, DOP853 at rtol 1e-11 (test_backends.REFERENCE).
#: Measured worst case over CHAINS, and the margin each tolerance leaves: peak velocities 4.7e-10 (relative;
#: 8.5x), peak forces 4.9e-10 (relative, with peak_rtol; 8x), the wall's impulse 9.1e-10 (relative, with
#: peak_rtol; 4.4x), peak times 7.2e-10 (absolute; 7x), grid velocities 1.8e-9 (5.5x), the wall force on the
#: grid 4.8e-10 (WALL_FORCE_ATOL; 10x), energy 1.5e-9 (6.7x), momentum 6e-15 (MOMENTUM_ATOL), exit within
#: 0.003 of the reference's (EXIT_ATOL: the step that detects it), t_end on exit + margin exactly.
CASE = Case(gc.DOP853(rtol=1e-10, atol=1e-12), peak_rtol=4e-9, time_atol=5e-9, time_rtol=0.0, grid_atol=1e-8,
            energy_atol=1e-8)
WALL_FORCE_ATOL = 5e-9


@pytest.mark.parametrize("chain_name", list(CHAINS))
def test_numpy_backend_conforms_to_dop853(chain_name):
    """The checks of ``test_backends.test_conformance_with_dop853``, run through ``simulate(backend=...)``
    with :class:`NumpyBackend`, plus the contacts' peak forces and the wall force on the grid (which
    this backend computes in its own code, too)."""
    chain = chain_named(chain_name)
    ref = reference_result(chain_name)
    case = CASE
    res = gc.simulate(chain, case.integrator, t_grid=T_GRID, exit_margin=EXIT_MARGIN, backend=NumpyBackend())
    what = f"the numpy-test backend on the {chain_name} chain"

    assert res.status == gc.Status.SUCCESS, f"{what}: {res.status.name} ({res.message})"
    assert res.integrator == case.integrator.name

    # peaks, at the granules whose peaks the reference resolves
    np.testing.assert_array_equal(res.granule, ref.granule)
    ok = in_order(ref)
    assert ok[:2].all() and ok.sum() >= 0.5 * ok.size, f"too many out-of-order peaks in the reference: {ref.peak_time}"
    np.testing.assert_allclose(res.peak_velocity[ok], ref.peak_velocity[ok], rtol=case.peak_rtol, atol=0,
                               err_msg=f"{what}: peak velocities")
    late = np.abs(res.peak_time - ref.peak_time)
    bad = ok & (late > case.time_atol + case.time_rtol * np.abs(ref.peak_time))
    assert not bad.any(), (f"{what}: peak times differ at granules {res.granule[bad]}: "
                           f"{res.peak_time[bad]} vs {ref.peak_time[bad]}")
    np.testing.assert_allclose(res.peak_force, ref.peak_force, rtol=case.peak_rtol, atol=0,
                               err_msg=f"{what}: peak forces")

    # velocities on the grid (at t = 0 exactly the initial state)
    assert res.velocity.shape == (chain.observed.size, T_GRID.size)
    np.testing.assert_allclose(res.velocity, ref.velocity, rtol=0, atol=case.grid_atol,
                               err_msg=f"{what}: grid velocities")
    np.testing.assert_array_equal(res.velocity[:, 0], np.r_[chain.initial_velocity, np.zeros(chain.observed.size - 1)])

    # conservation
    assert abs(res.energy_error) <= case.energy_atol, f"{what}: energy error {res.energy_error:.2e}"
    if chain.wall:
        assert np.isnan(res.momentum_error)
        assert res.wall_impulse == pytest.approx(ref.wall_impulse, rel=case.peak_rtol), what
        assert res.wall_impulse > chain.momentum  # the pulse came back: the granules end moving away from the wall
        np.testing.assert_allclose(res.wall_force, ref.wall_force, rtol=0, atol=WALL_FORCE_ATOL,
                                   err_msg=f"{what}: wall force on the grid")
    else:
        assert abs(res.momentum_error) <= MOMENTUM_ATOL, f"{what}: momentum error {res.momentum_error:.2e}"

    # the same stop event, and the run landed exactly on it
    assert ref.exit_time > 0 and abs(res.exit_time - ref.exit_time) <= EXIT_ATOL, (
        f"{what}: exit at {res.exit_time:.6g}, reference {ref.exit_time:.6g}")
    assert res.t_end == pytest.approx(max(res.exit_time + EXIT_MARGIN, T_GRID[-1]), rel=0, abs=1e-12), (
        f"{what}: t_end {res.t_end!r}, exit {res.exit_time!r}")


# -- 2. ensembles through the base class's batch loop ---------------------------------------------------
def test_numpy_backend_runs_an_ensemble():
    """``run_ensemble(backend=NumpyBackend())``: ``Backend.integrate_batch`` calls ``integrate`` per
    realisation. Against the same call on the default CPU backend (SciPy's DOP853 at the same
    tolerances): every status 0, peak velocities per realisation within the accuracy contract (1e-6;
    measured 1.4e-10), peak times and the mean pulse to 1e-6 (measured 5.7e-10 and 1.6e-9), and the
    store's parameter record names the backend that computed it (the CPU default's names none)."""
    kwargs = dict(realizations=6, chunk_size=3, seed=1, chains="decorated",
                  integrator=gc.DOP853(rtol=1e-10, atol=1e-12), progress=False)
    ds = gc.run_ensemble(4, backend=NumpyBackend(), **kwargs)
    ref = gc.run_ensemble(4, **kwargs)

    assert ds["status"].shape == (1, 6) and (ds["status"].values == 0).all(), ds["status"].values
    assert (ref["status"].values == 0).all()
    np.testing.assert_allclose(ds["peak_velocity"].values, ref["peak_velocity"].values, rtol=1e-6, atol=0)
    np.testing.assert_allclose(ds["peak_time"].values, ref["peak_time"].values, rtol=0, atol=1e-6)
    np.testing.assert_allclose(ds["mean_velocity"].values, ref["mean_velocity"].values, rtol=0, atol=1e-6)
    assert json.loads(ds.attrs["granchain_parameters"])["backend"] == "numpy-test"
    assert "backend" not in json.loads(ref.attrs["granchain_parameters"])


# -- 3. refusals ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("chain, integrator, match", [
    (gc.monodisperse(5).replace(contact=gc.Viscous(0.1)), gc.DOP853(), "elastic power-law contacts only.*dissipates"),
    (gc.monodisperse(5).with_precompression(0.1), gc.DOP853(), "no code for a precompressed chain"),
    (gc.monodisperse(5), gc.Verlet(dt=1e-3), "fixed step or goal-oriented zones"),
], ids=["dissipative", "precompressed", "fixed step"])
def test_numpy_backend_refuses_what_it_does_not_integrate(chain, integrator, match):
    """``simulate`` hands the chain to the backend's ``check`` first: a dissipative contact law, a
    static load and a fixed-step method are refused with a message saying why, before any step."""
    with pytest.raises(ValueError, match=f"^the numpy-test backend .*{match}"):
        gc.simulate(chain, integrator, backend=NumpyBackend())
