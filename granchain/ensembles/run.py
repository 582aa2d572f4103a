"""``run_ensemble``: many random chains of one family, seeded, parallel, resumable, on disk, on Dask.

An ensemble is a chain family (:mod:`granchain.families`: how realisation i draws its random
parameters from (seed, i) and becomes a chain) integrated by any registered integrator
(:mod:`granchain.solve.integrators`, through ``Integrator.integrate_batch``). Work is split into
chunks of realisations. A chunk is computed locally (Numba threads) or as a task on a Dask
cluster (:mod:`granchain.ensembles.chunks`), and its results are written into the store
(:mod:`granchain.ensembles.store`) before it counts as done. What determines the result is one value,
:class:`~granchain.ensembles.spec.EnsembleSpec`. An interrupted run started again with the same arguments skips the done chunks;
redone chunks overwrite their own slots, so nothing is counted twice and the result is
bitwise identical to an uninterrupted run.
"""

from __future__ import annotations

import sys
import time
import warnings

import numpy as np

from .._validate import count
from ..families import ChainFamily, RandomDecorated
from ..model.chain import HERTZ
from ..solve.defaults import (DAMPED_ATOL, DAMPED_RTOL, ENSEMBLE_ATOL, ENSEMBLE_RTOL, RANDOM_ATOL, RANDOM_RTOL,
                              SMOOTH_ATOL, SMOOTH_RTOL)
from ..solve.integrators import DP5, Integrator, RunControls, get_integrator
from . import backend as _backend
from . import pulse_window as _window
from .chunks import _dask_chunk, chunk_buffers, compute_chunk  # noqa: F401 (chunk_buffers: kept importable from here)
from .pulse_window import AUTO
from .spec import EnsembleSpec, default_time_grid, ensemble_integrator, family_integrator
from .store import MemorySink, ZarrSink, _check_out, check_same_family

__all__ = ["EnsembleSpec", "EnsembleInterrupted", "run_ensemble", "default_time_grid", "ENSEMBLE_RTOL", "ENSEMBLE_ATOL",
           "SMOOTH_RTOL", "SMOOTH_ATOL", "RANDOM_RTOL", "RANDOM_ATOL", "DAMPED_RTOL", "DAMPED_ATOL", "ensemble_integrator",
           "family_integrator"]


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
        (500 on the CPU; 30,000 on the GPU, the paper's ensemble in one launch: a launch needs thousands of
        chains to fill the GPU and lasts until its slowest chain ends).
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
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(1, thread_name_prefix="granchain-chunks") as helper:
        return _run_with(spec, out, resume, client, threads, report, helper)


def _run_with(spec: EnsembleSpec, out, resume: bool, client, threads, report, helper) -> xarray.Dataset:
    """:func:`_run` with its helper thread (``_run_local``'s)."""
    ahead = None
    if spec.has_pulse_windows and spec.pulse_ends is None:
        spec, ahead = _with_pulse_windows(spec, out if resume else None, threads, report,
                                          helper if client is None else None)
    sink = MemorySink(spec) if out is None else ZarrSink(spec, out, bool(resume), log=report.message)
    futures = []
    try:
        pending = sink.pending()
        report.start(spec.realizations - sum(_size(spec.chunk_slice(j)) for j in pending), len(pending))
        if client is None:
            _run_local(spec, sink, pending, threads, report, helper, ahead)
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
        helper.shutdown(wait=True)  # the chunk being written (an interruption's too) is in before the store closes
        if out is not None:
            sink.close()


