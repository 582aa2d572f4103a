"""``optimize``: which chain of a design space does best, by SciPy's optimisers over batched runs.

The global search is SciPy's ``differential_evolution`` with ``vectorized=True`` and
``updating="deferred"``: a whole generation arrives as one (D, S) array and is evaluated as one batch
of the compiled ensemble kernel (:class:`granchain.design.BatchEvaluator`; a Dask client spreads it
over workers). Constraints are SciPy ``NonlinearConstraint`` s (Lampinen's feasibility rules: an
infeasible design is never integrated). A local refinement (``"powell"`` or ``"nelder-mead"``,
``scipy.optimize.minimize`` within the bounds) polishes the best design with what is left of the
budget. Both are deterministic for a seed, and every evaluation goes into the run's history
(:class:`granchain.design.history.History`), which makes a run resumable.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from .._validate import count
from .._version import __version__
from .evaluate import BatchEvaluator
from .history import History
from .result import DesignResult

__all__ = ["LOCAL_METHODS", "minimum_budget", "optimize"]

#: Local refinements: SciPy ``minimize`` methods that need no gradient and take bounds.
LOCAL_METHODS = {"powell": "Powell", "nelder-mead": "Nelder-Mead"}

#: What SciPy's minimisers are given for a design that failed or is infeasible: a barrier, finite so that
#: Powell's and Nelder-Mead's arithmetic stays defined.
_BARRIER = 1e30


class _BudgetSpent(Exception):
    pass


def population_size(space, popsize: int) -> int:
    """Designs per generation of differential evolution: popsize x D (SciPy's rule)."""
    return popsize * space.dim


def minimum_budget(space, popsize: int = 10, local: str | None = "powell") -> int:
    """The smallest budget a run can use: the initial population and one generation (and, with a local
    refinement, 2 D + 1 more evaluations, one sweep of Powell's or a Nelder-Mead simplex)."""
    S = population_size(space, popsize)
    return 2 * S + (0 if local is None or space.integer else 2 * space.dim + 1)


class _Progress:
    """A bar of evaluations (terminal or notebook), one line per batch otherwise, or nothing."""

    def __init__(self, total: int, enabled: bool, label: str):
        self.enabled, self.total, self.done, self.t0, self.bar = bool(enabled), total, 0, time.monotonic(), None
        self.last = 0.0
        if self.enabled and ("ipykernel" in sys.modules or bool(getattr(sys.stderr, "isatty", lambda: False)())):
            from tqdm.auto import tqdm

            self.bar = tqdm(total=total, unit=" designs", desc=label, dynamic_ncols=True, mininterval=0.5)

    def update(self, k: int, best: float, replayed: int) -> None:
        self.done += k
        if self.bar is not None:
            self.bar.update(k)
            self.bar.set_postfix_str(f"best {best:.6g}", refresh=False)
        elif self.enabled and (self.done >= self.total or time.monotonic() - self.last >= 2.0):
            self.last = time.monotonic()
            rate = self.done / max(time.monotonic() - self.t0, 1e-9)
            extra = f" ({replayed} already evaluated: looked up)" if replayed else ""
            print(f"{self.done}/{self.total} evaluations{extra}, best {best:.6g}, {rate:.1f}/s", file=sys.stderr, flush=True)

    def close(self, best: float | None = None) -> None:
        """End the report. A run may stop below its budget (differential evolution's generations and the
        refinement do not divide it exactly): the bar is then closed at the evaluations done, and the
        line report prints its last line, so that neither is left at a stale count."""
        if self.bar is not None:
            if self.done < self.total:
                self.bar.total = self.done
                self.bar.refresh()
            self.bar.close()
        elif self.enabled and self.done and self.done < self.total:
            rate = self.done / max(time.monotonic() - self.t0, 1e-9)
            tail = "" if best is None else f", best {best:.6g}"
            print(f"{self.done} evaluations (of a budget of {self.total}) done{tail}, {rate:.1f}/s", file=sys.stderr, flush=True)


def optimize(space, objective, *, budget: int = 200, seed: int = 0, popsize: int = 10, local: str | None = "powell",
             statistic="mean", integrator=None, out=None, resume: bool = True, client=None, workers=None, progress: bool = False,
             mutation=(0.5, 1.0), recombination: float = 0.7) -> DesignResult:
    """The best design of ``space`` for ``objective`` within ``budget`` evaluations.

    Parameters
    ----------
    space : granchain.design.DesignSpace
        :class:`TaperedSpace`, :class:`DecoratedSpace`, :class:`BinarySpace`, :class:`RandomDecoratedSpace`
        or :class:`FunctionSpace` (with its bounds and constraints).
    objective : granchain.design.Objective or str
        ``"wall-force"``, ``"transmitted-energy"``, ``"transmitted-momentum"``, ``"impulse-duration"``,
        ``"arrival-time"``, ``"sensor-force"`` (:data:`granchain.design.OBJECTIVES`), minimised or maximised
        as its ``sense`` says.
    budget : int
        Evaluations of designs in all (a random space's design counts once, whatever its realisations).
        At least :func:`minimum_budget`.
    seed : int
        Seeds differential evolution: the same seed, the same run.
    popsize : int
        Differential evolution's population is popsize x D designs per generation.
    local : "powell", "nelder-mead" or None
        The local refinement of the best design, with a fifth of the budget (at least 2 D + 1); None: none.
        Not for a binary space (its parameters are integers).
    statistic : "mean" or float
        For random spaces: the mean over the realisations, or this quantile (e.g. 0.9).
    integrator : optional
        Default :func:`granchain.design.evaluate.default_integrator`.
    out : path, optional
        A directory: the history (``history.zarr``, resumable) and ``result.json``.
    resume : bool
        Continue the run saved in ``out`` (default); False: an existing run there is an error.
    client : dask.distributed.Client, optional
        Evaluate each generation on this cluster (one batch per worker).
    workers : callable, optional
        A map-like callable, as SciPy's ``differential_evolution(workers=...)`` takes it
        (``multiprocessing.Pool(k).map``, ``concurrent.futures.Executor.map``, ``client.map`` of a Dask
        client), or a Dask client: each generation is split into one batch per core and the batches are
        mapped. The values, and so the run, do not depend on it. A process pool must start its
        processes by "spawn" or "forkserver" (``multiprocessing.get_context("spawn").Pool(2)``): the
        compiled kernels run on GNU OpenMP threads, which a forked process cannot use.
    progress : bool
        A progress bar (one line per generation when stderr is not a terminal).
    """

    evaluator = BatchEvaluator(space, objective, integrator=integrator, statistic=statistic, client=client, workers=workers)
    objective = evaluator.objective
    popsize = count("popsize", popsize, minimum=2)
    seed = count("seed", seed, minimum=0)
    if local is not None and local not in LOCAL_METHODS:
        raise ValueError(f"local must be one of {sorted(LOCAL_METHODS)} or None, got {local!r}")
    if space.integer:
        local = None
    budget = count("budget", budget, minimum=1)
    need = minimum_budget(space, popsize, local)
    S = population_size(space, popsize)
    if budget < need:
        raise ValueError(f"budget = {budget} evaluations is below this run's minimum {need}: differential evolution needs its "
                         f"initial population and one generation (2 x {S} = 2 x popsize {popsize} x {space.dim} parameters)"
                         + (f" and the local refinement {2 * space.dim + 1}" if need > 2 * S else "")
                         + f"; raise --budget to at least {need}, or lower popsize")
    local_budget = 0 if local is None else max(2 * space.dim + 1, budget // 5)
    snap_budget = 0 if space.integer else min(space.dim + 1, max(0, budget - need))
    maxiter = (budget - local_budget - S) // S
    record = {"space": space.describe(), "objective": objective.describe(), **evaluator.describe(), "seed": seed,
              "popsize": popsize, "local": local, "mutation": list(np.atleast_1d(mutation).astype(float)),
              "recombination": float(recombination)}
    from os import fspath, makedirs
    from os import path as osp

    lock = None
    if out is not None:
        makedirs(fspath(out), exist_ok=True)
        # One run at a time per directory (a run started again while the interrupted one is still ending,
        # or twice): the ensembles' store lock, on the history (a ValueError naming the holder's PID).
        from ..ensembles.lock import StoreLock

        lock = StoreLock(osp.join(fspath(out), "history.zarr"))
        lock.acquire()
    try:
        return _run(space, objective, evaluator, record, budget=budget, seed=seed, popsize=popsize, local=local,
                    maxiter=maxiter, snap_budget=snap_budget, out=out, resume=resume, progress=progress, mutation=mutation,
                    recombination=recombination)
    finally:
        if lock is not None:
            lock.release()


def _run(space, objective, evaluator, record, *, budget, seed, popsize, local, maxiter, snap_budget, out, resume, progress,
         mutation, recombination) -> DesignResult:
    """The search itself (``optimize`` checked the arguments and holds the run directory's lock)."""
    from os import fspath
    from os import path as osp

    from scipy.optimize import NonlinearConstraint, differential_evolution, minimize

    history = History(space.names, record, None if out is None else osp.join(fspath(out), "history.zarr"), resume)
    bar = _Progress(budget, progress, f"design {space.kind}")
    best = [np.inf]

    def evaluate(X: np.ndarray, stage: str) -> np.ndarray:
        found, value, stderr, failed = history.lookup(X)
        todo = ~found
        if todo.any():
            ev = evaluator(X[todo])
            value[todo], stderr[todo], failed[todo] = ev.value, ev.stderr, ev.failed
        history.add(X, value, stderr, failed, stage)
        history.replayed += int(found.sum())
        if todo.any():
            history.flush(force=False)
        f = np.where(np.isfinite(value), objective.sense * value, _BARRIER)
        best[0] = min(best[0], float(f.min()))
        bar.update(X.shape[0], objective.sense * best[0], history.replayed)
        return f

    def de_func(x):  # (D, S): one generation
        return evaluate(np.ascontiguousarray(np.asarray(x, dtype=float).T), "global")

    constraints = ()
    if space.constraints.active or hasattr(space, "min_width"):
        constraints = NonlinearConstraint(lambda x: space.violation(np.atleast_2d(np.asarray(x).T))[None], -np.inf, 0.0)
    try:
        de = differential_evolution(de_func, space.bounds, maxiter=maxiter, popsize=popsize, tol=0.0, atol=0.0,
                                    mutation=mutation, recombination=recombination, rng=np.random.default_rng(seed),
                                    polish=False, init="latinhypercube", updating="deferred", vectorized=True,
                                    constraints=constraints, integrality=[True] * space.dim if space.integer else None)
        message = f"differential evolution: {de.message}"
        if local is not None and history.count < budget:
            left = budget - history.count - snap_budget
            x0 = _best_x(history, objective)
            used = [0]

            def local_func(x):
                if used[0] >= left:
                    raise _BudgetSpent
                used[0] += 1
                x = np.clip(np.asarray(x, dtype=float), space.lower, space.upper)
                return float(evaluate(x[None], "local")[0])

            try:
                loc = minimize(local_func, x0, method=LOCAL_METHODS[local], bounds=space.bounds,
                               options={"maxfev": left, "xtol": 1e-6, "ftol": 1e-10} if local == "powell"
                               else {"maxfev": left, "xatol": 1e-6, "fatol": 1e-10})
                message += f"; {LOCAL_METHODS[local]} refinement: {loc.message} ({used[0]} evaluations)"
            except _BudgetSpent:
                message += f"; {LOCAL_METHODS[local]} refinement stopped at the budget ({left} evaluations)"
        if history.count < budget:
            message += _snap_to_bounds(space, history, objective, budget - history.count, evaluate)
    finally:
        history.flush()
        bar.close(objective.sense * best[0] if np.isfinite(best[0]) else None)
    result = DesignResult.from_history(space, objective, evaluator, history, seed=seed, budget=budget, message=message,
                                       version=__version__)
    if out is not None:
        result.save(out)
    return result


#: How near a bound (as a fraction of its parameter's range) the best design must be for the bound
#: itself to be tried.
SNAP = 0.05


def _snap_to_bounds(space, history, objective, left: int, evaluate) -> str:
    """Try the best design with each parameter that lies within :data:`SNAP` of a bound set to that
    bound (one batch). Optima on a bound are common in design (an objective monotone in a parameter),
    and neither differential evolution (it samples the interior) nor Powell's or Nelder-Mead's searches
    reach a bound in few evaluations."""
    x = _best_x(history, objective)
    span = space.upper - space.lower
    near_lo, near_hi = (x - space.lower) < SNAP * span, (space.upper - x) < SNAP * span
    candidates = []
    for j in range(space.dim):
        for near, bound in ((near_lo[j], space.lower[j]), (near_hi[j], space.upper[j])):
            if near and x[j] != bound:
                y = x.copy()
                y[j] = bound
                candidates.append(y)
    if len(candidates) > 1:
        y = x.copy()
        y[near_lo] = space.lower[near_lo]
        y[near_hi] = space.upper[near_hi]
        candidates.append(y)
    candidates = candidates[:left]
    if not candidates:
        return ""
    evaluate(np.array(candidates), "local")
    return f"; {len(candidates)} designs on the nearby bounds tried"


def _best_x(history: History, objective) -> np.ndarray:
    f = np.where(np.isfinite(history.value), objective.sense * history.value, np.inf)
    return history.x[int(np.argmin(f))]
