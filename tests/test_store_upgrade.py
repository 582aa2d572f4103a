"""Stores survive upgrades: a store written by granchain 0.4.0 (fixtures in tests/data, written by
that version: make_v0.4.0_fixtures.py) is resumed and extended by this version bitwise, because a
resumed store is compared on its results version, not on the package version.
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
        assert_same_results(resumed, fixture.load())
    assert_same_results(resumed, _run(make(), **kw))
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
    assert_same_results(extended, _run(make(), **more))


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
