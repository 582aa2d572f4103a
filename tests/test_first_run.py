"""A run compiles only the kernels it uses, and the trailing window's bookkeeping stays within the
window (so a long chain costs in proportion to its length, not its square).

Speed itself is measured in ``benchmarks/bench_first_run.py`` (compilation per kernel, the first
``granchain pulse`` against granchain 0.4.0, cost against chain length), never here: these machines
are shared and noisy. What is tested here is what makes those numbers possible, and could break
silently: which compiled functions a run touches, and that a long windowed run is right.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import granchain as gc

PROBE = textwrap.dedent(
    """
    import json, sys
    import granchain as gc
    from granchain.backends.kernels import batch, dispatch
    job = sys.argv[1]
    small = gc.decorated([0.05, 0.3, 0.012])
    if job == "pulse":
        gc.simulate(small)
    elif job == "ensemble":
        gc.run_ensemble(6, realizations=2, progress=False, chains="decorated")
    elif job == "damped":
        gc.simulate(small.with_dissipation(0.05))
    elif job == "shared":
        gc.simulate(gc.effective(small))
        gc.run_ensemble(6, realizations=2, progress=False, chains="effective")
    names = ["dp5_chain", "dp5_chain_general", "rkn4_chain", "rkn4_chain_general", "verlet_chain",
             "verlet_chain_general"]
    used = {name: len(getattr(dispatch, name).signatures) for name in names}
    used["integrate_batch"] = len(batch.integrate_batch.signatures)
    print(json.dumps(used))
    """
)


def _compiled(job: str) -> dict:
    """The kernels holding compiled code (from the cache or compiled) after ``job`` in a fresh
    interpreter, with the number of signatures each holds."""
    out = subprocess.run([sys.executable, "-c", PROBE, job], capture_output=True, text=True, check=True)
    return {name: n for name, n in json.loads(out.stdout.splitlines()[-1]).items() if n > 0}


def test_a_pulse_compiles_dp5_for_the_papers_chain_alone():
    """A first ``simulate`` of a decorated chain (DP5, elastic, unloaded) loads or compiles DP5's kernel
    for the paper's chain and nothing else: not RKN4, Verlet, the real-contact loops or the ensemble
    kernel (each of which cost a newcomer's first run its compilation). A damped chain takes the
    real-contact kernel, an ensemble of decorated chains RKN4's kernel (its default) and the ensemble
    kernel, which calls it through its address: the check can fail both ways. Each once: one signature
    (a second, e.g. for read-only arrays, would be a second compilation of the whole step loop)."""
    assert _compiled("pulse") == {"dp5_chain": 1}
    assert _compiled("damped") == {"dp5_chain_general": 1}
    assert _compiled("ensemble") == {"rkn4_chain": 1, "integrate_batch": 1}


def test_simulate_and_an_ensemble_share_the_compiled_kernel():
    """An ensemble of effective chains after a ``simulate`` of one (both DP5, the paper's model) uses
    the entry point ``simulate`` compiled, not a second specialisation of it: the arrays a chain holds
    are read-only and an ensemble's are not, and the kernels get both as writable C arrays."""
    out = subprocess.run([sys.executable, "-c", PROBE, "shared"], capture_output=True, text=True, check=True)
    used = {name: n for name, n in json.loads(out.stdout.splitlines()[-1]).items() if n > 0}
    assert used == {"dp5_chain": 1, "integrate_batch": 1}


#: A probe's preamble: ``compiled`` collects the qualified names of the functions Numba compiles from
#: the moment ``listen()`` is called (the ``numba:compile`` event: a cache load does not trigger it).
LISTEN = textwrap.dedent(
    """
    import json
    from numba.core import event
    compiled = []

    class Listener(event.Listener):
        def on_start(self, ev):
            compiled.append(ev.data["dispatcher"].py_func.__qualname__)

        def on_end(self, ev):
            pass

    def listen():
        event.register("numba:compile", Listener())
    """
)

CACHE_PROBE = LISTEN + textwrap.dedent(
    """
    listen()
    import granchain as gc
    small = gc.decorated([0.05, 0.3, 0.012])
    gc.simulate(small)
    gc.simulate(small.with_dissipation(0.05))
    gc.run_ensemble(6, realizations=2, progress=False)
    print(json.dumps(compiled))
    """
)


def test_a_second_process_compiles_nothing():
    """The kernels are specialised by closures (the Runge-Kutta entry points on the method and the model
    class, the root searches on the function followed, the force routine's call on the model class) and
    the ensemble kernel takes the entry point as a first-class function: Numba must still find all of
    them in its on-disk cache in the next process (it keys a closure on the values of its variables). A
    second process running a pulse, a damped pulse and an ensemble of the paper's two chains compiles
    no function at all (a cache miss would cost every CLI start and Dask worker its compilation)."""
    runs = [subprocess.run([sys.executable, "-c", CACHE_PROBE], capture_output=True, text=True, check=True)
            for _ in range(2)]
    compiled = json.loads(runs[1].stdout.splitlines()[-1])
    assert compiled == [], f"compiled again in a second process: {sorted(set(compiled))}"


def test_a_long_windowed_chain_carries_the_solitary_wave():
    """20,000 granules with the trailing window (its cuts shift the stage arrays over the window only,
    the peak search visits only the observed granules inside it, and behind the solitary wave, where
    the contacts stay closed at rounding-size compressions, it cuts across a contact whose force is
    below ``window.CUT_FORCE``): the solitary wave that forms from the impulse travels unchanged to
    the far end. Every peak velocity past granule 100 equals, within 1e-8, the solitary wave's peak at
    granule 150 of a 200-granule chain integrated without any window (DP5 at rtol 1e-10: an independent
    run, no cut, no relaxed zone), and the wave's arrival times are equally spaced (to 1e-8). At
    rtol 1e-8 the run measured 2.6e-10 and 1.1e-10. A stage array left unshifted, a peak missed at a
    window edge or a cut that lost a force that mattered would break the wave (the negative control:
    granule 2's peak is not the solitary wave's)."""
    n = 20_000
    res = gc.simulate(gc.monodisperse(n), integrator=gc.RKN4.windowed(1e-8, 1e-11))
    assert res.status == 0, res.message
    ref = gc.simulate(gc.monodisperse(200), integrator=gc.DP5(1e-10, 1e-13)).peak_velocity[150]
    v = res.peak_velocity[100:-20]
    assert np.abs(v - ref).max() < 1e-8, np.abs(v - ref).max()
    assert abs(res.peak_velocity[1] - ref) > 1e-3  # the wave forms over the first granules
    dt = np.diff(res.peak_time[100:-20])
    assert np.ptp(dt) < 1e-8 * dt.mean(), (dt.min(), dt.max())


def test_each_closure_made_by_a_kernel_factory_has_a_name_of_its_own():
    """Numba names a compiled function's machine code after its qualified name and a per-process
    counter, and looks up the address of an ensemble's entry point by that name. Two closures of one
    factory (the entry points of DP5 and RKN4, the root searches, the force routine's calls) that
    shared a qualified name got the same symbol when both came from the on-disk cache, and the lookup
    returned the other method's code (the next test). Each must be named for the constants it is
    compiled for."""
    from granchain.backends.kernels import dense, dispatch, forces

    groups = [[dispatch.dp5_chain, dispatch.dp5_chain_general, dispatch.rkn4_chain, dispatch.rkn4_chain_general],
              [dense._acceleration_root, dense._approach_root, dense._force_rate_root, dense._elastic_acceleration_root],
              [forces._accelerations_paper, forces._accelerations_general]]
    for group in groups:
        names = [f.py_func.__qualname__ for f in group]
        assert len(set(names)) == len(names), names


LAW_PROBE = textwrap.dedent(
    """
    import json
    import granchain as gc
    from granchain.backends.kernels import dense, forces
    helpers = {"dense_acceleration": dense.dense_acceleration, "dense_force": dense.dense_force,
               "contact_law_force": forces.contact_law_force, "plastic_force": forces.plastic_force,
               "force_rate": forces.force_rate, "elastic_acceleration": dense.elastic_acceleration}
    def compiled():
        return sorted(name for name, f in helpers.items() if f.signatures)
    small = gc.decorated([0.05, 0.3, 0.012])
    gc.simulate(small)
    paper = compiled()
    gc.simulate(small.with_dissipation(0.05))
    print(json.dumps([paper, compiled()]))
    """
)


@pytest.mark.slow
def test_the_papers_chain_compiles_no_real_contact_law(tmp_path):
    """With an empty cache, a first ``simulate`` of the paper's chain (elastic, unloaded) compiles the elastic
    law's helpers alone: not the general acceleration and force on the dense output, nor the yielding or
    viscoelastic laws, which its step loop never calls (each is compilation a newcomer's first run pays
    for). Negative control: a damped chain next, in the same process, compiles them."""
    import os

    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba-cache"), GRANCHAIN_CACHE=str(tmp_path / "cache"))
    out = subprocess.run([sys.executable, "-c", LAW_PROBE], capture_output=True, text=True, check=True, env=env)
    paper, damped = json.loads(out.stdout.splitlines()[-1])
    assert paper == ["elastic_acceleration"]
    assert {"dense_acceleration", "dense_force", "contact_law_force", "force_rate"} <= set(damped)


SWITCH_PROBE = textwrap.dedent(
    """
    import json, sys
    import granchain as gc
    family = gc.RandomDecorated(6)
    steps = []
    for name in sys.argv[1].split(","):
        integ = {"dp5": gc.DP5.windowed(), "rkn4": gc.RKN4.windowed(1e-6, 1e-9)}[name]
        ds = gc.run_ensemble(family, realizations=2, seed=1, progress=False, integrator=integ, chains="decorated",
                             pulse_window="full")
        alone = gc.simulate(family.chain(1, 0, "decorated"), integ, t_grid=ds["time"].values)
        steps.append([name, int(ds["n_steps"].isel(chain=0, realization=0)), int(alone.n_steps)])
    print(json.dumps(steps))
    """
)


@pytest.mark.slow
def test_ensembles_run_their_own_method_with_kernels_from_the_cache(tmp_path):
    """An ensemble integrates every realisation with the method it was given, also when the entry
    points come from the on-disk cache written by other processes: one process caches RKN4's entry
    point, another DP5's, and a third that loads both and alternates ensembles of the two must see
    each ensemble's first realisation take the steps of ``simulate`` with the same integrator (RKN4
    at DP5's tolerances takes ~2x DP5's steps: the wrong method cannot pass). With the two entry
    points named alike (before granchain 0.5's fix), the third process's second RKN4 ensemble ran DP5."""
    import os

    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba-cache"))

    def run(jobs: str) -> list:
        out = subprocess.run([sys.executable, "-c", SWITCH_PROBE, jobs], capture_output=True, text=True, check=True,
                             env=env)
        return json.loads(out.stdout.splitlines()[-1])

    run("rkn4")
    run("dp5")
    results = run("rkn4,dp5,rkn4,dp5")
    for name, in_ensemble, alone in results:
        assert in_ensemble == alone, results
    assert results[0][1] > 1.5 * results[1][1], results  # the two methods are told apart by their steps


def test_the_command_line_says_when_it_compiles():
    """A first run spends 10-20 s compiling: the command line says so on stderr when the compilation
    starts and how long it took at the end. Nothing once the function is compiled (nothing to compile
    in this process: the negative control), and nothing with ``quiet``."""
    import io

    from numba import njit

    from granchain.cli._compile import compile_notice

    @njit(cache=False)
    def twice(x):
        return 2.0 * x

    stream = io.StringIO()
    with compile_notice(stream):
        assert twice(1.5) == 3.0
        twice(2.5)  # compiled already: one announcement
    lines = stream.getvalue().splitlines()
    assert len(lines) == 2, lines
    assert lines[0].startswith("granchain: compiling the kernels this command uses")
    assert lines[1].startswith("granchain: ") and "s of this run went into compiling" in lines[1]
    assert float(lines[1].split()[1]) >= 0.0

    again = io.StringIO()
    with compile_notice(again):
        twice(3.5)
    assert again.getvalue() == ""

    @njit(cache=False)
    def thrice(x):
        return 3.0 * x

    quiet = io.StringIO()
    with compile_notice(quiet, quiet=True):
        assert thrice(1.0) == 3.0
    assert quiet.getvalue() == ""


WARM_PROBE = LISTEN + textwrap.dedent(
    """
    from granchain.backends import warm
    from granchain.backends.kernels import dispatch
    before = warm.is_cached(dispatch.dp5_chain)
    helper = warm.compile_elsewhere("dp5")
    started = helper is not None
    warm.wait_for(dispatch.dp5_chain)  # as an ensemble does before it compiles DP5 itself
    code = helper.poll() if started else None
    after = warm.is_cached(dispatch.dp5_chain)
    again = warm.compile_elsewhere("dp5")
    listen()
    import granchain as gc
    gc.run_ensemble(6, realizations=2, chains="effective", progress=False)
    print(json.dumps([before, started, code, after, again is None, compiled]))
    """
)


@pytest.mark.slow
def test_a_helper_process_compiles_dp5_into_the_cache(tmp_path):
    """The paper's first run compiles DP5's entry point in a helper process while it compiles RKN4's:
    with an empty cache the helper is started, ``wait_for`` (what an ensemble calls before it would
    compile DP5) returns once the helper is done, DP5 is then in the cache, no second helper starts, and an ensemble of effective chains loads DP5 from there instead of compiling it
    (it compiles only the ensemble kernel). Before the helper, the cache is empty (the check can fail)."""
    import os

    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba-cache"))
    out = subprocess.run([sys.executable, "-c", WARM_PROBE], capture_output=True, text=True, check=True, env=env)
    before, started, code, after, none_again, compiled = json.loads(out.stdout.splitlines()[-1])
    assert (before, started, code, after, none_again) == (False, True, 0, True, True)
    assert not any("kernel_dp5" in name for name in compiled), compiled
    assert any("integrate_batch" in name for name in compiled), compiled


def test_no_helper_process_once_dp5_is_cached():
    """With DP5's entry point cached (compiled by this test session), no helper process is started,
    and stopping no helper is a no-op."""
    from granchain.backends import warm
    from granchain.backends.kernels import dispatch

    gc.simulate(gc.effective(gc.decorated([0.05, 0.3, 0.012])))
    assert warm.is_cached(dispatch.dp5_chain)
    assert warm.compile_elsewhere("dp5") is None
    warm.stop(None)


def test_ensembles_start_the_helper_only_where_dp5_comes_second(monkeypatch):
    """``run_ensemble`` asks for a helper compiling DP5 (the paper's chain) when it integrates another
    method first and DP5 later, on this machine: the defaults for both chains of the paper's family.
    Not for one chain kind, DP5 for all, real contacts (another entry point) or a cluster."""
    from granchain.backends import warm
    from granchain.ensembles import run as run_module
    from granchain.ensembles.run import EnsembleSpec

    asked = []
    monkeypatch.setattr(warm, "compile_elsewhere", lambda job: asked.append(job))

    def asks(family, client=None, **kw) -> bool:
        asked.clear()
        run_module._compile_ahead(EnsembleSpec(family, 10, **kw), client)
        return asked == ["dp5"]

    paper = gc.RandomDecorated(6)
    assert asks(paper)
    assert not asks(paper, chains="decorated")
    assert not asks(paper, chains="effective")
    assert not asks(paper, integrator=gc.DP5.windowed(1e-8, 1e-11))
    assert asks(paper, chain_integrators={"decorated": gc.RKN4.windowed(), "effective": gc.DP5()})
    assert not asks(paper, client=object())
    assert not asks(gc.RandomDecorated(6, contact=gc.Viscoelastic(0.05)))


CACHE_DIR_PROBE = textwrap.dedent(
    """
    import json, numba
    from granchain.backends import kernels
    from granchain.backends.kernels import dispatch, forces
    print(json.dumps([kernels.__file__, str(kernels.CACHE_ROOT), str(kernels.CACHE_DIR), numba.config.CACHE_DIR,
                      dispatch.dp5_chain._cache._cache_path, forces._accelerations_paper._cache._cache_path]))
    """
)


def _cache_paths(tmp_path, tree=None, **env_vars):
    """Where a fresh interpreter caches the kernels, with ``env_vars`` (None: unset) over this environment,
    importing granchain from ``tree`` (default: this one). Also reads Numba's cache path of two compiled
    functions (a dispatcher's private ``_cache``: the directory it would write)."""
    import os

    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "GRANCHAIN_CACHE", "XDG_CACHE_HOME")}
    env.update({k: str(v) for k, v in env_vars.items() if v is not None})
    if tree is not None:
        env["PYTHONPATH"] = str(tree)
    out = subprocess.run([sys.executable, "-c", CACHE_DIR_PROBE], capture_output=True, text=True, check=True, env=env,
                         cwd=tmp_path)
    init, root, directory, numba_dir, *functions = json.loads(out.stdout.splitlines()[-1])
    return Path(init).parent, Path(root), Path(directory), numba_dir, [Path(f) for f in functions]


