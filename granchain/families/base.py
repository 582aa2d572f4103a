"""The contract every chain family keeps: :class:`ChainFamily` and :class:`RandomParameter`.

:class:`ChainFamily` is the base class the ensemble runner, the store, the readers and the figures
see: the one seam for a new kind of random chain (the concrete families live in
``decorated_families``, ``radii_families`` and ``custom``). It also holds what every family
shares: its physics as one value, ``family.model`` (a :class:`granchain.ChainModel`: contact law, static
load, striker, wall), and how it enters a record, a batch and a single chain; drawing a batch of
realisations from
``realization_rng(seed, i)``; the default time grid. :class:`RandomParameter` describes one
per-realisation random parameter as the store holds it.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from .._validate import finite_scalar
from ..model.chain import Chain
from ..model.chainmodel import ChainModel
from ..model.random import realization_rng
from .batch import ChainBatch, _add_striker

_RADIUS_UNITS = "radius"  # rescaled: in units of the reference (large) granule's radius


@dataclass(frozen=True)
class RandomParameter:
    """One random parameter a family draws per realisation (a store variable).

    ``dims`` are its dimensions after ``realization`` (each named in the family's
    :meth:`ChainFamily.dims`); ``dtype`` a NumPy dtype name; ``units`` a units string pint parses
    (``"1"``) or, for a rescaled quantity, its kind (a key of :data:`granchain.units.RESCALED`:
    ``"radius"``, ``"mass"``, ``"velocity"``), stored as units "1" with what it counts.
    """

    name: str
    dims: tuple
    dtype: str
    units: str
    long_name: str


class ChainFamily:
    """Base of every chain family (see the module docstring for the contract).

    Subclasses are frozen dataclasses with a class attribute ``kind`` (the registry and
    CLI name) and implement :meth:`parameters`, :meth:`dims`, :meth:`draw`,
    :meth:`build`, :meth:`chain`, :meth:`describe` and the properties :attr:`chains`,
    :attr:`size`, :attr:`n_observed` and :meth:`granule_coordinate`.

    The chains' physics is one value, the field ``model`` (a :class:`granchain.ChainModel`): the contact
    law (None: ``PowerLaw(n)``, the paper's; or another ``granchain.model.contacts.ContactLaw``), the static
    load (the precompression F0, 0: none), the striker (None: granule 1 struck with velocity 1; else a free
    sphere of that mass, rescaled, struck instead, one material) and the wall. The concrete families also
    take its parts as keywords (``contact``, ``static_force``, ``striker_mass``, ``wall``) and keep them as
    fields, read from the model.
    """

    kind: ClassVar[str]
    n: float
    wall: bool = False  # (class defaults; the concrete families have these fields)
    contact: object = None
    static_force: float = 0.0
    striker_mass: float | None = None
    model: ChainModel | None = None

    # -- the chains' physics --------------------------------------------------------------
    def _validate_model(self) -> None:
        """Make ``model`` the family's :class:`granchain.ChainModel` (checked for its exponent n) from ``model=``
        and the keywords ``contact``, ``static_force``, ``striker_mass``, ``wall``: a keyword left at its default
        takes the model's value; one given with another value than the model's is refused."""
        keywords = ChainModel(self.contact, self.static_force, self.striker_mass, self.wall).for_exponent(self.n)
        model = keywords
        if self.model is not None:
            if not isinstance(self.model, ChainModel):
                raise ValueError(f"model must be a granchain.ChainModel (contact law, static load, striker, wall) or None, "
                                 f"got {self.model!r}")
            model = self.model.for_exponent(self.n)
            default = ChainModel()
            clash = [name for name in ("contact", "static_force", "striker_mass", "wall")
                     if getattr(keywords, name) != getattr(default, name) and getattr(keywords, name) != getattr(model, name)]
            if clash:
                raise ValueError(f"{type(self).__name__} got {', '.join(clash)} both in model= and as keywords, with other "
                                 "values: give each once")
        for name in ("contact", "static_force", "striker_mass", "wall"):
            object.__setattr__(self, name, getattr(model, name))
        object.__setattr__(self, "model", model)

    @property
    def contact_law(self):
        """The chains' contact law (``PowerLaw(n)`` unless another one was given)."""
        return self.model.law(self.n)

    @property
    def elastic(self) -> bool:
        """The paper's contacts: no damping, no static load, no striker."""
        return self.model.elastic

    def _recorded(self, record: dict) -> dict:
        """A :meth:`describe` record with the model's parts that differ from the paper's chain (records of the
        paper's chains stay as before, so their stores resume unchanged; a store resumed with other
        contact settings is refused with the difference)."""
        return {**record, **self.model.record()}

    def _model_batch(self, batch: ChainBatch, first_radius) -> ChainBatch:
        """The batch with the family's striker (before its wall, if any: call this first)."""
        return batch if self.striker_mass is None else _add_striker(batch, self.striker_mass, first_radius)

    def _model_chain(self, chain: Chain) -> Chain:
        """One chain with the family's real contacts (bitwise a row of :meth:`build`)."""
        return self.model.apply(chain)

    # -- what the family is -------------------------------------------------------------
    @property
    def chains(self) -> tuple:
        """Names of the chains the family builds for one realisation (first: the exact chain)."""
        raise NotImplementedError

    def character(self, chain: str) -> str:
        """What the family's ``chain`` kind is like for an integrator, which picks its default method and
        tolerances (``granchain.solve.defaults``): "light granules" (light granules between heavy ones set
        the step: the paper's decorated chains), "smooth" (masses that change slowly, no light granules:
        the effective chains) or "reflecting" (masses that jump at random along the chain, whose reflected
        waves give granules their peak after the front has passed). This one: "reflecting", the safe
        choice for any chain (a tighter tolerance, no relaxed zone); a family of other chains says so."""
        if chain not in self.chains:
            raise ValueError(f"{type(self).__name__} builds the chains {list(self.chains)}, not {chain!r}")
        return "reflecting"

    @property
    def size(self) -> int:
        """Granules M of the exact chain."""
        raise NotImplementedError

    @property
    def n_observed(self) -> int:
        """Observed granules K (the store's ``granule`` dimension), the same for every chain."""
        raise NotImplementedError

    def granule_coordinate(self) -> tuple:
        """(values, long_name) of the store's ``granule`` coordinate."""
        raise NotImplementedError

    @property
    def n_contacts(self) -> int:
        """Contacts C whose peak forces the store records (its ``contact`` dimension), the same for
        every chain of the family: every contact between granules (not a wall's) by default."""
        return self.size - 1

    def contact_coordinate(self) -> tuple:
        """(values, long_name) of the store's ``contact`` coordinate."""
        return np.arange(1, self.n_contacts + 1), "contact q between granules q and q+1 (1-based; every contact)"

    def parameters(self) -> tuple:
        """The :class:`granchain.families.RandomParameter` records of what :meth:`draw` returns."""
        raise NotImplementedError

    def dims(self) -> dict:
        """Extra dimensions of the parameters: name -> (coordinate values, long_name)."""
        return {}

    def dim_sizes(self) -> dict:
        """Sizes of every dimension a parameter may use: ``granule`` (the observed granules) and :meth:`dims`."""
        return {"granule": self.n_observed, **{d: len(values) for d, (values, _) in self.dims().items()}}

    def describe(self) -> dict:
        """JSON-able record of the family (stored with ensembles; see :func:`family_from_record`)."""
        raise NotImplementedError

    def label(self) -> str:
        """A one-line description for titles and progress bars."""
        return self.kind

    # -- realisations -------------------------------------------------------------------
    def draw(self, rng: np.random.Generator) -> dict:
        """The random parameters of one realisation from its generator."""
        raise NotImplementedError

    def draw_batch(self, seed: int, realizations) -> dict:
        """Parameters of realisations ``realizations`` (each from ``realization_rng(seed, i)``), stacked."""
        idx = np.atleast_1d(np.asarray(realizations, dtype=np.int64))
        sizes = self.dim_sizes()
        out = {p.name: np.empty((idx.size,) + tuple(sizes[d] for d in p.dims), dtype=p.dtype) for p in self.parameters()}
        for row, i in enumerate(idx):
            for name, value in self.draw(realization_rng(seed, i)).items():
                out[name][row] = value
        return out

    def build(self, params: dict, chain: str) -> ChainBatch:
        """The batch of chains ``chain`` (one of :attr:`chains`) for stacked ``params``."""
        raise NotImplementedError

    def chain(self, seed: int, realization: int, chain: str | None = None) -> Chain:
        """Realisation ``realization`` under ``seed`` as a :class:`~granchain.Chain` (default: the exact
        chain), built with the public single-chain builders; bitwise a row of :meth:`build`."""
        raise NotImplementedError

    def _chain_name(self, chain: str | None) -> str:
        chain = self.chains[0] if chain is None else chain
        if chain not in self.chains:
            raise ValueError(f"{type(self).__name__} builds the chains {list(self.chains)}, not {chain!r}")
        return chain

    def default_time_grid(self, dt: float = 0.1) -> np.ndarray:
        """Times of the averaged pulse: 0 to 1.3 x the BCA arrival time at the last observed granule
        (the largest over 8 fixed sample realisations) + 10."""
        from .. import bca

        dt = finite_scalar("dt", dt, positive=True)
        t_arrival = 0.0
        for i in range(8):
            ch = self.chain(0, i)
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    t_arrival = max(t_arrival, float(bca.travel_times(ch).arrival_time[-1]))
            except ValueError:  # n <= 2: no binary-collision estimate; ~2.5 time units per granule
                t_arrival = max(t_arrival, 2.5 * ch.size)
        return _grid(1.3 * t_arrival + 10.0, dt)


def _flag(name: str, value) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def _grid(t_end: float, dt: float) -> np.ndarray:
    return np.round(np.arange(0.0, t_end + 0.5 * dt, dt), 12)
