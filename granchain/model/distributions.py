"""Distributions of the small-granule radius (in units of the large radius).

The paper draws the small radii uniformly on [alpha, beta] (Sec. IV, alpha =
0.01, beta = 0.4) and notes that its results hold for any distribution on which
the effective description is valid (Sec. V). The same objects serve any random
radius (e.g. every radius of a polydisperse chain, :class:`granchain.RandomRadii`);
the small-granule checks (radius <= 1, the effective-validity warning above 0.4)
are made where radii are used as *small* granules (:func:`small_radius_distribution`:
decorated families and the BCA). Three classes:

* :class:`Uniform` - the paper's case, with closed forms where the theory has them;
* :class:`Truncated` - any ``scipy.stats`` continuous distribution truncated to a
  sub-interval of (0, 1), sampled by inverse transform.

* :class:`Mixture` - a finite mixture of these (e.g. a bimodal law).

All expose ``support``, ``pdf``, ``cdf``, ``ppf``, ``sample(rng, size)``,
``expect(func)`` (quadrature over the support) and ``describe()`` (a JSON-able
record for file attributes and run-parameter checks).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np
from scipy import integrate

from .._validate import EFFECTIVE_VALIDITY_LIMIT, finite_scalar, warn_effective_validity

__all__ = ["Uniform", "Truncated", "Mixture", "as_distribution", "distribution_from_record", "small_radius_distribution"]


class _Base:
    support: tuple[float, float]

    def expect(self, func) -> float:
        """E[func(R)] by adaptive quadrature over the support."""
        lo, hi = self.support
        val, _ = integrate.quad(lambda r: func(r) * self.pdf(r), lo, hi, epsabs=0.0, epsrel=1e-12, limit=200)
        return float(val)

    def sample(self, rng: np.random.Generator, size) -> np.ndarray:
        """Radii by inverse transform of ``rng.random(size)`` (one uniform per radius)."""
        return self.ppf(rng.random(size))

    def key(self) -> str:
        """Canonical string of ``describe()``, for comparing run parameters."""
        return json.dumps(self.describe(), sort_keys=True)


@dataclass(frozen=True)
class Uniform(_Base):
    """Radii uniform on [alpha, beta], 0 < alpha < beta (paper Sec. IV; small radii need beta <= 1)."""

    alpha: float = 0.01
    beta: float = 0.4

    def __post_init__(self):
        a = finite_scalar("alpha", self.alpha)
        b = finite_scalar("beta", self.beta)
        if a <= 0.0:
            raise ValueError(f"alpha = {a!r} must be > 0 (a small granule needs a positive radius)")
        if a >= b:
            raise ValueError(f"alpha = {a!r} must be < beta = {b!r}")
        object.__setattr__(self, "alpha", a)
        object.__setattr__(self, "beta", b)

    @property
    def support(self) -> tuple[float, float]:
        return (self.alpha, self.beta)

    def pdf(self, r):
        r = np.asarray(r, dtype=float)
        return np.where((r >= self.alpha) & (r <= self.beta), 1.0 / (self.beta - self.alpha), 0.0)

    def cdf(self, r):
        r = np.asarray(r, dtype=float)
        return np.clip((r - self.alpha) / (self.beta - self.alpha), 0.0, 1.0)

    def ppf(self, u):
        return self.alpha + (self.beta - self.alpha) * np.asarray(u, dtype=float)

    def label(self) -> str:
        return f"U[{self.alpha:g}, {self.beta:g}]"

    def describe(self) -> dict:
        return {"name": "uniform", "alpha": self.alpha, "beta": self.beta}


@dataclass(frozen=True, eq=False)
class Truncated(_Base):
    """A frozen ``scipy.stats`` continuous distribution truncated to [lower, upper].

    ``lower``/``upper`` default to (0, 1) (``0 <= lower < upper``; small radii need
    ``upper <= 1``); the distribution must put positive probability on the interval. Example::

        Truncated(scipy.stats.beta(2, 8), upper=0.4)
        Truncated(scipy.stats.lognorm(0.5, scale=0.1))
    """

    dist: object
    lower: float = 0.0
    upper: float = 1.0
    _mass: tuple = field(init=False, repr=False)

    def __post_init__(self):
        if not (hasattr(self.dist, "ppf") and hasattr(self.dist, "cdf") and hasattr(self.dist, "pdf")):
            raise ValueError(
                "dist must be a frozen scipy.stats continuous distribution, e.g. scipy.stats.beta(2, 8); "
                f"got {self.dist!r}"
            )
        lo = finite_scalar("lower", self.lower)
        hi = finite_scalar("upper", self.upper)
        if not (0.0 <= lo < hi):
            raise ValueError(f"need 0 <= lower < upper for radii, got lower = {lo!r}, upper = {hi!r}")
        f_lo, f_hi = float(self.dist.cdf(lo)), float(self.dist.cdf(hi))
        if not f_hi > f_lo:
            raise ValueError(
                f"{self._dist_name()} puts no probability on [{lo:g}, {hi:g}]: choose a distribution "
                "with mass on the small-radius interval"
            )
        object.__setattr__(self, "lower", lo)
        object.__setattr__(self, "upper", hi)
        object.__setattr__(self, "_mass", (f_lo, f_hi))

    def _dist_name(self) -> str:
        return getattr(getattr(self.dist, "dist", None), "name", type(self.dist).__name__)

    @property
    def support(self) -> tuple[float, float]:
        d_lo, d_hi = (float(s) for s in self.dist.support())
        return (max(self.lower, d_lo), min(self.upper, d_hi))

    def pdf(self, r):
        r = np.asarray(r, dtype=float)
        f_lo, f_hi = self._mass
        inside = (r >= self.lower) & (r <= self.upper)
        return np.where(inside, self.dist.pdf(r) / (f_hi - f_lo), 0.0)

    def cdf(self, r):
        f_lo, f_hi = self._mass
        r = np.clip(np.asarray(r, dtype=float), self.lower, self.upper)
        return np.clip((self.dist.cdf(r) - f_lo) / (f_hi - f_lo), 0.0, 1.0)

    def ppf(self, u):
        f_lo, f_hi = self._mass
        r = self.dist.ppf(f_lo + (f_hi - f_lo) * np.asarray(u, dtype=float))
        # Guard the open ends against round-off and a radius of exactly zero.
        lo, hi = self.support
        return np.clip(r, np.nextafter(max(lo, 0.0), 1.0), hi)

    def label(self) -> str:
        return f"{self._dist_name()}{tuple(self.dist.args)} truncated to [{self.lower:g}, {self.upper:g}]"

    def describe(self) -> dict:
        kwds = {k: float(v) for k, v in getattr(self.dist, "kwds", {}).items()}
        return {
            "name": f"truncated {self._dist_name()}",
            "args": [float(a) for a in getattr(self.dist, "args", ())],
            "kwds": kwds,
            "lower": self.lower,
            "upper": self.upper,
        }

    def __eq__(self, other):
        return isinstance(other, Truncated) and self.key() == other.key()

    def __hash__(self):
        return hash(self.key())


@dataclass(frozen=True, eq=False)
class Mixture(_Base):
    """A finite mixture sum_i w_i p_i(r) of granchain distributions (e.g. a bimodal law of two
    :class:`Truncated` normals). Weights are normalised to sum 1. ``ppf`` inverts the mixture's cdf
    by bisection to machine precision (64 halvings of the support), so ``sample`` stays one
    uniform per radius, like the other distributions. A bimodal law on [0.01, 0.4]:
    ``Mixture((Truncated(stats.norm(0.05, 0.02), 0.01, 0.4), Truncated(stats.norm(0.35, 0.02), 0.01, 0.4)))``.
    """

    components: tuple
    weights: tuple = None

    def __post_init__(self):
        comps = tuple(as_distribution(c) for c in self.components)
        if not comps:
            raise ValueError("components must hold at least one distribution, e.g. (Uniform(0.01, 0.1), Uniform(0.3, 0.4))")
        w = np.ones(len(comps)) if self.weights is None else np.asarray(self.weights, dtype=float).reshape(-1)
        if w.size != len(comps) or not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
            raise ValueError(f"weights must be {len(comps)} finite non-negative numbers with a positive sum, got {self.weights!r}")
        object.__setattr__(self, "components", comps)
        object.__setattr__(self, "weights", tuple(float(x) for x in w / w.sum()))

    @property
    def support(self) -> tuple[float, float]:
        los, his = zip(*(c.support for c in self.components))
        return (min(los), max(his))

    def pdf(self, r):
        return sum(w * c.pdf(r) for w, c in zip(self.weights, self.components))

    def cdf(self, r):
        return sum(w * c.cdf(r) for w, c in zip(self.weights, self.components))

    def ppf(self, u):
        u = np.asarray(u, dtype=float)
        lo, hi = self.support
        a, b = np.full(u.shape, lo), np.full(u.shape, hi)
        for _ in range(64):  # bisection: the cdf is monotone; 64 halvings reach double precision
            mid = 0.5 * (a + b)
            below = self.cdf(mid) < u
            a = np.where(below, mid, a)
            b = np.where(below, b, mid)
        return np.clip(0.5 * (a + b), np.nextafter(max(lo, 0.0), 1.0), hi)

    def label(self) -> str:
        return "mixture(" + " + ".join(f"{w:g} {c.label()}" for w, c in zip(self.weights, self.components)) + ")"

    def describe(self) -> dict:
        return {"name": "mixture", "weights": list(self.weights), "components": [c.describe() for c in self.components]}

    def __eq__(self, other):
        return isinstance(other, Mixture) and self.key() == other.key()

    def __hash__(self):
        return hash(self.key())


def as_distribution(dist=None, *, alpha: float | None = None, beta: float | None = None):
    """Normalise the ways a caller may name a small-radius distribution.

    ``None`` gives the paper's U[0.01, 0.4] (or U[alpha, beta] if given); a
    granchain distribution passes through; a frozen scipy.stats distribution is
    truncated to (0, 1).
    """
    if dist is None:
        return Uniform(0.01 if alpha is None else alpha, 0.4 if beta is None else beta)
    if alpha is not None or beta is not None:
        raise ValueError("give either dist or alpha/beta, not both")
    if isinstance(dist, (Uniform, Truncated, Mixture)):
        return dist
    return Truncated(dist)


def small_radius_distribution(dist=None, *, what: str = "the small-radius distribution", stacklevel: int = 1):
    """``as_distribution(dist)`` checked for use as *small* radii (decorated chains, the BCA).

    Refuses a support beyond 1 (a "small" granule larger than the large ones) and warns
    (:class:`granchain.EffectiveValidityWarning`) when it puts mass above 0.4, where the
    effective description stops being valid (paper Sec. III A). The warning is attributed
    to the frame ``stacklevel`` levels up (1: the caller of this function).
    """
    d = as_distribution(dist)
    lo, hi = d.support
    if hi > 1.0:
        raise ValueError(
            f"{what} {d.label()} reaches radius {hi:g} > 1: small granules must be no larger than the large "
            "ones (radii are in units of the large radius); truncate it to <= 1, e.g. Truncated(dist, upper=0.4)"
        )
    if hi > EFFECTIVE_VALIDITY_LIMIT and float(d.cdf(EFFECTIVE_VALIDITY_LIMIT)) < 1.0:
        warn_effective_validity(hi, what=f"{what} {d.label()}", stacklevel=stacklevel + 2)
    return d


def distribution_from_record(record: dict):
    """The distribution a stored ``describe()`` record names (inverse of ``describe``)."""
    name = record.get("name", "")
    if name == "uniform":
        return Uniform(record["alpha"], record["beta"])
    if name.startswith("truncated "):
        from scipy import stats

        dist = getattr(stats, name[len("truncated "):], None)
        if dist is None:
            raise ValueError(f"the stored distribution {name!r} is not a scipy.stats distribution here")
        return Truncated(dist(*record.get("args", ()), **record.get("kwds", {})), record["lower"], record["upper"])
    if name == "mixture":
        return Mixture(tuple(distribution_from_record(c) for c in record["components"]), tuple(record["weights"]))
    raise ValueError(f"cannot rebuild the stored distribution {record!r}")
