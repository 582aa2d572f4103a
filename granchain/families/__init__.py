"""Chain families: how realisation i of an ensemble becomes a chain.

An ensemble (:func:`granchain.run_ensemble`) is a *family* of random chains of one
size. A family says

* which random parameters realisation i draws from its generator
  ``realization_rng(seed, i)`` (:meth:`ChainFamily.parameters`, :meth:`ChainFamily.draw`, :class:`RandomParameter`;
  they are stored per realisation, so any row of a store can be rebuilt);
* how a batch of those parameters becomes the one chain representation, batched
  (:meth:`ChainFamily.build`: masses, stiffnesses, initial velocities, observed granules),
  with the same functions the single-chain builders use, so that a row is bitwise the
  :class:`~granchain.Chain` of :meth:`ChainFamily.chain`;
* which chains it can build: the exact chain and, for decorated families, the effective
  chain of paper Sec. III A (:attr:`ChainFamily.chains`);
* its record for the store (:meth:`ChainFamily.describe`; :func:`family_from_record`
  rebuilds it).

Families: :class:`RandomDecorated` (the paper's chain), :class:`TaperedDecorated`,
:class:`RandomRadii` (polydisperse), :class:`BinaryRandom` (two species) and
:class:`CustomFamily` (a user's function). Every family but the custom one takes
``wall=True``: its chains then end in a fixed wall (a last granule of infinite mass,
:meth:`granchain.Chain.with_wall`), how protectors are tested; the free end is the
default. Every family but the custom one also takes the real contacts of
``granchain.model.contacts``: ``contact=granchain.Viscoelastic(gamma)`` (dissipation),
``static_force=F0`` (precompression) and ``striker_mass=M`` (a free striker in front of
granule 1); a custom family's chains bring their own. Units are the paper's rescaled ones (Sec. II):
radii in units of the reference (large) radius, masses R^3, the struck granule starts
with velocity 1.
"""

from __future__ import annotations

import hashlib
import inspect
import warnings
from dataclasses import dataclass, field
from typing import Callable, ClassVar, NamedTuple

import numpy as np

from .._validate import count, exponent, finite_scalar
from ..model.chain import (
    HERTZ,
    Chain,
    decorated,
    from_radii,
    sphere_mass,
    sphere_stiffness,
    wall_stiffness,
)
from ..model.contacts import PowerLaw, Precompression, Viscoelastic
from ..model.distributions import (
    as_distribution,
    distribution_from_record,
    small_radius_distribution,
)
from ..model.effective import effective, effective_parameters
from ..model.random import realization_rng

__all__ = [
    "FAMILIES",
    "BinaryRandom",
    "ChainBatch",
    "ChainFamily",
    "CustomFamily",
    "RandomDecorated",
    "RandomParameter",
    "RandomRadii",
    "TaperedDecorated",
    "family_from_dataset",
    "family_from_record",
]

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


class ChainBatch(NamedTuple):
    """A batch of R chains of one size M, in the one chain representation.

    masses (R, M) (the last column inf for chains ending in a wall), stiffness (R, M-1),
    initial_velocity (R,), observed (K,) 0-based granule indices shared by every row, the
    contact exponent n, and ``contacts`` (C,): the 0-based contacts whose peak forces the
    store records (the family's ``contact`` dimension; None: every contact but a wall's).
    """

    masses: np.ndarray
    stiffness: np.ndarray
    initial_velocity: np.ndarray
    observed: np.ndarray
    n: float
    contacts: np.ndarray | None = None

    def recorded_contacts(self) -> np.ndarray:
        """``contacts``, or every contact but the wall's."""
        if self.contacts is not None:
            return np.asarray(self.contacts, dtype=np.int64)
        M = self.masses.shape[-1]
        return np.arange(M - 1 - bool(np.isinf(self.masses[..., -1]).any()), dtype=np.int64)


