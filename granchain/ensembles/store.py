"""The ensemble store: one schema table, the in-memory and Zarr sinks, the resume check and the reader.

The schema (:data:`RESULTS`, :data:`AVERAGED`, :data:`PROGRESS`, plus the family's own
random parameters) is the single place that names the variables, their dimensions, dtypes, fill
values and metadata: the ensemble runner allocates its compute buffers from it
(:func:`chunk_variables`), and the writer, the resume check, the reader :func:`open_store` (which
every granchain reader uses), the analysis and the tests read it.

Layout of a store (dims ``chain``, ``realization``, ``granule`` = the family's observed
granules, ``time``, and the family's parameter dims such as ``gap``):

* root group: the family's random parameters ``(realization, ...)``, the per-realisation
  results ``(chain, realization[, granule])``, the averaged pulse ``(chain, granule, time)``;
  attributes: the family, integrator and run records (JSON) and every parameter;
* ``progress`` group: per chunk of realisations the fixed-point sums of the averaged pulse
  and a ``done`` flag (sums first, flag last; Zarr writes each storage chunk atomically).
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
from dataclasses import dataclass, field

import numpy as np

from .._status import NOT_COMPUTED, Status, describe_codes
from .._version import RESULTS_OF_VERSION, __version__
from ..units import RESCALED, rescaled_attrs

__all__ = ["Variable", "RESULTS", "FORCES", "WALL", "AVERAGED", "ALIGNED", "PROGRESS", "PROGRESS_ALIGNED", "MemorySink",
           "ZarrSink", "StoreRepairWarning", "open_store", "stored_record", "check_same_parameters", "checked_variables",
           "result_variables", "per_realisation_variables", "progress_sum_variables", "chunk_variables"]

#: Rescaled quantities are stored as dimensionless numbers (units "1": pint, pint-xarray and UDUNITS
#: read them), with what they count in ``rescaled_quantity``/``units_description`` (granchain.units).
UNITS_V = rescaled_attrs("velocity")
UNITS_T = rescaled_attrs("time")
UNITS_F = rescaled_attrs("force")


@dataclass(frozen=True)
class Variable:
    """One stored variable: dimensions, dtype, fill value (= not computed) and metadata."""

    name: str
    dims: tuple
    dtype: str
    fill: object
    units: str | dict  # a units string pint parses, or rescaled_attrs(kind) for a rescaled quantity
    long_name: str
    attrs: dict = field(default_factory=dict)

    def metadata(self) -> dict:
        units = dict(self.units) if isinstance(self.units, dict) else {"units": self.units}
        return {**units, "long_name": self.long_name, **self.attrs}


#: Per-realisation results of every chain.
RESULTS = (
    Variable("peak_velocity", ("chain", "realization", "granule"), "float64", np.nan, UNITS_V,
             "maximum velocity of large granule k in the realisation"),
    Variable("peak_time", ("chain", "realization", "granule"), "float64", np.nan, UNITS_T,
             "time of the maximum velocity of large granule k (arrival time)"),
    Variable("status", ("chain", "realization"), "int8", NOT_COMPUTED, "1",
             "integration status (0 = success; -1 = not computed)",
             {"flag_values": [NOT_COMPUTED] + [int(s) for s in Status],
              "flag_meanings": " ".join(["NOT_COMPUTED"] + [s.name for s in Status])}),
    Variable("energy_error", ("chain", "realization"), "float64", np.nan, "1", "relative energy drift (E_end - E_0)/E_0"),
    Variable("n_steps", ("chain", "realization"), "int64", -1, "1", "accepted integration steps"),
    Variable("t_end", ("chain", "realization"), "float64", np.nan, UNITS_T, "time the integration stopped"),
)

#: Peak contact forces per realisation. The ``contact`` dimension is the family's
#: (:meth:`granchain.ChainFamily.contact_coordinate`), the same for every chain of the family:
#: decorated families, contact q on the right of large granule q (decorated chain: large granule q
#: and small granule q; effective chain: q and q+1); other families, every contact (q and q+1).
FORCES = (
    Variable("peak_force", ("chain", "realization", "contact"), "float64", np.nan, UNITS_F,
             "maximum contact force c delta^(n-1) of contact q (decorated families: the contact on the right of "
             "large granule q; other families: between granules q and q+1)"),
    Variable("peak_force_time", ("chain", "realization", "contact"), "float64", np.nan, UNITS_T,
             "time of the maximum force of contact q (the compression maximum)"),
)

#: Families with a rigid wall at the far end (``wall=True``): the wall contact's peak force.
WALL = (
    Variable("peak_wall_force", ("chain", "realization"), "float64", np.nan, UNITS_F,
             "maximum force on the rigid wall at the far end of the chain"),
    Variable("peak_wall_force_time", ("chain", "realization"), "float64", np.nan, UNITS_T,
             "time of the maximum force on the wall"),
)


def result_variables(family) -> tuple:
    """The per-realisation results a family's store holds: :data:`RESULTS`, :data:`FORCES`, and
    :data:`WALL` when its chains end in a wall."""
    return RESULTS + FORCES + (WALL if family.wall else ())


def per_realisation_variables(family) -> tuple:
    """Everything stored per realisation (dimension ``realization``): the family's random
    parameters and its results. Written chunk by chunk, checksummed, filled, extended."""
    return parameter_variables(family) + result_variables(family)


#: The averaged pulse, computed from the exact fixed-point sums once every chunk is done.
AVERAGED = (
    Variable("mean_velocity", ("chain", "granule", "time"), "float64", np.nan, UNITS_V,
             "ensemble-averaged velocity <v_k(t)> of large granule k over successful realisations"),
    Variable("mean_velocity_stderr", ("chain", "granule", "time"), "float64", np.nan, UNITS_V, "standard error of <v_k(t)>"),
    Variable("n_valid", ("chain",), "int64", 0, "1", "successful realisations in mean_velocity"),
)

#: The aligned pulse (only in ensembles run with ``lags``): <v_k(t_k^peak + tau)> over successful
#: realisations, each shifted by its own peak time at k (granchain.backends.kernels.aligned).
ALIGNED = (
    Variable("aligned_velocity", ("chain", "granule", "lag"), "float64", np.nan, UNITS_V,
             "aligned pulse <v_k(t_k^peak + tau)>: velocity of large granule k at lag tau after the realisation's own peak there"),
    Variable("aligned_velocity_stderr", ("chain", "granule", "lag"), "float64", np.nan, UNITS_V,
             "standard error of the aligned pulse"),
)

#: Fixed-point sums are integers counting 2^-fixed_point_bits of the rescaled velocity (or its square).
_FIXED = {"units": "1", "units_description": "integer count of 2^-fixed_point_bits (the store's attribute fixed_point_bits) "
                                           "rescaled velocity units V_1 (V_1^2 for the sums of squares)"}

#: The ``progress`` group: one storage chunk per run chunk.
PROGRESS = (
    Variable("sum_v", ("chunk", "chain", "granule", "time"), "int64", 0, _FIXED,
             "sum over the chunk's successful realisations of round(v * 2^bits)"),
    Variable("sum_v2", ("chunk", "chain", "granule", "time"), "int64", 0, _FIXED,
             "sum over the chunk's successful realisations of round(v^2 * 2^bits)"),
    Variable("n_valid", ("chunk", "chain"), "int64", 0, "1", "successful realisations of the chunk"),
    Variable("checksum", ("chunk", "checked"), "int64", 0, "1",
             "BLAKE2b-64 of the chunk's stored values, per checked variable (written before done)"),
    Variable("done", ("chunk",), "int8", 0, "1", "1 once every result of the chunk and its checksums are on disk"),
)

#: The aligned pulse's fixed-point sums per chunk, in the ``progress`` group (with ``lags`` only).
PROGRESS_ALIGNED = (
    Variable("sum_a", ("chunk", "chain", "granule", "lag"), "int64", 0, _FIXED,
             "sum over the chunk's successful realisations of round(v_k(t_k^peak + tau) * 2^bits)"),
    Variable("sum_a2", ("chunk", "chain", "granule", "lag"), "int64", 0, _FIXED,
             "sum over the chunk's successful realisations of round(v_k(t_k^peak + tau)^2 * 2^bits)"),
)

#: The progress variables that hold one run chunk's results (checked like the per-realisation results).
PROGRESS_SUMS = ("sum_v", "sum_v2", "n_valid")


def progress_sums(spec) -> tuple:
    """Names of the progress variables holding one chunk's results: :data:`PROGRESS_SUMS`, and the
    aligned pulse's sums with ``lags``."""
    return PROGRESS_SUMS + (tuple(v.name for v in PROGRESS_ALIGNED) if spec.lags is not None else ())


