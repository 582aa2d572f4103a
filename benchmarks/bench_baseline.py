"""This tree against a baseline revision (default: the granchain 0.4.0 release), measured in the same run.

A reorganisation of the internals promises the same results at the same speed. This script checks
both promises against the baseline revision (``--baseline``, default ``df53015``, the 0.4.0 release
commit from this repository's history), checked out with ``git worktree add --detach`` into a
temporary directory that is removed at the end (also on an error or Ctrl-C). The current tree is
the checkout this script lives in, as it is on disk (uncommitted changes included: the header says
which files under granchain/ differ from HEAD, and a note at the end whether any changed during
the run); ``--current REV`` measures a commit instead, from a second worktree (a stable snapshot
while someone edits the checkout, or two commits against each other to find which one costs).

Each side runs in its own long-lived worker subprocess with ``PYTHONPATH=<tree>``, so that
``import granchain`` resolves to that tree (the editable install's import hook comes after
PYTHONPATH); each worker prints the ``granchain.__file__`` and ``__version__`` it imported. Both
workers get an empty Numba cache of their own, so the first use of the kernels (the warm-up, never
timed with the workloads) is a compilation on both sides and its time is comparable.

Workloads, all through the public API that both sides share:

1. ``simulate``: CPU time per realisation on random decorated chains, N = 26 and N = 101 (the same
   realisations on both sides, seed 0, ``default_time_grid(N)``), with ``RKN4.relaxed(1e-5, 1e-8)``
   (0.4.0's ensemble default for decorated chains), ``RKN4.windowed(1e-5, 1e-8)`` and the exact
   ``DP5()``: the kernels' per-step speed, as bench_window.py measures it;
2. ``run_ensemble`` at N = 26, decorated and effective chains, 0.4.0's default integrators (named on
   both sides; the averaged pulse on the whole grid) and threads, in memory: realisations per second
   (wall), as bench_ensemble.py measures it;
3. the paper's run reduced: ``granchain reproduce``'s ensembles (N = 6, 11, 16, 26, both chains,
   U[0.01, 0.4], seed 1000 * 2026 + N, default time grid and chunk size, 0.4.0's integrators as in 2.) at ``--realizations``
   realisations each, in memory: wall time;
4. ``import granchain`` in a fresh interpreter: wall time of the import statement.

Timing under noise: the two sides take turns workload by workload, round after round, the side
that goes first swapping every round (A B, B A, A B, ...), so a slow spell or a warm cache favours
neither; each side keeps its best (for workload 1 each realisation's best over the rounds and over ``--passes``
passes within each round, summed: a realisation takes milliseconds, and one pass per round left a workload's
verdict to five samples per realisation; N = 26 RKN4.windowed read 0.86-0.94x in three such runs where
ten fresh processes per tree, three passes each, read 0.998x).
Every round runs in fresh worker processes (loading the kernels from their side's cache, untimed):
the same code timed in separate processes differed by 10-20 % on a shared 2-core machine, more than
between rounds of one process, so a side's best is over as many processes as rounds. Workload 1
runs each of its cases in a process of its own, which loads that case's kernel alone (untimed).
The ratio printed is current speed / baseline speed (> 1: the current tree is faster), PASS at
>= 0.97. The results of every workload are compared between the sides (peak velocities and times,
grid velocities, step counts, every variable of the ensembles' Datasets): ``bitwise equal`` or the
largest difference.

    python benchmarks/bench_baseline.py                    # about 20 minutes on 2 shared cores, half a minute of it compiling
    python benchmarks/bench_baseline.py --quick            # smoke run, 2-3 minutes (mostly compiling; numbers not meaningful)
    python benchmarks/bench_baseline.py --baseline 3cd9c6b --current 70456b5 --rounds 3   # one commit's cost
"""

from __future__ import annotations

import argparse
import datetime
import hashlib
import json
import os
import platform
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

