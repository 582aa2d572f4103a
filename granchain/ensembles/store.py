"""Writing a store and resuming it, by the names it has always had: this module re-exports the parts.

* :mod:`~granchain.ensembles.sinks` - the in-memory and Zarr sinks (:class:`MemorySink`,
  :class:`ZarrSink`, :class:`StoreRepairWarning`) and the Zarr writes only they make;
* :mod:`~granchain.ensembles.layout` - the Datasets a store is made of (``empty_dataset``,
  ``progress_dataset``, ``chunk_dataset``, ``finalize``, ``mean_from_sums``) and
  :func:`integrators_as_run`;
* :mod:`~granchain.ensembles.compat` - records of earlier versions in today's form
  (:func:`current_record`, :func:`stored_record`);
* :mod:`~granchain.ensembles.params` - the parameter record (``stored_parameters``) and the resume
  checks (:func:`check_same_parameters`, :func:`check_same_family`);
* :mod:`~granchain.ensembles.files` - the ``out`` path check, lenient JSON reads, atomic writes;
* :mod:`~granchain.ensembles.verify` - what every reader checks before it hands out data.

What is stored is the schema's (:mod:`~granchain.ensembles.schema`, re-exported here); reading a store
is :func:`granchain.open_store` (:mod:`~granchain.ensembles.read`).
"""

from __future__ import annotations

from .compat import _current_family_record, _record_of_010, current_record, stored_record  # noqa: F401
from .files import _atomic_write, _check_out, _read_json, _short  # noqa: F401
from .layout import (  # noqa: F401
    _CHECKED_ATTRS,
    _PROGRESS_ABOUT,
    chunk_dataset,
    empty_dataset,
    finalize,
    integrators_as_run,
    mean_from_sums,
    progress_dataset,
)
from .params import _differences, _flatten, check_same_family, check_same_parameters, stored_parameters  # noqa: F401
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
from .sinks import MemorySink, StoreRepairWarning, ZarrSink, writable_array  # noqa: F401

__all__ = ["MemorySink", "ZarrSink", "StoreRepairWarning", "stored_record", "current_record", "check_same_parameters",
           "check_same_family",
           "integrators_as_run", "ALIGNED", "AVERAGED", "FORCES", "PROGRESS", "PROGRESS_ALIGNED", "PROGRESS_SUMS", "RESULTS", "WALL", "Variable", "averaged_variables", "checked_variables", "chunk_variables", "digest", "parameter_variables", "per_realisation_variables", "progress_sum_variables", "progress_sums", "progress_variables", "result_variables", "sizes"]
