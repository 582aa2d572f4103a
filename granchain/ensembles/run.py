"""``run_ensemble``: many random chains of one family, seeded, parallel, resumable, on disk, on Dask.

An ensemble is a chain family (:mod:`granchain.families`: how realisation i draws its random
parameters from (seed, i) and becomes a chain) integrated by any registered integrator
(:mod:`granchain.solve.integrators`, through ``Integrator.integrate_batch``). Work is split into
chunks of realisations. A chunk is computed locally (Numba threads) or as a task on a Dask
cluster, and its results are written into the store (:mod:`granchain.ensembles.store`) before it counts
as done. An interrupted run started again with the same arguments skips the done chunks;
redone chunks overwrite their own slots, so nothing is counted twice and the result is
bitwise identical to an uninterrupted run.
"""

from __future__ import annotations

import math
import sys
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from .._validate import count
from .._version import RESULTS_VERSION
from ..families import ChainFamily, RandomDecorated
from ..model.chain import HERTZ
from ..solve.defaults import (DAMPED_ATOL, DAMPED_RTOL, ENSEMBLE_ATOL, ENSEMBLE_RTOL, LIGHT_GRANULES, RANDOM_ATOL,
                              RANDOM_RTOL, REFLECTING, SMOOTH, SMOOTH_ATOL, SMOOTH_RTOL, default_integrator)
from ..solve.integrators import DP5, Integrator, RunControls, get_integrator
from ..solve.simulation import linear_crossing_time, time_limit
from . import backend as _backend
from . import pulse_window as _window
from .pulse_window import AUTO, FULL
from .store import MemorySink, Variable, ZarrSink, _check_out, check_same_family

__all__ = ["EnsembleSpec", "EnsembleInterrupted", "run_ensemble", "default_time_grid", "ENSEMBLE_RTOL", "ENSEMBLE_ATOL",
           "SMOOTH_RTOL", "SMOOTH_ATOL", "RANDOM_RTOL", "RANDOM_ATOL", "DAMPED_RTOL", "DAMPED_ATOL", "ensemble_integrator",
           "family_integrator"]


def ensemble_integrator(chain: str = "decorated", *, conservative: bool = True, windowed: bool = True) -> Integrator:
    """The default integrator of :class:`RandomDecorated`'s chain kinds by name: "decorated" chains are
    :data:`~granchain.solve.defaults.LIGHT_GRANULES`, "effective" ones
    :data:`~granchain.solve.defaults.SMOOTH`, and any other name
    :data:`~granchain.solve.defaults.REFLECTING` (:func:`granchain.solve.defaults.default_integrator`:
    ``RKN4.windowed()`` at :data:`ENSEMBLE_RTOL`, :meth:`DP5.windowed` at :data:`SMOOTH_RTOL`, ``DP5`` at
    :data:`RANDOM_RTOL`; ``DP5.relaxed`` at :data:`DAMPED_RTOL` for decorated chains whose contacts are not
    ``conservative``). An ensemble asks its family instead (:meth:`ChainFamily.character`), which
    knows what its chains are like whatever their names. ``windowed``: the trailing window (False:
    ``relaxed``, every granule integrated to the end of the time grid)."""
    character = {"decorated": LIGHT_GRANULES, "effective": SMOOTH}.get(chain, REFLECTING)
    return default_integrator(character, conservative=conservative, windowed=windowed)


def family_integrator(family: ChainFamily, chain: str, *, windowed: bool = True, method: type | None = None) -> Integrator:
    """The integrator the family's ``chain`` kind is integrated with unless one is given: that of its
    character (:meth:`ChainFamily.character`, :func:`granchain.solve.defaults.default_integrator`), for the
    family's contacts; ``method``: another adaptive Runge-Kutta class at the character's settings."""
    return default_integrator(family.character(chain), conservative=family.model.conservative, windowed=windowed,
                              method=method)


def default_time_grid(family=26, dt: float = 0.1) -> np.ndarray:
    """Grid for <v_k(t)> of a family (or of ``RandomDecorated(family)`` for a number N of large
    granules: to 1.1 x the BCA arrival time at granule N, slope 2.35 per granule, + 10)."""
    if not isinstance(family, ChainFamily):
        family = RandomDecorated(family)
    return family.default_time_grid(dt)


