"""The adaptive Runge-Kutta step loop, one generic loop specialised on a method's scheme (``schemes``:
DP5, ``dp5``; RKN4(3), ``rkn4``): PI step control, max-norm error, the active and trailing windows,
peaks and grid samples from the dense output (``dense``), the stop rule (``stop``). The step control
(tolerances, the relaxed zone, the trailing window: ``records.Steps``) is the run's, separate from the
scheme. What an accepted step records is written as blocks of their own, inlined into the loop
(``observe``: ``yield_turn``, ``velocity_peaks``, ``force_peaks``, ``sample_grid``), as is the trailing
window's cut (:func:`trailing_window`; the stop rule is ``stop.end_of_step``).

Step control: the PI controller of Hairer, Norsett & Wanner, *Solving ODEs I*, Sec. II.4 (DOPRI5).
The error norm is the maximum over components: the pulse is localised, and a root-mean-square norm
would dilute its error over the resting granules.
"""

from __future__ import annotations

import math
import types

import numpy as np
from numba import njit

from ..._status import MAX_STEPS, NONFINITE, STEP_UNDERFLOW
from .dense import ROOT_ACCELERATION, ROOT_ELASTIC_ACCELERATION
from .forces import (
    accelerations_once,
    add_potential,
    plastic_force,
    plastic_work,
    static_state,
    unloading_curve,
)
from .jit import JIT, JIT_INLINE, JIT_INTERNAL, named
from .memory import borrowed, keep_alive
from .observe import force_peaks, sample_grid, velocity_peaks, yield_turn
from .peaks import (
    final_force_peaks,
    final_peaks,
    initial_force_records,
    initial_records,
    is_new_peak,
    write_info,
)
from .records import Dense, Forces, Model, Outputs, Run, Steps
from .stop import end_of_step, stop_time
from .window import (
    advance_window,
    initial_window,
    is_finite_window,
    margin,
    open_contact_behind,
)

SAFETY = 0.9
BETA = 0.08  # PI controller: Gustafsson's value, few rejections when stability limits the step
MIN_FACTOR = 0.2
MAX_FACTOR = 10.0
#: Bit masks of a float64 (:func:`max_ratio`): all but the sign; the exponent of inf and NaN.
SIGN_CLEAR = 0x7FFF_FFFF_FFFF_FFFF
EXPONENT_ALL_ONES = 0x7FF0_0000_0000_0000
#: The padded layout: the loops over the window (stages, error norm, update) run
#: to the next multiple of LANES past its end. LLVM vectorises them LANES doubles wide (AVX-512) and
#: finishes a loop whose length is not a multiple of that one element at a time, which cost a step
#: as much as the vector part (the six stages: ~460 ns for a window of 31 granules, ~290 ns for 32).
#: The granules between the window's end and that multiple are exactly at rest and uncompressed
#: (``window.WINDOW_MARGIN``) or padding past the chain's end (zero stiffness, zero inverse mass):
#: every stage gives them exact zeros, so the results are bitwise those of the unpadded loops.
LANES = 8
#: Thornton's elastic-plastic contacts (``forces.plastic_force``): an accepted step in which a contact on its
#: loading branch turns back (``observe.yield_turn``) is retaken to end at the turn, unless the turn lies in
#: the step's last TURN_SLACK: the stages past the turn follow the loading line where the contact unloads.
TURN_SLACK = 1e-6


@njit(**JIT_INLINE)
def padded_width(hw):
    """The loop length for a window of ``hw`` granules: ``hw`` rounded up to a multiple of LANES."""
    return (hw + LANES - 1) // LANES * LANES


def pi_exponent(scheme) -> float:
    """The PI controller's exponent of the error for ``scheme`` (``schemes.Scheme``): 1/q - 0.75 BETA for
    an error estimate O(h^q) (Hairer, Norsett & Wanner, Sec. IV.2)."""
    return 1.0 / scheme.error_order - 0.75 * BETA


