"""Write ``real-contacts.json``: the numbers of real contacts (a static load, viscoelastic contacts, a
striker, walls, several materials) as granchain computed them before the chain's physics became one
value (``ChainModel``) and the step loop one generic loop over scheme values.

It was run once, from a checkout of commit 8a40b2e (the last commit before that reorganisation)::

    git worktree add --detach /tmp/gc-8a40b2e 8a40b2e
    cd /tmp && PYTHONPATH=/tmp/gc-8a40b2e python /path/to/tests/data/make_real_contacts_fixture.py

and ``tests/test_real_contacts_fixture.py`` checks that today's code gives the same numbers bitwise.
Do not regenerate it: a change of results is a decision (make a new fixture and say why). It uses only
the API both versions share: the chain's ``with_*`` methods, ``from_radii(materials=)`` and the
families' keywords ``contact``, ``static_force``, ``striker_mass`` and ``wall``. Every number is
written as ``float.hex`` (integers as they are), with the processor it was computed on: Numba compiles
for the host, and another processor may round differently.
"""

from __future__ import annotations

import json
import platform
import subprocess
import sys
from pathlib import Path

import numpy as np

import granchain as gc

#: What is recorded of each single-chain run (every one a field of ``SimulationResult`` in both versions).
SIMULATE_FIELDS = ("peak_velocity", "peak_time", "velocity", "peak_force", "n_steps", "energy_error", "t_end")


def chains():
    base = gc.random_decorated(6, gc.Uniform(0.01, 0.4), seed=3)
    return {
        "precompressed": base.with_precompression(0.05),
        "viscoelastic": base.with_dissipation(restitution=0.9),
        "striker": base.with_striker(mass=3.0),
        "striker-light": base.with_striker(mass=0.2),
        "materials-wall": gc.from_radii([1.0, 0.6, 1.0, 0.6, 1.0, 0.6], materials=["steel", "ptfe"] * 3, wall=True),
        "everything": base.with_precompression(0.02).with_dissipation(restitution=0.95).with_striker(mass=2.0).with_wall(),
    }


def integrators(chain_name):
    """Explicit tolerances (defaults may move; the fixture pins the numbers of these integrators)."""
    out = {"DP5(1e-8, 1e-11)": gc.DP5(rtol=1e-8, atol=1e-11)}
    if chain_name not in ("viscoelastic", "everything"):  # RKN4 needs forces of positions only
        out["RKN4(1e-6, 1e-9)"] = gc.RKN4(rtol=1e-6, atol=1e-9)
    return out


def families():
    dist = gc.Uniform(0.01, 0.4)
    return {
        "decorated-precompressed": gc.RandomDecorated(5, dist, static_force=0.05),
        "decorated-viscoelastic": gc.RandomDecorated(5, dist, contact=gc.Viscoelastic(0.05)),
        "tapered-striker-wall": gc.TaperedDecorated(5, q=0.1, distribution=dist, striker_mass=2.0, wall=True),
        "polydisperse-damped-loaded": gc.RandomRadii(6, gc.Uniform(0.5, 1.0), contact=gc.Viscoelastic(0.05),
                                                     static_force=0.02),
        "binary-striker-wall": gc.BinaryRandom(6, radii=(1.0, 0.5), striker_mass=2.0, wall=True),
    }


#: Ensemble size per family: a few realisations of each chain kind, every stored variable recorded,
#: the averaged pulse on a coarse grid.
REALIZATIONS = 3
SEED = 11
ENSEMBLE_GRID = np.linspace(0.0, 30.0, 61)


def encode(a):
    a = np.asarray(a)
    if a.dtype.kind == "f":
        return [float(x).hex() for x in a.ravel()], list(a.shape), "f"
    return [int(x) for x in a.ravel()], list(a.shape), "i"


#: The time grid of the single-chain cases (the pulse crosses the six large granules by t ~ 15).
GRID = np.linspace(0.0, 25.0, 51)


def main() -> None:
    out = {"granchain": gc.__version__, "file": gc.__file__, "processor": processor(), "simulate": {}, "ensembles": {}}
    for name, chain in chains().items():
        for iname, integ in integrators(name).items():
            r = gc.simulate(chain, integ, t_grid=GRID)
            out["simulate"][f"{name} {iname}"] = {f: encode(getattr(r, f)) for f in SIMULATE_FIELDS}
            out["simulate"][f"{name} {iname}"]["status"] = int(r.status)
    for name, fam in families().items():
        ds = gc.run_ensemble(fam, realizations=REALIZATIONS, seed=SEED, t_grid=ENSEMBLE_GRID, progress=False)
        out["ensembles"][name] = {v: encode(ds[v].values) for v in sorted(ds.data_vars)
                                  if ds[v].dtype.kind in "fiu"}
    path = Path(__file__).with_name("real-contacts.json")
    path.write_text(json.dumps(out, sort_keys=True) + "\n")
    print(f"wrote {path} from granchain {gc.__version__} at {gc.__file__}", file=sys.stderr)


def processor() -> str:
    """What Numba compiles for: LLVM's name of the host processor and a digest of its features (two machines
    that share a marketing name, "Intel(R) Xeon(R) Processor", may differ in vector width), with the
    marketing name (Linux) for a reader."""
    import hashlib

    import llvmlite.binding as llvm

    features = llvm.get_host_cpu_features().flatten()
    model = platform.processor() or platform.machine()
    try:
        text = subprocess.run(["lscpu"], capture_output=True, text=True, check=False).stdout
        model = next((line.split(":", 1)[1].strip() for line in text.splitlines() if line.startswith("Model name:")), model)
    except OSError:
        pass
    return f"{llvm.get_host_cpu_name()} (LLVM features {hashlib.sha256(features.encode()).hexdigest()[:12]}; {model})"


if __name__ == "__main__":
    main()
