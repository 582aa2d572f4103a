"""Bad inputs to the store's surface: ``open_store``, ``run_ensemble``'s store and run arguments, and the
``granchain ensemble`` / ``info`` / ``export`` command lines. Each is refused before anything is integrated,
with an error that names what to change (the harness: tests/_bad_inputs.py)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from _bad_inputs import Api, Cli, check

import granchain as gc

DATA = Path(__file__).parent / "data"
#: A cheap run: four large granules, the decorated chain only (one integrator, nothing compiled ahead),
#: no averaged-pulse windows (no pilot realisations).
RUN = dict(realizations=4, chunk_size=2, chains="decorated", pulse_window="full", progress=False, threads=1)


def _run(tmp, family=4, **kw):
    return gc.run_ensemble(family, **{**RUN, "out": tmp / "s.zarr", **kw})


def _not_a_store(tmp) -> Path:
    (tmp / "d").mkdir()
    _file(tmp / "d", "notes.txt")
    return tmp / "d"


def _fake_store(tmp, family=None, **kw) -> Path:
    """A directory holding only the parameter record of a store of ``family`` (as run_ensemble would write
    it for RUN and ``kw``): what a resume compares before anything is computed."""
    from granchain.ensembles.run import EnsembleSpec

    args = {**RUN, **kw}
    spec = EnsembleSpec(family or gc.RandomDecorated(4), args["realizations"], args.get("seed", 0), args["chains"],
                        chunk_size=args["chunk_size"], pulse_window=args["pulse_window"], backend=args.get("backend"))
    path = tmp / "s.zarr"
    path.mkdir()
    (path / ".zgroup").write_text('{"zarr_format": 2}')
    (path / ".zattrs").write_text(json.dumps({"granchain_parameters": json.dumps(spec.describe(), sort_keys=True)}))
    return path


def _plain_zarr(tmp) -> Path:
    import xarray as xr

    path = tmp / "other.zarr"
    xr.Dataset({"a": ("x", [1.0])}).to_zarr(path, zarr_format=2, consolidated=False)
    return path


def _plain_netcdf(tmp) -> Path:
    import xarray as xr

    pytest.importorskip("netCDF4")
    path = tmp / "other.nc"
    xr.Dataset({"a": ("x", [1.0])}).to_netcdf(path)
    return path


def _copy_010(tmp) -> Path:
    path = tmp / "old.zarr"
    shutil.copytree(DATA / "v0.1.0-decorated-N6.zarr", path)
    return path


def _garbled_records(tmp) -> Path:
    path = tmp / "garbled.zarr"
    (path / "progress").mkdir(parents=True)
    (path / ".zgroup").write_text('{"zarr_format": 2}')
    (path / ".zattrs").write_text("{ not json")
    (path / "progress" / ".zattrs").write_text("{ not json")
    return path


def _file(tmp, name="f.txt") -> Path:
    (tmp / name).write_text("x")
    return tmp / name


CASES = [
    # -- open_store -------------------------------------------------------------------------------------
    Api("open_store-path-None", lambda tmp: gc.open_store(None), r"path must be a str or os\.PathLike"),
    Api("open_store-path-number", lambda tmp: gc.open_store(123), r"path must be a str or os\.PathLike"),
    Api("open_store-missing", lambda tmp: gc.open_store(tmp / "missing.zarr"), r"does not exist.*granchain ensemble --out"),
    Api("open_store-empty-directory", lambda tmp: gc.open_store(tmp), r"not a granchain ensemble store.*--out PATH"),
    Api("open_store-text-file", lambda tmp: gc.open_store(_file(tmp)), r"neither a Zarr store .* nor a netCDF file"),
    Api("open_store-other-zarr", lambda tmp: gc.open_store(_plain_zarr(tmp)), r"not a granchain ensemble store"),
    Api("open_store-other-netcdf", lambda tmp: gc.open_store(_plain_netcdf(tmp)), r"not a granchain ensemble store"),
    Api("open_store-garbled-records", lambda tmp: gc.open_store(_garbled_records(tmp)), r"not a granchain ensemble store"),
    Api("open_store-group-results", lambda tmp: gc.open_store(tmp, group="results"), r"group must be None .* or 'progress'"),
    Api("open_store-load-string", lambda tmp: gc.open_store(tmp, load="yes"), r"load must be True .* or False"),
    Api("open_store-verify-string", lambda tmp: gc.open_store(tmp, verify="no"), r"verify must be True .* or False"),
    Api("open_store-verify-None", lambda tmp: gc.open_store(tmp, verify=None), r"verify must be True .* or False"),
    # -- run_ensemble: counts ------------------------------------------------------------------------------
    Api("run-realizations-zero", lambda tmp: _run(tmp, realizations=0), r"realizations must be >= 1"),
    Api("run-realizations-negative", lambda tmp: _run(tmp, realizations=-5), r"realizations must be >= 1"),
    Api("run-realizations-fraction", lambda tmp: _run(tmp, realizations=2.5), r"realizations must be a whole number"),
    Api("run-realizations-string", lambda tmp: _run(tmp, realizations="10"), r"realizations must be a whole number"),
    Api("run-realizations-bool", lambda tmp: _run(tmp, realizations=True), r"realizations must be a whole number"),
    Api("run-realizations-nan", lambda tmp: _run(tmp, realizations=float("nan")), r"realizations must be a whole number"),
    Api("run-chunk-size-zero", lambda tmp: _run(tmp, chunk_size=0), r"chunk_size must be >= 1"),
    Api("run-chunk-size-negative", lambda tmp: _run(tmp, chunk_size=-1), r"chunk_size must be >= 1"),
    Api("run-chunk-size-fraction", lambda tmp: _run(tmp, chunk_size=1.5), r"chunk_size must be a whole number"),
    Api("run-chunk-size-dtype-like", lambda tmp: _run(tmp, chunk_size="int64"), r"chunk_size must be a whole number"),
    Api("run-seed-negative", lambda tmp: _run(tmp, seed=-1), r"seed must be >= 0"),
    Api("run-seed-fraction", lambda tmp: _run(tmp, seed=1.5), r"seed must be a whole number"),
    Api("run-seed-string", lambda tmp: _run(tmp, seed="abc"), r"seed must be a whole number"),
    Api("run-threads-zero", lambda tmp: _run(tmp, threads=0), r"threads must be >= 1"),
    # -- run_ensemble: paths and the store -----------------------------------------------------------------
    Api("run-out-empty", lambda tmp: _run(tmp, out=""), r"out must be a non-empty path"),
    Api("run-out-number", lambda tmp: _run(tmp, out=123), r"out must be a path"),
    Api("run-out-existing-file", lambda tmp: _run(tmp, out=_file(tmp)), r"is an existing file, not a Zarr store"),
    Api("run-out-under-a-file", lambda tmp: _run(tmp, out=_file(tmp) / "s.zarr"), r"cannot create its folder"),
    Api("run-out-not-a-store", lambda tmp: _run(tmp, out=_not_a_store(tmp)),
        r"exists but is not a granchain ensemble store; choose another path"),
    Api("run-out-records-garbled", lambda tmp: _run(tmp, out=_garbled_records(tmp)), r"lost its parameter record.*rm -r"),
    Api("run-resume-string", lambda tmp: _run(tmp, resume="yes"), r"resume must be True or False"),
    Api("run-no-resume-existing", lambda tmp: _run(tmp, out=_fake_store(tmp), resume=False),
        r"already exists: pass resume=True"),
    Api("run-resume-other-seed", lambda tmp: _run(tmp, out=_fake_store(tmp, seed=5)),
        r"different parameters \(seed: stored 5, asked 0\)"),
    Api("run-resume-other-chunk-size", lambda tmp: _run(tmp, out=_fake_store(tmp, chunk_size=1)),
        r"different parameters \(chunk_size: stored 1, asked 2\)"),
    Api("run-resume-shrink", lambda tmp: _run(tmp, out=_fake_store(tmp, realizations=8)),
        r"realizations: stored 8, asked 4\).*never shrunk"),
    Api("run-resume-other-contacts", lambda tmp: _run(tmp, gc.RandomDecorated(4, contact=gc.Viscoelastic(0.05)),
                                                      out=_fake_store(tmp), integrator=gc.DP5()),
        r"written with different contact settings \(family\.contact\.gamma: stored None, asked 0\.05"),
    Api("run-resume-other-static-force", lambda tmp: _run(tmp, gc.RandomDecorated(4, static_force=0.1), out=_fake_store(tmp)),
        r"different contact settings \(family\.static_force: stored None, asked 0\.1\)"),
    Api("run-resume-0.1.0-store", lambda tmp: _run(tmp, gc.RandomDecorated(6), out=_copy_010(tmp)),
        r"written by granchain 0\.1\.0.*cannot be resumed"),
    Api("run-chains-unknown", lambda tmp: _run(tmp, chains="granular"), r"chains must be one or more of"),
    Api("run-t-grid-empty", lambda tmp: _run(tmp, t_grid=[]), r"t_grid must be a non-empty, finite, increasing"),
    Api("run-t-grid-decreasing", lambda tmp: _run(tmp, t_grid=[0.0, 1.0, 0.5]), r"t_grid must be .*increasing"),
    Api("run-lags-empty", lambda tmp: _run(tmp, lags=[]), r"lags must be a non-empty"),
    Api("run-pulse-window-unknown", lambda tmp: _run(tmp, pulse_window="half"), r"pulse_window must be 'auto'"),
    # -- run_ensemble: the backend -------------------------------------------------------------------------
    Api("run-backend-unknown", lambda tmp: _run(tmp, backend="gpu"), r"backend must be one of \['cpu', .*'cuda'\]"),
    Api("run-backend-number", lambda tmp: _run(tmp, backend=1), r"backend must be one of .* or a granchain.backends.Backend"),
    Api("run-backend-integrator-name", lambda tmp: _run(tmp, backend="dp5"), r"backend must be one of"),
    Api("run-switch-backend-string", lambda tmp: _run(tmp, switch_backend="yes"), r"switch_backend must be True or False"),
    Api("run-resume-other-backend", lambda tmp: _run(tmp, out=_fake_store(tmp), backend="numba"),
        r"computed with the 'cpu' backend and this run asks for 'numba'.*switch_backend=True"),
    Api("run-resume-store-of-another-backend", lambda tmp: _run(tmp, out=_fake_store(tmp, backend="numba")),
        r"computed with the 'numba' backend and this run asks for 'cpu'.*backend='numba'"),
    # -- granchain ensemble ----------------------------------------------------------------------------
    *[Cli(f"ensemble-{flag[2:]}-{value}", ["ensemble", "--large", "4", flag, value, "--out", "{tmp}/s.zarr"], words)
      for flag, value, words in (
          ("--realizations", "0", r"--realizations must be >= 1"),
          ("--realizations", "-3", r"--realizations must be >= 1"),
          ("--realizations", "ten", r"--realizations: invalid int value"),
          ("--chunk-size", "0", r"--chunk-size must be >= 1"),
          ("--chunk-size", "2.5", r"--chunk-size: invalid int value"),
          ("--seed", "-1", r"--seed must be >= 0"),
          ("--seed", "float64", r"--seed: invalid int value"),
          ("--threads", "0", r"--threads must be >= 1"),
          ("--dt", "0", r"--dt must be a finite number > 0"),
          ("--dt", "nan", r"--dt must be a finite number > 0"),
          ("--t-end", "-1", r"--t-end must be a finite number > 0"))],
    Cli("ensemble-backend-unknown", ["ensemble", "--large", "4", "--backend", "gpu", "--out", "{tmp}/s.zarr"],
        r"--backend: invalid choice: 'gpu' \(choose from 'cpu', 'cuda'\)"),
    Cli("ensemble-backend-missing-value", ["ensemble", "--large", "4", "--out", "{tmp}/s.zarr", "--backend"],
        r"--backend: expected one argument"),
    Cli("ensemble-out-empty", ["ensemble", "--large", "4", "--out", ""], r"--out must be a path"),
    Cli("ensemble-out-missing", ["ensemble", "--large", "4"], r"--out"),
    Cli("ensemble-out-existing-file", ["ensemble", "--large", "4", "--out", "{tmp}/f.txt"], r"is an existing file, not a Zarr store",
        files={"f.txt": "x"}),
    Cli("ensemble-out-under-a-file", ["ensemble", "--large", "4", "--realizations", "2", "--pulse-window", "full",
                                      "--out", "{tmp}/f.txt/s.zarr"], r"cannot create its folder", files={"f.txt": "x"}),
    # -- granchain info ----------------------------------------------------------------------------------
    Cli("info-missing", ["info", "{tmp}/missing.zarr"], r"is not a directory"),
    Cli("info-a-file", ["info", "{tmp}/f.txt"], r"is not a directory", files={"f.txt": "x"}),
    Cli("info-not-a-store", ["info", "{tmp}"], r"not a granchain ensemble store"),
    Cli("info-no-argument", ["info"], r"required: store"),
    # -- granchain export --------------------------------------------------------------------------------
    Cli("export-missing-store", ["export", "{tmp}/missing.zarr", "{tmp}/x.nc"], r"not a granchain ensemble store"),
    Cli("export-not-a-store", ["export", "{tmp}", "{tmp}/x.nc"], r"not a granchain ensemble store"),
    Cli("export-no-verify-not-a-store", ["export", "--no-verify", "{tmp}", "{tmp}/x.nc"], r"not a granchain ensemble store"),
    Cli("export-file-empty", ["export", "{tmp}", ""], r"FILE must be a path"),
    Cli("export-file-exists", ["export", "{tmp}", "{tmp}/f.txt"], r"already exists: pass --force", files={"f.txt": "x"}),
    Cli("export-file-folder-missing", ["export", "{tmp}", "{tmp}/nowhere/x.nc"], r"folder .* is missing or not writable"),
    Cli("export-no-file", ["export", "{tmp}"], r"required: file"),
]


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input_is_refused_clearly(case, tmp_path):
    check(case, tmp_path)