@njit(**JIT_INLINE)
def max_ratio(ratio, hi):
    """The error norm from the scheme's error ratios (``error_ratios``: positions in ``ratio[:hi]``,
    velocities in ``ratio[hi:2 hi]``): their maximum, inf if any is not finite. The ratios are
    |embedded error| / (w_i (atol + rtol max(|y|, |y_new|))), w_i = ``steps.relaxed_factor`` for the
    granules of the relaxed zone, else 1 (multiplying by 1 is exact: without a relaxed zone the norm is
    bitwise the plain one).

    The scheme's ratios go through the scratch array ``ratio`` so that its division loop vectorises; their
    maximum is then an integer maximum of their bit patterns (below; ``ratio[0]`` is overwritten with
    it). A NaN ratio (a non-finite state) is never lost to a later finite one: its pattern is above
    every finite one.
    """
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
def unpack_steps(params):
    """DP5's and RKN4's params = [rtol, atol, first_step, fixed_step (0: adaptive), relaxed_lag,
    relaxed_factor, window_lag (lags 0: off)] (``records.Method.params``) as ``records.Steps``."""
    return Steps(params[0], params[1], params[2], params[3], int(params[4]), params[5], int(params[6]))


@njit(**JIT_INTERNAL)
def padded_arrays(model, state):
    """The arrays of the step loop of :func:`rk_kernel`, in the padded layout (see LANES): state,
    stiffness and inverse masses of the M granules followed by LANES padding granules with zero
    stiffness and zero inverse mass, which stay exactly at rest; the static overlaps and forces of a
    precompressed chain; the zeroed scratch arrays (stage derivatives ``Kx``, ``Kv`` (7, Mp); ``xs``,
    ``vs`` (Mp); contact forces ``F`` (Mp + 1); dense-output weights ``Q``, ``Qv`` (7); the stages'
    dissipated power ``Pd`` (7); error ratios ``ratio`` (2 Mp); ``peak_d``, ``t_frozen`` (M)); and each
    contact's history ``hist`` and yield overlap ``dy`` (Mp; Thornton's law: its largest overlap, starting at
    its yield overlap, from ``state.history``; empty for every other law).

    A function of its own, called by the kernel: allocated in the kernel's own code, where LLVM sees
    the arrays' sizes, the step loop ran 3-7 % slower on N = 101 decorated chains (DP5 and RKN4,
    same-run timings)."""
    x0, v0, h0 = state
    m0, c0, p = model.masses, model.stiffness, model.params
    M = m0.shape[0]
    Mp = M + LANES
    xp = np.zeros(Mp)
    vp = np.zeros(Mp)
    cp = np.zeros(Mp)
    inv_mp = np.zeros(Mp)
    opp = np.zeros(Mp)  # static overlaps delta0_k (precompression; else 0)
    f0pp = np.zeros(Mp)  # static forces f0_k
    for i in range(M):  # (element by element: a slice assignment compiles its shape check's error message)
        xp[i] = x0[i]
        vp[i] = v0[i]
        inv_mp[i] = 1.0 / m0[i]
    for j in range(M - 1):
        cp[j] = c0[j]
    if p.static_force > 0.0:
        for j in range(M - 1):
            opp[j], f0pp[j] = static_state(c0[j], p)
    plastic = p.yield_overlap > 0.0
    histp = np.zeros(Mp if plastic else 0)  # (empty for every other law: never read)
    dyp = np.zeros(Mp if plastic else 0)
    if plastic:  # virgin contacts: the history starts at the yield overlaps (records.State)
        for j in range(M - 1):
            dyp[j] = h0[j] if h0[j] > 0.0 else c0[j] * c0[j] * p.yield_overlap
            histp[j] = dyp[j]
    Kxp = np.zeros((7, Mp))  # stage derivatives of x (= stage velocities), window-local index
    Kvp = np.zeros((7, Mp))  # stage derivatives of v (= stage accelerations), window-local index
    xsp = np.zeros(Mp)
    vsp = np.zeros(Mp)
    Fp = np.zeros(Mp + 1)  # contact forces, F[j + 1] for contact j (see forces.accelerations)
    Qp = np.zeros(7)
    Qvp = np.zeros(7)  # RKN4's velocity weights (DP5 uses Q for both)
    Pdp = np.zeros(7)  # dissipated power at DP5's stages
    ratiop = np.zeros(2 * Mp)
    peak_dp = np.zeros(M)  # compression at each contact's recorded peak force (for the screen)
    t_frozenp = np.zeros(M)  # time each granule left the trailing window
    return xp, vp, cp, inv_mp, opp, f0pp, Kxp, Kvp, xsp, vsp, Fp, Qp, Qvp, Pdp, ratiop, peak_dp, t_frozenp, histp, dyp


