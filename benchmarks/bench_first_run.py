"""What a first run costs, and whether long chains cost linearly: this tree against a baseline
revision (default: the granchain 0.4.0 release), measured in the same run.

1. **First result**: in a fresh interpreter with an empty Numba cache (``NUMBA_CACHE_DIR`` pointing at
   a new directory), wall time on each side of ``granchain pulse --small-radii 0.05,0.3,0.012`` and of
   ``granchain reproduce --quick --out DIR`` (``--no-reproduce`` skips it), then the same command
   again (cache warm: what is not compilation). The sides take turns, the side that goes first
   swapping every round (``--rounds``, best of them per side: a busy machine only slows a run down).
   Targets: the first pulse at least 4x faster than the baseline (aim: under 10 s), the first
   ``reproduce --quick`` at least 2x (aim: under 30 s); PASS or MISS for each. The baseline is checked
   out with ``git worktree add --detach`` into a temporary directory (removed at the end) and imported
   through ``PYTHONPATH``.
2. **Compilation per kernel** (this tree; with ``--kernels-against REV`` that revision too, which must
   have the API the jobs use): in a fresh interpreter with an empty cache, the first call of each
   kernel a run can need, in the order a user meets them (DP5 on the paper's chain, the ensemble
   kernels of the paper's two chains, RKN4, Verlet, DP5 and RKN4 with real contacts), less the same
   call warm: the compilation each one adds.
3. **Long chains**: CPU time of ``simulate(monodisperse(N), integrator=RKN4.windowed())`` (no time
   grid: the trailing window's own cost) for N = 1,000 .. 16,000 on this tree, with the ratio
   cost(16,000)/cost(1,000) (linear: 16), N = 100,000 once; the baseline at N = 1,000 and 4,000.

    python benchmarks/bench_first_run.py                 # ~10 minutes on 2 shared cores
    python benchmarks/bench_first_run.py --rounds 3 --no-large
    python benchmarks/bench_first_run.py --baseline HEAD~3
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BASELINE_REV = "df53015"  # granchain 0.4.0 as released
PULSE = ["pulse", "--small-radii", "0.05,0.3,0.012"]
REPRODUCE = ["reproduce", "--quick", "--quiet", "--out", "{out}"]
#: (command, speed-up over the baseline that passes, wall seconds aimed at)
TARGETS = {"pulse": (PULSE, 4.0, 10.0), "reproduce --quick": (REPRODUCE, 2.0, 30.0)}

KERNELS = r"""
import time, numpy as np, granchain as gc
small = gc.decorated([0.05, 0.3, 0.012])
jobs = [
    ("DP5, the paper's chain (a first pulse)", lambda: gc.simulate(small)),
    ("ensembles of the paper's two chains", lambda: gc.run_ensemble(6, realizations=4, progress=False)),
    ("RKN4", lambda: gc.simulate(small, integrator=gc.RKN4())),
    ("Verlet", lambda: gc.simulate(small, integrator=gc.Verlet(1e-3))),
    ("DP5 with dissipation", lambda: gc.simulate(small.with_dissipation(0.1))),
    ("RKN4 with precompression", lambda: gc.simulate(small.with_precompression(0.01), integrator=gc.RKN4())),
]
total = 0.0
for name, job in jobs:
    t0 = time.perf_counter(); job(); first = time.perf_counter() - t0
    t0 = time.perf_counter(); job(); warm = time.perf_counter() - t0
    total += first - warm
    print(f"  compile {name:42s} {first - warm:6.1f} s")
print(f"  compile all of the above{'':20s} {total:6.1f} s")
"""

SCALING = r"""
import sys, time, granchain as gc
sizes = [int(a) for a in sys.argv[1:]]
gc.simulate(gc.monodisperse(50), integrator=gc.RKN4.windowed())
for n in sizes:
    chain = gc.monodisperse(n)
    best = float("inf")
    for _ in range(1 if n > 20000 else 3):
        t0 = time.process_time(); r = gc.simulate(chain, integrator=gc.RKN4.windowed()); best = min(best, time.process_time() - t0)
    print(n, best, int(r.n_steps))
