"""What the GPU's step loop records: each contact's first records (its static state and first force peak
candidate, a yielding contact's history), the peaks an accepted step holds (velocity maxima of the observed
granules, force maxima of the contacts), the grid samples (the averaged pulse's velocities, the wall's force, the
sensed contacts' forces), the turn of a yielding contact that retakes a step, and the last instant's candidates.
Device functions compiled for a kernel's method and contacts (:func:`make_observers`), which the step loop
(``kernel.make_kernel``) calls, as the CPU's step loop calls its record blocks (``kernels.observe``:
``sample_grid``, ``force_peaks``, ``yield_turn``; ``kernels.peaks``: ``final_peaks``, ``initial_force_records``).

Each works on the granules its thread holds (``own`` .. ``own + G - 1``). Those that read a neighbour's state
read it from the step's dense output in the group's shared arrays ``hx0, hv0, ha0, hx1, hv1, ha1`` (positions,
velocities and accelerations at the step's two ends), which the step loop has filled and synchronised; the
group's reductions (the latest peak, the earliest turn, the plastic work's sum) are the step loop's, through its
exchange. Moving these blocks out of the step loop changed no kernel's registers, spills or stack
(``benchmarks/gpu_registers.py``).
"""

from __future__ import annotations

import math
from collections import namedtuple

from numba import cuda, int64

from ..kernels.observe import HISTORY_RTOL, SCREEN
from .device import (
    ROOT_ACCELERATION,
    ROOT_APPROACH,
    ROOT_DAMPED_ACCELERATION,
    ROOT_FORCE_RATE,
    compression,
    contact_force,
    dense_compression,
    dense_law_force,
    dense_v,
    elastic_force,
    falls,
    force_rate,
    hermite3,
    hermite_max_estimate,
    law_force,
    plastic_work,
    root,
    static_state,
)

#: The record device functions of a kernel, by name.
Observers = namedtuple("Observers", ["initial_records", "yield_turn", "step_peaks", "sample_grid", "final_records"])


