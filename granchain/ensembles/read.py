"""Reading a store: :func:`open_store`, which every granchain reader uses (the analysis, the figures,
``granchain info``, ``export``, ``theory``, the jackknife over chunks), with the records and metadata in
the form this version writes (the schema, :mod:`~granchain.ensembles.schema`, and the compatibility
layer of :mod:`~granchain.ensembles.compat`), writing nothing.
"""

from __future__ import annotations

import json
import os

import numpy as np

from .schema import ALIGNED, AVERAGED, FORCES, PROGRESS, PROGRESS_ALIGNED, RESULTS, WALL, WINDOW
from .compat import current_record
from .files import _short
from .layout import _CHECKED_ATTRS, _PROGRESS_ABOUT, empty_dataset
from .params import stored_parameters

__all__ = ["open_store"]

#: Root attributes that say where and when a store was written (kept as stored by :func:`open_store`);
#: every other attribute granchain writes follows from the parameter record and is given in today's form.
_PROVENANCE = ("created", "history", "granchain_version", "numpy_version", "scipy_version", "numba_version", "source")

_WHAT_TO_GIVE = ("give the path of an ensemble store written by `granchain ensemble --out PATH` or "
                 "granchain.run_ensemble(..., out=PATH), or a netCDF file written by `granchain export`")


