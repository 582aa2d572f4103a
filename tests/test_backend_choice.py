"""Choosing the backend that computes an ensemble (``run_ensemble(backend=...)``, ``--backend``).

A backend chosen by name or instance gets every chunk through its ``integrate_batch`` with the same
arguments as the integrator's own; a fake backend that hands them on to the Numba backend must therefore
give bitwise the default's results, and one call per chunk and chain kind (a GPU fills its cores only with
a whole chunk). A store records a backend other than the CPU default (every existing record stays as it
was), and is continued on the backend that computed it unless ``switch_backend`` accepts another one,
which its record then lists. No GPU is needed: the "cuda" cases check the refusal on a machine without one.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import warnings

import numpy as np
import pytest

import granchain as gc
from granchain.backends import Backend, get_backend
from granchain.cli import main
from granchain.ensembles.run import EnsembleSpec, compute_chunk

FAMILY = gc.RandomDecorated(6)
#: Small and cheap: 12 realisations in chunks of 5 (a short last chunk), both chain kinds.
RUN = dict(realizations=12, seed=7, progress=False)
CHUNK = 5
COMPARED = ("peak_velocity", "peak_time", "peak_force", "peak_force_time", "status", "n_steps", "t_end", "energy_error",
            "mean_velocity", "mean_velocity_stderr", "n_valid")


class Fake(Backend):
    """A backend that is not the CPU default: the Numba backend's integrate_batch, counted."""

    name = "fake"
    default_chunk_size = CHUNK

    def __init__(self):
        self.calls = []  # (rows, Numba threads during the call)

    def integrate_batch(self, integrator, masses, *args, **kwargs):
        import numba

        self.calls.append((masses.shape[0], numba.get_num_threads()))
        return get_backend("numba").integrate_batch(integrator, masses, *args, **kwargs)


def assert_same(a, b, names=COMPARED):
    for name in names:
        np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=name)


@pytest.fixture(scope="module")
def default(tmp_path_factory):
    return gc.run_ensemble(FAMILY, chunk_size=CHUNK, **RUN)


def test_a_chosen_backend_gives_the_defaults_results_bitwise(default):
    fake = Fake()
    ds = gc.run_ensemble(FAMILY, backend=fake, **RUN)  # chunk_size: the backend's default
    assert_same(ds, default)
    record = json.loads(ds.attrs["granchain_parameters"])
    assert record["backend"] == "fake" and record["chunk_size"] == CHUNK
    # one call per chunk and chain kind (3 chunks x 2 kinds), plus the averaged-pulse windows' pilot (one per kind)
    assert sorted(rows for rows, _ in fake.calls) == sorted([5, 5, 2] * 2 + [64, 64])


def test_a_device_backend_gets_whole_chunks_and_leaves_numbas_threads_alone():
    import numba

    fake = Fake()
    spec = EnsembleSpec(FAMILY, 40, 1, ("effective",), chunk_size=40, pulse_window="full", backend=fake)
    seen = []
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        res = compute_chunk(spec, 0, threads=numba.config.NUMBA_NUM_THREADS, on_progress=seen.append)
    finally:
        numba.set_num_threads(before)
    assert fake.calls == [(40, 1)]  # one call for the chunk, Numba's thread count untouched
    assert seen == [40] and res["realizations"] == 40  # progress once, for the whole chunk
    # the CPU default splits the same chunk into progress batches (the control)
    cpu = EnsembleSpec(FAMILY, 40, 1, ("effective",), chunk_size=40, pulse_window="full")
    steps = []
    compute_chunk(cpu, 0, on_progress=steps.append)
    assert len(steps) > 1 and sum(steps) == 40


def test_the_record_names_a_backend_only_when_it_is_not_the_cpu_default():
    base = EnsembleSpec(FAMILY, 10, chunk_size=5)
    record = base.describe()
    assert "backend" not in record and "backends_used" not in record
    assert EnsembleSpec(FAMILY, 10, chunk_size=5, backend="cpu").describe() == record
    assert EnsembleSpec(FAMILY, 10, chunk_size=5, backend="numba").describe() == {**record, "backend": "numba"}
    assert EnsembleSpec(FAMILY, 10).chunk_size == 500  # the CPU's chunks
    assert EnsembleSpec(FAMILY, 10, backend=Fake()).chunk_size == CHUNK  # the backend's


def _no_repairs():
    """Warnings recorded during a run, to check that switching backends is no repair of the store."""
    return warnings.catch_warnings(record=True)