#: granchain 0.4.0 as released (the last commit before the internals were reorganised).
BASELINE_REV = "df53015"
#: Current speed / baseline speed below this is a MISS: the promise is "no loss beyond noise".
TARGET = 0.97
SEED = 0
PAPER_SIZES = (6, 11, 16, 26)
PAPER_SEED = 2026  # granchain reproduce's default; ensemble N uses 1000 * seed + N
ROOT = Path(__file__).resolve().parents[1]


# ----------------------------------------------------------------------------------------------
# Worker: runs inside one side's subprocess, where ``import granchain`` is that side's tree.
# ----------------------------------------------------------------------------------------------

def _integrator(gc, name):
    """The integrators of workload 1, built from each side's own classes at 0.4.0's tolerances (RKN4's
    default rtol is tighter since: the same work must be timed on both sides)."""
    return {"default": lambda: gc.RKN4.relaxed(1e-5, 1e-8), "windowed": lambda: gc.RKN4.windowed(1e-5, 1e-8),
            "exact": gc.DP5}[name]()


def _ensemble_settings(gc, chains=("decorated", "effective")) -> dict:
    """run_ensemble's keywords for the ensembles of 0.4.0's defaults on either side: its integrators, named,
    and the averaged pulse on the whole grid where the side knows averaged-pulse windows (today's defaults
    run the trailing window at tighter tolerances: other work, timed by bench_reproduce.py and
    bench_scaling.py)."""
    import inspect

    old = {"decorated": gc.RKN4.relaxed(1e-5, 1e-8), "effective": gc.DP5.relaxed(5e-8, 5e-11)}
    kw = {"integrator": {kind: old[kind] for kind in chains}}  # 0.4.0 refuses a kind the run does not compute
    if "pulse_window" in inspect.signature(gc.run_ensemble).parameters:
        kw["pulse_window"] = "full"
    return kw


def _digest(arrays: dict) -> str:
    h = hashlib.sha256()
    for key in sorted(arrays):
        h.update(key.encode())
        h.update(np.ascontiguousarray(arrays[key]).tobytes())
    return h.hexdigest()[:16]


def _dataset_arrays(ds, prefix="") -> dict:
    """Every data variable of an ensemble Dataset (values as stored: they must match bit for bit)."""
    return {prefix + name: np.asarray(var.values) for name, var in ds.data_vars.items()}


def _work_simulate(gc, task):
    n, name, count = task["n"], task["integrator"], task["realizations"]
    grid = gc.default_time_grid(n)
    chains = [gc.random_decorated(n, seed=SEED, realization=i) for i in range(count)]  # built outside the timing
    integ = _integrator(gc, name)
    gc.simulate(chains[0], integ, t_grid=grid)  # untimed: loads the kernel from the cache into this fresh process
    cpu, results = [np.inf] * count, [None] * count
    for _ in range(task.get("passes", 1)):  # each realisation's best over the passes (the same result each time)
        for i, chain in enumerate(chains):
            c0 = time.process_time()  # simulate is serial: the process's CPU time is the kernel's
            r = gc.simulate(chain, integ, t_grid=grid)
            cpu[i] = min(cpu[i], time.process_time() - c0)
            results[i] = r
    arrays = {field: np.stack([np.asarray(getattr(r, field)) for r in results])
              for field in ("peak_velocity", "peak_time", "velocity", "t_end", "energy_error", "n_steps", "n_evaluations")}
    arrays["status"] = np.array([int(r.status) for r in results])
    return {"cpu": cpu, "steps": float(np.mean(arrays["n_steps"])), "failed": int(np.sum(arrays["status"] != 0)),
            "label": repr(integ)}, arrays


def _work_ensemble(gc, task):
    t0, c0 = time.perf_counter(), time.process_time()
    ds = gc.run_ensemble(task["n"], realizations=task["realizations"], seed=SEED, chains=task["chain"], progress=False,
                         **_ensemble_settings(gc, ("decorated", "effective") if task["chain"] == "both" else (task["chain"],)))
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return {"wall": wall, "cpu": cpu, "failed": int((ds["status"] != 0).sum())}, _dataset_arrays(ds)


