"""run_ensemble: many random decorated chains, seeded, parallel, resumable, on disk, on Dask.

What is checked (DESIGN.md Secs. 2 and 5; issue "Ensembles of tens of thousands of random chains"):

* the result never depends on how the work was split: chunk size, Numba threads or Dask
  workers change nothing, bit for bit, per realisation AND in the averaged pulse (the kernel
  sums velocities in fixed point, so the mean is exact too);
* each realisation is exactly what ``simulate`` gives for the same chain and tolerances,
  and realisation i's radii depend only on (seed, i);
* an interrupted run (SIGKILL, SIGINT) resumed with the same arguments gives the same store
  as an uninterrupted run; other arguments or an existing store without --resume are refused;
* ``mean_velocity`` is the plain mean of the per-realisation traces (to the fixed-point
  rounding 2^-40), its standard error the sample std / sqrt(n);
* decorated and effective chains of the same realisations agree as the paper says;
* the store explains itself (units, long names, parameters) and needs no granchain to read;
* a failed realisation is a status, not an exception; bad arguments name the parameter;
* (slow) Numba's on-disk cache never serves an ensemble kernel compiled against older
  integrator code.

Stores live under pytest's tmp_path. Small chains (N = 6, 11) keep the file fast.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numba
import numpy as np
import pytest
import xarray as xr

import granchain as gc
from granchain.ensembles import run as ens

N = 6  # large granules of the small test ensembles
SEED = 11
R = 40  # realisations of the small test ensembles
PER_REALISATION = ("small_radius", "peak_velocity", "peak_time", "status", "energy_error", "n_steps", "t_end")
AVERAGED = ("mean_velocity", "mean_velocity_stderr", "n_valid")
COORDS = ("chain", "realization", "granule", "gap", "time")
FIXED_POINT_ULP = 2.0**-40  # the fixed-point resolution of the velocity sums (fixed_point_bits = 40)
DEFAULT_DECORATED = gc.RKN4.windowed(gc.ENSEMBLE_RTOL, gc.ENSEMBLE_ATOL)  # the ensembles' default integrator (decorated chains)


@pytest.fixture(autouse=True)
def _restore_numba_threads():
    """run_ensemble(threads=...) changes Numba's process-wide thread count: undo it after each test."""
    before = numba.get_num_threads()
    yield
    numba.set_num_threads(before)


def assert_identical(a, b, names=PER_REALISATION + AVERAGED, coords=COORDS):
    """Bitwise equality (NaN == NaN) of the named variables and coordinates of two Datasets."""
    for name in names + coords:
        x, y = np.asarray(a[name].values), np.asarray(b[name].values)
        assert x.shape == y.shape, f"{name}: shapes {x.shape} != {y.shape}"
        if x.dtype.kind in "fc":
            same = np.array_equal(x, y, equal_nan=True)
        else:
            same = np.array_equal(x, y)
        if not same:
            diff = np.nanmax(np.abs(x.astype(float) - y.astype(float))) if x.dtype.kind in "fiu" else "n/a"
            pytest.fail(f"{name} differs (max |difference| {diff})")


@pytest.fixture(scope="module")
def local():
    """The reference: a local, in-memory run with default threads and chunk_size 16."""
    return gc.run_ensemble(N, realizations=R, seed=SEED, chunk_size=16, progress=False)


# -- 1. the split of the work changes nothing -------------------------------------------------
def test_reference_run_is_complete(local):
    assert local.sizes == {"chain": 2, "realization": R, "granule": N, "gap": N - 1, "contact": N - 1,
                           "time": gc.default_time_grid(N).size}
    assert list(local["chain"].values) == ["decorated", "effective"]
    assert np.all(local["status"].values == gc.Status.SUCCESS)
    np.testing.assert_array_equal(local["n_valid"].values, [R, R])
    assert np.all(np.isfinite(local["peak_velocity"].values))
    # <v_k(t)> recorded inside each granule's averaged-pulse window (the struck granule's closes when the
    # pulse has passed granule 6 in the slow realisations), not computed after it
    inside = local["time"] <= local["pulse_window_end"]
    assert bool(local["mean_velocity"].where(inside, 0.0).notnull().all())
    assert bool(local["mean_velocity"].where(~inside).isnull().all()) and not bool(inside.all())
    # the struck granule: v = 1 at t = 0; every later large granule peaks later
    np.testing.assert_array_equal(local["peak_velocity"].values[..., 0], 1.0)
    assert np.all(np.diff(local["peak_time"].values[..., : N - 1], axis=-1) > 0)


