"""The ensemble store: one schema table, the in-memory and Zarr sinks, and the resume check.

The schema (:data:`RESULTS`, :data:`AVERAGED`, :data:`PROGRESS`, plus the family's own
random parameters) is the single place that names the variables, their dimensions, fill
values and metadata: the writer, the resume check, the analysis and the tests read it.

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
import json
import os
from dataclasses import dataclass, field

import numpy as np

from ._status import NOT_COMPUTED, Status, describe_codes
from ._version import __version__

__all__ = ["Variable", "RESULTS", "AVERAGED", "ALIGNED", "PROGRESS", "PROGRESS_ALIGNED", "MemorySink", "ZarrSink", "stored_record"]

UNITS_V = "V_1 (velocity of the struck granule; rescaled, paper Sec. II)"
UNITS_T = "rescaled time (paper Sec. II)"


@dataclass(frozen=True)
class Variable:
    """One stored variable: dimensions, dtype, fill value (= not computed) and metadata."""

    name: str
    dims: tuple
    dtype: str
    fill: object
    units: str
    long_name: str
    attrs: dict = field(default_factory=dict)

    def metadata(self) -> dict:
        return {"units": self.units, "long_name": self.long_name, **self.attrs}


#: Per-realisation results of every chain.
RESULTS = (
    Variable("peak_velocity", ("chain", "realization", "granule"), "float64", np.nan, UNITS_V,
             "maximum velocity of large granule k in the realisation"),
    Variable("peak_time", ("chain", "realization", "granule"), "float64", np.nan, UNITS_T,
             "time of the maximum velocity of large granule k (arrival time)"),
    Variable("status", ("chain", "realization"), "int8", NOT_COMPUTED, "1",
             "integration status (0 = success; -1 = not computed)", {"flag_meanings": " ".join(s.name for s in Status)}),
    Variable("energy_error", ("chain", "realization"), "float64", np.nan, "1", "relative energy drift (E_end - E_0)/E_0"),
    Variable("n_steps", ("chain", "realization"), "int64", -1, "1", "accepted integration steps"),
    Variable("t_end", ("chain", "realization"), "float64", np.nan, UNITS_T, "time the integration stopped"),
)

#: The averaged pulse, computed from the exact fixed-point sums once every chunk is done.
AVERAGED = (
    Variable("mean_velocity", ("chain", "granule", "time"), "float64", np.nan, UNITS_V,
             "ensemble-averaged velocity <v_k(t)> of large granule k over successful realisations"),
    Variable("mean_velocity_stderr", ("chain", "granule", "time"), "float64", np.nan, UNITS_V, "standard error of <v_k(t)>"),
    Variable("n_valid", ("chain",), "int64", 0, "1", "successful realisations in mean_velocity"),
)

#: The aligned pulse (only in ensembles run with ``lags``): <v_k(t_k^peak + tau)> over successful
#: realisations, each shifted by its own peak time at k (granchain._kernels._aligned).
ALIGNED = (
    Variable("aligned_velocity", ("chain", "granule", "lag"), "float64", np.nan, UNITS_V,
             "aligned pulse <v_k(t_k^peak + tau)>: velocity of large granule k at lag tau after the realisation's own peak there"),
    Variable("aligned_velocity_stderr", ("chain", "granule", "lag"), "float64", np.nan, UNITS_V,
             "standard error of the aligned pulse"),
)

#: The aligned pulse's fixed-point sums per chunk, in the ``progress`` group (with ``lags`` only).
PROGRESS_ALIGNED = (
    Variable("sum_a", ("chunk", "chain", "granule", "lag"), "int64", 0, "2^-fixed_point_bits V_1",
             "sum over the chunk's successful realisations of round(v_k(t_k^peak + tau) * 2^bits)"),
    Variable("sum_a2", ("chunk", "chain", "granule", "lag"), "int64", 0, "2^-fixed_point_bits V_1^2",
             "sum over the chunk's successful realisations of round(v_k(t_k^peak + tau)^2 * 2^bits)"),
)

#: The ``progress`` group: one storage chunk per run chunk.
PROGRESS = (
    Variable("sum_v", ("chunk", "chain", "granule", "time"), "int64", 0, "2^-fixed_point_bits V_1",
             "sum over the chunk's successful realisations of round(v * 2^bits)"),
    Variable("sum_v2", ("chunk", "chain", "granule", "time"), "int64", 0, "2^-fixed_point_bits V_1^2",
             "sum over the chunk's successful realisations of round(v^2 * 2^bits)"),
    Variable("n_valid", ("chunk", "chain"), "int64", 0, "1", "successful realisations of the chunk"),
    Variable("done", ("chunk",), "int8", 0, "1", "1 once every result of the chunk is on disk"),
)


def _zarr_format() -> dict:
    """Write Zarr format 2: a stable spec that every Zarr reader understands, with string coordinates
    (format 3 has no settled string data type yet)."""
    import zarr

    return {"zarr_format": 2} if int(zarr.__version__.split(".")[0]) >= 3 else {}


def parameter_variables(family) -> tuple:
    """The family's random parameters as store variables (dims ``realization`` + the parameter's)."""
    fills = {"f": np.nan, "i": -1, "u": 0, "b": False}
    return tuple(Variable(p.name, ("realization",) + tuple(p.dims), p.dtype, fills[np.dtype(p.dtype).kind], p.units, p.long_name)
                 for p in family.parameters())


def _sizes(spec) -> dict:
    sizes = {"chain": len(spec.chains), "realization": spec.realizations, "time": spec.t_grid.size, "chunk": spec.n_chunks,
             **spec.family.dim_sizes()}
    if spec.lags is not None:
        sizes["lag"] = spec.lags.size
    return sizes


def averaged_variables(spec) -> tuple:
    """The averaged variables of a run: :data:`AVERAGED`, plus :data:`ALIGNED` when it has ``lags``."""
    return AVERAGED + (ALIGNED if spec.lags is not None else ())


def progress_variables(spec) -> tuple:
    """The ``progress`` group's variables: :data:`PROGRESS`, plus :data:`PROGRESS_ALIGNED` with ``lags``."""
    return PROGRESS + (PROGRESS_ALIGNED if spec.lags is not None else ())