#: Seconds of work per progress update within a chunk (local runs with a progress report).
PROGRESS_SECONDS = 2.0


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
    integrator: Integrator | None = None
    t_grid: np.ndarray = field(default=None, repr=False)
    #: Realisations per chunk; None: the backend's ``default_chunk_size`` (500 on the CPU).
    chunk_size: int | None = None
    controls: RunControls = field(default_factory=RunControls)
    lags: np.ndarray = field(default=None, repr=False)
    #: {chain kind: Integrator}; filled from ``integrator`` (one for all kinds) or, without one, from
    #: each kind's :func:`family_integrator` (the default of its character). Given explicitly, it wins over ``integrator``.
    chain_integrators: dict | None = None
    #: "auto": each observed granule's averaged pulse in a window of its own, for the chain kinds whose
    #: integrator runs a trailing window (the defaults; :mod:`granchain.ensembles.pulse_window`); "full":
    #: the whole time grid (default integrators without the trailing window: the wake included).
    pulse_window: str = "auto"
    #: {chain kind: window ends (K,)} once set (``pulse_window.window_ends``, or a store's record); None before.
    pulse_ends: dict | None = field(default=None, repr=False)
    #: What computes the chunks: None (or "cpu"): each integrator's own backend; a backend's name ("cuda",
    #: "numba") or a ``granchain.backends.Backend``: its ``integrate_batch`` (``granchain.ensembles.backend``).
    backend: object = None
    #: Every backend that computed the store's chunks, in the order first used (``run_ensemble(
    #: switch_backend=True)``; the record's ``"backend"`` is the first); None: ``backend`` alone.
    backends_used: tuple | None = None

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
        if self.pulse_window not in (AUTO, FULL):
            raise ValueError(f"pulse_window must be {AUTO!r} (each granule's averaged pulse in a window of its own, the "
                             f"trailing window on: cost linear in N) or {FULL!r} (the whole time grid, the wake behind "
                             f"the pulse included), got {self.pulse_window!r}")
        # One integrator for every chain kind when one is given; else each kind's default.
        if self.chain_integrators is not None:
            # A dict may name kinds the family has but this run does not compute (one dict for runs of
            # "decorated", "effective" or both); a kind the family does not have is a typo, and a kind
            # the run computes needs its integrator.
            if not isinstance(self.chain_integrators, dict):
                raise ValueError(f"chain_integrators must be a dict {{chain kind: integrator}}, got {self.chain_integrators!r}")
            unknown = sorted(set(self.chain_integrators) - set(known))
            if unknown:
                raise ValueError(f"the integrator dict names chain kinds {unknown} that the family {type(self.family).__name__} does not "
                                 f"have; its kinds are {list(known)}")
            missing = [c for c in self.chains if c not in self.chain_integrators]
            if missing:
                raise ValueError(f"the integrator dict has no integrator for the chain kinds {missing} this run computes "
                                 f"(it names {sorted(self.chain_integrators)}); add them, or pass one integrator for all")
            per_chain = {c: get_integrator(self.chain_integrators[c]) for c in self.chains}
        else:
            given = self.integrator
            windowed = self.pulse_window == AUTO
            per_chain = {c: (get_integrator(given) if given is not None else family_integrator(self.family, c, windowed=windowed))
                         for c in self.chains}
            # A backend that runs fewer methods (the GPU: RKN4 alone) gets the light-granule chains' default,
            # RKN4, for the kinds whose default it has no kernel for: valid for every elastic chain.
            methods = getattr(_backend.resolve(_backend.checked(self.backend)), "methods", None)
            if given is None and methods is not None:
                fallback = default_integrator(LIGHT_GRANULES, conservative=self.family.model.conservative, windowed=windowed)
                per_chain = {c: (i if i.name in methods else fallback) for c, i in per_chain.items()}
        law = self.family.contact_law
        for c, integ in per_chain.items():  # refused here, before a store exists
            if integ.needs_conservative_forces and not law.conservative:
                raise ValueError(f"{integ.name} integrates x'' = f(x) and needs forces that depend on positions only; the "
                                 f"family's contact law {law!r} depends on velocities: use DP5 (the default for it) or DOP853")
        set_("integrator", per_chain[self.chains[0]])
        set_("chain_integrators", per_chain)
        grid = self.family.default_time_grid() if self.t_grid is None else np.asarray(self.t_grid, dtype=float).reshape(-1)
        if grid.size == 0 or not np.all(np.isfinite(grid)) or grid[0] < 0 or np.any(np.diff(grid) <= 0):
            raise ValueError("t_grid must be a non-empty, finite, increasing array of times >= 0")
        grid = np.array(grid)
        grid.setflags(write=False)
        set_("t_grid", grid)
        set_("pulse_ends", self._checked_pulse_ends())
        set_("backend", _backend.checked(self.backend))
        if self.backends_used is not None:
            used = tuple(self.backends_used) if isinstance(self.backends_used, (tuple, list)) else ()
            if not used or not all(isinstance(u, str) and u for u in used):
                raise ValueError(f"backends_used must list the names of the backends that computed the store, in the "
                                 f"order first used (e.g. ('cpu', 'cuda')), got {self.backends_used!r}")
            set_("backends_used", used)
        if self.chunk_size is None:
            set_("chunk_size", _backend.default_chunk_size(self.backend))
        set_("chunk_size", count("chunk_size", self.chunk_size, minimum=1))
        if not isinstance(self.controls, RunControls):
            raise ValueError(f"controls must be a granchain.RunControls, got {self.controls!r}")
        if self.lags is not None:  # the aligned pulse (granchain.backends.kernels.aligned); None: not accumulated
            lags = np.array(np.asarray(self.lags, dtype=float).reshape(-1))
            if lags.size == 0 or not np.all(np.isfinite(lags)) or np.any(np.diff(lags) <= 0):
                raise ValueError("lags must be a non-empty, finite, increasing array of times relative to each "
                                 "realisation's peak (e.g. numpy.arange(-10, 10.05, 0.1)), or None")
            lags.setflags(write=False)
            set_("lags", lags)

    def _checked_pulse_ends(self) -> dict | None:
        """The averaged-pulse windows as given (a dict per chain kind that gets one), or None where the run has
        none (``pulse_window="full"``, or no integrator with a trailing window)."""
        kinds = _window.applies(self) if self.pulse_window == AUTO else {}
        if not kinds or self.pulse_ends is None:
            return None
        if set(self.pulse_ends) != set(kinds):
            raise ValueError(f"pulse_ends must give the windows of the chain kinds {sorted(kinds)}, got {sorted(self.pulse_ends)}")
        K = self.family.n_observed
        ends = {}
        for kind, e in self.pulse_ends.items():
            e = np.array([np.inf if x is None else x for x in np.ravel(np.asarray(e, dtype=object))], dtype=float)
            if np.any(np.isnan(e)) or e.size != K:
                raise ValueError(f"the averaged-pulse window ends of the {kind} chains must be {K} times (inf: none), got {e!r}")
            e.setflags(write=False)
            ends[kind] = e
        return ends

    @property
    def has_pulse_windows(self) -> bool:
        """True when some chain kind of this run gets averaged-pulse windows (set or still to set)."""
        return self.pulse_window == AUTO and bool(_window.applies(self))

    def _other_integrators(self) -> dict:
        """``{"chain_integrators": {kind: record}}`` when the chain kinds are not all integrated by
        ``integrator`` (the default since granchain 0.3), else nothing (the record of earlier stores)."""
        records = {c: integ.describe() for c, integ in self.chain_integrators.items()}
        if all(r == self.integrator.describe() for r in records.values()):
            return {}
        return {"chain_integrators": records}

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
            **self._other_integrators(),
            "t_grid": {"start": float(self.t_grid[0]), "stop": float(self.t_grid[-1]), "size": int(self.t_grid.size),
                       "checksum": float(np.sum(self.t_grid * np.arange(1, self.t_grid.size + 1)))},
            "chunk_size": self.chunk_size,
            "exit_margin": self.controls.exit_margin,
            "peak_rtol": self.controls.peak_rtol,
            "max_steps": self.controls.max_steps,
            "results_version": RESULTS_VERSION,  # not the package version: an upgrade that computes the same numbers resumes
        }
        used = list(self.backends_used or (_backend.name_of(self.backend),))
        if used[0] != _backend.CPU:  # only then: a store of the CPU default keeps the record of earlier versions
            record["backend"] = used[0]
        if len(used) > 1:  # the run's history (not compared on resume, not in the checksums' key)
            record["backends_used"] = used
        if self.has_pulse_windows:  # only then: a run without windows keeps the record of earlier versions
            record["pulse_window"] = _window.record(self)
        if self.lags is not None:  # only then: stores without the aligned pulse keep their 0.1/0.2 record
            record["lags"] = {"start": float(self.lags[0]), "stop": float(self.lags[-1]), "size": int(self.lags.size),
                              "checksum": float(np.sum(self.lags * np.arange(1, self.lags.size + 1)))}
        return record