def _work_paper(gc, task):
    count = task["realizations"]
    chunk = max(50, min(1000, -(-count // 8)))  # as granchain reproduce chooses it
    arrays, walls, failed = {}, {}, 0
    t0, c0 = time.perf_counter(), time.process_time()
    for n in PAPER_SIZES:
        t1 = time.perf_counter()
        ds = gc.run_ensemble(n, gc.Uniform(0.01, 0.4), count, 1000 * PAPER_SEED + n, "both", t_grid=gc.default_time_grid(n),
                             chunk_size=chunk, progress=False, **_ensemble_settings(gc))
        walls[n] = time.perf_counter() - t1
        failed += int((ds["status"] != 0).sum())
        arrays.update(_dataset_arrays(ds, prefix=f"N{n}/"))
    return {"wall": time.perf_counter() - t0, "cpu": time.process_time() - c0, "walls": walls, "failed": failed,
            "chunk": chunk}, arrays


def worker() -> None:
    """Answer one JSON command per stdin line with one JSON line; anything else printed goes to stderr."""
    replies = sys.stdout
    sys.stdout = sys.stderr
    import numba

    import granchain as gc

    jobs = {"simulate": _work_simulate, "ensemble": _work_ensemble, "paper": _work_paper}
    for line in sys.stdin:
        task = json.loads(line)
        op = task["op"]
        if op == "quit":
            break
        if op == "hello":
            out = {"file": gc.__file__, "version": gc.__version__, "numba": numba.__version__,
                   "threads": numba.get_num_threads(), "decorated_default": repr(gc.ensemble_integrator("decorated")),
                   "effective_default": repr(gc.ensemble_integrator("effective"))}
        elif op == "warmup":
            # First use of every kernel the workloads call: Numba compiles into the empty cache here.
            t0 = time.perf_counter()
            chain = gc.random_decorated(6, seed=SEED, realization=0)
            for name in ("default", "windowed", "exact"):
                gc.simulate(chain, _integrator(gc, name), t_grid=gc.default_time_grid(6))
            gc.run_ensemble(6, realizations=4, seed=SEED, chains="both", chunk_size=4, progress=False)
            out = {"seconds": time.perf_counter() - t0, "layer": numba.threading_layer()}
        else:
            out, arrays = jobs[op](gc, task)
            out["digest"] = _digest(arrays)
            if task.get("save"):
                np.savez(task["save"], **arrays)
        replies.write(json.dumps(out) + "\n")
        replies.flush()


# ----------------------------------------------------------------------------------------------
# Driver
# ----------------------------------------------------------------------------------------------

def git(*args) -> str:
    # rstrip only: ``status --porcelain`` lines start with a meaningful space
    return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True, check=True).stdout.rstrip()


def tree_state() -> str:
    """A hash of every source file under granchain/ as on disk (to notice edits during the run, new files included)."""
    h = hashlib.sha256()
    for path in sorted((ROOT / "granchain").rglob("*.py")):
        h.update(str(path.relative_to(ROOT)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()


def load() -> str:
    return "load average " + " ".join(f"{x:.2f}" for x in os.getloadavg())


class Side:
    """One tree and its worker subprocess."""

    def __init__(self, name: str, tree: Path, scratch: Path):
        self.name, self.tree = name, tree
        self.env = dict(os.environ, PYTHONPATH=str(tree), NUMBA_CACHE_DIR=str(scratch / f"numba-cache-{name}"))
        self.scratch = scratch
        self.log = open(scratch / f"worker-{name}.log", "a")  # noqa: SIM115 (the worker outlives any block; close() closes it)
        self.proc = subprocess.Popen([sys.executable, str(Path(__file__).resolve()), "--worker"], cwd=tree, env=self.env,
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self.log, text=True)

    def ask(self, **task) -> dict:
        self.send(**task)
        return self.receive()

    def send(self, **task):
        try:
            self.proc.stdin.write(json.dumps(task) + "\n")
            self.proc.stdin.flush()
        except BrokenPipeError:
            self.stopped()

    def receive(self) -> dict:
        line = self.proc.stdout.readline()
        if not line:
            self.stopped()
        return json.loads(line)

    def stopped(self):
        """The worker has exited (an import error, say): raise with the end of what it wrote to stderr."""
        self.proc.wait()
        self.log.flush()
        tail = Path(self.log.name).read_text()[-3000:]
        raise RuntimeError(f"the {self.name} worker ({self.tree}) stopped:\n{tail}")

    def import_seconds(self) -> float:
        """Wall time of ``import granchain`` in a fresh interpreter of this side."""
        code = "import time; t0 = time.perf_counter(); import granchain; print(time.perf_counter() - t0)"
        out = subprocess.run([sys.executable, "-c", code], cwd=self.tree, env=self.env, capture_output=True, text=True,
                             check=True).stdout
        return float(out.strip().splitlines()[-1])

    def close(self, interrupted=False):
        """Let the worker quit; on an error or Ctrl-C kill it at once (it may be busy for minutes)."""
        if self.proc.poll() is None and interrupted:
            self.proc.kill()
            self.proc.wait()
        elif self.proc.poll() is None:
            try:
                self.proc.stdin.write(json.dumps({"op": "quit"}) + "\n")
                self.proc.stdin.flush()
                self.proc.wait(timeout=10)
            except (OSError, subprocess.TimeoutExpired):
                self.proc.kill()
                self.proc.wait()
        self.log.close()


def compare(path_a: Path, path_b: Path) -> str:
    """``bitwise equal`` or where the two sides' results differ (and by how much)."""
    with np.load(path_a) as a, np.load(path_b) as b:
        only = sorted(set(a.files) ^ set(b.files))
        diffs = []
        for key in sorted(set(a.files) & set(b.files)):
            x, y = a[key], b[key]
            if x.shape != y.shape or x.dtype != y.dtype:
                diffs.append(f"{key}: {x.dtype}{x.shape} vs {y.dtype}{y.shape}")
            elif x.tobytes() != y.tobytes():
                if x.dtype.kind in "fiub":
                    xf, yf = x.astype(float), y.astype(float)
                    differ = ~((xf == yf) | (np.isnan(xf) & np.isnan(yf)))
                    d = np.abs(xf - yf)[differ]
                    diffs.append(f"{key}: {differ.sum()} of {x.size} differ, max |diff| {np.nanmax(d) if d.size else np.nan:.2e}")
                else:
                    diffs.append(f"{key}: differ")
    text = "bitwise equal" if not diffs else "DIFFERENT: " + "; ".join(diffs)
    if only:
        text += f" (on one side only, not compared: {', '.join(only)})"
    return text


def ratio_line(label: str, base: float, cur: float, unit: str, results: str, faster_is_smaller=True,
               verdict=True) -> tuple[str, float]:
    """One table row; ``base``/``cur`` are times (smaller = faster) or rates (larger = faster)."""
    speed = base / cur if faster_is_smaller else cur / base
    mark = ("PASS" if speed >= TARGET else "MISS") if verdict else "    "
    return f"   {label:<44s} {base:10.3f} {cur:10.3f} {unit:<10s} {speed:6.3f}x  {mark}  {results}".rstrip(), speed


def _interrupt(signum, frame):
    raise KeyboardInterrupt  # a SIGTERM too ends in main's ``finally``, which removes the worktree


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog=__doc__.split("\n\n", 1)[1],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--baseline", default=BASELINE_REV, help=f"git revision to compare with (default {BASELINE_REV}: granchain 0.4.0)")
    p.add_argument("--current", default=None,
                   help="git revision to measure instead of the working tree (a second worktree: a stable snapshot "
                        "while someone edits the checkout)")
    p.add_argument("--rounds", type=int, default=5, help="alternating rounds; each side keeps its best (default 5)")
    p.add_argument("--realizations", type=int, default=2000,
                   help="realisations per N and chain of the paper's run (default 2000; the paper has 30000)")
    p.add_argument("--simulate", default="40,8", help="realisations simulated at N = 26 and at N = 101 (default 40,8)")
    p.add_argument("--passes", type=int, default=3,
                   help="passes over workload 1's realisations in each round, each realisation keeping its best "
                        "(default 3: a realisation takes milliseconds, so one pass per round left the best of 5 "
                        "samples to a few lucky ones)")
    p.add_argument("--decorated", type=int, default=400, help="decorated realisations of the ensemble workload (default 400)")
    p.add_argument("--effective", type=int, default=4000, help="effective realisations of the ensemble workload (default 4000)")
    p.add_argument("--imports", type=int, default=10, help="fresh interpreters per side timing the import (default 10)")
    p.add_argument("--quick", action="store_true", help="smoke run: 2 rounds, small workloads (numbers not meaningful)")
    p.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker:
        worker()
        return 0
    if args.quick:
        args.rounds, args.realizations, args.simulate, args.decorated, args.effective, args.imports = 2, 100, "4,1", 50, 500, 3
        args.passes = 1
    n26, n101 = (int(s) for s in args.simulate.split(","))

    signal.signal(signal.SIGTERM, _interrupt)
    rev = git("rev-parse", "--short", f"{args.baseline}^{{commit}}")
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    if args.current is None:
        head = git("rev-parse", "--short", "HEAD")
        dirty = [line[3:] for line in git("status", "--porcelain", "--", "granchain").splitlines() if line.strip()]
        current = (f"the working tree {ROOT} (HEAD {head}; {len(dirty)} files under granchain/ differ from HEAD"
                   + (f": {', '.join(dirty[:6])}{', ...' if len(dirty) > 6 else ''})" if dirty else ")"))
    else:
        cur_rev = git("rev-parse", "--short", f"{args.current}^{{commit}}")
        current = f"{cur_rev} (a git worktree)"
    state = tree_state()
    print(f"bench_baseline: current = {current} vs baseline = {rev}" + (f" ({args.baseline})" if args.baseline != rev else "")
          + f" (a git worktree), {now}")
    print(f"machine: {platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}; {load()} (before)")
    print(f"timing: {args.rounds} rounds, each in fresh processes, the sides alternating workload by workload (the first side "
          f"swapping every round), best per side; speed ratio = current/baseline (> 1: current faster), PASS at >= {TARGET}", flush=True)

    scratch = Path(tempfile.mkdtemp(prefix="granchain-bench-baseline-"))
    worktrees, sides = [], {}
    try:
        trees = {"baseline": rev, "current": None if args.current is None else cur_rev}
        for name, commit in trees.items():
            if commit is None:
                trees[name] = ROOT
                continue
            trees[name] = scratch / name
            subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(trees[name]), commit],
                           capture_output=True, check=True)
            worktrees.append(trees[name])
        sides = {name: Side(name, tree, scratch) for name, tree in trees.items()}
        for side in sides.values():
            info = side.ask(op="hello")
            print(f"{side.name:>8s}: granchain {info['version']} from {info['file']}, numba {info['numba']}, "
                  f"{info['threads']} threads; decorated default {info['decorated_default']}")
            if not info["file"].startswith(str(side.tree)):
                raise RuntimeError(f"the {side.name} worker imported granchain from {info['file']}, not from {side.tree}")
        # Both sides compile at once (Numba compiles on one core each): it halves the wait on 2 cores.
        for side in sides.values():
            side.send(op="warmup")
        first = {name: side.receive() for name, side in sides.items()}
        print("first use (warm-up, both sides at once: Numba compiles every kernel the workloads call into an empty cache; "
              "one measurement, not timed with the workloads): " + ", ".join(f"{n} {w['seconds']:.1f} s" for n, w in first.items())
              + f"; threading layer {first['current']['layer']}", flush=True)
        report = measure(args, sides, scratch, n26, n101)
    finally:
        interrupted = sys.exc_info()[0] is not None
        for side in sides.values():
            side.close(interrupted)
        failed = [w for w in worktrees
                  if subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(w)], check=False,
                                    capture_output=True).returncode]
        shutil.rmtree(scratch, ignore_errors=True)
        if failed:  # only then: prune also drops other stale worktree entries of the repository
            subprocess.run(["git", "-C", str(ROOT), "worktree", "prune"], check=False, capture_output=True)

    print(report)
    print(f"machine after the run: {load()}")
    if args.current is None and tree_state() != state:
        print("NOTE  granchain/ in the working tree changed on disk during the run: the current worker kept the modules "
              "it had imported, the fresh interpreters of workload 4 saw the new files")
    return 0


