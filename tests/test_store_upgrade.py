"""Stores survive upgrades: a store written by granchain 0.4.0 (fixtures in tests/data, written by
that version: make_v0.4.0_fixtures.py) is resumed and extended by this version, because a resumed
store is compared on its results version, not on the package version: what it holds is kept bitwise,
what this version adds is bitwise a fresh run's on this machine, and a fresh run agrees with the
fixture, written on another machine, within the accuracy contract (:data:`CONTRACT`).
"""

from __future__ import annotations

import json
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from conftest import FIXTURE_GRID, FIXTURES_040

import granchain as gc
from granchain._version import RESULTS_VERSION
from granchain.ensembles.store import (
    StoreRepairWarning,
    check_same_parameters,
    current_record,
)

DATA = Path(__file__).parent / "data"
GRID = FIXTURE_GRID
FIXTURES = FIXTURES_040
#: Every result a store holds (per realisation and averaged); metadata are allowed to change.
RESULTS = ("peak_velocity", "peak_time", "status", "energy_error", "n_steps", "t_end", "peak_force", "peak_force_time",
           "peak_wall_force", "peak_wall_force_time", "small_radius", "mean_velocity", "mean_velocity_stderr", "n_valid",
           "aligned_velocity", "aligned_velocity_stderr")


def assert_same_results(a: xr.Dataset, b: xr.Dataset) -> None:
    names = [n for n in RESULTS if n in a or n in b]
    for name in names:
        np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=name)


#: What the same computation on another processor may differ by. Numba compiles the kernels for the
#: processor it runs on (vector widths, the maths library's last bit), so a fixture written on one machine
#: and a fresh run on another agree within the accuracy contract, not bitwise; the step controller's and
#: the stop rule's decisions taken at round-off distance from a threshold may then differ, so the run's
#: own bookkeeping (steps, end time, energy error of a run that went on longer) is not compared across
#: machines. Measured for the tapered-wall fixture on an AMD EPYC against the machine that wrote it:
#: peaks 3.6e-8 relative, times 5e-10, averaged pulse 1.2e-7, 4 of 24 end times moved by the stop rule.
CONTRACT = {"peak_velocity": dict(rtol=1e-6, atol=0), "peak_time": dict(rtol=0, atol=1e-6),
            "peak_force": dict(rtol=1e-6, atol=0), "peak_force_time": dict(rtol=0, atol=1e-6),
            "peak_wall_force": dict(rtol=1e-6, atol=0), "peak_wall_force_time": dict(rtol=0, atol=1e-6),
            "mean_velocity": dict(rtol=0, atol=1e-6), "mean_velocity_stderr": dict(rtol=0, atol=1e-6),
            "aligned_velocity": dict(rtol=0, atol=1e-6), "aligned_velocity_stderr": dict(rtol=0, atol=1e-6),
            "status": dict(rtol=0, atol=0), "small_radius": dict(rtol=0, atol=0), "n_valid": dict(rtol=0, atol=0)}


def assert_same_within_contract(a: xr.Dataset, b: xr.Dataset) -> None:
    """``a`` and ``b`` computed by the same code on two machines (see :data:`CONTRACT`)."""
    for name, tol in CONTRACT.items():
        if name in a or name in b:
            np.testing.assert_allclose(a[name].values, b[name].values, err_msg=name, equal_nan=True, **tol)


def assert_new_realisations_as_fresh(extended: xr.Dataset, fresh: xr.Dataset, first: int) -> None:
    """The realisations from ``first`` on, computed by this version on this machine: bitwise a fresh run's."""
    per_realisation = [n for n in RESULTS if n in extended and "realization" in extended[n].dims]
    for name in per_realisation:
        np.testing.assert_array_equal(extended[name].isel(realization=slice(first, None)).values,
                                      fresh[name].isel(realization=slice(first, None)).values, err_msg=name)


def _copy(name, tmp_path) -> Path:
    path = tmp_path / name
    shutil.copytree(DATA / name, path)
    return path


def _run(family, path=None, **kw):
    return gc.run_ensemble(family, out=path, progress=False, threads=1, chains="both", **kw)


@pytest.mark.parametrize("name", sorted(FIXTURES))
def test_a_040_store_reads_as_todays_family(name):
    make, _ = FIXTURES[name]
    with xr.open_zarr(DATA / name, consolidated=False) as ds:
        assert ds.attrs["granchain_version"] == "0.4.0"
        assert gc.family_from_dataset(ds) == make()


@pytest.mark.parametrize("name", sorted(FIXTURES))
def test_a_040_store_resumes_with_its_metadata_brought_up_to_date(name, tmp_path):
    """Resumed by this version: nothing is recomputed, the results are the fixture's and a fresh run's
    bitwise, one warning says which metadata were rewritten, and afterwards every units attribute is
    one pint reads."""
    make, kw = FIXTURES[name]
    path = _copy(name, tmp_path)
    with pytest.warns(StoreRepairWarning, match="written by granchain 0.4.0") as caught:
        resumed = _run(make(), path, **kw)
    assert len([w for w in caught if issubclass(w.category, StoreRepairWarning)]) == 1
    with xr.open_zarr(DATA / name, consolidated=False) as fixture:
        assert_same_results(resumed, fixture.load())  # nothing recomputed
    assert_same_within_contract(resumed, _run(make(), **kw))  # the fixture was written on another machine
    with xr.open_zarr(path, consolidated=False) as ds:
        assert json.loads(ds.attrs["granchain_parameters"])["results_version"] == RESULTS_VERSION
        assert ds["peak_time"].attrs["units"] == "1" and ds["peak_time"].attrs["rescaled_quantity"] == "time"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a second resume has nothing left to bring up to date
        _run(make(), path, **kw)


