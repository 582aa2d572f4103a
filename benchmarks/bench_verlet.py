"""What the accuracy contract costs: granchain's integrators against a plain compiled velocity Verlet.

The field's usual code for these chains is a fixed-step velocity Verlet loop in C or Fortran. This
script writes that loop in Numba (:func:`plain_verlet`: positions, Hertz forces, velocities, and the
peaks of the observed granules located as granchain locates them, from the sign change of the
acceleration with the Hermite cubic of the velocity) and measures, on the same random decorated
chains (N = 26 large granules, ``granchain.random_decorated``, seeds 0..R-1):

1. the largest step of the plain loop that meets the accuracy contract on every chain (peak
   velocities within 1e-6 relative and peak times of granules 2..N-1 within 1e-5 of SciPy DOP853 at
   rtol 1e-10; the free end's peak time sits on a plateau), from
   dt = 4e-3 down by halves;
2. the CPU per chain of granchain's ensemble default (``ensemble_integrator()``: RKN4.windowed), of
   ``RKN4.relaxed()`` (every granule to the end: ``pulse_window="full"``) and of ``DP5()`` against the plain loop at that step: "x ahead" (aim >= 3x
   for the ensemble default);
3. ``granchain.Verlet(dt)`` at the same step against the plain loop, per step (aim <= 1.5x). What
   ``Verlet`` does on top of the plain loop: the peak contact force of every contact (one test per
   contact per step), the time grid, the stop rule (the pulse has left the chain) and the window that
   grows with the pulse.

Every timing is the best of ``--repeat`` runs (CPU time of this process, after a warm-up run that
compiles or loads the kernels), one chain at a time on one core.

    python benchmarks/bench_verlet.py                 # ~1 minute (DOP853 references ~2.5 s per chain)
    python benchmarks/bench_verlet.py --chains 6 --repeat 3
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
from numba import njit

import granchain as gc

N_LARGE = 26
PEAK_V_RTOL = 1e-6
PEAK_T_ATOL = 1e-5


@njit(cache=True)
def plain_verlet(m, c, v0, obs, dt, t_end):
    """Velocity Verlet for m_k x_k'' = F_{k-1} - F_k, F_k = c_k max(x_k - x_{k+1}, 0)^(3/2) (Eq. motion_rescaled,
    n = 5/2), granule 0 struck with v0; to t_end. Peaks of the observed granules: where a_k changes sign
    from + to -, the Hermite cubic of (v, a) at the zero of the linear interpolant of a. Returns
    (peak velocities, peak times, steps)."""
    M = m.shape[0]
    x = np.zeros(M)
    v = np.zeros(M)
    a = np.zeros(M)
    a_new = np.zeros(M)
    F = np.zeros(M + 1)
    v[0] = v0
    n_obs = obs.shape[0]
    peak_v = np.zeros(n_obs)
    peak_t = np.zeros(n_obs)
    for q in range(n_obs):  # the struck granule's peak is its initial velocity, at t = 0
        peak_v[q] = v[obs[q]]
    t = 0.0
    steps = 0
    while t < t_end:
        for k in range(M):
            x[k] += dt * v[k] + 0.5 * dt * dt * a[k]
        for j in range(M - 1):
            d = max(x[j] - x[j + 1], 0.0)
            F[j + 1] = c[j] * d * np.sqrt(d)
        for k in range(M):
            a_new[k] = (F[k] - F[k + 1]) / m[k]
        for q in range(n_obs):
            k = obs[q]
            v1 = v[k] + 0.5 * dt * (a[k] + a_new[k])
            if a[k] > 0.0 and a_new[k] <= 0.0:
                th = a[k] / (a[k] - a_new[k])
                t2 = th * th
                t3 = t2 * th
                vp = ((2 * t3 - 3 * t2 + 1) * v[k] + (t3 - 2 * t2 + th) * dt * a[k] + (-2 * t3 + 3 * t2) * v1
                      + (t3 - t2) * dt * a_new[k])
                if vp > peak_v[q]:
                    peak_v[q] = vp
                    peak_t[q] = t + th * dt
        for k in range(M):
            v[k] += 0.5 * dt * (a[k] + a_new[k])
            a[k] = a_new[k]
        t += dt
        steps += 1
    return peak_v, peak_t, steps


def cpu(fn, repeat):
    """Best CPU time of ``repeat`` calls (after one untimed call) and the last result."""
    out = fn()
    best = np.inf
    for _ in range(repeat):
        t0 = time.process_time()
        out = fn()
        best = min(best, time.process_time() - t0)
    return best, out


def errors(peak_v, peak_t, ref):
    """Largest relative peak-velocity and absolute peak-time deviation from the reference result. Peak
    times of granules 2..N-1: the free end's velocity rises to a plateau once its contact opens (its
    acceleration is exactly 0 from then on), so its peak time is defined only to within a step."""
    return (float(np.max(np.abs(peak_v / ref.peak_velocity - 1.0))),
            float(np.max(np.abs(peak_t - ref.peak_time)[1:-1])))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--chains", type=int, default=12, help="random decorated chains (seeds 0..chains-1)")
    ap.add_argument("--repeat", type=int, default=5, help="timings per chain and integrator (best kept)")
    args = ap.parse_args(argv)
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f}; one chain at a time, one core")
    chains = [gc.random_decorated(N_LARGE, seed=s) for s in range(args.chains)]
    refs = [gc.simulate(ch, gc.DOP853(rtol=1e-10, atol=1e-12)) for ch in chains]
    assert all(r.ok for r in refs)
    obs = [np.asarray(ch.observed, dtype=np.int64) for ch in chains]
    t_end = [r.t_end for r in refs]

    def plain(i, dt):
        ch = chains[i]
        return plain_verlet(ch.masses, ch.stiffness, float(ch.initial_velocity), obs[i], dt, t_end[i])

    # 1. the plain loop's step at the contract (and, for comparison, at its velocity half alone)
    dt_contract = dt_velocity = None
    for dt in 4e-3 / 2.0 ** np.arange(7):
        worst_v = worst_t = 0.0
        for i in range(len(chains)):
            pv, pt, _ = plain(i, dt)
            ev, et = errors(pv, pt, refs[i])
            worst_v, worst_t = max(worst_v, ev), max(worst_t, et)
        ok = worst_v <= PEAK_V_RTOL and worst_t <= PEAK_T_ATOL
        print(f"plain Verlet dt = {dt:.2e}: worst peak velocity {worst_v:.2e}, peak time {worst_t:.2e}"
              f" [{'meets' if ok else 'misses'} the contract]")
        if dt_velocity is None and worst_v <= PEAK_V_RTOL:
            dt_velocity = dt
        if ok:
            dt_contract = dt
            break
    if dt_contract is None:
        raise SystemExit("the plain loop did not meet the contract down to dt = 6.25e-5")

    # 2. and 3. CPU per chain
    def per_chain(fn):
        total = 0.0
        steps = 0
        worst = (0.0, 0.0)
        for i in range(len(chains)):
            sec, out = cpu(lambda i=i: fn(i), args.repeat)
            total += sec
            if isinstance(out, tuple):
                steps += out[2]
                ev, et = errors(out[0], out[1], refs[i])
            else:
                steps += out.n_steps
                ev, et = errors(out.peak_velocity, out.peak_time, refs[i])
            worst = (max(worst[0], ev), max(worst[1], et))
        return total / len(chains), steps / len(chains), worst

    base, base_steps, base_err = per_chain(lambda i: plain(i, dt_contract))
    print(f"\nbaseline: plain compiled velocity Verlet at dt = {dt_contract:.2e}: {1e3 * base:.2f} ms per chain, "
          f"{base_steps:.0f} steps, {1e9 * base / base_steps:.0f} ns per step (errors {base_err[0]:.1e}, {base_err[1]:.1e})")
    if dt_velocity != dt_contract:
        loose, loose_steps, _ = per_chain(lambda i: plain(i, dt_velocity))
        print(f"(the plain loop at dt = {dt_velocity:.2e}, where it meets the peak velocities but not the peak times: "
              f"{1e3 * loose:.2f} ms per chain)")
    ens = gc.ensemble_integrator()
    zone = "windowed" if ens.window_lag else "relaxed"
    ens_name = f"ensemble default {type(ens).__name__}.{zone}({ens.rtol:g}, {ens.atol:g})"
    for name, integ, aim in ((ens_name, ens, 3.0), ("RKN4.relaxed()", gc.RKN4.relaxed(), None),
                             ("DP5()", gc.DP5(), None)):
        sec, steps, err = per_chain(lambda i, integ=integ: gc.simulate(chains[i], integ))
        verdict = "" if aim is None else f" [aim >= {aim:g}x: {'PASS' if base / sec >= aim else 'MISS'}]"
        extra = "" if dt_velocity == dt_contract else f", {loose / sec:.2f}x ahead of the loop at dt = {dt_velocity:.2e}"
        print(f"{name:44s} {1e3 * sec:7.2f} ms per chain ({steps:6.0f} steps, errors {err[0]:.1e}, {err[1]:.1e}): "
              f"{base / sec:5.2f}x ahead of the plain loop{verdict}{extra}")
    sec, steps, err = per_chain(lambda i: gc.simulate(chains[i], gc.Verlet(dt_contract)))
    ratio = (sec / steps) / (base / base_steps)
    print(f"{'granchain Verlet(dt = %.2e)' % dt_contract:44s} {1e3 * sec:7.2f} ms per chain ({steps:6.0f} steps, "
          f"errors {err[0]:.1e}, {err[1]:.1e}): per step {ratio:.2f}x the plain loop "
          f"[aim <= 1.5x: {'PASS' if ratio <= 1.5 else 'MISS'}]")
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