# -- The trailing window's cut ------------------------------------------------------------------------------

@njit(**JIT_INLINE)
def trailing_window(target, X, C, p, Kx, Kv, lo, hi, q_lo, q_open, t, run, t_frozen, frozen_potential):
    """The trailing window's cut: behind observed granule ``target`` (front - window_lag), and not past a
    granule whose averaged-pulse window is still open (``run.pulse_end``: its grid velocities up to then are
    recorded exactly), across the last contact behind it that is open now (``window.open_contact_behind``).
    Granules lo..new_lo-1 leave: they keep their velocities, the potential of the contacts among them (the
    contact at the new edge is open) and their exit time (``t_frozen``); the stage arrays Kx, Kv shift by the
    cut over the padded window only (past it they are zeros: the stages write granules
    0..padded_width(hi - lo) - 1 alone), so that a cut costs O(window), not O(chain) (which made long
    chains quadratic). Returns (new_lo, q_lo, q_open, frozen_potential); new_lo == lo: no cut."""
    obs, pulse_end = run.observed, run.pulse_end
    n_obs = obs.shape[0]
    if pulse_end.shape[0] > 0:
        while q_open < n_obs and pulse_end[q_open] < t:
            q_open += 1
        target = min(target, q_open)
    new_lo = open_contact_behind(X, C, p, lo, obs[target])
    if new_lo > lo:
        d = new_lo - lo
        frozen_potential = add_potential(frozen_potential, X, C, p, 0, d - 1)
        for i in range(d):
            t_frozen[lo + i] = t
        wp = padded_width(hi - lo)
        for s in range(7):
            for i in range(wp - d):
                Kx[s, i] = Kx[s, i + d]
                Kv[s, i] = Kv[s, i + d]
            for i in range(wp - d, wp):
                Kx[s, i] = 0.0
                Kv[s, i] = 0.0
        while q_lo < n_obs and obs[q_lo] < new_lo:
            q_lo += 1
    return new_lo, q_lo, q_open, frozen_potential


#: The blocks of ``observe`` compiled once per scheme (they call its functions), as globals
#: ``_<block>_<scheme name>`` of this module.
SCHEME_BLOCKS = ("yield_turn", "velocity_peaks", "force_peaks", "sample_grid")


