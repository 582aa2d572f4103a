"""The decorated families: large granules with one random small granule in each gap.

:class:`RandomDecorated` (the paper's chain, unit large granules) and :class:`TaperedDecorated`
(large radii (1 - q)^(k-1)) share :class:`_Decorated`: the draw of the small radii, the batched
"decorated" chain and its "effective" chain of paper Sec. III A (Eqs. renorm-mass, effec-int), and
the default time grid from the BCA arrival time. TaperedDecorated also reads the records and the
signature of granchain <= 0.4, whose second argument was the ratio of successive large radii.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from .._validate import count, exponent, finite_scalar
from ..model.chain import HERTZ, Chain, decorated, sphere_mass, sphere_stiffness
from ..model.chainmodel import ChainModel
from ..model.distributions import small_radius_distribution
from ..model.effective import effective, effective_parameters
from ..model.random import realization_rng
from .base import _RADIUS_UNITS, ChainFamily, RandomParameter, _flag, _grid
from .batch import ChainBatch, _add_wall, _stack


class _Decorated(ChainFamily):
    """Shared by the decorated families: large granules (radii :meth:`large_radii`) with a random
    small granule in each gap; the exact "decorated" chain and its "effective" chain. (No fields
    here: a dataclass base would fix the positional order of its subclasses' fields.)"""

    n_large: int
    distribution: object
    momentum_conserving: bool

    def _validate(self, stacklevel: int) -> None:
        object.__setattr__(self, "n_large", count("n_large", self.n_large, minimum=2))
        dist = small_radius_distribution(self.distribution, what=f"the small-radius distribution of {type(self).__name__}",
                                         stacklevel=stacklevel + 1)
        object.__setattr__(self, "distribution", dist)
        object.__setattr__(self, "n", exponent(self.n))
        object.__setattr__(self, "momentum_conserving", bool(self.momentum_conserving))
        object.__setattr__(self, "wall", _flag("wall", self.wall))
        self._validate_model()

    def large_radii(self) -> np.ndarray:
        raise NotImplementedError

    def default_time_grid(self, dt: float = 0.1) -> np.ndarray:
        """To 1.1 x the BCA arrival time at granule N, + 10: the paper's slope 2.35 per large granule
        (Eq. slope, unit large granules) scaled by :meth:`arrival_ratio`."""
        t_end = 1.1 * 2.35 * (self.n_large - 1) * self.arrival_ratio() + 10.0
        return _grid(t_end, finite_scalar("dt", dt, positive=True))

    def arrival_ratio(self) -> float:
        """BCA arrival time at granule N of this family's effective chains over that of the same radius
        ratios between unit large granules (8 fixed sample realisations; exactly 1 without a taper)."""
        from .. import bca

        rng = np.random.default_rng(0)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ratios = self.distribution.sample(rng, (8, self.n_large - 1))
            own = bca.arrival_times(ratios * self.small_scale(), self.n, large_radii=self.large_radii())[:, -1]
            unit = bca.arrival_times(ratios, self.n)[:, -1]
        return float(own.sum() / unit.sum())

    def small_scale(self) -> np.ndarray:
        """What a drawn radius ratio is multiplied by to give gap j's small radius (N-1,)."""
        big = self.large_radii()
        return np.minimum(big[:-1], big[1:])

    @property
    def chains(self) -> tuple:
        return ("decorated", "effective")

    def character(self, chain: str) -> str:
        """The decorated chain's light granules set the step; its effective chain is smooth (see
        :meth:`ChainFamily.character`)."""
        super().character(chain)
        return "light granules" if chain == "decorated" else "smooth"

    @property
    def size(self) -> int:
        return 2 * self.n_large - 1

    @property
    def n_observed(self) -> int:
        return self.n_large

    def granule_coordinate(self) -> tuple:
        return np.arange(1, self.n_large + 1), "large-granule index k (decorated index 2k-1)"

    @property
    def n_contacts(self) -> int:
        return self.n_large - 1

    def contact_coordinate(self) -> tuple:
        return (np.arange(1, self.n_large),
                "contact q on the right of large granule q: decorated chain, between large granule q and small granule q "
                "(decorated indices 2q-1, 2q); effective chain, between granules q and q+1")

    def parameters(self) -> tuple:
        return (RandomParameter("small_radius", ("gap",), "float64", _RADIUS_UNITS,
                                "radius of the small granule between large granules j and j+1"),)

    def dims(self) -> dict:
        return {"gap": (np.arange(1, self.n_large), "small-granule index j (between large granules j and j+1)")}

    def draw(self, rng) -> dict:
        return {"small_radius": self.distribution.sample(rng, self.n_large - 1) * self.small_scale()}

    def build(self, params: dict, chain: str) -> ChainBatch:
        chain = self._chain_name(chain)
        small = _stack(params, "small_radius")
        R, G = small.shape
        big = np.broadcast_to(self.large_radii(), (R, G + 1))
        if chain == "decorated":
            radii = np.empty((R, 2 * G + 1))
            radii[:, 0::2] = big
            radii[:, 1::2] = small
            obs = np.arange(0, 2 * G + 1, 2)
            batch = ChainBatch(sphere_mass(radii), sphere_stiffness(radii), np.ones(R), obs, self.n, obs[:-1])
        else:
            mu, c_eff = effective_parameters(big, small, self.n)  # Eqs. (renorm-mass), (effec-int)
            # As granchain.effective: velocity 1, or m_1 v_1 / mu_1 (momentum-conserving).
            v0 = sphere_mass(big[:, 0]) * 1.0 / mu[:, 0] if self.momentum_conserving else np.ones(R)
            batch = ChainBatch(mu, c_eff, v0, np.arange(G + 1), self.n, np.arange(G))
        batch = self._model_batch(batch, big[:, 0])
        return _add_wall(batch, big[:, -1]) if self.wall else batch

    def chain(self, seed: int, realization: int, chain: str | None = None) -> Chain:
        chain = self._chain_name(chain)
        small = self.draw(realization_rng(seed, realization))["small_radius"]
        exact = decorated(small, large_radius=self.large_radii(), n=self.n, wall=self.wall)
        # The effective chain carries the same real contacts: its renormalisation (paper Sec. III A) is
        # derived for elastic, unloaded contacts, so with them it is a model to compare, not a theorem.
        return self._model_chain(exact if chain == "decorated" else effective(exact, momentum_conserving=self.momentum_conserving))


@dataclass(frozen=True)
class RandomDecorated(_Decorated):
    """The paper's chain: N large granules of radius 1, and between each pair a small granule whose
    radius is drawn i.i.d. from ``distribution`` (default U[0.01, 0.4], paper Sec. IV).

    Chains: "decorated" (2N-1 granules, the large ones observed) and "effective" (N granules,
    Eqs. renorm-mass, effec-int, zetak). ``momentum_conserving`` gives the effective chain's
    granule 1 the velocity m_1 v_1 / mu_1 instead of 1 (see :func:`granchain.effective`).
    Warns (:class:`granchain.EffectiveValidityWarning`) if the distribution reaches beyond 0.4.
    """

    n_large: int = 26
    distribution: object = None
    n: float = HERTZ
    momentum_conserving: bool = False
    wall: bool = False
    contact: object = None
    static_force: float = 0.0
    striker_mass: float | None = None
    model: ChainModel | None = field(default=None, repr=False, compare=False)

    kind: ClassVar[str] = "decorated"

    def __post_init__(self):
        self._validate(stacklevel=3)

    def large_radii(self) -> np.ndarray:
        return np.ones(self.n_large)

    def describe(self) -> dict:
        return self._recorded({"family": self.kind, "n_large": self.n_large,
                               "distribution": self.distribution.describe(), "n": self.n,
                               "momentum_conserving": self.momentum_conserving})

    def label(self) -> str:
        return f"random decorated, N = {self.n_large}, small radii {self.distribution.label()}{self.model.label()}"

    def arrival_ratio(self) -> float:
        return 1.0


#: How a TaperedDecorated record says which q it holds (records of granchain <= 0.4 held the ratio).
_TAPER = "(1 - q)^(k-1)"


def _q_of_ratio(ratio: float) -> float:
    """q = 1 - ratio as the number a person would write (0.1 for the ratio 0.9, not 0.09999999999999998),
    provided 1 - q gives the ratio back bitwise, so the chain is the one the ratio built; else 1 - ratio."""
    q = float(f"{1.0 - ratio:.15g}")
    return q if 1.0 - q == ratio else 1.0 - ratio


@dataclass(frozen=True, init=False)
class TaperedDecorated(_Decorated):
    """A tapered decorated chain: large radii (1 - q)^(k-1), k = 1..N, the convention of
    :func:`granchain.tapered` (each large granule a fraction q smaller than the one before, the
    tapered chains of the paper's Sec. I): q = 0 is :class:`RandomDecorated` bitwise, q > 0
    shrinks, q < 0 grows. In gap j a small granule of radius
    X_j min(R_j, R_{j+1}), X_j i.i.d. from ``distribution``: the distribution is that of the ratio of
    the small radius to its smaller neighbour, the ratio that decides the effective description's
    validity.

    The effective chain uses Eq. (renorm-mass) with the local large masses and the two-contacts-in-
    series interaction for unequal neighbours (:func:`granchain.effective_parameters`).

    ``q`` is keyword-only. Up to granchain 0.4 the second argument was the ratio of successive
    large radii (radii ratio^(k-1), untapered at 1); a positional second argument, or ``ratio=``,
    is still read that way, with a DeprecationWarning, so that old code never silently builds
    another chain: ``TaperedDecorated(26, 0.95)`` is ``TaperedDecorated(26, q=0.05)``. Stores
    written by those versions record the ratio and are read as such.
    """

    n_large: int = 26
    q: float = 0.05
    distribution: object = None
    n: float = HERTZ
    momentum_conserving: bool = False
    wall: bool = False
    contact: object = None
    static_force: float = 0.0
    striker_mass: float | None = None
    model: ChainModel | None = field(default=None, repr=False, compare=False)

    kind: ClassVar[str] = "tapered-decorated"

    def __init__(self, n_large: int = 26, *args, q: float | None = None, distribution=None, n: float = HERTZ,
                 momentum_conserving: bool = False, wall: bool = False, ratio: float | None = None, contact=None,
                 static_force: float = 0.0, striker_mass: float | None = None, model: ChainModel | None = None):
        if len(args) > 5:
            raise TypeError(f"TaperedDecorated takes at most 6 positional arguments, got {1 + len(args)}")
        if args:  # the signature of granchain <= 0.4: (n_large, ratio, distribution, n, momentum_conserving, wall)
            old = dict(zip(("ratio", "distribution", "n", "momentum_conserving", "wall"), args))
            if "distribution" in old and distribution is not None:
                raise TypeError("TaperedDecorated got the distribution both by position and by keyword")
            ratio = old.pop("ratio") if ratio is None else ratio
            distribution = old.pop("distribution", distribution)
            n, momentum_conserving, wall = old.get("n", n), old.get("momentum_conserving", momentum_conserving), old.get("wall", wall)
        if ratio is not None:
            if q is not None:
                raise ValueError("give q (large radii (1 - q)^(k-1)) or the deprecated ratio (radii ratio^(k-1)), not both")
            ratio = finite_scalar("ratio", ratio, positive=True)
            warnings.warn(f"TaperedDecorated's second argument is now q, the fraction by which each large radius "
                          f"shrinks (radii (1 - q)^(k-1), as in granchain.tapered); the ratio {ratio:g} you passed "
                          f"is read as q = 1 - {ratio:g}. Write TaperedDecorated({n_large}, q={1.0 - ratio:.6g}, ...)",
                          DeprecationWarning, stacklevel=2)
            q = _q_of_ratio(ratio)
        for name, value in (("n_large", n_large), ("q", 0.05 if q is None else q), ("distribution", distribution), ("n", n),
                            ("momentum_conserving", momentum_conserving), ("wall", wall), ("contact", contact),
                            ("static_force", static_force), ("striker_mass", striker_mass), ("model", model)):
            object.__setattr__(self, name, value)
        self.__post_init__()

    def __post_init__(self):
        q = finite_scalar("q", self.q)
        if not q < 1.0:
            raise ValueError(f"q = {q:g} must be < 1: the large radii are (1 - q)^(k-1) (q = 0 untapered, q > 0 shrinking, "
                             "q < 0 growing; before granchain 0.5 this argument was the ratio 1 - q)")
        object.__setattr__(self, "q", q)
        self._validate(stacklevel=4)
        span = (1.0 - q) ** (self.n_large - 1)
        if span < 1e-3 or span > 1e3:
            raise ValueError(f"q = {q:g} over {self.n_large} large granules spans radii {span:.3g}..1: choose q closer to 0 "
                             "(radii within a factor 1000; before granchain 0.5 this argument was the ratio 1 - q)")

    def large_radii(self) -> np.ndarray:
        return (1.0 - self.q) ** np.arange(self.n_large, dtype=float)

    def describe(self) -> dict:
        return self._recorded({"family": self.kind, "n_large": self.n_large, "q": self.q, "large_radii": _TAPER,
                               "distribution": self.distribution.describe(), "n": self.n,
                               "momentum_conserving": self.momentum_conserving})

    def label(self) -> str:
        return (f"tapered decorated, N = {self.n_large}, q = {self.q:g}, small/large ratio {self.distribution.label()}"
                f"{self.model.label()}")
