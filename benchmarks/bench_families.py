"""Ensemble rates through the chain-family seam, against granchain 0.1.0 measured in the same run.

1. ``RandomDecorated(26)`` (the paper's chain), decorated and effective chains: realisations per
   second of ``run_ensemble`` now, and of granchain 0.1.0 (git revision ``bf1cb2a``, the last
   commit before the chain-family redesign, extracted with ``git archive`` into a temporary
   directory and run in a subprocess with the same Python, seed, realisations, chunk size and
   threads). The two are measured alternately (``--repeat`` rounds, best of each) so that load
   on a shared machine hits both alike. The redesign must not cost speed: ratio now / 0.1.0.
2. The new families at comparable sizes (51 granules, as the decorated N = 26 chain):
   ``TaperedDecorated(26, q=0.02)``, ``RandomRadii(51, U[0.5, 1])``, ``BinaryRandom(51, (1, 0.5), 0.5)``,
   and ``CustomFamily`` (a Python function returning 51 radii), whose chains are built in Python
   one realisation at a time: its build time per realisation is printed apart.

    python benchmarks/bench_families.py            # ~3 minutes
    python benchmarks/bench_families.py --quick    # smoke run
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numba
import numpy as np

import granchain as gc

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_simulate import machine  # noqa: E402

BASELINE_REV = "bf1cb2a"
SEED = 0
ROOT = Path(__file__).resolve().parents[1]

_OLD = """
import json, sys, time
sys.path.insert(0, {path!r})
import granchain as gc
assert gc.__file__.startswith({path!r}), gc.__file__
gc.run_ensemble(26, realizations=2, seed=0, chains={chain!r}, chunk_size=2, progress=False)  # compile / load the cache
t0 = time.perf_counter()
ds = gc.run_ensemble(26, realizations={count}, seed={seed}, chains={chain!r}, chunk_size={chunk}, progress=False)
seconds = time.perf_counter() - t0
print(json.dumps({{"seconds": seconds, "failed": int((ds["status"] != 0).sum()), "version": gc.__version__,
                  "peak": ds["peak_velocity"].values.tolist()}}))
"""


def old_rate(path: str, chain: str, count: int, chunk: int):
    script = _OLD.format(path=path, chain=chain, count=count, seed=SEED, chunk=chunk)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=3600)
    if proc.returncode != 0:
        raise RuntimeError(proc.stderr)
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    return count / out["seconds"], out


#: What granchain 0.1.0 integrated with (the exact DP5 at the ensembles' tolerances): part 1 compares
#: like with like. The defaults have changed since (0.3: relaxed zone; 0.4: RKN4 for decorated chains),
#: and their gains are benchmarks/bench_window.py's, not the family seam's.
V010_INTEGRATOR = gc.DP5(1e-6, 1e-9)


def new_rate(family, chain: str, count: int, chunk: int, integrator=None):
    t0 = time.perf_counter()
    ds = gc.run_ensemble(family, realizations=count, seed=SEED, chains=chain, chunk_size=chunk, progress=False,
                         integrator=integrator)
    return count / (time.perf_counter() - t0), ds


def shrinking_radii(rng):
    """A user's family: 51 radii, each a random fraction of the one before (a random taper)."""
    return np.cumprod(rng.uniform(0.97, 1.0, 51))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--decorated", type=int, default=200, help="decorated realisations (default 200)")
    p.add_argument("--effective", type=int, default=2000, help="effective realisations (default 2000)")
    p.add_argument("--families", type=int, default=200, help="realisations of each new family (default 200)")
    p.add_argument("--chunk-size", type=int, default=500)
    p.add_argument("--repeat", type=int, default=2, help="alternating rounds old/new, best of each (default 2)")
    p.add_argument("--quick", action="store_true", help="smoke run: 20 decorated, 200 effective, 20 per family, 1 round")
    args = p.parse_args(argv)
    if args.quick:
        args.decorated, args.effective, args.families, args.repeat = 20, 200, 20, 1
    print(f"bench_families: seed {SEED}, chunk_size {args.chunk_size}, {numba.get_num_threads()} Numba threads, "
          f"granchain {gc.__version__} vs 0.1.0 ({BASELINE_REV})")
    print(f"machine: {machine()}")

    with tempfile.TemporaryDirectory() as old:
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", BASELINE_REV, "granchain"], capture_output=True, check=True)
        subprocess.run(["tar", "-x", "-C", old], input=archive.stdout, check=True)
        print(f"\n1. RandomDecorated(26): realisations/s, best of {args.repeat} alternating rounds")
        print(f"{'chain':>10s} {'realisations':>13s} {'0.1.0':>10s} {'now':>10s} {'now / 0.1.0':>12s}  same results")
        family = gc.RandomDecorated(26)
        for chain, count in (("decorated", args.decorated), ("effective", args.effective)):
            new_rate(family, chain, 2, 2, V010_INTEGRATOR)  # warm-up
            olds, news = [], []
            for _ in range(args.repeat):
                rate, out = old_rate(old, chain, count, args.chunk_size)
                olds.append(rate)
                rate, ds = new_rate(family, chain, count, args.chunk_size, V010_INTEGRATOR)
                news.append(rate)
            same = np.array_equal(np.asarray(out["peak"]), ds["peak_velocity"].values)
            ratio = max(news) / max(olds)
            print(f"{chain:>10s} {count:13d} {max(olds):10.1f} {max(news):10.1f} {ratio:11.2f}x  {'bitwise' if same else 'DIFFERENT'}")
            verdict = "PASS" if ratio >= 0.95 else "MISS"
            print(f"{verdict}  {chain}: the redesign costs {max(0.0, 1 - ratio):.0%} of the 0.1.0 rate (target: no loss beyond 5 % noise)")

    print(f"\n2. New families, {args.families} realisations each, 51 granules (as the decorated N = 26 chain)")
    print(f"{'family':>44s} {'chain':>18s} {'realisations/s':>15s} {'vs decorated N = 26':>20s}")
    ref, _ = new_rate(family, "decorated", args.families, args.chunk_size)
    custom = gc.CustomFamily(shrinking_radii, name="shrinking")
    for fam in (gc.TaperedDecorated(26, q=0.02), gc.RandomRadii(51, gc.Uniform(0.5, 1.0)), gc.BinaryRandom(51, (1.0, 0.5), 0.5), custom):
        new_rate(fam, fam.chains[0], 2, 2)  # warm-up
        rate, ds = new_rate(fam, fam.chains[0], args.families, args.chunk_size)
        failed = int((ds["status"] != 0).sum())
        print(f"{fam.label():>44s} {fam.chains[0]:>18s} {rate:15.1f} {rate / ref:19.2f}x" + (f"  ({failed} failed)" if failed else ""))
    t0 = time.perf_counter()
    custom.draw_batch(SEED, np.arange(args.families))
    per = (time.perf_counter() - t0) / args.families
    t0 = time.perf_counter()
    family.draw_batch(SEED, np.arange(args.families))
    per_ref = (time.perf_counter() - t0) / args.families
    print(f"CustomFamily builds in Python: {per * 1e6:.0f} us per realisation (RandomDecorated draws in {per_ref * 1e6:.0f} us)")
    print(f"machine after the run: {machine()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