def rk_kernel(scheme, general):
    """The compiled single-chain entry point ``kernel(record, model, run, state, out)`` of the
    Runge-Kutta method ``scheme`` (``schemes.Scheme``: ``schemes.DP5``, ``schemes.RKN4``) for the model
    class ``general`` (see below): ``dispatch`` makes one per pair.

    The scheme and ``general`` are constants of the kernel's code, which Numba prunes the branches they
    decide before typing them: the DP5 kernel holds no RKN4 code, the paper's chain (``general`` False)
    none of the real contacts' (a static load, damping and the dissipated power: see
    ``forces.accelerations``). The scheme's constants are variables of this closure (Numba compiles
    them as constants, and keys a closure's cache entry on their values); its functions are called as
    ``SCHEME.stages``, ``SCHEME.weights``, ..., where ``SCHEME`` is a global name that
    :func:`_specialised` binds to the scheme's module for each kernel (a module or a compiled function
    held in a closure variable would defeat Numba's cache: it keys the entry on the pickled variables,
    and a compiled function pickles with an id of its process). One compiled function holds the step
    loop and the set-up around it (:func:`padded_arrays` allocates its arrays): it is compiled, and
    cached, only when a run uses it. The step loop used to be a
    function of its own, called by one wrapper per pair with the two as literal arguments; Numba
    typed and lowered every method's and model's branches of it (it does not prune on a literal
    argument) and LLVM optimised and compiled the loop's code a second time in the wrapper's library.
    With a run-time method and ``general`` the loop cost DP5 ~6 % more per realisation, and one
    force routine with a run-time test cost the paper's ensembles 10-20 % (same-run timings against
    granchain 0.4.0).
    """
    kind = scheme.kind  # for the root searches (``dense.first_root``), which take it as a run-time value
    lazy_dense = scheme.lazy_dense
    separate_velocity_weights = scheme.separate_velocity_weights
    end_in_stage = scheme.end_in_stage
    velocity_forces = scheme.velocity_forces
    evaluations = scheme.evaluations
    exponent = pi_exponent(scheme)
    # The acceleration the velocity peaks follow: the paper's chain compiles the elastic law's search alone.
    acceleration = ROOT_ACCELERATION if general else ROOT_ELASTIC_ACCELERATION

    def kernel(record, model, run, state, out):
        """Integrate one chain (``model``, ``records.Model``) from ``state`` (x, v at t = 0; receives the
        final state) with the Runge-Kutta method of the kernel's scheme (``general`` True for real
        contacts) and the step control ``steps`` (``records.Steps``, from ``record.params``: see
        :func:`unpack_steps`), recording into ``out`` (``records.Outputs``) what ``run`` asks
        (``records.Run``).

        For each observed granule q (0-based index run.observed[q]) the kernel writes the maximum
        velocity ``peak_v[q]`` and its time ``peak_t[q]`` (see ``peaks.is_new_peak`` for ties), and the
        velocity at each time t_grid[g] into ``grid_v[g, q]`` (time-major: one contiguous row per grid
        time). For each contact j (0-based, M-1 of them) it writes the maximum contact force
        ``peak_f[j]`` and its time ``peak_ft[j]`` (0 at t = 0 for a contact that never closed; same tie
        rule as the velocities); with a wall (``model.params.wall``) ``grid_f[g]`` receives the wall force at
        t_grid[g] (untouched otherwise). ``steps.fixed_step > 0`` turns step control off. With
        ``run.stop_at_exit`` the run ends ``exit_margin`` after the pulse has left the last granule (and
        not before t_grid[-1]); otherwise at ``t_max``.

        Goal-oriented error control (``granchain.DP5``; off when the lags are 0; the Python layer sets
        them to 0 for a chain ending in a wall, whose pulse comes back, and says so in its records). The
        *front* is the most advanced observed granule whose velocity maximum has been located; it never
        moves backwards.
        - ``relaxed_lag`` > 0: granules behind observed granule front - relaxed_lag enter the error norm
          with tolerances ``relaxed_factor`` times looser (the relaxed zone).
        - ``window_lag`` > 0: granules behind observed granule front - window_lag, cut across the
          last contact behind it that is open at that moment, leave the integration (the trailing
          window): they keep their velocity (positions continue ballistically), their peaks are final,
          and the contact at the window's edge is dropped. Granules lo..M-1 stay integrated, so the
          work per step is bounded by the window, not the chain.

        ``out.info`` receives the INFO_* slots of ``records`` (t_end, steps, rejected, exit time, force
        evaluations, window start, potential energy of the frozen contacts). Returns the status code
        (``granchain._status``).
        """
        # The steps' controls (``record``: ``records.Method``, its ``params`` laid out by ``unpack_steps``).
        steps = unpack_steps(record.params)
        x0, v0, h0 = state  # the initial state; receives the final one
        m0, p = model.masses, model.params
        M = m0.shape[0]
        (xp, vp, cp, inv_mp, opp, f0pp, Kxp, Kvp, xsp, vsp, Fp, Qp, Qvp, Pdp, ratiop, peak_dp,
         t_frozenp, histp, dyp) = padded_arrays(model, state)
        # The step loop works on borrowed views (see memory.borrowed: no reference counting in the loop's
        # calls): the arguments are held by our caller, the arrays allocated here by the keep_alive call
        # after the loop.
        m, c = borrowed(m0), borrowed(cp)
        x, v = borrowed(xp), borrowed(vp)
        inv_m, Kx, Kv, xs, vs, F = borrowed(inv_mp), borrowed(Kxp), borrowed(Kvp), borrowed(xsp), borrowed(vsp), borrowed(Fp)
        Q, Qv, ratio, peak_d, t_frozen = borrowed(Qp), borrowed(Qvp), borrowed(ratiop), borrowed(peak_dp), borrowed(t_frozenp)
        op, f0p, Pd, hist, dy = borrowed(opp), borrowed(f0pp), borrowed(Pdp), borrowed(histp), borrowed(dyp)
        model = Model(m, c, p)
        run = Run(borrowed(run.observed), borrowed(run.t_grid), run.t_max, run.stop_at_exit, run.exit_margin, run.max_steps,
                  run.peak_rtol, borrowed(run.contacts), borrowed(run.pulse_end))
        out = Outputs(borrowed(out.peak_v), borrowed(out.peak_t), borrowed(out.grid_v), borrowed(out.peak_f),
                      borrowed(out.peak_ft), borrowed(out.grid_f), borrowed(out.info), borrowed(out.grid_c))
        obs, t_grid = run.observed, run.t_grid
        peak_v, peak_t, peak_f, peak_ft = out.peak_v, out.peak_t, out.peak_f, out.peak_ft
        peak_rtol = run.peak_rtol
        h_fixed, relax_lag, window_lag = steps.fixed_step, steps.relaxed_lag, steps.window_lag
        n_obs = obs.shape[0]
        n_grid = t_grid.shape[0]

        # The window: granules lo..hi-1 are integrated (lo = 0 until a trailing-window cut). Kx, Kv are
        # window-local (shifted to start at lo at each cut); the other arrays are read through views from
        # granule lo on, taken in the step loop below.
        QV = Qv if separate_velocity_weights else Q  # velocity weights (the scheme's ``weights``)
        goal = relax_lag > 0 or window_lag > 0
        damped = general and p.gamma > 0.0
        # Thornton's contacts: each one's largest overlap (hist) is state, moved after every accepted step, and
        # a step is retaken to end where a contact turns from loading to unloading (see TURN_SLACK)
        plastic = general and p.yield_overlap > 0.0
        ahead = margin(p)
        # Counters passed to compiled functions start as int64, not as the literal 0 or 1: Numba would
        # compile those functions twice, once for the literal it meets first while inferring types.
        lo = np.int64(0)
        hi = initial_window(x[:M], v[:M], ahead)
        Pd[0] = accelerations_once(x, v, Forces(c, inv_m, p, op, f0p, hist, dy), hi, F, Kv[0], general)
        for i in range(hi):
            Kx[0, i] = v[i]
        n_eval = np.int64(1)
        front = -1  # observed granule (index into obs) of the front
        # Observed granules in the window: obs[q_lo..q_hi-1] (obs increases; both ends only move forward),
        # so that a step's peak search costs O(window), not O(observed granules) (long chains).
        q_lo = 0
        q_hi = 0
        while q_hi < n_obs and obs[q_hi] < hi:
            q_hi += 1
        # Observed granules whose averaged-pulse window has closed: obs[0..q_open-1] (run.pulse_end; only
        # moves forward). The trailing window never cuts ahead of obs[q_open].
        q_open = 0
        relaxed = 0  # granules lo..lo+relaxed-1 are in the relaxed zone
        frozen_potential = 0.0
        dissipated = 0.0

        t = 0.0
        g = initial_records(obs, v, t_grid, peak_v, peak_t, out.grid_v)
        t_needed = t_grid[n_grid - 1] if n_grid > 0 else 0.0
        initial_force_records(x[:M], v[:M], model, g, out, run.contacts)

        h = h_fixed if h_fixed > 0.0 else steps.first_step
        err_old = 1e-4
        exit_since = -1.0
        n_acc = np.int64(0)
        n_rej = np.int64(0)
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
            # The velocities at a step's end: the last stage (DP5) or the new solution (RKN4: the same
            # numbers, which it copies into Kx[6] only with its dense output).
            VE = Kx[6] if end_in_stage else VS
            XM, VM, MM = x[lo:M], v[lo:M], m[lo:]
            OP = op[lo:]
            H, DY = hist[lo:], dy[lo:]
            FM = Forces(C, IM, p, OP, f0p[lo:], H, DY)
            while status < 0:
                if n_acc + n_rej >= run.max_steps:
                    status = MAX_STEPS
                    break
                # Land exactly on the end: t_max, or exit_margin after the pulse left (not before t_grid[-1]).
                t_stop = stop_time(run, exit_since, t_needed)
                last = False
                if t + h >= t_stop:
                    h = t_stop - t
                    last = True
                hw = hi - lo
                hp = padded_width(hw)
                # The stages (DP5: 2..7, RKN4: 1..3; the last is the new solution's, reused as the first
                # next step).
                SCHEME.stages(X, V, Kx, Kv, XS, VS, h, hp, FM, F, Pd, general)
                n_eval += evaluations
                # xs, vs now hold the new solution at t + h (DP5: 5th order; RKN4: 4th order).
                accept = True
                err = 0.0
                if h_fixed <= 0.0:
                    SCHEME.error_ratios(X, V, XS, VS, Kx, Kv, h, hp, relaxed, steps.relaxed_factor, steps.rtol, steps.atol,
                                        ratio)
                    err = max_ratio(ratio, hp)
                    if velocity_forces:  # (a constant: the branch is not compiled for the other schemes)
                        if damped:
                            err = max(err, SCHEME.dissipated_error_ratio(Pd, h, dissipated, steps.rtol, steps.atol))
                    if not math.isfinite(err):
                        status = NONFINITE
                        break
                    accept = err <= 1.0
                if not accept:
                    n_rej += 1
                    h *= max(MIN_FACTOR, SAFETY * err**-exponent)
                    if h < 1e-14 * max(1.0, t):
                        status = STEP_UNDERFLOW
                    continue
                step = Dense(X, V, Kx, Kv, h)
                if plastic:  # retaken to end where a contact turns from loading to unloading
                    turn = yield_turn(kind, step, VE, hw, FM, Q, QV)
                    if turn < 1.0 - TURN_SLACK:
                        n_rej += 1
                        h *= turn
                        continue
                # Accepted: peaks and grid samples from the dense output over [t, t + h].
                front, dense_ready = velocity_peaks(kind, acceleration, not lazy_dense, step, XS, VS, hp, FM, Q, QV, obs, q_lo,
                                                    q_hi, lo, t, peak_v, peak_t, peak_rtol, front)
                dense_ready = force_peaks(kind, dense_ready, damped, plastic, step, XS, VS, VE, hw, hp, FM, Q, QV, lo, t,
                                          peak_f, peak_ft, peak_d, peak_rtol)
                if g < n_grid and t_grid[g] <= t + h:
                    g = sample_grid(general, dense_ready, g, step, XS, VS, hp, FM, Q, QV, lo, hi, M, t, run, out, v, f0p)
                for i in range(hp):
                    X[i] = XS[i]
                    V[i] = VS[i]
                    Kx[0, i] = VE[i]
                    Kv[0, i] = Kv[6, i]
                if plastic:  # the loading branch moves each contact's history
                    for j in range(hw - 1):
                        H[j] = max(H[j], OP[j] + (X[j] - X[j + 1]))
                if velocity_forces:
                    if damped:
                        dissipated += SCHEME.dissipated(Pd, h)
                        Pd[0] = Pd[6]
                t = t + h if not last else t_stop
                n_acc += 1
                if h_fixed > 0.0 and not is_finite_window(X, V, hw):  # adaptive: checked in the error norm
                    status = NONFINITE
                    break
                if hi < M:
                    new_hi = lo + advance_window(XM, VM, hw, ahead)
                    if new_hi > hi:
                        hi = new_hi
                        while q_hi < n_obs and obs[q_hi] < hi:
                            q_hi += 1
                        Pd[0] = accelerations_once(X, V, FM, hi - lo, F, Kv[0], general)
                        for i in range(hi - lo):
                            Kx[0, i] = V[i]
                        n_eval += 1
                cut = False
                if goal and front >= 0:
                    if window_lag > 0 and front >= window_lag:
                        new_lo, q_lo, q_open, frozen_potential = trailing_window(front - window_lag, X, C, p, Kx, Kv, lo, hi,
                                                                                 q_lo, q_open, t, run, t_frozen, frozen_potential)
                        if new_lo > lo:
                            lo = new_lo
                            cut = True
                            if damped:  # the power of the contacts still integrated (the next step's first stage)
                                Pd[0] = accelerations_once(x[lo:], v[lo:], Forces(c[lo:], inv_m[lo:], p, op[lo:], f0p[lo:],
                                                                                  hist[lo:], dy[lo:]), hi - lo, F, Kv[0], general)
                                n_eval += 1
                    if relax_lag > 0 and front >= relax_lag:
                        relaxed = max(0, obs[front - relax_lag] - lo)

                # The stop rule, called once (each inlined copy is compiled again), on the chain from the window start.
                if cut:  # (the inner loop ends after this step: its views are taken again from the new start)
                    XM, VM, MM = x[lo:M], v[lo:M], m[lo:]
                gap = 0.0
                if plastic and hist[M - 2] > dy[M - 2]:  # a yielded last contact opens at its plastic overlap (its dent)
                    gap = unloading_curve(hist[M - 2], dy[M - 2])[1] - op[M - 2]
                status, exit_since = end_of_step(XM, VM, MM, p.wall, hi - lo, t, run, exit_since, t_needed, gap)
                if status >= 0:
                    break

                if h_fixed <= 0.0:
                    fac = SAFETY * max(err, 1e-10) ** -exponent * err_old**BETA
                    fac = min(MAX_FACTOR, max(MIN_FACTOR, fac))
                    h *= fac
                    err_old = max(err, 1e-4)
                if cut:  # new views from the new window start
                    break
        X, V, C = x[lo:M], v[lo:M], c[lo:M - 1]  # the chain without padding (a cut in the last step left the views behind)
        final_peaks(obs, lo, V, Kv[0], t, peak_rtol, peak_v, peak_t)
        if plastic:  # as final_force_peaks, by Thornton's force and each contact's history
            for j in range(X.shape[0] - 1):
                if V[j] - V[j + 1] > 0.0:
                    f = plastic_force(op[lo + j] + (X[j] - X[j + 1]), hist[lo + j], C[j], dy[lo + j])
                    if f > 0.0 and is_new_peak(f, peak_f[lo + j], peak_rtol):
                        peak_f[lo + j] = f
                        peak_ft[lo + j] = t
            for j in range(M - 1):  # the plastic work, a function of the history; the final history returned
                dissipated += plastic_work(hist[j], c[j], dy[j])
                h0[j] = hist[j]
        else:
            final_force_peaks(X, V, C, p, lo, t, peak_rtol, peak_f, peak_ft)
        for k in range(lo):  # the granules behind the window continued ballistically
            x[k] += v[k] * (t - t_frozen[k])
        write_info(out.info, t, n_acc, n_rej, exit_since, n_eval, lo, frozen_potential, dissipated)
        keep_alive(xp, vp, cp, inv_mp, Kxp, Kvp, xsp, vsp, Fp, Qp, Qvp, ratiop, peak_dp, t_frozenp, opp, f0pp, Pdp, histp, dyp)
        for i in range(M):
            x0[i] = xp[i]
            v0[i] = vp[i]
        return status

    return njit(**JIT)(named(f"{scheme.name}_{'general' if general else 'paper'}")(_specialised(kernel, scheme)))


def _specialised(func, scheme):
    """``func`` with its global names bound for ``scheme``: a copy of the function whose code reads ``SCHEME``
    as ``_scheme_<name>``, a global of ``func``'s module (this one, or ``observe``) set here to
    ``scheme.module``, and each block of :data:`SCHEME_BLOCKS` as ``_<block>_<name>``, that block compiled
    (inlined) for the scheme. The copy keeps ``func``'s module's globals, so what tests patch there it sees."""
    tag = scheme.name
    names = {"SCHEME": f"_scheme_{tag}"}
    func.__globals__[names["SCHEME"]] = scheme.module
    for block in SCHEME_BLOCKS:
        if block in func.__code__.co_names:
            names[block] = f"_{block}_{tag}"
            if names[block] not in globals():
                globals()[names[block]] = njit(**JIT_INLINE)(_specialised(globals()[block], scheme))
    code = func.__code__
    code = code.replace(co_names=tuple(names.get(name, name) for name in code.co_names))
    bound = types.FunctionType(code, func.__globals__, func.__name__, func.__defaults__, func.__closure__)
    bound.__qualname__, bound.__doc__, bound.__module__ = func.__qualname__, func.__doc__, func.__module__
    return bound
