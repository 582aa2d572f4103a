"""``granchain theory`` on the command line: what it prints, what it writes, how it compares with a
store, and how it refuses bad input (exit 2, a message on stderr, nothing on stdout).

Every run uses a small window (memory 2, 3 nodes, 2000 samples) and a private cache, so the tests
take seconds and neither use nor fill the user's cache.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import xarray as xr

import granchain as gc
from granchain import theory
from granchain.cli import main

FAST = ("--memory", "2", "--nodes", "3", "--samples", "2000")


pytestmark = pytest.mark.usefixtures("private_theory_cache")  # conftest.py


def run_cli(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_help_names_the_options(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["theory", "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for option in ("--alpha", "--beta", "--large", "--compare", "--out", "--json", "--memory", "--nodes",
                   "--no-stiffness-disorder"):
        assert option in out


def test_json_is_the_prediction(capsys):
    """--json prints one object whose arrays are predict()'s for the same settings."""
    code, out, err = run_cli(capsys, "theory", "--large", "8", "--json", *FAST)
    assert code == 0, err
    lines = [line for line in out.splitlines() if line.strip()]
    assert len(lines) == 1
    obj = json.loads(lines[0])
    ref = theory.predict(gc.Uniform(0.01, 0.4), 8, memory=2, nodes=3, samples=2000)
    for name in ("mean_peak_velocity", "averaged_peak_velocity", "arrival_time_mean", "arrival_time_std"):
        assert len(obj[name]) == 8
        np.testing.assert_allclose(obj[name], ref[name].values, rtol=1e-12)
    # the pulse decays along a random chain (k = 2..N-1; the last granule is the free end)
    assert obj["mean_peak_velocity"][-2] < obj["mean_peak_velocity"][1]
    assert obj["distribution_label"] == "U[0.01, 0.4]" and obj["memory"] == 2


def test_out_writes_dataset_report_and_figure(tmp_path, capsys):
    out_dir = tmp_path / "th"
    code, out, err = run_cli(capsys, "theory", "--large", "8", "--out", str(out_dir), *FAST)
    assert code == 0, err
    assert "| k |" in out and f"wrote {out_dir / 'theory.nc'}" in out
    with xr.open_dataset(out_dir / "theory.nc") as ds:
        assert ds.sizes["granule"] == 8
        assert np.isfinite(ds["mean_peak_velocity"].values).all()
    assert "<max_t v_k>" in (out_dir / "theory.md").read_text()
    assert (out_dir / "theory.png").stat().st_size > 10_000


def test_compare_with_a_store_reports_errors(tmp_path, capsys):
    store = tmp_path / "e.zarr"
    gc.run_ensemble(8, realizations=40, seed=3, chains="decorated", chunk_size=20, out=store, progress=False)
    code, out, err = run_cli(capsys, "theory", "--large", "8", "--compare", str(store), *FAST)
    assert code == 0, err
    assert "measured <max_t v_k>" in out and "errors over k = 4..7 against 40 realisations (decorated chain)" in out
    code, out, err = run_cli(capsys, "theory", "--large", "8", "--compare", str(store), "--json", *FAST)
    measured = json.loads(out)["measured"]
    assert measured["realizations"] == 40 and len(measured["mean_peak_velocity"]) == 8


@pytest.mark.parametrize("argv, words", [
    (("--large", "1"), "--large"),
    (("--alpha", "0.3", "--beta", "0.1"), "alpha"),
    (("--alpha", "-0.1"), "alpha"),
    (("--n", "2"), "n > 2"),
    (("--memory", "0"), "memory"),
    (("--compare", "no-such-store.zarr"), "no store at"),
])
def test_bad_input_exits_2_with_a_message(capsys, argv, words):
    code, out, err = run_cli(capsys, "theory", *FAST, *argv)  # argv last: it overrides FAST
    assert code == 2 and out == ""
    assert words in err, err


def test_compare_refuses_a_store_of_another_size(tmp_path, capsys):
    store = tmp_path / "e6.zarr"
    gc.run_ensemble(6, realizations=10, seed=3, chains="decorated", out=store, progress=False)
    code, out, err = run_cli(capsys, "theory", "--large", "8", "--compare", str(store), *FAST)
    assert code == 2 and "pass the same --large" in err