@pytest.mark.parametrize("chunk_size, threads", [(7, None), (40, None), (16, 1), (7, 2), (40, 1)])
def test_chunking_and_threads_do_not_change_results(local, chunk_size, threads):
    ds = gc.run_ensemble(N, realizations=R, seed=SEED, chunk_size=chunk_size, threads=threads, progress=False)
    assert_identical(ds, local)


def test_a_strided_time_grid_is_taken(local):
    """run_ensemble takes a grid that is a strided view (``t[::2]``) as its contiguous copy."""
    grid = local["time"].values
    ds = gc.run_ensemble(N, realizations=4, seed=SEED, t_grid=grid[::2], progress=False)
    np.testing.assert_array_equal(ds["time"].values, grid[::2])
    np.testing.assert_array_equal(ds["mean_velocity"].values,
                                  gc.run_ensemble(N, realizations=4, seed=SEED, t_grid=grid[::2].copy(),
                                                  progress=False)["mean_velocity"].values)


def test_run_ensemble_threads_leaves_the_default_alone():
    """``threads=None`` means "all cores" (docstring): an earlier ``threads=1`` call must not stick."""
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    gc.run_ensemble(N, realizations=4, seed=SEED, chunk_size=4, threads=1, progress=False)
    assert numba.get_num_threads() == numba.config.NUMBA_NUM_THREADS, (
        "run_ensemble(threads=1) left Numba at 1 thread for every later run_ensemble()/simulate() call"
    )


def test_dask_cluster_gives_the_local_result(local, tmp_path):
    """Two worker processes with one thread each, writing a Zarr store: identical to the local run."""
    distributed = pytest.importorskip("distributed")
    store = tmp_path / "dask.zarr"
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        with distributed.Client(cluster) as client:
            ds = gc.run_ensemble(N, realizations=R, seed=SEED, chunk_size=7, out=store, client=client, progress=False)
            n_workers = len(client.scheduler_info()["workers"])
    assert n_workers == 2
    assert_identical(ds, local)
    with xr.open_dataset(store, engine="zarr") as on_disk:
        assert_identical(on_disk, local)


# -- 2. each realisation is simulate() of its own chain -----------------------------------------
def test_rows_equal_simulate(local):
    grid = local["time"].values
    for i in range(R):
        chain = gc.random_decorated(N, seed=SEED, realization=i)
        np.testing.assert_array_equal(local["small_radius"].values[i], chain.meta["small_radii"])
        for kind, ch in (("decorated", chain), ("effective", gc.effective(chain))):
            r = gc.simulate(ch, gc.ensemble_integrator(kind), t_grid=grid)  # each chain kind's default
            row = local.sel(chain=kind, realization=i)
            np.testing.assert_array_equal(row["peak_velocity"].values, r.peak_velocity, err_msg=f"{kind} realisation {i}")
            np.testing.assert_array_equal(row["peak_time"].values, r.peak_time, err_msg=f"{kind} realisation {i}")
            assert int(row["status"]) == int(r.status)
            assert int(row["n_steps"]) == r.n_steps
            assert float(row["t_end"]) == r.t_end
            assert float(row["energy_error"]) == r.energy_error


def test_radii_depend_only_on_seed_and_index(local):
    longer = gc.run_ensemble(N, realizations=60, seed=SEED, chunk_size=25, progress=False)
    np.testing.assert_array_equal(longer["small_radius"].values[:R], local["small_radius"].values)
    # not only the radii: every per-realisation result of the first 40 is the same
    assert_identical(longer.isel(realization=slice(0, R)), local, names=PER_REALISATION, coords=("chain", "granule", "gap", "time"))
    np.testing.assert_array_equal(local["small_radius"].values, gc.draw_small_radii(None, N - 1, SEED, np.arange(R)))
    other = gc.run_ensemble(N, realizations=R, seed=SEED + 1, chains="effective", chunk_size=16, progress=False)
    assert np.all(np.any(other["small_radius"].values != local["small_radius"].values, axis=1)), "another seed must change every row"
    # realisation i's stream is SeedSequence(seed).spawn(i + 1)[i] (as documented)
    for i in (0, 7, 39):
        a = gc.realization_rng(SEED, i).random(4)
        b = np.random.default_rng(np.random.SeedSequence(SEED).spawn(i + 1)[i]).random(4)
        np.testing.assert_array_equal(a, b)
    # the paper's distribution U[0.01, 0.4]
    small = longer["small_radius"].values
    assert small.min() >= 0.01 and small.max() <= 0.4


# -- 3. interrupted runs resume to the uninterrupted result ------------------------------------
CLI = ["--large", "6", "--realizations", "400", "--chunk-size", "20", "--quiet", "--threads", "1"]
CHUNKS = 20  # 400 / 20


