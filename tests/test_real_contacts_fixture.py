"""Real contacts give the very numbers they gave before the chain's physics became one value.

``tests/data/real-contacts.json`` was written once by commit 8a40b2e, the last before ``ChainModel``, the
backend seam and the generic step loop (``tests/data/make_real_contacts_fixture.py``, which says how).
It holds, for a static load, viscoelastic contacts, heavy and light strikers, two materials against a
wall and all of them at once, ``simulate``'s peaks, grid velocities, contact-force peaks, step counts,
end times and energy errors under DP5 (and RKN4 where the forces depend on positions only), and for
each shipped family with real contacts (decorated with a static load and with viscoelastic contacts,
tapered with a striker and a wall, polydisperse damped and loaded, binary with a striker and a wall) every
numeric variable of a small ensemble. On the processor that wrote it, each must come out bitwise the
same: it could fail by a lowering of the law, the static state, the striker or the wall that rounds
differently, or by a default integrator that changed. On another processor Numba compiles other
instructions, and the numbers agree within the accuracy contract instead
(``test_store_upgrade.CONTRACT``).
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest
from test_store_upgrade import CONTRACT

import granchain as gc

DATA = Path(__file__).parent / "data"
FIXTURE = json.loads((DATA / "real-contacts.json").read_text())
_spec = importlib.util.spec_from_file_location("make_real_contacts_fixture", DATA / "make_real_contacts_fixture.py")
MAKE = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(MAKE)
SAME_PROCESSOR = MAKE.processor() == FIXTURE["processor"]
#: simulate's fields compared within the contract on another processor; the run's own bookkeeping (steps,
#: end time, energy error) only on the fixture's processor (see test_store_upgrade.CONTRACT).
SIMULATE_CONTRACT = {"peak_velocity": CONTRACT["peak_velocity"], "peak_time": CONTRACT["peak_time"],
                     "peak_force": CONTRACT["peak_force"], "velocity": dict(rtol=0, atol=1e-6)}


def decode(entry) -> np.ndarray:
    values, shape, kind = entry
    if kind == "f":
        return np.array([float.fromhex(x) for x in values], dtype=float).reshape(shape)
    return np.array(values).reshape(shape)


def assert_as_fixture(name: str, got, want, field: str, contract: dict) -> None:
    got = np.asarray(got)
    if SAME_PROCESSOR:
        np.testing.assert_array_equal(got, want, err_msg=f"{name}: {field} differs from the fixture")
    elif field in contract:
        np.testing.assert_allclose(got, want, err_msg=f"{name}: {field}", equal_nan=True, **contract[field])


CHAINS = MAKE.chains()
SIMULATE_CASES = [(c, i) for c in CHAINS for i in MAKE.integrators(c)]


def test_the_fixture_covers_what_it_says():
    """Every case the maker lists is in the file, and the file holds nothing else (a negative control for the
    parametrisation below: a case missing from the file would otherwise never be compared)."""
    assert sorted(FIXTURE["simulate"]) == sorted(f"{c} {i}" for c, i in SIMULATE_CASES)
    assert sorted(FIXTURE["ensembles"]) == sorted(MAKE.families())
    assert all(len(v) >= 10 for v in FIXTURE["ensembles"].values())


@pytest.mark.parametrize("chain, integrator", SIMULATE_CASES)
def test_simulate_as_before(chain, integrator):
    r = gc.simulate(CHAINS[chain], MAKE.integrators(chain)[integrator], t_grid=MAKE.GRID)
    want = FIXTURE["simulate"][f"{chain} {integrator}"]
    assert int(r.status) == want["status"]
    for field in MAKE.SIMULATE_FIELDS:
        assert_as_fixture(f"{chain} {integrator}", getattr(r, field), decode(want[field]), field, SIMULATE_CONTRACT)


@pytest.mark.parametrize("family", sorted(MAKE.families()))
def test_ensembles_as_before(family):
    ds = gc.run_ensemble(MAKE.families()[family], realizations=MAKE.REALIZATIONS, seed=MAKE.SEED,
                         t_grid=MAKE.ENSEMBLE_GRID, progress=False)
    for name, entry in FIXTURE["ensembles"][family].items():
        assert name in ds, f"{family}: the ensemble no longer stores {name}"
        assert_as_fixture(family, ds[name].values, decode(entry), name, CONTRACT)


def test_a_changed_number_is_seen():
    """Negative control: the comparison sees a change in the last bit of one peak."""
    want = FIXTURE["simulate"]["striker DP5(1e-8, 1e-11)"]
    peaks = decode(want["peak_velocity"])
    nudged = peaks.copy()
    nudged[2] = np.nextafter(nudged[2], np.inf) if SAME_PROCESSOR else nudged[2] * (1 + 1e-5)
    with pytest.raises(AssertionError):
        assert_as_fixture("striker", nudged, peaks, "peak_velocity", SIMULATE_CONTRACT)