def test_the_kernels_are_cached_in_a_user_cache_directory_keyed_on_their_sources(tmp_path):
    """Numba's cache of the kernels is never next to their sources (an installed package may be
    read-only, and pip does not track files written there: they once shadowed an editable reinstall):
    it is ``granchain-kernels-<key>`` under ``$GRANCHAIN_CACHE/numba``, else ``$XDG_CACHE_HOME/granchain/numba``,
    and under a user's own ``NUMBA_CACHE_DIR`` when set (theirs wins). Every compiled function, including
    the closures a factory makes, gets its cache path there. The key is the digest of the kernel sources:
    the same sources elsewhere share it, one edited source changes it (two versions never share machine
    code: the negative control)."""
    import shutil

    for env, root in ((dict(GRANCHAIN_CACHE=tmp_path / "own"), tmp_path / "own" / "numba"),
                      (dict(XDG_CACHE_HOME=tmp_path / "xdg"), tmp_path / "xdg" / "granchain" / "numba"),
                      (dict(GRANCHAIN_CACHE=tmp_path / "own", NUMBA_CACHE_DIR=tmp_path / "nb"), tmp_path / "nb")):
        package, got_root, directory, numba_dir, functions = _cache_paths(tmp_path, **env)
        assert got_root == root and directory.parent == root, (env, got_root, directory)
        assert directory.name.startswith("granchain-kernels-") and numba_dir == str(directory)
        stamp = (directory / "granchain-kernels.sha256").read_text()
        assert len(stamp) == 64 and directory.name == f"granchain-kernels-{stamp[:16]}"
        for f in functions:
            assert directory in f.parents and package not in f.parents, (f, package)
    key = directory.name

    tree = tmp_path / "tree"
    shutil.copytree(Path(gc.__file__).parent, tree / "granchain", ignore=shutil.ignore_patterns("__pycache__"))
    same = _cache_paths(tmp_path, tree, GRANCHAIN_CACHE=tmp_path / "own")
    assert same[0] == tree / "granchain" / "backends" / "kernels" and same[2].name == key
    with open(tree / "granchain" / "backends" / "kernels" / "forces.py", "a") as f:
        f.write("\n# an edit\n")
    edited = _cache_paths(tmp_path, tree, GRANCHAIN_CACHE=tmp_path / "own")
    assert edited[2].parent == tmp_path / "own" / "numba" and edited[2].name != key


def test_old_kernel_caches_are_pruned_to_the_most_recently_used(tmp_path):
    """A new key's first use removes the directories of other keys but the three most recently used
    (two installations in use side by side keep theirs); directories without granchain's stamp (a user's
    other caches under their NUMBA_CACHE_DIR) are never touched, nor the one in use."""
    import os

    root = tmp_path / "nb"
    old = []
    for i in range(5):
        d = root / f"granchain-kernels-{i:016x}"
        d.mkdir(parents=True)
        (d / "granchain-kernels.sha256").write_text(f"{i:064x}")
        (d / "entry.nbi").write_text("")
        os.utime(d / "granchain-kernels.sha256", (1e9 + i, 1e9 + i))  # i = 4 used last
        old.append(d)
    other = root / "someone-elses"
    other.mkdir()
    _, _, directory, _, _ = _cache_paths(tmp_path, NUMBA_CACHE_DIR=root)
    assert sorted(p.name for p in root.iterdir()) == sorted([directory.name, other.name] + [d.name for d in old[2:]])
