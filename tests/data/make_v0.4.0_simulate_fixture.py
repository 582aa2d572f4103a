"""Written once with granchain 0.4.0 (commit df53015), to check that later versions give the very same
numbers from ``simulate`` for every compiled integrator (the reorganisation of the kernels into
backends and grouped records promised no change of results). Run from the repository root with that
version importable, e.g.

    git archive df53015 | tar -x -C /tmp/g040 && PYTHONPATH=/tmp/g040 python tests/data/make_v0.4.0_simulate_fixture.py

Floats are stored as ``float.hex`` strings, so the comparison is bitwise. Never regenerate this file
with newer code.
"""
import json

import numpy as np

import granchain as gc

assert gc.__version__ == "0.4.0", "run this with granchain 0.4.0 (df53015)"
decorated = gc.random_decorated(8, gc.Uniform(0.01, 0.4), seed=3)
CHAINS = {
    "decorated": decorated,
    "effective": gc.effective(decorated),
    "monodisperse": gc.monodisperse(10),
    "exponent-3": gc.from_radii([1.0, 0.7, 1.2, 0.9, 1.1], n=3.0),
    "decorated-wall": gc.random_decorated(6, gc.Uniform(0.01, 0.4), seed=4).with_wall(),
}
INTEGRATORS = {
    "DP5()": gc.DP5(),
    "DP5.relaxed()": gc.DP5.relaxed(),
    "RKN4.relaxed()": gc.RKN4.relaxed(),
    "RKN4.windowed()": gc.RKN4.windowed(),
    "Verlet(dt=1e-3)": gc.Verlet(dt=1e-3),
}
grid = np.linspace(0.0, 40.0, 81)
hexes = lambda a: [float(x).hex() for x in np.ravel(a)]  # noqa: E731
out = {}
for cname, chain in CHAINS.items():
    for iname, integ in INTEGRATORS.items():
        r = gc.simulate(chain, integ, t_grid=grid)
        out[f"{cname} / {iname}"] = {
            "status": int(r.status), "n_steps": int(r.n_steps), "peak_velocity": hexes(r.peak_velocity),
            "peak_time": hexes(r.peak_time), "velocity": hexes(r.velocity), "peak_force": hexes(r.peak_force),
            "peak_force_time": hexes(r.peak_force_time), "energy_error": float(r.energy_error).hex(),
        }
with open("tests/data/v0.4.0-simulate.json", "w") as f:
    json.dump({"grid": [0.0, 40.0, 81], "runs": out}, f, indent=0, sort_keys=True)
