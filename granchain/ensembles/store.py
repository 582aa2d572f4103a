"""Writing a store and resuming it: the in-memory and Zarr sinks, the stored records and their
compatibility layer (records of earlier versions read in today's form), and the resume check.

What is stored is the schema's (:mod:`~granchain.ensembles.schema`, re-exported here); reading a store
is :func:`granchain.open_store` (:mod:`~granchain.ensembles.read`).
"""

from __future__ import annotations

import datetime as _dt
import json
import os

import numpy as np

from .._status import describe_codes
from .._version import RESULTS_OF_VERSION, __version__
from .schema import (  # the schema's names, as before it had a module of its own
    ALIGNED,
    AVERAGED,
    FORCES,
    PROGRESS,
    PROGRESS_ALIGNED,
    PROGRESS_SUMS,
    RESULTS,
    UNITS_T,
    WALL,
    Variable,
    averaged_variables,
    checked_variables,
    chunk_variables,
    digest,
    parameter_variables,
    per_realisation_variables,
    progress_sum_variables,
    progress_sums,
    progress_variables,
    result_variables,
    sizes,
)
from . import verify as _verify

__all__ = ["MemorySink", "ZarrSink", "StoreRepairWarning", "stored_record", "current_record", "check_same_parameters",
           "check_same_family",
           "integrators_as_run", "ALIGNED", "AVERAGED", "FORCES", "PROGRESS", "PROGRESS_ALIGNED", "PROGRESS_SUMS", "RESULTS", "WALL", "Variable", "averaged_variables", "checked_variables", "chunk_variables", "digest", "parameter_variables", "per_realisation_variables", "progress_sum_variables", "progress_sums", "progress_variables", "result_variables", "sizes"]

def integrators_as_run(spec) -> dict:
    """{chain kind: the record of its integrator as it runs on the family's chains}
    (``granchain.backends.integrator_as_run``): derived from the parameters, so not compared on resume."""
    from ..backends import integrator_as_run
    from ..model.contacts import FreeEnd, LoadedEnd, FixedWall

    boundary = FixedWall if spec.family.wall else (LoadedEnd if spec.family.static_force > 0 else FreeEnd)
    return {kind: integrator_as_run(integ, boundary) for kind, integ in spec.chain_integrators.items()}


def _attrs(spec) -> dict:
    d = spec.describe()
    family = spec.family
    integ = spec.integrator.describe()
    import numba
    import scipy

    created = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    attrs = {
        "Conventions": "CF-1.8",
        "title": f"granchain ensemble: {family.label()}",
        "history": f"{created} created by granchain {__version__} run_ensemble",
        "institution": "granchain users",
        "numpy_version": np.__version__,
        "scipy_version": scipy.__version__,
        "numba_version": numba.__version__,
        "source": f"granchain {__version__} run_ensemble (exact dynamics of paper Eq. motion_rescaled)",
        "references": "U. Harbola, A. Rosas, A. H. Romero and K. Lindenberg, Pulse propagation in decorated random chains",
        "granchain_parameters": json.dumps(d, sort_keys=True),
        "granchain_family": json.dumps(d["family"], sort_keys=True),
        "granchain_integrator": json.dumps(integ, sort_keys=True),
        # the integrators as they ran on the family's chains (a wall switches goal control off, and says why)
        "granchain_integrator_as_run": json.dumps(integrators_as_run(spec), sort_keys=True),
        "granchain_version": __version__,
        "created": created,
        **({} if family.elastic else {"granchain_contact_model": json.dumps(
            {**family.contact_law.describe(), "static_force": family.static_force, "striker_mass": family.striker_mass},
            sort_keys=True)}),
        "family": family.kind,
        "realizations": spec.realizations,
        "seed": spec.seed,
        "n": family.n,
        "integrator": integ["name"],
        "chunk_size": spec.chunk_size,
        "exit_margin": spec.controls.exit_margin,
        "peak_rtol": spec.controls.peak_rtol,
        "max_steps": spec.controls.max_steps,
        "fixed_point_bits": spec.fixed_point_bits,
        "status_codes": describe_codes(),
    }
    for key, value in integ.items():  # e.g. rtol, atol of DP5; dt of Verlet
        if key != "name" and value is not None:
            attrs[key] = value
    record = d["family"]
    for key in ("n_large", "size", "q", "p", "momentum_conserving"):
        if key in record:
            attrs[key] = int(record[key]) if isinstance(record[key], bool) else record[key]
    if "distribution" in record:
        attrs["distribution"] = family.distribution.label()
        for key in ("alpha", "beta"):
            if key in record["distribution"]:
                attrs[key] = record["distribution"][key]
    return attrs


