"""One schema drives the compute buffers, the writer and every reader; ``granchain.open_store`` is the
one way granchain opens a store.

* ``open_store`` returns a fresh store as stored, and a store of granchain 0.1.0 or 0.4.0 (fixtures in
  tests/data, written by those versions) with today's records and metadata, without writing anything;
  a path that is not a store gets an error saying what to give instead.
* Every reader goes through it: no module but the store's calls ``xarray.open_zarr`` (checked on the
  source, with a negative control), and each reader, given a store's path, calls it (a spy).
* The chunk's compute buffers are the schema's: a chunk's result holds exactly the schema's variables,
  in their dtypes, and a variable added to the schema gets its buffer, reaches the integrator and is
  stored.
"""

from __future__ import annotations

import ast
import hashlib
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import scipy.stats as st
import xarray as xr
from conftest import FIXTURE_GRID, FIXTURES_040

import granchain as gc
from granchain.ensembles import read, schema, store
from granchain.ensembles import run as ens

DATA = Path(__file__).parent / "data"
PACKAGE = Path(gc.__file__).parent
GRID = FIXTURE_GRID
FAMILY = gc.RandomDecorated(4)
RUN = dict(realizations=6, seed=1, chunk_size=3)


@pytest.fixture(scope="module")
def fresh(tmp_path_factory):
    path = tmp_path_factory.mktemp("open") / "s.zarr"
    gc.run_ensemble(FAMILY, out=path, progress=False, threads=1, **RUN)
    return path


def tree_digest(path: Path) -> str:
    """One hash of every file (name and bytes) under ``path``: any write changes it."""
    h = hashlib.blake2b(digest_size=16)
    for file in sorted(p for p in path.rglob("*") if p.is_file()):
        h.update(str(file.relative_to(path)).encode() + b"\0" + file.read_bytes())
    return h.hexdigest()


def assert_same_values(a: xr.Dataset, b: xr.Dataset) -> None:
    assert set(a.variables) == set(b.variables)
    for name in a.variables:
        assert a[name].dtype == b[name].dtype, name
        np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=name)


# -- open_store on stores of this version and of earlier ones ----------------------------------------
def test_one_function_in_three_places():
    assert gc.open_store is read.open_store is gc.ensembles.open_store
    assert "open_store" in gc.__all__ and "open_store" in gc.ensembles.__all__


@pytest.mark.parametrize("load", [False, True])
def test_a_fresh_store_opens_as_stored(fresh, load):
    before = tree_digest(fresh)
    for group in (None, "progress"):
        with xr.open_zarr(fresh, group=group, consolidated=False) as raw:
            ds = gc.open_store(fresh, group=group, load=load)
            assert_same_values(ds, raw.load())
            assert ds.attrs == raw.attrs
            for name in raw.variables:
                assert ds[name].attrs == raw[name].attrs, name
            # lazy: Dask arrays read when used; load=True: NumPy arrays in memory
            assert (ds["done" if group else "peak_velocity"].chunks is None) == load
    assert tree_digest(fresh) == before  # nothing written




@pytest.mark.parametrize("name", sorted(FIXTURES_040))
def test_a_040_store_opens_with_todays_records_and_metadata(name, tmp_path):
    """The records are those this version writes for the same run (a resume compares them equal), the
    metadata those of a fresh store of the same parameters, the values the stored ones, and nothing
    on disk changes (resuming is what rewrites the metadata)."""
    make, kw = FIXTURES_040[name]
    path = tmp_path / name
    shutil.copytree(DATA / name, path)
    before = tree_digest(path)
    ds = gc.open_store(path)
    kw = dict(kw)  # run_ensemble's integrator dict is the spec's chain_integrators
    spec = ens.EnsembleSpec(make(), chains="both", chain_integrators=kw.pop("integrator"), **kw)
    assert json.loads(ds.attrs["granchain_parameters"]) == spec.describe()
    assert json.loads(ds.attrs["granchain_family"]) == make().describe()
    assert json.loads(ds.attrs["granchain_integrator"]) == spec.integrator.describe()
    assert ds.attrs["granchain_version"] == "0.4.0"  # where it came from is kept
    reference = store.empty_dataset(spec, lazy=True)
    for var in ds.variables:
        assert ds[var].attrs == reference[var].attrs, var
    with xr.open_zarr(path, consolidated=False) as raw:
        assert_same_values(ds, raw)
        # negative control: the store itself holds the old records and units
        assert "results_version" not in json.loads(raw.attrs["granchain_parameters"])
        assert raw["peak_time"].attrs["units"] != "1"
    progress = gc.open_store(path, group="progress", load=True)
    assert progress.attrs["granchain_parameters"] == ds.attrs["granchain_parameters"]
    assert progress["sum_v"].attrs == dict(next(v for v in store.PROGRESS if v.name == "sum_v").metadata())
    assert tree_digest(path) == before
    if "tapered" in name:  # 0.4's q was the ratio of successive radii: today's q = 1 - 0.9
        assert ds.attrs["q"] == pytest.approx(0.1) and gc.family_from_dataset(ds) == make()