def _add_wall(batch: ChainBatch, last_radius) -> ChainBatch:
    """The batch with a fixed wall after its last granule: mass inf, stiffness sqrt(2 R_M)
    (:func:`granchain.wall_stiffness`, the limit of Eq. r-prime), the expressions of
    :meth:`granchain.Chain.with_wall`, so that rows stay bitwise the single chains."""
    R = batch.masses.shape[0]
    masses = np.concatenate((batch.masses, np.full((R, 1), np.inf)), axis=1)
    stiffness = np.concatenate((batch.stiffness, wall_stiffness(np.broadcast_to(last_radius, (R,)))[:, None]), axis=1)
    contacts = batch.recorded_contacts()  # fixed before the wall is added: the wall's contact is stored apart
    return batch._replace(masses=masses, stiffness=stiffness, contacts=contacts)


def _add_striker(batch: ChainBatch, mass: float, first_radius) -> ChainBatch:
    """The batch struck by a free sphere of ``mass`` (radius mass^(1/3), one material) in front of its
    first granule (radius ``first_radius``): the expressions of :meth:`granchain.Chain.with_striker`,
    so that rows stay bitwise the single chains. Observed granules and recorded contacts shift by one
    (the striker's own contact is not recorded)."""
    R = batch.masses.shape[0]
    r_s = np.full(R, (mass / 1.0) ** (1.0 / 3.0))
    pair = np.stack((r_s, np.broadcast_to(first_radius, (R,)).astype(float)), axis=1)
    contacts = batch.recorded_contacts() + 1  # fixed before the striker's contact is added
    return batch._replace(masses=np.concatenate((np.full((R, 1), float(mass)), batch.masses), axis=1),
                          stiffness=np.concatenate((sphere_stiffness(pair), batch.stiffness), axis=1),
                          observed=np.asarray(batch.observed) + 1, contacts=contacts)