def test_resuming_on_another_backend_is_refused_unless_switched(default, tmp_path, capsys):
    store = tmp_path / "s.zarr"
    gc.run_ensemble(FAMILY, chunk_size=CHUNK, out=store, **{**RUN, "realizations": 7})
    with pytest.raises(ValueError, match=r"computed with the 'cpu' backend and this run asks for 'fake'.*"
                                         r"switch_backend=True \(CLI: --switch-backend\)"):
        gc.run_ensemble(FAMILY, out=store, backend=Fake(), **RUN)
    with _no_repairs() as caught:
        warnings.simplefilter("always")
        fake = Fake()
        ds = gc.run_ensemble(FAMILY, out=store, backend=fake, switch_backend=True, **RUN)  # extended to 12 on the fake
    assert not [w for w in caught if "rewrote" in str(w.message) or "recomputing" in str(w.message)], \
        [str(w.message) for w in caught]
    assert fake.calls  # the extension ran on the fake backend
    record = json.loads(ds.attrs["granchain_parameters"])
    assert "backend" not in record and record["backends_used"] == ["cpu", "fake"] and record["chunk_size"] == CHUNK
    assert "continued on the fake backend" in ds.attrs["history"]
    assert_same(ds, default)  # (bitwise here: the fake hands on to the CPU's kernels)
    reread = gc.open_store(store)  # every checksum still verifies
    assert_same(reread, default)
    # once switched, either backend continues it without asking again, and the record stays
    again = gc.run_ensemble(FAMILY, out=store, **RUN)
    assert json.loads(again.attrs["granchain_parameters"])["backends_used"] == ["cpu", "fake"]
    assert main(["info", str(store)]) == 0
    assert "backend      cpu, then fake" in capsys.readouterr().out


def test_a_store_of_another_backend_is_not_continued_on_the_cpu(tmp_path, capsys):
    store = tmp_path / "s.zarr"
    gc.run_ensemble(FAMILY, out=store, backend=Fake(), chains="effective", pulse_window="full",
                    **{**RUN, "realizations": 5})
    with pytest.raises(ValueError, match=r"computed with the 'fake' backend and this run asks for 'cpu'"):
        gc.run_ensemble(FAMILY, out=store, chains="effective", pulse_window="full", **{**RUN, "realizations": 5})
    assert main(["info", "--json", str(store)]) == 0
    assert json.loads(capsys.readouterr().out)["backend"] == "fake"


def test_info_says_cpu_for_a_store_without_a_backend(tmp_path, capsys):
    store = tmp_path / "s.zarr"
    gc.run_ensemble(FAMILY, out=store, chains="effective", pulse_window="full", chunk_size=5, **{**RUN, "realizations": 5})
    assert main(["info", str(store)]) == 0
    assert "backend      cpu\n" in capsys.readouterr().out


def test_unknown_backend_names_the_choices():
    with pytest.raises(ValueError, match=r"backend must be one of \['cpu', 'numba', 'scipy', 'cuda'\]"):
        gc.run_ensemble(FAMILY, backend="gpu", **RUN)


def _cuda_usable() -> bool:
    try:
        get_backend("cuda")
    except Exception:  # noqa: BLE001 -- BackendUnavailable (or no cuda backend): not usable here
        return False
    return True


@pytest.mark.parametrize("command", [["ensemble", "--large", "4", "--realizations", "2", "--out", "{tmp}/s.zarr"],
                                     ["reproduce", "--quick", "--out", "{tmp}/r"],
                                     ["design", "--out", "{tmp}/d"],
                                     ["validity", "--quick", "--out", "{tmp}/v"],
                                     ["pulse", "--radii", "1,1,1", "--plot", "{tmp}/p.png"]])
def test_cli_backend_cuda_without_a_gpu_is_one_line_and_exit_2(command, tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_ENABLE_CUDASIM"}
    if _cuda_usable():
        pytest.skip("a GPU (or the CUDA simulator) is usable here: the refusal is for machines without one")
    argv = [a.replace("{tmp}", str(tmp_path)) for a in command]
    proc = subprocess.run([sys.executable, "-m", "granchain", *argv, "--backend", "cuda"], capture_output=True, text=True,
                          env=env, timeout=120)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"granchain {command[0]}: error:") and "cuda" in lines[0], proc.stderr
    assert "Traceback" not in proc.stderr and not any(tmp_path.iterdir())  # refused before anything was written


#: Makes ``numba.cuda`` fail on import as an installed numba-cuda does under a NumPy it does not support (a
#: release calling ``np.row_stack`` under NumPy 2.5: an AttributeError, not an ImportError).
BROKEN_NUMBA_CUDA = """
import importlib.abc, sys
class Broken(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name == "numba.cuda" or name.startswith("numba.cuda."):
            raise AttributeError("module 'numpy' has no attribute 'row_stack'")
        return None
sys.meta_path.insert(0, Broken())
"""