def empty_dataset(spec, lazy: bool):
    """The result Dataset with every variable at full size, filled with its not-computed value."""
    import xarray as xr

    dims = sizes(spec)
    if lazy:
        import dask.array as da

        def full(shape, fill, dtype, dims):
            chunks = tuple(min(spec.chunk_size, s) if d == "realization" else s for d, s in zip(dims, shape))
            return da.full(shape, fill, dtype=dtype, chunks=chunks)

    def var(v: Variable):
        shape = tuple(dims[d] for d in v.dims)
        data = full(shape, v.fill, v.dtype, v.dims) if lazy else np.full(shape, v.fill, dtype=v.dtype)
        return (v.dims, data, v.metadata())

    family = spec.family
    granules, granule_name = family.granule_coordinate()
    coords = {
        "chain": ("chain", np.array(spec.chains, dtype=object).astype(str), {"long_name": "which chain of the realisation"}),
        "realization": ("realization", np.arange(spec.realizations),
                        {"long_name": "realisation index i (random parameters from SeedSequence(seed, spawn_key=(i,)))", "units": "1"}),
        "granule": ("granule", np.asarray(granules), {"long_name": granule_name, "units": "1"}),
        "time": ("time", np.asarray(spec.t_grid), {**UNITS_T, "long_name": "time"}),
        "contact": ("contact", np.asarray(family.contact_coordinate()[0]), {"long_name": family.contact_coordinate()[1], "units": "1"}),
    }
    for dim, (values, long_name) in family.dims().items():  # indices: dimensionless ("1"), strings have no units
        values = np.asarray(values)
        coords[dim] = (dim, values, {"long_name": long_name, **({"units": "1"} if values.dtype.kind in "iuf" else {})})
    if spec.lags is not None:
        coords["lag"] = ("lag", np.asarray(spec.lags), {**UNITS_T,
                                                        "long_name": "time tau after the realisation's own peak time at k"})
    variables = per_realisation_variables(family) + averaged_variables(spec)
    return xr.Dataset({v.name: var(v) for v in variables}, coords=coords, attrs=_attrs(spec))


def progress_dataset(spec):
    """The ``progress`` group (all zeros) and its encoding (one storage chunk per run chunk)."""
    import xarray as xr

    dims = sizes(spec)
    data, encoding = {}, {}
    for v in progress_variables(spec):
        shape = tuple(dims[d] for d in v.dims)
        data[v.name] = (v.dims, np.full(shape, v.fill, dtype=v.dtype), v.metadata())
        encoding[v.name] = {"chunks": (1,) + shape[1:]}
    coords = {"checked": ("checked", np.array(checked_variables(spec), dtype=object).astype(str), dict(_CHECKED_ATTRS))}
    ds = xr.Dataset(data, coords=coords, attrs={"granchain_parameters": json.dumps(spec.describe(), sort_keys=True),
                                                "about": _PROGRESS_ABOUT})
    return ds, encoding


_CHECKED_ATTRS = {"long_name": "variable whose chunk values the checksum covers"}
_PROGRESS_ABOUT = "bookkeeping of granchain.run_ensemble: fixed-point velocity sums per chunk and done flags"


def chunk_dataset(spec, res: dict):
    """The per-realisation variables of one finished chunk (the family's parameters and the results)."""
    import xarray as xr

    out = {v.name: (v.dims, np.asarray(res[v.name]).astype(v.dtype, copy=False))
           for v in per_realisation_variables(spec.family)}
    return xr.Dataset(out)


def mean_from_sums(sum_v, sum_v2, n_valid, bits: int):
    """(mean, standard error) over the last axes from fixed-point sums (chain, ...) and counts (chain,)."""
    scale = 2.0**bits
    nv = n_valid.astype(float).reshape((-1,) + (1,) * (sum_v.ndim - 1))
    s1 = sum_v.astype(float) / scale
    s2 = sum_v2.astype(float) / scale
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = s1 / nv
        var = np.maximum(s2 - s1 * mean, 0.0) / (nv - 1.0)
        stderr = np.sqrt(var / nv)
    return np.where(nv > 0, mean, np.nan), np.where(nv > 1, stderr, np.nan)


def finalize(ds, spec, sum_v, sum_v2, n_valid, sum_a=None, sum_a2=None):
    """mean_velocity (and the aligned pulse, with ``lags``) and standard errors from the exact fixed-point sums;
    with averaged-pulse windows, NaN (not computed) past each granule's window, and the windows themselves."""
    mean, stderr = mean_from_sums(sum_v, sum_v2, n_valid, spec.fixed_point_bits)
    if spec.pulse_ends:
        from .pulse_window import AHEAD, applies

        kinds = applies(spec)
        ends = np.array([spec.pulse_ends.get(c, np.full(sum_v.shape[1], np.inf)) for c in spec.chains])  # (chain, granule)
        past = np.asarray(spec.t_grid)[None, None, :] > ends[:, :, None]
        mean[past] = np.nan
        stderr[past] = np.nan
        ds["pulse_window_end"].values = ends
        ds["pulse_window_ahead"].values = np.array([AHEAD if c in kinds else 0 for c in spec.chains], dtype=np.int64)
    ds["mean_velocity"].values, ds["mean_velocity_stderr"].values = mean, stderr
    if spec.lags is not None:
        ds["aligned_velocity"].values, ds["aligned_velocity_stderr"].values = mean_from_sums(
            sum_a, sum_a2, n_valid, spec.fixed_point_bits)
    ds["n_valid"].values = n_valid.astype(np.int64)
    return ds