class ChainFamily:
    """Base of every chain family (see the module docstring for the contract).

    Subclasses are frozen dataclasses with a class attribute ``kind`` (the registry and
    CLI name) and implement :meth:`parameters`, :meth:`dims`, :meth:`draw`,
    :meth:`build`, :meth:`chain`, :meth:`describe` and the properties :attr:`chains`,
    :attr:`size`, :attr:`n_observed` and :meth:`granule_coordinate`.

    The real contacts the chains share (the concrete families have these fields): ``contact``, the
    contact law (None: ``PowerLaw(n)``, the paper's; or a :class:`granchain.Viscoelastic`),
    ``static_force`` (the precompression F0, 0: none) and ``striker_mass`` (None: granule 1 struck
    with velocity 1; else a free sphere of that mass, rescaled, struck instead, one material).
    """

    kind: ClassVar[str]
    n: float
    wall: bool = False  # (a class default; the concrete families have a ``wall`` field)
    contact: object = None
    static_force: float = 0.0
    striker_mass: float | None = None

    # -- real contacts --------------------------------------------------------------------
    def _validate_model(self) -> None:
        law = self.contact
        if law is not None:
            if not isinstance(law, (PowerLaw, Viscoelastic)):
                raise ValueError(f"contact must be a granchain.PowerLaw or granchain.Viscoelastic law (or None), got {law!r}")
            if law.n != self.n:
                raise ValueError(f"the contact law's exponent n = {law.n:g} differs from the family's n = {self.n:g}: give the same n")
            if isinstance(law, PowerLaw):
                law = None  # the default, recorded as such (stores of the paper's chain keep their record)
        object.__setattr__(self, "contact", law)
        force = Precompression(self.static_force).force
        if force > 0 and self.n <= 1.0:
            raise ValueError(f"precompression needs an exponent n > 1, got n = {self.n:g}")
        object.__setattr__(self, "static_force", force)
        if self.striker_mass is not None:
            object.__setattr__(self, "striker_mass", finite_scalar("striker_mass", self.striker_mass, positive=True))

    @property
    def contact_law(self):
        """The chains' contact law (``PowerLaw(n)`` unless a viscoelastic one was given)."""
        return PowerLaw(self.n) if self.contact is None else self.contact

    @property
    def elastic(self) -> bool:
        """The paper's contacts: no damping, no static load, no striker."""
        return self.contact is None and self.static_force == 0.0 and self.striker_mass is None

    def model(self) -> dict | None:
        """What the chains share besides their arrays, as :class:`granchain.Chain` keywords (the
        ``model`` of ``Integrator.integrate_batch``); None for the paper's chains."""
        if self.elastic:
            return None
        return {"contact": self.contact_law, "static_force": self.static_force, "striker": self.striker_mass is not None}

    def _with_model(self, record: dict) -> dict:
        """A :meth:`describe` record with the real contacts that differ from the paper's (records of the
        paper's chains stay as before, so their stores resume unchanged; a store resumed with other
        contact settings is refused with the difference)."""
        extra = {}
        if self.contact is not None:
            extra["contact"] = self.contact.describe()
        if self.static_force > 0:
            extra["static_force"] = self.static_force
        if self.striker_mass is not None:
            extra["striker_mass"] = self.striker_mass
        return {**record, **extra}

    def _model_label(self) -> str:
        parts = []
        if self.contact is not None:
            parts.append(f"viscoelastic gamma = {self.contact.gamma:.4g}{'' if self.contact.clamp else ' (unclamped)'}")
        if self.static_force > 0:
            parts.append(f"precompressed F0 = {self.static_force:.4g}")
        if self.striker_mass is not None:
            parts.append(f"striker of mass {self.striker_mass:.4g}")
        return (", " + ", ".join(parts)) if parts else ""

    def _model_batch(self, batch: ChainBatch, first_radius) -> ChainBatch:
        """The batch with the family's striker (before its wall, if any: call this first)."""
        return batch if self.striker_mass is None else _add_striker(batch, self.striker_mass, first_radius)

    def _model_chain(self, chain: Chain) -> Chain:
        """One chain with the family's real contacts (bitwise a row of :meth:`build`)."""
        if self.striker_mass is not None:
            chain = chain.with_striker(mass=self.striker_mass)
        if self.contact is not None or self.static_force > 0:
            chain = chain.replace(contact=self.contact_law, static_force=self.static_force)
        return chain

    # -- what the family is -------------------------------------------------------------
    @property
    def chains(self) -> tuple:
        """Names of the chains the family builds for one realisation (first: the exact chain)."""
        raise NotImplementedError

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

    def _walled(self, record: dict) -> dict:
        """A :meth:`describe` record with ``"wall": True`` for a family with a wall (free-end records
        stay as before, so stores written without the option resume unchanged)."""
        return {**record, "wall": True} if self.wall else record

    def _wall_label(self) -> str:
        return ", against a fixed wall" if self.wall else ""

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


def _stack(params: dict, name: str) -> np.ndarray:
    try:
        a = np.asarray(params[name], dtype=float)
    except KeyError:
        raise ValueError(f"build() needs the parameter {name!r}; got {sorted(params)}") from None
    return a[None] if a.ndim == 1 else a


# ---------------------------------------------------------------------------- decorated families
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

    kind: ClassVar[str] = "decorated"

    def __post_init__(self):
        self._validate(stacklevel=3)

    def large_radii(self) -> np.ndarray:
        return np.ones(self.n_large)

    def describe(self) -> dict:
        return self._with_model(self._walled({"family": self.kind, "n_large": self.n_large,
                                              "distribution": self.distribution.describe(), "n": self.n,
                                              "momentum_conserving": self.momentum_conserving}))

    def label(self) -> str:
        return (f"random decorated, N = {self.n_large}, small radii {self.distribution.label()}{self._wall_label()}"
                f"{self._model_label()}")

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

    kind: ClassVar[str] = "tapered-decorated"

    def __init__(self, n_large: int = 26, *args, q: float | None = None, distribution=None, n: float = HERTZ,
                 momentum_conserving: bool = False, wall: bool = False, ratio: float | None = None, contact=None,
                 static_force: float = 0.0, striker_mass: float | None = None):
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
                            ("static_force", static_force), ("striker_mass", striker_mass)):
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
        return self._with_model(self._walled({"family": self.kind, "n_large": self.n_large, "q": self.q, "large_radii": _TAPER,
                                              "distribution": self.distribution.describe(), "n": self.n,
                                              "momentum_conserving": self.momentum_conserving}))

    def label(self) -> str:
        return (f"tapered decorated, N = {self.n_large}, q = {self.q:g}, small/large ratio {self.distribution.label()}"
                f"{self._wall_label()}{self._model_label()}")


