"""The ``granchain`` command line: pulse, bca, ensemble, --help.

Sub-commands are called in-process through ``granchain.cli.main(argv)`` (exit code
returned, output captured by capsys); ``python -m granchain --help`` runs in a subprocess.
Contract (issue "granchain pulse"): ``--small-radii`` builds the decorated chain with one
more large granule than small radii and observes the large granules, reported as k = 1..N;
``--json`` prints exactly one JSON object; bad input exits 2 with a message on stderr and
nothing on stdout.
"""

from __future__ import annotations

import json
import subprocess
import sys

import numba
import numpy as np
import pytest

import granchain as gc
from granchain.cli import main

SMALL = "0.05,0.3,0.012"  # three small radii: a decorated chain of N = 4 large granules


@pytest.fixture(autouse=True)
def _restore_numba_threads():
    before = numba.get_num_threads()
    yield
    numba.set_num_threads(before)


def run_cli(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def one_json_object(out: str) -> dict:
    lines = [line for line in out.splitlines() if line.strip()]
    assert len(lines) == 1, f"expected exactly one line of JSON on stdout, got {out!r}"
    obj = json.loads(lines[0])
    assert isinstance(obj, dict)
    return obj


# -- pulse -------------------------------------------------------------------------------------
def test_pulse_json_decorated_reports_large_granules_1_to_N(capsys):
    code, out, err = run_cli(capsys, "pulse", "--small-radii", SMALL, "--json")
    assert code == 0, err
    obj = one_json_object(out)
    assert set(obj) == {"granule", "peak_velocity", "peak_time", "ok", "status"}
    assert obj["ok"] is True and obj["status"]["name"] == "SUCCESS", obj["status"]
    assert obj["granule"] == [1, 2, 3, 4], (
        f"--small-radii observes the large granules k = 1..N; got {obj['granule']} (indices in the full decorated chain)"
    )
    assert len(obj["peak_velocity"]) == len(obj["peak_time"]) == 4


def test_pulse_json_values_are_simulate(capsys):
    code, out, _ = run_cli(capsys, "pulse", "--small-radii", SMALL, "--json")
    assert code == 0
    obj = one_json_object(out)
    r = gc.simulate(gc.decorated([0.05, 0.3, 0.012]))
    np.testing.assert_array_equal(obj["peak_velocity"], r.peak_velocity)  # JSON floats round-trip exactly
    np.testing.assert_array_equal(obj["peak_time"], r.peak_time)
    assert obj["peak_velocity"][0] == 1.0 and obj["peak_time"][0] == 0.0
    assert all(0.0 < v <= 1.0 for v in obj["peak_velocity"])
    assert obj["peak_time"] == sorted(obj["peak_time"])


def test_pulse_effective_matches_decorated(capsys):
    _, out, _ = run_cli(capsys, "pulse", "--small-radii", SMALL, "--json")
    dec = one_json_object(out)
    code, out, err = run_cli(capsys, "pulse", "--small-radii", SMALL, "--effective", "--json")
    assert code == 0, err
    eff = one_json_object(out)
    assert eff["granule"] == [1, 2, 3, 4]
    # observed: velocities within 0.35 %, times within 0.03 (paper: "almost identical")
    np.testing.assert_allclose(eff["peak_velocity"], dec["peak_velocity"], rtol=0.02)
    np.testing.assert_allclose(eff["peak_time"], dec["peak_time"], atol=0.1)
    # momentum-conserving start: granule 1 starts with m_1/mu_1 < 1
    code, out, _ = run_cli(capsys, "pulse", "--small-radii", SMALL, "--effective", "--momentum-conserving", "--json")
    assert code == 0
    mc = one_json_object(out)
    assert mc["peak_velocity"][0] < 1.0
    np.testing.assert_allclose(mc["peak_velocity"][1:], dec["peak_velocity"][1:], rtol=0.05)


def test_pulse_radii_observes_all_granules(capsys):
    code, out, err = run_cli(capsys, "pulse", "--radii", "1,0.5,0.25", "--json")
    assert code == 0, err
    obj = one_json_object(out)
    assert obj["granule"] == [1, 2, 3]
    r = gc.simulate(gc.from_radii([1.0, 0.5, 0.25]))
    np.testing.assert_array_equal(obj["peak_velocity"], r.peak_velocity)
    # lighter granules fly off faster (momentum goes down the decreasing chain)
    assert obj["peak_velocity"][0] == 1.0 < obj["peak_velocity"][1] < obj["peak_velocity"][2]


def test_pulse_table_is_readable(capsys):
    code, out, err = run_cli(capsys, "pulse", "--small-radii", SMALL)
    assert code == 0, err
    _, js, _ = run_cli(capsys, "pulse", "--small-radii", SMALL, "--json")
    obj = one_json_object(js)
    lines = out.splitlines()
    assert lines[0].split() == ["granule", "peak_velocity", "peak_time"]
    rows = [line.split() for line in lines[1:] if line.strip() and not line.startswith("#")]
    assert len(rows) == 4 and all(len(row) == 3 for row in rows)
    assert [int(row[0]) for row in rows] == obj["granule"]  # the same labels as --json
    assert [int(row[0]) for row in rows] == [1, 2, 3, 4], "the table must label the large granules k = 1..N too"
    np.testing.assert_allclose([float(row[1]) for row in rows], obj["peak_velocity"], atol=1e-9)
    np.testing.assert_allclose([float(row[2]) for row in rows], obj["peak_time"], atol=1e-6)
    assert any("SUCCESS" in line for line in lines if line.startswith("#"))


@pytest.mark.parametrize(
    "argv, words",
    [
        (["pulse", "--radii", "1,-0.5,0.25"], ["radii", "> 0"]),
        (["pulse", "--small-radii", "0.05,-0.3"], ["small_radii", "> 0"]),
        (["pulse", "--small-radii", "0.05,abc", "--json"], ["comma-separated numbers"]),
        (["pulse", "--radii", "1,0.5,0.25", "--effective", "--json"], ["--effective", "--small-radii"]),
        (["pulse", "--radii", "1,0.5", "--integrator", "rk4"], ["unknown integrator", "rk4"]),
        (["pulse", "--radii", "1,0.5", "--integrator", "verlet", "--rtol", "1e-6"], ["verlet", "rtol"]),
        (["pulse", "--radii", "1,0.5", "--n", "1"], ["n = 1", "n > 1"]),
    ],
)
def test_pulse_bad_input_exits_2(capsys, argv, words):
    code, out, err = run_cli(capsys, *argv)
    assert code == 2
    assert out == "", f"nothing may be printed on stdout, got {out!r}"
    assert err.startswith("granchain pulse: error:"), err
    for word in words:
        assert word in err, f"{word!r} not in {err!r}"


def test_pulse_usage_errors_exit_2(capsys):
    for argv in (["pulse"], ["pulse", "--radii", "1,1", "--small-radii", "0.1"]):
        with pytest.raises(SystemExit) as exc:
            main(argv)
        assert exc.value.code == 2
        out, err = capsys.readouterr()
        assert out == "" and "usage:" in err


def test_python_m_granchain_help():
    proc = subprocess.run([sys.executable, "-m", "granchain", "--help"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("usage: granchain")
    for command in ("pulse", "bca", "ensemble"):
        assert command in proc.stdout
    proc = subprocess.run([sys.executable, "-m", "granchain", "pulse", "--help"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and "--small-radii" in proc.stdout and "--json" in proc.stdout


def test_no_command_prints_help_and_exits_2(capsys):
    code, out, _ = run_cli(capsys)
    assert code == 2 and "usage: granchain" in out


# -- bca ---------------------------------------------------------------------------------------
def test_bca_json(capsys):
    code, out, err = run_cli(capsys, "bca", "--json")
    assert code == 0, err
    obj = one_json_object(out)
    assert obj["large"] == 26 and obj["granule"] == 25 and obj["alpha"] == 0.01 and obj["beta"] == 0.4
    assert obj["A"] == pytest.approx(2.43884, abs=1e-5)  # DESIGN.md Sec. 3
    assert obj["slope"] == pytest.approx(2.3482, abs=1e-4)  # paper: S = 2.348
    assert obj["mean"] > 0 and obj["std"] > 0
    code, out, _ = run_cli(capsys, "bca", "--json", "--realizations", "200", "--large", "11")
    assert code == 0
    mc = one_json_object(out)["monte_carlo"]
    assert mc["realizations"] == 200 and mc["mean"] > 0


def test_bca_bad_granule_exits_2(capsys):
    code, out, err = run_cli(capsys, "bca", "--large", "6", "--granule", "7")
    assert code == 2 and out == "" and "--granule" in err


# -- ensemble ------------------------------------------------------------------------------------
def test_ensemble_writes_a_store(tmp_path, capsys):
    import xarray as xr

    store = tmp_path / "cli.zarr"
    code, out, err = run_cli(capsys, "ensemble", "--large", "4", "--realizations", "10", "--chunk-size", "4",
                             "--seed", "7", "--chain", "effective", "--out", str(store), "--threads", "1")
    assert code == 0, err
    assert out.startswith(f"wrote {store}") and "failed integrations: 0" in out
    # --quiet: nothing but errors (the same store again: resumed, all chunks done)
    code, out, err = run_cli(capsys, "ensemble", "--large", "4", "--realizations", "10", "--chunk-size", "4",
                             "--seed", "7", "--chain", "effective", "--out", str(store), "--quiet", "--threads", "1")
    assert code == 0 and out == "" and err == "", (out, err)
    with xr.open_dataset(store, engine="zarr") as ds:
        assert list(ds["chain"].values) == ["effective"] and ds.sizes["realization"] == 10
        assert ds.attrs["seed"] == 7
        ref = gc.run_ensemble(4, realizations=10, seed=7, chains="effective", chunk_size=4, progress=False)
        np.testing.assert_array_equal(ds["peak_time"].values, ref["peak_time"].values)
        np.testing.assert_array_equal(ds["mean_velocity"].values, ref["mean_velocity"].values)


def test_a_reader_that_stops_early_is_not_an_error(tmp_path):
    """`granchain pulse ... --json | head -c 20`: the closed pipe must not print an 'unexpected' error."""
    import subprocess
    import sys

    radii = ",".join(["1"] * 2500)  # ~110 kB of JSON: more than a pipe buffer holds
    proc = subprocess.run(f"{sys.executable} -m granchain pulse --radii {radii} --json | head -c 20", shell=True,
                          capture_output=True, text=True, cwd=tmp_path, timeout=300,
                          env={**__import__("os").environ, "PYTHONPATH": str(__import__("pathlib").Path(__file__).parents[1])})
    assert proc.stdout == '{"granule": [1, 2, 3'
    assert "unexpected" not in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
