"""``run_ensemble``: many random decorated chains, seeded, parallel, resumable, on disk, on Dask.

Work is split into chunks of realisations. A chunk is computed by the
compiled ensemble kernel (Numba threads) locally or as a task on a Dask
cluster, and its results are written into a Zarr store before it counts as
done: per-realisation variables into their region of the root group, the
chunk's fixed-point velocity sums and its ``done`` flag into the ``progress``
group (sums first, flag last; Zarr writes each storage chunk atomically). An
interrupted run started again with the same arguments skips the done chunks;
redone chunks overwrite their own slots, so nothing is counted twice and the
result is bitwise identical to an uninterrupted run.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import os
import sys
import warnings
from dataclasses import dataclass, field

import numpy as np

from . import __version__
from ._chain import HERTZ, sphere_mass, sphere_stiffness
from ._distributions import as_distribution
from ._effective import effective_parameters
from ._integrators import DP5
from ._kernels._common import power_code
from ._kernels._ensemble import dp5_ensemble
from ._random import draw_small_radii
from ._simulate import Status, time_limit
from ._validate import count, exponent, finite_scalar

__all__ = ["EnsembleSpec", "run_ensemble", "default_time_grid", "ENSEMBLE_RTOL", "ENSEMBLE_ATOL"]

CHAINS = ("decorated", "effective")


def _zarr_format() -> dict:
    """Write Zarr format 2: a stable spec that every Zarr reader understands, with string coordinates
    (format 3 has no settled string data type yet)."""
    import zarr

    return {"zarr_format": 2} if int(zarr.__version__.split(".")[0]) >= 3 else {}

#: Ensemble defaults. Per-realisation peaks stay within ~1e-6 (relative) of
#: DOP853 at rtol 1e-10: far below the ensemble's statistical error (~1e-3
#: for 30,000 realisations), at half the cost of simulate()'s tighter defaults.
ENSEMBLE_RTOL = 1e-6
ENSEMBLE_ATOL = 1e-9


def default_time_grid(n_large: int, dt: float = 0.1) -> np.ndarray:
    """Grid for <v_k(t)>: to 1.1 x the BCA arrival time at granule N (slope 2.35 per granule) + 10."""
    t_end = 1.1 * 2.35 * (n_large - 1) + 10.0
    return np.round(np.arange(0.0, t_end + 0.5 * dt, dt), 12)


def _fixed_point_bits(realizations: int, vmax: float = 2.0) -> int:
    """Bits after the binary point so that sums of v^2 over all realisations fit in int64."""
    return int(min(40, math.floor(math.log2(2.0**62 / (realizations * vmax * vmax)))))


@dataclass(frozen=True)
class EnsembleSpec:
    """Every parameter that determines an ensemble's result (validated)."""

    n_large: int = 26
    distribution: object = None
    realizations: int = 1000
    seed: int = 0
    chains: tuple = CHAINS
    n: float = HERTZ
    rtol: float = ENSEMBLE_RTOL
    atol: float = ENSEMBLE_ATOL
    t_grid: np.ndarray = field(default=None, repr=False)
    chunk_size: int = 500
    momentum_conserving: bool = False
    exit_margin: float = 3.0
    peak_rtol: float = 1e-6
    max_steps: int = 20_000_000

    def __post_init__(self):
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731
        set_("n_large", count("n_large", self.n_large, minimum=2))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # warned about once, by run_ensemble
            set_("distribution", as_distribution(self.distribution))
        set_("realizations", count("realizations", self.realizations, minimum=1))
        set_("seed", count("seed", self.seed, minimum=0))
        chains = (self.chains,) if isinstance(self.chains, str) else tuple(self.chains)
        if chains == ("both",):
            chains = CHAINS
        if not chains or any(c not in CHAINS for c in chains) or len(set(chains)) != len(chains):
            raise ValueError(f"chains must be 'decorated', 'effective' or 'both' (or a tuple of those), got {self.chains!r}")
        set_("chains", tuple(c for c in CHAINS if c in chains))
        set_("n", exponent(self.n))
        DP5(self.rtol, self.atol)  # validates the tolerances
        set_("rtol", float(self.rtol))
        set_("atol", float(self.atol))
        grid = default_time_grid(self.n_large) if self.t_grid is None else np.asarray(self.t_grid, dtype=float).reshape(-1)
        if grid.size == 0 or not np.all(np.isfinite(grid)) or grid[0] < 0 or np.any(np.diff(grid) <= 0):
            raise ValueError("t_grid must be a non-empty, finite, increasing array of times >= 0")
        grid.setflags(write=False)
        set_("t_grid", grid)
        set_("chunk_size", count("chunk_size", self.chunk_size, minimum=1))
        set_("exit_margin", finite_scalar("exit_margin", self.exit_margin))
        set_("peak_rtol", finite_scalar("peak_rtol", self.peak_rtol))
        set_("max_steps", count("max_steps", self.max_steps, minimum=1))

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
        return {
            "n_large": self.n_large,
            "distribution": self.distribution.describe(),
            "realizations": self.realizations,
            "seed": self.seed,
            "chains": list(self.chains),
            "n": self.n,
            "integrator": "dp5",
            "rtol": self.rtol,
            "atol": self.atol,
            "t_grid": {"start": float(self.t_grid[0]), "stop": float(self.t_grid[-1]), "size": int(self.t_grid.size),
                       "checksum": float(np.sum(self.t_grid * np.arange(1, self.t_grid.size + 1)))},
            "chunk_size": self.chunk_size,
            "momentum_conserving": self.momentum_conserving,
            "exit_margin": self.exit_margin,
            "peak_rtol": self.peak_rtol,
            "max_steps": self.max_steps,
            "granchain_version": __version__,
        }


