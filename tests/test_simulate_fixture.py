"""``simulate`` gives the very numbers granchain 0.4.0 gave.

The kernels were reorganised behind a backend layer (split by concern, grouped records, the model's
scalars in one record) with the promise that no result changes. ``tests/data/v0.4.0-simulate.json``
was written once by granchain 0.4.0 (``tests/data/make_v0.4.0_simulate_fixture.py``): peak
velocities and times, velocities on a grid, contact-force peaks, step counts and the energy error of
five chains (decorated, its effective chain, monodisperse, a general exponent, decorated against a
wall) under every compiled integrator and its goal-oriented variants, as ``float.hex`` strings. Each
must come out bitwise the same. A change of results is possible (a better method, a fixed bug), but
it must be a decision: regenerating this file is not allowed (make a new fixture and say why).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import granchain as gc

FIXTURE = Path(__file__).parent / "data" / "v0.4.0-simulate.json"
DATA = json.loads(FIXTURE.read_text())
DECORATED = gc.random_decorated(8, gc.Uniform(0.01, 0.4), seed=3)
CHAINS = {
    "decorated": DECORATED,
    "effective": gc.effective(DECORATED),
    "monodisperse": gc.monodisperse(10),
    "exponent-3": gc.from_radii([1.0, 0.7, 1.2, 0.9, 1.1], n=3.0),
    "decorated-wall": gc.random_decorated(6, gc.Uniform(0.01, 0.4), seed=4).with_wall(),
}
#: {fixture name: the integrator of 0.4.0 it names}; RKN4's default tolerances were 1e-5, 1e-8 then
#: (3e-6, 3e-9 now: its peak contact forces missed the accuracy contract, benchmarks/validate_tolerances.py).
INTEGRATORS = {
    "DP5()": gc.DP5(),
    "DP5.relaxed()": gc.DP5.relaxed(),
    "RKN4.relaxed()": gc.RKN4.relaxed(1e-5, 1e-8),
    "RKN4.windowed()": gc.RKN4.windowed(1e-5, 1e-8),
    "Verlet(dt=1e-3)": gc.Verlet(dt=1e-3),
}


def hexes(a) -> list[str]:
    return [float(x).hex() for x in np.ravel(a)]


def test_the_fixture_covers_every_case():
    assert set(DATA["runs"]) == {f"{c} / {i}" for c in CHAINS for i in INTEGRATORS}


@pytest.mark.parametrize("integ_name", list(INTEGRATORS))
@pytest.mark.parametrize("chain_name", list(CHAINS))
def test_simulate_is_bitwise_that_of_0_4_0(chain_name, integ_name):
    start, stop, size = DATA["grid"]
    r = gc.simulate(CHAINS[chain_name], INTEGRATORS[integ_name], t_grid=np.linspace(start, stop, size))
    expected = DATA["runs"][f"{chain_name} / {integ_name}"]
    got = {"status": int(r.status), "n_steps": int(r.n_steps), "peak_velocity": hexes(r.peak_velocity),
           "peak_time": hexes(r.peak_time), "velocity": hexes(r.velocity), "peak_force": hexes(r.peak_force),
           "peak_force_time": hexes(r.peak_force_time), "energy_error": float(r.energy_error).hex()}
    for key, value in expected.items():
        assert got[key] == value, f"{chain_name} / {integ_name}: {key} differs from granchain 0.4.0's"


def test_a_slightly_different_run_is_seen():
    """Negative control: the comparison is sensitive. The same chain under DP5 with rtol one part in
    10^4 away from the default differs from the fixture in its peak velocities' bits."""
    default = gc.DP5()
    nudged = gc.DP5(rtol=default.rtol * 1.0001, atol=default.atol)
    start, stop, size = DATA["grid"]
    r = gc.simulate(CHAINS["decorated"], nudged, t_grid=np.linspace(start, stop, size))
    assert hexes(r.peak_velocity) != DATA["runs"]["decorated / DP5()"]["peak_velocity"]
