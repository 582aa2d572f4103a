"""Many realisations in parallel (Numba threads), one single-chain integration each.

Realisation r of a batch is integrated by the single-chain entry point of ``dispatch`` that
``granchain.simulate`` runs for the same chain (an argument of the kernel), on the same chain arrays: per-realisation results are
bitwise independent of how realisations are grouped, and equal to ``simulate``.

The entry point is a first-class function (``dispatch.kernel_function``): its machine code, compiled (or
loaded from the cache) once for ``simulate`` and ensembles alike, is called through its address. The
ensemble kernel is then one compiled function for every method and model class, and small: called by
name, the entry point's code (the whole step loop) was linked into the ensemble kernel and optimised and
compiled by LLVM again, four times over (the parallel loop's body, its two wrappers and the kernel
itself), which was most of an ensemble's first compilation.

The ensemble-averaged pulse <v_k(t)> is accumulated as running sums in fixed
point: each velocity is rounded to a multiple of 2^-bits and summed as an
int64. Integer addition is associative, so the sums (and the mean) are bitwise
identical whatever the thread count, chunk size or number of Dask workers;
the rounding (~1e-12 for bits = 40) is far below the integration error.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

from ..._status import SUCCESS
from .aligned import accumulate_aligned
from .queue import take
from .forces import energy_error as run_energy_error
from .jit import JIT, JIT_PARALLEL
from .records import (
    INFO_DISSIPATED,
    INFO_SIZE,
    INFO_STEPS,
    INFO_T_END,
    Model,
    Outputs,
    Params,
    Partials,
    Run,
    State,
)


@njit(**JIT)
def accumulate_fixed_point(grid_v, scale, acc1, acc2):
    """acc1 += round(v * scale), acc2 += round(v^2 * scale) over a (T, K) velocity grid."""
    T, K = grid_v.shape
    for g in range(T):
        for q in range(K):
            w = grid_v[g, q]
            if w != 0.0:  # granules the pulse has not reached are exactly at rest
                acc1[g, q] += np.int64(np.rint(w * scale))
                acc2[g, q] += np.int64(np.rint(w * w * scale))


@njit(**JIT)
def accumulate_fixed_point_1d(grid_f, scale, acc):
    """acc += round(f * scale) over a (T,) grid (the wall force)."""
    for g in range(grid_f.shape[0]):
        w = grid_f[g]
        if w != 0.0:
            acc[g] += np.int64(np.rint(w * scale))


@njit(**JIT)
def gather_forces(peak_f, peak_ft, contacts, force_out, force_time_out):
    """The recorded contacts' peak forces and times (``contacts``: 0-based contact indices) into
    ``force_out``, ``force_time_out``. A wall's contact is the chain's last: its peak is
    ``peak_f[-1]``, ``peak_ft[-1]``."""
    for q in range(contacts.shape[0]):
        force_out[q] = peak_f[contacts[q]]
        force_time_out[q] = peak_ft[contacts[q]]


def thread_sums(n_threads, T, K, L):
    """Zeroed per-thread partial sums for :func:`integrate_batch` (``records.Partials``: sum_v, sum_v2
    (n_threads, T, K), sum_wall (n_threads, T), n_valid (n_threads,), sum_a, sum_a2 (n_threads, L, K),
    all int64).

    The caller allocates them: allocated inside the parallel kernel, before its ``prange`` loop,
    arrays that the loop writes cost time in proportion to their size for every scheduling chunk
    under ``numba.parallel_chunksize(1)``, which this kernel ran under before its rows came from a queue
    (measured with Numba 0.68: 2.4 ms per
    iteration for two (2, 2686, 101) arrays, nothing when they are arguments; an N = 101 windowed
    realisation took 25.4 instead of 14.8 ms)."""
    return Partials(np.zeros((n_threads, T, K), dtype=np.int64), np.zeros((n_threads, T, K), dtype=np.int64),
                    np.zeros((n_threads, T), dtype=np.int64), np.zeros(n_threads, dtype=np.int64),
                    np.zeros((n_threads, L, K), dtype=np.int64), np.zeros((n_threads, L, K), dtype=np.int64))


@njit(**JIT_PARALLEL)
def integrate_batch(kernel, batch, method, run, tally, rows, sums, partials):
    """Integrate realisations r = 0..R-1 (rows of ``batch``, ``records.Batch``: each struck at granule 1
    with its ``initial_velocity``) with ``method`` by the single-chain entry point ``kernel``
    (``dispatch.kernel_function`` of the entry point ``dispatch.chain_kernel`` picks, for the records of
    ``row_records``), recording what ``run`` asks (its
    ``exit_margin``, ``max_steps``, ``peak_rtol``, ``observed``, ``t_grid``, ``pulse_end``; the run stops at the
    pulse's exit with ``run.stop_at_exit``, else, successfully, at the row's ``batch.t_max[r]`` (also its
    limit otherwise; ``run.t_max`` is not read): a precompressed chain,
    whose contacts never open).

    Per realisation writes (``rows``, ``records.Rows``) peak_velocity[r, :], peak_time[r, :], status[r],
    energy_error[r] ((E_end + E_dissipated - E_0)/E_0), dissipated_energy[r] (E_dissipated), n_steps[r], t_end[r],
    the peak forces of the contacts ``tally.contacts`` (0-based) into peak_force[r, :], peak_force_time[r, :] and, for
    chains ending in a wall, the
    wall's peak force and time into peak_wall_force[r], peak_wall_force_time[r] (untouched otherwise). Adds (``sums``,
    ``records.Sums``) round(v * scale) and round(v^2 * scale) of every successful realisation's
    observed velocities on ``t_grid`` into sum_v / sum_v2 (int64, (T, K)), with a wall
    round(F_wall * scale) into sum_wall (T,), and counts them in n_valid[0]. With a non-empty
    ``tally.lags`` (L,), also adds the aligned pulse's sums (``aligned``) into sum_a / sum_a2 (int64,
    (L, K)); with an empty one those stay untouched. ``partials``: zeroed per-thread partial sums from
    :func:`thread_sums` for numba.get_num_threads() threads (their first axis), added into ``sums``
    at the end. Each thread takes the rows one at a time, in the order ``batch.order``, from the queue
    ``batch.taken`` (``queue``: numba's prange gives each thread a fixed block): no result depends on which
    thread integrates which row.
    """
    masses, stiffness, v_init, t_limit = batch.masses, batch.stiffness, batch.initial_velocity, batch.t_max
    order, taken = batch.order, batch.taken
    # Rebuilt by a call: Numba's parallel lowering passes a named tuple into the loop body only when
    # it finds the call (or argument) that made it, not a field read (batch.params).
    params = Params(*batch.params)
    wall = params.wall
    obs, t_grid = run.observed, run.t_grid
    # (read here: the parallel loop gets the fields, not the record; see params above)
    stop_at_exit, exit_margin, max_steps, peak_rtol, sensed, pulse_end = (run.stop_at_exit, run.exit_margin, run.max_steps,
                                                                          run.peak_rtol, run.contacts, run.pulse_end)
    contacts, scale, lags = tally
    peak_v, peak_t, peak_f, peak_ft, wall_f, wall_ft, status, energy_error, n_steps, t_end, dissipated = rows
    sum_v, sum_v2, sum_wall, n_valid, sum_a, sum_a2 = sums
    acc1, acc2, accw, cnt, al1, al2 = partials
    R, M = masses.shape
    K = obs.shape[0]
    T = t_grid.shape[0]
    L = lags.shape[0]
    n_threads = cnt.shape[0]
    for _ in prange(n_threads):  # one iteration per thread; the rows come from the queue
        tid = numba.get_thread_id()
        while True:
            j = take(taken)
            if j >= R:
                break
            r = order[j]
            m = masses[r]
            c = stiffness[r]
            x = np.zeros(M)
            v = np.zeros(M)
            v[0] = v_init[r]  # the impulse on granule 1 (granchain.model.contacts.Impulse)
            # each contact's largest overlap (Thornton's law; the kernel starts it at yield; unread by every other law)
            history = np.zeros(M - 1 if params.yield_overlap > 0.0 else 0)
            grid_v = np.zeros((T, K))
            pf = np.zeros(M - 1)
            pft = np.zeros(M - 1)
            grid_f = np.zeros(T)
            info = np.zeros(INFO_SIZE)
            grid_c = np.zeros((T, sensed.shape[0]))
            row_run = Run(obs, t_grid, t_limit[r], stop_at_exit, exit_margin, max_steps, peak_rtol, sensed, pulse_end)
            st = kernel(method, Model(m, c, params), row_run, State(x, v, history),
                        Outputs(peak_v[r], peak_t[r], grid_v, pf, pft, grid_f, info, grid_c))
            gather_forces(pf, pft, contacts, peak_f[r], peak_ft[r])
            if wall:
                wall_f[r] = pf[M - 2]
                wall_ft[r] = pft[M - 2]
            status[r] = st
            n_steps[r] = np.int64(info[INFO_STEPS])
            t_end[r] = info[INFO_T_END]
            dissipated[r] = info[INFO_DISSIPATED]
            energy_error[r] = run_energy_error(x, v, m, c, params, info, history, v_init[r])
            if st == SUCCESS:
                cnt[tid] += 1
                accumulate_fixed_point(grid_v, scale, acc1[tid], acc2[tid])
                if wall:
                    accumulate_fixed_point_1d(grid_f, scale, accw[tid])
                accumulate_aligned(t_grid, grid_v, peak_t[r], lags, scale, al1[tid], al2[tid])
    for th in range(n_threads):
        n_valid[0] += cnt[th]
        for g in range(T):
            for q in range(K):
                sum_v[g, q] += acc1[th, g, q]
                sum_v2[g, q] += acc2[th, g, q]
            sum_wall[g] += accw[th, g]
        for g in range(L):
            for q in range(K):
                sum_a[g, q] += al1[th, g, q]
                sum_a2[g, q] += al2[th, g, q]


def row_records(batch, method, run, rows):
    """The records :func:`integrate_batch` passes to ``kernel`` for row 0 of ``batch``, as it builds
    them in its loop (arrays of the same types, zeros): what ``dispatch.kernel_function`` compiles the
    entry point for. (A difference in type would stop the ensemble kernel's compilation: the call
    would not match the function's signature.)"""
    M = batch.masses.shape[1]
    T, K = run.t_grid.shape[0], run.observed.shape[0]
    params = Params(*batch.params)
    return (method, Model(batch.masses[0], batch.stiffness[0], params), run._replace(t_max=float(batch.t_max[0])),
            State(np.zeros(M), np.zeros(M), np.zeros(M - 1)),
            Outputs(rows.peak_velocity[0], rows.peak_time[0], np.zeros((T, K)), np.zeros(M - 1), np.zeros(M - 1), np.zeros(T),
                    np.zeros(INFO_SIZE), np.zeros((T, run.contacts.shape[0]))))