# ---------------------------------------------------------------------------- undecorated families
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
        return self._with_model(self._walled({"family": self.kind, "size": self.size,
                                              "distribution": self.distribution.describe(), "n": self.n}))

    def label(self) -> str:
        return f"random polydisperse, M = {self.size}, radii {self.distribution.label()}{self._wall_label()}{self._model_label()}"


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
        return self._with_model(self._walled({"family": self.kind, "size": self.size, "radii": list(self.radii), "p": self.p,
                                              "n": self.n}))

    def label(self) -> str:
        return (f"binary random, M = {self.size}, radii {self.radii[0]:g}/{self.radii[1]:g}, p = {self.p:g}{self._wall_label()}"
                f"{self._model_label()}")


# ---------------------------------------------------------------------------- a user's family
def function_fingerprint(fn) -> dict:
    """What identifies a user's function in a record: its qualified name and the SHA-256 of its source
    (of its ``repr`` when the source cannot be read), so that a resumed run refuses an edited function."""
    try:
        source = inspect.getsource(fn)
    except (OSError, TypeError):
        source = repr(fn)
    return {"build": f"{getattr(fn, '__module__', '?')}.{getattr(fn, '__qualname__', repr(fn))}",
            "source_sha256": hashlib.sha256(source.encode()).hexdigest()}


