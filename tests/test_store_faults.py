"""Stores that never lie: every injected fault ends bitwise equal to an uninterrupted run, or in a
clear error naming the file and the fix.

Faults: delete / truncate / garble a data chunk, a progress-sum chunk, a checksum chunk, a done flag,
the root and progress ``.zattrs``, ``.zgroup``, a coordinate, ``.zmetadata``; kill -9 at random instants
(also while the store is created); two writers; a stale lock. Plus: partial stores read status = -1
everywhere, and extending 40 -> 80 realisations equals a fresh run of 80.

Readers trust nothing the writer would not: a flipped bit, a chunk copied from another seed's store, a
deleted or truncated chunk, a deleted averaged-pulse chunk and an edited seed are refused alike by
``open_store`` (at once and lazily), ``granchain export`` and the analysis, and reported by ``granchain
info``. The lock file lives exactly as long as its run (finished, refused or interrupted).
"""

from __future__ import annotations

import json
import os
import random
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
import warnings

import numpy as np
import pytest
import xarray as xr
import zarr

import granchain as gc
from granchain.ensembles.lock import StoreLock
from granchain.ensembles.store import StoreRepairWarning

KW = dict(realizations=40, seed=1, chunk_size=10, progress=False, threads=1)
VOLATILE = ("created", "history")


def _run(path, family=6, **kw):
    return gc.run_ensemble(family, out=path, **{**KW, **kw})


def _open(path):
    return xr.open_dataset(path, engine="zarr", consolidated=False)


def assert_same_store(a, b):
    """Bitwise the same values, coordinates and attributes (creation time and history aside)."""
    with _open(a) as x, _open(b) as y:
        for ds in (x, y):
            for k in VOLATILE:
                ds.attrs.pop(k, None)
        xr.testing.assert_identical(x, y)
        for name in x.variables:  # NaN payloads and -0.0 too
            assert x[name].values.tobytes() == y[name].values.tobytes(), name


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    path = tmp_path_factory.mktemp("ref") / "ref.zarr"
    _run(path)
    return path


def _copy(reference, tmp_path):
    path = tmp_path / "store.zarr"
    shutil.copytree(reference, path)
    return path


def _delete(f):
    os.remove(f)


