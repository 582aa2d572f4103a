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
    assert main(["info", "--json", str(damaged)]) == 1
    info = json.loads(capsys.readouterr().out)
    assert list(info["damaged_chunks"]) == ["1"] and "peak_velocity/0.1.0" in info["damaged_chunks"]["1"]


def test_export_writes_cf_netcdf_equal_to_the_store(store, tmp_path, capsys):
    nc = tmp_path / "s.nc"
    assert main(["export", str(store), str(nc)]) == 0
    with xr.open_dataset(nc) as a, xr.open_dataset(store, engine="zarr") as b:
        assert a.attrs["Conventions"] == "CF-1.8" and "history" in a.attrs
        for key in ("numpy_version", "scipy_version", "numba_version"):
            assert a.attrs[key]
        from granchain._status import Status

        assert list(a["status"].attrs["flag_values"]) == [-1] + [int(s) for s in Status]
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


def test_export_refuses_a_damaged_store_unless_told_not_to_verify(store, tmp_path, capsys):
    """One flipped bit (written through Zarr, so the file decodes): export refuses it naming the file and the
    fix, info reports the same chunk, and --no-verify exports it anyway with a warning."""
    import zarr

    from granchain.cli.export import export
    from granchain.ensembles.verify import StoreVerificationWarning

    damaged = tmp_path / "d.zarr"
    shutil.copytree(store, damaged)
    arr = zarr.open_array(str(damaged / "peak_velocity"), mode="r+", zarr_format=2)
    value = np.array(arr[1, 3, 2], dtype=np.float64)
    arr[1, 3, 2] = (value.view(np.uint64) ^ np.uint64(1 << 62)).view(np.float64)
    nc = tmp_path / "d.nc"
    assert main(["export", str(damaged), str(nc)]) == 2
    err = capsys.readouterr().err
    assert "chunk 0 does not match its checksum: the data file peak_velocity/0.0.0" in err and "--no-verify" in err, err
    assert not nc.exists()
    assert main(["info", str(damaged)]) == 1  # damage reported, and in the exit status
    out = capsys.readouterr().out
    assert "damaged      chunk 0 does not match its checksum: the data file peak_velocity/0.0.0" in out and "intact" not in out
    assert main(["export", "--no-verify", str(damaged), str(nc)]) == 0  # the CLI prints warnings on stderr
    assert "warning: " in (err := capsys.readouterr().err) and "without verifying" in err, err
    with pytest.warns(StoreVerificationWarning, match="without verifying"):
        export(damaged, tmp_path / "api.nc", verify=False)
    with xr.open_dataset(nc) as ds:
        assert ds["peak_velocity"].values[1, 3, 2] > 1e300  # exported as stored, damage and all