def test_a_numba_cuda_that_breaks_on_import_is_one_line_and_exit_2(tmp_path):
    """An installed numba-cuda that raises something other than ImportError on import (a release calling np.row_stack
    does so under NumPy 2.5) is a reason the backend cannot run, said in one line, never a traceback; and without
    ``--backend cuda`` nothing imports it (the CPU run works)."""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_ENABLE_CUDASIM"}
    code = BROKEN_NUMBA_CUDA + (
        "from granchain.backends import cuda\n"
        "ok, why = cuda.available()\n"
        "assert not ok and 'fails to import (AttributeError' in why and 'NumPy' in why, why\n"
        "from granchain.cli import main\n"
        "sys.exit(main(sys.argv[1:]))\n")
    store = tmp_path / "s.zarr"
    argv = ["ensemble", "--large", "4", "--realizations", "2", "--quiet", "--out", str(store)]
    proc = subprocess.run([sys.executable, "-c", code, *argv, "--backend", "cuda"], capture_output=True, text=True,
                          env=env, timeout=300)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("granchain ensemble: error: the cuda backend cannot run here"), proc.stderr
    assert "fails to import" in lines[0] and "backend='cpu'" in lines[0] and not store.exists()
    proc = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0 and store.exists(), proc.stderr  # the negative control: the CPU never needs numba.cuda