class MemorySink:
    """Results kept in memory (no ``out`` path): nothing to resume."""

    def __init__(self, spec):
        self.spec = spec
        self.ds = empty_dataset(spec, lazy=False)
        dims = sizes(spec)  # the progress group's sums, per chunk, as a store holds them
        self.sums = {v.name: np.full(tuple(dims[d] for d in v.dims), v.fill, dtype=v.dtype) for v in progress_sum_variables(spec)}

    def pending(self) -> list[int]:
        return list(range(self.spec.n_chunks))

    def write(self, res: dict) -> None:
        j = res["chunk"]
        sl = self.spec.chunk_slice(j)
        for name, values in chunk_dataset(self.spec, res).data_vars.items():
            self.ds[name][{"realization": sl}] = values
        for name, sums in self.sums.items():
            sums[j] = res[name]

    def finalize(self):
        total = {name: sums.sum(0) for name, sums in self.sums.items()}
        aligned = (total["sum_a"], total["sum_a2"]) if self.spec.lags is not None else ()
        return finalize(self.ds, self.spec, total["sum_v"], total["sum_v2"], total["n_valid"], *aligned)


class StoreRepairWarning(UserWarning):
    """A damaged part of a store was found and is being repaired (the message names it)."""


def _fmt2() -> dict:
    return {"zarr_format": 2}


def _read_json(path):
    """The JSON document in ``path``, or None if it is missing or unreadable."""
    try:
        with open(path, "rb") as f:
            return json.loads(f.read())
    except (OSError, ValueError):
        return None


def stored_parameters(path) -> str | None:
    """The parameter record of a store (progress group first, then the root attributes)."""
    for attrs in (os.path.join(path, "progress", ".zattrs"), os.path.join(path, ".zattrs")):
        doc = _read_json(attrs)
        if isinstance(doc, dict) and isinstance(doc.get("granchain_parameters"), str):
            return doc["granchain_parameters"]
    return None


def writable_array(path, name: str):
    """The existing Zarr array ``name`` of the store at ``path``, open for writing, that writes every
    chunk it is given, even one equal to the fill value (a missing data file means damage:
    :mod:`~granchain.ensembles.verify`). ``zarr.open`` honours ``config`` for an existing array; ``zarr.open_array``
    (zarr 3.1) silently drops it, and a chunk of all zeros (status, done) was then deleted, not written."""
    import zarr

    arr = zarr.open(store=path, path=name, mode="r+", zarr_format=2, config={"write_empty_chunks": True})
    if not isinstance(arr, zarr.Array):
        raise ValueError(f"{path}/{name} is not a Zarr array")
    return arr


def _write_together(writes) -> None:
    """``array[region] = values`` for every (array, region, values), as one batch of Zarr's asynchronous
    writes: the same bytes in the same files as one assignment after the other, but the ~15 writes of a
    chunk overlap (each alone waits ~1 ms for Zarr's I/O thread) instead of queueing one by one. Returns
    once every write is on disk; the first failure is raised."""
    import asyncio

    from zarr.core.sync import sync

    async def together():
        await asyncio.gather(*(array.async_array.setitem(region, values) for array, region, values in writes))

    sync(together())


def _region(dims, axis_dim, sl):
    return tuple(sl if d == axis_dim else slice(None) for d in dims)


def _reference_metadata(spec) -> tuple[dict, set]:
    """Every metadata document (and coordinate chunk) of a fresh store for ``spec``, built in memory:
    {key: bytes}, and the names of the coordinate arrays (their chunks are data to restore)."""
    import zarr

    mapping: dict = {}
    store = zarr.storage.MemoryStore(mapping)
    ds = empty_dataset(spec, lazy=True)
    ds.to_zarr(store, mode="w-", compute=False, consolidated=False, **_fmt2())
    progress, encoding = progress_dataset(spec)
    progress.to_zarr(store, group="progress", mode="a", encoding=encoding, consolidated=False, **_fmt2())
    coords = set(ds.coords) | {f"progress/{c}" for c in progress.coords}
    docs = {k: (v.to_bytes() if hasattr(v, "to_bytes") else bytes(v)) for k, v in mapping.items()}
    docs["progress/.zattrs"] = _sealed(docs[".zattrs"], docs["progress/.zattrs"])
    return docs, coords


def _sealed(root: bytes, progress: bytes) -> bytes:
    """The progress group's attributes (JSON) with the digest of the root attributes (JSON, as stored) added."""
    doc = json.loads(progress)
    doc[_verify.ATTRIBUTES_DIGEST] = _verify.attributes_digest(json.loads(root))
    return json.dumps(doc, indent=4, sort_keys=True).encode()


_VOLATILE_ATTRS = _verify.VOLATILE  # kept from the store when root attributes are restored


