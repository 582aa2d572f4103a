"""``benchmarks/bench_gpu.py --smoke`` under Numba's CUDA simulator: the GPU benchmark runs once on a
machine with a GPU and no second chance, so its every part is checked here at tiny sizes (N = 4, a few
realisations; the CUDA backend and the naive peer run in the simulator; the smoke run's layouts are those
the simulator runs quickly: ``tests/test_cuda.py`` checks the warp-shuffle one). Slow: about two minutes."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "benchmarks" / "bench_gpu.py"
#: The smoke run's budget here: its own (170 s) skips the parts that no longer fit, which on a loaded machine
#: (the slow suite runs on two workers) would be read as a missing part. The subprocess's timeout stays the guard.
BUDGET_S, TIMEOUT_S = 540, 600

#: The line each part prints once it has measured (an error or skip line does not count).
PART_LINES = {
    "machine": r"^\[machine\] device CUDA simulator.*CPUs: \d+ CPUs allowed on (\d+ physical cores \([\d.]+ threads? "
               r"per core\)|physical cores unknown)",
    "1 compile": r"^\[1 compile\] decorated N=4 L=32/shared: warm-up",
    "1 gpu L=32/shared": r"^\[1 gpu\] decorated N=4 L=32/shared \(shared exchange.*integration [\d.]+ s",
    "1 gpu L=1": r"^\[1 gpu\] decorated N=4 L=1 \(shared exchange.*integration [\d.]+ s",
    "1 gpu L=1/n": r"^\[1 gpu\] decorated N=4 L=1/n \(shared exchange.*exponent compiled in\).*integration [\d.]+ s",
    "1 gpu effective": r"^\[1 gpu\] effective N=4 L=32/shared \(shared exchange.*integration [\d.]+ s",
    "1 gpu effective dp5": r"^\[1 gpu\] effective N=4 L=32/shared dp5 \(asked for\) \(shared exchange.*integration [\d.]+ s"
                           r".*dp5 rtol",
    "1 gpu dp5 / rkn4": r"^\[1 gpu\] effective N=4 L=32/shared: DP5 / RKN4 integration = [\d.]+x",
    "2 peer": r"^\[2 peer\] naive thread-per-chain velocity Verlet.*kernel [\d.]+ s.*granchain [\d.]+x faster",
    "2 accuracy": r"^\[2 accuracy\] peer vs the GPU backend .*largest relative peak-velocity difference",
    "3 cpu decorated": r"^\[3 cpu\] CPU decorated N=4, threads=\d+.*GPU L=32 / CPU-\d+: [\d.]+x",
    "3 cpu effective": r"^\[3 cpu\] CPU effective N=4, threads=\d+",
    "3 threads": r"^\[3 threads\] CPU decorated N=4,  1 threads.*speed-up over 1 thread 1\.00x.*in the kernels [\d.]+ s, "
                 r"outside them \(serial\) -?[\d.]+ s",
    "4 reproduce": r"^\[4 reproduce\] `granchain reproduce .*wall [\d.]+ s",
    "5 agree decorated": r"^\[5 agree\] decorated N=4, .*within the contract",
    "5 agree effective": r"^\[5 agree\] effective N=4, .*within the contract",
    "6 damped": r"^\[6 damped\] decorated N=4, viscoelastic .*GPU L=32/shared .*dp5 rtol.*CPU-\d+ wall / GPU wall = [\d.]+x",
    "6 agree": r"^\[6 agree\] decorated N=4, viscoelastic .*relative difference of the dissipated energy",
    "7 loaded": r"^\[7 loaded\] decorated N=4, precompressed F0 = 0.01, wall: GPU L=32/shared .*rkn4 rtol.*CPU-\d+ wall / "
                 r"GPU wall = [\d.]+x",
    "7 agree": r"^\[7 agree\] decorated N=4, precompressed .*relative difference of the wall's peak force",
    "8 yielding": r"^\[8 yielding\] decorated N=4, Thornton's yielding contacts .*GPU L=32/shared .*dp5 rtol.*CPU-\d+ wall / "
                  r"GPU wall = [\d.]+x",
    "8 agree": r"^\[8 agree\] decorated N=4, Thornton's .*relative difference of the dissipated energy",
    "summary": r"^\[summary\] decorated integration +<= 1.5 s: (PASS|FAIL) ",
    "summary total": r"^\[summary\] total [\d.]+ s",
}


def missing_lines(text: str) -> list:
    """The parts of :data:`PART_LINES` whose line ``text`` lacks, and every error line of a part."""
    missing = [name for name, pattern in PART_LINES.items() if not re.search(pattern, text, re.MULTILINE)]
    errors = re.findall(r"^\[\d [\w ]*error\].*$", text, re.MULTILINE)
    return missing + errors


@pytest.mark.slow
def test_smoke_run_prints_every_part():
    """Every part's line, and no error line. Then, as the negative control of that check (in the same test, so
    that the smoke run is made once wherever pytest-xdist sends it), the output without part 3's lines, or with
    a part's error line, is reported."""
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1"}
    out = subprocess.run([sys.executable, str(SCRIPT), "--smoke", "--budget", str(BUDGET_S)], capture_output=True,
                         text=True, cwd=ROOT, env=env, timeout=TIMEOUT_S)
    assert out.returncode == 0, out.stderr[-3000:]
    assert missing_lines(out.stdout) == [], out.stdout + out.stderr[-3000:]

    without = "\n".join(line for line in out.stdout.splitlines() if not line.startswith("[3 "))
    assert {"3 cpu decorated", "3 cpu effective", "3 threads"} <= set(missing_lines(without))
    failed = out.stdout + "\n[2 peer error] CudaSupportError: no device\n"
    assert missing_lines(failed) == ["[2 peer error] CudaSupportError: no device"]


def test_kernel_clock_times_the_cpu_kernels(monkeypatch):
    """The ``[3 threads]`` lines' split of the wall (``KernelClock``) times the CPU backend's batch kernel
    through the module global it wraps: were the backend to call the kernel by another name, the clock would
    read 0 and every CPU speed-up would look serial-bound. A run inside the clock adds its kernel time; the
    same run after it adds nothing, and the backend's own function is back."""
    import importlib.util

    import granchain as gc
    import granchain.backends.numba_backend as nb

    spec = importlib.util.spec_from_file_location("bench_gpu", SCRIPT)
    bench = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, "bench_gpu", bench)  # its dataclasses look their module up while it loads
    spec.loader.exec_module(bench)
    original = nb.integrate_batch

    def ensemble():
        t0 = time.perf_counter()
        gc.run_ensemble(gc.RandomDecorated(4), realizations=8, chains="effective", progress=False)
        return time.perf_counter() - t0

    ensemble()  # compiled (or loaded from the cache) outside the measurement
    with bench.KernelClock() as clock:
        wall = ensemble()
    assert 0.0 < clock.seconds <= wall
    inside = clock.seconds
    ensemble()
    assert clock.seconds == inside and nb.integrate_batch is original
