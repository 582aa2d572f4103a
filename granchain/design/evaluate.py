"""The batched evaluator: a generation of designs as one call of the compiled ensemble kernel.

A generation of P designs (P x R chains for a random space: R realisations each, the same
realisations for every design) is built as one :class:`granchain.families.ChainBatch` by the space
and integrated by ``Integrator.integrate_batch`` (the kernel :func:`granchain.run_ensemble` uses,
parallel over rows in Numba threads); the objective reads the per-row outputs. No Python loop of
:func:`granchain.simulate` per design, except for the objectives that need one row's wall-force
history (``Objective.route == "history"``, see :mod:`granchain.design.objectives`).

A Dask ``client`` splits a generation into one batch per worker (``client.map``); ``workers``, a
map-like callable as SciPy's optimisers take it (``multiprocessing.Pool(k).map``,
``concurrent.futures.Executor.map``, or a Dask client's ``map`` whose futures are gathered), splits
it into one batch per part. The values do not depend on the split (rows are independent).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..backends import batch_chain
from ..model.chainmodel import ChainModel
from ..solve import defaults as _defaults
from ..solve.integrators import DP5, RunControls, get_integrator
from ..solve.simulation import simulate, time_limit
from .objectives import Objective, get_objective

__all__ = ["BatchEvaluator", "Evaluation", "default_integrator", "evaluate_chains", "run_rows"]

#: Bootstrap resamples for the standard error of a quantile over the realisations (seeded: the
#: error bar of a design does not change between runs).
BOOTSTRAP = 400


@dataclass(frozen=True)
class Evaluation:
    """Values of P designs: ``value`` (P,) (NaN where a design failed or is infeasible), ``stderr``
    (P,) (NaN for a deterministic space), ``failed`` (P,) the number of failed integrations (rows)."""

    value: np.ndarray
    stderr: np.ndarray
    failed: np.ndarray


def model_of(contact) -> ChainModel:
    """The ``model`` of ``Backend.run_batch`` for a design run whose chains have the contact law ``contact``
    (None: the paper's elastic contacts)."""
    return ChainModel(contact)


def run_rows(batch, integrator, contacts, backend=None, contact=None) -> dict:
    """Integrate every row of ``batch`` with the compiled batch kernel (``Backend.run_batch``); the per-row
    outputs by name. ``contacts``: the contacts whose peak forces the objective reads. ``backend``: None,
    the integrator's own backend; a backend's name ("cuda") or a ``granchain.backends.Backend``: that
    backend. ``contact``: the chains' contact law (None: the paper's)."""
    from ..backends import get_backend
    from ..ensembles import backend as _backend

    batch = batch._replace(contacts=np.asarray(contacts, dtype=np.int64))
    R, K, C = batch.masses.shape[0], len(batch.observed), batch.contacts.size
    t_grid = np.zeros(1)  # no averaged pulse: one sample, the objectives read peaks
    out = {"peak_velocity": np.full((R, K), np.nan), "peak_time": np.full((R, K), np.nan),
           "peak_force": np.full((R, C), np.nan), "peak_force_time": np.full((R, C), np.nan),
           "peak_wall_force": np.full(R, np.nan), "peak_wall_force_time": np.full(R, np.nan),
           "status": np.full(R, -1, dtype=np.int8),
           "energy_error": np.full(R, np.nan), "n_steps": np.full(R, -1, dtype=np.int64), "t_end": np.full(R, np.nan),
           "sum_v": np.zeros((1, K), dtype=np.int64), "sum_v2": np.zeros((1, K), dtype=np.int64),
           "sum_wall": np.zeros(1, dtype=np.int64), "n_valid": np.zeros(1, dtype=np.int64), "lags": None}
    t_max = time_limit(batch.masses.shape[1], float(np.min(batch.initial_velocity)), batch.n)
    chosen = get_backend(integrator.backend) if backend is None else _backend.resolve(backend)
    chosen.run_batch(integrator, batch, out, t_grid=t_grid, t_max=t_max, controls=RunControls(), scale=1.0,
                     model=model_of(contact))
    return out


def _history_value(chain, objective: Objective, integrator) -> float:
    """One chain's value from :func:`granchain.simulate` with its wall force on a fine grid: a first run
    finds when the pulse has come back, the second samples the force up to then (every 0.01 time
    units, at least 2000 samples)."""
    first = simulate(chain, integrator)
    if not first.ok:
        return float("nan")
    t_end = float(first.t_end)
    res = simulate(chain, integrator, t_grid=np.linspace(0.0, t_end, max(2001, int(t_end / 0.01) + 1)))
    return objective.from_result(res) if res.ok else float("nan")


def evaluate_chains(batch, objective: Objective, integrator, backend=None, contact=None) -> tuple:
    """(values (R,), ok (R,)) of every row of ``batch`` for ``objective``: through the batch kernel (on
    ``backend``, :func:`run_rows`), or row by row with simulate for a history objective (on the CPU: one
    chain's wall force on a fine grid is no work for a GPU). ``contact``: the chains' contact law."""
    wall = bool(np.isinf(batch.masses[0, -1]))
    objective.check(wall)
    if objective.route(wall) == "rows":
        rows = run_rows(batch, integrator, objective.contacts(batch.masses.shape[1] - int(wall)), backend, contact)
        ok = rows["status"] == 0
        values = np.where(ok, objective.from_rows(rows, batch), np.nan)
        return values, ok
    values = np.array([_history_value(batch_chain(batch.masses[r], batch.stiffness[r], batch.n, batch.initial_velocity[r],
                                                  batch.observed, model_of(contact)), objective, integrator)
                       for r in range(batch.masses.shape[0])])
    return values, np.isfinite(values)


def _statistic(values: np.ndarray, statistic) -> tuple:
    """(value, stderr) of one design's realisations: the mean and its standard error std/sqrt(R), or the
    quantile ``statistic`` and a seeded bootstrap standard error."""
    v = values[np.isfinite(values)]
    if v.size < 2:
        return float("nan"), float("nan")
    if statistic == "mean":
        return float(v.mean()), float(v.std(ddof=1) / np.sqrt(v.size))
    q = float(statistic)
    rng = np.random.default_rng(12345)
    boot = np.quantile(v[rng.integers(0, v.size, (BOOTSTRAP, v.size))], q, axis=1)
    return float(np.quantile(v, q)), float(boot.std(ddof=1))


def default_integrator(space, contact=None):
    """Chains whose light granules set the step (``space.character``, decorated chains): the ensembles' method
    and tolerances for them (``RKN4.relaxed`` at :data:`granchain.ENSEMBLE_RTOL`,
    :func:`granchain.solve.defaults.default_integrator`),
    every granule integrated to the end (a design's objective may read any granule or contact, and its
    chains are short); every other chain, and every chain whose contact law dissipates (RKN4 integrates
    forces of positions only): ``DP5()``, :func:`granchain.simulate`'s default, so that a reported value
    is exactly what ``simulate(space.chain(best))`` gives."""
    if space.character == _defaults.LIGHT_GRANULES and (contact is None or contact.conservative):
        return _defaults.default_integrator(_defaults.LIGHT_GRANULES, windowed=False)
    return DP5()


def _check_statistic(statistic):
    if statistic == "mean":
        return statistic
    try:
        q = float(statistic)
    except (TypeError, ValueError):
        q = -1.0
    if not 0.0 < q < 1.0:
        raise ValueError(f"statistic must be 'mean' or a quantile in (0, 1) (e.g. 0.9: nine realisations in ten do better), "
                         f"got {statistic!r}")
    return q


class BatchEvaluator:
    """``evaluator(X)`` -> :class:`Evaluation` of the designs X (P, D) of ``space`` for ``objective``.

    ``integrator``: default the ensembles' for the space's chain kind
    (:func:`default_integrator`); ``statistic``: "mean" or a quantile, for random spaces;
    ``client``: a ``dask.distributed.Client`` (one batch per worker); ``workers``: a map-like callable
    ``workers(func, parts)`` (or a Dask client), ``parts`` the generation split into ``parts`` batches
    (default: as many as this machine has cores); ``backend``: None or "cpu" (default), the integrator's own
    backend; "cuda" (or a ``granchain.backends.Backend``): a generation's rows on that backend, recorded
    in :meth:`describe` (two backends agree within the accuracy contract, not bitwise); ``contact``: the
    chains' contact law (a ``granchain.model.contacts.ContactLaw`` of the space's exponent, e.g.
    ``granchain.Viscous(0.1)``: a protector that dissipates; None: the paper's elastic contacts), recorded
    in :meth:`describe`."""

    def __init__(self, space, objective, *, integrator=None, statistic="mean", client=None, workers=None,
                 parts: int | None = None, backend=None, contact=None):
        from ..ensembles import backend as _backend
        from ..model.contacts import PowerLaw, checked_law

        self.backend = _backend.checked(backend)
        _backend.resolve(self.backend)  # a GPU where none is usable: refused before the first generation
        if workers is not None and hasattr(workers, "scheduler_info") and hasattr(workers, "gather"):
            client, workers = (workers if client is None else client), None  # a Dask client given as workers
        if workers is not None and not callable(workers):
            raise ValueError(f"workers must be a function workers(func, iterable) that applies func to each item, as "
                             f"multiprocessing.Pool(2).map, an Executor's map or a Dask client's map do, or a Dask client; "
                             f"got {workers!r}")
        if client is not None and workers is not None:
            raise ValueError("give either client (a Dask client) or workers (a map-like callable), not both")
        self.workers = workers
        self.parts = parts
        self.space = space
        contact = checked_law(contact, space.n, "design space")
        if isinstance(contact, PowerLaw):
            contact = None  # the default, recorded as such
        if contact is not None:
            mats = getattr(space, "materials", None)
            if contact is not None and contact.history and mats and len(set(mats)) > 1:
                raise ValueError("the elastic-plastic contact takes each contact's yield overlap from its prefactor, which "
                                 "holds for granules of one material: give this design space one material (or an "
                                 "elastic or viscous law for two)")
        self.contact = contact
        self.objective = get_objective(objective)
        self.objective.check(space.wall)
        self.objective.bind(space.granules)  # e.g. a sensor's contact must exist in these chains
        self.integrator = default_integrator(space, contact) if integrator is None else get_integrator(integrator)
        if contact is not None:
            self.integrator.check_law(contact, hint=" (the default for it)")
        methods = _backend.default_methods(_backend.resolve(self.backend))
        if integrator is None and methods is not None and self.integrator.name not in methods and contact is None:
            # a backend whose defaults exclude it (the GPU's is RKN4, measured there): the decorated chains' method,
            # every granule to the end, valid for every elastic chain (recorded in describe())
            self.integrator = _defaults.default_integrator(_defaults.LIGHT_GRANULES, windowed=False)
        self.statistic = _check_statistic(statistic)
        self.client = client

    def describe(self) -> dict:
        from ..ensembles import backend as _backend

        # the backend only when it is not the CPU default: the records of earlier runs stay as they were
        # the backend and the contact law only when they are not the defaults: earlier records stay as they were
        return {"integrator": self.integrator.describe(), "statistic": self.statistic,
                **({} if self.backend is None else {"backend": _backend.name_of(self.backend)}),
                **({} if self.contact is None else {"contact": self.contact.describe()})}

    def chain(self, chain):
        """``chain`` (a design or the reference) with this run's contact law."""
        return chain if self.contact is None else chain.replace(contact=self.contact)

    def __call__(self, X) -> Evaluation:
        X = self.space.as_array(X)
        if X.shape[0] == 0:
            return Evaluation(np.zeros(0), np.zeros(0), np.zeros(0, dtype=np.int64))
        if self.workers is not None and X.shape[0] >= 2:
            import os
            from functools import partial

            k = min(self.parts or os.cpu_count() or 2, X.shape[0])
            parts = [p for p in np.array_split(X, k) if p.size]
            results = list(self.workers(partial(_evaluate, self.space, self.objective, self.integrator, self.statistic,
                                                backend=self.backend, contact=self.contact), parts))
            if results and not isinstance(results[0], Evaluation) and hasattr(results[0], "result"):
                results = [r.result() for r in results]  # futures (a Dask client's map)
            return Evaluation(*(np.concatenate([getattr(r, f) for r in results]) for f in ("value", "stderr", "failed")))
        if self.client is None or X.shape[0] < 2:
            return _evaluate(self.space, self.objective, self.integrator, self.statistic, X, self.backend, self.contact)
        workers = max(1, len(self.client.scheduler_info().get("workers", {})))
        parts = [p for p in np.array_split(X, min(workers, X.shape[0])) if p.size]
        futures = self.client.map(_evaluate, [self.space] * len(parts), [self.objective] * len(parts),
                                  [self.integrator] * len(parts), [self.statistic] * len(parts), parts,
                                  [self.backend] * len(parts), [self.contact] * len(parts), pure=False)
        results = self.client.gather(futures)
        return Evaluation(*(np.concatenate([getattr(r, f) for r in results]) for f in ("value", "stderr", "failed")))


def _evaluate(space, objective, integrator, statistic, X, backend=None, contact=None) -> Evaluation:
    """The values of designs X (a top-level function, so that Dask can ship it)."""
    P = X.shape[0]
    feasible = space.violation(X) <= 0.0
    value, stderr, failed = np.full(P, np.nan), np.full(P, np.nan), np.zeros(P, dtype=np.int64)
    if not feasible.any():
        return Evaluation(value, stderr, failed)
    Xf = X[feasible]
    values, ok = evaluate_chains(space.batch(Xf), objective, integrator, backend, contact)
    R = space.realizations
    values, ok = values.reshape(Xf.shape[0], R), ok.reshape(Xf.shape[0], R)
    idx = np.flatnonzero(feasible)
    failed[idx] = (~ok).sum(axis=1)
    if R == 1:
        value[idx] = values[:, 0]
    else:
        for i, row in zip(idx, values):
            value[i], stderr[i] = _statistic(row, statistic)
    return Evaluation(value, stderr, failed)
