"""Does a multirate treatment of the light granules' neighbourhoods pay?

A multirate scheme integrates a fast granule (a light small granule, between its two large
neighbours) with its own short steps, and the rest of the chain with the long steps the other
granules allow. Two measurements, both against the same chains as they are (the baseline, same run):

1. The ceiling: each chain re-run by granchain with its lightest small granule made heavier (radius
   0.1), and with every small granule below 0.05 or 0.1 raised to it. Same integrator, time grid
   and tolerances; CPU-ms best of ``--repeat``, accepted steps. The first variant is what a perfect
   multirate treatment of the lightest granule's neighbourhood, with free micro-steps, would cost.
2. The prototype (``_multirate_prototype``): RKN4(3) with ``RKN4.relaxed()``'s relaxed zone, single-
   rate and multirate in the same code (no peaks or records: the ratio is what multirate buys).
   Small granules lighter than a threshold radius go multirate once they are in the relaxed zone
   (behind the pulse, where they rattle): micro-steps with their own step control on the quintic
   Hermite trajectories of their neighbours, their pushes added to the neighbours exactly. For each
   threshold: CPU-ms, macro- and micro-steps, and the accuracy of the observed granules' velocities
   on the time grid against the single-rate code at rtol 1e-10 (max over grid and realisations),
   with the single-rate relaxed run's as the yardstick.

Samples: the paper's N = 26 set (seed 1000 * 2026 + 26): its first ``--late`` realisations whose
lightest small granule (r < 0.013) sits in the last third of the chain (the
"lightest-granule-late" case, where the light granule's short steps cost longest), and its first ``--random`` realisations. Integrators (part 1): the
decorated ensembles' default ``RKN4.relaxed()`` and ``RKN4.windowed()``.

    python benchmarks/bench_multirate.py            # a minute or two
    python benchmarks/bench_multirate.py --quick    # smoke run
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

import granchain as gc
from granchain.solve.integrators import RELAXED_FACTOR, RELAXED_LAG

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _multirate_prototype  # noqa: E402
from bench_simulate import machine  # noqa: E402

N_LARGE = 26
SEED = 1000 * 2026 + N_LARGE  # the paper's N = 26 set (granchain reproduce)
LIGHT = 0.013  # "lightest-granule-late": lightest small radius below this ...
LATE = 2 / 3  # ... and beyond this fraction of the chain
HEAVIER = 0.1  # the ceiling: the lightest small granule re-run with this radius
INTEGRATORS = {"rkn4-rel": lambda: gc.RKN4.relaxed(), "rkn4-win": lambda: gc.RKN4.windowed()}
#: Threshold radii of the prototype's fast granules (0: single-rate, the baseline).
FAST_RADII = (0.0, 0.015, 0.03, 0.05, 0.1)
#: Worth a second step loop in the kernel: a gain of at least this on random realisations. (Adding
#: RKN4's loop doubled the fresh-install compile time; the multirate loop would add as much again,
#: with its own accuracy contract to validate.)
WORTH = 1.2


def late_realisations(family, count, limit=20_000):
    """The first ``count`` realisations of the set whose lightest small granule is light and late, and
    the fraction of the set they are (counted over the realisations searched)."""
    found, searched = [], 0
    for i in range(limit):
        small = family.chain(SEED, i, "decorated").meta["small_radii"]
        searched += 1
        if small.min() < LIGHT and np.argmin(small) >= LATE * small.size:
            found.append(i)
            if len(found) == count:
                break
    return found, len(found) / searched


def variants(chain):
    """The chain as is, with its lightest small granule made heavier (the ceiling), and with every
    small granule lighter than 0.05 or 0.1 raised to it (for comparison)."""
    radii = chain.radii
    small = radii[1::2]
    lightest = 1 + 2 * int(np.argmin(small))
    out = {"as is": radii}
    r = radii.copy()
    r[lightest] = max(HEAVIER, r[lightest])
    out[f"lightest->{HEAVIER}"] = r
    for floor in (0.05, 0.1):
        r = radii.copy()
        r[1::2] = np.maximum(small, floor)
        out[f"all<{floor}"] = r
    return {name: gc.from_radii(r, observed=chain.observed, kind="decorated") for name, r in out.items()}


def timed(chain, integrator, grid, repeat):
    """(best CPU seconds of ``repeat`` runs, accepted steps) of one simulate() call."""
    result = gc.simulate(chain, integrator, t_grid=grid)
    best = np.inf
    for _ in range(repeat):
        t0 = time.process_time()
        gc.simulate(chain, integrator, t_grid=grid)
        best = min(best, time.process_time() - t0)
    return best, result.n_steps


def prototype(family, indices, grid, fast_radius, rtol=1e-5, atol=1e-8):
    """Per realisation: (CPU seconds, macro-steps, micro-steps, fast granules, grid velocities) of one
    run of the prototype with the relaxed zone of RKN4.relaxed() and the threshold radius
    ``fast_radius`` (0: single-rate). rtol < 1e-8 runs it single-rate without the relaxed zone (the
    reference)."""
    reference = rtol < 1e-8
    lag, factor = (0, 1.0) if reference else (RELAXED_LAG, RELAXED_FACTOR)
    fast_mass = fast_radius ** 3 * (1 + 1e-9)  # masses in units of a large granule's (radius 1)
    out = []
    for i in indices:
        chain = family.chain(SEED, i, "decorated")
        x0 = np.zeros(chain.size)
        v0 = np.zeros(chain.size)
        v0[0] = chain.initial_velocity
        grid_v = np.zeros((grid.size, chain.observed.size))
        counts = np.zeros(4, np.int64)
        t0 = time.process_time()
        _multirate_prototype.integrate(chain.masses, chain.stiffness, chain.observed, x0, v0, grid, rtol, atol, lag,
                                       factor, fast_mass, grid_v, counts)
        out.append((time.process_time() - t0, counts[0], counts[2], counts[3], grid_v))
    return out


def best_prototype_runs(family, indices, grid, repeat):
    """{threshold radius: prototype runs} with each realisation's best CPU time of ``repeat`` rounds,
    the thresholds measured alternately within a round (a slow spell of this shared machine then
    hits every threshold, not one)."""
    runs = {radius: prototype(family, indices, grid, radius) for radius in FAST_RADII}
    for _ in range(repeat - 1):
        for radius in FAST_RADII:
            again = prototype(family, indices, grid, radius)
            runs[radius] = [(min(a[0], b[0]),) + a[1:] for a, b in zip(runs[radius], again)]
    return runs


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--late", type=int, default=8, help="lightest-granule-late realisations")
    p.add_argument("--random", type=int, default=48, help="realisations of the set taken in order")
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--quick", action="store_true", help="smoke run (numbers not meaningful)")
    args = p.parse_args(argv)
    if args.quick:
        args.late, args.random, args.repeat = 2, 2, 1
    print(machine())
    family = gc.RandomDecorated(N_LARGE)
    grid = family.default_time_grid()
    late, fraction = late_realisations(family, args.late)
    samples = {"random": list(range(args.random)), "late": late}
    print(f"\nSamples of the paper's N = {N_LARGE} set (seed {SEED}): late = realisations {late} "
          f"({100 * fraction:.1f} % of the realisations searched are lightest-granule-late); random = 0..{args.random - 1}")

    print("\n1. The ceiling: CPU-ms per realisation (granchain.simulate, best of {}), accepted steps, ns per step, "
          "and the gain of each variant over the chain as is".format(args.repeat))
    print(f"{'integrator':>10} {'sample':>7} {'variant':>16} {'CPU-ms':>8} {'steps':>8} {'ns/step':>8} {'gain':>6}")
    for name, make in INTEGRATORS.items():
        integrator = make()
        for sample, indices in samples.items():
            cost, steps = {}, {}
            for i in indices:
                for variant, chain in variants(family.chain(SEED, i, "decorated")).items():
                    c, s = timed(chain, integrator, grid, args.repeat)
                    cost[variant] = cost.get(variant, 0.0) + c
                    steps[variant] = steps.get(variant, 0) + s
            for variant in cost:
                print(f"{name:>10} {sample:>7} {variant:>16} {1e3 * cost[variant] / len(indices):8.2f} "
                      f"{steps[variant] / len(indices):8.0f} {1e9 * cost[variant] / steps[variant]:8.0f} "
                      f"{cost['as is'] / cost[variant]:5.2f}x")

    print(f"\n2. The prototype (RKN4(3), relaxed zone of RKN4.relaxed()): per realisation, CPU-ms (best of {args.repeat} "
          "alternating rounds), "
          "macro- and micro-steps, fast granules; the gain over single-rate; max |v - v_ref| on the grid "
          "(v_ref: single-rate, rtol 1e-10)")
    print(f"{'sample':>7} {'fast r <':>8} {'CPU-ms':>8} {'macro':>7} {'micro':>7} {'fast':>5} {'gain':>6} {'max error':>10}")
    gains = {}
    for sample, indices in samples.items():
        reference = [r[4] for r in prototype(family, indices, grid, 0.0, rtol=1e-10, atol=1e-13)]  # compiles too
        best_runs = best_prototype_runs(family, indices, grid, args.repeat)
        for radius in FAST_RADII:
            runs = best_runs[radius]
            cost = sum(r[0] for r in runs)
            if radius == 0.0:
                base = cost
            error = max(np.abs(r[4] - ref).max() for r, ref in zip(runs, reference))
            gains[sample, radius] = base / cost
            k = len(indices)
            print(f"{sample:>7} {radius if radius else '(single)':>8} {1e3 * cost / k:8.2f} {sum(r[1] for r in runs) / k:7.0f} "
                  f"{sum(r[2] for r in runs) / k:7.0f} {sum(r[3] for r in runs) / k:5.1f} {base / cost:5.2f}x {error:10.1e}")

    best = max((g, r) for (sample, r), g in gains.items() if sample == "random" and r > 0.0)
    late_best = max(g for (sample, r), g in gains.items() if sample == "late" and r > 0.0)
    verdict = "PAYS" if best[0] >= WORTH else "DOES NOT PAY"
    if args.quick:
        verdict = f"(smoke run, {args.random} random realisations: not meaningful) {verdict}"
    print(f"\n{verdict}  multirate light granules, random realisations: at best {best[0]:.2f}x (fast r < {best[1]}); "
          f"lightest-granule-late: at best {late_best:.2f}x (worth a second step loop at >= {WORTH}x)")


if __name__ == "__main__":
    main()
