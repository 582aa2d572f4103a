"""Bad input fails with a message naming the parameter (API) or option (CLI), never a traceback (issue 10)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import granchain as gc
import granchain.analysis as analysis
import granchain.bca as bca
from granchain.cli import main

API = [
    (lambda: gc.run_ensemble(6, realizations=4, seed=-1, progress=False), "seed"),
    (lambda: gc.run_ensemble(6, realizations=4, seed="abc", progress=False), "seed"),
    (lambda: gc.run_ensemble(6, realizations=4, seed=1.5, progress=False), "seed"),
    (lambda: gc.run_ensemble(6, realizations=4, threads=0, progress=False), "threads"),
    (lambda: gc.run_ensemble(6, realizations=4, threads=99, progress=False), "threads"),
    (lambda: gc.run_ensemble(6, realizations=4, out="", progress=False), "out"),
    (lambda: gc.run_ensemble(6, realizations=4, out="/proc/x.zarr", progress=False), "out"),
    (lambda: gc.run_ensemble(6, realizations=4, resume="yes", progress=False), "resume"),
    (lambda: gc.decorated([2.0]), "small_radii"),
    (lambda: analysis.fit_stretched_exp([], []), "fit_stretched_exp"),
    (lambda: analysis.averaged_pulse_peak("x"), "ds"),
]


@pytest.mark.parametrize("call, name", API, ids=[f"api-{i}-{n}" for i, (_, n) in enumerate(API)])
def test_api_names_the_parameter(call, name):
    with pytest.raises(ValueError, match=name):
        call()


def test_api_regular_file_as_out(tmp_path):
    f = tmp_path / "file.zarr"
    f.write_text("x")
    with pytest.raises(ValueError, match="existing file"):
        gc.run_ensemble(6, realizations=4, out=f, progress=False)


def test_bca_A_is_finite_for_large_n():
    assert np.isfinite(bca.A(1e6)) and abs(bca.A(2.5) - 2.43884) < 1e-5


def test_simulate_warns_when_it_does_not_succeed():
    chain = gc.random_decorated(6, seed=0, realization=0)
    with pytest.warns(RuntimeWarning, match="MAX_STEPS"):
        r = gc.simulate(chain, max_steps=10)
    assert not r.ok
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert gc.simulate(chain).ok  # no warning on success


def test_verlet_warns_beyond_its_stability_limit():
    chain = gc.random_decorated(6, seed=0, realization=0)
    from granchain._integrators import VerletStabilityWarning

    with pytest.warns(VerletStabilityWarning, match="dt"):
        gc.simulate(chain, gc.Verlet(dt=0.05))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert gc.simulate(chain, gc.Verlet()).ok  # the default step is stable


ENS = ["ensemble", "--large", "6", "--realizations", "4", "--quiet"]
CLI = [
    (ENS + ["--dt", "0", "--out", "{tmp}/a.zarr"], "--dt"),
    (ENS + ["--out", "/proc/x.zarr"], "out"),
    (ENS + ["--out", ""], "--out"),
    (ENS + ["--threads", "0", "--out", "{tmp}/a.zarr"], "--threads"),
    (ENS + ["--threads", "-2", "--out", "{tmp}/a.zarr"], "--threads"),
    (ENS + ["--out", "{tmp}/file"], "existing file"),
    (ENS + ["--seed", "-1", "--out", "{tmp}/a.zarr"], "--seed"),
    (ENS + ["--scheduler", "tcp://127.0.0.1:9", "--out", "{tmp}/a.zarr"], "--scheduler"),
    (["pulse", "--small-radii", "0.1,,0.2"], "--small-radii"),
    (["pulse", "--small-radii", "0.1,0.2", "--momentum-conserving"], "--momentum-conserving"),
    (["reproduce", "--realizations", "3", "--out", "{tmp}/r"], "--realizations"),
    (["reproduce", "--seed", "-1", "--out", "{tmp}/r"], "--seed"),
    (["reproduce", "--out", ""], "--out"),
    (["reproduce", "--out", "/proc/x"], "--out"),
    (["info", "{tmp}/missing.zarr"], "missing.zarr"),
    (["export", "{tmp}/missing.zarr", "{tmp}/x.nc"], "missing.zarr"),
]


@pytest.mark.parametrize("argv, name", CLI, ids=[f"cli-{i}-{a[0]}" for i, (a, _) in enumerate(CLI)])
def test_cli_names_the_option_without_traceback(argv, name, tmp_path, capsys):
    (tmp_path / "file").write_text("x")
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == 2, err
    assert name in err and "error" in err
    assert "Traceback" not in err