@pytest.mark.parametrize("name", sorted(FIXTURES))
def test_a_040_store_is_extended_bitwise(name, tmp_path):
    make, kw = FIXTURES[name]
    path = _copy(name, tmp_path)
    more = {**kw, "realizations": kw["realizations"] + 2 * kw["chunk_size"]}
    with pytest.warns(StoreRepairWarning):
        extended = _run(make(), path, **more)
    with xr.open_zarr(DATA / name, consolidated=False) as fixture:
        old = fixture.load()
    n_old = old.sizes["realization"]
    per_realisation = [n for n in RESULTS if n in old and "realization" in old[n].dims]
    assert_same_results(extended[per_realisation].isel(realization=slice(0, n_old)), old[per_realisation])
    fresh = _run(make(), **more)
    assert_new_realisations_as_fresh(extended, fresh, n_old)
    assert_same_within_contract(extended, fresh)


def test_a_040_store_resumes_without_naming_its_pulse_window_or_integrators(tmp_path):
    """A store is continued as it was started: the call that made a 0.4.0 store with 0.4.0's defaults
    (the averaged pulse on the whole grid, the relaxed integrators at 0.4.0's looser tolerances) resumes
    it as it is, naming neither pulse_window="full" nor the integrators, and gives the fixture's results;
    the same call for a new store gets today's defaults, the trailing window with each granule's
    averaged-pulse window at today's tolerances (negative control: its record has them, the 0.4.0 one
    not)."""
    name = "v0.4.0-decorated-N6.zarr"
    make, kw = FIXTURES[name]
    kw = {k: v for k, v in kw.items() if k not in ("pulse_window", "integrator")}
    path = _copy(name, tmp_path)
    with pytest.warns(StoreRepairWarning):
        resumed = _run(make(), path, **kw)
    with xr.open_zarr(DATA / name, consolidated=False) as fixture:
        assert_same_results(resumed, fixture.load())
    stored = json.loads(resumed.attrs["granchain_parameters"])
    assert "pulse_window" not in stored
    fresh = _run(make(), tmp_path / "new.zarr", **kw)
    record = json.loads(fresh.attrs["granchain_parameters"])
    assert record["pulse_window"]["rule"] == "auto" and record["integrator"]["window_lag"] == 7
    assert record["integrator"]["rtol"] == gc.ENSEMBLE_RTOL != stored["integrator"]["rtol"]


def test_an_interrupted_040_store_is_finished_bitwise(tmp_path):
    """A chunk of the 0.4.0 store not done (its done flag lost): this version computes it, and the
    store equals a fresh run."""
    name = "v0.4.0-decorated-N6.zarr"
    make, kw = FIXTURES[name]
    path = _copy(name, tmp_path)
    (path / "progress" / "done" / "1").unlink()
    with pytest.warns(StoreRepairWarning):
        finished = _run(make(), path, **kw)
    assert_same_results(finished, _run(make(), **kw))


def test_the_record_names_the_results_version_not_the_package_version():
    from granchain.ensembles.run import EnsembleSpec

    record = EnsembleSpec(gc.RandomDecorated(4), realizations=2).describe()
    assert record["results_version"] == RESULTS_VERSION and "granchain_version" not in record
    old = {**{k: v for k, v in record.items() if k != "results_version"}, "granchain_version": "0.4.0"}
    assert current_record(old) == record


@pytest.mark.parametrize("stored, words", [
    ({"granchain_version": "9.9.9"}, "granchain_version: stored '9.9.9'"),  # a version it does not know: refused
    ({"results_version": RESULTS_VERSION + 1}, f"results_version: stored {RESULTS_VERSION + 1}"),
])
def test_other_results_versions_are_refused(stored, words):
    from granchain.ensembles.run import EnsembleSpec

    spec = EnsembleSpec(gc.RandomDecorated(4), realizations=2)
    record = {k: v for k, v in spec.describe().items() if k != "results_version"} | stored
    with pytest.raises(ValueError, match="results are never mixed") as exc:
        check_same_parameters("s.zarr", json.dumps(record), spec)
    assert words in str(exc.value)


def test_a_010_store_is_refused_with_what_to_do(tmp_path):
    path = _copy("v0.1.0-decorated-N6.zarr", tmp_path)
    with pytest.raises(ValueError, match=r"written by granchain 0.1.0.*cannot be resumed or extended.*DP5\(1e-6, 1e-9\)"):
        gc.run_ensemble(gc.RandomDecorated(6, gc.Uniform(0.01, 0.4)), realizations=24, seed=7, out=path, progress=False,
                        t_grid=np.round(np.arange(0.0, 20.05, 0.5), 12), chunk_size=10, integrator=gc.DP5(1e-6, 1e-9))
