"""One chunk of an ensemble: the family's random parameters drawn for its realisations, each chain kind
integrated by its backend into buffers the store schema allocates, and the results in the store's layout.

:func:`compute_chunk` is a top-level function so that Dask can ship it to workers; it returns the
same numbers however the chunk is split into batches (per-realisation results are independent, and
the sums are fixed-point integers), which is what makes an interrupted run resume bitwise.
"""

from __future__ import annotations

import time

import numpy as np

from ..solve.simulation import linear_crossing_time, time_limit
from . import backend as _backend
from . import pulse_window as _window
from .spec import EnsembleSpec
from .store import Variable

#: Seconds of work per progress update within a chunk (local runs with a progress report).
PROGRESS_SECONDS = 2.0


def compute_chunk(spec: EnsembleSpec, j: int, threads: int | None = None, on_progress=None, params=None) -> dict:
    """Results of chunk j: the family's random parameters, per-realisation results and fixed-point sums.
    ``params``: the family's parameters of the chunk's realisations, drawn already
    (``ChainFamily.draw_batch``; drawn here where None).

    A top-level function so that Dask can ship it to workers. ``on_progress(k)`` (local runs) is
    called after every batch of k realisations; the batches are an implementation detail that does
    not change any result (per-realisation results are independent, and the sums are integers).
    A backend that does not run on Numba's threads (a GPU: :func:`granchain.ensembles.backend.runs_on_cpu`)
    gets the whole chunk in one call, its progress reported once per chunk, and Numba's thread count is
    left alone: a GPU fills its cores only with thousands of chains per launch.
    """
    if not _backend.runs_on_cpu(spec.backend):
        res = _compute_chunk(spec, j, params=params)
        if on_progress is not None:
            on_progress(res["realizations"])
        return res
    import numba

    previous = numba.get_num_threads()
    if threads is not None:
        numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
    try:
        if on_progress is None:
            return _compute_chunk(spec, j, params=params)
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
            part = None if params is None else {k: a[start - sl.start:stop - sl.start] for k, a in params.items()}
            parts.append(_compute_chunk(spec, j, slice(start, stop), part))
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


def _compute_chunk(spec: EnsembleSpec, j: int, sl: slice | None = None, params: dict | None = None) -> dict:
    """Chunk j (or its realisations ``sl``): a dict holding every :func:`~granchain.ensembles.schema.chunk_variables`
    entry under its name (per-realisation arrays over the realisations computed, the progress sums without
    their ``chunk`` dim), plus ``chunk`` and ``realizations``. ``params``: the family's parameters of those
    realisations where drawn already."""
    from .store import progress_sum_variables, result_variables

    sl = spec.chunk_slice(j) if sl is None else sl
    idx = np.arange(sl.start, sl.stop)
    family = spec.family
    params = family.draw_batch(spec.seed, idx) if params is None else params
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