def open_store(path, *, group: str | None = None, load: bool = False, verify: bool = True):
    """An ensemble store as an ``xarray.Dataset``, read in the form this version writes.

    Every granchain reader (the analysis, the figures, ``granchain info``, ``export``, ``theory``, the
    jackknife over chunks) opens stores with it. Nothing is written: a store of an earlier version is
    brought up to date in the returned Dataset only (resuming it with :func:`granchain.run_ensemble`
    rewrites its metadata on disk). ``xarray.open_dataset(path, engine="zarr")`` still opens a store
    without granchain, as stored.

    Parameters
    ----------
    path : str or os.PathLike
        A Zarr store (format 2) written by :func:`granchain.run_ensemble` (``out=``) or ``granchain
        ensemble --out``, finished or not, or a netCDF file written by ``granchain export``.
    group : None or "progress"
        None: the results. ``"progress"``: the per-chunk fixed-point sums, checksums and done flags
        (Zarr stores only).
    load : bool
        False: lazy (Dask arrays, read when used). True: every value read into memory.
    verify : bool
        True (default): the store is checked against what its writer recorded
        (:mod:`granchain.ensembles.verify`, the check ``granchain info`` reports): the parameter record
        and root attributes against their digest, every finished chunk read against its checksum (keyed by
        the store, the variable and the chunk), the averaged pulse against its own. Values are hashed as
        they are read: with ``load=True`` at once, lazily as each chunk is computed (a missing data file,
        an edited record or a damaged averaged pulse is found at once). What does not match is refused
        with :class:`~granchain.ensembles.verify.StoreDamagedError` (a ``ValueError``) naming the file and
        how to repair it (running the ensemble again with the same arguments recomputes damaged chunks).
        False: read without checking, with a :class:`~granchain.ensembles.verify.StoreVerificationWarning`.
        Stores written before the checksums were keyed are checked as far as their checksums go (values
        alone); a store of granchain 0.1.0 has none.

    Returns
    -------
    xarray.Dataset
        The stored values, unchanged. The records (attributes ``granchain_parameters``,
        ``granchain_family``, ``granchain_integrator``) are in today's form (the compatibility layer
        ``granchain.ensembles.compat.current_record`` that a resume compares records with:
        ``results_version`` instead of the package version, earlier meanings of family fields
        translated, and for a store of granchain 0.1.0 its family and integrator as records); the other
        attributes granchain writes and the variables' metadata (units, long_name, flags) are those a
        store of the same parameters gets today, except where and when it was written (``created``,
        ``history``, the versions), kept as stored, as is any attribute granchain does not write (the
        ``physical_*`` scale of ``granchain ensemble --material``). The integers an exported netCDF
        file holds in 32 bits are read back in the store's dtypes.

    Raises
    ------
    ValueError
        For a path that is not a granchain store (it says what to give instead), a store whose
        metadata cannot be read (``granchain info PATH`` says what is damaged), a store that does not
        match its checksums (``StoreDamagedError``), or another group.
    """
    import xarray as xr

    if not isinstance(verify, (bool, np.bool_)):
        raise ValueError(f"verify must be True (check the store against its checksums) or False (read it anyway, "
                         f"with a warning), got {verify!r}")
    if not isinstance(load, (bool, np.bool_)):
        raise ValueError(f"load must be True (read every value into memory) or False (lazy), got {load!r}")
    if group not in (None, "progress"):
        raise ValueError(f"group must be None (the results) or 'progress' (the per-chunk sums and done flags), got {group!r}")
    try:
        text = os.fsdecode(os.fspath(path))
    except TypeError:
        raise ValueError(f"path must be a str or os.PathLike naming a store, got {path!r}") from None
    if os.path.isdir(text):
        params = stored_parameters(text)
        if params is None:
            raise ValueError(f"{text} is not a granchain ensemble store (no granchain_parameters record in "
                             f"{os.path.join(text, '.zattrs')} or {os.path.join(text, 'progress', '.zattrs')}): {_WHAT_TO_GIVE}")
        # Everything read at once (load) needs no Dask: chunks=None reads the same values ~5x faster.
        opener = lambda: xr.open_zarr(text, group=group, consolidated=False, zarr_format=2,  # noqa: E731
                                      **({"chunks": None} if load else {}))
    elif os.path.isfile(text):
        with open(text, "rb") as f:
            magic = f.read(8)
        if not (magic.startswith(b"CDF") or magic == b"\x89HDF\r\n\x1a\n"):
            raise ValueError(f"{text} is neither a Zarr store (a directory) nor a netCDF file: {_WHAT_TO_GIVE}")
        if group is not None:
            raise ValueError(f"{text} is a netCDF export, which holds the results only: open the Zarr store it was "
                             f"exported from for the {group!r} group")
        params = None
        opener = lambda: xr.open_dataset(text)  # noqa: E731 -- the netCDF engine that reads the file
    else:
        raise ValueError(f"{text} does not exist: {_WHAT_TO_GIVE}")
    try:
        ds = opener()
    except Exception as exc:  # noqa: BLE001 -- damaged metadata, a missing netCDF engine: said with what to do
        raise ValueError(_unreadable(text, exc)) from None
    try:
        params = ds.attrs.get("granchain_parameters", params)
        if not isinstance(params, str):
            raise ValueError(f"{text} is not a granchain ensemble store (no granchain_parameters attribute): {_WHAT_TO_GIVE}")
        if os.path.isdir(text):
            ds = _checked(ds, text, group, load) if verify else _unchecked(ds, text)
        if load:
            try:
                ds.load()
            except Exception as exc:  # noqa: BLE001 -- a truncated or garbled chunk
                raise ValueError(_unreadable(text, exc)) from None
        result = _todays_form(ds, group, params)
    except BaseException:
        ds.close()
        raise
    if load:
        ds.close()  # the values are in memory: no file stays open
    return result


def _unchecked(ds, path: str):
    import warnings

    from .verify import StoreVerificationWarning

    warnings.warn(f"{path} is read without verifying it (verify=False): damaged or misplaced values are not found; "
                  f"`granchain info {path}` checks it", StoreVerificationWarning, stacklevel=4)
    return ds


