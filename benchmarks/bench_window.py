"""Goal-oriented error control: CPU cost of the relaxed zone, the trailing window and RKN4.

Baselines, both measured in the same run:

- ``exact``: the exact DP5 at the ensembles' tolerances (``DP5(1e-6, 1e-9)``, every granule
  integrated to the end with the full tolerance: the ensemble default of 0.2), in this
  version's kernel: the ratio to it is what the goal-oriented error control alone buys;
- ``0.2 DP5``: the same integrator in granchain as it was in 0.2 ("the 0.2 DP5":
  commit ``BASELINE_COMMIT``, taken from this repository's history with ``git archive`` and timed in
  a subprocess on the same realisations). The ratio to it adds what the step-loop kernel work
  bought (borrowed arrays in the step loop: no reference counting; see ``granchain.backends.kernels.memory.borrowed``).
  Skipped, with a note, where there is no git history.

Compared:

- ``relaxed``  = ``DP5.relaxed()``, the ensemble default for decorated chains in 0.3 (accuracy
  contract: peaks and the averaged pulse, tests/test_window.py; effective chains default to the same
  at rtol 5e-8, ``granchain.ensemble_integrator``);
- ``windowed`` = ``DP5.windowed()``, relaxed zone plus trailing window (peaks contract; the averaged
  pulse's tail is not kept, see ``granchain.DP5``);
- ``rkn4``     = ``RKN4.relaxed()``, the Runge-Kutta-Nystrom pair with the same relaxed zone at its
  default rtol (3e-6; 1e-5 before 2026-11-27, when the README's results were measured);
- ``rkn4-win`` = ``RKN4.windowed()``, the ensemble default for decorated chains now.

1. CPU-seconds per decorated realisation at N = 26 (``run_ensemble``, decorated chains, default time
   grid), 1 and 2 Numba threads; CPU time = process time (all threads), best of ``--repeat``,
   the integrators measured alternately.
2. Scaling: CPU-ms per decorated realisation at N = 26, 51, 101 (``--scaling`` realisations each,
   one thread), and cost(101) / cost(26) (target <= 4.5: linear in N).
3. The paper's data set (``granchain reproduce`` defaults: 30,000 realisations of both chains at
   N = 6, 11, 16, 26), estimated from wall-clock rates at all threads, with the ensemble defaults
   (per chain kind) and with the exact baseline (target <= 5 minutes).

    python benchmarks/bench_window.py            # a few minutes
    python benchmarks/bench_window.py --quick    # smoke run
"""

from __future__ import annotations

import argparse
import io
import json
import os
import shutil
import subprocess
import sys
import tarfile
import tempfile
import time

import numba

import granchain as gc

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_simulate import machine  # noqa: E402

INTEGRATORS = {
    "exact": lambda: gc.DP5(1e-6, 1e-9),
    "relaxed": lambda: gc.DP5.relaxed(),  # looked up when called: the 0.2 baseline imports this module too
    "windowed": lambda: gc.DP5.windowed(),
    "rkn4": lambda: gc.RKN4.relaxed(),
    "rkn4-win": lambda: gc.RKN4.windowed(),
}
GOAL = ("relaxed", "windowed", "rkn4", "rkn4-win")
PAPER_SIZES = (6, 11, 16, 26)
PAPER_REALIZATIONS = 30_000
TARGET_SPEEDUP = 2.5
TARGET_SCALING = 4.5
TARGET_PAPER = 300.0
#: granchain 0.2 (before the goal-oriented error control and the step-loop kernel work): its DP5.
BASELINE_COMMIT = "3dc0bcf"
BASELINE_SCRIPT = """
import importlib.util, json, os, sys
# granchain from the extracted directory, also where the package is installed in editable mode
# (whose import hook would win over sys.path); then this benchmark's own run() on it
package, bench_dir, n_large, realizations, threads, repeat = sys.argv[1], sys.argv[2], *(int(a) for a in sys.argv[3:7])
spec = importlib.util.spec_from_file_location("granchain", os.path.join(package, "granchain", "__init__.py"),
                                              submodule_search_locations=[os.path.join(package, "granchain")])
gc = importlib.util.module_from_spec(spec)
sys.modules["granchain"] = gc
spec.loader.exec_module(gc)
assert gc.__file__.startswith(package), gc.__file__
sys.path.insert(0, bench_dir)
from bench_window import run
run(6, 2, gc.DP5(1e-6, 1e-9), threads=threads)  # compile
cpu, wall, failed, steps = min(run(n_large, realizations, gc.DP5(1e-6, 1e-9), threads=threads) for _ in range(repeat))
print(json.dumps([gc.__version__, cpu, steps, failed]))
"""