def _attrs(spec) -> dict:
    d = spec.describe()
    family = spec.family
    integ = spec.integrator.describe()
    attrs = {
        "title": f"granchain ensemble: {family.label()}",
        "source": f"granchain {__version__} run_ensemble (exact dynamics of paper Eq. motion_rescaled)",
        "references": "U. Harbola, A. Rosas, A. H. Romero and K. Lindenberg, Pulse propagation in decorated random chains",
        "granchain_parameters": json.dumps(d, sort_keys=True),
        "granchain_family": json.dumps(d["family"], sort_keys=True),
        "granchain_integrator": json.dumps(integ, sort_keys=True),
        "granchain_version": __version__,
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
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

    sizes = _sizes(spec)
    full = np.full
    if lazy:
        import dask.array as da

        def full(shape, fill, dtype, dims):
            chunks = tuple(min(spec.chunk_size, s) if d == "realization" else s for d, s in zip(dims, shape))
            return da.full(shape, fill, dtype=dtype, chunks=chunks)

    def var(v: Variable):
        shape = tuple(sizes[d] for d in v.dims)
        data = full(shape, v.fill, v.dtype, v.dims) if lazy else np.full(shape, v.fill, dtype=v.dtype)
        return (v.dims, data, v.metadata())

    family = spec.family
    granules, granule_name = family.granule_coordinate()
    coords = {
        "chain": ("chain", np.array(spec.chains, dtype=object).astype(str), {"long_name": "which chain of the realisation"}),
        "realization": ("realization", np.arange(spec.realizations),
                        {"long_name": "realisation index i (random parameters from SeedSequence(seed, spawn_key=(i,)))"}),
        "granule": ("granule", np.asarray(granules), {"long_name": granule_name}),
        "time": ("time", np.asarray(spec.t_grid), {"units": UNITS_T, "long_name": "time"}),
    }
    for dim, (values, long_name) in family.dims().items():
        coords[dim] = (dim, np.asarray(values), {"long_name": long_name})
    if spec.lags is not None:
        coords["lag"] = ("lag", np.asarray(spec.lags), {"units": UNITS_T,
                                                        "long_name": "time tau after the realisation's own peak time at k"})
    variables = parameter_variables(family) + RESULTS + averaged_variables(spec)
    return xr.Dataset({v.name: var(v) for v in variables}, coords=coords, attrs=_attrs(spec))


def progress_dataset(spec):
    """The ``progress`` group (all zeros) and its encoding (one storage chunk per run chunk)."""
    import xarray as xr

    sizes = _sizes(spec)
    data, encoding = {}, {}
    for v in progress_variables(spec):
        shape = tuple(sizes[d] for d in v.dims)
        data[v.name] = (v.dims, np.full(shape, v.fill, dtype=v.dtype), v.metadata())
        encoding[v.name] = {"chunks": (1,) + shape[1:]}
    ds = xr.Dataset(data, attrs={"granchain_parameters": json.dumps(spec.describe(), sort_keys=True),
                                 "about": "bookkeeping of granchain.run_ensemble: fixed-point velocity sums per chunk and done flags"})
    return ds, encoding


def chunk_dataset(spec, res: dict):
    """The per-realisation variables of one finished chunk (the family's parameters and the results)."""
    import xarray as xr

    out = {v.name: (v.dims, np.asarray(res[v.name]).astype(v.dtype, copy=False)) for v in parameter_variables(spec.family) + RESULTS}
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
        shape = (spec.n_chunks, len(spec.chains), spec.family.n_observed, spec.t_grid.size)
        self.sum_v = np.zeros(shape, dtype=np.int64)
        self.sum_v2 = np.zeros(shape, dtype=np.int64)
        self.n_valid = np.zeros((spec.n_chunks, len(spec.chains)), dtype=np.int64)
        if spec.lags is not None:
            shape = (spec.n_chunks, len(spec.chains), spec.family.n_observed, spec.lags.size)
            self.sum_a, self.sum_a2 = np.zeros(shape, dtype=np.int64), np.zeros(shape, dtype=np.int64)

    def pending(self) -> list[int]:
        return list(range(self.spec.n_chunks))

    def write(self, res: dict) -> None:
        j = res["chunk"]
        sl = self.spec.chunk_slice(j)
        for name, values in chunk_dataset(self.spec, res).data_vars.items():
            self.ds[name][{"realization": sl}] = values
        self.sum_v[j], self.sum_v2[j], self.n_valid[j] = res["sum_v"], res["sum_v2"], res["n_valid"][:, 0]
        if self.spec.lags is not None:
            self.sum_a[j], self.sum_a2[j] = res["sum_a"], res["sum_a2"]

    def finalize(self):
        aligned = (self.sum_a.sum(0), self.sum_a2.sum(0)) if self.spec.lags is not None else ()
        return finalize(self.ds, self.spec, self.sum_v.sum(0), self.sum_v2.sum(0), self.n_valid.sum(0), *aligned)


class ZarrSink:
    """Results in a Zarr store at ``path``; finished chunks survive any interruption."""

    def __init__(self, spec, path, resume: bool):
        import xarray as xr

        self.spec, self.path = spec, os.fspath(path)
        if os.path.exists(self.path):
            if not resume:
                raise ValueError(f"{self.path} already exists: pass resume=True (CLI: --resume) to continue it, or choose another path")
            try:
                stored = xr.open_zarr(self.path, group="progress").attrs.get("granchain_parameters")
            except Exception as exc:  # not a Zarr store, or not ours
                raise ValueError(f"{self.path} exists but is not a granchain ensemble store ({exc}); choose another path") from None
            check_same_parameters(self.path, stored, spec)
        else:
            empty_dataset(spec, lazy=True).to_zarr(self.path, mode="w-", compute=False, **_zarr_format())
            progress, encoding = progress_dataset(spec)
            progress.to_zarr(self.path, group="progress", mode="a", encoding=encoding, **_zarr_format())

    def _progress(self):
        import xarray as xr

        return xr.open_zarr(self.path, group="progress", consolidated=False)

    def pending(self) -> list[int]:
        done = self._progress()["done"].values
        return [j for j in range(self.spec.n_chunks) if not done[j]]

    def write(self, res: dict) -> None:
        import xarray as xr

        j = res["chunk"]
        chunk_dataset(self.spec, res).to_zarr(self.path, region={"realization": self.spec.chunk_slice(j)}, mode="r+", **_zarr_format())
        region = {"chunk": slice(j, j + 1)}
        sums = xr.Dataset({
            "sum_v": (("chunk", "chain", "granule", "time"), res["sum_v"][None]),
            "sum_v2": (("chunk", "chain", "granule", "time"), res["sum_v2"][None]),
            "n_valid": (("chunk", "chain"), res["n_valid"].T),
        })
        if self.spec.lags is not None:
            for name in ("sum_a", "sum_a2"):
                sums[name] = (("chunk", "chain", "granule", "lag"), res[name][None])
        sums.to_zarr(self.path, group="progress", region=region, mode="r+", consolidated=False, **_zarr_format())
        # The flag last: a chunk counts as done only once all its data are on disk.
        xr.Dataset({"done": (("chunk",), np.ones(1, dtype=np.int8))}).to_zarr(
            self.path, group="progress", region=region, mode="r+", consolidated=False, **_zarr_format())

    def finalize(self):
        import xarray as xr

        prog = self._progress().load()
        ds = xr.open_zarr(self.path).load()
        aligned = (prog["sum_a"].values.sum(0), prog["sum_a2"].values.sum(0)) if self.spec.lags is not None else ()
        ds = finalize(ds, self.spec, prog["sum_v"].values.sum(0), prog["sum_v2"].values.sum(0), prog["n_valid"].values.sum(0),
                      *aligned)
        region = {"chain": slice(None), "granule": slice(None), "time": slice(None)}
        if self.spec.lags is not None:
            region["lag"] = slice(None)
        ds[[v.name for v in averaged_variables(self.spec)]].to_zarr(self.path, region=region, mode="r+", **_zarr_format())
        return ds


def check_same_parameters(path, stored: str | None, spec) -> None:
    """Refuse to resume a store written with other parameters, listing the differences."""
    if stored is None:
        raise ValueError(f"{path} is not a granchain ensemble store (no granchain_parameters); choose another path")
    old, new = json.loads(stored), json.loads(json.dumps(spec.describe(), sort_keys=True))
    if old != new:
        diff = ", ".join(f"{k}: stored {old.get(k)!r}, asked {new.get(k)!r}" for k in sorted(set(old) | set(new)) if old.get(k) != new.get(k))
        raise ValueError(f"{path} was written with different parameters ({diff}); "
                         "results are never mixed: use another path, or the stored parameters to resume")


def stored_record(ds, key: str = "family") -> dict | None:
    """The family (``key="family"``), integrator or run record stored in a Dataset's attributes
    (None for stores written before granchain 0.2, which hold no family record)."""
    name = {"family": "granchain_family", "integrator": "granchain_integrator", "parameters": "granchain_parameters"}[key]
    text = ds.attrs.get(name)
    return None if text is None else json.loads(text)