# --------------------------------------------------------------------------- compute
def compute_chunk(spec: EnsembleSpec, j: int, threads: int | None = None, on_progress=None) -> dict:
    """Results of chunk j: the family's random parameters, per-realisation results and fixed-point sums.

    A top-level function so that Dask can ship it to workers. ``on_progress(k)`` (local runs) is
    called after every batch of k realisations; the batches are an implementation detail that does
    not change any result (per-realisation results are independent, and the sums are integers).
    A backend that does not run on Numba's threads (a GPU: :func:`granchain.ensembles.backend.runs_on_cpu`)
    gets the whole chunk in one call, its progress reported once per chunk, and Numba's thread count is
    left alone: a GPU fills its cores only with thousands of chains per launch.
    """
    if not _backend.runs_on_cpu(spec.backend):
        res = _compute_chunk(spec, j)
        if on_progress is not None:
            on_progress(res["realizations"])
        return res
    import numba

    previous = numba.get_num_threads()
    if threads is not None:
        numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
    try:
        if on_progress is None:
            return _compute_chunk(spec, j)
        # Batches for progress within a chunk: a small first batch measures the rate, then each batch
        # is about PROGRESS_SECONDS of work. Small batches cost speed (a parallel-kernel launch and
        # its set-up per batch, and load imbalance between threads over few realisations of very
        # different cost): batches of 16 halved the effective-chain rate (bench_families.py).
        sl = spec.chunk_slice(j)
        step = max(16, 8 * numba.get_num_threads())
        parts = []
        start = sl.start
        while start < sl.stop:
            stop = min(start + step, sl.stop)
            t0 = time.perf_counter()
            parts.append(_compute_chunk(spec, j, slice(start, stop)))
            elapsed = time.perf_counter() - t0
            on_progress(parts[-1]["realizations"])
            step = max(step, int((stop - start) * PROGRESS_SECONDS / max(elapsed, 1e-3)))
            start = stop
        return _merge(parts, spec)
    finally:
        numba.set_num_threads(previous)