def _cli(store, *args, resume=True):
    return [sys.executable, "-m", "granchain", "ensemble", *CLI, "--out", str(store), *(["--resume"] if resume else []), *args]


def _done_chunks(store) -> int:
    try:
        with xr.open_zarr(store, group="progress", consolidated=False) as p:
            return int(p["done"].values.sum())
    except Exception:  # not created yet, or a chunk being replaced right now
        return 0


def _run_to_completion(cmd, cwd):
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=cwd, timeout=600)
    assert proc.returncode == 0, f"exit {proc.returncode}\nstdout: {proc.stdout}\nstderr: {proc.stderr}"
    # --quiet: nothing on stdout; failed integrations would be reported on stderr
    assert proc.stdout == "" and "did not succeed" not in proc.stderr, (proc.stdout, proc.stderr)
    return proc


def _interrupt(store, sig, cwd, min_done=3, timeout=240.0):
    """Start the CLI, wait until ``min_done`` chunks are on disk, send ``sig``; (returncode, stdout, stderr)."""
    # A runner that starts us in the background (no job control) makes SIGINT ignored, and
    # children inherit that; restore the default so Python turns SIGINT into KeyboardInterrupt.
    proc = subprocess.Popen(_cli(store), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=cwd,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + timeout  # includes interpreter start and loading the Numba cache
        while _done_chunks(store) < min_done:
            if proc.poll() is not None:
                out, err = proc.communicate()
                pytest.fail(f"the run ended (exit {proc.returncode}) before it could be interrupted\n{out}\n{err}")
            if time.monotonic() > deadline:
                pytest.fail(f"fewer than {min_done} chunks done after {timeout} s")
            time.sleep(0.02)
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc.returncode, out, err


def _chunk_files(store) -> dict:
    """Modification times of the storage chunks of one per-realisation variable (one per run chunk)."""
    root = os.path.join(store, "small_radius")
    files = {}
    for dirpath, _, names in os.walk(root):
        for name in names:
            if not name.startswith(".") and name != "zarr.json":
                path = os.path.join(dirpath, name)
                files[path] = os.stat(path).st_mtime_ns
    return files


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    """The same CLI arguments run once without interruption."""
    work = tmp_path_factory.mktemp("uninterrupted")
    store = work / "full.zarr"
    _run_to_completion(_cli(store), cwd=work)
    return store


def _resume_and_compare(store, uninterrupted, cwd):
    done = _done_chunks(store)
    assert 3 <= done < CHUNKS, f"{done} chunks done: the interruption should leave a partial store"
    before = _chunk_files(store)
    _run_to_completion(_cli(store), cwd=cwd)
    after = _chunk_files(store)
    # done chunks are skipped, not recomputed: their storage chunks are untouched
    unchanged = sum(after.get(p) == t for p, t in before.items())
    assert unchanged >= done, f"only {unchanged} storage chunks untouched, {done} chunks were done before resuming"
    assert _done_chunks(store) == CHUNKS
    with xr.open_dataset(store, engine="zarr") as a, xr.open_dataset(uninterrupted, engine="zarr") as b:
        assert_identical(a, b)
        assert np.all(a["status"].values == 0) and np.all(a["n_valid"].values == 400)


def test_resume_after_sigkill_is_bitwise_identical(tmp_path, uninterrupted):
    store = tmp_path / "killed.zarr"
    returncode, _, _ = _interrupt(store, signal.SIGKILL, cwd=tmp_path)
    assert returncode == -signal.SIGKILL
    _resume_and_compare(store, uninterrupted, cwd=tmp_path)


@pytest.fixture(scope="module")
def sigint_run(tmp_path_factory):
    work = tmp_path_factory.mktemp("sigint")
    store = work / "interrupted.zarr"
    returncode, out, err = _interrupt(store, signal.SIGINT, cwd=work)
    return store, work, returncode, out, err


def test_sigint_stops_with_a_resume_hint(sigint_run):
    store, _, returncode, out, err = sigint_run
    assert returncode != 0, "an interrupted run must not report success"
    assert "interrupted" in out + err and "resume" in out + err and str(store) in out + err
    assert 3 <= _done_chunks(store) < CHUNKS


def test_resume_after_sigint_is_bitwise_identical(sigint_run, uninterrupted):
    store, work, *_ = sigint_run
    _resume_and_compare(store, uninterrupted, cwd=work)


def test_sigint_is_reported_cleanly_by_the_cli(sigint_run):
    """Ctrl-C is an expected event for a long run: a one-line hint naming --resume, no traceback."""
    _, _, returncode, out, err = sigint_run
    assert returncode in (130, -signal.SIGINT)
    assert "--resume" in out + err, f"the hint must tell a CLI user to add --resume, got: {(out + err).strip()}"
    assert "Traceback" not in err, "Ctrl-C printed a Python traceback"


def test_resume_with_other_parameters_is_refused(uninterrupted, capsys):
    from granchain.cli import main

    for args, what in ((["--seed", "1"], "seed"), (["--realizations", "300"], "realizations"), (["--beta", "0.3"], "distribution")):
        argv = ["ensemble", *CLI, "--out", str(uninterrupted), "--resume"]
        for flag, value in zip(args[::2], args[1::2]):
            if flag in argv:
                argv[argv.index(flag) + 1] = value
            else:
                argv += [flag, value]
        assert main(argv) == 2
        captured = capsys.readouterr()
        assert captured.out == ""
        assert "different parameters" in captured.err and what in captured.err, captured.err
    with xr.open_dataset(uninterrupted, engine="zarr") as ds:  # untouched
        assert ds.attrs["seed"] == 0 and ds.sizes["realization"] == 400


def test_existing_store_without_resume_is_refused(uninterrupted, tmp_path, capsys):
    from granchain.cli import main

    # resuming is the default of the CLI and the API (issue 10); --no-resume refuses an existing store
    assert main(["ensemble", *CLI, "--out", str(uninterrupted), "--no-resume"]) == 2
    captured = capsys.readouterr()
    assert "already exists" in captured.err and "--resume" in captured.err and captured.out == ""
    # not a granchain store at all
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    assert main(["ensemble", *CLI, "--out", str(foreign), "--resume"]) == 2
    assert "not a granchain ensemble store" in capsys.readouterr().err
    # the library refuses the same way
    with pytest.raises(ValueError, match="already exists"):
        gc.run_ensemble(6, realizations=400, chunk_size=20, out=uninterrupted, resume=False, progress=False)


# -- 4. the averaged pulse -----------------------------------------------------------------------
def test_mean_velocity_is_the_mean_of_simulated_traces():
    n_real = 30
    ds = gc.run_ensemble(N, realizations=n_real, seed=5, chunk_size=8, progress=False)
    grid = ds["time"].values
    for kind in ("decorated", "effective"):
        traces = []
        for i in range(n_real):
            chain = gc.random_decorated(N, seed=5, realization=i)
            r = gc.simulate(chain if kind == "decorated" else gc.effective(chain), gc.ensemble_integrator(kind), t_grid=grid)
            assert r.ok
            traces.append(r.velocity)
        v = np.array(traces)  # (realisation, granule, time)
        mean = v.mean(axis=0)
        se = v.std(axis=0, ddof=1) / np.sqrt(n_real)
        got = ds.sel(chain=kind)
        assert int(got["n_valid"]) == n_real
        # inside each granule's averaged-pulse window (recorded there, NaN after: compared where recorded;
        # the trailing window cuts nothing in chains this short, so the traces are simulate's)
        inside = (got["time"] <= got["pulse_window_end"]).transpose("granule", "time").values
        assert np.array_equal(np.isfinite(got["mean_velocity"].values), inside)
        mean, se = np.where(inside, mean, np.nan), np.where(inside, se, np.nan)
        # each velocity is rounded to a multiple of 2^-40 before summing: |error| <= 2^-41 per term
        np.testing.assert_allclose(got["mean_velocity"].values, mean, rtol=0, atol=1e-11)
        # the variance comes from sums of v and v^2 in fixed point: |error of se^2| <= 3 * 2^-41 / (n - 1)
        np.testing.assert_allclose(got["mean_velocity_stderr"].values ** 2, se**2, rtol=1e-9, atol=4 * 2.0**-41 / (n_real - 1))
        np.testing.assert_allclose(got["mean_velocity_stderr"].values, se, rtol=1e-6, atol=3e-7)
        # the grid starts with the struck granule at v = 1, all others at rest
        np.testing.assert_array_equal(got["mean_velocity"].values[:, 0], [1.0] + [0.0] * (N - 1))


# -- 5. decorated vs effective chains (paper Sec. IV) --------------------------------------------
def test_decorated_and_effective_chains_agree():
    """N = 11, 300 paired realisations. Observed (seeds 2024, 7, 99): mean arrival times differ by
    at most 0.034 at k = 2..N-1 (growing ~0.003 per granule, the decorated chain slightly ahead),
    mean peak velocities by <= 0.2 % at k = 2..N-1 and 0.5 % at the free end k = N (the effective
    chain's last granule is faster), averaged-pulse peaks by <= 0.71 %, their times by one grid
    step. k = 1 (struck) and k = N (free end) are excluded from the arrival times, as in the
    paper's fits, and from the times of the averaged-pulse peaks."""
    n_large = 11
    ds = gc.run_ensemble(n_large, realizations=300, seed=2024, chunk_size=100, progress=False)
    assert np.all(ds["status"].values == 0)
    dec, eff = ds.sel(chain="decorated"), ds.sel(chain="effective")
    inner = slice(1, n_large - 1)  # k = 2..N-1
    t_dec, t_eff = dec["peak_time"].mean("realization").values, eff["peak_time"].mean("realization").values
    dt = np.abs(t_dec - t_eff)[inner]
    assert dt.max() < 0.05, f"mean arrival times differ by {dt.max():.4f}"
    # and the arrival time grows like the paper's ~2.4 per large granule
    slope = np.polyfit(np.arange(2, n_large), t_dec[inner], 1)[0]
    assert 2.3 < slope < 2.5, slope
    v_dec, v_eff = dec["peak_velocity"].mean("realization").values, eff["peak_velocity"].mean("realization").values
    dv = np.abs(v_eff / v_dec - 1)
    assert dv[inner].max() < 0.005, f"mean peak velocities differ by {dv[inner].max():.2%}"
    assert dv[-1] < 0.01, f"mean peak velocities at the free end differ by {dv[-1]:.2%}"
    a_dec, a_eff = dec["mean_velocity"].max("time").values, eff["mean_velocity"].max("time").values
    da = np.abs(a_eff / a_dec - 1)[1:]
    assert da.max() < 0.015, f"averaged-pulse peaks differ by {da.max():.2%}"
    tm = np.abs(dec["mean_velocity"].idxmax("time").values - eff["mean_velocity"].idxmax("time").values)[inner]
    step = float(np.diff(ds["time"].values).max())
    assert tm.max() <= max(0.1, step) + 1e-9, tm  # within one grid step (or 0.1)
    # (not at the free end: its <v_N(t)> ends on a plateau, the last granule flying off, flat to ~1e-8
    # over several time units, where the time of the maximum is set by differences at that level)
    # the two amplitudes of DESIGN.md Sec. 2 are different things: the averaged pulse decays faster
    assert np.all(a_dec[2:] < v_dec[2:])


# -- 6. a store that explains itself ---------------------------------------------------------------
def test_every_variable_is_described(local):
    for name, var in local.data_vars.items():
        assert var.attrs.get("units"), f"{name} has no units"
        assert var.attrs.get("long_name"), f"{name} has no long_name"
    for name, coord in local.coords.items():
        assert coord.attrs.get("long_name"), f"coordinate {name} has no long_name"
    assert local["time"].attrs.get("units")
    for key in ("seed", "realizations", "granchain_version", "created", "granchain_parameters"):
        assert key in local.attrs, key
    params = json.loads(local.attrs["granchain_parameters"])
    assert params["seed"] == SEED == local.attrs["seed"]
    assert params["realizations"] == R == local.attrs["realizations"]
    assert params["family"] == json.loads(local.attrs["granchain_family"]) == gc.RandomDecorated(N).describe()
    assert params["family"]["n_large"] == N == local.attrs["n_large"]
    integrator = json.loads(local.attrs["granchain_integrator"])
    assert integrator == params["integrator"] == {"name": "rkn4", "rtol": gc.ENSEMBLE_RTOL, "atol": gc.ENSEMBLE_ATOL,
                                                   "first_step": 1e-3, "fixed_step": None, "relaxed_lag": 4,
                                                   "relaxed_factor": 1000.0, "window_lag": 7}
    assert local.attrs["rtol"] == gc.ENSEMBLE_RTOL and local.attrs["integrator"] == "rkn4"
    assert local.attrs["granchain_version"] == gc.__version__


def test_store_opens_without_granchain(tmp_path):
    store = tmp_path / "plain.zarr"
    gc.run_ensemble(N, realizations=12, seed=3, chunk_size=5, out=store, progress=False)
    script = textwrap.dedent(
        f"""
        import json, sys
        import xarray as xr
        ds = xr.open_dataset({str(store)!r}, engine="zarr")
        out = {{
            "granchain_imported": "granchain" in sys.modules,
            "sizes": dict(ds.sizes),
            "attrs": sorted(ds.attrs),
            "undescribed": [k for k, v in ds.data_vars.items() if not (v.attrs.get("units") and v.attrs.get("long_name"))],
            "params": json.loads(ds.attrs["granchain_parameters"]),
            "n_valid": ds["n_valid"].values.tolist(),
            "chain": [str(c) for c in ds["chain"].values],
        }}
        print(json.dumps(out))
        """
    )
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert proc.returncode == 0, proc.stderr
    got = json.loads(proc.stdout.strip().splitlines()[-1])
    assert got["granchain_imported"] is False
    assert got["undescribed"] == []
    assert got["sizes"]["realization"] == 12 and got["sizes"]["granule"] == N
    assert {"seed", "realizations", "granchain_version", "created", "granchain_parameters"} <= set(got["attrs"])
    assert got["params"]["seed"] == 3 and got["n_valid"] == [12, 12] and got["chain"] == ["decorated", "effective"]


# -- 7. failures are statuses -----------------------------------------------------------------------
def test_failed_realisations_are_recorded_not_fatal():
    """A step budget between the cheapest and dearest decorated realisations: some fail
    (MAX_STEPS), the others and every effective chain succeed; only successes enter the sums."""
    assert int(gc.Status.MAX_STEPS) == 2 and int(gc.Status.SUCCESS) == 0
    full = ens.compute_chunk(ens.EnsembleSpec(gc.RandomDecorated(N), realizations=16, seed=3, chunk_size=16), 0)
    steps = full["n_steps"][0]
    budget = int(np.median(steps))
    spec = ens.EnsembleSpec(gc.RandomDecorated(N), realizations=16, seed=3, chunk_size=16, controls=gc.RunControls(max_steps=budget))
    out = ens.compute_chunk(spec, 0)
    status = out["status"]
    assert set(np.unique(status[0])) == {0, 2}, status[0]
    assert np.all(status[1] == 0), "effective chains take ~150 steps: all succeed"
    assert np.all(status[0][steps >= budget] == 2)  # accepted steps alone exceed the budget
    assert np.all(out["n_steps"][0][status[0] == 2] <= budget)
    np.testing.assert_array_equal(out["n_valid"], [(status[0] == 0).sum(), 16])  # (chain,): the schema's dims without chunk
    ok = status[0] == 0
    np.testing.assert_array_equal(out["peak_velocity"][0][ok], full["peak_velocity"][0][ok])
    # the velocity sums hold exactly the successful realisations (same fixed-point rounding)
    scale = 2.0**spec.fixed_point_bits
    expected = np.zeros_like(out["sum_v"][0])
    for i in np.flatnonzero(ok):
        r = gc.simulate(gc.random_decorated(N, seed=3, realization=i), DEFAULT_DECORATED, t_grid=spec.t_grid)
        expected += np.rint(r.velocity * scale).astype(np.int64)
    np.testing.assert_array_equal(out["sum_v"][0], expected)


# -- 8. argument validation ---------------------------------------------------------------------------
@pytest.mark.parametrize(
    "kwargs, name",
    [
        ({"chains": "foo"}, "chains"),
        ({"realizations": 0}, "realizations"),
        ({"chunk_size": 0}, "chunk_size"),
        ({"t_grid": [0.0, 2.0, 1.0]}, "t_grid"),
        ({"t_grid": []}, "t_grid"),
        ({"n": 1}, "n"),
        ({"n_large": 1}, "n_large"),
        ({"seed": -1}, "seed"),
        ({"rtol": 0.0}, "rtol"),
        # one set of run-control checks for simulate and ensembles
        ({"exit_margin": -1.0}, "exit_margin"),
        ({"peak_rtol": -1e-6}, "peak_rtol"),
        ({"max_steps": 0}, "max_steps"),
        ({"integrator": "rk4"}, "integrator"),
        ({"integrator": gc.Verlet(1e-3), "rtol": 1e-7}, "rtol"),
        ({"n_large": gc.RandomDecorated(N), "distribution": gc.Uniform(0.1, 0.2)}, "distribution"),
        ({"n_large": "26"}, "family"),
    ],
)
def test_bad_arguments_name_the_parameter(kwargs, name, tmp_path):
    store = tmp_path / "never.zarr"
    args = {"n_large": N, "realizations": 4, "progress": False, "out": store} | kwargs
    with pytest.raises(ValueError, match=rf"\b{name}\b"):
        gc.run_ensemble(**args)
    assert not store.exists(), "a refused run must not leave a store behind"


# -- 9. the compiled-kernel cache ----------------------------------------------------------------------
_CACHE_PROBE = """
import json, sys
sys.path.insert(0, {root!r})
import granchain as gc
assert gc.__file__.startswith({root!r}), gc.__file__
ds = gc.run_ensemble(4, realizations=2, seed=1, chains="decorated", chunk_size=2, progress=False)
r = gc.simulate(gc.random_decorated(4, seed=1, realization=0), gc.ensemble_integrator("decorated"),
                t_grid=ds["time"].values)
print(json.dumps({{"ensemble": int(ds["n_steps"].values[0, 0]), "simulate": r.n_steps}}))
"""


@pytest.mark.slow
def test_kernel_cache_follows_edits_of_the_integrator(tmp_path):
    """``cache=True`` keys a kernel's cache on its own source file only. The Runge-Kutta entry point
    (``backends/kernels/rkloop.py``) inlines RKN4's stages and error estimate (``backends/kernels/rkn4.py``):
    after an edit of the method alone, a stale cache would integrate with the old code. On a copy of
    the package: warm the cache, change a weight of RKN4's error estimate, and check that ``simulate``
    takes other steps and that ``run_ensemble`` (which calls the same entry point) takes the same."""
    root = tmp_path / "pkg"
    shutil.copytree(Path(gc.__file__).parent, root / "granchain", ignore=shutil.ignore_patterns("__pycache__"))
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}

    def probe():
        proc = subprocess.run([sys.executable, "-c", _CACHE_PROBE.format(root=str(root))], capture_output=True, text=True,
                              cwd=tmp_path, env=env, timeout=600)
        assert proc.returncode == 0, proc.stderr
        return json.loads(proc.stdout.strip().splitlines()[-1])

    before = probe()
    assert before["ensemble"] == before["simulate"]
    rkn4 = root / "granchain" / "backends" / "kernels" / "rkn4.py"
    text = rkn4.read_text()
    old = "25 / 189 - 3 / 20, 1 / 20\n"
    assert text.count(old) == 1, "the probe edits RKN4's error weight EB3 = 1 / 20 in backends/kernels/rkn4.py: update the test"
    rkn4.write_text(text.replace(old, "25 / 189 - 3 / 20, 1 / 19\n"))
    after = probe()
    assert after["simulate"] != before["simulate"], "the edit should change the step sequence"
    assert after["ensemble"] == after["simulate"], (
        f"run_ensemble used a stale compiled kernel: {after['ensemble']} steps, simulate {after['simulate']}"
    )


