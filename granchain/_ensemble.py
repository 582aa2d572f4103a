"""``run_ensemble``: many random chains of one family, seeded, parallel, resumable, on disk, on Dask.

An ensemble is a chain family (:mod:`granchain.families`: how realisation i draws its random
parameters from (seed, i) and becomes a chain) integrated by any registered integrator
(:mod:`granchain._integrators`, through ``Integrator.integrate_batch``). Work is split into
chunks of realisations. A chunk is computed locally (Numba threads) or as a task on a Dask
cluster, and its results are written into the store (:mod:`granchain._store`) before it counts
as done. An interrupted run started again with the same arguments skips the done chunks;
redone chunks overwrite their own slots, so nothing is counted twice and the result is
bitwise identical to an uninterrupted run.
"""

from __future__ import annotations

import math
import sys
import warnings
from dataclasses import dataclass, field

import numpy as np

from ._chain import HERTZ
from ._integrators import DP5, Integrator, RunControls, get_integrator
from ._simulate import time_limit
from ._store import MemorySink, ZarrSink
from ._validate import count
from ._version import __version__
from .families import ChainFamily, RandomDecorated

__all__ = ["EnsembleSpec", "run_ensemble", "default_time_grid", "ENSEMBLE_RTOL", "ENSEMBLE_ATOL", "ensemble_integrator"]

#: Ensemble defaults. Per-realisation peaks stay within ~1e-6 (relative) of
#: DOP853 at rtol 1e-10: far below the ensemble's statistical error (~1e-3
#: for 30,000 realisations), at half the cost of simulate()'s tighter defaults.
ENSEMBLE_RTOL = 1e-6
ENSEMBLE_ATOL = 1e-9


def ensemble_integrator() -> Integrator:
    """The ensembles' default integrator: DP5 at :data:`ENSEMBLE_RTOL`, :data:`ENSEMBLE_ATOL`."""
    return DP5(ENSEMBLE_RTOL, ENSEMBLE_ATOL)


def default_time_grid(family=26, dt: float = 0.1) -> np.ndarray:
    """Grid for <v_k(t)> of a family (or of ``RandomDecorated(family)`` for a number N of large
    granules: to 1.1 x the BCA arrival time at granule N, slope 2.35 per granule, + 10)."""
    if not isinstance(family, ChainFamily):
        family = RandomDecorated(family)
    return family.default_time_grid(dt)


def _fixed_point_bits(realizations: int, vmax: float = 2.0) -> int:
    """Bits after the binary point so that sums of v^2 over all realisations fit in int64."""
    return int(min(40, math.floor(math.log2(2.0**62 / (realizations * vmax * vmax)))))