def _merge(parts: list, spec: EnsembleSpec) -> dict:
    """One chunk's result from the results of consecutive batches of its realisations: per-realisation
    arrays are joined along their ``realization`` axis, the fixed-point sums added (both read from the
    store schema). An array the schema does not name is an error, never a silent wrong join."""
    from .store import per_realisation_variables, progress_sums

    if len(parts) == 1:
        return parts[0]
    axis = {v.name: v.dims.index("realization") for v in per_realisation_variables(spec.family)}
    sums = progress_sums(spec)
    out = {"chunk": parts[0]["chunk"], "realizations": sum(p["realizations"] for p in parts)}
    for key in parts[0]:
        if key in out:
            continue
        if key in sums:  # exact integer sums
            out[key] = sum(p[key] for p in parts)
        elif key in axis:
            out[key] = np.concatenate([p[key] for p in parts], axis=axis[key])
        else:
            raise KeyError(f"chunk result {key!r} is neither a store variable nor a sum: add it to the schema (granchain/ensembles/schema.py)")
    return out


# The compute buffers come from the store schema (granchain.ensembles.schema): a chunk's result holds every
# result and progress sum of the schema under its name, allocated with the Variable's dtype and fill value
# and its dims' sizes, so a variable added to the schema gets its buffer, reaches the integrator in
# ``out`` (``Integrator.integrate_batch``) and is written to the store. Where the kernels' conventions
# differ from the store's (an array no store holds, sums grid axis first), they are converted here, in
# one place:

#: What the kernels compute that no store holds: the wall force summed on the time grid.
UNSTORED = (Variable("sum_wall", ("chunk", "chain", "time"), "int64", 0, "1",
                     "sum over the chunk's successful realisations of round(F_wall * 2^bits)"),)

#: Grid dimensions: the kernels add a realisation's samples (grid, granule) row by row, grid axis first.
_GRID_DIMS = ("time", "lag")


def _kernel_dims(v: Variable) -> tuple:
    """The dims in which the kernels fill one chunk's share of a progress sum: chain first (one chain kind
    per call), the grid axis before the granule, and a count per chain (n_valid) as a one-element array."""
    rest = [d for d in v.dims if d not in ("chunk", "chain")]
    rest = [d for d in rest if d in _GRID_DIMS] + [d for d in rest if d not in _GRID_DIMS]
    return ("chain", *(rest or ["one"]))


def _store_layout(buffer: np.ndarray, v: Variable) -> np.ndarray:
    """A progress sum from the kernels' layout (:func:`_kernel_dims`) to the schema's dims without ``chunk``."""
    have = [d for d in _kernel_dims(v) if d != "one"]
    buffer = buffer.reshape(buffer.shape[:len(have)])  # drops the one-element axis of a count
    return np.ascontiguousarray(buffer.transpose([have.index(d) for d in v.dims if d != "chunk"]))


