"""The Datasets a store is made of, built from the schema (:mod:`~granchain.ensembles.schema`): the
result Dataset at full size with every parameter in its attributes, the ``progress`` group, one chunk's
values, and the averaged pulse computed from the exact fixed-point sums.

Both writers (:mod:`~granchain.ensembles.sinks`) build their results with these, and the reader
(:mod:`~granchain.ensembles.read`) compares a store's metadata with a fresh one's.
"""

from __future__ import annotations

import datetime as _dt
import json

import numpy as np

from .._status import describe_codes
from .._version import __version__
from .schema import (
    UNITS_T,
    Variable,
    averaged_variables,
    checked_variables,
    per_realisation_variables,
    progress_variables,
    sizes,
)

__all__ = ["integrators_as_run", "empty_dataset", "progress_dataset", "chunk_dataset", "mean_from_sums", "finalize"]


def integrators_as_run(spec) -> dict:
    """{chain kind: the record of its integrator as it runs on the family's chains}
    (``granchain.backends.integrator_as_run``): derived from the parameters, so not compared on resume."""
    from ..backends import integrator_as_run

    boundary = spec.family.model.boundary
    law = spec.family.contact_law
    return {kind: integrator_as_run(integ, boundary, law) for kind, integ in spec.chain_integrators.items()}


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