def _run_local(spec: EnsembleSpec, sink, pending: list, threads, report, helper, ahead=None) -> None:
    """The chunks ``pending`` in order on this machine, with the work around the kernels done beside them.

    The ``helper`` thread draws the next chunk's random parameters and writes the last finished chunk into
    the sink while this thread runs the kernels, which release the GIL (``kernels.jit.JIT_PARALLEL``).
    That work is serial: done between the kernels it left every core but one idle for its duration,
    which was 2.5 % of an effective-chain ensemble on one thread (the draws; 1.6 % more with a store, its
    chunks' writes), and so bounded 16 threads below 12x one thread (10x with a store; Amdahl's law).
    Creating and closing a store stay serial. The results are those of the
    plain order (realisation i's parameters depend on (seed, i) alone, and each chunk is written whole,
    in order). A chunk counts as done once written; an interruption waits for the chunk being written,
    so finished work is never lost (``_run`` shuts the helper down before it closes the store).
    ``ahead``: (chunk, the future of its draws) begun during the pilot (:func:`_with_pulse_windows`), used if
    that chunk comes first."""
    # Batches within a chunk only where they are shown (the bar); otherwise one kernel call per chunk.
    within = report.update if report.mode == "bar" else None
    drawn = None
    if pending:
        drawn = ahead[1] if ahead is not None and ahead[0] == pending[0] else helper.submit(_draw, spec, pending[0])
    writing = None  # (the write's future, chunk, realisations)
    for k, j in enumerate(pending):
        params = drawn.result()
        drawn = helper.submit(_draw, spec, pending[k + 1]) if k + 1 < len(pending) else None
        res = compute_chunk(spec, j, threads=threads, on_progress=within, params=params)
        if writing is not None:
            _written(writing, report, within)
        writing = (helper.submit(sink.write, res), j, res["realizations"])
    if writing is not None:
        _written(writing, report, within)


#: Realisations drawn between two yields of the GIL by the helper thread (:func:`_draw`).
DRAW_GROUP = 16


def _draw(spec: EnsembleSpec, j: int) -> dict:
    """The family's random parameters of chunk j (``ChainFamily.draw_batch``), drawn in groups of
    :data:`DRAW_GROUP` realisations with the GIL let go between them. The draws are Python (~16 us a
    realisation: a generator per realisation, so that realisation i depends on (seed, i) alone) and run on
    the helper thread beside the main thread's work; without the yields the main thread, wanting the GIL
    back (from a kernel, or between its own NumPy calls), waited up to the interpreter's switch interval
    (5 ms) each time. The parameters are those of one ``draw_batch`` call, row for row."""
    sl = spec.chunk_slice(j)
    groups = []
    for start in range(sl.start, sl.stop, DRAW_GROUP):
        groups.append(spec.family.draw_batch(spec.seed, np.arange(start, min(start + DRAW_GROUP, sl.stop))))
        time.sleep(0)  # lets the GIL go: a thread waiting for it takes it now
    if len(groups) == 1:
        return groups[0]
    return {name: np.concatenate([g[name] for g in groups]) for name in groups[0]}


def _written(writing: tuple, report, within) -> None:
    """Wait for a chunk's write (its error, if any, raised here) and count the chunk done."""
    future, j, realizations = writing
    future.result()
    report.chunk_done(j, realizations, counted=within is not None)


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


def _with_pulse_windows(spec: EnsembleSpec, out, threads, report, helper=None) -> tuple:
    """(``spec`` with its averaged-pulse windows set, ``ahead``): the windows of the store ``out`` when it was
    started with windows (a store is continued with its own), else from the pilot realisations
    (:func:`granchain.ensembles.pulse_window.window_ends`). While the pilot integrates, ``helper`` (a local
    run's helper thread, or None) draws chunk 0, the first of a new run: after the pilot, those draws left
    every core but one idle (~16 us a realisation: ~8 ms a CPU chunk of 500, ~0.5 s a GPU chunk of 30,000).
    They do not depend on the windows. ``ahead``: (0, the future of those draws), or None."""
    import dataclasses

    record = _window.stored_record(out) if out is not None else None
    ends = _window.ends_of_record(record.get("pulse_window")) if record is not None else None
    ahead = None
    if ends is None:
        report.message(f"setting each granule's averaged-pulse window from the arrival times of realisations "
                       f"0..{_window.PILOT_REALIZATIONS - 1}")
        if helper is not None:
            ahead = (0, helper.submit(_draw, spec, 0))
        ends = _window.window_ends(spec, lambda pilot: compute_chunk(pilot, 0, threads=threads))
    return dataclasses.replace(spec, pulse_ends=ends), ahead


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
