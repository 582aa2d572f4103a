"""Bad input fails with a message naming the parameter (API) or option (CLI), never a traceback; inputs that cannot work are refused before anything runs or is written."""

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
    from granchain.solve.integrators import VerletStabilityWarning

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


# -- inputs that used to run silently --------------------------------------------------------------

def test_empty_validity_grid_is_refused_before_anything_is_written(tmp_path, capsys):
    from granchain.paper import validity

    with pytest.raises(ValueError, match=r"no grid point has alpha < beta \(alphas=\[0.5\], betas=\[0.1\]\)"):
        validity.validity_map(tmp_path / "api", alphas=[0.5], betas=[0.1], n_large=4, progress=False)
    assert not (tmp_path / "api").exists()
    out = tmp_path / "v"
    code = main(["validity", "--out", str(out), "--alphas", "0.5", "--betas", "0.1", "--quick"])
    stdout, err = capsys.readouterr()
    assert code == 2 and stdout == "" and "give at least one alpha below a beta" in err
    assert not out.exists()


def test_validity_report_reads_sensibly_where_a_row_has_no_point(tmp_path):
    """alpha = 0.3 has no beta above it in the grid: the summary says nothing about it, instead of
    splicing "N=6, alpha=0.3: < 0.1" into the sentence."""
    from granchain.paper import validity

    ds = validity.validity_map(tmp_path / "v", alphas=[0.05, 0.3], betas=[0.1, 0.2], n_large=4, realizations=20, blocks=4,
                               progress=False, netcdf=False)
    text = validity.report_section(ds)
    assert "alpha = 0.3" not in text and "alpha=0.3" not in text
    for line in text.splitlines():
        if line.startswith("- "):
            assert "(N = 4, alpha = 0.05)" in line, line


@pytest.mark.parametrize("make, words", [
    (lambda: gc.DP5(rtol=2), "rtol = 2 must lie in (0, 1)"),
    (lambda: gc.RKN4(rtol=1.0), "rtol = 1 must lie in (0, 1)"),
    (lambda: gc.DOP853(atol=1.5), "atol = 1.5 must lie in (0, 1)"),
    (lambda: gc.DP5.relaxed(0.005), "rtol * relaxed_factor = 5 must stay below 1"),
    (lambda: gc.DP5(rtol=0), "rtol must be > 0"),
])
def test_tolerances_outside_zero_one_are_refused(make, words):
    with pytest.raises(ValueError) as exc:
        make()
    assert words in str(exc.value)


def test_cli_ensemble_with_rtol_2_writes_no_store(tmp_path, capsys):
    store = tmp_path / "r.zarr"
    code = main(["ensemble", "--large", "6", "--realizations", "10", "--rtol", "2", "--out", str(store)])
    out, err = capsys.readouterr()
    assert code == 2 and out == "" and "rtol = 2 must lie in (0, 1)" in err
    assert not store.exists()


def test_integrator_dict_may_name_kinds_the_run_does_not_compute():
    """One dict for runs of either chain: the unused kind's integrator is ignored, the results are
    bitwise those of the dict without it."""
    fam = gc.RandomDecorated(4)
    kw = dict(realizations=4, chains=("decorated",), progress=False, threads=1)
    extra = gc.run_ensemble(fam, integrator={"decorated": gc.DP5(1e-6, 1e-9), "effective": gc.Verlet(0.01)}, **kw)
    alone = gc.run_ensemble(fam, integrator={"decorated": gc.DP5(1e-6, 1e-9)}, **kw)
    np.testing.assert_array_equal(extra["peak_time"].values, alone["peak_time"].values)
    np.testing.assert_array_equal(extra["peak_velocity"].values, alone["peak_velocity"].values)


@pytest.mark.parametrize("integrator, words", [
    ({"decorated": gc.DP5(), "efective": gc.DP5()}, "names chain kinds ['efective'] that the family RandomDecorated does not have"),
    ({"effective": gc.DP5()}, "no integrator for the chain kinds ['decorated'] this run computes"),
])
def test_integrator_dict_errors_say_what_is_wrong(integrator, words):
    with pytest.raises(ValueError) as exc:
        gc.run_ensemble(gc.RandomDecorated(4), realizations=4, chains=("decorated",), integrator=integrator, progress=False)
    assert words in str(exc.value)
