"""The store's schema: one table that names every stored variable, its dimensions, dtype, fill value
(= not computed) and metadata. The ensemble runner allocates its compute buffers from it
(:func:`chunk_variables`), the writer and the resume check (:mod:`~granchain.ensembles.store`) write and
compare what it lists, the reader (:func:`granchain.open_store`) gives every variable today's metadata
from it, and the tests read it: a new stored variable is one row here.

Layout of a store (dims ``chain``, ``realization``, ``granule`` = the family's observed
granules, ``time``, and the family's parameter dims such as ``gap``):

* root group: the family's random parameters ``(realization, ...)``, the per-realisation
  results ``(chain, realization[, granule])``, the averaged pulse ``(chain, granule, time)``;
  attributes: the family, integrator and run records (JSON) and every parameter;
* ``progress`` group: per chunk of realisations the fixed-point sums of the averaged pulse
  and a ``done`` flag (sums first, flag last; Zarr writes each storage chunk atomically).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np

from .._status import NOT_COMPUTED, Status
from ..units import RESCALED, rescaled_attrs

__all__ = ["Variable", "RESULTS", "FORCES", "WALL", "DISSIPATION", "AVERAGED", "WINDOW", "ALIGNED", "PROGRESS", "PROGRESS_ALIGNED", "PROGRESS_SUMS",
           "result_variables", "per_realisation_variables", "progress_sums", "progress_sum_variables", "chunk_variables",
           "averaged_variables", "progress_variables", "parameter_variables", "sizes", "checked_variables", "digest"]

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

#: Families with a fixed wall at the far end (``wall=True``): the wall contact's peak force.
WALL = (
    Variable("peak_wall_force", ("chain", "realization"), "float64", np.nan, UNITS_F,
             "maximum force on the fixed wall at the far end of the chain"),
    Variable("peak_wall_force_time", ("chain", "realization"), "float64", np.nan, UNITS_T,
             "time of the maximum force on the wall"),
)


#: Families with a viscoelastic contact law: the energy its contacts dissipated (the energy check,
#: energy_error, includes it: (E_end + E_dissipated - E_0) / E_0).
DISSIPATION = (
    Variable("dissipated_energy", ("chain", "realization"), "float64", np.nan, rescaled_attrs("energy"),
             "energy dissipated by the viscoelastic contacts"),
)


def result_variables(family) -> tuple:
    """The per-realisation results a family's store holds: :data:`RESULTS`, :data:`FORCES`, and
    :data:`WALL` when its chains end in a wall."""
    return RESULTS + FORCES + (WALL if family.model.wall else ()) + (DISSIPATION if family.model.dissipates else ())


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

#: The averaged pulse's window at each observed granule (only in ensembles whose integrator runs a trailing
#: window, with ``pulse_window="auto"``: :mod:`granchain.ensembles.pulse_window`). ``mean_velocity`` is
#: recorded for t <= pulse_window_end and NaN (not computed) after it.
WINDOW = (
    Variable("pulse_window_end", ("chain", "granule"), "float64", np.inf, UNITS_T,
             "end of the averaged pulse's window at large granule k: <v_k(t)> recorded for t <= it (inf: whole grid)",
             {"comment": "granule k stays integrated in every realisation until this time (the trailing window waits "
                         "for it); set from the ensemble's first realisations (granchain.ensembles.pulse_window)"}),
    Variable("pulse_window_ahead", ("chain",), "int64", 0, "1",
             "observed granules the pulse has passed in the slow realisations when a window closes (0: no windows)"),
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
             "BLAKE2b-64 of the chunk's stored values, per checked variable (written before done)",
             {"checksum_scheme": 2,
              "comment": "keyed by the store's parameter record (all but realizations), the variable's name and the "
                         "chunk index, so a chunk copied from another store or another place does not match "
                         "(granchain.ensembles.verify); stores without checksum_scheme hash the values alone"}),
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
    """The averaged variables of a run: :data:`AVERAGED`, plus :data:`ALIGNED` when it has ``lags`` and
    :data:`WINDOW` when it has averaged-pulse windows (written with them, once every chunk is done)."""
    return AVERAGED + (ALIGNED if spec.lags is not None else ()) + (WINDOW if spec.pulse_ends else ())


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


def digest(values, dtype, key: bytes | None = None, label: str = "") -> int:
    """BLAKE2b-64 (as a signed int64) of the values as stored (dtype, C order).

    ``key`` (the store's identity, :func:`granchain.ensembles.verify.store_identity`) and ``label`` (the
    variable and the chunk index) bind the digest to where the values belong: the same values in another
    store, or in another chunk, have another digest. Without them, the values alone (the checksums of
    stores written before ``checksum_scheme`` 2)."""
    a = np.ascontiguousarray(values, dtype=np.dtype(dtype))
    h = hashlib.blake2b(digest_size=8, key=key or b"")
    if key is not None:
        h.update(label.encode() + b"\0")
    h.update(memoryview(a).cast("B") if a.size else b"")
    return int.from_bytes(h.digest(), "little", signed=True)
