"""granchain on one GPU against its peers, in one run: the CUDA backend per thread layout, a naive
one-thread-per-chain Verlet written here, the CPU backend on 16 threads, ``granchain reproduce`` on the
GPU, and the agreement of the two backends, with a summary of the targets.

Parts, in this order, each guarded (one that fails prints its error and the rest go on); every
measurement is one labelled line ``[part what] ...``, and every ratio is against a baseline measured in
the same run:

1. ``[1 gpu]``: the paper's decorated N = 26 set (``granchain.RandomDecorated(26)``, small radii
   U[0.01, 0.4]), 30,000 realisations, seed 0, on ``CudaBackend(threads_per_chain=L)`` for L = 32 (one
   warp per chain: warp shuffles with votes, the default; the same with Hertz's exponent compiled into the
   kernel, ``compiled_exponent=True``, uncapped and capped at 200 registers (ptxas, G = 2: 232 registers
   without spills, 8 chains per multiprocessor; capped, 10 chains and 136/140 B of spills); shuffle trees
   for the integer reductions; capped at 168 registers, which ptxas reaches without spills at G = 1
   (``benchmarks/gpu_registers.py``; a cap of 128 spilled 956/1,796 B at G = 2 and is no longer timed, to
   leave the budget to the later parts); shared memory) and 1 (one thread per chain: 3,000 realisations,
   scaled linearly, said in the line; L = 64 ran 3.5x slower than 32 on an H200 and is no longer timed);
   the integration time is the backend's own (``timings``: device time, synchronised, summed
   over the run's batches, the pulse-window pilot included), the wall time is ``run_ensemble``'s; then
   the effective N = 26 set (L = 32) with the GPU's default, RKN4, and with DP5 (their CPU default, asked
   for), and the ratio of the two. A small warm-up per layout comes first, its time printed apart
   (``[1 compile]``: compilation and first launch).
2. ``[2 peer]``: the naive peer, :func:`peer_kernel`: plain velocity Verlet at dt = 2.5e-4 (the largest
   step at which such a loop meets the accuracy contract, ``benchmarks/bench_verlet.py``), one thread
   per chain, over the same 30,000 decorated chains, each to the end of the ensemble's time grid
   (``family.default_time_grid()[-1]``: the ensemble integrates at least that far, then stops once the
   pulse has left; the peer does not look for the exit). Its peaks are checked against the GPU
   backend's on the first 100 chains (``[2 accuracy]``: the peer's accuracy at that step).
3. ``[3 cpu]``: the same sets on the CPU backend with 16 threads (2,000 realisations, scaled to
   30,000) and ``[3 threads]``: 1, 2, 4, 8, 16 threads on 1,000 realisations of each kind: speed-up
   over one thread and CPU seconds per realisation (``getrusage(RUSAGE_SELF)``: user + system seconds
   of every thread of the process). Ratio GPU / CPU-16, wall against wall (both ``run_ensemble`` end
   to end), and CPU wall against GPU integration. The speed-ups are read against the ``[machine]`` line's
   CPUs (:func:`cpu_topology`): the physical cores under the CPUs allowed, since two SMT threads of one core
   share it (16 threads on 8 cores cannot run 16x one thread), and a cgroup CPU quota where one is set; the
   summary's CPU lines repeat the cores. Each ``[3 threads]`` line splits the wall into the time inside the
   compiled kernels (the parallel region) and outside them (serial: draws, chain arrays, the pilot's windows,
   the Dataset; :class:`KernelClock`), so that a speed-up short of the thread count says whether the kernels
   or the serial part fell short.
4. ``[4 reproduce]``: ``granchain reproduce --backend cuda --out DIR`` in a subprocess (wall time,
   compilation and figures included; 8 ensembles of 30,000) and the integration time of that same
   run (the CUDA backends' ``timings``, read by a small driver around the command). Skipped, saying
   why, where the command has no ``--backend`` option.
5. ``[5 agree]``: the first 1,000 chains of each kind on both backends (same seed: realisation i
   depends on (seed, i) only, so parts 1 and 3 already hold them; computed here where they failed):
   the largest relative difference of the peak velocities, the largest difference of the peak times,
   and the fraction within the accuracy contract (``granchain.DP5``'s notes: peak velocities within
   1e-6 relative, peak times within 1e-5; each backend is held to it against DOP853, so two backends
   may differ by up to twice it). Each line names the integrators the two runs used.

6. ``[6 damped]``: the decorated N = 26 set with Kuwabara-Kono viscoelastic contacts (restitution 0.9 at the
   impact speed, ``granchain.Viscoelastic.from_restitution``): the GPU backend's DP5 (the default for
   contacts that dissipate) on 3,000 realisations, the same on the CPU's 16 threads, their wall times and
   ratio, and the largest differences of the two backends' peak velocities, peak times and dissipated
   energies. Not a target: it shows what dissipative ensembles cost on the GPU.

7. ``[7 loaded]``: the same set precompressed by F0 = 0.01 against a fixed wall (``RandomDecorated(...,
   static_force=0.01, wall=True)``: every chain runs to its time limit, the loaded contacts never open), as part 6
   measures it, with ``[7 agree]``: the peaks' and the wall's peak force's largest differences. Not a target.

8. ``[8 yielding]``: the same set with Thornton's elastic-plastic contacts (yield speed 0.3: the struck
   granule's first contacts yield, the far ones stay elastic), DP5 on both backends, as part 6 measures it, with
   ``[8 agree]``: the peaks' and the plastic work's largest differences. Not a target: what yielding contacts,
   each with its history and a step retaken at every turn from loading to unloading, cost on the GPU.

``[summary]``: decorated integration <= 1.5 s; >= 8x the peer; >= 20x CPU-16; reproduce integration
<= 10 s, wall <= 60 s; CPU >= 13x on 16 threads; each PASS/FAIL with its number (MISSING where the
part that measures it failed or was skipped).

On the device machine (one H100 or H200, 16 cores, no registry; the whole run is budgeted to finish in
under 6 minutes there: ``--budget``, parts that no longer fit are skipped with a line saying so)::

    bash .device/remote.sh python benchmarks/bench_gpu.py

Here, or in CI, without a GPU: ``--smoke`` runs every part at tiny sizes under Numba's CUDA simulator
(N = 4, 1-4 realisations, no pulse-window pilot, every ensemble stopped after 20 steps, the peer to
t = 3 at dt = 5e-3, ``reproduce`` at 20 realisations on the CPU backend: it checks the script, its
numbers mean nothing), in about a minute; ``tests/test_bench_gpu.py`` (marked slow) does that. CI
never runs the full benchmark::

    NUMBA_ENABLE_CUDASIM=1 python benchmarks/bench_gpu.py --smoke

Where ``granchain.backends.cuda`` cannot be imported, ``--stub`` (automatic with ``--smoke``) stands in
a backend that runs the CPU ensemble and times it as its "kernel": the plumbing is tested, the
numbers mean nothing, and every line says "stub".
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
import traceback
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from numba import cuda, float64  # (module globals: the CUDA simulator replaces only these inside a kernel)

ROOT = Path(__file__).resolve().parents[1]

#: The accuracy contract (``granchain.DP5``'s notes): peak velocities within 1e-6 relative, peak times within 1e-5.
PEAK_V_RTOL = 1e-6
PEAK_T_ATOL = 1e-5

#: Part 7's precompression F0 (rescaled: a fiftieth of the pulse's peak contact force, ~0.5).
LOAD = 0.01
#: Part 8's yield speed (rescaled: the relative impact speed at which two reference granules first yield).
YIELD_SPEED = 0.3

#: The targets of the summary: (label, comparison, threshold).
TARGETS = {
    "decorated integration": ("<=", 1.5, "s"),
    "vs the peer": (">=", 8.0, "x"),
    "vs CPU-16": (">=", 20.0, "x"),
    "reproduce integration": ("<=", 10.0, "s"),
    "reproduce wall": ("<=", 60.0, "s"),
    "CPU 16 threads decorated": (">=", 13.0, "x"),
    "CPU 16 threads effective": (">=", 13.0, "x"),
}


@dataclass(frozen=True)
class Sizes:
    """What a run measures: the full benchmark (the device machine) or the smoke run (the simulator)."""

    n_large: int = 26
    realizations: int = 30_000  # the paper's set, and what every scaled number is scaled to
    naive: int = 3_000  # L = 1 (one thread per chain)
    warmup: int = 256
    cpu16: int = 2_000
    sweep: int = 1_000
    threads: tuple = (1, 2, 4, 8, 16)
    agree: int = 1_000
    damped: int = 3_000  # (and the precompressed set's)
    peer_check: int = 100
    peer_dt: float = 2.5e-4
    peer_t_end: float | None = None  # None: the ensemble's time grid end
    reproduce: tuple = ()  # extra arguments of `granchain reproduce`
    budget_s: float = 330.0
    #: run_ensemble's keywords for every ensemble of the run (none: the defaults).
    ensemble_kw: tuple = ()
    #: The layouts of part 1 (``--layouts``): threads per chain, then optionally the exchange ("shuffle":
    #: warp shuffles, the default at 32; "shared": shared memory and barriers), a register cap, and
    #: "butterfly" (the shuffle exchange's integer reductions by shuffle trees, not warp votes), and "n" (the
    #: chains' exponent compiled into the kernel: ``CudaBackend(compiled_exponent=True)``). The variants of
    #: the default layout first, so that a tight budget skips the slow ones.
    layouts: tuple = ("32", "32/n", "32/n/200", "32/butterfly", "32/168", "32/shared", "1")
    #: The layout the other parts compare with (the backend's default: one warp per chain, shuffles).
    reference: str = "32"


FULL = Sizes()
#: The simulator runs a block's threads as Python threads in step: an N = 4 chain took 154 s with 32
#: threads (75 s without the pulse-window pilot's 64 chains), so the smoke run has no pilot
#: (``pulse_window="full"``) and stops every realisation after 20 steps (status MAX_STEPS).
SMOKE = Sizes(n_large=4, realizations=2, naive=2, warmup=1, cpu16=2, sweep=4, agree=2, damped=2, peer_check=2,
              peer_dt=5e-3, peer_t_end=3.0, reproduce=("--realizations", "20"), budget_s=170.0,
              ensemble_kw=(("pulse_window", "full"), ("max_steps", 20)),
              # (the simulator emulates a warp shuffle with two barriers of 32 Python threads: ~1 minute for the
              # smoke run's 40 steps; tests/test_cuda.py checks the shuffle layout)
              layouts=("32/shared", "1", "1/n"), reference="32/shared")


# --------------------------------------------------------------------------- the GPU backend's contract
class StubBackend:
    """Stands in for ``granchain.backends.cuda.CudaBackend`` until it exists: the CPU ensemble, timed
    as a whole and recorded as its "kernel" (the plumbing of this script, not a GPU number)."""

    stub = True

    def __init__(self, threads_per_chain: int):
        self.threads_per_chain = threads_per_chain
        self.timings = []


def parse_layout(layout) -> tuple:
    """(threads per chain, exchange or None, max_registers or None, votes, compiled exponent) of a layout
    "L[/exchange][/regs][/butterfly][/n]" ("butterfly": the shuffle exchange's integer reductions by shuffle
    trees instead of warp votes; "n": the exponent compiled into the kernel). ValueError for anything else."""
    parts = str(layout).split("/")
    known = ("shuffle", "shared", "butterfly", "n")
    for p in parts[1:]:
        if not (p in known or p.isdigit()):
            raise ValueError(f"unknown layout option {p!r} in {layout!r} (known: {', '.join(known)}, a register count)")
    exchange = next((p for p in parts[1:] if p in ("shuffle", "shared")), None)
    regs = next((int(p) for p in parts[1:] if p.isdigit()), None)
    return int(parts[0]), exchange, regs, "butterfly" not in parts[1:], "n" in parts[1:]


def layout_key(layout):
    """A layout as part 1 files its results: the int L for a plain "L", else the string."""
    return int(layout) if str(layout).isdigit() else str(layout)


def gpu_backend(layout, stub: bool):
    """The GPU backend of a layout (``CudaBackend(threads_per_chain=L, exchange=..., max_registers=..., votes=...,
    compiled_exponent=...)``; :func:`parse_layout`), or the stub."""
    L, exchange, regs, votes, exponent = parse_layout(layout)
    if stub:
        return StubBackend(L)
    from granchain.backends.cuda import CudaBackend

    return CudaBackend(threads_per_chain=L, exchange=exchange, max_registers=regs, votes=votes, compiled_exponent=exponent)


def ensemble(run, realizations, seed, chains, *, backend=None, chunk_size=None, threads=None, integrator=None,
             family=None):
    """``granchain.run_ensemble`` of ``family`` (default the run's) in memory, no progress, with the run's keywords;
    ``backend`` passed only where one is named (else the CPU default; the stub runs the CPU ensemble and
    appends its wall time to its ``timings``); ``integrator`` likewise (else the family's default)."""
    import granchain as gc

    family = run.family() if family is None else family
    kw = {"realizations": realizations, "seed": seed, "chains": chains, "out": None, "progress": False,
          **dict(run.sizes.ensemble_kw), **({} if integrator is None else {"integrator": integrator})}
    if chunk_size is not None:
        kw["chunk_size"] = chunk_size
    if threads is not None:
        kw["threads"] = threads
    if isinstance(backend, StubBackend):
        t0 = time.perf_counter()
        ds = gc.run_ensemble(family, **kw)
        backend.timings.append({"kernel_s": time.perf_counter() - t0, "realizations": realizations})
        return ds
    if backend is not None:
        kw["backend"] = backend
    return gc.run_ensemble(family, **kw)


def peaks(ds, n: int | None = None):
    """(peak_velocity, peak_time, ok) of the Dataset's one chain kind, realisations 0..n-1: (n, K), (n, K), (n,)."""
    sl = slice(0, n)
    v = ds["peak_velocity"].isel(chain=0, realization=sl).transpose("realization", "granule").values
    t = ds["peak_time"].isel(chain=0, realization=sl).transpose("realization", "granule").values
    ok = ds["status"].isel(chain=0, realization=sl).values == 0
    return v, t, ok


# --------------------------------------------------------------------------- the naive peer
_PEER = {}


def peer_kernel(M: int, K: int):
    """A plain velocity Verlet in numba.cuda, one thread per chain of M granules (K observed), compiled
    once per M: m_k x_k'' = F_{k-1} - F_k, F_k = c_k max(x_k - x_{k+1}, 0)^(3/2) (paper Eq.
    motion_rescaled, n = 5/2), granule 0 struck with v0, ``n_steps`` steps of ``dt``. The peak of an
    observed granule is located as ``bench_verlet.plain_verlet`` (and granchain) locates it: where its
    acceleration changes sign from + to -, the Hermite cubic of (v, a) at the zero of the linear
    interpolant of a. Arrays are (granule, chain), so that neighbouring threads read neighbouring
    addresses; each thread keeps x, v, a, 1/m, c of its chain in local memory."""
    if M in _PEER:
        return _PEER[M]

    @cuda.jit
    def kernel(masses, stiffness, v0, slot, dt, n_steps, peak_v, peak_t):
        r = cuda.grid(1)
        if r >= v0.shape[0]:
            return
        x = cuda.local.array(M, float64)
        v = cuda.local.array(M, float64)
        a = cuda.local.array(M, float64)
        m = cuda.local.array(M, float64)
        c = cuda.local.array(M, float64)
        for k in range(M):
            x[k] = 0.0
            v[k] = 0.0
            a[k] = 0.0
            m[k] = masses[k, r]
            c[k] = stiffness[k, r] if k < M - 1 else 0.0
        v[0] = v0[r]
        for q in range(K):
            peak_v[q, r] = 0.0
            peak_t[q, r] = 0.0
        peak_v[0, r] = v0[r]  # the struck granule's peak: its initial velocity, at t = 0
        h = 0.5 * dt
        for s in range(n_steps):
            for k in range(M):
                x[k] += dt * v[k] + h * dt * a[k]
            f_left = 0.0
            for k in range(M):
                f_right = 0.0
                if k < M - 1:
                    d = x[k] - x[k + 1]
                    if d > 0.0:
                        f_right = c[k] * d * math.sqrt(d)
                a_new = (f_left - f_right) / m[k]
                f_left = f_right
                v1 = v[k] + h * (a[k] + a_new)
                q = slot[k]
                if q >= 0 and a[k] > 0.0 and a_new <= 0.0:
                    th = a[k] / (a[k] - a_new)
                    t2 = th * th
                    t3 = t2 * th
                    vp = ((2.0 * t3 - 3.0 * t2 + 1.0) * v[k] + (t3 - 2.0 * t2 + th) * dt * a[k]
                          + (-2.0 * t3 + 3.0 * t2) * v1 + (t3 - t2) * dt * a_new)
                    if vp > peak_v[q, r]:
                        peak_v[q, r] = vp
                        peak_t[q, r] = (s + th) * dt
                v[k] = v1
                a[k] = a_new

    _PEER[M] = kernel
    return kernel


def run_peer(batch, dt: float, t_end: float):
    """The peer over every chain of ``batch`` (a ``ChainBatch``): (peak_v (R, K), peak_t (R, K), kernel
    seconds, wall seconds with the transfers, steps)."""
    masses = np.ascontiguousarray(np.asarray(batch.masses, dtype=float).T)
    stiffness = np.ascontiguousarray(np.asarray(batch.stiffness, dtype=float).T)
    v0 = np.ascontiguousarray(batch.initial_velocity, dtype=float)
    M, R = masses.shape
    observed = np.asarray(batch.observed, dtype=np.int64)
    slot = np.full(M, -1, dtype=np.int64)
    slot[observed] = np.arange(observed.size)
    K = observed.size
    n_steps = int(math.ceil(t_end / dt))
    kernel = peer_kernel(M, K)
    t0 = time.perf_counter()
    d = [cuda.to_device(a) for a in (masses, stiffness, v0, slot)]
    pv = cuda.device_array((K, R))
    pt = cuda.device_array((K, R))
    cuda.synchronize()
    threads = 128
    t1 = time.perf_counter()
    kernel[(R + threads - 1) // threads, threads](*d, dt, n_steps, pv, pt)
    cuda.synchronize()
    t2 = time.perf_counter()
    out_v, out_t = pv.copy_to_host().T, pt.copy_to_host().T
    return out_v, out_t, t2 - t1, time.perf_counter() - t0, n_steps


# --------------------------------------------------------------------------- the run
@dataclass
class Run:
    sizes: Sizes
    stub: bool
    smoke: bool
    parts: tuple
    t0: float = field(default_factory=time.perf_counter)
    results: dict = field(default_factory=dict)  # summary numbers by TARGETS key
    data: dict = field(default_factory=dict)  # datasets and timings kept for later parts
    device: str = ""
    cores: int | None = None  # physical cores under the CPUs allowed (cpu_topology)

    def line(self, label: str, text: str) -> None:
        print(f"[{label}] {text}", flush=True)

    def elapsed(self) -> float:
        return time.perf_counter() - self.t0

    def left(self) -> float:
        return self.sizes.budget_s - self.elapsed()

    def fits(self, label: str, need_s: float) -> bool:
        """True while ``need_s`` seconds are left of the budget; else a line saying what is skipped."""
        if self.left() >= need_s:
            return True
        self.line(label, f"skipped: {self.left():.0f} s left of the {self.sizes.budget_s:.0f} s budget, this needs ~{need_s:.0f} s")
        return False

    @property
    def tag(self) -> str:
        return " [stub: CPU ensemble timed as the kernel, not a GPU number]" if self.stub else ""

    def family(self):
        import granchain as gc

        return gc.RandomDecorated(self.sizes.n_large)


def device_name() -> str:
    """The CUDA device's name (numba.cuda), or what stands in for it."""
    if os.environ.get("NUMBA_ENABLE_CUDASIM") == "1":
        return "CUDA simulator (NUMBA_ENABLE_CUDASIM=1)"
    try:
        name = cuda.get_current_device().name
    except Exception as exc:  # noqa: BLE001 (no device: the peer's part then fails with its own error)
        return f"no CUDA device ({type(exc).__name__}: {exc})"
    return name.decode() if isinstance(name, bytes) else str(name)


def cpu_topology() -> tuple:
    """(physical cores, a line): the CPUs this process may run on, as the CPU speed-ups need them read. Two
    threads of one core (SMT) share its units, so 16 threads on 8 cores cannot run 16x one thread; a cgroup
    quota below the CPUs allowed caps the speed-up at the quota. The physical cores are the distinct
    (package, core) pairs of the allowed CPUs (Linux sysfs; None where it cannot be read)."""
    allowed = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else list(range(os.cpu_count() or 1))
    cores = set()
    try:
        for c in allowed:
            topo = Path(f"/sys/devices/system/cpu/cpu{c}/topology")
            cores.add(((topo / "physical_package_id").read_text().strip(), (topo / "core_id").read_text().strip()))
    except OSError:
        cores = None
    quota = "no cgroup CPU quota"
    try:  # cgroup v2: "max 100000" (none) or "<quota> <period>" in microseconds
        q, period = Path("/sys/fs/cgroup/cpu.max").read_text().split()[:2]
        if q != "max":
            quota = f"cgroup CPU quota {int(q) / int(period):g} CPUs"
    except (OSError, ValueError):
        try:  # cgroup v1
            q = int(Path("/sys/fs/cgroup/cpu/cpu.cfs_quota_us").read_text())
            if q > 0:
                quota = f"cgroup CPU quota {q / int(Path('/sys/fs/cgroup/cpu/cpu.cfs_period_us').read_text()):g} CPUs"
        except (OSError, ValueError):
            quota = "cgroup CPU quota unknown"
    model = platform.processor() or platform.machine()
    try:
        model = next(ln.split(":", 1)[1].strip() for ln in Path("/proc/cpuinfo").read_text().splitlines()
                     if ln.startswith("model name"))
    except (OSError, StopIteration):
        pass
    n_cores = len(cores) if cores else None
    per_core = len(allowed) / n_cores if n_cores else 0
    where = (f"on {n_cores} physical cores ({per_core:g} thread{'' if per_core == 1 else 's'} per core)" if n_cores
             else "on physical cores unknown (no sysfs topology)")
    return n_cores, f"{len(allowed)} CPUs allowed {where}; {quota}; {model}"


def cpu_seconds() -> float:
    """User + system CPU seconds of this process, every thread (``getrusage``)."""
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime


def gpu_run(run: Run, backend, chains: str, R: int, integrator=None, family=None):
    """One timed GPU ensemble of R realisations (seed 0, one chunk): (Dataset, integration s, wall s, the
    backend's timings of the run: one per batch, the pulse-window pilot's first)."""
    n0 = len(backend.timings)
    t0 = time.perf_counter()
    ds = ensemble(run, R, 0, chains, backend=backend, chunk_size=R, integrator=integrator, family=family)
    wall = time.perf_counter() - t0
    new = backend.timings[n0:]
    return ds, sum(float(t["kernel_s"]) for t in new), wall, new


def worst(x) -> float:
    """The largest finite value of ``x`` (0 where none: the smoke run's granules the pulse never reached)."""
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    return float(x.max()) if x.size else 0.0


def batches(timings) -> str:
    """The backend's batches of a run, as "realisations in seconds", comma-separated (and which is the
    pulse-window pilot: ``run_ensemble`` integrates realisations 0..63 first to set each granule's window)."""
    from granchain.ensembles.pulse_window import PILOT_REALIZATIONS

    text = ", ".join(f"{int(t['realizations']):,} in {float(t['kernel_s']):.3f} s" for t in timings)
    if len(timings) > 1 and int(timings[0]["realizations"]) == PILOT_REALIZATIONS:
        text += ", the first the pulse-window pilot"
    return text


def integrator_of(ds) -> str:
    """The integrator a Dataset's chains ran with (its record), e.g. "rkn4 rtol 3e-06"."""
    return f"{ds.attrs.get('integrator', '?')} rtol {ds.attrs.get('rtol', '?')}"


def compared(ok_a, ok_b, v_a, v_b):
    """The realisations to compare: status 0 on both runs where there are any; else (the smoke run, whose
    realisations stop after a few steps) those with finite peaks on both. Returns (mask, what it is)."""
    ok = ok_a & ok_b
    if ok.any():
        return ok, f"{int(ok.sum())} status 0 on both"
    finite = np.all(np.isfinite(v_a) & np.isfinite(v_b), axis=1)
    return finite, f"none status 0 on both: the {int(finite.sum())} with finite peaks"


def part_gpu(run: Run) -> None:
    s = run.sizes
    N = s.n_large
    # The effective chains twice: with the GPU's default, RKN4, and with their CPU default, DP5, which the GPU
    # runs when asked (the line says which is faster there).
    cases = [("decorated", x, None) for x in s.layouts] + [("effective", s.reference, None), ("effective", s.reference, "dp5")]
    for chains, layout, method in cases:
        L = layout_key(layout)
        label = f"{chains} N={N} L={L}" + (f" {method} (asked for)" if method else "")
        if not run.fits(f"1 gpu {chains} L={L}", 20.0):
            continue
        try:
            backend = gpu_backend(layout, run.stub)
            t0 = time.perf_counter()
            ensemble(run, s.warmup, 0, chains, backend=backend, chunk_size=s.warmup, integrator=method)
            run.line("1 compile", f"{label}: warm-up of {s.warmup} realisations {time.perf_counter() - t0:.2f} s "
                                  f"(compilation and first launch){run.tag}")
            R = s.naive if L == 1 else s.realizations
            if not run.stub:
                label += (f" ({backend.exchange} exchange{', warp votes' if backend.votes else ''}, "
                          f"max_registers {backend.max_registers}"
                          f"{', exponent compiled in' if backend.compiled_exponent else ''})")
            scale = s.realizations / R
            ds, kernel, wall, timings = gpu_run(run, backend, chains, R, integrator=method)
        except Exception as exc:  # noqa: BLE001 (one layout failing leaves the others)
            run.line(f"1 gpu {chains} L={L} error", f"{type(exc).__name__}: {exc}")
            traceback.print_exc(limit=4)
            continue
        ok = int(np.sum(ds["status"].values == 0))
        how = (f"{R:,} realisations, scaled x{scale:g} to {s.realizations:,} (linearly)" if scale != 1
               else f"{R:,} realisations")
        run.line("1 gpu", f"{label}: {how}: integration {kernel * scale:.3f} s (device, synchronised; "
                          f"{integrator_of(ds)}; batches {batches(timings)}), wall {wall * scale:.3f} s, "
                          f"{s.realizations / (wall * scale):,.0f} realisations/s; {ok:,} of {R:,} status 0; "
                          f"device {run.device}{run.tag}")
        run.data[(chains if method is None else f"{chains} {method}", L)] = {"ds": ds, "kernel": kernel * scale,
                                                                              "wall": wall * scale}
    ref = layout_key(s.reference)
    if ("effective", ref) in run.data and ("effective dp5", ref) in run.data:
        run.line("1 gpu", f"effective N={N} L={ref}: DP5 / RKN4 integration = "
                          f"{run.data[('effective dp5', ref)]['kernel'] / run.data[('effective', ref)]['kernel']:.2f}x "
                          f"(the GPU's default for them is RKN4){run.tag}")
    dec = {L: d for (kind, L), d in run.data.items() if kind == "decorated"}
    if dec:
        best = min(dec, key=lambda L: dec[L]["kernel"])
        run.results["decorated integration"] = (dec[best]["kernel"], f"L={best}")
        if 1 in dec and best != 1:
            run.line("1 gpu", f"layouts: thread per chain (L=1) / best (L={best}) integration = "
                              f"{dec[1]['kernel'] / dec[best]['kernel']:.2f}x{run.tag}")


def gpu_reference(run: Run, chains: str, n: int):
    """The GPU backend's Dataset of realisations 0..n-1 (part 1's L = 32 run where it holds them, else
    computed now), and where it comes from."""
    ref = run.sizes.reference
    got = run.data.get((chains, layout_key(ref)))
    if got is not None and got["ds"].sizes["realization"] >= n:
        return got["ds"], f"part 1's L={ref} run"
    return ensemble(run, n, 0, chains, backend=gpu_backend(ref, run.stub), chunk_size=n), f"a new L={ref} run of {n}"


def part_peer(run: Run) -> None:
    s = run.sizes
    family = run.family()
    R = s.realizations
    t_end = float(family.default_time_grid()[-1]) if s.peer_t_end is None else s.peer_t_end
    why = ("the end of the ensemble's time grid, which the ensemble integrates at least" if s.peer_t_end is None
           else "short, smoke run")
    batch = family.build(family.draw_batch(0, np.arange(R)), "decorated")
    warm = family.build(family.draw_batch(0, np.arange(min(R, 32))), "decorated")
    t0 = time.perf_counter()
    run_peer(warm, s.peer_dt, 10 * s.peer_dt)
    run.line("2 compile", f"peer kernel: {time.perf_counter() - t0:.2f} s (compilation and a 10-step launch)")
    pv, pt, kernel, wall, steps = run_peer(batch, s.peer_dt, t_end)
    line = (f"naive thread-per-chain velocity Verlet, dt = {s.peer_dt:g}, to t = {t_end:.1f} ({why}; no exit test): "
            f"{R:,} decorated N={s.n_large} chains, {steps:,} steps, kernel {kernel:.3f} s, wall {wall:.3f} s with the "
            f"transfers; device {run.device}")
    gpu = run.data.get(("decorated", layout_key(run.sizes.reference)))
    if gpu is not None:
        ratio = kernel / gpu["kernel"]
        run.results["vs the peer"] = (ratio, "L=32 integration vs the peer's kernel")
        line += f"; GPU granchain L=32 integration / peer = {gpu['kernel'] / kernel:.3f} (granchain {ratio:.1f}x faster){run.tag}"
    else:
        line += "; no GPU granchain run to compare (part 1 failed or was skipped)"
    run.line("2 peer", line)
    n = min(s.peer_check, R)
    ref, where = gpu_reference(run, "decorated", n)
    rv, rt, rok = peaks(ref, n)
    ok, which = compared(rok, np.ones(n, dtype=bool), rv, pv[:n])
    with np.errstate(divide="ignore", invalid="ignore"):
        dv = np.abs(pv[:n] / rv - 1.0)[ok]
    dt = np.abs(pt[:n] - rt)[ok][:, 1:-1]  # the free end's peak time sits on a plateau (bench_verlet.py)
    run.line("2 accuracy", f"peer vs the GPU backend ({where}) on chains 0..{n - 1} ({which}): largest "
                           f"relative peak-velocity difference {worst(dv):.2e}, largest peak-time difference "
                           f"(granules 2..N-1) {worst(dt):.2e} (contract 1e-6, 1e-5){run.tag}")


class KernelClock:
    """Wall seconds inside the CPU backend's compiled batch kernel (``granchain.backends.numba_backend``'s
    ``integrate_batch``: the parallel region, the threads' own reductions included) while the block runs; the
    rest of an ensemble's wall is its serial part (draws, chain arrays, buffers, the pilot's windows, the
    Dataset), which caps the speed-up over one thread (Amdahl). NaN where that function is not there."""

    def __init__(self):
        self.seconds = 0.0
        self._orig = None

    def __enter__(self):
        import granchain.backends.numba_backend as nb

        self._orig = getattr(nb, "integrate_batch", None)
        if self._orig is None:
            self.seconds = math.nan
            return self

        def timed(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return self._orig(*args, **kwargs)
            finally:
                self.seconds += time.perf_counter() - t0

        nb.integrate_batch = timed
        return self

    def __exit__(self, *exc):
        if self._orig is not None:
            import granchain.backends.numba_backend as nb

            nb.integrate_batch = self._orig
        return False


def timed_cpu(run: Run, chains: str, R: int, threads: int):
    """(Dataset, wall s, CPU s, wall s inside the compiled kernels) of a CPU-backend ensemble."""
    with KernelClock() as clock:
        c0, t0 = cpu_seconds(), time.perf_counter()
        ds = ensemble(run, R, 0, chains, threads=threads)
        wall = time.perf_counter() - t0
    return ds, wall, cpu_seconds() - c0, clock.seconds


def part_cpu(run: Run) -> None:
    import numba

    s = run.sizes
    avail = numba.config.NUMBA_NUM_THREADS
    sweep = tuple(t for t in s.threads if t <= avail)
    top = max(sweep)
    note = "" if top == max(s.threads) else f" (Numba can use {avail} threads here: {max(s.threads)} not measured)"
    for chains in ("decorated", "effective"):
        t0 = time.perf_counter()
        ensemble(run, 2 * top, 0, chains, threads=top)
        run.line("3 compile", f"CPU {chains}: warm-up {time.perf_counter() - t0:.2f} s (Numba compilation or cache load)")
    for chains in ("decorated", "effective"):
        R = s.cpu16
        scale = s.realizations / R
        _, wall, cpu, _ = timed_cpu(run, chains, R, top)
        line = (f"CPU {chains} N={s.n_large}, threads={top}{note}: {R:,} realisations scaled x{scale:g} to "
                f"{s.realizations:,}: wall {wall * scale:.2f} s, CPU {cpu / R * 1e3:.3f} ms per realisation")
        gpu = run.data.get((chains, layout_key(run.sizes.reference)))
        if gpu is not None:
            line += (f"; GPU L=32 / CPU-{top}: {wall * scale / gpu['wall']:.1f}x (wall vs wall), "
                     f"{wall * scale / gpu['kernel']:.1f}x (CPU wall vs GPU integration){run.tag}")
            if chains == "decorated":
                run.results["vs CPU-16"] = (wall * scale / gpu["wall"], f"wall vs wall, CPU on {top} threads")
        run.line("3 cpu", line)
    if not run.fits("3 threads", 30.0):
        return
    for chains in ("decorated", "effective"):
        base = None
        for th in sweep:
            ds, wall, cpu, inside = timed_cpu(run, chains, s.sweep, th)
            base = base or wall
            if th == 1:
                run.data[("cpu", chains)] = ds
            run.line("3 threads", f"CPU {chains} N={s.n_large}, {th:>2} threads, {s.sweep:,} realisations: wall {wall:.2f} s, "
                                  f"speed-up over 1 thread {base / wall:.2f}x, CPU {cpu / s.sweep * 1e3:.3f} ms per realisation; "
                                  f"in the kernels {inside:.3f} s, outside them (serial) {wall - inside:.3f} s")
        if top == 16:
            on = f", {run.cores} physical cores" if run.cores else ""
            run.results[f"CPU 16 threads {chains}"] = (base / wall, f"wall(1 thread) / wall(16){on}")


#: Run in the subprocess of part 4: ``granchain reproduce`` with its arguments, and afterwards one line
#: ``BENCH_REPRODUCE {json}``: the CUDA backends' integration time (every instance's ``timings``) and the
#: time inside ``compute_chunk`` (chains, integration and buffers of every chunk: the fallback where no
#: CUDA backend ran).
DRIVER = r'''
import json, sys, time
T0 = time.perf_counter()
instances = []
try:
    from granchain.backends.cuda import CudaBackend
    _init = CudaBackend.__init__
    def _record(self, *a, **k):
        _init(self, *a, **k)
        instances.append(self)
    CudaBackend.__init__ = _record
except ImportError:
    CudaBackend = None
import granchain.backends as backends
import granchain.ensembles.run as run
chunks = {"s": 0.0, "n": 0}
_compute = run.compute_chunk
def _timed(*a, **k):
    t = time.perf_counter()
    try:
        return _compute(*a, **k)
    finally:
        chunks["s"] += time.perf_counter() - t
        chunks["n"] += 1
run.compute_chunk = _timed
from granchain.cli import main
rc = main(sys.argv[1:])
if CudaBackend is not None:
    instances += [b for b in getattr(backends, "_BACKENDS", {}).values() if isinstance(b, CudaBackend) and b not in instances]
timings = [t for b in instances for t in getattr(b, "timings", [])]
print("BENCH_REPRODUCE " + json.dumps({"rc": rc, "kernel_s": sum(t["kernel_s"] for t in timings), "batches": len(timings),
      "realizations": sum(t["realizations"] for t in timings), "chunk_s": chunks["s"], "chunks": chunks["n"],
      "in_process_s": time.perf_counter() - T0}), flush=True)
sys.exit(rc)
'''


def part_reproduce(run: Run) -> None:
    s = run.sizes
    helptext = subprocess.run([sys.executable, "-m", "granchain", "reproduce", "--help"], capture_output=True, text=True,
                              cwd=ROOT).stdout
    has_backend = "--backend" in helptext
    if not has_backend and not run.smoke:
        run.line("4 reproduce", "skipped: `granchain reproduce --help` has no --backend option yet")
        return
    # The smoke run cannot afford 8 ensembles on the simulator: it checks the driver with the CPU backend.
    backend = "cpu" if run.smoke else "cuda"
    argv = ["reproduce", *(["--backend", backend] if has_backend else []), *s.reproduce, "--quiet"]
    reserve = 25.0  # part 5 and the summary
    if not run.fits("4 reproduce", 60.0 + reserve):
        return
    with tempfile.TemporaryDirectory(prefix="bench-gpu-") as tmp:
        cmd = [sys.executable, "-c", DRIVER, *argv, "--out", str(Path(tmp) / "out")]
        t0 = time.perf_counter()
        try:
            p = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=max(30.0, run.left() - reserve))
        except subprocess.TimeoutExpired:
            run.line("4 reproduce error", f"`granchain {' '.join(argv)}` killed after {time.perf_counter() - t0:.0f} s (budget)")
            return
        wall = time.perf_counter() - t0
    record = next((json.loads(x.split(" ", 1)[1]) for x in p.stdout.splitlines() if x.startswith("BENCH_REPRODUCE ")), None)
    if p.returncode != 0 or record is None:
        run.line("4 reproduce error", f"`granchain {' '.join(argv)}` exited {p.returncode}: {(p.stderr or p.stdout)[-600:]}")
        return
    what = "" if has_backend else " (no --backend option: the default backend)"
    if run.smoke:
        what += " [smoke: the CPU backend, the driver's plumbing only]"
    line = (f"`granchain {' '.join(argv)}`{what}: wall {wall:.1f} s (subprocess: start, compilation, figures, report); "
            f"inside compute_chunk {record['chunk_s']:.1f} s over {record['chunks']} chunks")
    if record["batches"]:
        line += f"; CUDA integration {record['kernel_s']:.2f} s ({record['batches']} batches, {record['realizations']:,} realisations)"
        run.results["reproduce integration"] = (record["kernel_s"], "CUDA timings")
    else:
        line += "; no CUDA backend timings recorded"
    run.line("4 reproduce", line)
    if not run.smoke:
        run.results["reproduce wall"] = (wall, "subprocess wall")


def part_agree(run: Run) -> None:
    s = run.sizes
    n = s.agree
    for chains in ("decorated", "effective"):
        gpu, gwhere = gpu_reference(run, chains, n)
        cpu = run.data.get(("cpu", chains))
        cwhere = "part 3's 1-thread run"
        if cpu is None or cpu.sizes["realization"] < n:
            cpu, cwhere = ensemble(run, n, 0, chains), f"a new run of {n}"
        gv, gt, gok = peaks(gpu, n)
        cv, ct, cok = peaks(cpu, n)
        ok, which = compared(gok, cok, gv, cv)
        with np.errstate(divide="ignore", invalid="ignore"):
            dv = np.abs(gv / cv - 1.0)[ok]
        dt = np.abs(gt - ct)[ok]
        inside = np.isfinite(dv) & np.isfinite(dt)
        within = ((dv <= PEAK_V_RTOL) & (dt <= PEAK_T_ATOL))[inside]
        within2 = ((dv <= 2 * PEAK_V_RTOL) & (dt <= 2 * PEAK_T_ATOL))[inside]
        fraction = (lambda w: f"{w.mean():.4f}" if w.size else "n/a (no peaks)")
        run.line("5 agree", f"{chains} N={s.n_large}, realisations 0..{n - 1} (GPU: {gwhere}, {integrator_of(gpu)}; CPU: "
                            f"{cwhere}, {integrator_of(cpu)}; {which}): "
                            f"largest relative peak-velocity difference {worst(dv):.2e}, largest peak-time difference "
                            f"{worst(dt):.2e} ({worst(dt[:, :-1]):.2e} without the free end); within the contract "
                            f"(1e-6 relative, 1e-5) {fraction(within)} of the peaks, within twice it {fraction(within2)}{run.tag}")


def part_damped(run: Run) -> None:
    import granchain as gc

    law = gc.Viscoelastic.from_restitution(0.9)
    real_contacts(run, "6 damped", gc.RandomDecorated(run.sizes.n_large, contact=law),
                  f"decorated N={run.sizes.n_large}, {law.label()} (restitution 0.9)")


def part_loaded(run: Run) -> None:
    import granchain as gc

    real_contacts(run, "7 loaded", gc.RandomDecorated(run.sizes.n_large, static_force=LOAD, wall=True),
                  f"decorated N={run.sizes.n_large}, precompressed F0 = {LOAD:g}, wall")


def part_yielding(run: Run) -> None:
    import granchain as gc

    real_contacts(run, "8 yielding", gc.RandomDecorated(run.sizes.n_large, contact=gc.ElasticPlastic(YIELD_SPEED)),
                  f"decorated N={run.sizes.n_large}, Thornton's yielding contacts (yield speed {YIELD_SPEED:g})")


def real_contacts(run: Run, key: str, family, label: str) -> None:
    """Parts 6, 7 and 8: ``family`` (a chain of real contacts) on the GPU backend and on the CPU's 16 threads, each with
    its default method, ``run.sizes.damped`` realisations: the wall times, their ratio, and the largest differences
    of the two backends' peaks and of the dissipated energy (damped; yielding: the plastic work) or the wall's peak
    force (against a wall)."""
    import numba

    s = run.sizes
    R = s.damped
    if not run.fits(key, 40.0):
        return
    part = key.split()[0]
    backend = gpu_backend(s.reference, run.stub)
    t0 = time.perf_counter()
    ensemble(run, s.warmup, 0, "decorated", backend=backend, chunk_size=s.warmup, family=family)
    run.line(f"{part} compile", f"{label}: warm-up of {s.warmup} realisations {time.perf_counter() - t0:.2f} s{run.tag}")
    gpu, kernel, wall, timings = gpu_run(run, backend, "decorated", R, family=family)
    threads = max(t for t in s.threads if t <= numba.config.NUMBA_NUM_THREADS)  # (16 on the device machine)
    ensemble(run, 2 * threads, 0, "decorated", threads=threads, family=family)  # (compiles the CPU's kernel for it)
    t0 = time.perf_counter()
    cpu = ensemble(run, R, 0, "decorated", threads=threads, family=family)
    cpu_wall = time.perf_counter() - t0
    run.line(key, f"{label}: GPU L={s.reference} {R:,} realisations ({integrator_of(gpu)}): integration {kernel:.3f} s, "
                  f"wall {wall:.3f} s; CPU {threads} threads ({integrator_of(cpu)}): wall {cpu_wall:.3f} s; "
                  f"CPU-{threads} wall / GPU wall = {cpu_wall / wall:.2f}x{run.tag}")
    gv, gt, gok = peaks(gpu)
    cv, ct, cok = peaks(cpu)
    ok, which = compared(gok, cok, gv, cv)
    name = "dissipated_energy" if family.contact is not None else "peak_wall_force"
    with np.errstate(divide="ignore", invalid="ignore"):
        dv = np.abs(gv / cv - 1.0)[ok]
        dq = np.abs(gpu[name].isel(chain=0).values / cpu[name].isel(chain=0).values - 1.0)[ok]
    dt = np.abs(gt - ct)[ok]
    what = (f"the dissipated energy {worst(dq):.2e} (mean dissipated {float(np.nanmean(cpu[name].values)):.4g} of the "
            f"impulse's 0.5)" if name == "dissipated_energy" else
            f"the wall's peak force {worst(dq):.2e} (mean {float(np.nanmean(cpu[name].values)):.4g})")
    run.line(f"{part} agree", f"{label} ({which}): largest relative peak-velocity difference {worst(dv):.2e}, largest "
                              f"peak-time difference {worst(dt):.2e}, largest relative difference of {what}{run.tag}")


def summary(run: Run) -> None:
    run.line("summary", f"targets ({'smoke run: sizes too small to judge' if run.smoke else 'full run'}; device {run.device}; "
                        f"{os.cpu_count()} CPUs){run.tag}")
    for key, (op, limit, unit) in TARGETS.items():
        got = run.results.get(key)
        if got is None:
            run.line("summary", f"{key:<26} {op} {limit:g} {unit}: MISSING (its part failed or was skipped)")
            continue
        value, how = got
        ok = value <= limit if op == "<=" else value >= limit
        run.line("summary", f"{key:<26} {op} {limit:g} {unit}: {'PASS' if ok else 'FAIL'} {value:.3g} {unit} ({how})")
    run.line("summary", f"total {run.elapsed():.1f} s")


PARTS = {1: ("gpu", part_gpu), 2: ("peer", part_peer), 3: ("cpu", part_cpu), 4: ("reproduce", part_reproduce),
         5: ("agree", part_agree), 6: ("damped", part_damped), 7: ("loaded", part_loaded), 8: ("yielding", part_yielding)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--smoke", action="store_true", help="tiny sizes (N = 4, a few realisations) for the CUDA simulator: "
                                                         "checks the script, measures nothing")
    ap.add_argument("--stub", action="store_true", help="a stand-in for the CUDA backend (the CPU ensemble, timed): "
                                                        "automatic with --smoke where granchain.backends.cuda is missing")
    ap.add_argument("--parts", default="1,2,3,4,5,6,7,8", help="which parts to run, comma-separated (default all: "
                                                            "1,2,3,4,5,6,7,8)")
    ap.add_argument("--layouts", default=None, help="part 1's layouts, comma-separated: threads per chain, then "
                                                    "optionally /shuffle or /shared, /REGS (a register cap) and "
                                                    "/butterfly (no warp votes), /n (the exponent compiled in); "
                                                    "default 32,32/n,32/n/200,32/butterfly,32/168,32/shared,1")
    ap.add_argument("--budget", type=float, default=None, help="seconds the run may take; parts that no longer fit are "
                                                               "skipped (default 330 full, 170 smoke)")
    args = ap.parse_args(argv)
    try:
        parts = tuple(sorted({int(p) for p in args.parts.split(",") if p.strip()}))
    except ValueError:
        ap.error(f"--parts must be part numbers 1-8 separated by commas, got {args.parts!r}")
    if not parts or any(p not in PARTS for p in parts):
        ap.error(f"--parts must be part numbers 1-8 separated by commas, got {args.parts!r}")
    sizes = SMOKE if args.smoke else FULL
    if args.budget is not None:
        if not args.budget > 0:
            ap.error(f"--budget must be a positive number of seconds, got {args.budget}")
        sizes = replace(sizes, budget_s=args.budget)
    if args.layouts is not None:
        try:
            layouts = tuple(x.strip() for x in args.layouts.split(",") if x.strip())
            for x in layouts:
                parse_layout(x)
        except ValueError:
            ap.error(f"--layouts must be layouts such as 32,32/shared,64/128,32/butterfly, got {args.layouts!r}")
        if not layouts:
            ap.error("--layouts needs at least one layout")
        sizes = replace(sizes, layouts=layouts)
    stub = args.stub
    if not stub:
        try:
            import granchain.backends.cuda  # noqa: F401
        except ImportError as exc:
            if args.smoke:
                stub = True
                print(f"[setup] granchain.backends.cuda is not importable ({exc}): the stub stands in", flush=True)
            else:
                print(f"[setup] granchain.backends.cuda is not importable ({exc}): the GPU parts will fail; "
                      f"--stub checks the script without it", flush=True)
    import granchain as gc
    import numba

    run = Run(sizes, stub, args.smoke, parts)
    run.device = device_name()
    run.cores, topology = cpu_topology()
    rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=ROOT).stdout.strip()
    run.line("machine", f"device {run.device}; {os.cpu_count()} CPUs (Numba threads {numba.config.NUMBA_NUM_THREADS}); "
                        f"{platform.machine()}, Python {platform.python_version()}, numba {numba.__version__}, granchain "
                        f"{gc.__version__} ({rev or 'no git'}); load average {os.getloadavg()[0]:.2f}; CPUs: {topology}; "
                        f"{'smoke' if args.smoke else 'full'} run, budget {sizes.budget_s:.0f} s; GPU backend: "
                        f"{'stub' if stub else 'granchain.backends.cuda.CudaBackend'}")
    for p in parts:
        name, fn = PARTS[p]
        try:
            fn(run)
        except Exception as exc:  # noqa: BLE001 (a failing part must leave the others their time)
            run.line(f"{p} {name} error", f"{type(exc).__name__}: {exc}")
            traceback.print_exc(limit=6)
    summary(run)
    return 0


if __name__ == "__main__":
    sys.exit(main())
