"""Design evaluation rates: the batched evaluator against a Python loop of ``simulate``, same run.

1. Designs evaluated per second for tapered protectors of N = 20 elastic granules against a rigid
   wall (the peak wall force; q spread over [0, 0.15]): ``granchain.design.BatchEvaluator`` (one call
   of the compiled ensemble kernel per generation, Numba threads over the designs) against a Python
   loop of ``granchain.simulate(space.chain(x))`` with the same integrator (``DP5()``, simulate's
   default), so that both compute the same numbers (checked, to round-off). Measured alternately
   (``--repeat`` rounds, best of each). Aim: >= 10x on 2 cores. The script also prints what batching
   can gain at most here: simulate's overhead per call is a fraction of a millisecond and a design of
   20 elastic granules against a wall takes some 18,000 DP5 steps, so the batch's gain is bounded by
   its threads (about 2x on 2 free cores), not by the loop's Python.
2. The wall time of the CLI's default run (``python -m granchain design --out DIR``, a fresh
   directory, in a subprocess: imports and the kernels' cache load included). Aim: < 60 s.

    python benchmarks/bench_design.py            # ~1 minute
    python benchmarks/bench_design.py --quick    # smoke run
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time

import numba
import numpy as np

import granchain as gc
from granchain import design

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_simulate import machine

TARGET_RATIO = 10.0
TARGET_CLI = 60.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--designs", type=int, default=200, help="designs per timing (default 200)")
    ap.add_argument("--repeat", type=int, default=3, help="alternating rounds, best of each (default 3)")
    ap.add_argument("--quick", action="store_true", help="smoke run: 40 designs, 1 round")
    args = ap.parse_args()
    count, repeat = (40, 1) if args.quick else (args.designs, args.repeat)
    print(machine(), flush=True)
    print(f"numba threads: {numba.get_num_threads()}; load average before: {os.getloadavg()}", flush=True)

    space = design.TaperedSpace(20, q=(0.0, 0.15))
    evaluator = design.BatchEvaluator(space, "wall-force")
    X = np.linspace(0.0, 0.15, count)[:, None]
    evaluator(X[:4])  # warm-up: the kernels' cache load is never timed
    gc.simulate(space.chain(X[0]))

    batch_t, loop_t = [], []
    for _ in range(repeat):
        t0 = time.perf_counter()
        batched = evaluator(X).value
        batch_t.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        looped = np.array([gc.simulate(space.chain(x)).peak_wall_force for x in X])
        loop_t.append(time.perf_counter() - t0)
    agree = float(np.max(np.abs(batched / looped - 1.0)))
    rate_b, rate_l = count / min(batch_t), count / min(loop_t)
    ratio = rate_b / rate_l
    print(f"designs/s, N = 20 tapered chains with a wall ({count} designs, best of {repeat}): batched {rate_b:.1f}, "
          f"loop of simulate {rate_l:.1f}; largest relative difference of the values {agree:.1e}", flush=True)
    print(f"batched / loop = {ratio:.2f}x  [aim >= {TARGET_RATIO:g}x on 2 cores: {'PASS' if ratio >= TARGET_RATIO else 'MISS'}]",
          flush=True)
    # What batching can save: simulate's own cost per call besides the integration (a 2-granule chain
    # integrates in a few microseconds, so its time is that overhead) against the time per design.
    # The batch removes the overhead and runs rows on Numba's threads, so it can reach at most
    # threads x (1 + overhead / integration).
    tiny = gc.tapered(2, 0.1, wall=True)
    gc.simulate(tiny)
    t0 = time.perf_counter()
    for _ in range(200):
        gc.simulate(tiny)
    overhead = (time.perf_counter() - t0) / 200
    per_design = min(loop_t) / count
    ceiling = numba.get_num_threads() * (1.0 + overhead / max(per_design - overhead, 1e-12))
    print(f"simulate's overhead per call {overhead * 1e3:.2f} ms, time per design in the loop {per_design * 1e3:.1f} ms: "
          f"batching's ceiling here ~{ceiling:.1f}x ({numba.get_num_threads()} threads, if the cores are free)", flush=True)

    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, PYTHONPATH=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "granchain", "design", "--out", os.path.join(tmp, "run"), "--quiet"],
                              capture_output=True, text=True, env=env, timeout=1800)
        wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(proc.stderr)
    print(f"CLI default run (python -m granchain design --out DIR): {wall:.1f} s  "
          f"[aim < {TARGET_CLI:g} s: {'PASS' if wall < TARGET_CLI else 'MISS'}]", flush=True)
    print(f"load average after: {os.getloadavg()}", flush=True)


if __name__ == "__main__":
    main()
