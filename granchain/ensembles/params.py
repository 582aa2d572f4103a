"""A store's parameter record and the checks that compare it with a run's before the run continues it.

:func:`stored_parameters` reads the record (progress group first, then the root attributes);
:func:`check_same_family` and :func:`check_same_parameters` refuse to resume or extend a store written
with other settings, naming each setting that differs, so that results are never mixed. Records of
earlier versions are compared in today's form (:mod:`~granchain.ensembles.compat`).
"""

from __future__ import annotations

import json
import os

from .compat import current_record
from .files import _read_json

__all__ = ["stored_parameters", "check_same_parameters", "check_same_family"]


def stored_parameters(path) -> str | None:
    """The parameter record of a store (progress group first, then the root attributes)."""
    for attrs in (os.path.join(path, "progress", ".zattrs"), os.path.join(path, ".zattrs")):
        doc = _read_json(attrs)
        if isinstance(doc, dict) and isinstance(doc.get("granchain_parameters"), str):
            return doc["granchain_parameters"]
    return None


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
    _check_backends(path, old, new)
    old.pop("backends_used", None), new.pop("backends_used", None)  # the run's history, checked just above
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


def _check_backends(path, old: dict, new: dict) -> None:
    """Refuse a run whose backend did not compute the store, unless it comes with ``switch_backend`` (its
    record then lists the store's backends and its own after them: :mod:`granchain.ensembles.backend`),
    naming both backends rather than a difference of records."""
    from .backend import other_backend, stored_backends

    was, now = stored_backends(old), stored_backends(new)
    if now == was or (now[:len(was)] == was and len(now) == len(was) + 1):
        return
    raise other_backend(path, was, now[-1])


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