def _truncate(f):
    with open(f, "r+b") as h:
        h.truncate(max(1, os.path.getsize(f) // 3))


def _garble(f):
    with open(f, "r+b") as h:
        data = bytearray(h.read())
        for i in range(len(data) // 2, len(data)):
            data[i] ^= 0x5A
        h.seek(0)
        h.write(data)


FAULTS = [
    ("peak_velocity/0.1.0", _delete), ("peak_velocity/0.1.0", _truncate), ("peak_velocity/0.1.0", _garble),
    ("status/0.2", _delete), ("small_radius/3.0", _garble),
    ("progress/sum_v/2.0.0.0", _delete), ("progress/sum_v/2.0.0.0", _truncate), ("progress/sum_v2/1.0.0.0", _garble),
    ("progress/checksum/0.0", _truncate), ("progress/done/1", _delete), ("progress/done/3", _garble),
    (".zattrs", _delete), (".zattrs", _garble), ("progress/.zattrs", _delete), (".zgroup", _delete),
    ("peak_time/.zattrs", _delete), ("n_steps/.zarray", _garble), ("time/0", _truncate), (".zmetadata", _garble),
]


@pytest.mark.parametrize("target, fault", FAULTS, ids=[f"{f.__name__[1:]}-{t}" for t, f in FAULTS])
def test_fault_is_repaired_to_the_uninterrupted_store(reference, tmp_path, target, fault):
    path = _copy(reference, tmp_path)
    fault(os.path.join(path, *target.split("/")))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        _run(path)
    messages = [str(w.message) for w in caught if issubclass(w.category, StoreRepairWarning)]
    # consolidated metadata is rewritten on every run; a missing done flag just means "not done": recomputed
    if target != ".zmetadata" and not (target.startswith("progress/done") and fault is _delete):
        name = target.split("/")[-1] if target.startswith("progress/done") else target
        assert any(name in m or target.split("/")[0] in m for m in messages), messages
    assert_same_store(path, reference)


def test_lost_parameter_records_are_refused_with_the_fix(reference, tmp_path):
    path = _copy(reference, tmp_path)
    os.remove(path / ".zattrs")
    os.remove(path / "progress" / ".zattrs")
    with pytest.raises(ValueError, match=r"\.zattrs.*rm -r"):
        _run(path)


def test_partial_store_reads_not_computed_everywhere(tmp_path):
    from granchain.ensembles.run import EnsembleSpec, compute_chunk
    from granchain.ensembles.store import ZarrSink

    spec = EnsembleSpec(gc.RandomDecorated(6), 40, 1, chunk_size=10)
    path = tmp_path / "partial.zarr"
    sink = ZarrSink(spec, path)
    sink.write(compute_chunk(spec, 1))  # realisations 10..19 only
    sink.close()
    readers = [lambda: xr.open_dataset(path, engine="zarr"), lambda: xr.open_zarr(path), lambda: xr.open_zarr(path, consolidated=False)]
    for read in readers:
        with read() as ds:
            for name in ("status", "n_steps"):
                v = ds[name].values
                assert v.dtype.kind == "i", f"{name} became {v.dtype}"
                assert np.all(v[:, :10] == -1) and np.all(v[:, 20:] == -1) and np.all(v[:, 10:20] >= 0), name
            assert np.all(ds["status"].values[:, 10:20] == 0)
    group = zarr.open_group(str(path), mode="r")
    assert np.all(group["status"][:, 30:] == -1) and np.all(group["n_steps"][:, :10] == -1)


@pytest.mark.parametrize("first", [40, 45])
def test_extending_equals_a_fresh_run(tmp_path, first):
    fresh, grown = tmp_path / "fresh.zarr", tmp_path / "grown.zarr"
    _run(fresh, realizations=80)
    _run(grown, realizations=first)
    _run(grown, realizations=80)
    assert_same_store(grown, fresh)


def test_a_store_is_never_shrunk(reference):
    with pytest.raises(ValueError, match="realizations.*never shrunk"):
        _run(reference, realizations=30)


def test_stale_lock_is_taken_over(reference, tmp_path):
    path = _copy(reference, tmp_path)
    with open(f"{path}.lock", "w") as f:
        json.dump({"pid": 999_999_999, "host": socket.gethostname(), "since": "2020-01-01T00:00:00+00:00"}, f)
    with pytest.warns(UserWarning, match="stale lock.*999999999"):
        _run(path)
    assert_same_store(path, reference)


def test_second_writer_is_refused_with_the_holder(reference, tmp_path):
    path = _copy(reference, tmp_path)
    with StoreLock(str(path)):
        with pytest.raises(ValueError, match=rf"being written by PID {os.getpid()} on host {socket.gethostname()}"):
            _run(path)


# -- processes -----------------------------------------------------------------------------------
CLI = ["--large", "6", "--realizations", "40", "--chunk-size", "5", "--seed", "1", "--threads", "1", "--quiet"]


def _cli(path):
    return [sys.executable, "-m", "granchain", "ensemble", *CLI, "--out", str(path)]


@pytest.fixture(scope="module")
def cli_reference(tmp_path_factory):
    path = tmp_path_factory.mktemp("cliref") / "ref.zarr"
    proc = subprocess.run(_cli(path), capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    return path


def test_two_writers_started_together(cli_reference, tmp_path):
    path = tmp_path / "both.zarr"
    procs = [subprocess.Popen(_cli(path), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(2)]
    results = [(p.wait(timeout=600), *p.communicate()) for p in procs]
    for rc, out, err in results:
        assert "Traceback" not in err, err
        assert rc == 0 or (rc == 2 and "being written by PID" in err), (rc, err)
    assert any(rc == 0 for rc, *_ in results)
    if any(rc != 0 for rc, *_ in results):  # the loser's advice: run again later
        subprocess.run(_cli(path), check=True, capture_output=True, timeout=600)
    assert_same_store(path, cli_reference)


def _kill_loop(cli_reference, tmp_path, kills, seed):
    rng = random.Random(seed)
    path = tmp_path / "killed.zarr"
    for k in range(kills):
        proc = subprocess.Popen(_cli(path), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        # early instants hit the store's creation (just after the imports), later ones chunks being written
        time.sleep(rng.uniform(0.3, 4.0))
        proc.send_signal(signal.SIGKILL)
        err = proc.communicate()[1].decode()
        assert "Traceback" not in err, err
        leftovers = [n for n in os.listdir(tmp_path) if ".creating-" in n and not os.path.exists(path)]
        assert os.path.exists(path) or leftovers or True  # absent, or complete enough to resume (checked next run)
    proc = subprocess.run(_cli(path), capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert not [n for n in os.listdir(tmp_path) if ".creating-" in n], "temporary store left behind"
    assert_same_store(path, cli_reference)


def test_kill_9_at_random_instants_short(cli_reference, tmp_path):
    _kill_loop(cli_reference, tmp_path, kills=5, seed=10)


@pytest.mark.slow
def test_kill_9_at_random_instants_20_times(cli_reference, tmp_path):
    _kill_loop(cli_reference, tmp_path, kills=20, seed=11)


def test_kill_during_creation_leaves_a_resumable_state(cli_reference, tmp_path):
    """A run killed while creating leaves only a hidden temporary store, never a half-made one."""
    path = tmp_path / "created.zarr"
    stale = tmp_path / ".created.zarr.creating-424242"
    stale.mkdir()
    (stale / ".zgroup").write_text('{"zarr_format": 2}')
    proc = subprocess.run(_cli(path), capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert not stale.exists()
    assert_same_store(path, cli_reference)


# -- every reader verifies what the writer and `granchain info` verify --------------------------------
def _flip_bit(path):
    """One flipped bit in a stored value (the exponent's top bit of a peak velocity: 0.87 -> ~1.5e308),
    written through Zarr so that the file still decodes: only its checksum can tell."""
    arr = zarr.open_array(str(path / "peak_velocity"), mode="r+", zarr_format=2)
    value = np.array(arr[0, 12, 1], dtype=np.float64)
    arr[0, 12, 1] = (value.view(np.uint64) ^ np.uint64(1 << 62)).view(np.float64)


def _copy_chunk_from(other):
    """Chunk 1 of a store of another seed (every data file of it, its sums and its checksum record) copied in:
    consistent with itself, so only checksums bound to the store can tell."""
    def fault(path):
        group = zarr.open_group(str(path), mode="r", zarr_format=2, use_consolidated=False)
        names = [str(x) for x in group["progress/checked"][...]] + ["progress/checksum", "progress/done"]
        for name in names:
            dims = group[name].metadata.attributes["_ARRAY_DIMENSIONS"]
            axis = "chunk" if name.startswith("progress/") else "realization"
            key = ".".join("1" if d == axis else "0" for d in dims)
            shutil.copy(os.path.join(other, *name.split("/"), key), os.path.join(path, *name.split("/"), key))
    return fault


def _edit_root_attribute(key, value):
    def fault(path):
        attrs = json.loads((path / ".zattrs").read_text())
        attrs[key] = value
        (path / ".zattrs").write_text(json.dumps(attrs))
    return fault


def _edit_record_seed(path):
    attrs = json.loads((path / ".zattrs").read_text())
    record = json.loads(attrs["granchain_parameters"])
    record["seed"] = 5
    attrs["granchain_parameters"] = json.dumps(record, sort_keys=True)
    (path / ".zattrs").write_text(json.dumps(attrs))


@pytest.fixture(scope="module")
def other_seed(tmp_path_factory):
    path = tmp_path_factory.mktemp("seed2") / "seed2.zarr"
    _run(path, seed=2)
    return path


#: (fault, words every reader's refusal and `granchain info` say)
READER_FAULTS = {
    "flipped-bit": (lambda other: _flip_bit, r"chunk 1 does not match its checksum: the data file peak_velocity/0\.1\.0"),
    "chunk-of-another-seed": (_copy_chunk_from, r"chunk 1 does not match its checksum.*copied from another store"),
    "deleted-chunk": (lambda other: lambda p: _delete(p / "peak_velocity" / "0.1.0"),
                      r"chunk 1 has a missing data file peak_velocity/0\.1\.0"),
    "truncated-chunk": (lambda other: lambda p: _truncate(p / "peak_velocity" / "0.1.0"),
                        r"chunk 1 has an unreadable data file peak_velocity/0\.1\.0 \(truncated or garbled"),
    "deleted-mean-velocity": (lambda other: lambda p: _delete(p / "mean_velocity" / "0.0.0"),
                              r"averaged variable mean_velocity that does not match its checksum"),
    "edited-seed-attribute": (lambda other: _edit_root_attribute("seed", 5),
                              r"root attributes \(\.zattrs\) that do not match the digest.*seed"),
    "edited-seed-in-record": (lambda other: _edit_record_seed,
                              r"parameter record .* differs from the one its chunks were written with \(seed: 5"),
}


@pytest.mark.parametrize("fault", sorted(READER_FAULTS))
def test_every_reader_refuses_what_info_reports(reference, other_seed, tmp_path, fault, capsys):
    """open_store (at once and lazily), `granchain export` and the analysis refuse the damaged store, naming
    it, the file and the fix; `granchain info` reports the same finding; verify=False reads with a warning;
    running the ensemble again repairs the store to the uninterrupted one."""
    from granchain import analysis
    from granchain.cli import main
    from granchain.cli.info import summary
    from granchain.ensembles.verify import StoreDamagedError, StoreVerificationWarning

    make, words = READER_FAULTS[fault]
    path = _copy(reference, tmp_path)
    make(other_seed)(path)
    # (the analysis says it could not read the store, with open_store's refusal)
    for read, error in ((lambda: gc.open_store(path, load=True), StoreDamagedError),
                        (lambda: gc.open_store(path).load(), StoreDamagedError),
                        (lambda: analysis.mean_peak_amplitude(path), ValueError)):
        with pytest.raises(error, match=words) as exc:
            read()
        assert str(path) in str(exc.value) and "run the ensemble command again" in str(exc.value)
        assert "verify=False" in str(exc.value)
    pytest.importorskip("netCDF4")
    assert main(["export", str(path), str(tmp_path / "x.nc")]) == 2
    err = capsys.readouterr().err
    assert re.search(words, err) and "--no-verify" in err and "Traceback" not in err, err
    assert not (tmp_path / "x.nc").exists()
    facts = summary(str(path))
    assert any(re.search(words, line) for line in facts["damaged"] + [f"chunk {j} {w}" for j, w in facts["damaged_chunks"].items()]), facts
    assert main(["info", str(path)]) == 1  # damage reported, and in the exit status
    assert "intact" not in capsys.readouterr().out
    with pytest.warns(StoreVerificationWarning, match="without verifying"):
        if fault == "truncated-chunk":  # nothing can decode that file: still refused, naming what to do
            with pytest.raises(ValueError, match="could not be read.*granchain info"):
                gc.open_store(path, load=True, verify=False)
        else:
            ds = gc.open_store(path, load=True, verify=False)
            assert ds.sizes["realization"] == KW["realizations"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StoreRepairWarning)
        _run(path)
    assert_same_store(path, reference)
    gc.open_store(path, load=True)  # verified again


def test_an_intact_store_is_read_without_a_word(reference, tmp_path, capsys):
    """Negative control of the test above: the undamaged store opens, exports and reports intact, warning-free."""
    from granchain.cli import main

    path = _copy(reference, tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gc.open_store(path, load=True)
        gc.open_store(path).load()
        gc.open_store(path, group="progress").load()
        gc.analysis.mean_peak_amplitude(path)
        assert main(["info", str(path)]) == 0
        assert "intact       every chunk, the averaged pulse and the parameter record match" in capsys.readouterr().out
        pytest.importorskip("netCDF4")
        assert main(["export", str(path), str(tmp_path / "x.nc")]) == 0


def test_the_progress_group_is_verified_too(reference, tmp_path):
    from granchain.ensembles.verify import StoreDamagedError

    path = _copy(reference, tmp_path)
    arr = zarr.open_array(str(path / "progress" / "sum_v"), mode="r+", zarr_format=2)
    arr[2, 0, 1, 5] = arr[2, 0, 1, 5] + 1
    gc.open_store(path, load=True)  # the results do not read the sums
    with pytest.raises(StoreDamagedError, match=r"chunk 2 does not match its checksum: the data file progress/sum_v/2\.0\.0\.0"):
        gc.open_store(path, group="progress", load=True)
    with pytest.raises(ValueError, match="chunk 2 does not match its checksum"):
        gc.analysis.ChunkSums.from_store(path)


def test_a_lazy_read_verifies_only_the_chunks_it_reads(reference, tmp_path):
    """Lazily, each chunk is verified when it is read: a damaged chunk is refused as soon as it is read, and
    the others stay readable (values are hashed as read, never read twice)."""
    from granchain.ensembles.verify import StoreDamagedError

    path = _copy(reference, tmp_path)
    _flip_bit(path)
    ds = gc.open_store(path)
    with xr.open_zarr(reference, consolidated=False) as ref:
        np.testing.assert_array_equal(ds["peak_velocity"].isel(realization=slice(0, 10)).values,
                                      ref["peak_velocity"].isel(realization=slice(0, 10)).values)
        np.testing.assert_array_equal(ds["peak_velocity"].isel(realization=[3, 25, 39]).values,
                                      ref["peak_velocity"].isel(realization=[3, 25, 39]).values)
    with pytest.raises(StoreDamagedError, match="chunk 1"):
        ds["peak_velocity"].isel(realization=15).values


# -- the lock file lives as long as its run --------------------------------------------------------------
def test_no_lock_file_after_a_run_finished_or_refused(reference, tmp_path):
    assert not os.path.exists(f"{reference}.lock")
    path = _copy(reference, tmp_path)
    _run(path)
    assert not os.path.exists(f"{path}.lock")
    with pytest.raises(ValueError, match="different parameters"):
        _run(path, seed=7)
    assert not os.path.exists(f"{path}.lock")
    with pytest.raises(ValueError, match="already exists"):
        _run(path, resume=False)
    assert not os.path.exists(f"{path}.lock")


def test_no_lock_file_after_an_interrupted_run(reference, tmp_path, monkeypatch):
    from granchain.ensembles import run as ens

    compute = ens.compute_chunk

    def interrupted_at_chunk_2(spec, j, **kw):
        if j == 2:
            raise KeyboardInterrupt  # as Ctrl-C in a progress callback
        return compute(spec, j, **kw)

    path = tmp_path / "interrupted.zarr"
    monkeypatch.setattr(ens, "compute_chunk", interrupted_at_chunk_2)
    with pytest.raises(gc.EnsembleInterrupted if hasattr(gc, "EnsembleInterrupted") else KeyboardInterrupt):
        _run(path)
    assert not os.path.exists(f"{path}.lock")
    monkeypatch.setattr(ens, "compute_chunk", compute)
    _run(path)
    assert_same_store(path, reference)
    assert not os.path.exists(f"{path}.lock")


def test_an_interruption_waits_for_the_chunk_being_written(reference, tmp_path, monkeypatch):
    """The chunks are written by a helper thread while the next chunk's kernels run: Ctrl-C during chunk 2,
    with chunk 1 still being written, leaves chunks 0 and 1 in the store, and the resumed run computes
    only the rest and ends bitwise as the uninterrupted one."""
    from granchain.ensembles import run as ens
    from granchain.ensembles.sinks import ZarrSink

    compute, write = ens.compute_chunk, ZarrSink.write
    written, computed = [], []

    def slow_write(self, res):
        time.sleep(0.5)  # chunk 2 starts, and is interrupted, while chunk 1 is being written
        write(self, res)
        written.append(res["chunk"])

    def interrupted_at_chunk_2(spec, j, **kw):
        if j == 2:
            raise KeyboardInterrupt
        return compute(spec, j, **kw)

    def counted(spec, j, **kw):
        computed.append(j)
        return compute(spec, j, **kw)

    path = tmp_path / "interrupted.zarr"
    monkeypatch.setattr(ZarrSink, "write", slow_write)
    monkeypatch.setattr(ens, "compute_chunk", interrupted_at_chunk_2)
    with pytest.raises(ens.EnsembleInterrupted):
        _run(path)
    assert written == [0, 1]
    monkeypatch.setattr(ens, "compute_chunk", counted)
    _run(path)
    assert computed == [2, 3]
    assert_same_store(path, reference)


def test_the_lock_file_is_there_while_held_and_a_second_writer_is_refused(tmp_path):
    from granchain.ensembles.lock import StoreLockedError

    path = str(tmp_path / "s.zarr")
    with StoreLock(path):
        assert json.loads(open(f"{path}.lock").read())["pid"] == os.getpid()
        with pytest.raises(StoreLockedError, match=rf"being written by PID {os.getpid()}"):
            StoreLock(path).acquire()
    assert not os.path.exists(f"{path}.lock")
    lock = StoreLock(path)
    lock.acquire()  # free again
    lock.release()
    lock.release()  # idempotent
    assert not os.path.exists(f"{path}.lock")


def test_a_writer_granted_a_released_file_starts_over(tmp_path, monkeypatch):
    """The race of deleting the lock file on release: B opens the file, A releases (deletes it, unlocks), B is
    granted the lock on the deleted file. B must notice and lock the file at the path instead, so that a
    third writer C is refused (were B to keep the deleted file, C would create a new one and both would write)."""
    import granchain.ensembles.lock as lockmod
    from granchain.ensembles.lock import StoreLockedError

    path = str(tmp_path / "s.zarr")
    a, b = StoreLock(path), StoreLock(path)
    a.acquire()
    real_open, released = os.open, []

    def open_then_release(*args, **kw):
        fd = real_open(*args, **kw)
        if args and str(args[0]).endswith(".lock") and not released:
            released.append(True)
            a.release()  # between B's open and B's flock
        return fd

    monkeypatch.setattr(lockmod.os, "open", open_then_release)
    b.acquire()
    monkeypatch.setattr(lockmod.os, "open", real_open)
    assert released and os.path.exists(f"{path}.lock")
    assert os.stat(f"{path}.lock").st_ino == os.fstat(b._fd).st_ino  # B holds the file at the path
    with pytest.raises(StoreLockedError):
        StoreLock(path).acquire()
    b.release()
    assert not os.path.exists(f"{path}.lock")


def test_resuming_with_other_contact_settings_names_them(reference, tmp_path, capsys):
    from granchain.cli import main

    path = _copy(reference, tmp_path)
    with pytest.raises(ValueError, match=r"written with different contact settings \(family\.contact\.gamma: stored None, "
                                         r"asked 0\.05"):
        _run(path, family=gc.RandomDecorated(6, contact=gc.Viscoelastic(0.05)))
    argv = ["ensemble", "--large", "6", "--realizations", "40", "--chunk-size", "10", "--seed", "1", "--threads", "1",
            "--quiet", "--out", str(path), "--dissipation", "0.05"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "written with different contact settings" in err and "family.contact.gamma" in err, err
    assert "integrates x'' = f(x)" not in err
    assert not os.path.exists(f"{path}.lock")
    assert_same_store(path, reference)  # untouched