@dataclass(frozen=True, init=False)
class CustomFamily(ChainFamily):
    """Any family a user can write as a function ``build(rng) -> radii`` (a 1-d array: a chain of
    spheres, :func:`granchain.from_radii`) or ``build(rng) -> Chain``.

    Every realisation must give a chain of the same size (and, for a Chain, the same observed
    granules and n). The function is called once here with ``numpy.random.default_rng(0)`` to learn
    the size, then once per realisation with ``realization_rng(seed, i)``: it must draw all its
    randomness from that generator. Chains are built in Python, one realisation at a time (slower
    to build than the other families, which build whole batches with NumPy), and integrated by the
    compiled kernels like any other family. The stored record names the function and the SHA-256
    of its source: a store resumed with an edited function is refused.

    Parameters
    ----------
    build : callable
        ``build(rng) -> radii`` or ``build(rng) -> granchain.Chain`` (a Chain may end in a wall,
        e.g. ``granchain.from_radii(radii, wall=True)``; the store's ``contact`` dimension is then
        every contact, the wall's last).
    name : str
        The chain's name in the store's ``chain`` coordinate.
    observed : sequence of int, optional
        0-based observed granules for radii builds (default: all).
    n : float
        Contact exponent for radii builds (a Chain brings its own).
    """

    build_fn: Callable
    name: str
    observed: tuple | None
    n: float
    returns_chain: bool = field(repr=False)
    _probe: Chain = field(repr=False, compare=False)

    kind: ClassVar[str] = "custom"

    def __init__(self, build: Callable, *, name: str = "custom", observed=None, n: float = HERTZ):
        if not callable(build):
            raise ValueError(f"CustomFamily needs a function build(rng) -> radii or Chain, got {build!r}")
        if not isinstance(name, str) or not name.strip() or name in ("both",):
            raise ValueError(f"name must be a non-empty string naming the chain, got {name!r}")
        object.__setattr__(self, "build_fn", build)
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "n", exponent(n))
        object.__setattr__(self, "observed", None if observed is None else tuple(int(k) for k in observed))
        object.__setattr__(self, "returns_chain", None)
        probe = self._make_chain(np.random.default_rng(0), "the probe call build(numpy.random.default_rng(0))")
        object.__setattr__(self, "_probe", probe)

    def _make_chain(self, rng, where: str) -> Chain:
        out = self.build_fn(rng)
        if self.returns_chain is None:
            object.__setattr__(self, "returns_chain", isinstance(out, Chain))
        if isinstance(out, Chain) != self.returns_chain:
            raise ValueError(f"{where} returned {type(out).__name__}, but the first call returned "
                             f"{'a Chain' if self.returns_chain else 'radii'}: return the same kind every time")
        if isinstance(out, Chain):
            if self.observed is not None:
                raise ValueError("observed= is for builds that return radii; a Chain brings its own observed granules")
            return out
        try:
            return from_radii(out, n=self.n, observed=self.observed, kind=self.name)
        except ValueError as exc:
            raise ValueError(f"{where} returned {type(out).__name__}, neither a granchain.Chain nor valid radii: {exc}") from None

    @property
    def chains(self) -> tuple:
        return (self.name,)

    @property
    def size(self) -> int:
        return self._probe.size

    @property
    def n_observed(self) -> int:
        return self._probe.observed.size

    @property
    def wall(self) -> bool:
        """Whether the chains end in a wall (a build returning a Chain that ends in one)."""
        return self._probe.wall

    def granule_coordinate(self) -> tuple:
        return self._probe.observed + 1, "observed granule (1-based index in the chain)"

    def parameters(self) -> tuple:
        if not self.returns_chain:
            return (RandomParameter("radius", ("site",), "float64", _RADIUS_UNITS, "radius of the granule"),)
        return (RandomParameter("mass", ("site",), "float64", "mass", "mass of the granule"),
                RandomParameter("stiffness", ("contact",), "float64", "1", "contact prefactor c_k (force c_k delta^(n-1))"),
                RandomParameter("initial_velocity", (), "float64", "velocity", "velocity of granule 1 at t = 0"))

    def dims(self) -> dict:
        M = self.size
        return {"site": (np.arange(1, M + 1), "granule index in the chain (1-based)"),
                "contact": (np.arange(1, M), "contact between granules k and k+1")}

    def draw(self, rng) -> dict:
        ch = self._make_chain(rng, "build(rng)")
        p = self._probe
        if ch.size != p.size or not np.array_equal(ch.observed, p.observed) or ch.n != p.n:
            raise ValueError(f"build(rng) gave a chain of {ch.size} granules observing {ch.observed.size} (n = {ch.n:g}); "
                             f"every realisation must match the first: {p.size} granules, {p.observed.size} observed, n = {p.n:g}")
        if ch.describe_model() != p.describe_model() or ch.striker != p.striker:
            raise ValueError(f"build(rng) gave a chain with other contacts ({ch.describe_model()}) than the first call "
                             f"({p.describe_model()}): every realisation must share its contact law, static load and striker")
        if not self.returns_chain:
            return {"radius": ch.radii}
        return {"mass": ch.masses, "stiffness": ch.stiffness, "initial_velocity": ch.initial_velocity}

    @property
    def contact_law(self):
        return self._probe.contact

    @property
    def static_force(self) -> float:
        return self._probe.static_force

    @property
    def striker_mass(self) -> float | None:
        return float(self._probe.masses[0]) if self._probe.striker else None

    @property
    def elastic(self) -> bool:
        return self._probe.elastic and not self._probe.striker

    def model(self) -> dict | None:
        """The real contacts of the chains the function returns (those of the first call: every
        realisation must have the same)."""
        p = self._probe
        return None if self.elastic else {"contact": p.contact, "static_force": p.static_force, "striker": p.striker}

    def build(self, params: dict, chain: str) -> ChainBatch:
        self._chain_name(chain)
        if not self.returns_chain:
            radii = _stack(params, "radius")
            return ChainBatch(sphere_mass(radii), sphere_stiffness(radii), np.ones(radii.shape[0]), self._probe.observed, self._probe.n,
                              np.arange(self.size - 1))
        masses, stiffness = _stack(params, "mass"), _stack(params, "stiffness")
        return ChainBatch(masses, stiffness, np.atleast_1d(np.asarray(params["initial_velocity"], dtype=float)),
                          self._probe.observed, self._probe.n, np.arange(self.size - 1))

    def chain(self, seed: int, realization: int, chain: str | None = None) -> Chain:
        self._chain_name(chain)
        return self._make_chain(realization_rng(seed, realization), "build(rng)")

    def describe(self) -> dict:
        return {"family": self.kind, "name": self.name, **function_fingerprint(self.build_fn), "size": self.size,
                "returns": "chain" if self.returns_chain else "radii",
                "observed": None if self.observed is None else list(self.observed), "n": self._probe.n,
                **({} if self.elastic else {"contact_model": self._probe.describe_model()})}

    def label(self) -> str:
        return f"custom family {self.name!r}, M = {self.size}"


