"""What real contacts cost: a decorated N = 26 realisation with a viscoelastic law, a static load, and
all of them together (with a striker and a wall), against the elastic chain, measured in the same run.

Each variant is the paper's family (``RandomDecorated(26)``, U[0.01, 0.4], the same realisations:
seed 0) with one setting changed, integrated by ``run_ensemble`` with its default integrator (the
elastic and the precompressed chains: ``RKN4.relaxed()``; a viscoelastic law needs DP5:
``DP5.relaxed(DAMPED_RTOL, DAMPED_ATOL)``), in memory, default threads. The variants take turns
round after round (the order rotating), each keeps its best wall time; printed is the wall time per
realisation and the ratio to the elastic chain (> 1: costs more). Why a precompressed realisation
costs more: its contacts never open, so it runs to a time (twice the linear crossing time) instead
of stopping at the pulse's exit, with every granule integrated (a loaded far end reflects the pulse:
no relaxed zone).

    python benchmarks/bench_contacts.py                 # ~2 minutes on 2 cores after compilation
    python benchmarks/bench_contacts.py --realizations 100 --rounds 2    # quicker
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

import granchain as gc

#: The settings of each variant (keywords of RandomDecorated). The damping is that of a coefficient of
#: restitution of 0.9 at the impact speed; the static load F0 = 0.1 is ~1/10 of the pulse's contact
#: force (f_r ~ 10, strongly nonlinear); the striker is as heavy as two large granules.
GAMMA = gc.Viscoelastic.from_restitution(0.9, 1.0).gamma
VARIANTS = {
    "elastic": {},
    "dissipative": {"contact": gc.Viscoelastic(GAMMA)},
    "precompressed": {"static_force": 0.1},
    "combined": {"contact": gc.Viscoelastic(GAMMA), "static_force": 0.1, "striker_mass": 2.0, "wall": True},
}


def run(variant: str, realizations: int) -> tuple[float, object]:
    family = gc.RandomDecorated(26, **VARIANTS[variant])
    t0 = time.perf_counter()
    ds = gc.run_ensemble(family, realizations=realizations, chains="decorated", progress=False,
                         chunk_size=max(1, realizations // 2))
    return time.perf_counter() - t0, ds


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--realizations", type=int, default=400)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args(argv)
    print(f"# granchain {gc.__version__}: decorated N = 26, {args.realizations} realisations per run, best of "
          f"{args.rounds} rounds; gamma = {GAMMA:.6g} (e = 0.9 at speed 1), F0 = 0.1")
    for v in VARIANTS:  # compile every kernel path once, untimed
        run(v, 4)
    best = {v: np.inf for v in VARIANTS}
    info = {}
    names = list(VARIANTS)
    for r in range(args.rounds):
        order = names[r % len(names):] + names[:r % len(names)]
        for v in order:
            wall, ds = run(v, args.realizations)
            best[v] = min(best[v], wall)
            ok = ds["status"].values == 0
            info[v] = (json.loads(ds.attrs["granchain_integrator"])["name"], int(ok.sum()),
                       float(np.median(ds["n_steps"].values)), float(np.max(np.abs(ds["energy_error"].values[ok]))))
    base = best["elastic"] / args.realizations
    print(f"{'variant':<14} {'ms/realisation':>15} {'x elastic':>10} {'integrator':>10} {'ok':>6} {'median steps':>13} "
          f"{'max |energy error|':>19}")
    for v in VARIANTS:
        per = best[v] / args.realizations
        name, ok, steps, err = info[v]
        print(f"{v:<14} {1e3 * per:15.3f} {per / base:10.2f} {name:>10} {ok:6d} {steps:13.0f} {err:19.2e}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