def run(n_large, realizations, integrator, chains="decorated", threads=None, seed=0):
    """(CPU seconds, wall seconds, failed realisations, mean accepted steps) of one ensemble."""
    c0, w0 = time.process_time(), time.perf_counter()
    ds = gc.run_ensemble(gc.RandomDecorated(n_large), realizations=realizations, seed=seed, chains=chains,
                         integrator=integrator, threads=threads, progress=False, chunk_size=max(realizations, 1))
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    return cpu, wall, int((ds["status"] != 0).sum()), float(ds["n_steps"].mean())


def baseline_package() -> str | None:
    """A directory holding granchain as of BASELINE_COMMIT (git archive), or None without git history."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    try:
        tar = subprocess.run(["git", "-C", root, "archive", BASELINE_COMMIT, "granchain"], capture_output=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return None
    path = tempfile.mkdtemp(prefix="granchain-baseline-")
    with tarfile.open(fileobj=io.BytesIO(tar)) as archive:
        if hasattr(tarfile, "data_filter"):  # Python >= 3.11.4: refuse links and paths outside `path`
            archive.extractall(path, filter="data")
        else:
            archive.extractall(path)
    return path


def run_baseline(package, n_large, realizations, threads, repeat):
    """(CPU seconds, mean accepted steps, failed) of the 0.2 DP5 on the same realisations, in a subprocess."""
    env = dict(os.environ, NUMBA_CACHE_DIR=os.path.join(package, "numba-cache"))
    bench_dir = os.path.dirname(os.path.abspath(__file__))
    out = subprocess.run([sys.executable, "-c", BASELINE_SCRIPT, package, bench_dir, str(n_large), str(realizations), str(threads),
                          str(repeat)],
                         env=env, capture_output=True, text=True, check=True).stdout
    version, cpu, steps, failed = json.loads(out.strip().splitlines()[-1])
    return cpu, steps, failed, version


def best(n_large, realizations, threads, repeat):
    """Best-of-``repeat`` CPU seconds per integrator, measured alternately."""
    out = {name: None for name in INTEGRATORS}
    for _ in range(repeat):
        for name, make in INTEGRATORS.items():
            cpu, wall, failed, steps = run(n_large, realizations, make(), threads=threads)
            if out[name] is None or cpu < out[name][0]:
                out[name] = (cpu, wall, failed, steps)
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="small sizes (a smoke run, numbers not meaningful)")
    p.add_argument("--realizations", type=int, default=96, help="decorated realisations at N = 26 (part 1)")
    p.add_argument("--scaling", type=int, default=12, help="realisations per size in part 2")
    p.add_argument("--repeat", type=int, default=2)
    args = p.parse_args(argv)
    if args.quick:
        args.realizations, args.scaling, args.repeat = 8, 2, 1
    print(machine())
    for make in INTEGRATORS.values():  # compile once, outside the timings
        run(6, 2, make(), chains="both")

    package = baseline_package()
    try:
        measure(args, package)
    finally:  # the extracted baseline goes, also on an error or Ctrl-C
        if package is not None:
            shutil.rmtree(package, ignore_errors=True)


def measure(args, package):
    """Parts 1-3 and the verdicts (``package``: the baseline's directory, or None)."""
    print(f"\n1. CPU-ms per decorated realisation, N = 26, {args.realizations} realisations, best of {args.repeat} "
          f"(baselines, same run: exact DP5(1e-6, 1e-9) in this version; 0.2 DP5 = the same at commit {BASELINE_COMMIT})")
    if package is None:
        print(f"   (no git history here: the 0.2 DP5 baseline (commit {BASELINE_COMMIT}) is skipped)")
    print(f"{'threads':>7} {'integrator':>10} {'CPU-ms':>8} {'steps':>8} {'failed':>6} {'vs exact':>9} {'vs 0.2':>8}")
    verdicts = []
    for threads in (1, 2):
        res = best(26, args.realizations, threads, args.repeat)
        base = res["exact"][0]
        old = None
        if package is not None:
            cpu, steps, failed, version = run_baseline(package, 26, args.realizations, threads, args.repeat)
            old = cpu
            print(f"{threads:7d} {'0.2 DP5':>10} {1000 * cpu / args.realizations:8.2f} {steps:8.0f} {failed:6d} "
                  f"{base / cpu:8.2f}x {1.0:7.2f}x   (granchain {version})")
        for name, (cpu, wall, failed, steps) in res.items():
            vs_old = f"{old / cpu:7.2f}x" if old else f"{'-':>8}"
            print(f"{threads:7d} {name:>10} {1000 * cpu / args.realizations:8.2f} {steps:8.0f} {failed:6d} {base / cpu:8.2f}x {vs_old}")
        for name in GOAL:
            ratio = base / res[name][0]
            line = f"{ratio:.2f}x fewer CPU-seconds than this version's exact DP5"
            if old:  # the baseline the speed target names: the 0.2 DP5
                ratio = old / res[name][0]
                line = f"{ratio:.2f}x fewer CPU-seconds than the 0.2 DP5 ({line})"
            verdicts.append(f"{'PASS' if ratio >= TARGET_SPEEDUP else 'MISS'}  {name}, {threads} thread(s): {line} "
                            f"(target >= {TARGET_SPEEDUP}x, aim 4x)")

    print(f"\n2. Scaling: CPU-ms per decorated realisation, {args.scaling} realisations per size, 1 thread")
    sizes = (26, 51, 101)
    print(f"{'integrator':>10} " + " ".join(f"{'N = ' + str(n):>10}" for n in sizes) + f" {'101/26':>8}")
    for name, make in INTEGRATORS.items():
        costs = [run(n, args.scaling, make(), threads=1)[0] / args.scaling for n in sizes]
        ratio = costs[-1] / costs[0]
        print(f"{name:>10} " + " ".join(f"{1000 * c:10.1f}" for c in costs) + f" {ratio:8.1f}")
        if name != "exact":
            verdicts.append(f"{'PASS' if ratio <= TARGET_SCALING else 'MISS'}  {name}: cost(101)/cost(26) = {ratio:.1f} "
                            f"(target <= {TARGET_SCALING}; exact: see the table)")

    threads = numba.config.NUMBA_NUM_THREADS
    print(f"\n3. The paper's set ({PAPER_REALIZATIONS} realisations x both chains x N = {PAPER_SIZES}), "
          f"estimated from wall-clock rates at {threads} threads")
    sample = {"decorated": max(args.realizations, 8), "effective": 10 * max(args.realizations, 8)}
    for name in ("exact", "default"):
        total = 0.0
        parts = []
        for n in PAPER_SIZES:
            for kind, count in sample.items():
                wall = run(n, count, INTEGRATORS["exact"]() if name == "exact" else None, chains=kind)[1]
                total += PAPER_REALIZATIONS * wall / count
                parts.append(f"{kind[:3]} N={n}: {PAPER_REALIZATIONS * wall / count:5.0f} s")
        print(f"{name:>10}: {total / 60:5.1f} min  ({'; '.join(parts)})")
        if name == "default":
            verdicts.append(f"{'PASS' if total <= TARGET_PAPER else 'MISS'}  paper set with the ensemble defaults: "
                            f"{total / 60:.1f} min estimated (target <= {TARGET_PAPER / 60:.0f} min)")
    print()
    print("\n".join(verdicts))


if __name__ == "__main__":
    main()