#: Families by ``kind`` (the CLI's ``--family`` choices, and ``family`` in stored records).
FAMILIES = {cls.kind: cls for cls in (RandomDecorated, RandomRadii, BinaryRandom, TaperedDecorated, CustomFamily)}


def family_from_record(record: dict) -> ChainFamily:
    """The family a stored :meth:`ChainFamily.describe` record names (not :class:`CustomFamily`,
    whose function is not stored: pass the family itself)."""
    record = dict(record)
    kind = record.pop("family", None)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # warned about when the ensemble was made
        wall = bool(record.get("wall", False))
        model = _model_of_record(record)
        if kind == RandomDecorated.kind:
            return RandomDecorated(record["n_large"], distribution_from_record(record["distribution"]), n=record["n"],
                                   momentum_conserving=record["momentum_conserving"], wall=wall, **model)
        if kind == TaperedDecorated.kind:
            # records of granchain <= 0.4 hold the ratio of successive large radii under "q"
            q = record["q"] if record.get("large_radii") == _TAPER else _q_of_ratio(record["q"])
            return TaperedDecorated(record["n_large"], q=q, distribution=distribution_from_record(record["distribution"]),
                                    n=record["n"], momentum_conserving=record["momentum_conserving"], wall=wall, **model)
        if kind == RandomRadii.kind:
            return RandomRadii(record["size"], distribution_from_record(record["distribution"]), n=record["n"], wall=wall,
                               **model)
        if kind == BinaryRandom.kind:
            return BinaryRandom(record["size"], tuple(record["radii"]), record["p"], n=record["n"], wall=wall, **model)
    if kind == CustomFamily.kind:
        raise ValueError(f"a CustomFamily ({record.get('build')}) cannot be rebuilt from its record: pass the family itself")
    raise ValueError(f"unknown chain family {kind!r}; known: {sorted(FAMILIES)}")



def _model_of_record(record: dict) -> dict:
    """The real-contact keywords of a family record (:meth:`ChainFamily._with_model`; none in records
    of the paper's chains)."""
    out = {}
    law = record.get("contact")
    if law is not None:
        if law.get("law") != "viscoelastic":
            raise ValueError(f"unknown contact law in the stored record: {law!r}")
        # records written before the clamp option hold no "clamp": they were all clamped (the default)
        out["contact"] = Viscoelastic(law["gamma"], law["n"], clamp=law.get("clamp", True))
    if record.get("static_force"):
        out["static_force"] = float(record["static_force"])
    if record.get("striker_mass") is not None:
        out["striker_mass"] = float(record["striker_mass"])
    return out


def family_from_dataset(ds) -> ChainFamily:
    """The family of an ensemble Dataset (``run_ensemble``'s result or a store opened with
    :func:`granchain.open_store` or xarray) or of the store at a path, rebuilt from its stored record
    (read through the store's compatibility layer: a store written by granchain 0.1.0 holds no family
    record, its parameters then describe the :class:`RandomDecorated` it was). Raises ValueError for a
    :class:`CustomFamily` (its function is not stored) or a Dataset that is no ensemble."""
    from ..ensembles.store import stored_record

    record = stored_record(ds, "family")
    if record is None:
        raise ValueError("this Dataset holds no granchain family record (granchain_family attribute): "
                         "is it an ensemble written by granchain.run_ensemble?")
    return family_from_record(record)
