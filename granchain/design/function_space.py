"""A user's design space: a function of the parameters that returns radii or a Chain."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..families import ChainBatch, function_fingerprint
from ..model.chain import HERTZ, Chain, from_radii
from .space import Constraints, DesignSpace, _bounds, _init

__all__ = ["FunctionSpace"]


@dataclass(frozen=True, init=False)
class FunctionSpace(DesignSpace):
    """A user's space: ``build(params) -> radii`` (a 1-d array: spheres of one material,
    :func:`granchain.from_radii`) or ``-> Chain``, with ``params`` a dict by name; ``bounds`` a dict
    name -> (low, high). Every design must give a chain of the same size. Chains are built in Python
    one design at a time (the ready spaces build whole generations with NumPy) and integrated as one
    batch like the others. ``wall=True`` adds a fixed wall of the granules' material to radii builds (a Chain brings its own)."""

    build_fn: Callable = field(default=None, repr=False)

    def __init__(self, build: Callable, bounds: dict, *, wall: bool = True, n: float = HERTZ, name: str = "function",
                 constraints: Constraints | None = None):
        if not callable(build):
            raise ValueError(f"FunctionSpace needs a function build(params) -> radii or Chain, got {build!r}")
        if not isinstance(bounds, dict) or not bounds:
            raise ValueError("bounds must be a non-empty dict {name: (low, high)}")
        pairs = [_bounds(k, v) for k, v in bounds.items()]
        object.__setattr__(self, "build_fn", build)
        _init(self, tuple(bounds), [p[0] for p in pairs], [p[1] for p in pairs], wall=wall, n=n, constraints=constraints,
              kind=name)
        probe = self._chains(0.5 * (self.lower + self.upper)[None])[0]  # fails early with what to change
        object.__setattr__(self, "_probe", probe)
        object.__setattr__(self, "wall", probe.wall)  # a build returning a Chain brings its own end

    def _one(self, x) -> Chain:
        p = {k: float(v) for k, v in zip(self.names, x)}
        try:
            out = self.build_fn(p)
        except Exception as exc:
            raise ValueError(f"the design function failed for {p}: {type(exc).__name__}: {exc}") from exc
        if isinstance(out, Chain):
            return out
        try:
            return from_radii(out, n=self.n, kind=self.kind, wall=self.wall)
        except (ValueError, TypeError) as exc:
            raise ValueError(f"the design function returned an invalid chain for {p}: {exc}. Return positive radii (at least "
                             "2, granule 1 first) or a granchain.Chain, for every design within the bounds") from None

    def _chains(self, X) -> list:
        chains = [self._one(x) for x in self.as_array(X)]
        first = getattr(self, "_probe", chains[0])
        for p, ch in zip(self.as_array(X), chains):
            if ch.size != first.size or ch.n != first.n or not np.array_equal(ch.observed, first.observed) or ch.wall != first.wall:
                raise ValueError(f"the design function returned a chain of {ch.size} granules (n = {ch.n:g}, wall {ch.wall}) for "
                                 f"{self.params(p)}, but {first.size} (n = {first.n:g}, wall {first.wall}) for the centre of the "
                                 "bounds: every design must give a chain of the same size, so that a generation is one batch")
            if not ch.elastic or ch.striker:
                raise ValueError("the design function returned a chain with real contacts (dissipation, precompression or a "
                                 "striker): design spaces run the paper's elastic contacts")
        return chains

    @property
    def granules(self) -> int:
        return int(self._probe.size - int(self._probe.wall))

    @property
    def wall_of_chains(self) -> bool:
        return self._probe.wall

    def radii(self, X) -> np.ndarray:
        chains = self._chains(X)
        if any(ch.radii is None for ch in chains):
            raise ValueError("the design function returned chains without radii: constraints on radii, mass and length need them")
        return np.stack([ch.radii[:-1] if ch.wall else ch.radii for ch in chains])

    def batch(self, X) -> ChainBatch:
        chains = self._chains(X)
        return ChainBatch(np.stack([c.masses for c in chains]), np.stack([c.stiffness for c in chains]),
                          np.array([c.initial_velocity for c in chains]), chains[0].observed, chains[0].n)

    def chain(self, params) -> Chain:
        return self._one(self.as_array(params)[0])

    def violation(self, X) -> np.ndarray:
        X = self.as_array(X)
        if not self.constraints.active:
            return np.full(X.shape[0], -np.inf)
        chains = self._chains(X)
        radii = self.radii(X)
        masses = np.stack([c.masses[:-1] if c.wall else c.masses for c in chains])
        return self.constraints.violation(radii, masses)

    def reference_chain(self) -> Chain:
        p = self._probe
        return from_radii(np.ones(p.size - int(p.wall)), n=p.n, kind="monodisperse", wall=p.wall)

    def describe(self) -> dict:
        rec = self._common()
        rec["wall"] = self._probe.wall
        return {**rec, **function_fingerprint(self.build_fn), "size": self._probe.size - int(self._probe.wall)}

    def label(self) -> str:
        return f"{self.kind} (a user's function), {self._probe.size - int(self._probe.wall)} granules"
