"""``optimize``: which chain of a design space does best, by SciPy's optimisers over batched runs.

The global search is SciPy's ``differential_evolution`` with ``vectorized=True`` and
``updating="deferred"``: a whole generation arrives as one (D, S) array and is evaluated as one batch
of the compiled ensemble kernel (:class:`granchain.design.BatchEvaluator`; a Dask client spreads it
over workers). Constraints are SciPy ``NonlinearConstraint`` s (Lampinen's feasibility rules: an
infeasible design is never integrated). A local refinement (``"powell"`` or ``"nelder-mead"``,
``scipy.optimize.minimize`` within the bounds) polishes the best design with what is left of the
budget. For one or two real parameters a final bounded polish (``_polish``: a local grid, then
SciPy's bounded Brent or Nelder-Mead) follows, on top of the budget. All are deterministic for a seed,
and every evaluation goes into the run's history (:class:`granchain.design.history.History`), which
makes a run resumable. The result carries the evidence of convergence (:func:`_convergence`).
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
from .space import DesignSpace

__all__ = ["LOCAL_METHODS", "minimum_budget", "optimize"]

#: Local refinements: SciPy ``minimize`` methods that need no gradient and take bounds.
LOCAL_METHODS = {"powell": "Powell", "nelder-mead": "Nelder-Mead"}

#: What SciPy's minimisers are given for a design that failed or is infeasible: a barrier, finite so that
#: Powell's and Nelder-Mead's arithmetic stays defined.
_BARRIER = 1e30


class _BudgetSpent(Exception):
    pass


class _EvaluationError(Exception):
    """An evaluation failed. Not a ValueError or TypeError on purpose: SciPy's differential evolution
    replaces those, raised inside its map, by its own words about the map-like callable; this one passes
    through and :func:`optimize` raises it again as the ValueError it carries."""

    def __init__(self, error: ValueError):
        super().__init__(str(error))
        self.error = error


def _failure(space, X: np.ndarray, exc: BaseException) -> ValueError:
    """The error of a failed evaluation of designs X: the design that failed (found by building each
    design's chain alone, which costs no integration) and the cause, with what to change."""
    cause = f"{type(exc).__name__}: {exc}" if not isinstance(exc, ValueError) else str(exc)
    which = None
    for x in X:
        try:
            space.batch(x[None])
        except Exception as one:  # noqa: BLE001 -- the first design whose chain cannot be built
            which, cause = x, (f"{type(one).__name__}: {one}" if not isinstance(one, ValueError) else str(one))
            break
    if which is None:
        where = (f"the design {space.params(X[0])}" if X.shape[0] == 1
                 else f"one of {X.shape[0]} designs evaluated together (the first: {space.params(X[0])})")
    else:
        where = f"the design {space.params(which)}"
    return ValueError(f"evaluating {where} failed: {cause}. Every design within the bounds must give a valid chain, of one "
                      "size for all: narrow the bounds (or fix the design function) to exclude it")


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

    def __init__(self, total: int, enabled: bool, label: str, extra: int = 0):
        self.enabled, self.total, self.done, self.t0, self.bar = bool(enabled), total + extra, 0, time.monotonic(), None
        self.budget, self.extra = total, extra  # the budget, and at most ``extra`` evaluations of the polish on top
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
            polish = f" and at most {self.extra} of the polish" if self.extra else ""
            print(f"{self.done} evaluations (of a budget of {self.budget}{polish}) done{tail}, {rate:.1f}/s", file=sys.stderr,
                  flush=True)


def optimize(space, objective, *, budget: int = 200, seed: int = 0, popsize: int = 10, local: str | None = "powell",
             statistic="mean", integrator=None, out=None, resume: bool = True, client=None, workers=None, progress: bool = False,
             mutation=(0.5, 1.0), recombination: float = 0.7, polish: bool = True, backend=None,
             switch_backend: bool = False, contact=None) -> DesignResult:
    """Search ``space`` for the design that does best for ``objective`` within ``budget`` evaluations; the
    result says how sure it is (:attr:`DesignResult.convergence`: a search that stops at its budget has
    found the best design it evaluated, not a proven optimum).

    Every check that needs no integration comes first (arguments, chain size, whether any design meets
    the constraints, the output directory: :mod:`granchain.design.preflight`); a design whose evaluation
    fails stops the run with a ValueError naming the design and the cause.

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
    polish : bool
        For a space of one or two real parameters: a last bounded local search from the best design
        (``_polish``, at most ``POLISH_EVALUATIONS`` evaluations on top of the budget), which can
        only improve the result. Its change is reported in :attr:`DesignResult.convergence`.
    backend : str, optional
        What integrates the generations: None or "cpu" (default), the integrator's own backend; "cuda", an
        NVIDIA GPU (``pip install granchain[cuda]``). Recorded with the run when not "cpu"; a run in ``out``
        is continued on the backend that computed it.
    switch_backend : bool
        Continue a run in ``out`` that another backend computed (its values then come from two backends,
        within the accuracy contract, not bitwise); the record keeps ``"backend"`` (the first) and adds
        ``"backends_used"`` in the order first used. False: such a run is refused, naming both.
    contact : granchain.model.contacts.ContactLaw, optional
        The contact law of every chain of the run, designs and reference alike (None: the paper's elastic
        contacts). A dissipative law (``granchain.Viscous``, ``granchain.Viscoelastic``) designs a
        protector that takes energy out of the pulse; it is integrated with DP5 (the default for it) and
        recorded with the run, which is continued only with the same law.
    """

    from .preflight import check_feasible, check_size, output_directory

    if not isinstance(space, DesignSpace):
        raise ValueError(f"space must be a granchain.design space (TaperedSpace, DecoratedSpace, BinarySpace, "
                         f"RandomDecoratedSpace or FunctionSpace), got {space!r}")
    check_size(space)  # before the evaluator: a sensor objective asks the chains' size
    if not isinstance(switch_backend, (bool, np.bool_)):
        raise ValueError(f"switch_backend must be True or False, got {switch_backend!r}")
    evaluator = BatchEvaluator(space, objective, integrator=integrator, statistic=statistic, client=client, workers=workers,
                               backend=backend, contact=contact)
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
    from contextlib import nullcontext
    from os import makedirs
    from os import path as osp

    polish = bool(polish)
    check_feasible(space)  # a request no design can meet is refused here, not after a run of NaNs
    if out is not None:
        out = output_directory(out)
        if resume:
            record = _continued_backends(osp.join(out, "history.zarr"), record, evaluator, switch_backend)
        makedirs(out, exist_ok=True)
        # One run at a time per directory (a run started again while the interrupted one is still ending,
        # or twice): the ensembles' store lock, on the history (a ValueError naming the holder's PID),
        # released on every way out of the run (an error, an interrupt).
        from ..ensembles.lock import StoreLock

        lock = StoreLock(osp.join(out, "history.zarr"))
    else:
        lock = nullcontext()
    with lock:
        try:
            return _run(space, objective, evaluator, record, budget=budget, seed=seed, popsize=popsize, local=local,
                        maxiter=maxiter, snap_budget=snap_budget, out=out, resume=resume, progress=progress,
                        mutation=mutation, recombination=recombination, polish=polish)
        except _EvaluationError as exc:
            raise exc.error from exc.__cause__


def _continued_backends(path, record: dict, evaluator, switch: bool) -> dict:
    """``record`` for a run continuing the history at ``path`` (if any) on the evaluator's backend: refused
    when another backend computed it, unless ``switch``; then with the backends used so far and this one
    (:mod:`granchain.ensembles.backend`, the rules of the ensemble stores)."""
    import json
    import os

    from ..ensembles import backend as _backend

    if not os.path.isdir(path):
        return record
    try:
        import zarr

        stored = json.loads(zarr.open_group(path, mode="r").attrs.get("granchain_design", "{}"))
    except Exception:  # noqa: BLE001 -- an unreadable history: the History's own check says what is wrong
        return record
    used = _backend.check_same_backend(path, stored, _backend.name_of(evaluator.backend), bool(switch))
    if used is None:
        return record
    record = {k: v for k, v in record.items() if k != "backend"}
    return {**record, **({} if used[0] == _backend.CPU else {"backend": used[0]}), "backends_used": list(used)}


def _run(space, objective, evaluator, record, *, budget, seed, popsize, local, maxiter, snap_budget, out, resume, progress,
         mutation, recombination, polish) -> DesignResult:
    """The search itself (``optimize`` checked the arguments and holds the run directory's lock)."""
    from os import fspath
    from os import path as osp

    from scipy.optimize import NonlinearConstraint, differential_evolution, minimize

    history = History(space.names, record, None if out is None else osp.join(fspath(out), "history.zarr"), resume)
    will_polish = polish and not space.integer and space.dim <= POLISH_DIM
    bar = _Progress(budget, progress, f"design {space.kind}", POLISH_EVALUATIONS[space.dim] if will_polish else 0)
    best = [np.inf]

    def evaluate(X: np.ndarray, stage: str) -> np.ndarray:
        found, value, stderr, failed = history.lookup(X)
        todo = ~found
        if todo.any():
            try:
                ev = evaluator(X[todo])
            except (KeyboardInterrupt, _BudgetSpent, _EvaluationError):
                raise
            except Exception as exc:  # noqa: BLE001 -- named and carried past SciPy (see _EvaluationError)
                raise _EvaluationError(_failure(space, X[todo], exc)) from exc
            value[todo], stderr[todo], failed[todo] = ev.value, ev.stderr, ev.failed
        history.add(X, value, stderr, failed, stage)
        history.replayed += int(found.sum())
        if todo.any():
            history.flush(force=False)
        f = np.where(np.isfinite(value), objective.sense * value, _BARRIER)
        if f.size:
            best[0] = min(best[0], float(f.min()))
        bar.update(X.shape[0], objective.sense * best[0], history.replayed)
        return f

    def de_func(x):  # (D, S): one generation
        return evaluate(np.ascontiguousarray(np.asarray(x, dtype=float).T), "global")

    constraints = ()
    if space.constraints.active or hasattr(space, "min_width"):
        def violation(x):
            X = np.atleast_2d(np.asarray(x).T)
            try:
                return space.violation(X)[None]
            except Exception as exc:  # noqa: BLE001 -- named and carried past SciPy (see _EvaluationError)
                raise _EvaluationError(_failure(space, X, exc)) from exc

        constraints = NonlinearConstraint(violation, -np.inf, 0.0)
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
        before = objective.sense * float(np.min(np.where(np.isfinite(history.value), objective.sense * history.value, np.inf)))
        polished = None
        if will_polish and np.isfinite(before):
            polished = _polish(space, history, objective, evaluate)
        convergence = _convergence(history, objective, de, before, polished, population_size(space, popsize))
    finally:
        history.flush()
        bar.close(objective.sense * best[0] if np.isfinite(best[0]) else None)
    result = DesignResult.from_history(space, objective, evaluator, history, seed=seed, budget=budget, message=message,
                                       version=__version__, convergence=convergence)
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


#: Spaces of at most this many real parameters get the final polish (a local grid is affordable there).
POLISH_DIM = 2
#: The polish's local grid spans +-POLISH_WIDTH of each parameter's range around the best design.
POLISH_WIDTH = 0.01
#: Evaluations the polish may spend (on top of the budget): a grid of 21 (one parameter) or 7 x 7 (two)
#: designs, then a bounded Brent or Nelder-Mead search.
POLISH_EVALUATIONS = {1: 60, 2: 110}


def _polish(space, history, objective, evaluate) -> dict:
    """A bounded local search from the best design, for one or two real parameters.

    A design objective such as the peak wall force is deterministic but rugged at fine scales (a tapered
    chain's wall force changes by tens of per cent between q values 1e-4 apart, as the last granules'
    collisions reorder), so a smooth local method alone stops in the nearest dimple. The polish first
    evaluates a local grid (+-:data:`POLISH_WIDTH` of each range, 21 designs in 1-D, 7 x 7 in 2-D, one
    batch), then runs SciPy's bounded Brent (``minimize_scalar(method="bounded")``, 1-D) or Nelder-Mead
    within the bounds (2-D) from the best node, within the cell around it. Every evaluation goes into the
    history, so the result can only improve. Returns what it did."""
    from scipy.optimize import minimize, minimize_scalar

    D = space.dim
    x0 = _best_x(history, objective)
    span = space.upper - space.lower
    lo = np.maximum(space.lower, x0 - POLISH_WIDTH * span)
    hi = np.minimum(space.upper, x0 + POLISH_WIDTH * span)
    count0 = history.count
    limit = POLISH_EVALUATIONS[D]
    axes = [np.linspace(lo[j], hi[j], 21 if D == 1 else 7) for j in range(D)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, D)
    ok = space.violation(grid) <= 0.0
    if ok.any():
        evaluate(grid[ok], "local")
    x1 = _best_x(history, objective)
    step = np.array([a[1] - a[0] for a in axes])
    cell_lo, cell_hi = np.maximum(space.lower, x1 - step), np.minimum(space.upper, x1 + step)

    def one(x):
        if history.count - count0 >= limit:
            raise _BudgetSpent
        x = np.clip(np.atleast_1d(np.asarray(x, dtype=float)), space.lower, space.upper)
        if space.violation(x[None])[0] > 0.0:
            return _BARRIER
        return float(evaluate(x[None], "local")[0])  # sense x value, or the barrier for a failed design

    method = "bounded Brent" if D == 1 else "Nelder-Mead"
    try:
        if D == 1:
            res = minimize_scalar(lambda q: one([q]), bounds=(float(cell_lo[0]), float(cell_hi[0])), method="bounded",
                                  options={"xatol": 1e-8 * float(span[0]), "maxiter": limit})
        else:
            res = minimize(one, x1, method="Nelder-Mead", bounds=list(zip(cell_lo, cell_hi)),
                           options={"xatol": 1e-8 * float(span.min()), "fatol": 1e-12, "maxfev": limit})
        status = f"{method}: {res.message}"
    except _BudgetSpent:
        status = f"{method}: stopped at its {limit} evaluations"
    return {"evaluations": history.count - count0, "method": f"local grid of {grid.shape[0]} designs, then {method}",
            "status": status}


#: Generations of differential evolution over which the last improvement is reported.
LAST_GENERATIONS = 3


def _convergence(history, objective, de, before: float, polished: dict | None, S: int) -> dict:
    """The evidence of how near the optimum a run came, for the summary (instead of calling it "best"):
    the global search's own flag and message, how much its last :data:`LAST_GENERATIONS` generations
    improved the best value (a search still improving has not converged), the evaluations used, and the
    polish's change of the value (a large change means the search had not settled)."""
    sense = objective.sense
    f = np.where(np.isfinite(history.value), sense * history.value, np.inf)
    glob = np.flatnonzero(history.stage == History.STAGES["global"])
    out = {"evaluations": int(history.count), "optimizer_converged": bool(de.success), "optimizer_message": str(de.message),
           "generations": int(max(glob.size // S - 1, 0)) if S else 0}
    if glob.size > S:
        running = np.minimum.accumulate(f[glob])
        k = min(LAST_GENERATIONS, glob.size // S - 1)
        then, now = running[-1 - k * S], running[-1]
        out["last_generations"] = k
        out["improvement_last_generations"] = float((then - now) / abs(then)) if np.isfinite(then) and then != 0 else None
    final = float(np.min(f)) if np.isfinite(f).any() else float("nan")
    out["value_before_polish"] = before
    out["value"] = sense * final
    if polished is not None:
        out["polish"] = {**polished, "change": float((sense * final - before) / abs(before)) if before else None}
    return out