def progress_sum_variables(spec) -> tuple:
    """The progress variables holding one chunk's results (:func:`progress_sums`), as schema entries."""
    names = progress_sums(spec)
    return tuple(v for v in progress_variables(spec) if v.name in names)


def chunk_variables(spec) -> tuple:
    """What one computed chunk holds, each under its schema name: the family's random parameters and the
    per-realisation results (:func:`per_realisation_variables`, dim ``realization`` = the chunk's
    realisations) and its progress sums (:func:`progress_sum_variables`, without the ``chunk`` dim).
    The ensemble runner allocates its compute buffers from the results and the sums."""
    return per_realisation_variables(spec.family) + progress_sum_variables(spec)


def averaged_variables(spec) -> tuple:
    """The averaged variables of a run: :data:`AVERAGED`, plus :data:`ALIGNED` when it has ``lags``."""
    return AVERAGED + (ALIGNED if spec.lags is not None else ())


def progress_variables(spec) -> tuple:
    """The ``progress`` group's variables: :data:`PROGRESS`, plus :data:`PROGRESS_ALIGNED` with ``lags``."""
    return PROGRESS + (PROGRESS_ALIGNED if spec.lags is not None else ())


def parameter_variables(family) -> tuple:
    """The family's random parameters as store variables (dims ``realization`` + the parameter's)."""
    fills = {"f": np.nan, "i": -1, "u": 0, "b": False}
    return tuple(Variable(p.name, ("realization",) + tuple(p.dims), p.dtype, fills[np.dtype(p.dtype).kind],
                          rescaled_attrs(p.units) if p.units in RESCALED else p.units, p.long_name)
                 for p in family.parameters())


