"""Written once with granchain 0.4.0 (commit df53015, the last before the stored units became "1"
and TaperedDecorated's q became the literature's), to check that later versions resume and extend
its stores bitwise. Run from the repository root with that version importable, e.g.

    git archive df53015 | tar -x -C /tmp/g040 && PYTHONPATH=/tmp/g040 python tests/data/make_v0.4.0_fixtures.py

Never regenerate them with newer code.
"""
import numpy as np
import granchain as gc

assert gc.__version__ == "0.4.0" and not hasattr(gc.units, "si_value"), "run this with granchain 0.4.0 (df53015)"
grid = np.round(np.arange(0.0, 30.05, 0.5), 12)
# the ensembles' defaults of 0.4.0: RKN4.relaxed() for decorated chains, DP5.relaxed(5e-8, 5e-11) for effective ones
gc.run_ensemble(gc.RandomDecorated(6, gc.Uniform(0.01, 0.4)), realizations=24, seed=7, chains="both", t_grid=grid,
                chunk_size=8, out="tests/data/v0.4.0-decorated-N6.zarr", resume=False, progress=False, threads=1)
# a family whose record changed meaning (q was the ratio 0.9), a wall, the aligned pulse
gc.run_ensemble(gc.TaperedDecorated(5, 0.9, gc.Uniform(0.05, 0.35), wall=True), realizations=12, seed=3, chains="both",
                t_grid=grid, chunk_size=4, out="tests/data/v0.4.0-tapered-wall-N5.zarr", resume=False, progress=False,
                threads=1, lags=np.round(np.arange(-4.0, 4.05, 0.5), 12))