@dataclass(frozen=True)
class EnsembleSpec:
    """Every parameter that determines an ensemble's result (validated)."""

    family: ChainFamily
    realizations: int = 1000
    seed: int = 0
    chains: tuple = ("both",)
    integrator: Integrator = field(default_factory=ensemble_integrator)
    t_grid: np.ndarray = field(default=None, repr=False)
    chunk_size: int = 500
    controls: RunControls = field(default_factory=RunControls)
    lags: np.ndarray = field(default=None, repr=False)

    def __post_init__(self):
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731
        if not isinstance(self.family, ChainFamily):
            raise ValueError(f"family must be a granchain chain family (e.g. granchain.RandomDecorated(26)), got {self.family!r}")
        set_("realizations", count("realizations", self.realizations, minimum=1))
        set_("seed", count("seed", self.seed, minimum=0))
        known = self.family.chains
        chains = (self.chains,) if isinstance(self.chains, str) else tuple(self.chains)
        if chains in (("both",), ("all",)):
            chains = known
        if not chains or any(c not in known for c in chains) or len(set(chains)) != len(chains):
            raise ValueError(f"chains must be one or more of {list(known)} (or 'both'), got {self.chains!r}")
        set_("chains", tuple(c for c in known if c in chains))
        set_("integrator", get_integrator(self.integrator))
        grid = self.family.default_time_grid() if self.t_grid is None else np.asarray(self.t_grid, dtype=float).reshape(-1)
        if grid.size == 0 or not np.all(np.isfinite(grid)) or grid[0] < 0 or np.any(np.diff(grid) <= 0):
            raise ValueError("t_grid must be a non-empty, finite, increasing array of times >= 0")
        grid = np.array(grid)
        grid.setflags(write=False)
        set_("t_grid", grid)
        set_("chunk_size", count("chunk_size", self.chunk_size, minimum=1))
        if not isinstance(self.controls, RunControls):
            raise ValueError(f"controls must be a granchain.RunControls, got {self.controls!r}")
        if self.lags is not None:  # the aligned pulse (granchain._kernels._aligned); None: not accumulated
            lags = np.array(np.asarray(self.lags, dtype=float).reshape(-1))
            if lags.size == 0 or not np.all(np.isfinite(lags)) or np.any(np.diff(lags) <= 0):
                raise ValueError("lags must be a non-empty, finite, increasing array of times relative to each "
                                 "realisation's peak (e.g. numpy.arange(-10, 10.05, 0.1)), or None")
            lags.setflags(write=False)
            set_("lags", lags)

    @property
    def n_chunks(self) -> int:
        return -(-self.realizations // self.chunk_size)

    def chunk_slice(self, j: int) -> slice:
        return slice(j * self.chunk_size, min((j + 1) * self.chunk_size, self.realizations))

    @property
    def fixed_point_bits(self) -> int:
        return _fixed_point_bits(self.realizations)

    def describe(self) -> dict:
        """JSON-able record of the parameters (stored with the results, compared on resume)."""
        record = {
            "family": self.family.describe(),
            "realizations": self.realizations,
            "seed": self.seed,
            "chains": list(self.chains),
            "integrator": self.integrator.describe(),
            "t_grid": {"start": float(self.t_grid[0]), "stop": float(self.t_grid[-1]), "size": int(self.t_grid.size),
                       "checksum": float(np.sum(self.t_grid * np.arange(1, self.t_grid.size + 1)))},
            "chunk_size": self.chunk_size,
            "exit_margin": self.controls.exit_margin,
            "peak_rtol": self.controls.peak_rtol,
            "max_steps": self.controls.max_steps,
            "granchain_version": __version__,
        }
        if self.lags is not None:  # only then: stores without the aligned pulse keep their 0.1/0.2 record
            record["lags"] = {"start": float(self.lags[0]), "stop": float(self.lags[-1]), "size": int(self.lags.size),
                              "checksum": float(np.sum(self.lags * np.arange(1, self.lags.size + 1)))}
        return record


# --------------------------------------------------------------------------- compute
def compute_chunk(spec: EnsembleSpec, j: int, threads: int | None = None) -> dict:
    """Results of chunk j: the family's random parameters, per-realisation results and fixed-point sums.

    A top-level function so that Dask can ship it to workers.
    """
    import numba

    previous = numba.get_num_threads()
    if threads is not None:
        numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
    try:
        return _compute_chunk(spec, j)
    finally:
        numba.set_num_threads(previous)


def _compute_chunk(spec: EnsembleSpec, j: int) -> dict:
    sl = spec.chunk_slice(j)
    idx = np.arange(sl.start, sl.stop)
    family = spec.family
    params = family.draw_batch(spec.seed, idx)
    R, K, T, nc = idx.size, family.n_observed, spec.t_grid.size, len(spec.chains)
    out = {
        "chunk": j,
        "realizations": R,
        **params,
        "peak_velocity": np.zeros((nc, R, K)),
        "peak_time": np.zeros((nc, R, K)),
        "status": np.zeros((nc, R), dtype=np.int64),
        "energy_error": np.zeros((nc, R)),
        "n_steps": np.zeros((nc, R), dtype=np.int64),
        "t_end": np.zeros((nc, R)),
        "sum_v": np.zeros((nc, T, K), dtype=np.int64),  # time-major in the kernels
        "sum_v2": np.zeros((nc, T, K), dtype=np.int64),
        "n_valid": np.zeros((nc, 1), dtype=np.int64),
    }
    scale = float(2.0**spec.fixed_point_bits)
    per_chain = ("peak_velocity", "peak_time", "status", "energy_error", "n_steps", "t_end", "sum_v", "sum_v2", "n_valid")
    if spec.lags is not None:  # the aligned pulse, lag-major in the kernels
        out["sum_a"] = np.zeros((nc, spec.lags.size, K), dtype=np.int64)
        out["sum_a2"] = np.zeros((nc, spec.lags.size, K), dtype=np.int64)
        per_chain += ("sum_a", "sum_a2")
    for ci, name in enumerate(spec.chains):
        batch = family.build(params, name)
        masses = np.ascontiguousarray(batch.masses, dtype=float)
        v0 = np.ascontiguousarray(batch.initial_velocity, dtype=float)
        t_max = max(time_limit(masses.shape[1], float(v0.min()), batch.n), float(spec.t_grid[-1]))
        spec.integrator.integrate_batch(
            masses, np.ascontiguousarray(batch.stiffness, dtype=float), batch.n, v0,
            np.ascontiguousarray(batch.observed, dtype=np.int64), t_grid=spec.t_grid, t_max=t_max, controls=spec.controls,
            scale=scale, out={**{k: out[k][ci] for k in per_chain}, "lags": spec.lags},
        )
    for name in ("sum_v", "sum_v2", "sum_a", "sum_a2"):
        if name in out:  # (chain, granule, time | lag)
            out[name] = np.ascontiguousarray(out[name].transpose(0, 2, 1))
    return out


def _dask_chunk(spec: EnsembleSpec, j: int) -> dict:
    """Dask task: one chunk with as many Numba threads as the worker has."""
    try:
        from distributed import get_worker

        threads = get_worker().state.nthreads
    except (ImportError, ValueError, AttributeError):
        threads = None
    return compute_chunk(spec, j, threads=threads)


_SUGAR_DEFAULTS = {"distribution": None, "n": HERTZ, "momentum_conserving": False}


def _family_of(family, distribution, n, momentum_conserving) -> ChainFamily:
    """``family`` itself, or ``RandomDecorated`` for the old call ``run_ensemble(n_large, distribution, ...)``."""
    given = {"distribution": distribution, "n": n, "momentum_conserving": momentum_conserving}
    if isinstance(family, ChainFamily):
        extra = [k for k, v in given.items() if v is not _SUGAR_DEFAULTS[k] and v != _SUGAR_DEFAULTS[k]]
        if extra:
            raise ValueError(f"{', '.join(extra)} belong to the family when one is given: e.g. "
                             f"run_ensemble(RandomDecorated(26, distribution, n=2.5, momentum_conserving=False), ...)")
        return family
    if isinstance(family, (int, np.integer)) and not isinstance(family, bool):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            fam = RandomDecorated(family, distribution, n=n, momentum_conserving=momentum_conserving)
        for w in caught:  # re-issued at the caller of run_ensemble
            warnings.warn(w.message, w.category, stacklevel=4)
        return fam
    raise ValueError(f"family must be a chain family (granchain.RandomDecorated(26), RandomRadii(...), ...) "
                     f"or a number N of large granules, got {family!r}")


def _integrator_of(integrator, rtol, atol) -> Integrator:
    if integrator is None:
        return DP5(ENSEMBLE_RTOL if rtol is None else rtol, ENSEMBLE_ATOL if atol is None else atol)
    if rtol is not None or atol is not None:
        raise ValueError("rtol/atol set the default DP5; with integrator= set them on the integrator, e.g. DP5(rtol=1e-7)")
    return get_integrator(integrator)


def run_ensemble(family=26, distribution=None, realizations: int = 1000, seed: int = 0, chains="both", *,
                 integrator=None, n: float = HERTZ, rtol: float | None = None, atol: float | None = None, t_grid=None,
                 chunk_size: int = 500, out=None, resume: bool = True, client=None, progress: bool = True,
                 momentum_conserving: bool = False, exit_margin: float = 3.0, peak_rtol: float = 1e-6,
                 max_steps: int = 20_000_000, threads: int | None = None, n_large: int | None = None, lags=None):
    """Integrate ``realizations`` random chains of a family, with any registered integrator.

    Parameters
    ----------
    family : ChainFamily or int
        The chain family (:class:`granchain.RandomDecorated`, :class:`granchain.TaperedDecorated`,
        :class:`granchain.RandomRadii`, :class:`granchain.BinaryRandom`,
        :class:`granchain.CustomFamily`). A number N is the paper's chain,
        ``RandomDecorated(N, distribution, n=n, momentum_conserving=momentum_conserving)``.
    distribution, n, momentum_conserving
        Only with a number N (otherwise they belong to the family).
    n_large : int, optional
        The name of the first argument before granchain 0.2 (``run_ensemble(n_large=26)``), still accepted.
    realizations, seed : int
        Realisation i draws its random parameters from SeedSequence(seed, spawn_key=(i,)).
    chains : str or tuple
        Which of the family's chains to integrate for the same realisations (paired):
        "decorated", "effective" or "both" for decorated families; the family's one chain otherwise.
    integrator : DP5 | Verlet | DOP853 | str, optional
        Any registered integrator (default: DP5 at :data:`ENSEMBLE_RTOL`, :data:`ENSEMBLE_ATOL`,
        or at ``rtol``/``atol`` if given). DOP853 runs realisation by realisation in Python (slow).
    t_grid : array, optional
        Times of the averaged pulse <v_k(t)> (default: the family's ``default_time_grid()``).
    chunk_size : int
        Realisations per chunk: the unit of work, of saving and of resuming.
    out : path, optional
        Zarr store to write (and resume). Without it the results stay in memory.
    resume : bool
        Continue an existing store written with the same parameters (a store
        with other parameters is refused). False: an existing store is an error.
    client : dask.distributed.Client, optional
        Run the chunks as tasks on this cluster (results are identical).
    progress : bool
        Progress bar with realisations/s and ETA on stderr.
    exit_margin, peak_rtol, max_steps
        Run controls, as in :func:`granchain.simulate` (:class:`granchain.RunControls`).
    threads : int, optional
        Numba threads for local runs (default: all cores).
    lags : array, optional
        Also accumulate the *aligned* pulse <v_k(t_k^peak + tau)> on these lags tau (times relative
        to each realisation's own peak time at k; variables ``aligned_velocity``,
        ``aligned_velocity_stderr`` with dim ``lag``; see :mod:`granchain.dephasing`).
        Default None: not accumulated (the store is then exactly as without this option).

    Returns
    -------
    xarray.Dataset with dims chain, realization, granule (the family's observed granules),
    time and the family's parameter dims (see README).
    """
    if n_large is not None:
        family = n_large
    fam = _family_of(family, distribution, n, momentum_conserving)
    spec = EnsembleSpec(fam, realizations, seed, chains, _integrator_of(integrator, rtol, atol), t_grid, chunk_size,
                        RunControls(exit_margin, max_steps, peak_rtol), lags)
    sink = MemorySink(spec) if out is None else ZarrSink(spec, out, resume)
    pending = sink.pending()
    done_realizations = spec.realizations - sum(spec.chunk_slice(j).stop - spec.chunk_slice(j).start for j in pending)
    from tqdm.auto import tqdm

    bar = tqdm(total=spec.realizations, initial=done_realizations, unit=" realisations", disable=not progress, smoothing=0.05,
               desc=f"{fam.kind} {'+'.join(spec.chains)}", dynamic_ncols=True)
    futures = []
    try:
        if client is None:
            for j in pending:
                res = compute_chunk(spec, j, threads=threads)
                sink.write(res)
                bar.update(res["realizations"])
        else:
            from distributed import as_completed

            futures = [client.submit(_dask_chunk, spec, j, pure=False) for j in pending]
            for fut, res in as_completed(futures, with_results=True):
                sink.write(res)
                bar.update(res["realizations"])
                fut.release()
    except KeyboardInterrupt:
        if futures:
            client.cancel(futures)
        bar.close()
        if out is not None:
            print(f"\ninterrupted: finished chunks are saved in {out}; call again with the same arguments "
                  "(resume=True) to continue", file=sys.stderr, flush=True)
        raise
    bar.close()
    return sink.finalize()
