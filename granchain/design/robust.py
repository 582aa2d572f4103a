"""Robust design of a random decoration: designs judged over common realisations."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import count, finite_scalar
from ..model.chain import HERTZ, Chain, from_radii, sphere_mass
from ..model.distributions import Uniform
from ..model.random import realization_rng
from .space import Constraints, DesignSpace, _bounds, _init

__all__ = ["RandomDecoratedSpace"]


@dataclass(frozen=True, init=False)
class RandomDecoratedSpace(DesignSpace):
    """Robust design of a random decoration: ``n_large`` large granules of radius 1 and in each gap a
    small granule of radius drawn i.i.d. from U[alpha, beta] (the paper's distribution, Sec. IV); the
    parameters are alpha and beta. A design's value is a statistic (mean, or a quantile) of the
    objective over ``realizations`` realisations, and every design is evaluated on the *same*
    realisations (common random numbers): realisation i's small radii are
    ``Uniform(alpha, beta).sample(realization_rng(seed, i), N - 1)``, exactly those
    :class:`granchain.RandomDecorated` draws in :func:`granchain.run_ensemble` with the same seed, so
    that a comparison of two designs is not blurred by independent draws.

    ``min_width``: the smallest beta - alpha allowed (a constraint: alpha < beta)."""

    n_large: int = 10
    seed: int = 0
    min_width: float = 0.01

    def __init__(self, n_large: int = 10, alpha=(0.01, 0.3), beta=(0.05, 0.4), *, realizations: int = 64, seed: int = 0,
                 min_width: float = 0.01, wall: bool = True, n: float = HERTZ, constraints: Constraints | None = None):
        a_lo, a_hi = _bounds("alpha", alpha)
        b_lo, b_hi = _bounds("beta", beta)
        if a_lo <= 0 or b_hi > 1:
            raise ValueError(f"small radii must lie in (0, 1]: alpha >= {a_lo:g} and beta <= {b_hi:g} must satisfy 0 < alpha, beta <= 1")
        min_width = finite_scalar("min_width", min_width, positive=True)
        if a_lo + min_width > b_hi:
            raise ValueError(f"no design has alpha + {min_width:g} <= beta within alpha in ({a_lo:g}, {a_hi:g}) and beta in "
                             f"({b_lo:g}, {b_hi:g}): raise the upper bound of beta or lower that of alpha")
        object.__setattr__(self, "n_large", count("n_large", n_large, minimum=2))
        object.__setattr__(self, "realizations", count("realizations", realizations, minimum=2))
        object.__setattr__(self, "seed", count("seed", seed, minimum=0))
        object.__setattr__(self, "min_width", min_width)
        object.__setattr__(self, "chain_kind", "decorated")
        _init(self, ("alpha", "beta"), [a_lo, b_lo], [a_hi, b_hi], wall=wall, n=n, constraints=constraints,
              kind="random-decorated")
        # One uniform per gap and realisation, drawn once: the common random numbers of every design.
        u = np.stack([realization_rng(self.seed, i).random(self.n_large - 1) for i in range(self.realizations)])
        u.setflags(write=False)
        object.__setattr__(self, "_uniforms", u)

    def family(self, params):
        """The :class:`granchain.RandomDecorated` family of one design (for :func:`granchain.run_ensemble`
        with ``seed=self.seed``: the same realisations)."""
        from ..families import RandomDecorated

        p = self.params(params)
        return RandomDecorated(self.n_large, Uniform(p["alpha"], p["beta"]), n=self.n, wall=self.wall)

    def small_radii(self, X) -> np.ndarray:
        """(P, R, N-1) small radii of P designs on the common realisations (the inverse transform
        Uniform(alpha, beta).ppf(u), as :class:`granchain.Uniform` samples)."""
        X = self.as_array(X)
        return np.stack([Uniform(a, b).ppf(self._uniforms) if a < b else np.full(self._uniforms.shape, a)
                         for a, b in X])

    def radii(self, X) -> np.ndarray:
        """(P * R, 2N-1): realisation r of design p in row p * R + r."""
        small = self.small_radii(X).reshape(-1, self.n_large - 1)
        radii = np.ones((small.shape[0], 2 * self.n_large - 1))
        radii[:, 1::2] = small
        return radii

    def observed(self, size: int) -> np.ndarray:
        return np.arange(0, size, 2)

    def violation(self, X) -> np.ndarray:
        X = self.as_array(X)
        width = (X[:, 0] + self.min_width - X[:, 1]) / self.min_width  # alpha + min_width <= beta
        if not self.constraints.active:
            return width
        radii = self.radii(X)
        per = self.constraints.violation(radii, sphere_mass(radii)).reshape(X.shape[0], self.realizations).max(axis=1)
        return np.maximum(width, per)

    def chain(self, params, realization: int = 0) -> Chain:
        """Realisation ``realization`` of one design (the row of :meth:`DesignSpace.batch`)."""
        X = self.as_array(params)[:1]
        b = self.batch(X)
        radii = self.radii(X)[realization]
        if self.wall:
            radii = np.append(radii, np.inf)
        return Chain(b.masses[realization], b.stiffness[realization], self.n, 1.0, b.observed, radii,
                     "design-random-decorated", {"design": self.params(X), "realization": realization})

    def reference_chain(self) -> Chain:
        return from_radii(np.ones(2 * self.n_large - 1), n=self.n, kind="monodisperse", wall=self.wall)

    def describe(self) -> dict:
        return {**self._common(), "n_large": self.n_large, "distribution": "uniform(alpha, beta)",
                "realizations": self.realizations, "seed": self.seed, "min_width": self.min_width}

    def label(self) -> str:
        return f"random decorated U[alpha, beta], {self.n_large} large granules, {self.realizations} realisations"
