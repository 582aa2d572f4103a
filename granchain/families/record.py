"""Reading a family back: from its record, and from the attributes of an ensemble Dataset.

:data:`FAMILIES` names every family by its ``kind``; :func:`family_from_record` rebuilds a family
from its :meth:`~granchain.ChainFamily.describe` record, reading the records of earlier versions in
their own meaning (TaperedDecorated's ratio of granchain <= 0.4, viscoelastic laws stored before
the clamp option); :func:`current_family_record` gives such a record in the form this version
writes. :func:`stored_family_record` finds the family record in a Dataset's attributes (a store of
granchain 0.1.0 names the paper's family by flat parameters) and :func:`family_from_dataset`
rebuilds it.

The family's record is read here, not in the ensemble store, so that the families do not depend on
the ensembles that use them: only opening a store given by its path reaches
:func:`granchain.open_store`, the one reader that verifies a store.
"""

from __future__ import annotations

import json
import os
import warnings

from ..model.chain import HERTZ
from ..model.chainmodel import ChainModel
from ..model.distributions import distribution_from_record
from .base import ChainFamily
from .custom import CustomFamily
from .decorated_families import _TAPER, RandomDecorated, TaperedDecorated, _q_of_ratio
from .radii_families import BinaryRandom, RandomRadii

#: Families by ``kind`` (the CLI's ``--family`` choices, and ``family`` in stored records).
FAMILIES = {cls.kind: cls for cls in (RandomDecorated, RandomRadii, BinaryRandom, TaperedDecorated, CustomFamily)}


def family_from_record(record: dict) -> ChainFamily:
    """The family a stored :meth:`ChainFamily.describe` record names (not :class:`CustomFamily`,
    whose function is not stored: pass the family itself)."""
    record = dict(record)
    kind = record.pop("family", None)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # warned about when the ensemble was made
        model = ChainModel.from_record(record)
        if kind == RandomDecorated.kind:
            return RandomDecorated(record["n_large"], distribution_from_record(record["distribution"]), n=record["n"],
                                   momentum_conserving=record["momentum_conserving"], model=model)
        if kind == TaperedDecorated.kind:
            # records of granchain <= 0.4 hold the ratio of successive large radii under "q"
            q = record["q"] if record.get("large_radii") == _TAPER else _q_of_ratio(record["q"])
            return TaperedDecorated(record["n_large"], q=q, distribution=distribution_from_record(record["distribution"]),
                                    n=record["n"], momentum_conserving=record["momentum_conserving"], model=model)
        if kind == RandomRadii.kind:
            return RandomRadii(record["size"], distribution_from_record(record["distribution"]), n=record["n"], model=model)
        if kind == BinaryRandom.kind:
            return BinaryRandom(record["size"], tuple(record["radii"]), record["p"], n=record["n"], model=model)
    if kind == CustomFamily.kind:
        raise ValueError(f"a CustomFamily ({record.get('build')}) cannot be rebuilt from its record: pass the family itself")
    raise ValueError(f"unknown chain family {kind!r}; known: {sorted(FAMILIES)}")


def current_family_record(record: dict) -> dict:
    """The record today's granchain writes for the family an earlier version recorded (records whose
    fields changed meaning, such as TaperedDecorated's q, are read in their own version's meaning)."""
    try:
        return family_from_record(record).describe()
    except (ValueError, KeyError, TypeError):  # a CustomFamily (its function is not stored), or unknown: as stored
        return record


def family_record_of_010(record: dict) -> dict:
    """The family record of a granchain 0.1.0 parameter record, which named the paper's family
    (RandomDecorated) by flat fields (n_large, distribution, n, momentum_conserving)."""
    return {"family": RandomDecorated.kind, "n_large": record["n_large"], "distribution": record["distribution"],
            "n": record.get("n", HERTZ), "momentum_conserving": bool(record.get("momentum_conserving", False))}


def stored_family_record(attrs) -> dict | None:
    """The family record in an ensemble's attributes (``Dataset.attrs``), in the form this version
    writes (:func:`current_family_record`: a record of an earlier version is read in its own meaning):
    the ``granchain_family`` attribute, else the family its ``granchain_parameters`` name (stores of
    granchain 0.1.0 have no family attribute: their parameters name the family by flat fields). None
    where the attributes hold no family record."""
    params = attrs.get("granchain_parameters")
    record = json.loads(params) if params is not None else {}
    text = attrs.get("granchain_family")
    if text is not None:
        return current_family_record(json.loads(text))
    if "family" not in record and "n_large" in record and "distribution" in record:
        return current_family_record(family_record_of_010(record))
    found = record.get("family")
    return current_family_record(found) if isinstance(found, dict) else None


def family_from_dataset(ds) -> ChainFamily:
    """The family of an ensemble Dataset (``run_ensemble``'s result or a store opened with
    :func:`granchain.open_store` or xarray) or of the store at a path, rebuilt from its stored record
    (read through the store's compatibility layer: a store written by granchain 0.1.0 holds no family
    record, its parameters then describe the :class:`RandomDecorated` it was). Raises ValueError for a
    :class:`CustomFamily` (its function is not stored) or a Dataset that is no ensemble."""
    if isinstance(ds, (str, os.PathLike)):
        from ..ensembles.read import open_store  # a path is opened by the reader that verifies stores

        ds = open_store(ds)
    record = stored_family_record(ds.attrs)
    if record is None:
        raise ValueError("this Dataset holds no granchain family record (granchain_family attribute): "
                         "is it an ensemble written by granchain.run_ensemble?")
    return family_from_record(record)