@pytest.mark.parametrize("name, family, seed, realizations, chunk_size", [
    ("v0.1.0-decorated-N6.zarr", lambda: gc.RandomDecorated(6, gc.Uniform(0.01, 0.4)), 7, 24, 10),
    ("v0.1.0-truncated-N5.zarr", lambda: gc.RandomDecorated(5, gc.Truncated(st.beta(2, 8), upper=0.4)),
     3, 12, 5),
])
def test_a_010_store_opens_with_its_family_and_integrator_as_records(name, family, seed, realizations, chunk_size):
    """0.1.0 named its family and its one integrator (the exact DP5) by flat fields: open_store gives the
    records today's run of the same realisations writes (it reproduces them bitwise, test_families)."""
    ds = gc.open_store(DATA / name)
    spec = ens.EnsembleSpec(family(), realizations, seed, "both", gc.DP5(1e-6, 1e-9), np.round(np.arange(0.0, 20.05, 0.5), 12),
                            chunk_size)
    assert json.loads(ds.attrs["granchain_parameters"]) == spec.describe()
    assert json.loads(ds.attrs["granchain_family"]) == family().describe()
    assert gc.family_from_dataset(ds) == family() == gc.family_from_dataset(DATA / name)
    with xr.open_zarr(DATA / name, consolidated=False) as raw:
        assert "granchain_family" not in raw.attrs  # negative control: the store has no family record
        assert_same_values(ds, raw)
    assert "peak_force" not in ds  # nothing is made up: 0.1.0 stored no contact forces


def test_an_exported_netcdf_file_opens_as_its_store(fresh, tmp_path):
    pytest.importorskip("netCDF4")
    from granchain.cli.export import export

    nc = export(fresh, tmp_path / "s.nc")
    ds, zarr_ds = gc.open_store(nc, load=True), gc.open_store(fresh, load=True)
    assert_same_values(ds, zarr_ds)  # n_steps, n_valid, ... back in 64 bits
    for name in zarr_ds.variables:
        assert ds[name].attrs == zarr_ds[name].attrs, name
    assert ds.attrs["granchain_parameters"] == zarr_ds.attrs["granchain_parameters"]
    with pytest.raises(ValueError, match="netCDF export, which holds the results only"):
        gc.open_store(nc, group="progress")


@pytest.mark.parametrize("make, words", [
    (lambda tmp: tmp / "missing.zarr", "does not exist"),
    (lambda tmp: (tmp / "empty.zarr").mkdir() or tmp / "empty.zarr", "is not a granchain ensemble store"),
    (lambda tmp: (tmp / "notes.txt").write_text("x") and tmp / "notes.txt", "neither a Zarr store"),
    (lambda tmp: xr.Dataset({"a": ("x", [1.0])}).to_zarr(tmp / "other.zarr", zarr_format=2, consolidated=False)
     and tmp / "other.zarr", "is not a granchain ensemble store"),
])
def test_a_path_that_is_not_a_store_says_what_to_give(make, words, tmp_path):
    path = make(tmp_path)
    with pytest.raises(ValueError, match=words) as exc:
        gc.open_store(path)
    assert str(path) in str(exc.value) and "granchain ensemble --out" in str(exc.value)


def test_other_groups_and_damaged_stores_are_refused_with_what_to_do(fresh, tmp_path):
    with pytest.raises(ValueError, match="group must be None"):
        gc.open_store(fresh, group="results")
    damaged = tmp_path / "d.zarr"
    shutil.copytree(fresh, damaged)
    (damaged / "peak_time" / ".zarray").write_text("{ not json")
    with pytest.raises(ValueError, match=r"could not be read.*granchain info"):
        gc.open_store(damaged)
    from granchain.cli import (
        info,  # which still reports what it can read of such a store, and what is damaged
    )

    facts = info.summary(str(damaged))
    assert "could not be read" in facts["unreadable"] and facts["realizations"] == RUN["realizations"]
    assert set(facts["damaged_chunks"]) == {0, 1} and "peak_time" in facts["damaged_chunks"][0]


# -- every reader goes through open_store --------------------------------------------------------------
def opens_zarr_directly(source: str) -> list[int]:
    """Lines of ``source`` that open a Zarr store with xarray directly: ``*.open_zarr(...)`` or
    ``*.open_dataset(..., engine="zarr")``."""
    lines = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.Call):
            continue
        name = node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", "")
        zarr_engine = any(k.arg == "engine" and isinstance(k.value, ast.Constant) and k.value.value == "zarr"
                          for k in node.keywords)
        if name == "open_zarr" or (name == "open_dataset" and zarr_engine):
            lines.append(node.lineno)
    return lines