def _checked(ds, path: str, group, load: bool):
    """``ds`` (just opened) with every checksummed variable read through the store's check
    (:class:`~granchain.ensembles.verify.StoreCheck`): at once with ``load``, chunk by chunk as Dask asks
    otherwise; the records, the listing of data files and the averaged variables are checked at once."""
    from .verify import StoreCheck, StoreDamagedError, Verification, _undecodable, what_to_do

    try:
        check = StoreCheck(path)
    except Exception as exc:  # noqa: BLE001 -- records the opener read but the check cannot
        raise StoreDamagedError(f"{path}: its checksum records cannot be read ({_short(exc)}); {what_to_do(path)}") from None
    progress = group == "progress"
    names = [n for n in check.names if n.startswith("progress/") == progress]
    found = Verification(path, check.scheme, check.complete, check.missing_files(names), list(check.problems))
    if group is None:
        averaged = {}
        # the averaged variables (no realization dim): small, read and checked at once
        for name in [n for n in ds.data_vars if "realization" not in ds[n].dims] if check.scheme else []:
            try:
                arr = check.group[name]
                averaged[name] = arr[...]
            except Exception as exc:  # noqa: BLE001 -- a truncated or garbled file
                found.problems.append(f"has an unreadable averaged variable {name} ({_undecodable(exc)})")
                continue
            why = check.averaged_problem(name, averaged[name], arr.dtype)
            if why:
                found.problems.append(why)
    if not found.ok:
        raise found.error()
    # The variables' data replaced in place (dims, attributes and encoding kept; no re-alignment of the Dataset).
    local = {name: name.split("/", 1)[1] if progress else name for name in names}
    names = [name for name in names if local[name] in ds.variables]
    values = check.read_variables(names) if load else {}
    for name in names:
        ds.variables[local[name]].data = values[name] if load else _lazy(check, name, ds[local[name]])
    for name, data in (averaged.items() if group is None else ()):
        ds.variables[name].data = data if load else _dask(data, ds[name])
    return ds


def _dask(values, var):
    import dask.array as da

    return da.from_array(values, chunks=var.chunks or values.shape, name=False)


def _lazy(check, name: str, var):
    """A Dask array reading ``name`` chunk by chunk through ``check`` (each chunk verified when read)."""
    import dask.array as da

    source = _VerifiedChunks(check, name)
    chunks = var.chunks or tuple((s,) for s in source.shape)
    return da.from_array(source, chunks=chunks, name=False, lock=False, fancy=False,
                         meta=np.empty((0,) * source.ndim, dtype=source.dtype))


class _VerifiedChunks:
    """An array-like over one checksummed variable: indexing it reads the whole run chunks it touches, each
    verified (:meth:`StoreCheck.read_chunk`), and returns the part asked for."""

    def __init__(self, check, name: str):
        arr, dims, self.axis, self.step = check._layout(name)
        self.check, self.name = check, name
        self.shape, self.dtype, self.ndim = tuple(arr.shape), arr.dtype, arr.ndim

    def __getitem__(self, key):
        key = key if isinstance(key, tuple) else (key,)
        if any(k is Ellipsis for k in key):
            i = next(i for i, k in enumerate(key) if k is Ellipsis)
            key = key[:i] + (slice(None),) * (self.ndim - len(key) + 1) + key[i + 1:]
        key = key + (slice(None),) * (self.ndim - len(key))
        n, r = self.shape[self.axis], key[self.axis]
        index = np.arange(n)[r]
        if np.size(index) == 0:
            return self.check.group[self.name][key]
        lo, hi = int(np.min(index)) // self.step, int(np.max(index)) // self.step
        block = np.concatenate([self.check.read_chunk(self.name, j) for j in range(lo, hi + 1)], axis=self.axis)
        start = lo * self.step
        if isinstance(r, slice):
            a, b, step = r.indices(n)
            local = slice(a - start, b - start if b - start >= 0 else None, step)
        else:
            local = index - start
        return block[key[:self.axis] + (local,) + key[self.axis + 1:]]


