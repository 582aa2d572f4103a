"""Where the wall time of ``granchain reproduce`` goes, phase by phase: this tree against a baseline
revision (default: the commit this benchmark was written on, before the reproduce path was trimmed),
measured in the same run.

Each side runs ``granchain reproduce`` in a fresh interpreter with a fresh output directory (so the
ensembles are computed, not resumed), with a phase timer installed around the functions the command
goes through. Time is charged to the innermost phase running on the main thread (exclusive), so the
phases add up to the total:

* ``imports``: every import (the command's own modules and those loaded on first use inside it);
* ``integration``: ``Backend.run_batch`` (the batch seam the ensembles call) and ``Integrator.integrate_batch``
  (what earlier versions called; the kernels and their Python wrapper; not trimmed here);
* ``chains``: the family's random draws and chain arrays, the chunk's buffers (``compute_chunk``);
* ``store: create``, ``store: write``, ``store: finalize``, ``store: read``: the Zarr store (creation,
  one write per chunk, the averaged pulse at the end, reading it again for the statistics);
* ``statistics: figN``, ``statistics: records``: the figures' data (fits, jackknives, the BCA, the
  Lilliefors Monte Carlo of Fig. 4) and the report's own fits;
* ``figures: plot``, ``figures: save``: drawing, and rendering to PNG and PDF;
* ``data files``: the figures' netCDF files; ``report``: report.md, report.html;
* ``other``: everything else (argument parsing, summary.json, the loops around the above).

The non-integration part is the total less ``integration``; its ratio baseline / this tree is the
figure of merit here (the integration is another job's). Both sides warm up first (a tiny run that
compiles or loads the Numba kernels; never timed). The baseline is exported with ``git archive``
into ``~/.cache/granchain-bench/`` (kept, so its Numba cache is reused) and imported through
``PYTHONPATH``. Peak memory is the maximum resident set size of each run's process.

    python benchmarks/bench_reproduce.py                        # the paper's run, 30,000 realisations (~6-8 minutes)
    python benchmarks/bench_reproduce.py --quick                # 600 realisations (~2 minutes)
    python benchmarks/bench_reproduce.py --realizations 3000 --repeats 2
    python benchmarks/bench_reproduce.py --baseline df53015     # against granchain 0.4.0
    python benchmarks/bench_reproduce.py --no-baseline          # this tree only
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The commit the reproduce path was profiled from (granchain 0.5 development, before it was trimmed).
BASELINE_REV = "f6a9782"

#: Run in each side's interpreter: install the phase timer, then ``granchain reproduce``.
DRIVER = r'''
import builtins, json, os, resource, sys, threading, time
T0 = time.perf_counter()
MAIN = threading.main_thread()
acc, cpu_acc, stack, state = {}, {}, [], {"phase": "other", "since": T0, "cpu_since": time.thread_time()}
cpu = {"ks_normal (CPU in worker threads)": 0.0}


def _charge(now):
    cpu_now = time.thread_time()  # the main thread's CPU time: what a busy machine inflates least
    acc[state["phase"]] = acc.get(state["phase"], 0.0) + now - state["since"]
    cpu_acc[state["phase"]] = cpu_acc.get(state["phase"], 0.0) + cpu_now - state["cpu_since"]
    state["since"], state["cpu_since"] = now, cpu_now


def _enter(phase):
    _charge(time.perf_counter())
    stack.append(state["phase"])
    state["phase"] = phase


def _leave():
    _charge(time.perf_counter())
    state["phase"] = stack.pop()


def timed(fn, phase):
    import functools

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        if threading.current_thread() is not MAIN:
            return fn(*args, **kwargs)
        _enter(phase)
        try:
            return fn(*args, **kwargs)
        finally:
            _leave()
    wrapper.__wrapped_phase__ = phase
    return wrapper


_import = builtins.__import__


def _timed_import(*args, **kwargs):
    if state["phase"] == "imports" or threading.current_thread() is not MAIN:
        return _import(*args, **kwargs)
    _enter("imports")
    try:
        return _import(*args, **kwargs)
    finally:
        _leave()


builtins.__import__ = _timed_import
_enter("imports")
import importlib
import granchain
import granchain.cli
import xarray

_PKG = os.path.dirname(granchain.__file__)


def _mod(*names):
    """The first of ``names`` that the imported tree has (by file: an editable install's import hook could
    otherwise resolve a module the tree lacks to another checkout), imported. The layouts differ between
    the trees compared: granchain 0.4.0 had granchain._ensemble where 0.5 has granchain.ensembles.run."""
    for name in names:
        rel = os.path.join(_PKG, *name.split(".")[1:])
        if os.path.exists(rel + ".py") or os.path.exists(os.path.join(rel, "__init__.py")):
            return importlib.import_module(name)
    return None


R = _mod("granchain.paper.reproduce", "granchain._reproduce")
F = _mod("granchain.paper.figures", "granchain.figures")
run_mod = _mod("granchain.ensembles.run", "granchain._ensemble")
store_mod = _mod("granchain.ensembles.store", "granchain._store")
fam_mod = _mod("granchain.families")
analysis = _mod("granchain.analysis")
integ_mod = _mod("granchain.solve.integrators", "granchain._integrators")
_leave()


def patch(owner, name, phase):
    fn = owner.__dict__.get(name) if isinstance(owner, type) else getattr(owner, name, None)
    if isinstance(fn, (classmethod, staticmethod)):
        if not hasattr(fn.__func__, "__wrapped_phase__"):
            setattr(owner, name, type(fn)(timed(fn.__func__, phase)))
    elif fn is not None and not hasattr(fn, "__wrapped_phase__"):
        setattr(owner, name, timed(fn, phase))


def subclasses(cls):
    out = [cls]
    for sub in cls.__subclasses__():
        out += subclasses(sub)
    return out


for cls in subclasses(integ_mod.Integrator):
    patch(cls, "integrate_batch", "integration")
_backends = _mod("granchain.backends")
if _backends is not None and hasattr(_backends, "Backend"):
    for cls in subclasses(_backends.Backend):  # (a version without run_batch: nothing patched here)
        patch(cls, "run_batch", "integration")
for cls in subclasses(fam_mod.ChainFamily):
    patch(cls, "draw_batch", "chains")
    patch(cls, "build", "chains")
patch(run_mod, "compute_chunk", "chains")
patch(store_mod.ZarrSink, "__init__", "store: create")
patch(store_mod.ZarrSink, "write", "store: write")
patch(store_mod.ZarrSink, "finalize", "store: finalize")
patch(analysis.ChunkSums, "from_store", "store: read")
patch(R, "chunk_sums", "store: read")
for mod in ("granchain.ensembles.read", "granchain.analysis", "granchain._store"):
    if _mod(mod) is not None:
        patch(_mod(mod), "open_store", "store: read")
for i in (1, 2, 3, 4):
    fig = getattr(F, f"fig{i}")
    patch(fig, "compute", f"statistics: fig{i}")
    patch(fig, "plot", "figures: plot")
patch(F, "save", "figures: save")
patch(_mod("granchain.paper.figures._style", "granchain.figures._style"), "save", "figures: save")
patch(R, "build_records", "statistics: records")
patch(R, "write_report", "report")
patch(xarray.Dataset, "to_netcdf", "data files")

_ks = analysis.ks_normal


def _ks_cpu(*args, **kwargs):
    t = time.thread_time()
    try:
        return _ks(*args, **kwargs)
    finally:
        cpu["ks_normal (CPU in worker threads)"] += time.thread_time() - t


analysis.ks_normal = _ks_cpu
code = granchain.cli.main(sys.argv[2:])
_charge(time.perf_counter())
result = {"granchain": granchain.__file__, "phases": acc, "main_cpu": cpu_acc, "process_cpu": time.process_time(), "total": time.perf_counter() - T0, "cpu": cpu,
          "max_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, "code": code}
with open(sys.argv[1], "w") as f:
    json.dump(result, f)
sys.exit(code)
'''

ORDER = ["imports", "integration", "chains", "store: create", "store: write", "store: finalize", "store: read",
         "statistics: fig1", "statistics: fig2", "statistics: fig3", "statistics: fig4", "statistics: records",
         "figures: plot", "figures: save", "data files", "report", "other"]


def loadavg() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "n/a"


def baseline_tree(rev: str) -> Path:
    """``rev`` exported with git archive into a kept cache folder (its Numba cache is reused)."""
    sha = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short=12", rev], capture_output=True, text=True,
                         check=True).stdout.strip()
    tree = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "granchain-bench" / f"tree-{sha}"
    if not (tree / "granchain" / "__init__.py").exists():
        tree.mkdir(parents=True, exist_ok=True)
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", sha], capture_output=True, check=True).stdout
        subprocess.run(["tar", "-x", "-C", str(tree)], input=archive, check=True)
    return tree


def run_side(tree: Path, realizations: int, quick: bool, workdir: Path, tag: str) -> dict:
    out = workdir / f"out-{tag}"
    shutil.rmtree(out, ignore_errors=True)
    result = workdir / f"{tag}.json"
    argv = ["reproduce", "--out", str(out), "--quiet", "--realizations", str(realizations)] + (["--quick"] if quick else [])
    env = dict(os.environ, PYTHONPATH=str(tree), MPLBACKEND="Agg")
    t0 = time.perf_counter()
    # cwd: ``python -c`` puts the working directory first on sys.path, ahead of PYTHONPATH (run from a
    # checkout, both sides would import the checkout's granchain)
    proc = subprocess.run([sys.executable, "-c", DRIVER, str(result)] + argv, env=env, capture_output=True, text=True,
                          cwd=workdir)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"{tag}: granchain reproduce failed:\n{proc.stderr[-3000:]}")
    res = json.loads(result.read_text())
    res["process_wall"] = wall
    if res.get("granchain") != str(tree / "granchain" / "__init__.py"):
        raise SystemExit(f"{tag}: imported {res.get('granchain')}, not the tree under test {tree}")
    res["summary"] = json.loads((out / "summary.json").read_text())
    shutil.rmtree(out, ignore_errors=True)
    return res


def median_phases(runs: list, key: str = "phases") -> dict:
    names = set().union(*(r[key] for r in runs))
    return {n: statistics.median(r[key].get(n, 0.0) for r in runs) for n in names}


def table(this: list, base: list | None, key: str = "phases") -> None:
    """Median seconds per phase (``key``: "phases", wall time; "main_cpu", the main thread's CPU time)."""
    p = median_phases(this, key)
    b = median_phases(base, key) if base else {}
    total = sum(p.values())
    btotal = sum(b.values()) if base else None
    names = [n for n in ORDER if n in p or n in b] + sorted((set(p) | set(b)) - set(ORDER))
    head = f"{'phase':24s} {'this tree':>10s} {'share':>6s}"
    if base:
        head += f" {'baseline':>10s} {'share':>6s} {'base/this':>9s}"
    print(head)
    for n in names:
        line = f"{n:24s} {p.get(n, 0.0):9.2f}s {100 * p.get(n, 0.0) / total:5.1f}%"
        if base:
            x, y = b.get(n, 0.0), p.get(n, 0.0)
            line += f" {x:9.2f}s {100 * x / btotal:5.1f}% " + (f"{x / y:8.2f}x" if y > 0.005 else f"{'-':>9s}")
        print(line)
    non = total - p.get("integration", 0.0)
    line = f"{'total':24s} {total:9.2f}s {100.0:5.1f}%"
    if base:
        line += f" {btotal:9.2f}s {100.0:5.1f}% {btotal / total:8.2f}x"
    print(line)
    line = f"{'non-integration':24s} {non:9.2f}s {100 * non / total:5.1f}%"
    if base:
        bnon = btotal - b.get("integration", 0.0)
        line += f" {bnon:9.2f}s {100 * bnon / btotal:5.1f}% {bnon / non:8.2f}x"
    print(line)
    if key != "phases":
        return
    for side, runs in (("this tree", this), ("baseline", base or [])):
        if runs:
            walls = ", ".join(f"{r['process_wall']:.1f}" for r in runs)
            rss = ", ".join(f"{r['max_rss_mb']:.0f}" for r in runs)
            ks = ", ".join(f"{r['cpu']['ks_normal (CPU in worker threads)']:.1f}" for r in runs)
            print(f"{side}: process wall {walls} s; peak RSS {rss} MB; Lilliefors CPU in threads {ks} s")


def compare_reports(this: dict, base: dict) -> None:
    """The two summary.json record lists, value by value (the same ensembles on both sides)."""
    a, b = this["summary"]["records"], base["summary"]["records"]
    key = lambda r: (r["section"], r["quantity"], r["range"])  # noqa: E731
    ka, kb = {key(r): r for r in a}, {key(r): r for r in b}
    if set(ka) != set(kb):
        print(f"report rows differ: only here {sorted(set(ka) - set(kb))}, only in the baseline {sorted(set(kb) - set(ka))}")
    same_display = sum(ka[k]["display"] == kb[k]["display"] and ka[k]["agrees"] == kb[k]["agrees"] for k in ka if k in kb)
    same_exact = sum(ka[k]["value"] == kb[k]["value"] and ka[k]["stderr"] == kb[k]["stderr"] for k in ka if k in kb)
    print(f"report rows: {len(ka)} here, {len(kb)} in the baseline; printed value and verdict equal in {same_display}, "
          f"value and stderr bitwise equal in {same_exact}")
    for k in sorted(k for k in ka if k in kb and (ka[k]["display"] != kb[k]["display"] or ka[k]["agrees"] != kb[k]["agrees"])):
        print(f"  differs: {k}: {kb[k]['display']!r} -> {ka[k]['display']!r}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--realizations", type=int, default=30_000, help="realisations per chain length (default 30000)")
    ap.add_argument("--quick", action="store_true", help="reproduce --quick (600 realisations)")
    ap.add_argument("--repeats", type=int, default=1, help="runs per side, alternating (default 1; medians are shown)")
    ap.add_argument("--baseline", default=BASELINE_REV, help=f"baseline revision (default {BASELINE_REV})")
    ap.add_argument("--no-baseline", action="store_true", help="this tree only")
    args = ap.parse_args(argv)
    print(f"bench_reproduce: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}; "
          f"{'--quick' if args.quick else f'{args.realizations} realisations'}, {args.repeats} run(s) per side")
    print(f"load average before: {loadavg()}")
    base_tree = None if args.no_baseline else baseline_tree(args.baseline)
    sides = [("this", ROOT)] + ([("base", base_tree)] if base_tree else [])
    with tempfile.TemporaryDirectory(prefix="bench-reproduce-") as tmp:
        work = Path(tmp)
        for tag, tree in sides:  # warm-up: compile or load the kernels, import once (never timed)
            run_side(tree, 20, False, work, f"warm-{tag}")
        runs = {tag: [] for tag, _ in sides}
        for i in range(args.repeats):
            for tag, tree in (sides if i % 2 == 0 else sides[::-1]):
                runs[tag].append(run_side(tree, args.realizations, args.quick, work, f"{tag}-{i}"))
                print(f"  {tag} run {i + 1}: {runs[tag][-1]['total']:.1f} s (load average {loadavg()})", flush=True)
    print(f"load average after: {loadavg()}")
    print()
    if base_tree:
        print(f"baseline: {args.baseline} ({base_tree})")
    print("wall time (the phases add up to the run's wall time less the interpreter's start):")
    table(runs["this"], runs.get("base"))
    print()
    print("main thread's CPU time (less sensitive to a busy machine; integration and the Lilliefors threads not included):")
    table(runs["this"], runs.get("base"), "main_cpu")
    print()
    if base_tree:
        compare_reports(runs["this"][0], runs["base"][0])
    return 0


if __name__ == "__main__":
    sys.exit(main())