def make_observers(method: str, G: int, damped: bool, precompressed: bool, plastic: bool, sensed: bool) -> Observers:
    """The record device functions of a kernel of ``method`` ("rkn4", "dp5" or "verlet") with ``G`` granules a
    thread, for contacts that are ``damped``, ``precompressed``, ``plastic`` (yielding), and with force
    ``sensed`` contacts: constants of their code, as of the kernel's (``kernel.make_kernel`` says what each
    means)."""
    VERLET = method == "verlet"
    DAMPED = bool(damped)
    LOADED = bool(precompressed)
    PLASTIC = bool(plastic)
    SENSED = bool(sensed)
    LOADED_DAMPED = LOADED and DAMPED  # (one constant: a test of DAMPED nested in LOADED's changed the others' PTX)

    @cuda.jit(device=True)
    def grid_force(j, hx0, hv0, ha0, hx1, hv1, ha1, h, theta, c, n, law, pre, yld):
        """Contact j's total force (prefactor ``c``) at theta in the step, on the interpolant its method's records
        are read on, by the chain's law: the wall's force on the grid, and a sensed contact's."""
        if DAMPED:
            return dense_law_force(j, hx0, hv0, ha0, hx1, hv1, ha1, h, theta, c, law, pre)
        if VERLET:
            return contact_force(compression(hermite3(hx0[j], hv0[j], hx1[j], hv1[j], h, theta)
                                             - hermite3(hx0[j + 1], hv0[j + 1], hx1[j + 1], hv1[j + 1], h, theta), j, pre), c, n)
        return elastic_force(dense_compression(j, hx0, hv0, ha0, hx1, hv1, ha1, h, theta, pre), j, c, n, yld)

    @cuda.jit(device=True)
    def initial_records(r, i, v, c, law, static, pre, yld, history, yield_overlap, peak_f, peak_ft, peak_d):
        """Contact i's first records (prefactor ``c``, its left granule's initial velocity ``v``), before the first
        step: no force peak yet, or in a precompressed chain its static state (into ``pre``) and its force at
        t = 0, the first peak candidate (``kernels.peaks.initial_force_records``); a yielding contact's yield
        overlap and history (into ``yld``: from ``history``, or for a virgin contact c_i^2 ``yield_overlap``,
        ``kernels.rkloop.padded_arrays``)."""
        peak_f[r, i] = 0.0
        peak_ft[r, i] = 0.0
        peak_d[r, i] = 0.0
        if LOADED:  # the static state, and the force at t = 0: the contact's first peak candidate
            pre[0, i], pre[1, i] = static_state(c, static, law)
            peak_f[r, i] = pre[1, i]
        if LOADED_DAMPED:  # (the struck granule's contact closes at v0: ``peaks.initial_force_records``)
            peak_f[r, i] = law_force(pre[0, i], v, c, law)
        if PLASTIC:  # virgin contacts: the history starts at the yield overlap (``rkloop.padded_arrays``)
            dy = history[r, i]
            yld[0, i] = dy if dy > 0.0 else c * c * yield_overlap
            yld[1, i] = yld[0, i]

    @cuda.jit(device=True)
    def yield_turn(own, lo, M, hx0, hv0, ha0, hx1, hv1, ha1, h, law, pre, yld):
        """The earliest turn in the step, as a fraction of it (1 where none), of this thread's contacts on their
        loading line: where a contact's compression peaks beyond its history (``kernels.observe.yield_turn``)."""
        turn = 1.0
        for s in range(G):
            i = own + s
            if i >= lo and i < M - 1:
                w0 = hv0[i] - hv0[i + 1]
                w1 = hv1[i] - hv1[i + 1]
                if falls(w0, w1):
                    theta = root(ROOT_APPROACH, i, M, w0, w1, hx0, hv0, ha0, hx1, hv1, ha1, h, 0.0, 0.0, 0.0,
                                 0.0, 0.0, law, pre, yld)
                    top = dense_compression(i, hx0, hv0, ha0, hx1, hv1, ha1, h, theta, pre)
                    if top > yld[1, i] + HISTORY_RTOL * yld[0, i] and theta < turn:
                        turn = theta
        return turn

    @cuda.jit(device=True)
    def step_peaks(r, t, h, own, lo, M, q_of, v, vs, a0, a3, c_left, c_right, inv_m, masses, stiffness,
                   hx0, hv0, ha0, hx1, hv1, ha1, n, law, pre, yld, peak_rtol, peak_v, peak_t, peak_f, peak_ft, peak_d):
        """The peaks an accepted step from t to t + h holds, on this thread's granules: an observed granule's
        velocity maximum (the root of its acceleration, damped or not: ``kernels.dense``; Verlet's at the zero of
        the linearly interpolated acceleration, ``kernels.verlet``) and a contact's force maximum (the root of the
        relative velocity where the compression screen passes it, of a damped force's rate:
        ``kernels.observe.force_peaks``). Returns the latest observed granule (its index among them) whose
        acceleration fell in the step, or -1: the pulse's front."""
        found = int64(-1)
        for s in range(G):
            i = own + s
            q = q_of[s]
            if i >= lo and i < M and q >= 0 and falls(a0[s], a3[s]):
                if VERLET:  # at the zero of the linearly interpolated acceleration (``kernels.verlet``)
                    theta = a0[s] / (a0[s] - a3[s])
                    vpk = hermite3(v[s], a0[s], vs[s], a3[s], h, theta)
                else:  # the root of its (damped) acceleration
                    theta = root(ROOT_DAMPED_ACCELERATION if DAMPED else ROOT_ACCELERATION, i, M, a0[s], a3[s],
                                 hx0, hv0, ha0, hx1, hv1, ha1, h, c_left[s] if i > lo else 0.0, c_right[s], 0.0,
                                 inv_m[s], 0.0, law, pre, yld)
                    vpk = dense_v(i, hx0, hv0, ha0, hx1, hv1, ha1, h, theta)
                if vpk > peak_v[r, q] + peak_rtol * abs(peak_v[r, q]):
                    peak_v[r, q] = vpk
                    peak_t[r, q] = t + theta * h
                found = max(found, q)
            if i >= lo and i < M - 1:
                w0 = hv0[i] - hv0[i + 1]
                w1 = hv1[i] - hv1[i + 1]
                if DAMPED:
                    r0 = force_rate(compression(hx0[i] - hx0[i + 1], i, pre), w0, ha0[i] - ha0[i + 1], c_right[s], law)
                    r1 = force_rate(compression(hx1[i] - hx1[i + 1], i, pre), w1, ha1[i] - ha1[i + 1], c_right[s], law)
                    if falls(r0, r1):  # the root of the force's rate; the force by the law there
                        theta = root(ROOT_FORCE_RATE, i, M, r0, r1, hx0, hv0, ha0, hx1, hv1, ha1, h,
                                     c_left[s] if i > lo else 0.0, c_right[s],
                                     stiffness[r, i + 1] if i < M - 2 else 0.0, inv_m[s], 1.0 / masses[r, i + 1],
                                     law, pre, yld)
                        fp = dense_law_force(i, hx0, hv0, ha0, hx1, hv1, ha1, h, theta, c_right[s], law, pre)
                        if fp > 0.0 and fp > peak_f[r, i] + peak_rtol * abs(peak_f[r, i]):
                            peak_f[r, i] = fp
                            peak_ft[r, i] = t + theta * h
                elif VERLET and falls(w0, w1):  # at the zero of the linearly interpolated relative velocity
                    theta = w0 / (w0 - w1)
                    dp = compression(hermite3(hx0[i], hv0[i], hx1[i], hv1[i], h, theta)
                                     - hermite3(hx0[i + 1], hv0[i + 1], hx1[i + 1], hv1[i + 1], h, theta), i, pre)
                    fp = contact_force(dp, c_right[s], n)
                    if fp > 0.0 and fp > peak_f[r, i] + peak_rtol * abs(peak_f[r, i]):
                        peak_f[r, i] = fp
                        peak_ft[r, i] = t + theta * h
                elif falls(w0, w1):
                    d0 = compression(hx0[i] - hx0[i + 1], i, pre)  # (the static overlap included)
                    d1 = compression(hx1[i] - hx1[i + 1], i, pre)
                    if hermite_max_estimate(d0, w0, d1, w1, h) >= SCREEN * peak_d[r, i]:
                        theta = root(ROOT_APPROACH, i, M, w0, w1, hx0, hv0, ha0, hx1, hv1, ha1, h, 0.0, 0.0, 0.0,
                                     0.0, 0.0, law, pre, yld)
                        dp = dense_compression(i, hx0, hv0, ha0, hx1, hv1, ha1, h, theta, pre)
                        fp = elastic_force(dp, i, c_right[s], n, yld)  # (yielding: the history at the step's start)
                        if fp > 0.0 and fp > peak_f[r, i] + peak_rtol * abs(peak_f[r, i]):
                            peak_f[r, i] = fp
                            peak_ft[r, i] = t + theta * h
                            peak_d[r, i] = dp
        return found

    @cuda.jit(device=True)
    def sample_grid(g, r, t, h, own, lo, M, q_of, v, c_right, hx0, hv0, ha0, hx1, hv1, ha1, n, law, pre, yld,
                    t_grid, pulse_end, windows, wall, grid_v, grid_f, sensors, grid_c):
        """The grid times from index ``g`` that fall in the step from t to t + h, sampled on this thread's
        granules (``kernels.observe.sample_grid``): the observed granules' velocities (0 past a granule's
        averaged-pulse window, the velocity it left with behind the trailing window), the wall's force and the
        sensed contacts' (NaN behind the trailing window). Returns the next grid index."""
        T = t_grid.shape[0]
        while g < T and t_grid[g] <= t + h:
            theta = (t_grid[g] - t) / h
            for s in range(G):
                i = own + s
                q = q_of[s]
                if q >= 0:
                    if windows and t_grid[g] > pulse_end[q]:  # past its averaged-pulse window: not recorded
                        grid_v[r, g, q] = 0.0
                    elif i < lo:  # behind the trailing window: the velocity it left with
                        grid_v[r, g, q] = v[s]
                    elif VERLET:
                        grid_v[r, g, q] = hermite3(hv0[i], ha0[i], hv1[i], ha1[i], h, theta)
                    else:
                        grid_v[r, g, q] = dense_v(i, hx0, hv0, ha0, hx1, hv1, ha1, h, theta)
                if wall and i == M - 2:
                    grid_f[r, g] = grid_force(M - 2, hx0, hv0, ha0, hx1, hv1, ha1, h, theta, c_right[s], n, law, pre,
                                              yld)
            if SENSED:
                for k in range(sensors.shape[0]):
                    j = sensors[k]
                    if j >= own and j < own + G:  # (behind the trailing window: NaN, as the CPU's)
                        grid_c[r, g, k] = math.nan if j < lo else grid_force(
                            j, hx0, hv0, ha0, hx1, hv1, ha1, h, theta, c_right[j - own], n, law, pre, yld)
            g += 1
        return g

    @cuda.jit(device=True)
    def final_records(r, t, own, lo, M, q_of, x, v, a0, c_right, hx0, hv0, n, law, pre, yld, peak_rtol,
                      peak_v, peak_t, peak_f, peak_ft, x_out, v_out, history, spent):
        """The end of the run, on this thread's granules (their final positions and velocities shared in ``hx0``,
        ``hv0``): the last instant is a peak candidate where a granule still speeds up, or a contact still
        compresses (``kernels.peaks.final_peaks``, ``final_force_peaks``); the final state written, and a yielding
        contact's final history. Returns ``spent`` plus, for yielding contacts, the plastic work of this thread's
        contacts, a function of their histories (``kernels.forces.plastic_work``)."""
        for s in range(G):
            i = own + s
            q = q_of[s]
            if i >= lo and q >= 0 and a0[s] > 0.0 and v[s] > peak_v[r, q] + peak_rtol * abs(peak_v[r, q]):
                peak_v[r, q] = v[s]
                peak_t[r, q] = t
            if i >= lo and i < M - 1:
                d = compression(x[s] - hx0[i + 1], i, pre)
                if d > 0.0 and v[s] - hv0[i + 1] > 0.0:
                    # (a damped force clamped at 0 never beats the recorded peak, which is >= 0)
                    f = law_force(d, v[s] - hv0[i + 1], c_right[s], law) if DAMPED else elastic_force(d, i, c_right[s], n, yld)
                    if f > peak_f[r, i] + peak_rtol * abs(peak_f[r, i]):
                        peak_f[r, i] = f
                        peak_ft[r, i] = t
            if i < M:
                x_out[r, i] = x[s]
                v_out[r, i] = v[s]
            if PLASTIC and i < M - 1:  # the plastic work, a function of the history; the final history returned
                spent += plastic_work(yld[1, i], c_right[s], yld[0, i])
                history[r, i] = yld[1, i]
        return spent

    return Observers(initial_records, yield_turn, step_peaks, sample_grid, final_records)
