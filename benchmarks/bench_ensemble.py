"""Realisations per second of ``run_ensemble`` vs a SciPy ``solve_ivp`` loop, and the paper set.

1. ``granchain.run_ensemble`` (in memory, progress bar off, default threads = all cores, after a
   warm-up) for decorated and effective chains at N = 6, 11, 16, 26: realisations per second,
   end to end (radii, chains, integration, averaged pulse, Dataset).
2. Baseline, same run: a plain loop of ``scipy.integrate.solve_ivp(method="RK45")`` over a subset of
   the same realisations at N = 26 (default 5 decorated, 20 effective), doing the same work per
   realisation (peaks located on the dense output, velocities on the ensemble's time grid, the same
   time span t_end). Its tolerance is the loosest of a scan whose peak-velocity error on the subset
   (vs SciPy DOP853 rtol 1e-10 / atol 1e-12) is no larger than the ensemble's on the same subset.
   The baseline is serial, as a SciPy loop is; the ensemble uses all cores: the ratio is per machine
   (divide by the thread count for per core).
3. The paper's data set, 30,000 realisations of both chains at N = 6, 11, 16, 26, estimated from the
   measured rates and compared with the targets (decorated N = 26 >= 100 realisations/s, effective
   N = 26 >= 4,000 realisations/s, the whole set <= 10 minutes).

    python benchmarks/bench_ensemble.py            # full run (a few minutes)
    python benchmarks/bench_ensemble.py --quick    # smoke run
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numba
import numpy as np

import granchain as gc
from granchain import ensemble_integrator

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_simulate import errors, machine, solve_ivp_pulse  # noqa: E402

PAPER_REALIZATIONS = 30_000
PAPER_SIZES = (6, 11, 16, 26)
TARGETS = {"decorated": 100.0, "effective": 4000.0}  # realisations/s at N = 26
TARGET_TOTAL = 600.0  # seconds for the whole paper set
SEED = 0


def _label(integrator) -> str:
    """``rkn4 rtol 1e-05 / atol 1e-08, relaxed zone`` for a header line."""
    zone = ", relaxed zone" if getattr(integrator, "relaxed_lag", None) else ""
    return f"{integrator.name} rtol {integrator.rtol:g} / atol {integrator.atol:g}{zone}"


def ensemble_rate(n_large, chain, realizations, chunk_size):
    t0 = time.perf_counter()
    ds = gc.run_ensemble(n_large, realizations=realizations, seed=SEED, chains=chain, chunk_size=chunk_size, progress=False)
    seconds = time.perf_counter() - t0
    failed = int((ds["status"] != 0).sum())
    return realizations / seconds, seconds, failed, ds


def baseline(ds, n_large, kind, count, reference):
    """Matched-accuracy solve_ivp loop over realisations 0..count-1 of ``ds`` (one chain kind)."""
    grid = ds["time"].values
    rows = ds.sel(chain=kind).isel(realization=slice(0, count))
    chains = []
    for i in range(count):
        chain = gc.random_decorated(n_large, seed=SEED, realization=i)
        chains.append(chain if kind == "decorated" else gc.effective(chain))
    refs = [reference(ch) for ch in chains]
    err_ens = max(errors(rows["peak_velocity"].values[i], rows["peak_time"].values[i], *refs[i])[0] for i in range(count))
    err_ens_t = max(errors(rows["peak_velocity"].values[i], rows["peak_time"].values[i], *refs[i])[1] for i in range(count))
    t_end = rows["t_end"].values
    print(f"  {kind}: ensemble accuracy on realisations 0..{count - 1}: velocity {err_ens:.1e}, time {err_ens_t:.1e}")
    for rtol in 10.0 ** np.arange(-4.0, -11.01, -0.5):
        atol = rtol * 1e-2
        t0 = time.perf_counter()
        out = [solve_ivp_pulse(ch, "RK45", rtol, atol, t_end[i], t_grid=grid) for i, ch in enumerate(chains)]
        seconds = time.perf_counter() - t0
        err = max(errors(pv, pt, *refs[i])[0] for i, (pv, pt, _, _) in enumerate(out))
        err_t = max(errors(pv, pt, *refs[i])[1] for i, (pv, pt, _, _) in enumerate(out))
        print(f"    RK45 rtol {rtol:8.1e}: {count / seconds:9.2f} realisations/s, velocity error {err:.1e}, time error {err_t:.1e}",
              flush=True)
        if err <= err_ens:
            return count / seconds, rtol, err, err_ens
    return np.nan, None, np.nan, err_ens


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--sizes", default="6,11,16,26", help="N values (default 6,11,16,26)")
    p.add_argument("--decorated", type=int, default=200, help="decorated realisations per N (default 200)")
    p.add_argument("--effective", type=int, default=2000, help="effective realisations per N (default 2000)")
    p.add_argument("--chunk-size", type=int, default=500, help="run_ensemble chunk_size (default 500)")
    p.add_argument("--baseline-decorated", type=int, default=5, help="solve_ivp decorated realisations at N = 26 (default 5)")
    p.add_argument("--baseline-effective", type=int, default=20, help="solve_ivp effective realisations at N = 26 (default 20)")
    p.add_argument("--quick", action="store_true", help="smoke run: 20 decorated / 200 effective per N, baseline 1 / 4")
    args = p.parse_args(argv)
    if args.quick:
        args.decorated, args.effective, args.baseline_decorated, args.baseline_effective = 20, 200, 1, 4
    sizes = [int(s) for s in args.sizes.split(",")]
    counts = {"decorated": args.decorated, "effective": args.effective}

    print(f"bench_ensemble: run_ensemble realisations/s, seed {SEED}, chunk_size {args.chunk_size}, "
          f"{numba.get_num_threads()} Numba threads, the ensembles' default integrators: "
          + "; ".join(f"{c} {_label(ensemble_integrator(c))}" for c in ("decorated", "effective")))
    print(f"machine: {machine()}")
    for n_large in sizes:  # warm-up: compilation / cache load, first allocation
        gc.run_ensemble(n_large, realizations=2, seed=SEED, chunk_size=2, progress=False)

    rates, datasets = {}, {}
    print(f"\n{'N':>4s} {'chain':>10s} {'realisations':>13s} {'seconds':>9s} {'realisations/s':>15s} {'failed':>7s}")
    for n_large in sizes:
        for kind in ("decorated", "effective"):
            rate, seconds, failed, ds = ensemble_rate(n_large, kind, counts[kind], args.chunk_size)
            rates[n_large, kind] = rate
            datasets[n_large, kind] = ds
            print(f"{n_large:4d} {kind:>10s} {counts[kind]:13d} {seconds:9.2f} {rate:15.1f} {failed:7d}", flush=True)

    n_base = max(sizes)
    print(f"\nbaseline at N = {n_base}: solve_ivp(RK45) loop at matched accuracy (serial), same realisations")

    def reference(chain):
        r = gc.simulate(chain, gc.DOP853(rtol=1e-10, atol=1e-12))
        return r.peak_velocity, r.peak_time

    base = {}
    for kind, count in (("decorated", args.baseline_decorated), ("effective", args.baseline_effective)):
        base[kind] = baseline(datasets[n_base, kind], n_base, kind, count, reference)

    print(f"\nN = {n_base}: {'chain':>10s} {'granchain/s':>12s} {'solve_ivp/s':>12s} {'ratio':>8s}   (solve_ivp rtol; accuracies)")
    for kind in ("decorated", "effective"):
        rate_ivp, rtol, err, err_ens = base[kind]
        ratio = rates[n_base, kind] / rate_ivp
        print(f"{'':8s}{kind:>10s} {rates[n_base, kind]:12.1f} {rate_ivp:12.2f} {ratio:7.0f}x   "
              f"(rtol {rtol:.1e}; velocity error solve_ivp {err:.1e} <= granchain {err_ens:.1e})"
              if rtol is not None else f"{'':8s}{kind:>10s}: no scanned tolerance matched {err_ens:.1e}")
    threads = numba.get_num_threads()
    print(f"        (granchain uses {threads} threads, solve_ivp 1: per core the ratios are {threads} times smaller)")

    print(f"\npaper set: {PAPER_REALIZATIONS} realisations of both chains at N = {', '.join(map(str, PAPER_SIZES))}")
    total = 0.0
    for n_large in PAPER_SIZES:
        row = []
        for kind in ("decorated", "effective"):
            rate = rates.get((n_large, kind))
            if rate is None:  # not measured: scale the nearest measured N by the chain length squared
                near = min(sizes, key=lambda s: abs(s - n_large))
                rate = rates[near, kind] * (near / n_large) ** 2
                kind_note = f"{kind} (est. from N = {near})"
            else:
                kind_note = kind
            seconds = PAPER_REALIZATIONS / rate
            total += seconds
            row.append(f"{kind_note} {seconds:7.1f} s")
        print(f"  N = {n_large:2d}: " + ", ".join(row))
    print()
    for kind in ("decorated", "effective"):
        if (26, kind) in rates:
            rate, target = rates[26, kind], TARGETS[kind]
            verdict = "PASS" if rate >= target else "MISS"
            print(f"{verdict}  {kind} N = 26: {rate:8.1f} realisations/s, target >= {target:g}: {rate / target:.2f} x target")
    verdict = "PASS" if total <= TARGET_TOTAL else "MISS"
    print(f"{verdict}  paper set: {total / 60:.1f} minutes on this machine, target <= {TARGET_TOTAL / 60:g} minutes: "
          f"{TARGET_TOTAL / total:.2f} x target")
    print(f"machine after the run: {machine()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