class ZarrSink:
    """Results in a Zarr store at ``path``; finished chunks survive any interruption.

    * creation is atomic: the store is built under a temporary name and renamed into place;
    * one writer: ``path + ".lock"`` (:class:`StoreLock`) is held for the whole run;
    * each chunk's values are checksummed (progress/checksum) before its ``done`` flag; on resume
      damaged metadata is restored from the parameters, every done chunk is verified, and a chunk
      whose data are missing, unreadable or changed is recomputed (a warning names it and why);
    * a store asked for more realisations than it holds is extended (realisation i depends only
      on (seed, i), so the result equals a fresh run of the larger size bitwise).
    """

    def __init__(self, spec, path, resume: bool = True, log=None):
        from .lock import StoreLock

        self.spec, self.path = spec, _check_out(path)
        self.log = log or (lambda message: None)
        self._arrays = {}  # Zarr arrays opened by write(), by name
        # the key of this store's checksums: its parameter record less the realisations (granchain.ensembles.verify)
        self.identity = _verify.store_identity(json.dumps(spec.describe(), sort_keys=True))
        self.lock = StoreLock(self.path)
        self.lock.acquire()
        try:
            if not os.path.lexists(self.path):
                self._create()
            else:
                if not resume:
                    raise ValueError(f"{self.path} already exists: pass resume=True (CLI: --resume) to continue it, "
                                     "or choose another path")
                self._open_existing()
        except BaseException:
            self.lock.release()
            raise

    # ------------------------------------------------------------------ creation
    def _create(self):
        import zarr

        parent, name = os.path.split(os.path.abspath(self.path))
        for stale in os.listdir(parent):  # left by a run killed while creating (we hold the lock)
            if stale.startswith(f".{name}.creating-"):
                import shutil

                shutil.rmtree(os.path.join(parent, stale), ignore_errors=True)
        tmp = os.path.join(parent, f".{name}.creating-{os.getpid()}")
        empty_dataset(self.spec, lazy=True).to_zarr(tmp, mode="w-", compute=False, consolidated=False, **_fmt2())
        progress, encoding = progress_dataset(self.spec)
        progress.to_zarr(tmp, group="progress", mode="a", encoding=encoding, consolidated=False, **_fmt2())
        self._write_fill(tmp, slice(0, self.spec.realizations))
        attrs = os.path.join(tmp, "progress", ".zattrs")
        with open(os.path.join(tmp, ".zattrs"), "rb") as root, open(attrs, "rb") as progress:
            _atomic_write(attrs, _sealed(root.read(), progress.read()))
        zarr.consolidate_metadata(tmp, zarr_format=2)
        os.rename(tmp, self.path)  # atomic: the store is absent or complete

    def _write_fill(self, path, sl):
        """Write the not-computed value of every per-realisation variable in ``sl`` explicitly, so that
        every reader (xarray, zarr) sees status = -1, n_steps = -1 and NaN there."""
        for v in per_realisation_variables(self.spec.family):
            arr = writable_array(path, v.name)
            region = _region(v.dims, "realization", sl)
            shape = tuple(s.stop - s.start if isinstance(s, slice) and s.stop is not None else n
                          for s, n in zip(region, arr.shape))
            arr[region] = np.full(shape, v.fill, dtype=v.dtype)

    # ------------------------------------------------------------------ resume
    def _open_existing(self):
        import dataclasses

        path = self.path
        if not os.path.isdir(path):
            raise ValueError(f"{path} exists and is not a directory (a Zarr store is a directory): choose another path")
        stored = stored_parameters(path)
        if stored is None:
            if os.path.exists(os.path.join(path, ".zgroup")) or os.path.exists(os.path.join(path, "progress")):
                raise ValueError(
                    f"{path} has lost its parameter record (both {os.path.join(path, '.zattrs')} and "
                    f"{os.path.join(path, 'progress', '.zattrs')} are missing or unreadable), so its results cannot be "
                    f"trusted: delete it (rm -r {path}) and run again")
            raise ValueError(f"{path} exists but is not a granchain ensemble store; choose another path")
        old_realizations = check_same_parameters(path, stored, self.spec, extend=True)
        old = dataclasses.replace(self.spec, realizations=old_realizations)
        if old.fixed_point_bits != self.spec.fixed_point_bits:
            raise ValueError(
                f"{path} holds {old_realizations} realisations summed with {old.fixed_point_bits} fixed-point bits; "
                f"{self.spec.realizations} realisations need {self.spec.fixed_point_bits} bits (more than 2^20 realisations), "
                "so they cannot extend it bitwise: start a new store for this run")
        # checksums of the values alone (before checksum_scheme 2): accepted once, and re-keyed by _verify
        unbound = (_read_json(os.path.join(path, "progress", "checksum", ".zattrs")) or {}).get("checksum_scheme") is None
        self._repair_metadata(old, warn=True)
        bad = self._verify(old, accept_unbound=unbound)
        if bad:
            self._mark_undone(bad)
        if old_realizations < self.spec.realizations:
            self._extend(old)
        import zarr

        zarr.consolidate_metadata(path, zarr_format=2)

    def _repair_metadata(self, spec, warn: bool):
        """Restore every metadata document (and coordinate) that differs from a fresh store's for ``spec``."""
        import zarr

        reference, coords = _reference_metadata(spec)
        stored_root = _read_json(os.path.join(self.path, ".zattrs")) or {}
        stored_progress = _read_json(os.path.join(self.path, "progress", ".zattrs")) or {}
        rewritten = []
        for key, raw in sorted(reference.items()):
            if not key.endswith((".zgroup", ".zattrs", ".zarray")):
                continue
            want = json.loads(raw)
            keep = stored_root if key == ".zattrs" else stored_progress if key == "progress/.zattrs" else {}
            for k in _VOLATILE_ATTRS:
                if k in keep and k in want:
                    want[k] = keep[k]
            if key == "progress/.zattrs" and warn and _verify.AVERAGED_DIGESTS in keep:
                want[_verify.AVERAGED_DIGESTS] = keep[_verify.AVERAGED_DIGESTS]  # until finalize writes them anew
            if key in (".zattrs", "progress/.zattrs") and not warn and "history" in want:
                want["history"] = (keep.get("history", want["history"]) + "\n" +
                                   f"{_dt.datetime.now(_dt.timezone.utc).isoformat(timespec='seconds')} extended to "
                                   f"{spec.realizations} realisations by granchain {__version__}")
            file = os.path.join(self.path, *key.split("/"))
            have = _read_json(file)
            if have == want:
                continue
            rewritten.append(f"{key} ({'missing' if not os.path.exists(file) else 'unreadable' if have is None else 'changed'})")
            os.makedirs(os.path.dirname(file), exist_ok=True)
            _atomic_write(file, json.dumps(want, indent=4, sort_keys=True).encode())
        if warn and rewritten:  # one warning: an upgrade from an earlier version rewrites many files at once
            written_by = stored_root.get("granchain_version") or stored_progress.get("granchain_version")
            by = f"written by granchain {written_by}; " if written_by and written_by != __version__ else ""
            self._warn(f"{self.path}: {len(rewritten)} metadata file(s) were missing, unreadable, edited, or in an earlier "
                       f"version's form ({by}units, descriptions and records change between versions); rewrote them from "
                       f"the stored parameters, results untouched: {', '.join(rewritten)}")
        ref_group = zarr.open_group(zarr.storage.MemoryStore({k: _buf(v) for k, v in reference.items()}), mode="r",
                                    zarr_format=2, use_consolidated=False)
        disk = zarr.open_group(self.path, mode="r+", zarr_format=2, use_consolidated=False)
        for name in sorted(coords):
            want = ref_group[name][...]
            try:
                same = np.array_equal(disk[name][...], want)
            except Exception:  # noqa: BLE001 -- unreadable coordinate chunks are restored
                same = False
            if not same:
                if warn:
                    self._warn(f"coordinate {os.path.join(self.path, name)} was missing or damaged; restored it")
                disk[name][...] = want

    def _verify(self, spec, accept_unbound: bool = False) -> list[int]:
        """Done chunks whose stored values do not match their checksums (with the reason reported): the check
        every reader makes (:class:`granchain.ensembles.verify.StoreCheck`). With ``accept_unbound`` (a store
        written before checksum_scheme 2), checksums of the values alone are accepted, and re-keyed."""
        import zarr

        group = zarr.open_group(self.path, mode="r", zarr_format=2, use_consolidated=False)
        done, bad = self._done_flags(group, spec)
        check = _verify.StoreCheck(self.path, accept_unbound=accept_unbound)
        check.done = done  # read flag by flag: an unreadable one (warned about) counts as not done
        if check.sums is None and (check.done == 1).any():  # an unreadable checksum record: every done chunk redone
            damaged = {int(j): "has an unreadable checksum record (progress/checksum)" for j in np.flatnonzero(check.done == 1)}
        else:
            damaged, values = {}, {}
            for name in check.names:
                try:
                    values[name] = check.read_variable(name, damaged)
                except Exception as exc:  # noqa: BLE001 -- unreadable metadata: every done chunk of it is redone
                    for j in np.flatnonzero(check.done == 1):
                        damaged.setdefault(int(j), f"has unreadable metadata for {name} ({_short(exc)})")
            self._rekey(check, sorted(check.unbound - set(damaged)), values)
        for j, reason in sorted(damaged.items()):
            sl = spec.chunk_slice(j)
            self._warn(f"{self.path}: chunk {j} (realisations {sl.start}-{sl.stop - 1}) {reason}; recomputing it")
        return sorted(set(bad) | set(damaged))

    def _rekey(self, check, chunks, values) -> None:
        """Rewrite the checksums of ``chunks`` (verified against checksums of their values alone, as stores
        written before checksum_scheme 2 hold them) keyed by this store's identity, variable and chunk."""
        if not chunks or any(values.get(name) is None for name in check.names):
            return  # (a variable that could not be read whole: re-keyed by the next resume)
        arr = writable_array(self.path, "progress/checksum")
        for j in chunks:
            row = []
            for name in check.names:
                a, dims, axis, step = check._layout(name)
                part = values[name][check._region(a, dims, axis, step, j)]
                row.append(digest(part, a.dtype, self.identity, _verify.chunk_label(name, j)))
            arr[j:j + 1] = np.array([row], dtype=np.int64)

    def _done_flags(self, group, spec, warn: bool = True):
        done, unreadable = np.zeros(spec.n_chunks, dtype=np.int8), []
        for j in range(spec.n_chunks):
            try:
                done[j] = group["progress/done"][j]
            except Exception:  # noqa: BLE001 -- an unreadable flag counts as not done
                unreadable.append(j)
                if warn:
                    self._warn(f"{self.path}: the done flag {os.path.join(self.path, 'progress', 'done', str(j))} is "
                               f"unreadable; chunk {j} will be recomputed")
        return done, unreadable

    def _mark_undone(self, chunks):
        done = writable_array(self.path, "progress/done")
        for j in chunks:
            done[j] = 0

    def _extend(self, old):
        """Grow the store from ``old.realizations`` to ``self.spec.realizations`` (same seed, same chunks)."""
        import zarr

        spec = self.spec
        self.log(f"extending {self.path} from {old.realizations} to {spec.realizations} realisations")
        last = old.n_chunks - 1
        start = old.realizations
        if old.chunk_slice(last) != spec.chunk_slice(last):  # the old last chunk was short: redo it whole
            self._mark_undone([last])
            start = old.chunk_slice(last).start
        group = zarr.open_group(self.path, mode="r+", zarr_format=2, use_consolidated=False)
        for v in per_realisation_variables(spec.family):
            arr = group[v.name]
            arr.resize(tuple(spec.realizations if d == "realization" else n for d, n in zip(v.dims, arr.shape)))
        group["realization"].resize((spec.realizations,))
        group["realization"][old.realizations:] = np.arange(old.realizations, spec.realizations)
        for v in progress_variables(spec):
            arr = writable_array(self.path, f"progress/{v.name}")
            shape = (spec.n_chunks,) + arr.shape[1:]
            arr.resize(shape)
            arr[old.n_chunks:] = np.full((spec.n_chunks - old.n_chunks,) + shape[1:], v.fill, dtype=v.dtype)
        self._write_fill(self.path, slice(start, spec.realizations))
        self._repair_metadata(spec, warn=False)  # the parameter record last: a crash before it repeats the extension

    def _warn(self, message: str):
        import warnings

        warnings.warn(message, StoreRepairWarning, stacklevel=4)

    # ------------------------------------------------------------------ the run
    def _progress(self):
        import xarray as xr

        return xr.open_zarr(self.path, group="progress", consolidated=False, chunks=None)

    def pending(self) -> list[int]:
        import zarr

        group = zarr.open_group(self.path, mode="r", zarr_format=2, use_consolidated=False)
        done, _ = self._done_flags(group, self.spec, warn=False)
        return [j for j in range(self.spec.n_chunks) if done[j] != 1]

    def _array(self, name: str):
        """The store's Zarr array ``name`` (``progress/...`` for the progress group), opened once per run.
        Chunks equal to the fill value are written too: a missing data file means damage (verify.StoreCheck)."""
        if name not in self._arrays:
            self._arrays[name] = writable_array(self.path, name)
        return self._arrays[name]

    def write(self, res: dict) -> None:
        """Chunk ``res["chunk"]``: its per-realisation values, its sums and checksums, then its done flag.

        Written with Zarr directly, into arrays opened once: the same bytes as ``Dataset.to_zarr`` with
        a region (the values are stored as they are, in the store's dtypes and codecs), without its
        ~0.1 s per chunk of re-opening and re-validating the store (12 s of the paper's run, while the
        threads of the next chunk waited)."""
        spec, j = self.spec, res["chunk"]
        sl = spec.chunk_slice(j)
        variables, sums = per_realisation_variables(spec.family), progress_sums(spec)
        values = {v.name: np.asarray(res[v.name]).astype(v.dtype, copy=False) for v in variables}
        # One chunk's sums (their schema dims without ``chunk`` in the result), with a leading chunk axis.
        table = {v.name: v for v in progress_variables(spec)}
        for name in sums:
            values[f"progress/{name}"] = np.asarray(res[name], dtype=table[name].dtype)[None]
        check = np.array([[digest(values[name], values[name].dtype, self.identity, _verify.chunk_label(name, j))
                           for name in checked_variables(spec)]], dtype=np.int64)
        here = slice(j, j + 1)
        writes = [(self._array(v.name), _region(v.dims, "realization", sl), values[v.name]) for v in variables]
        writes += [(self._array(f"progress/{name}"), _region(table[name].dims, "chunk", here), values[f"progress/{name}"])
                   for name in sums]
        writes.append((self._array("progress/checksum"), here, check))
        _write_together(writes)
        # The flag last: a chunk counts as done only once all its data and checksums are on disk.
        self._array("progress/done")[here] = np.ones(1, dtype=np.int8)

    def finalize(self):
        import xarray as xr
        import zarr

        try:
            # Read back without Dask (chunks=None): the same values, dtypes, attributes and encoding, at a
            # fifth of the time of loading through Dask's scheduler (~0.5 s per N = 26 store of 30,000).
            with self._progress() as p:
                prog = p.load()
            with xr.open_zarr(self.path, consolidated=False, chunks=None) as d:
                ds = d.load()
            aligned = (prog["sum_a"].values.sum(0), prog["sum_a2"].values.sum(0)) if self.spec.lags is not None else ()
            ds = finalize(ds, self.spec, prog["sum_v"].values.sum(0), prog["sum_v2"].values.sum(0),
                          prog["n_valid"].values.sum(0), *aligned)
            region = {"chain": slice(None), "granule": slice(None), "time": slice(None)}
            if self.spec.lags is not None:
                region["lag"] = slice(None)
            names = [v.name for v in averaged_variables(self.spec)]
            ds[names].to_zarr(self.path, region=region, mode="r+", consolidated=False, **_fmt2())
            # their checksums after them: a run stopped in between leaves a store the readers refuse and a resume repairs
            attrs = os.path.join(self.path, "progress", ".zattrs")
            doc = _read_json(attrs) or {}
            doc[_verify.AVERAGED_DIGESTS] = _verify.averaged_digests(self.identity, self.spec.realizations, ds, names)
            _atomic_write(attrs, json.dumps(doc, indent=4, sort_keys=True).encode())
            zarr.consolidate_metadata(self.path, zarr_format=2)
            return ds
        finally:
            self.close()

    def close(self):
        self.lock.release()