def measure(args, sides, scratch, n26, n101) -> str:
    """Run the rounds; return the report (the table and the verdicts)."""
    order = ["baseline", "current"]
    sim_cases = [(n, name, count) for n, count in ((26, n26), (101, n101)) if count > 0
                 for name in ("default", "windowed", "exact")]
    ens_cases = [("decorated", args.decorated), ("effective", args.effective)]
    sim = {}   # (case, side) -> per-realisation best CPU seconds
    ens = {}   # (case, side) -> best wall seconds
    cpu_best = {}  # (workload key, side) -> best CPU seconds of the wall-timed workloads
    paper = {}  # side -> best reply
    info, digests = {}, {}

    def run(key, side, worker=None, **task):
        task["save"] = str(scratch / f"{key}-{side}.npz") if (key, side) not in info else None
        out = (worker or sides[side]).ask(**task)
        info.setdefault((key, side), out)
        digests.setdefault((key, side), set()).add(out["digest"])
        return out

    for rnd in range(args.rounds):
        print(f"round {rnd + 1}/{args.rounds}: first {order[0]}, {load()}", file=sys.stderr, flush=True)
        if rnd > 0:  # fresh processes, their kernels loaded from the cache before any timing
            for name in order:
                old = sides[name]
                old.close()
                sides[name] = Side(name, old.tree, old.scratch)
                sides[name].send(op="warmup")
            for name in order:
                sides[name].receive()
        for case in sim_cases:
            n, name, count = case
            for side in order:
                # A process of its own per case and side, which loads that one kernel: the best over rounds is
                # then over as many process layouts as rounds for every case, not over one per round shared
                # by all six cases (after the warm-up's ensembles and every other kernel).
                alone = Side(side, sides[side].tree, scratch)
                try:
                    cpu = run(f"sim-{n}-{name}", side, alone, op="simulate", n=n, integrator=name, realizations=count,
                              passes=args.passes)["cpu"]
                finally:
                    alone.close()
                old = sim.get((case, side))
                sim[case, side] = cpu if old is None else [min(a, b) for a, b in zip(old, cpu)]
        for case in ens_cases:
            for side in order:
                out = run(f"ens-{case[0]}", side, op="ensemble", n=26, chain=case[0], realizations=case[1])
                ens[case, side] = min(ens.get((case, side), np.inf), out["wall"])
                cpu_best[f"ens-{case[0]}", side] = min(cpu_best.get((f"ens-{case[0]}", side), np.inf), out["cpu"])
        for side in order:
            out = run("paper", side, op="paper", realizations=args.realizations)
            cpu_best["paper", side] = min(cpu_best.get(("paper", side), np.inf), out["cpu"])
            if side not in paper or out["wall"] < paper[side]["wall"]:
                paper[side] = out
        order.reverse()

    imports = {"baseline": [], "current": []}
    order = ["baseline", "current"]
    for _ in range(args.imports):
        for side in order:
            imports[side].append(sides[side].import_seconds())
        order.reverse()

    def results(key):
        text = compare(scratch / f"{key}-baseline.npz", scratch / f"{key}-current.npz")
        unstable = [s for s in ("baseline", "current") if len(digests[key, s]) > 1]
        if unstable:
            text += f"; NOT REPRODUCIBLE across rounds on: {', '.join(unstable)}"
        return text

    def cpu_line(key):
        base, cur = cpu_best[key, "baseline"], cpu_best[key, "current"]
        return (f"   {'':<6s}CPU seconds, all threads (best of {args.rounds}; a busy machine inflates them less than wall "
                f"time; not the verdict): baseline {base:.3f}, current {cur:.3f}, speed {base / cur:.3f}x")

    lines, speeds = [], {}
    head = f"   {'':<44s} {'baseline':>10s} {'current':>10s} {'':<10s} {'speed':>7s}"
    labels = {"default": "RKN4.relaxed(1e-5)", "windowed": "RKN4.windowed(1e-5)", "exact": "DP5() (exact)"}
    lines.append(f"\n1. simulate: CPU-ms per realisation (seed 0, realisations 0..{n26 - 1} at N = 26, 0..{n101 - 1} at N = 101, "
                 f"default time grid; per realisation the best of {args.rounds} rounds x {args.passes} passes, summed)")
    lines.append(head)
    for case in sim_cases:
        n, name, count = case
        key = f"sim-{n}-{name}"
        base, cur = (1000 * sum(sim[case, s]) / count for s in ("baseline", "current"))
        steps = info[key, "current"]["steps"]
        line, speeds[f"simulate N = {n} {labels[name]}"] = ratio_line(
            f"N = {n:3d}  {labels[name]:<16s} {steps:8.0f} steps", base, cur, "CPU-ms", results(key))
        lines.append(line)
    lines.append(f"\n2. run_ensemble at N = 26, 0.4.0's default integrators, threads and chunk size, in memory: realisations/s "
                 f"(wall, best of {args.rounds})")
    lines.append(head)
    for case in ens_cases:
        key = f"ens-{case[0]}"
        base, cur = (case[1] / ens[case, s] for s in ("baseline", "current"))
        line, speeds[f"run_ensemble {case[0]}"] = ratio_line(f"{case[0]:<9s} {case[1]:6d} realisations", base, cur, "realis./s",
                                                             results(key), faster_is_smaller=False)
        lines += [line, cpu_line(key)]
    chunk = info["paper", "current"]["chunk"]
    lines.append(f"\n3. the paper's run reduced: N = {', '.join(map(str, PAPER_SIZES))}, both chains, {args.realizations} "
                 f"realisations each (the paper: 30000), seed 1000 * {PAPER_SEED} + N, chunk size {chunk}, in memory: "
                 f"wall seconds (best of {args.rounds})")
    lines.append(head)
    for n in PAPER_SIZES:
        base, cur = (paper[s]["walls"][str(n)] for s in ("baseline", "current"))
        lines.append(ratio_line(f"N = {n:2d} (in the best round)", base, cur, "s", "", verdict=False)[0])
    line, speeds["paper's run"] = ratio_line("whole run", paper["baseline"]["wall"], paper["current"]["wall"], "s", results("paper"))
    lines += [line, cpu_line("paper")]
    lines.append(f"\n4. import granchain in a fresh interpreter: wall ms of the import statement (best of {args.imports} "
                 f"per side, alternating)")
    lines.append(head)
    line, speeds["import granchain"] = ratio_line("import granchain", 1000 * min(imports["baseline"]),
                                                  1000 * min(imports["current"]), "ms", "")
    lines.append(line)
    failed = {s: sum(v["failed"] for (k, side), v in info.items() if side == s) for s in ("baseline", "current")}
    lines.append(f"\nfailed realisations (first round, all workloads): baseline {failed['baseline']}, current {failed['current']}")
    misses = [f"{k} ({v:.3f}x, {1 - v:.1%} slower)" for k, v in speeds.items() if v < TARGET]
    worst = min(speeds, key=speeds.get)
    lines.append(f"verdict: {len(speeds) - len(misses)} of {len(speeds)} PASS (speed >= {TARGET}); slowest ratio "
                 f"{speeds[worst]:.3f}x ({worst})" + ("" if not misses else "; MISS: " + ", ".join(misses)))
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(main())
