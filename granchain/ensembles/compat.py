"""Records of earlier granchain versions brought to today's form.

A stored parameter, family or integrator record is read in the meaning of the version that wrote it
(a field whose meaning changed, such as TaperedDecorated's q; granchain 0.1.0's flat fields) and
handed out as this version writes it, so that a store of an earlier version that computed the same
numbers compares equal on resume (:mod:`~granchain.ensembles.params`) and reads like a new one
(:func:`stored_record`, :func:`granchain.open_store`).
"""

from __future__ import annotations

import json
import os

from .._version import RESULTS_OF_VERSION
from ..families.record import current_family_record, family_record_of_010

__all__ = ["current_record", "stored_record"]


#: The family part is the families' own (granchain.families.record): one reading of a family record.
_current_family_record = current_family_record


def _record_of_010(record: dict) -> dict:
    """A granchain 0.1.0 record with its family and integrator as records: 0.1.0 stored the paper's family
    (RandomDecorated) and its one integrator, the exact DP5, as flat fields (n_large, distribution, n,
    momentum_conserving; integrator "dp5", rtol, atol). Today's ``DP5(rtol, atol)`` reproduces its
    realisations bitwise (tests/test_families.py)."""
    from ..solve.integrators import DP5

    record = dict(record)
    record["family"] = family_record_of_010(record)
    for flat in ("n_large", "distribution", "n", "momentum_conserving"):
        record.pop(flat, None)
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
