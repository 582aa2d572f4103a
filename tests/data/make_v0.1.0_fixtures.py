"""Written once with granchain 0.1.0 (commit bf1cb2a) before the chain-family redesign."""
import numpy as np, scipy.stats, granchain as gc
grid = np.round(np.arange(0.0, 20.05, 0.5), 12)
gc.run_ensemble(6, gc.Uniform(0.01, 0.4), realizations=24, seed=7, chains="both", t_grid=grid, chunk_size=10,
                out="tests/data/v0.1.0-decorated-N6.zarr", resume=False, progress=False, threads=1)
gc.run_ensemble(5, gc.Truncated(scipy.stats.beta(2, 8), upper=0.4), realizations=12, seed=3, chains="both", t_grid=grid,
                chunk_size=5, out="tests/data/v0.1.0-truncated-N5.zarr", resume=False, progress=False, threads=1)
