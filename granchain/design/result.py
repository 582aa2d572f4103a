"""The result of a design run: the best design, its chain and value, the reference, the history."""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field

import numpy as np

from ..model.chain import Chain

__all__ = ["DesignResult"]


def _num(x):
    return None if x is None or not math.isfinite(float(x)) else float(x)


@dataclass(frozen=True, eq=False)
class DesignResult:
    """What :func:`granchain.design.optimize` found.

    Attributes
    ----------
    space, objective
        The design space and the objective.
    x : (D,) array
        The best design's parameters; ``params`` the same by name.
    chain : granchain.Chain
        The best design's chain (for a random space: its realisation 0).
    value, stderr : float
        The objective of the best design (rescaled units; ``objective.kind`` says which quantity) and,
        for a random space, the standard error of the statistic over the realisations (NaN otherwise).
    reference_chain, reference_value
        A monodisperse chain of the same number of granules, of the struck granule's radius, with the
        same end, and its objective: what the design improves on.
    n_evaluations : int
        Evaluations of the run (including those replayed from a saved history).
    history : xarray.Dataset
        Every evaluation (dims ``evaluation``, ``parameter``).
    convergence : dict
        How sure the result is: the global search's flag and message (``optimizer_converged``,
        ``optimizer_message``), the relative improvement of its last generations
        (``improvement_last_generations``), the evaluations used, the value before the final polish and,
        for one or two real parameters, the polish's method, evaluations and relative change (``polish``).
        :meth:`convergence_text` says it in words (the summary's "how sure" line).
    """

    space: object
    objective: object
    x: np.ndarray
    params: dict
    chain: Chain
    value: float
    stderr: float
    reference_chain: Chain
    reference_value: float
    n_evaluations: int
    history: object = field(repr=False)
    integrator: object = field(repr=False, default=None)
    statistic: object = "mean"
    seed: int = 0
    budget: int = 0
    message: str = ""
    version: str = ""
    convergence: dict = field(default_factory=dict)

    @classmethod
    def from_history(cls, space, objective, evaluator, history, *, seed, budget, message, version,
                     convergence=None) -> DesignResult:
        f = np.where(np.isfinite(history.value), objective.sense * history.value, np.inf)
        if not np.isfinite(f).any():
            raise ValueError("no design of the run was feasible and integrated: widen the bounds or relax the constraints")
        i = int(np.argmin(f))
        x = history.x[i].copy()
        ref = evaluator.chain(space.reference_chain())
        from ..families import ChainBatch
        from .evaluate import evaluate_chains

        ref_batch = ChainBatch(ref.masses[None], ref.stiffness[None], np.array([ref.initial_velocity]), ref.observed, ref.n)
        ref_value = float(evaluate_chains(ref_batch, objective, evaluator.integrator, contact=evaluator.contact)[0][0])
        return cls(space, objective, x, space.params(x), evaluator.chain(space.chain(x)), float(history.value[i]), float(history.stderr[i]), ref,
                   ref_value, history.count, history.dataset(), evaluator.integrator, evaluator.statistic, seed, budget,
                   message, version, dict(convergence or {}))

    @property
    def best_radii(self) -> np.ndarray:
        """The best chain's radii (rescaled: granule 1 has radius 1), the wall excluded."""
        r = np.asarray(self.chain.radii)
        return r[:-1] if self.chain.wall else r

    def to_dict(self) -> dict:
        """A JSON-able record for programs (``result.json``)."""
        return {
            "space": self.space.describe(),
            "objective": {**self.objective.describe(), "long_name": self.objective.long_name,
                          "quantity": self.objective.kind, "units": "rescaled (paper Sec. II)"},
            "statistic": self.statistic if self.space.random else None,
            "best_params": self.params,
            "best_radii": [float(r) for r in self.best_radii],
            "best_value": _num(self.value),
            "best_stderr": _num(self.stderr) if self.space.random else None,
            **({"contact": self.chain.contact.describe()} if self.chain.contact.dissipates else {}),
            "reference": {"chain": f"monodisperse, {self.reference_chain.size - int(self.reference_chain.wall)} granules of radius 1"
                                   + (", fixed wall of the granules' material" if self.reference_chain.wall else ", free end"),
                          "value": _num(self.reference_value)},
            "n_evaluations": int(self.n_evaluations),
            "budget": int(self.budget),
            "seed": int(self.seed),
            "integrator": None if self.integrator is None else self.integrator.describe(),
            "message": self.message,
            "convergence": {k: (_num(v) if isinstance(v, float) else v) for k, v in self.convergence.items()},
            "granchain_version": self.version,
        }

    def save(self, directory) -> str:
        """Write ``result.json`` into ``directory``; returns its path."""
        os.makedirs(os.fspath(directory), exist_ok=True)
        path = os.path.join(os.fspath(directory), "result.json")
        tmp = path + ".tmp"
        with open(tmp, "w") as fh:
            json.dump(self.to_dict(), fh, indent=2)
        os.replace(tmp, path)
        return path

    def summary(self, scale=None) -> str:
        """A short markdown summary (physical units with a :class:`granchain.units.Scale`)."""
        obj = self.objective
        unit = ""
        value, ref = self.value, self.reference_value
        if scale is not None and obj.kind != "1":
            from ..units import SI_UNITS

            value, ref, unit = scale.to_si(value, obj.kind), scale.to_si(ref, obj.kind), f" {SI_UNITS[obj.kind]}"
        err = f" ± {scale.to_si(self.stderr, obj.kind) if scale is not None and obj.kind != '1' else self.stderr:.3g}" if self.space.random else ""
        ratio = self.value / self.reference_value if self.reference_value else float("nan")
        params = ", ".join(f"{k} = {v:.6g}" if isinstance(v, float) else f"{k} = {v}" for k, v in self.params.items())
        lines = [
            f"# Design: {self.space.label()}",
            "",
            f"- objective: {obj.long_name} ({'minimised' if obj.sense > 0 else 'maximised'})"
            + (f", {self.statistic} over {self.space.realizations} realisations (common to every design)" if self.space.random else ""),
            f"- design found: {params}",
            *([f"- contacts: {self.chain.contact.label()} (the design and the reference alike)"]
              if self.chain.contact.dissipates else []),
            f"- its value: {value:.6g}{unit}{err}",
            f"- monodisperse chain of the same size: {ref:.6g}{unit} (ratio {ratio:.4g})",
            f"- evaluations: {self.n_evaluations} (budget {self.budget}"
            + (f", plus {self.convergence['polish']['evaluations']} of the polish" if "polish" in self.convergence else "")
            + f"); {self.message}",
            f"- how sure: {self.convergence_text()}",
            f"- radii (granule 1 first, rescaled): {np.array2string(self.best_radii, precision=4, max_line_width=100)}",
        ]
        if scale is not None:
            lines.append(f"- units: {scale}")
        return "\n".join(lines) + "\n"

    def convergence_text(self) -> str:
        """How near the optimum the run came, in words: the global search's flag, its last generations'
        improvement and the polish's change (a search stops at its budget; that alone proves nothing)."""
        c = self.convergence
        if not c:
            return "no convergence record (a result from an older granchain)"
        parts = [("the global search reports convergence" if c.get("optimizer_converged")
                  else "the global search stopped without converging") + f" ({c.get('optimizer_message', '').rstrip('.')})"]
        imp = c.get("improvement_last_generations")
        if imp is not None:
            parts.append(f"its last {c['last_generations']} generations improved the value by {100 * imp:.3g} %")
        pol = c.get("polish")
        if pol:
            change = pol.get("change")
            parts.append(f"the final polish ({pol['method']}; {pol['status'].rstrip('.')}) changed it by "
                         + ("n/a" if change is None else f"{100 * change:+.3g} %"))
        else:
            parts.append("no final polish (it is run for one or two real parameters)")
        verdict = ("a local optimum to within the polish's resolution; other optima of a rugged objective may lie elsewhere"
                   if pol else "the optimum of the designs evaluated, not a proven optimum of the space")
        return "; ".join(parts) + f". This is {verdict}"

    def plot(self, scale=None, fig=None):
        """The convergence and the best design's wall force (or last granule's velocity) against the
        monodisperse references; see :func:`granchain.design.figure.plot`."""
        from .figure import plot

        return plot(self, scale=scale, fig=fig)
