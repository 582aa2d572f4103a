"""What a first run costs, and whether long chains cost linearly: this tree against a baseline
revision (default: the granchain 0.4.0 release), measured in the same run.

1. **First result**: ``granchain pulse --small-radii 0.05,0.3,0.012`` in a fresh interpreter with an
   empty Numba cache (``NUMBA_CACHE_DIR`` pointing at a new directory), wall time, on each side; and
   the same command again (cache warm). The baseline is checked out with ``git worktree add
   --detach`` into a temporary directory (removed at the end) and imported through ``PYTHONPATH``.
2. **Compilation per kernel** (this tree): in a fresh interpreter with an empty cache, the first
   call of each kernel a run can need, in the order a user meets them (DP5 on the paper's chain, the
   ensemble kernels of the paper's two chains, RKN4, Verlet, DP5 and RKN4 with real contacts), less
   the same call warm: the compilation each one adds.
3. **Long chains**: CPU time of ``simulate(monodisperse(N), integrator=RKN4.windowed())`` (no time
   grid: the trailing window's own cost) for N = 1,000 .. 16,000 on this tree, with the ratio
   cost(16,000)/cost(1,000) (linear: 16), N = 100,000 once; the baseline at N = 1,000 and 4,000.

    python benchmarks/bench_first_run.py                 # ~5 minutes on 2 shared cores
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

KERNELS = r"""
import time, numpy as np, granchain as gc
small = gc.decorated([0.05, 0.3, 0.012])
jobs = [
    ("DP5, the paper's chain (a first pulse)", lambda: gc.simulate(small)),
    ("ensemble kernels of the paper's chains", lambda: gc.run_ensemble(6, realizations=4, progress=False)),
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


def run(tree: Path, args, cache: Path | None, script: str | None = None) -> tuple[float, str]:
    env = dict(os.environ, PYTHONPATH=str(tree))
    if cache is not None:
        env["NUMBA_CACHE_DIR"] = str(cache)
    cmd = [sys.executable, "-c", script, *args] if script else [sys.executable, "-m", "granchain", *args]
    t0 = time.perf_counter()
    out = subprocess.run(cmd, env=env, cwd=tree, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if out.returncode != 0:
        raise RuntimeError(f"{cmd[:3]} failed in {tree}:\n{out.stderr[-2000:]}")
    return wall, out.stdout


def scaling(tree: Path, sizes, cache: Path) -> dict:
    _, out = run(tree, [str(n) for n in sizes], cache, SCALING)
    return {int(n): float(t) for n, t, _ in (line.split() for line in out.splitlines())}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--baseline", default=BASELINE_REV, help="git revision to compare with (default: 0.4.0)")
    parser.add_argument("--no-large", action="store_true", help="skip N = 100,000")
    args = parser.parse_args(argv)
    scratch = Path(tempfile.mkdtemp(prefix="granchain-first-run-"))
    base = scratch / "baseline"
    try:
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(base), args.baseline], check=True,
                       capture_output=True)
        print(f"baseline {args.baseline} ({base}); current: {ROOT}")
        print("1. first result, empty Numba cache: granchain " + " ".join(PULSE))
        cold = {}
        for name, tree in (("baseline", base), ("current", ROOT)):
            cold[name], _ = run(tree, PULSE, scratch / f"cache-{name}")
            warm, _ = run(tree, PULSE, scratch / f"cache-{name}")
            print(f"  {name:9s} first {cold[name]:6.1f} s, then {warm:5.1f} s (cache warm)")
        speedup = cold["baseline"] / cold["current"]
        print(f"  first pulse: {speedup:.2f}x faster than the baseline "
              f"({'PASS' if speedup >= 4 else 'MISS'} at >= 4x; aim under 10 s: {'met' if cold['current'] < 10 else 'not met'})")
        print("2. compilation per kernel (this tree, empty cache):")
        _, out = run(ROOT, [], scratch / "cache-kernels", KERNELS)
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
        subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(base)], capture_output=True)
        shutil.rmtree(scratch, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