def test_the_check_finds_direct_opens():
    """Negative control: the ways granchain's readers used to open stores are found."""
    assert opens_zarr_directly("import xarray as xr\nds = xr.open_zarr(p, consolidated=False)\n") == [2]
    assert opens_zarr_directly("from xarray import open_zarr\nopen_zarr(p, group='progress')\n") == [2]
    assert opens_zarr_directly("xr.open_dataset(p, engine='zarr')\n") == [1]
    assert opens_zarr_directly("xr.open_dataset('theory.nc')\nopen_store(p)\n") == []


def test_no_module_but_the_store_opens_zarr_with_xarray():
    """Only the store's own modules open Zarr with xarray: the writer (``sinks``: resuming, checking
    chunks) and the reader (``read``: :func:`granchain.open_store`); every other module goes through
    ``open_store``."""
    own = {PACKAGE / "ensembles" / "sinks.py", PACKAGE / "ensembles" / "read.py"}
    found = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        if path in own:
            continue
        lines = opens_zarr_directly(path.read_text())
        if lines:
            found[str(path.relative_to(PACKAGE))] = lines
    assert found == {}, f"open stores with granchain.open_store, not xarray directly: {found}"
    assert all(opens_zarr_directly(path.read_text()) for path in own)  # the places that do


def test_every_reader_given_a_path_calls_open_store(fresh, tmp_path, monkeypatch):
    from granchain import analysis
    from granchain.cli import info
    from granchain.cli import theory as cli_theory
    from granchain.paper.figures import theory as fig_theory

    calls = []
    real = read.open_store

    def spy(path, **kw):
        calls.append((str(path), kw.get("group")))
        return real(path, **kw)

    monkeypatch.setattr(read, "open_store", spy)
    readers = {
        "family_from_dataset": lambda: gc.family_from_dataset(fresh),
        "stored_record": lambda: store.stored_record(fresh, "parameters"),
        "analysis.mean_peak_amplitude": lambda: analysis.mean_peak_amplitude(fresh),
        "analysis.averaged_pulse_peak": lambda: analysis.averaged_pulse_peak(fresh),
        "ChunkSums.from_store": lambda: analysis.ChunkSums.from_store(fresh),
        "granchain info": lambda: info.summary(str(fresh)),
        "granchain theory --compare": lambda: cli_theory._measured(fresh, FAMILY.n_large, "uniform"),
        "theory figure": lambda: fig_theory._measured(fresh, None, FAMILY.n_large),
    }
    try:
        import netCDF4  # noqa: F401

        from granchain.cli.export import export

        readers["granchain export"] = lambda: export(fresh, tmp_path / "x.nc", force=True)
    except ImportError:
        pass
    for label, reader in readers.items():
        calls.clear()
        reader()
        assert (str(fresh), None) in calls or (str(fresh), "progress") in calls, label
    calls.clear()
    analysis.ChunkSums.from_store(fresh)
    assert (str(fresh), "progress") in calls  # the jackknife reads the per-chunk sums through it too


def test_the_validity_map_reads_its_sums_through_open_store(tmp_path, monkeypatch):
    from granchain.paper import validity

    calls = []
    real = read.open_store
    monkeypatch.setattr(read, "open_store", lambda path, **kw: calls.append((Path(path), kw.get("group"))) or real(path, **kw))
    path = tmp_path / "point.zarr"
    res = validity._run_point(gc.Uniform(0.05, 0.3), 4, 8, 1, 2, path, gc.DP5.relaxed(), False)
    assert (path, "progress") in calls and res["valid_realizations"] == 8


def test_analysis_of_a_path_is_the_analysis_of_its_dataset(fresh):
    from granchain import analysis

    by_path, by_ds = analysis.mean_peak_amplitude(fresh), analysis.mean_peak_amplitude(gc.open_store(fresh))
    np.testing.assert_array_equal(by_path.value, by_ds.value)
    np.testing.assert_array_equal(analysis.averaged_pulse_peak(fresh, "effective").velocity,
                                  analysis.averaged_pulse_peak(gc.open_store(fresh), "effective").velocity)