def _buf(raw: bytes):
    from zarr.core.buffer import default_buffer_prototype

    return default_buffer_prototype().buffer.from_bytes(raw)


def _short(exc) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0] if text else ''}"[:160]


def _atomic_write(file: str, data: bytes) -> None:
    tmp = f"{file}.tmp-{os.getpid()}"
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, file)


def _check_out(path, create: bool = True) -> str:
    """The store path as a string, refusing what can never be a store (with what to change). ``create``:
    make its folder; without, only check that it can be made (a run's arguments, before anything is
    computed or written)."""
    try:
        text = os.fspath(path)
    except TypeError:
        raise ValueError(f"out must be a path (str or pathlib.Path), got {path!r}") from None
    if isinstance(text, bytes):
        text = os.fsdecode(text)
    if not text.strip():
        raise ValueError("out must be a non-empty path such as runs/N26.zarr (CLI: --out), got an empty string")
    parent = os.path.dirname(os.path.abspath(text)) or "."
    if os.path.lexists(text) and not os.path.isdir(text):
        raise ValueError(f"out = {text} is an existing file, not a Zarr store (a directory): choose another path")
    if not create:
        existing = parent
        while not os.path.exists(existing) and os.path.dirname(existing) != existing:
            existing = os.path.dirname(existing)
        if not os.path.isdir(existing):
            raise ValueError(f"out = {text}: cannot create its folder {parent} ({existing} is a file); choose a writable path")
        if not os.access(existing, os.W_OK | os.X_OK):
            raise ValueError(f"out = {text}: its folder {existing} is not writable; choose a writable path")
        return text
    try:
        os.makedirs(parent, exist_ok=True)
    except OSError as exc:
        raise ValueError(f"out = {text}: cannot create its folder {parent} ({exc.strerror}); choose a writable path") from None
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ValueError(f"out = {text}: its folder {parent} is not writable; choose a writable path")
    return text


