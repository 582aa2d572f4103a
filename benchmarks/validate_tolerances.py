"""Which tolerances meet the accuracy contract, and at what cost: the ensembles' defaults against looser ones.

The contract (``granchain.DP5``'s notes, ``tests/test_window.py``): peak velocities within 1e-6
(relative), peak times within 1e-5 and peak contact forces within 1e-6 of the chain's largest force,
against SciPy DOP853 at rtol 1e-10, atol 1e-12. For each family kind the script integrates ``--chains``
random chains (realisations 0.. of seed 2026, plus, for decorated chains, the two stored worst cases
where the lightest granule comes last and the pulse piles up at the free end) with the kind's ensemble
default (``granchain.ensemble_integrator``) and with looser tolerances of the same method (atol =
rtol / 1000, as the defaults) and without the relaxed zone, and prints for each the worst error over all
chains as a fraction of the contract (the margin is its inverse) and the CPU per chain. The errors are
measured against DOP853 at rtol 1e-12 (the contract's DOP853 at 1e-10 is computed too, to tell which
peaks the references resolve). Peaks that no tolerance can settle are counted and left out (see
:func:`contract_fractions`).

    python benchmarks/validate_tolerances.py                   # 100 chains per kind, ~40 minutes
    python benchmarks/validate_tolerances.py --chains 20       # a first look, ~8 minutes
    python benchmarks/validate_tolerances.py --kinds decorated
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

import granchain as gc

SEED = 2026
PEAK_V_RTOL, PEAK_T_ATOL, PEAK_F_RTOL = 1e-6, 1e-5, 1e-6
#: Realisations of ``RandomDecorated(n)`` under the tests' seed whose last granule sets the worst case
#: of the paper's data set (tests/test_window.py: the lightest granule late, the pulse piling up).
WORST_DECORATED = ((6, 23394), (16, 25779))

#: kind: (family, its chain kind (None: the family's one), rtols tried with the relaxed zone, rtols without)
KINDS = {
    "decorated": (lambda: gc.RandomDecorated(26), "decorated", (3e-5, 1e-4, 3e-4), (1e-5, 2e-6)),
    "effective": (lambda: gc.RandomDecorated(26), "effective", (1.5e-7, 5e-7, 1.5e-6), (5e-8, 1e-8)),
    "random-radii": (lambda: gc.RandomRadii(26, gc.Uniform(0.5, 1.5)), None, (5e-8, 1.5e-7), (5e-8, 1e-8, 5e-9, 2e-9)),
    "binary": (lambda: gc.BinaryRandom(26, radii=(1.0, 0.5)), None, (5e-8, 1.5e-7), (5e-8, 1e-8, 5e-9, 2e-9)),
}


def contract_fractions(a, ref, ref_tight) -> tuple:
    """The largest errors of run ``a`` against the reference ``ref_tight`` (peak velocity, peak time, peak
    force) as fractions of their limits (<= 1 meets the contract), and the numbers of granules left out.

    - A granule whose velocity still rises when a run ends has no peak to compare: its "peak" is its
      velocity at the end of the run, and the end (``exit_margin`` after the stop rule holds at a step's
      end) moves with the step sizes (two DOP853 references at rtol 1e-10 and 1e-12 end 0.03 apart on
      such a chain, their "peaks" 2e-3 apart). Left out of the velocity and time errors.
    - A peak time on which the two references (``ref`` at rtol 1e-10, ``ref_tight`` at 1e-12) differ by
      more than a tenth of the contract is not resolved by them (a flat maximum: the time moves as the
      square root of the velocity's error). Left out of the time errors.
    """
    ended = ((np.abs(a.peak_time - a.t_end) < 1e-9) | (np.abs(ref.peak_time - ref.t_end) < 1e-9)
             | (np.abs(ref_tight.peak_time - ref_tight.t_end) < 1e-9))
    unresolved = ~ended & (np.abs(ref.peak_time - ref_tight.peak_time) > 0.1 * PEAK_T_ATOL)
    dv = np.max(np.abs(a.peak_velocity / ref_tight.peak_velocity - 1.0)[~ended], initial=0.0) / PEAK_V_RTOL
    dt = np.max(np.abs(a.peak_time - ref_tight.peak_time)[~ended & ~unresolved], initial=0.0) / PEAK_T_ATOL
    df = np.max(np.abs(a.peak_force - ref_tight.peak_force)) / np.max(ref_tight.peak_force) / PEAK_F_RTOL
    return np.array([dv, dt, df]), int(ended.sum()), int(unresolved.sum())


def atol_of(rtol: float) -> float:
    """rtol / 1000 as the defaults write it (5e-11, not 5e-8 / 1000 = 4.9999999999999995e-11: near the
    contract's limit the worst chain's error moves by ~10 % with such a change)."""
    return float(f"{rtol / 1000.0:.6g}")


def chains_of(kind: str, count: int) -> tuple:
    """The chains of ``kind`` and the name of their chain kind (what ``ensemble_integrator`` takes)."""
    make, name, _, _ = KINDS[kind]
    family = make()
    name = name or family.chains[0]
    chains = [family.chain(SEED, i, name) for i in range(count)]
    if kind == "decorated":  # the stored worst cases (tests/test_window.py)
        chains += [gc.RandomDecorated(n).chain(11, r, "decorated") for n, r in WORST_DECORATED]
    return chains, name


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--chains", type=int, default=100, help="random chains per kind (default 100)")
    ap.add_argument("--kinds", default=",".join(KINDS), help=f"comma-separated, of {', '.join(KINDS)}")
    args = ap.parse_args(argv)
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f}; one chain at a time")
    reference, tight = gc.DOP853(rtol=1e-10, atol=1e-12), gc.DOP853(rtol=1e-12, atol=1e-14)
    for kind in args.kinds.split(","):
        chains, name = chains_of(kind, args.chains)
        t0 = time.perf_counter()
        refs = [(gc.simulate(ch, reference), gc.simulate(ch, tight)) for ch in chains]
        assert all(r.ok and r2.ok for r, r2 in refs), kind
        default = gc.ensemble_integrator(name)
        cls = type(default)
        label = (f"{cls.__name__}.relaxed({default.rtol:g})" if default.relaxed_lag
                 else f"{cls.__name__}({default.rtol:g}) exact")
        print(f"\n{kind}: {len(chains)} chains (DOP853 references in {time.perf_counter() - t0:.0f} s); "
              f"ensemble default {label}")
        candidates = [(label + " (default)", default)]
        candidates += [(f"{cls.__name__}.relaxed({r:g})", cls.relaxed(r, atol_of(r))) for r in KINDS[kind][2]]
        # without the relaxed zone (every granule at the tolerance): maxima behind the front
        candidates += [(f"{cls.__name__}({r:g}) exact", cls(r, atol_of(r))) for r in KINDS[kind][3]
                       if not (r == default.rtol and not default.relaxed_lag)]
        for cand, integ in candidates:
            for ch in chains[:2]:  # compile or load the kernel outside the timing
                gc.simulate(ch, integ)
            worst, cpu, failed, n_over, n_ended, n_unresolved = np.zeros(3), 0.0, 0, 0, 0, 0
            for ch, (ref, ref_tight) in zip(chains, refs):
                t0 = time.process_time()
                a = gc.simulate(ch, integ)
                cpu += time.process_time() - t0
                if not a.ok:
                    failed += 1
                    continue
                e, ended, unresolved = contract_fractions(a, ref, ref_tight)
                n_ended += ended
                n_unresolved += unresolved
                worst = np.maximum(worst, e)
                n_over += bool(e.max() > 1.0)
            top = worst.max()
            verdict = "meets" if top <= 1.0 and not failed else f"MISSES on {n_over} chains"
            print(f"  {cand:34s} worst {top:6.2f} of the contract (velocity {worst[0]:6.2f}, time {worst[1]:5.2f}, "
                  f"force {worst[2]:5.2f}), {1e3 * cpu / len(chains):5.2f} ms per chain{f', {failed} runs failed' if failed else ''}"
                  f" [{verdict}]")
        print(f"  (left out: {n_ended} peaks at the end of a run, {n_unresolved} peak times the references do not resolve)")
    print(f"\nload average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