def _unreadable(path: str, exc: BaseException) -> str:
    hint = (" (reading netCDF needs the netCDF4 package: pip install 'granchain[netcdf]')"
            if os.path.isfile(path) and "engine" in str(exc) else "")
    return (f"{path} could not be read ({_short(exc)}){hint}; `granchain info {path}` says what is damaged, and running "
            "the ensemble command again (same arguments) repairs it")


def _todays_form(ds, group, params: str):
    """``ds`` (just opened, ours to change) with its records and metadata in today's form (see :func:`open_store`)."""
    try:
        record = current_record(json.loads(params))
    except ValueError:
        raise ValueError("the store's parameter record is not valid JSON: run the ensemble command again (same "
                         "arguments) to restore it from the other copy, or `granchain info` on the store") from None
    if group == "progress":
        _set_metadata(ds, {v.name: v.metadata() for v in PROGRESS + PROGRESS_ALIGNED} | {"checked": _CHECKED_ATTRS})
        ds.attrs.update(granchain_parameters=json.dumps(record, sort_keys=True), about=_PROGRESS_ABOUT)
        return ds
    records = {"granchain_parameters": json.dumps(record, sort_keys=True)}
    for key, name in (("family", "granchain_family"), ("integrator", "granchain_integrator")):
        if isinstance(record.get(key), dict):
            records[name] = json.dumps(record[key], sort_keys=True)
    spec = _spec_of(record, ds)
    if spec is None:  # a CustomFamily (its function is not stored): the records and the results' metadata
        _set_metadata(ds, {v.name: v.metadata() for v in RESULTS + FORCES + WALL + AVERAGED + ALIGNED + WINDOW})
        ds.attrs.update(records)
        return ds
    reference = empty_dataset(spec, lazy=True)
    for name, ref in reference.variables.items():  # a netCDF export's 32-bit integers, back in the store's dtypes
        if name in ds.variables and ds[name].dtype != ref.dtype and ds[name].dtype.kind in "iu" and ref.dtype.kind in "iu":
            cast = ds[name].astype(ref.dtype)
            ds = ds.assign_coords({name: cast}) if name in ds.coords else ds.assign({name: cast})
    _set_metadata(ds, {name: ref.attrs for name, ref in reference.variables.items()})
    # Attributes a store of these parameters gets today; where and when it was written as stored, and any
    # attribute granchain does not write itself (the physical scale of `granchain ensemble --material`, a user's) kept.
    ds.attrs = {**ds.attrs, **reference.attrs, **records, **{k: ds.attrs[k] for k in _PROVENANCE if k in ds.attrs}}
    return ds


def _set_metadata(ds, attrs: dict) -> None:
    for name, value in attrs.items():
        if name in ds.variables:
            ds.variables[name].attrs = dict(value)


def _spec_of(record: dict, ds):
    """The run a store's record (today's form) describes, on the store's own time and lag grids; None where
    it cannot be rebuilt (a CustomFamily, whose function is not stored, or an incomplete record)."""
    import warnings

    from ..families import family_from_record
    from ..solve.integrators import RunControls, integrator_from_record
    from .pulse_window import AUTO, FULL, ends_of_record
    from .run import EnsembleSpec

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # warned about when the ensemble was made
            per_chain = record.get("chain_integrators")
            return EnsembleSpec(
                family_from_record(record["family"]), record["realizations"], record["seed"], tuple(record["chains"]),
                None if per_chain else integrator_from_record(record["integrator"]), np.asarray(ds["time"].values),
                record["chunk_size"], RunControls(record["exit_margin"], record["max_steps"], record["peak_rtol"]),
                np.asarray(ds["lag"].values) if "lag" in ds.coords else None,
                chain_integrators={k: integrator_from_record(r) for k, r in per_chain.items()} if per_chain else None,
                # a record without windows is a run on the whole grid (every store before granchain 0.5)
                pulse_window=AUTO if "pulse_window" in record else FULL,
                pulse_ends=ends_of_record(record.get("pulse_window")))
    except (KeyError, TypeError, ValueError):
        return None
