"""How the ensembles' cost grows with the chain's length: CPU per decorated realisation at N = 26 and
N = 101 with the ensemble default (the trailing window, each granule's averaged pulse in a window of
its own) against the defaults before (``pulse_window="full"``: the relaxed zone, every granule
integrated to the end of the time grid), measured in the same run.

Target: cost(101) / cost(26) <= 5 with the default (linear in N is 100/25 = 4; the whole grid was ~14).

Each size runs ``--blocks`` blocks of ``--per-block`` realisations (realisations 0.. of seed 1, one
Numba thread, CPU time of the process), the settings alternating block by block so that a busy
neighbour hits both; the ratio's error bar is the standard error from the blocks (delta method). The
averaged-pulse windows are set once per size before timing (the pilot: 64 realisations, peaks only),
and the pilot's own CPU is printed apart: it is paid once per ensemble, 0.2 % of the paper's 30,000.

    python benchmarks/bench_scaling.py                 # ~3 minutes on 2 shared cores
    python benchmarks/bench_scaling.py --blocks 4 --per-block 16
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import time

import numpy as np

import granchain as gc
from granchain.ensembles import pulse_window
from granchain.ensembles.run import EnsembleSpec, compute_chunk

SIZES = (26, 101)


def spec_for(n_large: int, setting: str, realizations: int) -> tuple:
    """(spec with its windows set, CPU seconds of the pilot)."""
    spec = EnsembleSpec(gc.RandomDecorated(n_large), realizations, 1, ("decorated",), chunk_size=realizations,
                        pulse_window=setting)
    t0 = time.process_time()
    if spec.has_pulse_windows:
        spec = dataclasses.replace(spec, pulse_ends=pulse_window.window_ends(spec, lambda p: compute_chunk(p, 0, threads=1)))
    return spec, time.process_time() - t0


def block(spec, b: int, per_block: int) -> float:
    """CPU ms per realisation of realisations b*per_block .. (b+1)*per_block - 1."""
    sub = dataclasses.replace(spec, chunk_size=per_block)
    t0 = time.process_time()
    compute_chunk(sub, b, threads=1)
    return 1e3 * (time.process_time() - t0) / per_block


def ratio_with_error(a: np.ndarray, b: np.ndarray) -> tuple:
    """mean(b) / mean(a) and its standard error from the block samples (delta method)."""
    ma, mb = a.mean(), b.mean()
    sa, sb = a.std(ddof=1) / np.sqrt(a.size), b.std(ddof=1) / np.sqrt(b.size)
    r = mb / ma
    return r, r * np.hypot(sa / ma, sb / mb)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--blocks", type=int, default=8, help="blocks per size and setting (default 8)")
    p.add_argument("--per-block", type=int, default=8, help="realisations per block (default 8: 64 per size)")
    args = p.parse_args(argv)
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
          f"granchain {gc.__version__}; load average before: {os.getloadavg()[0]:.2f}")
    settings = ("auto", "full")
    n = args.blocks * args.per_block
    specs, pilot = {}, {}
    for setting in settings:
        for N in SIZES:
            specs[setting, N], pilot[setting, N] = spec_for(N, setting, n)
            block(dataclasses.replace(specs[setting, N], realizations=2), 0, 2)  # compiled or loaded before timing
    cost = {key: [] for key in specs}
    for b in range(args.blocks):
        for N in SIZES:
            for setting in settings:
                cost[setting, N].append(block(specs[setting, N], b, args.per_block))
    print(f"{'setting':28s} {'N = 26':>16s} {'N = 101':>16s}   cost(101)/cost(26)   pilot CPU (once per ensemble)")
    result = {}
    for setting, label in (("auto", "default (windowed, windows)"), ("full", "whole grid (relaxed, <0.5)")):
        c26, c101 = (np.array(cost[setting, N]) for N in SIZES)
        r, e = ratio_with_error(c26, c101)
        result[setting] = r, e
        pil = f"{pilot[setting, 26]:.2f} s, {pilot[setting, 101]:.2f} s" if setting == "auto" else "-"
        print(f"{label:28s} {c26.mean():8.2f} ms/real. {c101.mean():8.2f} ms/real.   {r:5.2f} +- {e:4.2f}         {pil}")
    r, e = result["auto"]
    print(f"verdict: default cost(101)/cost(26) = {r:.2f} +- {e:.2f} (target <= 5): {'PASS' if r <= 5 else 'MISS'}; "
          f"the whole grid's {result['full'][0]:.2f}; per realisation at N = 101 the default is "
          f"{np.mean(cost['full', 101]) / np.mean(cost['auto', 101]):.2f}x cheaper, at N = 26 "
          f"{np.mean(cost['full', 26]) / np.mean(cost['auto', 26]):.2f}x")
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