def _current_family_record(record: dict) -> dict:
    """The record today's granchain writes for the family an earlier version recorded (records whose
    fields changed meaning, such as TaperedDecorated's q, are read in their own version's meaning)."""
    from ..families import family_from_record

    try:
        return family_from_record(record).describe()
    except (ValueError, KeyError, TypeError):  # a CustomFamily (its function is not stored), or unknown: as stored
        return record


def _record_of_010(record: dict) -> dict:
    """A granchain 0.1.0 record with its family and integrator as records: 0.1.0 stored the paper's family
    (RandomDecorated) and its one integrator, the exact DP5, as flat fields (n_large, distribution, n,
    momentum_conserving; integrator "dp5", rtol, atol). Today's ``DP5(rtol, atol)`` reproduces its
    realisations bitwise (tests/test_families.py)."""
    from ..families import RandomDecorated
    from ..model.chain import HERTZ
    from ..solve.integrators import DP5

    record = dict(record)
    record["family"] = {"family": RandomDecorated.kind, "n_large": record.pop("n_large"),
                        "distribution": record.pop("distribution"), "n": record.pop("n", HERTZ),
                        "momentum_conserving": bool(record.pop("momentum_conserving", False))}
    if record.get("integrator") == "dp5" and "rtol" in record and "atol" in record:
        record["integrator"] = DP5(record.pop("rtol"), record.pop("atol")).describe()
    return record