def _python_rate_during(call) -> tuple:
    """(increments per second a Python thread counts while ``call()`` runs in this one, the same with this
    thread asleep): how much a Python helper thread gets done beside a compiled call."""
    import threading

    count = [0]
    stop = threading.Event()

    def counter():
        while not stop.is_set():
            count[0] += 1

    helper = threading.Thread(target=counter, daemon=True)
    helper.start()
    try:
        time.sleep(0.05)
        n0, t0 = count[0], time.perf_counter()
        time.sleep(0.2)
        free = (count[0] - n0) / (time.perf_counter() - t0)
        n0, t0 = count[0], time.perf_counter()
        call()
        during = (count[0] - n0) / (time.perf_counter() - t0)
    finally:
        stop.set()
        helper.join()
    return during, free


def test_the_ensemble_kernel_releases_the_gil(monkeypatch):
    """The helper thread that draws the next chunk's parameters and writes the last chunk (``run._run_local``)
    works beside the kernels only if they release the GIL: a Python thread keeps counting while the
    ensemble kernel runs. Negative control: beside a compiled loop that holds the GIL it all but stops."""
    import math

    from granchain.backends import numba_backend

    kernel = numba_backend.integrate_batch
    rates = []
    monkeypatch.setattr(numba_backend, "integrate_batch",
                        lambda *a, **k: rates.append(_python_rate_during(lambda: kernel(*a, **k))))
    gc.run_ensemble(gc.RandomDecorated(26), realizations=48, chains="decorated", chunk_size=48, threads=1,
                    pulse_window="full", progress=False)
    (during, free), = rates
    assert during > 0.3 * free, (during, free)

    @numba.njit(nogil=False)
    def holds_the_gil(n):
        x = 0.0
        for i in range(n):
            x = math.sin(x + i)
        return x

    holds_the_gil(10)
    during, free = _python_rate_during(lambda: holds_the_gil(20_000_000))
    assert during < 0.1 * free, (during, free)