"""


def run(tree: Path, args, cache: Path | None, script: str | None = None, scratch: Path | None = None) -> tuple[float, str]:
    env = dict(os.environ, PYTHONPATH=str(tree))
    if cache is not None:
        env["NUMBA_CACHE_DIR"] = str(cache)
    if scratch is not None:  # a fresh output directory for commands that write one
        out = Path(tempfile.mkdtemp(dir=scratch, prefix="out-"))
        args = [a.format(out=out) for a in args]
    cmd = [sys.executable, "-c", script, *args] if script else [sys.executable, "-m", "granchain", *args]
    t0 = time.perf_counter()
    out = subprocess.run(cmd, env=env, cwd=tree, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if out.returncode != 0:
        raise RuntimeError(f"{cmd[:3]} failed in {tree}:\n{out.stderr[-2000:]}")
    return wall, out.stdout


def first_runs(trees: dict, command, rounds: int, scratch: Path) -> dict:
    """{side: (best first wall, best warm wall, every first wall)}: each round, on each side, the command
    with a new empty Numba cache, then again with that cache warm; sides alternate (the first swapping
    every round)."""
    walls = {name: ([], []) for name in trees}
    for r in range(rounds):
        for name in (list(trees) if r % 2 == 0 else list(trees)[::-1]):
            cache = Path(tempfile.mkdtemp(dir=scratch, prefix=f"cache-{name}-"))
            walls[name][0].append(run(trees[name], command, cache, scratch=scratch)[0])
            walls[name][1].append(run(trees[name], command, cache, scratch=scratch)[0])
            shutil.rmtree(cache, ignore_errors=True)
    return {name: (min(first), min(warm), first) for name, (first, warm) in walls.items()}


def scaling(tree: Path, sizes, cache: Path) -> dict:
    _, out = run(tree, [str(n) for n in sizes], cache, SCALING)
    return {int(n): float(t) for n, t, _ in (line.split() for line in out.splitlines())}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--baseline", default=BASELINE_REV, help="git revision to compare with (default: 0.4.0)")
    parser.add_argument("--no-large", action="store_true", help="skip N = 100,000")
    parser.add_argument("--no-reproduce", action="store_true", help="skip the first reproduce --quick (~2.5 minutes a round)")
    parser.add_argument("--rounds", type=int, default=1, help="alternating rounds of the first runs, best per side (default 1)")
    parser.add_argument("--kernels-against", default=None, metavar="REV",
                        help="also the compilation per kernel of this revision (it must have the jobs' API)")
    args = parser.parse_args(argv)
    scratch = Path(tempfile.mkdtemp(prefix="granchain-first-run-"))
    base = scratch / "baseline"
    other = scratch / "kernels-against"
    try:
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(base), args.baseline], check=True,
                       capture_output=True)
        print(f"baseline {args.baseline} ({base}); current: {ROOT}; load average {os.getloadavg()[0]:.2f} (before)")
        trees = {"baseline": base, "current": ROOT}
        for n, (target, (command, factor, aim)) in enumerate(TARGETS.items(), start=1):
            if target.startswith("reproduce") and args.no_reproduce:
                continue
            print(f"1.{n} first result, empty Numba cache: granchain {' '.join(command).replace('{out}', 'DIR')}"
                  f" (best of {args.rounds} alternating round{'s' if args.rounds > 1 else ''})")
            res = first_runs(trees, command, args.rounds, scratch)
            for name, (first, warm, every) in res.items():
                rounds = f" (rounds: {', '.join(f'{w:.1f}' for w in every)})" if len(every) > 1 else ""
                print(f"  {name:9s} first {first:6.1f} s, then {warm:5.1f} s (cache warm){rounds}")
            speedup = res["baseline"][0] / res["current"][0]
            print(f"  first {target}: {speedup:.2f}x faster than the baseline "
                  f"({'PASS' if speedup >= factor else 'MISS'} at >= {factor:g}x; aim under {aim:g} s: "
                  f"{'met' if res['current'][0] < aim else 'not met'}); load average {os.getloadavg()[0]:.2f}")
        print("2. compilation per kernel (empty cache):")
        tables = {"current": ROOT}
        if args.kernels_against:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(other), args.kernels_against],
                           check=True, capture_output=True)
            tables = {args.kernels_against: other, "current": ROOT}
        for name, tree in tables.items():
            _, out = run(tree, [], Path(tempfile.mkdtemp(dir=scratch, prefix="cache-kernels-")), KERNELS)
            print(f" {name}:")
            print(out, end="")
        print("3. long chains, monodisperse, RKN4.windowed(), CPU s per run:")
        sizes = [1000, 2000, 4000, 8000, 16000] + ([] if args.no_large else [100_000])
        cur = scaling(ROOT, sizes, scratch / "cache-current")
        old = scaling(base, [1000, 4000], scratch / "cache-baseline")
        for n in sizes:
            extra = f"   baseline {old[n]:8.3f}" if n in old else ""
            print(f"  N = {n:7d}  current {cur[n]:8.3f}{extra}")
        r = cur[16000] / cur[1000]
        print(f"  cost(16,000)/cost(1,000) = {r:.1f} (linear 16; {'PASS' if r <= 20 else 'MISS'} at <= 20); "
              f"baseline cost(4,000)/cost(1,000) = {old[4000] / old[1000]:.1f}")
    finally:
        for tree in (base, other):
            if tree.exists():
                subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)], capture_output=True)
        shutil.rmtree(scratch, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
