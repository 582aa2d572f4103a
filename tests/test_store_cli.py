"""``granchain info`` and ``granchain export`` (CF-1.8 netCDF checked by the IOOS compliance checker)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest
import xarray as xr

import granchain as gc
from granchain.cli import main


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    path = tmp_path_factory.mktemp("cli") / "s.zarr"
    gc.run_ensemble(6, realizations=20, seed=2, chunk_size=10, out=path, progress=False, threads=1)
    return path


def test_info_reports_parameters_progress_and_damage(store, tmp_path, capsys):
    assert main(["info", str(store)]) == 0
    out = capsys.readouterr().out
    for words in ("decorated", "dp5", "20 realisations", "2/2 chunks done", "SUCCESS: 40", "intact",
                  "<v_k(t)> in each granule's window", "the whole grid for the last 5"):
        assert words in out, out
    damaged = tmp_path / "d.zarr"
    shutil.copytree(store, damaged)
    os.remove(damaged / "peak_velocity" / "0.1.0")
    assert main(["info", "--json", str(damaged)]) == 0
    info = json.loads(capsys.readouterr().out)
    assert list(info["damaged_chunks"]) == ["1"] and "peak_velocity/0.1.0" in info["damaged_chunks"]["1"]


def test_export_writes_cf_netcdf_equal_to_the_store(store, tmp_path, capsys):
    nc = tmp_path / "s.nc"
    assert main(["export", str(store), str(nc)]) == 0
    with xr.open_dataset(nc) as a, xr.open_dataset(store, engine="zarr") as b:
        assert a.attrs["Conventions"] == "CF-1.8" and "history" in a.attrs
        for key in ("numpy_version", "scipy_version", "numba_version"):
            assert a.attrs[key]
        assert list(a["status"].attrs["flag_values"]) == [-1, 0, 1, 2, 3, 4]
        assert a["status"].attrs["flag_meanings"].split()[0] == "NOT_COMPUTED"
        for name in b.data_vars:
            np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=name)
    assert main(["export", str(store), str(nc)]) == 2  # no silent overwrite
    assert "--force" in capsys.readouterr().err


def test_export_passes_the_cf_1_8_compliance_checker(store, tmp_path):
    pytest.importorskip("compliance_checker")
    nc = tmp_path / "cf.nc"
    assert main(["export", str(store), str(nc)]) == 0
    report = tmp_path / "report.json"
    checker = shutil.which("compliance-checker") or os.path.join(os.path.dirname(sys.executable), "compliance-checker")
    subprocess.run([checker, "--test", "cf:1.8", "--format", "json", "--output", str(report), str(nc)],
                   capture_output=True, text=True, timeout=300)
    result = json.loads(report.read_text())
    (checks,) = result.values()
    errors = [m for item in checks["high_priorities"] for m in item["msgs"]]
    # the one accepted complaint: CF's time-axis heuristic wants a dimensional (calendar) time, ours is rescaled
    errors = [m for m in errors if not ("'time'" in m and "standard_name" in m)]
    assert errors == [], errors