def test_the_order_realisations_are_started_in_changes_no_result(monkeypatch):
    """The CPU kernel starts a batch's realisations longest first (``backends.longest_first``); started in
    any other order (reversed, shuffled) every per-realisation result and sum is bitwise the same, and each
    row is its own realisation's (a kernel that wrote row j for the j-th started would fail here)."""
    from granchain.backends import numba_backend

    def run():
        return gc.run_ensemble(gc.RandomDecorated(6), realizations=24, seed=5, chunk_size=24, progress=False,
                               pulse_window="full")

    plain = run()
    rng = np.random.default_rng(0)
    for order in (lambda m, c: np.arange(m.shape[0])[::-1], lambda m, c: rng.permutation(m.shape[0])):
        monkeypatch.setattr(numba_backend, "longest_first", order)
        other = run()
        for name in plain.data_vars:
            assert plain[name].values.tobytes() == other[name].values.tobytes(), name


def test_the_ensemble_queue_gives_every_row_to_exactly_one_thread():
    """``kernels.queue.take`` under every thread of a parallel loop, as the ensemble kernel uses it: each of
    200,000 rows is taken exactly once (an increment that is not atomic loses or repeats rows when two threads
    race), the count ends at rows + threads (each thread's last take finds the queue empty), and every
    thread takes some (the rows go to whichever thread is free)."""
    from numba import njit, prange

    from granchain.backends.kernels.queue import take

    @njit(parallel=True)
    def drain(taken, hits, by_thread, work):
        for _ in prange(by_thread.shape[0]):
            tid = numba.get_thread_id()
            while True:
                j = take(taken)
                if j >= hits.shape[0]:
                    break
                hits[j] += 1
                by_thread[tid] += 1
                x = 0.0
                for i in range(200):  # a little work per row, so that no thread drains the queue alone
                    x = np.sqrt(x + i + j)
                work[j] = x

    threads = numba.get_num_threads()
    taken, hits, by_thread = np.zeros(1, np.int64), np.zeros(200_000, np.int64), np.zeros(threads, np.int64)
    drain(taken, hits, by_thread, np.zeros(hits.size))
    assert np.all(hits == 1)
    assert taken[0] == hits.size + threads
    assert by_thread.sum() == hits.size and (threads == 1 or np.all(by_thread > 0))