def current_record(record: dict) -> dict:
    """A stored parameter record in the form this version writes, so that a store of an earlier
    granchain that computed the same numbers compares equal: the package version it names becomes
    its results version (:data:`granchain._version.RESULTS_OF_VERSION`; an unknown version is left
    as it is, and the comparison then refuses it), and the family record is today's (fields whose
    meaning changed, such as TaperedDecorated's q, read in their own version's meaning). A record of
    granchain 0.1.0, which named its family and integrator by flat fields, gets both as records."""
    record = dict(record)
    if "family" not in record and "n_large" in record and "distribution" in record:
        record = _record_of_010(record)
    if "results_version" not in record and record.get("granchain_version") in RESULTS_OF_VERSION:
        record["results_version"] = RESULTS_OF_VERSION[record.pop("granchain_version")]
    if isinstance(record.get("family"), dict):
        record["family"] = _current_family_record(record["family"])
    return record


def _flatten(record: dict, prefix: str = "") -> dict:
    """{"family.contact.gamma": 0.07, ...}: a nested record's leaves by dotted path, so that a refusal names
    the very settings that differ (a contact law's damping, a static force) rather than whole records."""
    out = {}
    for key, value in record.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict) and value:
            out.update(_flatten(value, name + "."))
        else:
            out[name] = value
    return out