def chunk_buffers(spec: EnsembleSpec, realizations: int) -> dict:
    """Arrays at their not-computed values for ``realizations`` realisations of every chain, by kernel name: each
    result of :func:`~granchain.ensembles.schema.result_variables` (dims ``chain``, ``realization``, ...) and each
    progress sum (:func:`~granchain.ensembles.schema.progress_sum_variables`, in :func:`_kernel_dims`), plus the
    kernel-only arrays :data:`UNSTORED`. The kernels add into the sums, which start at their fill value, 0."""
    from .store import progress_sum_variables, result_variables, sizes

    dims = {**sizes(spec), "realization": realizations, "one": 1}

    def full(v: Variable, names, extra=()):
        return np.full(tuple(dims[d] for d in names) + extra, v.fill, dtype=v.dtype)

    out = {v.name: full(v, v.dims) for v in result_variables(spec.family)}
    out.update({v.name: full(v, _kernel_dims(v)) for v in progress_sum_variables(spec) + UNSTORED})
    return out


def _compute_chunk(spec: EnsembleSpec, j: int, sl: slice | None = None) -> dict:
    """Chunk j (or its realisations ``sl``): a dict holding every :func:`~granchain.ensembles.schema.chunk_variables`
    entry under its name (per-realisation arrays over the realisations computed, the progress sums without
    their ``chunk`` dim), plus ``chunk`` and ``realizations``."""
    from .store import progress_sum_variables, result_variables

    sl = spec.chunk_slice(j) if sl is None else sl
    idx = np.arange(sl.start, sl.stop)
    family = spec.family
    params = family.draw_batch(spec.seed, idx)
    buffers = chunk_buffers(spec, idx.size)
    scale = float(2.0**spec.fixed_point_bits)
    for ci, name in enumerate(spec.chains):
        batch = family.build(params, name)
        masses, stiffness, v0 = batch.masses, batch.stiffness, batch.initial_velocity
        t_max = max(time_limit(masses.shape[1], float(v0.min()), batch.n), float(spec.t_grid[-1]))
        if not family.model.ends_at_exit:
            # No exit to stop at: each row runs to its own time bounding the pulse's crossing, as
            # simulate's default_t_max on the grid, so that a row does not depend on its chunk.
            rows = [time_limit(masses.shape[1], float(v), batch.n) for v in v0]
            crossing = linear_crossing_time(masses, stiffness, batch.n, family.static_force)
            t_max = np.maximum(np.minimum(rows, 2.0 * crossing + 20.0), float(spec.t_grid[-1]))
        _run_batch(
            spec, name, batch, {**{k: a[ci] for k, a in buffers.items()}, "lags": spec.lags},
            t_grid=spec.t_grid, t_max=t_max, controls=spec.controls, scale=scale, model=family.model,
            pulse_end=_window.keep_until(spec.pulse_ends[name]) if spec.pulse_ends and name in spec.pulse_ends else None,
        )
    out = {"chunk": j, "realizations": idx.size, **params}
    stored = {v.name for v in result_variables(family)}
    out.update({name: a for name, a in buffers.items() if name in stored})
    for v in progress_sum_variables(spec):
        out[v.name] = _store_layout(buffers[v.name], v)
    return out


def _run_batch(spec: EnsembleSpec, kind: str, batch, buffers: dict, **kwargs) -> None:
    """``Backend.run_batch`` of the chain kind ``kind``'s integrator on the chosen backend, or (the CPU
    default) on the integrator's own (the kinds' may differ: DOP853 runs on SciPy)."""
    integrator = spec.chain_integrators[kind]
    backend = _backend.resolve(spec.backend)
    if backend is None:
        from ..backends import get_backend

        backend = get_backend(integrator.backend)
    backend.run_batch(integrator, batch, buffers, **kwargs)


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


def _integrator_of(integrator, rtol, atol, windowed: bool = True) -> Integrator | None:
    """The spec's ``integrator``: None (each chain kind's default), one integrator, or a dict
    {chain kind: integrator} (returned as it is: EnsembleSpec's ``chain_integrators``); ``rtol``/``atol``
    alone set DP5's, with the trailing window if ``windowed`` (else the relaxed zone only)."""
    if isinstance(integrator, dict) and rtol is None and atol is None:
        return integrator
    if integrator is None:
        if rtol is None and atol is None:
            return None  # each chain kind's default (family_integrator)
        # the one not given: DP5's goal tolerance (1e-6 or 1e-9)
        return DP5.windowed(rtol, atol) if windowed else DP5.relaxed(rtol, atol)
    if rtol is not None or atol is not None:
        raise ValueError("rtol/atol set the default DP5; with integrator= set them on the integrator, e.g. DP5(rtol=1e-7)")
    return get_integrator(integrator)


