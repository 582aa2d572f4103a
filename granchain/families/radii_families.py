"""The families that draw every radius: :class:`RandomRadii` (polydisperse) and :class:`BinaryRandom`.

Both share :class:`_RadiiFamily`: one chain of ``size`` spheres, every granule observed, built
from the drawn radii (masses R^3, stiffnesses of Eq. r-prime) with the same functions as
:func:`granchain.from_radii`. No small-granule checks: the effective description does not apply.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from .._validate import count, exponent, finite_scalar
from ..model.chain import HERTZ, Chain, from_radii, sphere_mass, sphere_stiffness
from ..model.chainmodel import ChainModel
from ..model.distributions import as_distribution
from ..model.random import realization_rng
from .base import _RADIUS_UNITS, ChainFamily, RandomParameter, _flag
from .batch import ChainBatch, _add_wall, _stack


class _RadiiFamily(ChainFamily):
    """Shared by families that draw every radius: one chain of ``size`` spheres, every granule observed."""

    size: int

    @property
    def n_observed(self) -> int:
        return self.size

    @property
    def chains(self) -> tuple:
        return (self.kind,)

    def granule_coordinate(self) -> tuple:
        return np.arange(1, self.size + 1), "granule index (1-based, every granule observed)"

    def radii_of(self, params: dict) -> np.ndarray:
        """Radii (R, M) of stacked parameters."""
        raise NotImplementedError

    def build(self, params: dict, chain: str) -> ChainBatch:
        self._chain_name(chain)
        radii = self.radii_of(params)
        batch = ChainBatch(sphere_mass(radii), sphere_stiffness(radii), np.ones(radii.shape[0]), np.arange(self.size), self.n)
        batch = self._model_batch(batch, radii[:, 0])
        return _add_wall(batch, radii[:, -1]) if self.wall else batch

    def chain(self, seed: int, realization: int, chain: str | None = None) -> Chain:
        self._chain_name(chain)
        params = {k: np.asarray(v)[None] for k, v in self.draw(realization_rng(seed, realization)).items()}
        return self._model_chain(from_radii(self.radii_of(params)[0], n=self.n, kind=self.kind, wall=self.wall))


@dataclass(frozen=True)
class RandomRadii(_RadiiFamily):
    """A random polydisperse chain: all ``size`` radii i.i.d. from ``distribution`` (a
    :class:`granchain.Uniform`, :class:`granchain.Truncated` or frozen scipy.stats distribution;
    radii in units of a reference radius), every granule observed. No small-granule checks: the
    effective description does not apply."""

    size: int = 26
    distribution: object = None
    n: float = HERTZ
    wall: bool = False
    contact: object = None
    static_force: float = 0.0
    striker_mass: float | None = None
    model: ChainModel | None = field(default=None, repr=False, compare=False)

    kind: ClassVar[str] = "polydisperse"

    def __post_init__(self):
        object.__setattr__(self, "size", count("size", self.size, minimum=2))
        if self.distribution is None:
            raise ValueError("RandomRadii needs a radius distribution, e.g. granchain.Uniform(0.8, 1.2)")
        object.__setattr__(self, "distribution", as_distribution(self.distribution))
        object.__setattr__(self, "n", exponent(self.n))
        object.__setattr__(self, "wall", _flag("wall", self.wall))
        self._validate_model()

    def parameters(self) -> tuple:
        return (RandomParameter("radius", ("granule",), "float64", _RADIUS_UNITS, "radius of the granule"),)

    def draw(self, rng) -> dict:
        return {"radius": self.distribution.sample(rng, self.size)}

    def radii_of(self, params: dict) -> np.ndarray:
        return _stack(params, "radius")

    def describe(self) -> dict:
        return self._recorded({"family": self.kind, "size": self.size,
                               "distribution": self.distribution.describe(), "n": self.n})

    def label(self) -> str:
        return f"random polydisperse, M = {self.size}, radii {self.distribution.label()}{self.model.label()}"


@dataclass(frozen=True)
class BinaryRandom(_RadiiFamily):
    """Binary (diatomic) disorder: ``size`` granules, each of species b (radius ``radii[1]``) with
    probability ``p`` and of species a (``radii[0]``) otherwise, independently (cf. Ponson et al.,
    PRE 82, 021301 (2010)). The struck granule is random too. p = 0 and p = 1 are the two
    monodisperse chains."""

    size: int = 26
    radii: tuple = (1.0, 0.5)
    p: float = 0.5
    n: float = HERTZ
    wall: bool = False
    contact: object = None
    static_force: float = 0.0
    striker_mass: float | None = None
    model: ChainModel | None = field(default=None, repr=False, compare=False)

    kind: ClassVar[str] = "binary"

    def __post_init__(self):
        object.__setattr__(self, "size", count("size", self.size, minimum=2))
        try:
            ra, rb = (finite_scalar("radii", r, positive=True) for r in self.radii)
        except (TypeError, ValueError):
            raise ValueError(f"radii must be two positive radii (R_a, R_b), got {self.radii!r}") from None
        object.__setattr__(self, "radii", (ra, rb))
        p = finite_scalar("p", self.p)
        if not 0.0 <= p <= 1.0:
            raise ValueError(f"p = {p!r} is a probability (of species b): need 0 <= p <= 1")
        object.__setattr__(self, "p", p)
        object.__setattr__(self, "n", exponent(self.n))
        object.__setattr__(self, "wall", _flag("wall", self.wall))
        self._validate_model()

    def parameters(self) -> tuple:
        return (RandomParameter("species", ("granule",), "int8", "1", "species of the granule (0 = a, 1 = b)"),)

    def draw(self, rng) -> dict:
        return {"species": (rng.random(self.size) < self.p).astype(np.int8)}

    def radii_of(self, params: dict) -> np.ndarray:
        species = np.asarray(params["species"])
        species = species[None] if species.ndim == 1 else species
        return np.where(species == 1, self.radii[1], self.radii[0]).astype(float)

    def describe(self) -> dict:
        return self._recorded({"family": self.kind, "size": self.size, "radii": list(self.radii), "p": self.p,
                               "n": self.n})

    def label(self) -> str:
        return (f"binary random, M = {self.size}, radii {self.radii[0]:g}/{self.radii[1]:g}, p = {self.p:g}{self.model.label()}")