@pytest.mark.parametrize("family", [gc.RandomDecorated(6), gc.RandomRadii(5, gc.Uniform(0.8, 1.2)),
                                    gc.BinaryRandom(7, p=0.3)], ids=lambda f: f.kind)
@pytest.mark.parametrize("chunk_size", [1, 15, 16, 17, 40])
def test_chunk_draws_in_groups_are_one_draw_row_for_row(family, chunk_size):
    """The helper thread draws a chunk's parameters in groups of ``run.DRAW_GROUP`` realisations, yielding the
    GIL between them: every parameter of every chunk is bitwise that of one ``draw_batch`` call over the
    chunk, whatever the chunk size against the group (below, at, above, several groups)."""
    from granchain.ensembles import run as ens

    spec = ens.EnsembleSpec(family, 90, 11, family.chains[:1], chunk_size=chunk_size)
    for j in (0, spec.n_chunks - 1):
        sl = spec.chunk_slice(j)
        grouped, whole = ens._draw(spec, j), family.draw_batch(11, np.arange(sl.start, sl.stop))
        assert grouped.keys() == whole.keys()
        for name in whole:
            assert grouped[name].dtype == whole[name].dtype and grouped[name].tobytes() == whole[name].tobytes(), name


def test_the_first_chunk_is_drawn_while_the_pilot_runs(monkeypatch):
    """A new run's first chunk is drawn on the helper thread while the pilot sets the averaged-pulse windows
    (after it, the draws left every core but one idle), each chunk is drawn once, and the result is bitwise
    the same however the draws and the pilot interleave. The pilot here waits until chunk 0's draw has begun: drawn after the
    pilot, it would not begin, and the pilot would give up after 30 s. Negative control: the same wait for
    chunk 1, which is drawn only once chunk 0 is integrated, gives up (after 1 s)."""
    import threading

    from granchain.ensembles import pulse_window
    from granchain.ensembles import run as ens

    def run():
        return gc.run_ensemble(gc.RandomDecorated(6), realizations=96, seed=4, chunk_size=32, progress=False)

    plain = run()
    draw, window_ends = ens._draw, pulse_window.window_ends
    begun = {j: threading.Event() for j in range(3)}
    drawn, waits = [], []

    def counted_draw(spec, j):
        drawn.append(j)
        begun[j].set()
        return draw(spec, j)

    monkeypatch.setattr(ens, "_draw", counted_draw)
    for j, timeout, expected in ((0, 30.0, True), (1, 1.0, False)):
        def pilot_waiting(spec, compute_rows, j=j, timeout=timeout):
            waits.append(begun[j].wait(timeout))
            return window_ends(spec, compute_rows)

        monkeypatch.setattr(pulse_window, "window_ends", pilot_waiting)
        for event in begun.values():
            event.clear()
        drawn.clear()
        waits.clear()
        other = run()
        assert waits == [expected], (j, waits)
        assert sorted(drawn) == [0, 1, 2], drawn
        for name in plain.data_vars:
            assert plain[name].values.tobytes() == other[name].values.tobytes(), name