# -- the compute buffers are the schema's --------------------------------------------------------------
@pytest.mark.parametrize("family, lags", [
    (FAMILY, None),
    (gc.RandomRadii(5, gc.Uniform(0.6, 1.0), wall=True), np.arange(-1.0, 1.01, 0.5)),
], ids=["decorated", "polydisperse-wall-aligned"])
def test_a_chunk_holds_the_schema_variables_and_nothing_else(family, lags):
    spec = ens.EnsembleSpec(family, realizations=5, seed=2, chunk_size=5, lags=lags)
    res = ens.compute_chunk(spec, 0)
    variables = {v.name: v for v in store.chunk_variables(spec)}
    assert set(res) - {"chunk", "realizations"} == set(variables)
    sizes = {**store.sizes(spec), "realization": 5}
    for name, v in variables.items():
        assert res[name].dtype == np.dtype(v.dtype), name
        assert res[name].shape == tuple(sizes[d] for d in v.dims if d != "chunk"), name
    assert ("peak_wall_force" in variables) == family.wall and ("sum_a" in variables) == (lags is not None)


@pytest.fixture
def marker(monkeypatch):
    """A per-realisation result added to the schema (dtype and fill of its own), which the backend's batch
    seam (``Backend.run_batch``, through which every chunk runs) fills with the number of granules of the
    chains it integrates."""
    from granchain.backends import Backend

    added = store.Variable("marker", ("chain", "realization"), "int16", -7, "1", "granules of the chain (test)")
    monkeypatch.setattr(schema, "RESULTS", schema.RESULTS + (added,))
    seen = []
    run_batch = Backend.run_batch

    def run_and_mark(self, integrator, batch, buffers, **kw):
        seen.append((buffers["marker"].dtype, buffers["marker"].copy()))
        run_batch(self, integrator, batch, buffers, **kw)
        buffers["marker"][:] = batch.masses.shape[1]

    monkeypatch.setattr(Backend, "run_batch", run_and_mark)
    return seen


def test_a_variable_added_to_the_schema_gets_its_buffer_and_is_stored(marker, tmp_path):
    path = tmp_path / "marked.zarr"
    memory = gc.run_ensemble(FAMILY, progress=False, threads=1, **RUN)
    disk = gc.run_ensemble(FAMILY, out=path, progress=False, threads=1, **RUN)
    # allocated from the schema: its dtype and its fill value (not computed) when the integrator gets it
    assert marker and all(dtype == np.int16 and np.all(values == -7) for dtype, values in marker)
    expected = np.array([[2 * FAMILY.n_large - 1] * RUN["realizations"], [FAMILY.n_large] * RUN["realizations"]])
    for ds in (memory, disk, gc.open_store(path, load=True)):
        assert ds["marker"].dtype == np.int16 and ds["marker"].dims == ("chain", "realization")
        np.testing.assert_array_equal(ds["marker"].values, expected)
    assert "marker" in gc.open_store(path, group="progress")["checked"].values  # and checksummed, like every result


def test_without_the_added_variable_there_is_no_buffer():
    """Negative control of the test above: the buffers follow the schema, not a list in the runner."""
    spec = ens.EnsembleSpec(FAMILY, realizations=2, chunk_size=2)
    assert "marker" not in ens.chunk_buffers(spec, 2) and "marker" not in ens.compute_chunk(spec, 0)


# -- stores of earlier versions are verified as far as their checksums go ------------------------------
def test_a_040_store_is_verified_by_its_values_and_a_resume_keys_its_checksums(tmp_path):
    """0.4.0 checksummed the values alone: a reader verifies those (a flipped value is refused), finds nothing
    wrong with the fixture, and a resume re-keys them (checksum_scheme 2), seals the averaged pulse and the
    attributes, and changes no value."""
    import warnings

    import zarr

    from granchain.ensembles.verify import StoreDamagedError, verify_store

    name = "v0.4.0-decorated-N6.zarr"
    make, kw = FIXTURES_040[name]
    path = tmp_path / name
    shutil.copytree(DATA / name, path)
    found = verify_store(path)
    assert found.scheme == 1 and found.ok and found.complete
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        before = gc.open_store(path, load=True)
    flipped = tmp_path / "flipped.zarr"
    shutil.copytree(path, flipped)
    arr = zarr.open_array(str(flipped / "peak_time"), mode="r+", zarr_format=2)
    arr[1, 9, 2] = arr[1, 9, 2] + 1e-9
    with pytest.raises(StoreDamagedError, match=r"chunk 1 does not match its checksum: the data file peak_time/0\.1\.0"):
        gc.open_store(flipped, load=True)
    with pytest.warns(store.StoreRepairWarning):  # the metadata brought up to date
        gc.run_ensemble(make(), out=path, progress=False, threads=1, chains="both", **kw)
    found = verify_store(path)
    assert found.scheme == 2 and found.ok, found
    assert_same_values(gc.open_store(path, load=True)[[v for v in before.data_vars]], before)


def test_a_010_store_has_nothing_to_verify_and_opens_quietly():
    import warnings

    from granchain.ensembles.verify import verify_store

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gc.open_store(DATA / "v0.1.0-decorated-N6.zarr", load=True)
    assert verify_store(DATA / "v0.1.0-decorated-N6.zarr").scheme == 0