# --------------------------------------------------------------------------- compute
def _chain_arrays(spec: EnsembleSpec, kind: str, small: np.ndarray):
    """Masses, stiffnesses (R, M), initial velocities (R,) and observed indices of a batch.

    The same functions ``decorated``/``effective`` use, applied along the last axis, so
    each row is bitwise the chain ``simulate`` users build for that realisation.
    """
    R, G = small.shape
    if kind == "decorated":
        radii = np.ones((R, 2 * G + 1))
        radii[:, 1::2] = small
        v0 = np.ones(R)
        return sphere_mass(radii), sphere_stiffness(radii), v0, np.arange(0, 2 * G + 1, 2)
    mu, c_eff = effective_parameters(np.ones((R, G + 1)), small, spec.n)
    v0 = 1.0 / mu[:, 0] if spec.momentum_conserving else np.ones(R)  # m_1 v_1 / mu_1 with m_1 = v_1 = 1
    return mu, c_eff, v0, np.arange(G + 1)


def compute_chunk(spec: EnsembleSpec, j: int, threads: int | None = None) -> dict:
    """Results of chunk j: per-realisation arrays and fixed-point velocity sums.

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
    import numba

    sl = spec.chunk_slice(j)
    idx = np.arange(sl.start, sl.stop)
    small = draw_small_radii(spec.distribution, spec.n_large - 1, spec.seed, idx)
    R, N, T = idx.size, spec.n_large, spec.t_grid.size
    nc = len(spec.chains)
    out = {
        "chunk": j,
        "small_radius": small,
        "peak_velocity": np.zeros((nc, R, N)),
        "peak_time": np.zeros((nc, R, N)),
        "status": np.zeros((nc, R), dtype=np.int64),
        "energy_error": np.zeros((nc, R)),
        "n_steps": np.zeros((nc, R), dtype=np.int64),
        "t_end": np.zeros((nc, R)),
        "sum_v": np.zeros((nc, T, N), dtype=np.int64),  # time-major in the kernel
        "sum_v2": np.zeros((nc, T, N), dtype=np.int64),
        "n_valid": np.zeros((nc, 1), dtype=np.int64),
    }
    scale = float(2.0**spec.fixed_point_bits)
    for ci, kind in enumerate(spec.chains):
        masses, stiffness, v0, obs = _chain_arrays(spec, kind, small)
        t_max = max(time_limit(masses.shape[1], float(v0.min()), spec.n), float(spec.t_grid[-1]))
        dp5_ensemble(
            masses, stiffness, spec.n, power_code(spec.n), v0, obs, spec.rtol, spec.atol, 1e-3, t_max,
            spec.exit_margin, spec.max_steps, spec.peak_rtol, spec.t_grid, scale, numba.get_num_threads(),
            out["peak_velocity"][ci], out["peak_time"][ci], out["status"][ci], out["energy_error"][ci],
            out["n_steps"][ci], out["t_end"][ci], out["sum_v"][ci], out["sum_v2"][ci], out["n_valid"][ci],
        )
    out["sum_v"] = np.ascontiguousarray(out["sum_v"].transpose(0, 2, 1))  # (chain, granule, time)
    out["sum_v2"] = np.ascontiguousarray(out["sum_v2"].transpose(0, 2, 1))
    return out


# --------------------------------------------------------------------------- dataset and store
_UNITS_V = "V_1 (velocity of the struck granule; rescaled, paper Sec. II)"
_UNITS_T = "rescaled time (paper Sec. II)"


def _attrs(spec: EnsembleSpec) -> dict:
    d = spec.describe()
    attrs = {
        "title": "granchain ensemble of random decorated chains (Harbola, Rosas, Romero, Lindenberg)",
        "granchain_parameters": json.dumps(d, sort_keys=True),
        "granchain_version": __version__,
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "n_large": spec.n_large,
        "realizations": spec.realizations,
        "seed": spec.seed,
        "n": spec.n,
        "distribution": spec.distribution.label(),
        "integrator": "dp5",
        "rtol": spec.rtol,
        "atol": spec.atol,
        "chunk_size": spec.chunk_size,
        "momentum_conserving": int(spec.momentum_conserving),
        "exit_margin": spec.exit_margin,
        "peak_rtol": spec.peak_rtol,
        "fixed_point_bits": spec.fixed_point_bits,
        "status_codes": "; ".join(f"{int(s)} = {s.name}: {s.message}" for s in Status),
    }
    for key in ("alpha", "beta"):
        if key in d["distribution"]:
            attrs[key] = d["distribution"][key]
    return attrs


def _empty_dataset(spec: EnsembleSpec, lazy: bool):
    """The result Dataset with every variable at full size, filled with missing values."""
    import xarray as xr

    zeros = np.full
    if lazy:
        import dask.array as da

        zeros = lambda shape, fill, dtype=float: da.full(shape, fill, dtype=dtype, chunks=_storage_chunks(spec, shape))  # noqa: E731
    R, N, T, C = spec.realizations, spec.n_large, spec.t_grid.size, len(spec.chains)
    var = lambda dims, shape, fill, dtype, **attrs: (dims, zeros(shape, fill, dtype=dtype), attrs)  # noqa: E731
    ds = xr.Dataset(
        {
            "small_radius": var(("realization", "gap"), (R, N - 1), np.nan, float, units="R_1 (large-granule radius)",
                                long_name="radius of the small granule between large granules j and j+1"),
            "peak_velocity": var(("chain", "realization", "granule"), (C, R, N), np.nan, float, units=_UNITS_V,
                                 long_name="maximum velocity of large granule k in the realisation"),
            "peak_time": var(("chain", "realization", "granule"), (C, R, N), np.nan, float, units=_UNITS_T,
                             long_name="time of the maximum velocity of large granule k (arrival time)"),
            "status": var(("chain", "realization"), (C, R), -1, np.int8, units="1",
                          long_name="integration status (0 = success; -1 = not computed)", flag_meanings=" ".join(s.name for s in Status)),
            "energy_error": var(("chain", "realization"), (C, R), np.nan, float, units="1", long_name="relative energy drift (E_end - E_0)/E_0"),
            "n_steps": var(("chain", "realization"), (C, R), -1, np.int64, units="1", long_name="accepted integration steps"),
            "t_end": var(("chain", "realization"), (C, R), np.nan, float, units=_UNITS_T, long_name="time the integration stopped"),
            "mean_velocity": var(("chain", "granule", "time"), (C, N, T), np.nan, float, units=_UNITS_V,
                                 long_name="ensemble-averaged velocity <v_k(t)> of large granule k over successful realisations"),
            "mean_velocity_stderr": var(("chain", "granule", "time"), (C, N, T), np.nan, float, units=_UNITS_V,
                                        long_name="standard error of <v_k(t)>"),
            "n_valid": var(("chain",), (C,), 0, np.int64, units="1", long_name="successful realisations in mean_velocity"),
        },
        coords={
            "chain": ("chain", np.array(spec.chains, dtype=object).astype(str), {"long_name": "decorated chain or its effective chain"}),
            "realization": ("realization", np.arange(R), {"long_name": "realisation index i (radii from SeedSequence(seed, spawn_key=(i,)))"}),
            "granule": ("granule", np.arange(1, N + 1), {"long_name": "large-granule index k (decorated index 2k-1)"}),
            "gap": ("gap", np.arange(1, N), {"long_name": "small-granule index j (between large granules j and j+1)"}),
            "time": ("time", np.asarray(spec.t_grid), {"units": _UNITS_T, "long_name": "time"}),
        },
        attrs=_attrs(spec),
    )
    return ds


def _storage_chunks(spec: EnsembleSpec, shape) -> tuple:
    """Zarr storage chunks: one run-chunk of realisations per storage chunk."""
    R = spec.realizations
    return tuple(min(spec.chunk_size, R) if s == R else s for s in shape)


def _progress_dataset(spec: EnsembleSpec):
    """The ``progress`` group (all zeros) and its encoding."""
    import xarray as xr

    C, N, T, J = len(spec.chains), spec.n_large, spec.t_grid.size, spec.n_chunks
    ds = xr.Dataset(
        {
            "sum_v": (("chunk", "chain", "granule", "time"), np.zeros((J, C, N, T), dtype=np.int64)),
            "sum_v2": (("chunk", "chain", "granule", "time"), np.zeros((J, C, N, T), dtype=np.int64)),
            "n_valid": (("chunk", "chain"), np.zeros((J, C), dtype=np.int64)),
            "done": (("chunk",), np.zeros(J, dtype=np.int8)),
        },
        attrs={"granchain_parameters": json.dumps(spec.describe(), sort_keys=True),
               "about": "bookkeeping of granchain.run_ensemble: fixed-point velocity sums per chunk and done flags"},
    )
    # One storage chunk per run chunk: each chunk's sums and flag are files of their own.
    encoding = {"sum_v": {"chunks": (1, C, N, T)}, "sum_v2": {"chunks": (1, C, N, T)}, "n_valid": {"chunks": (1, C)}, "done": {"chunks": (1,)}}
    return ds, encoding


def _chunk_dataset(spec: EnsembleSpec, res: dict):
    import xarray as xr

    return xr.Dataset(
        {
            "small_radius": (("realization", "gap"), res["small_radius"]),
            "peak_velocity": (("chain", "realization", "granule"), res["peak_velocity"]),
            "peak_time": (("chain", "realization", "granule"), res["peak_time"]),
            "status": (("chain", "realization"), res["status"].astype(np.int8)),
            "energy_error": (("chain", "realization"), res["energy_error"]),
            "n_steps": (("chain", "realization"), res["n_steps"]),
            "t_end": (("chain", "realization"), res["t_end"]),
        }
    )


def _finalize(ds, spec: EnsembleSpec, sum_v, sum_v2, n_valid):
    """mean_velocity and its standard error from the exact fixed-point sums."""
    scale = 2.0**spec.fixed_point_bits
    nv = n_valid.astype(float)[:, None, None]
    s1 = sum_v.astype(float) / scale
    s2 = sum_v2.astype(float) / scale
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = s1 / nv
        var = np.maximum(s2 - s1 * mean, 0.0) / (nv - 1.0)
        stderr = np.sqrt(var / nv)
    ds["mean_velocity"].values = np.where(nv > 0, mean, np.nan)
    ds["mean_velocity_stderr"].values = np.where(nv > 1, stderr, np.nan)
    ds["n_valid"].values = n_valid.astype(np.int64)
    return ds


class _MemorySink:
    """Results kept in memory (no ``out`` path): nothing to resume."""

    def __init__(self, spec: EnsembleSpec):
        self.spec = spec
        self.ds = _empty_dataset(spec, lazy=False)
        shape = (spec.n_chunks, len(spec.chains), spec.n_large, spec.t_grid.size)
        self.sum_v = np.zeros(shape, dtype=np.int64)
        self.sum_v2 = np.zeros(shape, dtype=np.int64)
        self.n_valid = np.zeros((spec.n_chunks, len(spec.chains)), dtype=np.int64)

    def pending(self) -> list[int]:
        return list(range(self.spec.n_chunks))

    def write(self, res: dict) -> None:
        j = res["chunk"]
        sl = self.spec.chunk_slice(j)
        for name, values in _chunk_dataset(self.spec, res).data_vars.items():
            self.ds[name][{"realization": sl}] = values
        self.sum_v[j], self.sum_v2[j], self.n_valid[j] = res["sum_v"], res["sum_v2"], res["n_valid"][:, 0]

    def finalize(self):
        return _finalize(self.ds, self.spec, self.sum_v.sum(0), self.sum_v2.sum(0), self.n_valid.sum(0))


class _ZarrSink:
    """Results in a Zarr store at ``path``; finished chunks survive any interruption."""

    def __init__(self, spec: EnsembleSpec, path, resume: bool):
        import xarray as xr

        self.spec, self.path = spec, os.fspath(path)
        if os.path.exists(self.path):
            if not resume:
                raise ValueError(f"{self.path} already exists: pass resume=True (CLI: --resume) to continue it, or choose another path")
            try:
                stored = xr.open_zarr(self.path, group="progress").attrs.get("granchain_parameters")
            except Exception as exc:  # not a Zarr store, or not ours
                raise ValueError(f"{self.path} exists but is not a granchain ensemble store ({exc}); choose another path") from None
            _check_same_parameters(self.path, stored, spec)
        else:
            _empty_dataset(spec, lazy=True).to_zarr(self.path, mode="w-", compute=False, **_zarr_format())
            progress, encoding = _progress_dataset(spec)
            progress.to_zarr(self.path, group="progress", mode="a", encoding=encoding, **_zarr_format())

    def _progress(self):
        import xarray as xr

        return xr.open_zarr(self.path, group="progress", consolidated=False)

    def pending(self) -> list[int]:
        done = self._progress()["done"].values
        return [j for j in range(self.spec.n_chunks) if not done[j]]

    def write(self, res: dict) -> None:
        import xarray as xr

        j = res["chunk"]
        _chunk_dataset(self.spec, res).to_zarr(self.path, region={"realization": self.spec.chunk_slice(j)}, mode="r+", **_zarr_format())
        region = {"chunk": slice(j, j + 1)}
        sums = xr.Dataset({
            "sum_v": (("chunk", "chain", "granule", "time"), res["sum_v"][None]),
            "sum_v2": (("chunk", "chain", "granule", "time"), res["sum_v2"][None]),
            "n_valid": (("chunk", "chain"), res["n_valid"].T),
        })
        sums.to_zarr(self.path, group="progress", region=region, mode="r+", consolidated=False, **_zarr_format())
        # The flag last: a chunk counts as done only once all its data are on disk.
        xr.Dataset({"done": (("chunk",), np.ones(1, dtype=np.int8))}).to_zarr(
            self.path, group="progress", region=region, mode="r+", consolidated=False, **_zarr_format())

    def finalize(self):
        import xarray as xr

        prog = self._progress().load()
        ds = xr.open_zarr(self.path).load()
        ds = _finalize(ds, self.spec, prog["sum_v"].values.sum(0), prog["sum_v2"].values.sum(0), prog["n_valid"].values.sum(0))
        ds[["mean_velocity", "mean_velocity_stderr", "n_valid"]].to_zarr(
            self.path, region={"chain": slice(None), "granule": slice(None), "time": slice(None)}, mode="r+", **_zarr_format())
        return ds


def _check_same_parameters(path, stored: str | None, spec: EnsembleSpec) -> None:
    if stored is None:
        raise ValueError(f"{path} is not a granchain ensemble store (no granchain_parameters); choose another path")
    old, new = json.loads(stored), json.loads(json.dumps(spec.describe(), sort_keys=True))
    if old != new:
        diff = ", ".join(f"{k}: stored {old.get(k)!r}, asked {new.get(k)!r}" for k in sorted(set(old) | set(new)) if old.get(k) != new.get(k))
        raise ValueError(f"{path} was written with different parameters ({diff}); "
                         "results are never mixed: use another path, or the stored parameters to resume")


def _dask_chunk(spec: EnsembleSpec, j: int) -> dict:
    """Dask task: one chunk with as many Numba threads as the worker has."""
    try:
        from distributed import get_worker

        threads = get_worker().state.nthreads
    except (ImportError, ValueError, AttributeError):
        threads = None
    return compute_chunk(spec, j, threads=threads)


def run_ensemble(n_large: int = 26, distribution=None, realizations: int = 1000, seed: int = 0, chains="both", *,
                 n: float = HERTZ, rtol: float = ENSEMBLE_RTOL, atol: float = ENSEMBLE_ATOL, t_grid=None,
                 chunk_size: int = 500, out=None, resume: bool = True, client=None, progress: bool = True,
                 momentum_conserving: bool = False, exit_margin: float = 3.0, peak_rtol: float = 1e-6, threads: int | None = None):
    """Integrate ``realizations`` random decorated chains (and/or their effective chains).

    Parameters
    ----------
    n_large : int
        N, large granules per chain (2N-1 granules in the decorated chain).
    distribution : granchain.Uniform | granchain.Truncated | scipy.stats frozen, optional
        Small radii (default: the paper's U[0.01, 0.4]).
    realizations, seed : int
        Realisation i draws its radii from SeedSequence(seed, spawn_key=(i,)).
    chains : "decorated", "effective" or "both"
        Which chains to integrate for the same realisations (paired).
    rtol, atol : float
        DP5 tolerances (defaults: :data:`ENSEMBLE_RTOL`, :data:`ENSEMBLE_ATOL`).
    t_grid : array, optional
        Times of the averaged pulse <v_k(t)> (default :func:`default_time_grid`).
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
    threads : int, optional
        Numba threads for local runs (default: all cores).

    Returns
    -------
    xarray.Dataset with dims chain, realization, granule, gap, time (see README).
    """
    as_distribution(distribution)  # warns once if the distribution leaves the effective description's validity
    spec = EnsembleSpec(n_large, distribution, realizations, seed, chains, n, rtol, atol, t_grid, chunk_size,
                        momentum_conserving, exit_margin, peak_rtol)
    sink = _MemorySink(spec) if out is None else _ZarrSink(spec, out, resume)
    pending = sink.pending()
    done_realizations = spec.realizations - sum(spec.chunk_slice(j).stop - spec.chunk_slice(j).start for j in pending)
    from tqdm.auto import tqdm

    bar = tqdm(total=spec.realizations, initial=done_realizations, unit=" realisations", disable=not progress, smoothing=0.05,
               desc=f"N={spec.n_large} {'+'.join(spec.chains)}", dynamic_ncols=True)
    futures = []
    try:
        if client is None:
            for j in pending:
                res = compute_chunk(spec, j, threads=threads)
                sink.write(res)
                bar.update(res["small_radius"].shape[0])
        else:
            from distributed import as_completed

            futures = [client.submit(_dask_chunk, spec, j, pure=False) for j in pending]
            for fut, res in as_completed(futures, with_results=True):
                sink.write(res)
                bar.update(res["small_radius"].shape[0])
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