def check_same_parameters(path, stored: str | None, spec, extend: bool = False) -> int:
    """Refuse to resume a store written with other parameters, listing the differences; returns the
    stored number of realisations (with ``extend``, a store may hold fewer than asked: it is extended)."""
    if stored is None:
        raise ValueError(f"{path} is not a granchain ensemble store (no granchain_parameters); choose another path")
    try:
        old = json.loads(stored)
    except ValueError:
        raise ValueError(f"{path}: its parameter record is not valid JSON; delete the store (rm -r {path}) and run again") from None
    new = json.loads(json.dumps(spec.describe(), sort_keys=True))
    if "family" not in old and "n_large" in old:  # granchain 0.1.0: no family record, no contact forces stored
        raise ValueError(f"{path} was written by granchain {old.get('granchain_version', '0.1.0')}, before contact forces and "
                         "family records were stored: it reads (xarray, granchain.analysis, the figures) but cannot be resumed "
                         "or extended; write a new store (the same family, seed and integrator=granchain.DP5(1e-6, 1e-9) "
                         "reproduce its realisations bitwise)")
    old = json.loads(json.dumps(current_record(old), sort_keys=True))  # an earlier version's record, in today's form
    stored_r = old.get("realizations")
    if extend and isinstance(stored_r, int) and stored_r <= new["realizations"]:
        old = {**old, "realizations": new["realizations"]}
    if old != new:
        diff, what = _differences(old, new)
        hint = " (a store can be extended to more realisations, never shrunk)" if old.get("realizations") != new["realizations"] else ""
        if old.get("pulse_window") != new.get("pulse_window") and "pulse_window" not in old:
            hint += (" (a store written before granchain 0.5 with a trailing window, whose granules behind it report the "
                     "velocity they left with, is resumed with pulse_window=\"full\", on the command line --pulse-window full)")
        if old.get("integrator") != new.get("integrator") or old.get("chain_integrators") != new.get("chain_integrators"):
            hint += (" (a store written with the exact DP5, every granule integrated to the end as before "
                     "granchain 0.3, is resumed with integrator=granchain.DP5(1e-6, 1e-9), on the command line "
                     "--integrator dp5 --rtol 1e-6 --atol 1e-9 --error-control exact; one written with granchain "
                     "0.3's defaults with integrator={'decorated': granchain.DP5.relaxed(), 'effective': "
                     "granchain.DP5.relaxed(5e-8, 5e-11)}, on the command line --integrator dp5; one written with "
                     "granchain 0.4's defaults with integrator={'decorated': granchain.RKN4.relaxed(1e-5, 1e-8), "
                     "'effective': granchain.DP5.relaxed(5e-8, 5e-11)})")
        raise ValueError(f"{path} was written with {what} ({diff}){hint}; "
                         "results are never mixed: use another path, or the stored parameters to resume")
    return int(stored_r)


#: The family fields that are its contacts (the law, its exponent, the static load, the striker, the wall).
_CONTACT_FIELDS = ("contact", "contact_model", "static_force", "striker_mass", "wall", "n")


def _differences(old: dict, new: dict, prefix: str = "") -> tuple[str, str]:
    """("name: stored x, asked y, ...", "different contact settings" / "different parameters") of two records."""
    flat_old, flat_new = _flatten(old, prefix), _flatten(new, prefix)
    keys = [k for k in sorted(set(flat_old) | set(flat_new)) if flat_old.get(k) != flat_new.get(k)]
    diff = ", ".join(f"{k}: stored {flat_old.get(k)!r}, asked {flat_new.get(k)!r}" for k in keys)
    contact = [k for k in keys if k.startswith("family.") and k.split(".")[1] in _CONTACT_FIELDS]
    if contact:
        return diff, "different contact settings" + (" and parameters" if len(contact) < len(keys) else "")
    return diff, "different parameters"


def check_same_family(path, family) -> None:
    """Refuse to continue a store written for another family (other contact settings: law, damping, static
    load, striker, wall), naming what differs, before anything else is taken from the store (its
    integrators, which suit its own contact law). Nothing happens where ``path`` holds no readable record
    (a new store; :func:`check_same_parameters` judges the rest)."""
    try:
        stored = stored_parameters(path) if os.path.isdir(path) else None
        old = current_record(json.loads(stored)).get("family") if stored is not None else None
    except (TypeError, ValueError, OSError):
        return
    if not isinstance(old, dict):
        return
    old = {"family": json.loads(json.dumps(old, sort_keys=True))}
    new = {"family": json.loads(json.dumps(family.describe(), sort_keys=True))}
    if old != new:
        diff, what = _differences(old, new)
        raise ValueError(f"{path} was written with {what} ({diff}); results are never mixed: use another path, or "
                         "the stored settings to resume (`granchain info STORE` shows them)")


def stored_record(ds, key: str = "family") -> dict | None:
    """The family (``key="family"``), integrator or run (``"parameters"``) record of an ensemble, in the
    form this version writes (:func:`current_record`: a record of an earlier version is read in its own
    meaning). ``ds``: a Dataset (``run_ensemble``'s result, a store opened by any reader) or the path of
    a store (:func:`open_store`). None where the Dataset holds no such record."""
    if isinstance(ds, (str, os.PathLike)):
        from .read import open_store

        ds = open_store(ds)
    params = ds.attrs.get("granchain_parameters")
    record = current_record(json.loads(params)) if params is not None else {}
    if key == "parameters":
        return record or None
    name = {"family": "granchain_family", "integrator": "granchain_integrator"}[key]
    text = ds.attrs.get(name)
    if text is not None:
        stored = json.loads(text)
        return _current_family_record(stored) if key == "family" else stored
    found = record.get(key)  # records of granchain 0.1.0 have neither attribute: its parameters name both
    return found if isinstance(found, dict) else None