def test_the_chunk_size_help_gives_each_backends_default(capsys):
    """``--chunk-size``'s help states the defaults a new store takes, the numbers the backends ask for."""
    from granchain.backends.cuda import CudaBackend
    from granchain.ensembles.backend import CPU_CHUNK_SIZE

    with pytest.raises(SystemExit):
        main(["ensemble", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert f"{CPU_CHUNK_SIZE} on the cpu, {CudaBackend.default_chunk_size} on cuda" in text


def test_design_rows_on_a_chosen_backend_equal_the_defaults():
    from granchain.design import TaperedSpace
    from granchain.design.evaluate import default_integrator, run_rows

    space = TaperedSpace(6, (0.0, 0.2), wall=False)
    batch = space.batch(np.array([[0.05], [0.15]]))
    integ = default_integrator(space)
    fake = Fake()
    a, b = run_rows(batch, integ, np.arange(5)), run_rows(batch, integ, np.arange(5), backend=fake)
    assert [rows for rows, _ in fake.calls] == [2]
    for name in ("peak_velocity", "peak_time", "peak_force", "status", "n_steps"):
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)


def test_design_runs_are_continued_on_their_backend(tmp_path):
    import zarr

    from granchain import design

    def run(**kw):
        return design.optimize(design.TaperedSpace(2, (-0.3, 0.5), wall=False), "transmitted-energy", budget=40, seed=0,
                               local=None, polish=False, out=tmp_path, **kw)

    fake = Fake()
    first = run(backend=fake)
    assert fake.calls
    with pytest.raises(ValueError, match=r"computed with the 'fake' backend and this run asks for 'cpu'"):
        run()
    again = run(switch_backend=True)  # replays the stored evaluations
    assert again.value == first.value
    record = json.loads(zarr.open_group(tmp_path / "history.zarr", mode="r").attrs["granchain_design"])
    assert record["backend"] == "fake" and record["backends_used"] == ["fake", "cpu"]


def test_validity_and_reproduce_pass_the_backend_on(tmp_path):
    from granchain.paper import reproduce, validity

    fake = Fake()
    ds = validity.validity_map(tmp_path / "v", alphas=[0.01], betas=[0.4], n_large=4, realizations=10, blocks=2,
                               progress=False, netcdf=False, backend=fake)
    assert fake.calls and ds.attrs["backend"] == "fake"
    (point,) = (tmp_path / "v" / "points").iterdir()
    assert gc.open_store(point).attrs["granchain_parameters"].count('"backend": "fake"') == 1
    fake.calls.clear()
    (ds4,) = reproduce.run_ensembles(tmp_path / "r", 10, 1, Ns=(4,), progress=False, log=lambda *_: None,
                                     backend=fake).values()
    assert fake.calls and json.loads(ds4.attrs["granchain_parameters"])["backend"] == "fake"


class RknOnly(Fake):
    """A backend that declares the one method it has kernels for, as the GPU backend does."""

    name = "rkn-only"
    methods = ("rkn4",)


def test_a_backend_with_fewer_methods_gets_rkn4_for_the_kinds_whose_default_it_lacks():
    """The effective chains' default is DP5; on a backend that runs RKN4 alone they get the decorated chains'
    default, RKN4 (recorded); an integrator the caller names is kept (and refused by the backend if it must)."""
    spec = EnsembleSpec(FAMILY, realizations=4, backend=RknOnly())
    assert {k: i.name for k, i in spec.chain_integrators.items()} == {"decorated": "rkn4", "effective": "rkn4"}
    assert spec.chain_integrators["effective"] == EnsembleSpec(FAMILY, realizations=4).chain_integrators["decorated"]
    assert EnsembleSpec(FAMILY, realizations=4).chain_integrators["effective"].name == "dp5"  # negative control
    named = EnsembleSpec(FAMILY, realizations=4, backend=RknOnly(), integrator="dp5")
    assert {i.name for i in named.chain_integrators.values()} == {"dp5"}


class DefaultsToRkn(Fake):
    """A backend with kernels for RKN4 and DP5 that defaults to RKN4 alone, as the GPU backend does."""

    name = "defaults-to-rkn"
    methods = ("rkn4", "dp5")
    default_methods = ("rkn4",)


class RunsBoth(Fake):
    """The same without a default of its own: the methods it runs are the defaults it takes."""

    name = "runs-both"
    methods = ("rkn4", "dp5")


def test_a_backend_that_runs_dp5_but_defaults_to_rkn4_gets_rkn4_unless_dp5_is_asked_for():
    """What the GPU backend declares: the effective chains get RKN4 by default, and DP5 when it is named. The
    negative control, a backend that runs both with no default of its own, keeps the CPU's DP5."""
    assert {i.name for i in EnsembleSpec(FAMILY, realizations=4, backend=DefaultsToRkn()).chain_integrators.values()} \
        == {"rkn4"}
    named = EnsembleSpec(FAMILY, realizations=4, backend=DefaultsToRkn(), integrator="dp5")
    assert {i.name for i in named.chain_integrators.values()} == {"dp5"}
    both = EnsembleSpec(FAMILY, realizations=4, backend=RunsBoth())
    assert {k: i.name for k, i in both.chain_integrators.items()} == {"decorated": "rkn4", "effective": "dp5"}


def test_contacts_that_dissipate_keep_each_kinds_own_default_on_a_backend_that_defaults_to_rkn4():
    """RKN4 cannot integrate damped contacts, so a backend that defaults to it (the GPU) leaves each chain kind
    the CPU's own default for them, DP5 at that kind's tolerances (the effective chains' are tighter than the
    decorated chains'), so that the two backends integrate the same problem. Negative control: an elastic
    family's effective chains are switched to RKN4 there."""
    import granchain as gc

    damped = gc.RandomDecorated(4, contact=gc.Viscoelastic(0.05))
    cpu = EnsembleSpec(damped, realizations=4).chain_integrators
    gpu = EnsembleSpec(damped, realizations=4, backend=DefaultsToRkn()).chain_integrators
    assert gpu == cpu
    assert {i.name for i in gpu.values()} == {"dp5"} and gpu["effective"].rtol < gpu["decorated"].rtol
    assert EnsembleSpec(FAMILY, realizations=4, backend=DefaultsToRkn()).chain_integrators["effective"].name == "rkn4"


def test_a_design_on_a_backend_without_its_default_method_uses_rkn4():
    from granchain.design import TaperedSpace
    from granchain.design.evaluate import BatchEvaluator

    space = TaperedSpace(6, (0.0, 0.2), wall=False)
    assert BatchEvaluator(space, "transmitted-energy").integrator.name == "dp5"  # negative control
    on = BatchEvaluator(space, "transmitted-energy", backend=RknOnly())
    assert on.integrator.name == "rkn4" and on.describe()["backend"] == "rkn-only"
    assert BatchEvaluator(space, "transmitted-energy", backend=DefaultsToRkn()).integrator.name == "rkn4"
    assert BatchEvaluator(space, "transmitted-energy", backend=RunsBoth()).integrator.name == "dp5"


def test_pulse_backend_cpu_is_the_default_and_cuda_picks_rkn4(capsys):
    """``granchain pulse --backend cpu`` prints what the default prints; with ``--backend cuda`` and no
    ``--integrator`` the integrator is RKN4 (the GPU's default, the method measured there), not DP5, except for
    contacts that dissipate."""
    import argparse

    from granchain.cli import main
    from granchain.cli.pulse import _integrator

    assert main(["pulse", "--radii", "1,0.5,1"]) == 0
    default = capsys.readouterr().out
    assert main(["pulse", "--radii", "1,0.5,1", "--backend", "cpu"]) == 0
    assert capsys.readouterr().out == default
    args = argparse.Namespace(integrator=None, rtol=None, atol=None, dt=None, backend="cuda")
    assert _integrator(args).name == "rkn4"
    assert _integrator(argparse.Namespace(**{**vars(args), "backend": "cpu"})).name == "dp5"
    assert _integrator(argparse.Namespace(**{**vars(args), "integrator": "dp5"})).name == "dp5"
    assert _integrator(args, conservative=False).name == "dp5"  # damped contacts: RKN4 cannot integrate them