def stored_integrators(out):
    """The integrators the store ``out`` was started with, as ``run_ensemble``'s ``integrator`` (one, or a
    dict {chain kind: integrator}): a store is continued as it was started, so one written with earlier
    defaults (granchain 0.4's tolerances were looser) resumes without naming them. None where there is no
    store or its record names no integrator this version can rebuild: the defaults are then asked for,
    and the store's parameter check says what differs."""
    from ..solve.integrators import integrator_from_record

    rec = _window.stored_record(out)
    if rec is None:
        return None
    try:
        per_chain = rec.get("chain_integrators")
        if per_chain:
            return {kind: integrator_from_record(r) for kind, r in per_chain.items()}
        return integrator_from_record(rec["integrator"])
    except (KeyError, TypeError, ValueError):
        return None


def run_ensemble(family=26, distribution=None, realizations: int = 1000, seed: int = 0, chains="both", *,
                 integrator=None, n: float = HERTZ, rtol: float | None = None, atol: float | None = None, t_grid=None,
                 chunk_size: int | None = None, out=None, resume: bool = True, client=None, progress: bool = True,
                 momentum_conserving: bool = False, exit_margin: float = 3.0, peak_rtol: float = 1e-6,
                 max_steps: int = 20_000_000, threads: int | None = None, n_large: int | None = None, lags=None,
                 pulse_window: str | None = None, backend=None, switch_backend: bool = False):
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
        Any registered integrator, used for every chain kind, or a dict {chain kind: integrator}
        naming one for each of ``chains`` (it may also name other kinds of the family, which this
        run does not use, so one dict serves runs of either chain; a kind the family does not have,
        or a computed kind without an integrator, is refused). Default: when ``out`` is an existing
        store, the integrators it was started with; else the default of each kind's character, which the
        family names (:meth:`ChainFamily.character`, :func:`family_integrator`: ``RKN4.windowed`` at
        :data:`ENSEMBLE_RTOL` for decorated chains, whose light granules set the step, ``DP5.windowed`` at
        :data:`SMOOTH_RTOL` for effective ones, ``relaxed`` instead of ``windowed`` with
        ``pulse_window="full"``; ``DP5`` at :data:`RANDOM_RTOL` for the others), or
        ``DP5.windowed(rtol, atol)`` (``DP5.relaxed`` with ``pulse_window="full"``) for all if
        ``rtol``/``atol`` are given (the other one then 1e-6 or 1e-9). ``granchain.DP5(1e-6, 1e-9)`` is
        the exact (untruncated) integration of earlier versions. DOP853 runs realisation by
        realisation in Python (slow).
    t_grid : array, optional
        Times of the averaged pulse <v_k(t)> (default: the family's ``default_time_grid()``).
    chunk_size : int, optional
        Realisations per chunk: the unit of work, of saving and of resuming. Default: when ``out`` is an
        existing store, the chunk size it was started with; else the backend's ``default_chunk_size``
        (500 on the CPU; a GPU asks for about 10,000, the chains it needs per launch to fill its cores).
    out : path, optional
        Zarr store to write (and resume). Without it the results stay in memory.
    resume : bool
        True (default, as in the CLI): continue an existing store written with the same parameters,
        after verifying every finished chunk (damaged chunks are recomputed), and extend it if more
        realisations are asked for than it holds; a store with other parameters is refused.
        False: an existing store is an error.
    client : dask.distributed.Client, optional
        Run the chunks as tasks on this cluster (results are identical).
    progress : bool
        Progress on stderr: a bar with realisations/s and ETA on a terminal or in a notebook,
        one line per chunk otherwise (e.g. redirected to a log file).
    exit_margin, peak_rtol, max_steps
        Run controls, as in :func:`granchain.simulate` (:class:`granchain.RunControls`).
    threads : int, optional
        Numba threads for local runs on the CPU, 1 .. the cores Numba can use (default: all cores).
    backend : str or granchain.backends.Backend, optional
        What computes the chunks. None or "cpu" (default): each integrator on its own backend (the Numba
        kernels, SciPy for DOP853). "cuda": an NVIDIA GPU (``pip install granchain[cuda]``; refused with
        ``granchain.backends.BackendUnavailable`` where numba-cuda or a GPU is missing), one kernel launch
        per chunk; "numba", or a ``Backend`` instance: that backend's ``integrate_batch`` for every chain
        kind. Results of two backends agree per realisation within the accuracy contract, not bitwise, so
        the store records a backend other than "cpu" (``"backend"`` in its parameter record; ``granchain
        info`` shows it) and is continued on the backend that computed it.
    switch_backend : bool
        Continue (or extend) a store computed on another backend than ``backend``: its chunks then come
        from two backends (per realisation within the accuracy contract, not bitwise). The record keeps
        ``"backend"``, the one the store was started with, and adds ``"backends_used"``, every backend
        that computed chunks in the order first used. False (default): such a run is refused, naming both.
    lags : array, optional
        Also accumulate the *aligned* pulse <v_k(t_k^peak + tau)> on these lags tau (times relative
        to each realisation's own peak time at k; variables ``aligned_velocity``,
        ``aligned_velocity_stderr`` with dim ``lag``; see :mod:`granchain.paper.dephasing`).
        Default None: not accumulated (the store is then exactly as without this option).
    pulse_window : {"auto", "full"}, optional
        Default: "auto", or, when ``out`` is an existing store, the setting it was started with ("full"
        for a store written before granchain 0.5). "auto": the averaged pulse <v_k(t)> of each observed granule k is recorded in a window
        of its own, [0, t_end[k]], that holds the pulse of every realisation (set from the arrival times
        of realisations 0..63: :mod:`granchain.ensembles.pulse_window`; the store's ``pulse_window_end``;
        NaN after it). Every granule stays integrated through its window, so the recorded <v_k(t)> is
        exact there, and the default integrators run the trailing window (``windowed``): a realisation
        costs linearly in the chain's length instead of quadratically. "full": the whole time grid for
        every granule, the wake long after the pulse included (default integrators ``relaxed``, every
        granule integrated to the end: the defaults before granchain 0.5). With an integrator given
        that has no trailing window the two are the same.

    Ctrl-C raises :class:`EnsembleInterrupted` (a KeyboardInterrupt) whose message says where the
    finished chunks are saved.

    Returns
    -------
    xarray.Dataset with dims chain, realization, granule (the family's observed granules),
    time and the family's parameter dims (see README).
    """
    if n_large is not None:
        family = n_large
    fam = _family_of(family, distribution, n, momentum_conserving)
    if out is not None:
        out = _check_out(out, create=False)  # a path that can be a store, or what to change (nothing made yet)
    continuing = out is not None and resume is True
    chosen = _backend.checked(backend)
    _backend.resolve(chosen)  # a GPU backend where none is usable is refused here, before any store is touched
    if not isinstance(switch_backend, (bool, np.bool_)):
        raise ValueError(f"switch_backend must be True or False, got {switch_backend!r}")
    used = None
    if continuing:  # other contact settings are named before the store's integrators (for its own law) are taken
        check_same_family(out, fam)
        record = _window.stored_record(out)
        if record is not None:  # a store is continued on its backend (or with switch_backend) and in its chunks
            used = _backend.check_same_backend(out, record, _backend.name_of(chosen), bool(switch_backend))
            if chunk_size is None and isinstance(record.get("chunk_size"), int):
                chunk_size = record["chunk_size"]
    if pulse_window is None:  # a store is continued as it was started; a new run gets the windows
        pulse_window = _window.stored_setting(out) if continuing else AUTO
    if integrator is None and rtol is None and atol is None and continuing:
        integrator = stored_integrators(out)  # None where there is no store: each kind's default
    integ = _integrator_of(integrator, rtol, atol, windowed=pulse_window == AUTO)
    per_chain = integ if isinstance(integ, dict) else None
    spec = EnsembleSpec(fam, realizations, seed, chains, None if per_chain else integ, t_grid, chunk_size,
                        RunControls(exit_margin, max_steps, peak_rtol), lags, chain_integrators=per_chain,
                        pulse_window=pulse_window, backend=chosen, backends_used=used)
    threads = _threads(threads)
    if not isinstance(resume, (bool, np.bool_)):
        raise ValueError(f"resume must be True or False, got {resume!r}")
    prepared, helper = _compile_ahead(spec, client)
    try:
        return _run(spec, out, resume, client, threads, _Progress(spec, progress))
    finally:
        if prepared is not None:
            prepared.release(helper)


def _run(spec: EnsembleSpec, out, resume: bool, client, threads, report) -> xarray.Dataset:
    """:func:`run_ensemble` once its arguments are checked: the averaged-pulse windows, the chunks, the
    store."""
    if spec.has_pulse_windows and spec.pulse_ends is None:
        spec = _with_pulse_windows(spec, out if resume else None, threads, report)
    sink = MemorySink(spec) if out is None else ZarrSink(spec, out, bool(resume), log=report.message)
    futures = []
    try:
        pending = sink.pending()
        report.start(spec.realizations - sum(_size(spec.chunk_slice(j)) for j in pending), len(pending))
        if client is None:
            for j in pending:
                # Batches within a chunk only where they are shown (the bar); otherwise one kernel call per chunk.
                within = report.update if report.mode == "bar" else None
                res = compute_chunk(spec, j, threads=threads, on_progress=within)
                sink.write(res)
                report.chunk_done(j, res["realizations"], counted=within is not None)
        else:
            from distributed import as_completed

            futures = [client.submit(_dask_chunk, spec, j, pure=False) for j in pending]
            for fut, res in as_completed(futures, with_results=True):
                sink.write(res)
                report.chunk_done(res["chunk"], res["realizations"], counted=False)
                fut.release()
        report.close()
        return sink.finalize()
    except KeyboardInterrupt:
        if futures:
            client.cancel(futures)
        report.close()
        where = (f"finished chunks are saved in {out}; call run_ensemble again with the same arguments to continue"
                 if out is not None else "no out= store was given, so nothing was saved")
        raise EnsembleInterrupted(f"interrupted: {where}") from None
    finally:
        if out is not None:
            sink.close()


def _compile_ahead(spec: EnsembleSpec, client):
    """(backend, handle): the first integrator's backend asked to prepare the run's integrators in the
    order it uses them (``Backend.prepare``: the Numba backend compiles DP5 in a helper process while this
    one compiles RKN4, the paper's defaults); (None, None) with a cluster, whose workers compile for
    themselves, for real contacts (other entry points) and on a chosen backend."""
    if client is not None or not spec.family.elastic or spec.backend is not None:
        return None, None
    from ..backends import get_backend

    integrators = [spec.chain_integrators[c] for c in spec.chains]
    backend = get_backend(integrators[0].backend)
    return backend, backend.prepare(integrators)


def _with_pulse_windows(spec: EnsembleSpec, out, threads, report) -> EnsembleSpec:
    """``spec`` with its averaged-pulse windows set: those of the store ``out`` when it was started with
    windows (a store is continued with its own), else from the pilot realisations
    (:func:`granchain.ensembles.pulse_window.window_ends`)."""
    import dataclasses

    record = _window.stored_record(out) if out is not None else None
    ends = _window.ends_of_record(record.get("pulse_window")) if record is not None else None
    if ends is None:
        report.message(f"setting each granule's averaged-pulse window from the arrival times of realisations "
                       f"0..{_window.PILOT_REALIZATIONS - 1}")
        ends = _window.window_ends(spec, lambda pilot: compute_chunk(pilot, 0, threads=threads))
    return dataclasses.replace(spec, pulse_ends=ends)


class EnsembleInterrupted(KeyboardInterrupt):
    """Ctrl-C during :func:`run_ensemble` (the message says where the finished chunks are)."""


def _size(sl: slice) -> int:
    return sl.stop - sl.start


def _threads(threads):
    if threads is None:
        return None
    import numba

    cores = numba.config.NUMBA_NUM_THREADS
    k = count("threads", threads, minimum=1)
    if k > cores:
        raise ValueError(f"threads = {k} is more than the {cores} threads Numba can use here; "
                         f"pass 1..{cores} (CLI: --threads), or leave it out for all cores")
    return k


class _Progress:
    """Progress on stderr: a bar on a terminal or in a notebook, one line per chunk otherwise, nothing
    when ``enabled`` is False. Local runs update the bar after every batch of a chunk's realisations."""

    def __init__(self, spec, enabled: bool):
        self.spec, self.enabled = spec, bool(enabled)
        self.mode = "off"
        if self.enabled:
            interactive = "ipykernel" in sys.modules or bool(getattr(sys.stderr, "isatty", lambda: False)())
            self.mode = "bar" if interactive else "lines"
        self.bar = None

    def message(self, text: str) -> None:
        if self.enabled:
            print(text, file=sys.stderr, flush=True)

    def start(self, done: int, chunks: int) -> None:
        import time

        self.t0, self.done0, self.done, self.chunks = time.monotonic(), done, done, chunks
        if self.mode == "bar":
            from tqdm.auto import tqdm

            self.bar = tqdm(total=self.spec.realizations, initial=done, unit=" realisations", smoothing=0.05,
                            desc=f"{self.spec.family.kind} {'+'.join(self.spec.chains)}", dynamic_ncols=True,
                            mininterval=0.5)
        elif self.mode == "lines" and done:
            self.message(f"resuming: {done} of {self.spec.realizations} realisations already done, {chunks} chunks to go")

    def update(self, k: int) -> None:
        self.done += k
        if self.bar is not None:
            self.bar.update(k)

    def chunk_done(self, j: int, k: int, counted: bool) -> None:
        import time

        if not counted:
            self.update(k)
        if self.mode == "lines":
            rate = (self.done - self.done0) / max(time.monotonic() - self.t0, 1e-9)
            eta = (self.spec.realizations - self.done) / rate if rate > 0 else float("inf")
            self.message(f"chunk {j + 1}/{self.spec.n_chunks} done: {self.done}/{self.spec.realizations} realisations, "
                         f"{rate:.1f}/s, ETA {eta:.0f} s")

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None