def sizes(spec) -> dict:
    """The size of every dimension of a run's store, by name."""
    return {"chain": len(spec.chains), "realization": spec.realizations, "time": spec.t_grid.size, "chunk": spec.n_chunks,
            "checked": len(checked_variables(spec)), "contact": spec.family.n_contacts,
            **spec.family.dim_sizes(), **({"lag": spec.lags.size} if spec.lags is not None else {})}


def checked_variables(spec) -> list[str]:
    """Every variable whose chunk values are checksummed: the family's parameters and results
    (:func:`per_realisation_variables`, read from the schema, so new results are checked
    automatically) and the progress sums."""
    return [v.name for v in per_realisation_variables(spec.family)] + [f"progress/{name}" for name in progress_sums(spec)]


def digest(values, dtype) -> int:
    """BLAKE2b-64 (as a signed int64) of the values as stored (dtype, C order)."""
    a = np.ascontiguousarray(values, dtype=np.dtype(dtype))
    return int.from_bytes(hashlib.blake2b(a.tobytes(), digest_size=8).digest(), "little", signed=True)


def integrators_as_run(spec) -> dict:
    """{chain kind: the record of its integrator as it runs on the family's chains}
    (``granchain.backends.integrator_as_run``): derived from the parameters, so not compared on resume."""
    from ..backends import integrator_as_run
    from ..model.contacts import FreeEnd, RigidWall

    boundary = RigidWall if spec.family.wall else FreeEnd
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
    """mean_velocity (and the aligned pulse, with ``lags``) and standard errors from the exact fixed-point sums."""
    ds["mean_velocity"].values, ds["mean_velocity_stderr"].values = mean_from_sums(sum_v, sum_v2, n_valid, spec.fixed_point_bits)
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
    :func:`check_chunk`). ``zarr.open`` honours ``config`` for an existing array; ``zarr.open_array``
    (zarr 3.1) silently drops it, and a chunk of all zeros (status, done) was then deleted, not written."""
    import zarr

    arr = zarr.open(store=path, path=name, mode="r+", zarr_format=2, config={"write_empty_chunks": True})
    if not isinstance(arr, zarr.Array):
        raise ValueError(f"{path}/{name} is not a Zarr array")
    return arr


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
    return {k: (v.to_bytes() if hasattr(v, "to_bytes") else bytes(v)) for k, v in mapping.items()}, coords


_VOLATILE_ATTRS = ("created", "history")  # kept from the store when root attributes are restored


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
        self._repair_metadata(old, warn=True)
        bad = self._verify(old)
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

    def _verify(self, spec) -> list[int]:
        """Done chunks whose stored values do not match their checksums (with the reason reported)."""
        import zarr

        group = zarr.open_group(self.path, mode="r", zarr_format=2, use_consolidated=False)
        names = checked_variables(spec)
        done, bad = self._done_flags(group, spec)
        for j in np.flatnonzero(done == 1):
            reason = self._check_chunk(group, spec, int(j), names)
            if reason:
                bad.append(int(j))
                sl = spec.chunk_slice(int(j))
                self._warn(f"{self.path}: chunk {j} (realisations {sl.start}-{sl.stop - 1}) {reason}; recomputing it")
        return bad

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

    def _check_chunk(self, group, spec, j: int, names) -> str | None:
        return check_chunk(self.path, group, j, names, spec.chunk_slice(j))

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

        return xr.open_zarr(self.path, group="progress", consolidated=False)

    def pending(self) -> list[int]:
        import zarr

        group = zarr.open_group(self.path, mode="r", zarr_format=2, use_consolidated=False)
        done, _ = self._done_flags(group, self.spec, warn=False)
        return [j for j in range(self.spec.n_chunks) if done[j] != 1]

    def _array(self, name: str):
        """The store's Zarr array ``name`` (``progress/...`` for the progress group), opened once per run.
        Chunks equal to the fill value are written too: a missing data file means damage (check_chunk)."""
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
        check = np.array([[digest(values[name], values[name].dtype) for name in checked_variables(spec)]], dtype=np.int64)
        for v in variables:
            self._array(v.name)[_region(v.dims, "realization", sl)] = values[v.name]
        here = slice(j, j + 1)
        for name in sums:
            self._array(f"progress/{name}")[_region(table[name].dims, "chunk", here)] = values[f"progress/{name}"]
        self._array("progress/checksum")[here] = check
        # The flag last: a chunk counts as done only once all its data and checksums are on disk.
        self._array("progress/done")[here] = np.ones(1, dtype=np.int8)

    def finalize(self):
        import xarray as xr
        import zarr

        try:
            with self._progress() as p:
                prog = p.load()
            with xr.open_zarr(self.path, consolidated=False) as d:
                ds = d.load()
            aligned = (prog["sum_a"].values.sum(0), prog["sum_a2"].values.sum(0)) if self.spec.lags is not None else ()
            ds = finalize(ds, self.spec, prog["sum_v"].values.sum(0), prog["sum_v2"].values.sum(0),
                          prog["n_valid"].values.sum(0), *aligned)
            region = {"chain": slice(None), "granule": slice(None), "time": slice(None)}
            if self.spec.lags is not None:
                region["lag"] = slice(None)
            ds[[v.name for v in averaged_variables(self.spec)]].to_zarr(self.path, region=region, mode="r+",
                                                                         consolidated=False, **_fmt2())
            zarr.consolidate_metadata(self.path, zarr_format=2)
            return ds
        finally:
            self.close()

    def close(self):
        self.lock.release()


def check_chunk(path, group, j: int, names, sl: slice) -> str | None:
    """Why chunk j (realisations ``sl``) of the store does not match its checksums, or None if it does.
    Reads only the store (dims and dtypes from its metadata), so ``granchain info`` can use it too."""
    try:
        sums = group["progress/checksum"][j]
    except Exception as exc:  # noqa: BLE001
        return f"has an unreadable checksum record (progress/checksum/{j}.0: {_short(exc)})"
    for k, name in enumerate(names):
        axis, region_slice = ("chunk", slice(j, j + 1)) if name.startswith("progress/") else ("realization", sl)
        try:
            arr = group[name]
            dims = arr.metadata.attributes["_ARRAY_DIMENSIONS"]
        except Exception as exc:  # noqa: BLE001
            return f"has unreadable metadata for {name} ({_short(exc)})"
        key = f"{name}/" + ".".join(str(j) if d == axis else "0" for d in dims)
        if not os.path.exists(os.path.join(path, *key.split("/"))):  # every chunk is written explicitly
            return f"has a missing data file {key}"
        try:
            values = arr[_region(dims, axis, region_slice)]
        except Exception as exc:  # noqa: BLE001 -- truncated or garbled chunk
            return f"has an unreadable data file {key} ({_short(exc)})"
        if digest(values, arr.dtype) != int(sums[k]):
            return (f"does not match its checksum: the data file {key} or the checksum record "
                    f"progress/checksum/{j}.0 has changed")
    return None


def verify_chunks(path, realizations: int, chunk_size: int) -> tuple:
    """(done flags, {chunk: why it does not match its checksums}) of the store at ``path``, read without
    changing it (``granchain info``); the checked variables are the store's own list (progress/checked).
    None instead of the dict for a store that holds no checksums (written by granchain 0.1.0)."""
    import zarr

    group = zarr.open_group(path, mode="r", zarr_format=2, use_consolidated=False)
    n_chunks = -(-realizations // chunk_size)
    try:
        done = np.asarray(group["progress/done"][...])
    except Exception:  # noqa: BLE001 -- unreadable flags: no chunk counts as done
        done = np.zeros(n_chunks, dtype=np.int8)
    try:
        names = [str(x) for x in group["progress/checked"][...]]
    except KeyError:  # granchain 0.1.0 stored no checksums: nothing to verify
        return done, None
    damaged = {}
    for j in np.flatnonzero(done == 1):
        sl = slice(int(j) * chunk_size, min((int(j) + 1) * chunk_size, realizations))
        reason = check_chunk(path, group, int(j), names, sl)
        if reason:
            damaged[int(j)] = reason
    return done, damaged


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


def _check_out(path) -> str:
    """The store path as a string, refusing what can never be a store (with what to change)."""
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
        diff = ", ".join(f"{k}: stored {old.get(k)!r}, asked {new.get(k)!r}" for k in sorted(set(old) | set(new)) if old.get(k) != new.get(k))
        hint = " (a store can be extended to more realisations, never shrunk)" if old.get("realizations") != new["realizations"] else ""
        if old.get("integrator") != new.get("integrator") or old.get("chain_integrators") != new.get("chain_integrators"):
            hint += (" (a store written with the exact DP5, every granule integrated to the end as before "
                     "granchain 0.3, is resumed with integrator=granchain.DP5(1e-6, 1e-9), on the command line "
                     "--integrator dp5 --rtol 1e-6 --atol 1e-9 --error-control exact; one written with granchain "
                     "0.3's defaults with integrator={'decorated': granchain.DP5.relaxed(), 'effective': "
                     "granchain.DP5.relaxed(5e-8, 5e-11)}, on the command line --integrator dp5)")
        raise ValueError(f"{path} was written with different parameters ({diff}){hint}; "
                         "results are never mixed: use another path, or the stored parameters to resume")
    return int(stored_r)


def stored_record(ds, key: str = "family") -> dict | None:
    """The family (``key="family"``), integrator or run (``"parameters"``) record of an ensemble, in the
    form this version writes (:func:`current_record`: a record of an earlier version is read in its own
    meaning). ``ds``: a Dataset (``run_ensemble``'s result, a store opened by any reader) or the path of
    a store (:func:`open_store`). None where the Dataset holds no such record."""
    if isinstance(ds, (str, os.PathLike)):
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


# ---------------------------------------------------------------------- reading a store
#: Root attributes that say where and when a store was written (kept as stored by :func:`open_store`);
#: every other attribute granchain writes follows from the parameter record and is given in today's form.
_PROVENANCE = ("created", "history", "granchain_version", "numpy_version", "scipy_version", "numba_version", "source")

_WHAT_TO_GIVE = ("give the path of an ensemble store written by `granchain ensemble --out PATH` or "
                 "granchain.run_ensemble(..., out=PATH), or a netCDF file written by `granchain export`")


def open_store(path, *, group: str | None = None, load: bool = False):
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

    Returns
    -------
    xarray.Dataset
        The stored values, unchanged. The records (attributes ``granchain_parameters``,
        ``granchain_family``, ``granchain_integrator``) are in today's form (the compatibility layer
        ``granchain.ensembles.store.current_record`` that a resume compares records with:
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
        metadata cannot be read (``granchain info PATH`` says what is damaged), or another group.
    """
    import xarray as xr

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
        opener = lambda: xr.open_zarr(text, group=group, consolidated=False, zarr_format=2)  # noqa: E731
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
        _set_metadata(ds, {v.name: v.metadata() for v in RESULTS + FORCES + WALL + AVERAGED + ALIGNED})
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
                chain_integrators={k: integrator_from_record(r) for k, r in per_chain.items()} if per_chain else None)
    except (KeyError, TypeError, ValueError):
        return None
