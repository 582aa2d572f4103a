"""One representation for every chain, and the builders that make one.

A :class:`Chain` is granules 1..M on a line, just touching (no precompression),
all at rest except granule 1 which moves with ``initial_velocity`` (the paper's
chain; real contacts below). Neighbours
k, k+1 repel with the power-law potential (c_k / n) delta^n while
delta = x_k - x_{k+1} > 0 (paper Eq. hertz-1 in the rescaled form of Eq.
motion_rescaled). Everything the integrators need is in ``masses``,
``stiffness``, ``n`` and ``initial_velocity``; ``observed`` names the granules
whose peak velocity and peak time are recorded.

A fixed wall at the far end is the same representation: a last granule of
infinite radius and mass (``masses[-1] = inf``, inverse mass 0) whose contact
stiffness is the limit of Eq. (r-prime) for R_{M} -> infinity, sqrt(2 R_{M-1})
(:func:`~granchain.model.spheres.wall_stiffness`). Build one with ``wall=True`` on the builders or
:meth:`Chain.with_wall`; the free end stays the default (the paper's case).

Real contacts are values of the chain too (``granchain.model.contacts``): a
viscoelastic contact law (:meth:`Chain.with_dissipation`), a static load
(:meth:`Chain.with_precompression`), a striker in front of granule 1
(:meth:`Chain.with_striker`), granules and a wall of other materials
(``materials=`` of :func:`from_radii`, ``material=`` of :meth:`Chain.with_wall`).
Without them a chain is the paper's, bit for bit.

Units are the paper's rescaled ones (Sec. II): radii in units of the radius of
the reference (first, large) granule, masses m = R^3 in units of its mass, time
and displacement as in Eq. (motion_rescaled). With several materials the
reference is granule 1's material: m_k = (rho_k / rho_1) R_k^3 and the contact
prefactors carry E*_k,k+1 / E*_1,1 (:func:`~granchain.model.spheres.material_stiffness`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._validate import count, exponent, finite_scalar, positive_array
from .chainmodel import ChainModel
from .contacts import (MIN_DYNAMIC_RATIO, ContactLaw, FixedWall, FreeEnd, Impulse, LoadedEnd, PowerLaw, Precompression, Striker,
                       Viscoelastic, checked_law, ends_at_exit, far_end)
from .spheres import (MASS_RANGE, RADIUS_RANGE, RIGID, STIFFNESS_RANGE, VELOCITY_RANGE, _check_radii,  # noqa: F401 (kept importable from here)
                      _in_range, _material, material_stiffness, material_wall_stiffness, sphere_mass, sphere_stiffness,
                      wall_stiffness)

__all__ = [
    "Chain",
    "from_radii",
    "monodisperse",
    "tapered",
    "decorated",
    "regular_decorated",
    "sphere_mass",
    "sphere_stiffness",
    "wall_stiffness",
    "material_stiffness",
    "material_wall_stiffness",
]

HERTZ = 2.5


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class Chain:
    """A granular chain in rescaled units (paper Eq. motion_rescaled).

    Parameters
    ----------
    masses : (M,) array, M >= 2
        Granule masses m_k > 0. The last may be ``numpy.inf``: a fixed wall (it never
        moves, is never observed, and takes the pulse's impulse; see :attr:`wall`).
    stiffness : (M-1,) array
        Contact prefactors c_k > 0: the force between k and k+1 is
        c_k * delta^(n-1) for delta > 0 (paper: r_k for spheres, Eq. r-prime;
        r_k / 2^(n-1) in the effective chain, Eq. effec-int).
    n : float
        Exponent of the contact potential (c/n) delta^n; n > 1. Hertz: 2.5.
    initial_velocity : float
        Velocity of granule 1 at t = 0 (the impulse); 1 in the paper's units.
    observed : (K,) int array, optional
        0-based indices of the granules whose pulse is recorded, ascending
        (default: all). For decorated chains these are the large granules.
    radii : (M,) array or None
        Radii the chain was built from (None for an effective chain); ``inf`` for a wall.
    kind : str
        A short description ("radii", "decorated", "effective", ...).
    contact : ContactLaw, optional
        The contact law (default ``PowerLaw(n)``, the paper's; its ``n`` must be ``n``): any
        :class:`granchain.model.contacts.ContactLaw`.
        :meth:`with_dissipation` sets a viscoelastic one.
    static_force : float
        The precompression F0 >= 0 (rescaled force units; 0: none, the paper's chain;
        :meth:`with_precompression`, :class:`granchain.Precompression`).
    striker : bool
        Granule 0 of the arrays is a striker, the struck body in front of granule 1
        (:meth:`with_striker`): not observed by default, and the granule labels
        (``PulseResult.granule``) start at 1 with the granule after it.

    Attributes
    ----------
    contact : granchain.model.contacts.ContactLaw
        The contact law.
    precompression : granchain.Precompression
        The static load (force 0 without one).
    boundary : FreeEnd, LoadedEnd or FixedWall (granchain.model.contacts)
        The far end: a wall when the last mass is infinite; held by the static force
        when the chain is precompressed without a wall; else free.
    initial : granchain.model.contacts.Impulse or granchain.model.contacts.Striker
        The initial state: granule 1 (or the striker) struck with ``initial_velocity``,
        the rest at rest in the static state.
    """

    masses: np.ndarray
    stiffness: np.ndarray
    n: float = HERTZ
    initial_velocity: float = 1.0
    observed: np.ndarray | None = None
    radii: np.ndarray | None = None
    kind: str = "custom"
    meta: dict = field(default_factory=dict, repr=False)
    contact: ContactLaw | None = field(default=None, repr=False)
    static_force: float = 0.0
    striker: bool = False
    precompression: Precompression = field(init=False, repr=False)
    boundary: FreeEnd | LoadedEnd | FixedWall = field(init=False, repr=False)
    initial: Impulse = field(init=False, repr=False)

    def __post_init__(self):
        m = _masses_with_wall(self.masses)
        c = positive_array("stiffness", self.stiffness)
        if c.size != m.size - 1:
            raise ValueError(
                f"stiffness needs one entry per contact (len(masses) - 1 = {m.size - 1}), got {c.size}"
            )
        _in_range("stiffness", c, STIFFNESS_RANGE, "contact prefactors (in units of the reference pair's)")
        n = exponent(self.n)
        v0 = finite_scalar("initial_velocity", self.initial_velocity, positive=True)
        if not VELOCITY_RANGE[0] <= v0 <= VELOCITY_RANGE[1]:
            raise ValueError(f"initial_velocity = {v0:g} is outside {VELOCITY_RANGE[0]:g}..{VELOCITY_RANGE[1]:g}: in rescaled units "
                             "the units' impact speed is 1, and a speed that far from it puts the compressions and the "
                             "collision times outside the range the integrators' tolerances are scaled for")
        wall = bool(np.isinf(m[-1]))
        if isinstance(self.striker, Impulse):
            raise ValueError("striker is a flag (whether granule 0 of the arrays is a striker), not a granchain.Striker: "
                             "add a striker with chain.with_striker(mass=... or radius=..., velocity=...)")
        if not isinstance(self.striker, (bool, np.bool_)):
            raise ValueError(f"striker must be True or False (whether granule 0 of the arrays is a striker), got {self.striker!r}")
        striker = bool(self.striker)
        if striker and m.size - wall < 3:
            raise ValueError("a chain with a striker needs the striker and at least 2 granules")
        contact = PowerLaw(n) if self.contact is None else checked_law(self.contact, n)
        load = Precompression.of(self.static_force)
        ratio = load.resolvable(float(m[0]), float(c[0]), n, v0)
        if ratio < MIN_DYNAMIC_RATIO:
            raise ValueError(
                f"the static force F0 = {load.force:g} (rescaled) is too large for this chain: granule 1 struck at "
                f"{v0:g} moves its contact by ~{ratio:.1e} of the static overlap, which double precision (2.2e-16) does "
                f"not resolve to the accuracy of the peaks; the dynamic part must be >= {MIN_DYNAMIC_RATIO:g} of it, "
                f"so give F0 <= {_largest_static_force(float(m[0]), float(c[0]), n, v0):.3g} (or strike harder)")
        if self.observed is None:
            obs = np.arange(int(striker), m.size - wall, dtype=np.int64)
        else:
            obs = np.asarray(self.observed)
            if obs.ndim != 1 or obs.size == 0 or not np.issubdtype(obs.dtype, np.integer):
                raise ValueError("observed must be a non-empty 1-d sequence of 0-based granule indices")
            obs = obs.astype(np.int64)
            if obs.min() < 0 or obs.max() >= m.size:
                raise ValueError(f"observed indices must lie in 0..{m.size - 1} (0-based), got {obs.tolist()}")
            if np.any(np.diff(obs) <= 0):
                raise ValueError("observed indices must be strictly increasing (no repeats)")
            if wall and obs[-1] == m.size - 1:
                raise ValueError(f"observed includes granule {m.size - 1} (0-based), the wall (infinite mass), which never moves: "
                                 f"observe granules 0..{m.size - 2}")
        radii = None if self.radii is None else _radii_with_wall(self.radii, wall)
        if radii is not None and radii.size != m.size:
            raise ValueError(f"radii has {radii.size} entries for {m.size} granules")
        if contact.history:
            _check_yielding(contact_yield_overlaps(contact, c, radii, self.meta), c, load)
        object.__setattr__(self, "masses", _frozen(m))
        object.__setattr__(self, "stiffness", _frozen(c))
        object.__setattr__(self, "n", n)
        object.__setattr__(self, "initial_velocity", v0)
        object.__setattr__(self, "observed", _frozen(obs))
        object.__setattr__(self, "radii", None if radii is None else _frozen(radii))
        object.__setattr__(self, "contact", contact)
        object.__setattr__(self, "static_force", load.force)
        object.__setattr__(self, "striker", striker)
        object.__setattr__(self, "precompression", load)
        object.__setattr__(self, "boundary", far_end(wall, load).of(c, load))
        if striker:
            r0 = None if radii is None else float(radii[0])
            object.__setattr__(self, "initial", Striker(v0, 0, float(m[0]), r0))
        else:
            object.__setattr__(self, "initial", Impulse(v0))

    # -- derived quantities -------------------------------------------------
    @property
    def size(self) -> int:
        """Number of granules M."""
        return int(self.masses.size)

    @property
    def wall(self) -> bool:
        """Whether the far end is a fixed wall (:attr:`boundary`; the last granule has infinite mass)."""
        return self.boundary.wall

    @property
    def labels(self) -> np.ndarray:
        """The observed granules' 1-based labels: granule 1 is the first granule after the striker
        (0 is the striker itself), else the first of the arrays."""
        return self.observed + 1 - int(self.striker)

    @property
    def elastic(self) -> bool:
        """The paper's chain: power-law contacts without damping or static load (a striker and
        materials change masses and stiffnesses only)."""
        return self.contact.conservative and not self.precompression.applied

    @property
    def ends_at_exit(self) -> bool:
        """Whether a run can end at the pulse's exit (or its return from a wall): not for a
        precompressed chain, whose loaded contacts do not open (it runs to a time instead,
        ``granchain.solve.simulation.default_t_max``)."""
        return ends_at_exit(type(self.boundary), self.precompression)

    @property
    def overlaps(self) -> np.ndarray:
        """The static overlaps delta0_k = (F0 / c_k)^(1/(n-1)) (zeros without precompression)."""
        return self.precompression.overlaps(self.stiffness, self.n)

    def replace(self, **changes) -> "Chain":
        """The same chain with some constructor arguments changed (a copy of ``meta``); every value goes
        through the constructor's checks."""
        allowed = ("masses", "stiffness", "n", "initial_velocity", "observed", "radii", "kind", "meta", "contact",
                   "static_force", "striker")
        unknown = sorted(set(changes) - set(allowed))
        if unknown:
            raise ValueError(f"Chain.replace() takes the constructor's arguments ({', '.join(allowed)}), not "
                             f"{', '.join(unknown)}: the precompression, boundary and initial state follow from them "
                             "(with_precompression, with_wall, with_striker)")
        flag = changes.get("striker", self.striker)
        if isinstance(flag, (bool, np.bool_)) and bool(flag) != self.striker:
            raise ValueError("replace(striker=...) would reinterpret granule 0 of the arrays (a granule would become a "
                             "striker or a striker a granule); add a striker with chain.with_striker(mass=..., velocity=...)")
        args = dict(masses=self.masses, stiffness=self.stiffness, n=self.n, initial_velocity=self.initial_velocity,
                    observed=self.observed, radii=self.radii, kind=self.kind, meta=dict(self.meta),
                    contact=self.contact, static_force=self.static_force, striker=self.striker)
        args.update(changes)
        return Chain(**args)

    def with_precompression(self, force) -> "Chain":
        """The same chain under a static compressive force F0 = ``force`` (rescaled force units; see
        :class:`granchain.Precompression` for the boundary convention: the load at the
        struck end, held at the far end by the wall if there is one, else by the same force).

        ``force`` may be a quantity with units (``"2 N"``) only through ``granchain.units``
        (``scale.to_rescaled("2 N", "force")``, :meth:`granchain.units.Scale.to_rescaled`), which knows the
        force unit."""
        if self.n <= 1.0:
            raise ValueError(f"precompression needs an exponent n > 1 (a contact that stiffens as it is compressed), got n = {self.n:g}")
        return self.replace(static_force=Precompression(force))

    def with_dissipation(self, gamma: float | None = None, *, restitution: float | None = None,
                         speed: float = 1.0, clamp: bool = True) -> "Chain":
        """The same chain with viscoelastic contacts (:class:`granchain.model.contacts.Viscoelastic`):
        give the damping time ``gamma``, or a coefficient of ``restitution`` in (0, 1] of two reference
        granules colliding at ``speed`` (rescaled; 1 is the impact speed of the paper's units), from
        which ``gamma`` is calibrated by solving the two-body problem. ``clamp``: the force never pulls
        (True, the default) or pulls at the end of a collision as in the published law whose restitution
        tables the literature gives (False; :class:`granchain.model.contacts.Viscoelastic`)."""
        if (gamma is None) == (restitution is None):
            raise ValueError("give either gamma (the damping time) or restitution (a coefficient of restitution, with speed)")
        law = (Viscoelastic(gamma, self.n, clamp) if gamma is not None
               else Viscoelastic.from_restitution(restitution, speed, n=self.n, clamp=clamp))
        return self.replace(contact=law)

    def with_striker(self, mass: float | None = None, *, radius: float | None = None, velocity: float | None = None,
                     material=None) -> "Chain":
        """The same chain struck by a free sphere instead of an initial velocity on granule 1.

        Give the striker's ``mass`` or its ``radius`` (rescaled: the reference granule, of radius 1,
        has mass 1) and its ``velocity`` (default: this chain's ``initial_velocity``). The striker is a
        sphere of granule 1's material, or of ``material`` (a :class:`granchain.units.Material`) for a
        chain built with ``materials=``: its contact with granule 1 is Hertz's for the pair (Eq. r-prime;
        :func:`~granchain.model.spheres.material_stiffness` for two materials); of a ``mass`` alone, the radius is that of a
        sphere of that mass. It sits in front of granule 1, just touching it (carrying the static load
        of a precompressed chain), and is launched at t = 0. Granule labels keep their meaning
        (granule 1 is the first after the striker), and the striker is not observed unless asked
        (:meth:`with_observed`, array index 0)."""
        if self.striker:
            raise ValueError("this chain already has a striker")
        if (mass is None) == (radius is None):
            raise ValueError("give the striker's mass or its radius (rescaled: granule 1 has mass 1 and radius 1)")
        mats = self.meta.get("materials")
        if material is not None and not mats:
            raise ValueError("a striker of another material needs the chain's own materials: build it with "
                             "granchain.from_radii(radii, materials=...)")
        ref = mats[0] if mats else None
        smat = _material(material) if material is not None else ref
        rho = 1.0 if smat is None or ref is None else smat.rho / ref.rho
        if radius is not None:
            r_s = finite_scalar("striker radius", radius, positive=True)
            m_s = rho * r_s * r_s * r_s
        else:
            m_s = finite_scalar("striker mass", mass, positive=True)
            r_s = (m_s / rho) ** (1.0 / 3.0)
        r1 = 1.0 if self.radii is None else float(self.radii[0])
        if smat is not None and ref is not None:
            c_s = float(material_stiffness(np.array([r_s, r1]), [smat, mats[0]], reference=ref)[0])
        else:
            c_s = float(sphere_stiffness(np.array([r_s, r1]))[0])
        v = self.initial_velocity if velocity is None else finite_scalar("striker velocity", velocity, positive=True)
        radii = None if self.radii is None else np.concatenate(([r_s], self.radii))
        meta = dict(self.meta)
        if mats:
            meta["materials"] = [smat] + list(mats)
        return Chain(masses=np.concatenate(([m_s], self.masses)), stiffness=np.concatenate(([c_s], self.stiffness)),
                     n=self.n, initial_velocity=v, observed=self.observed + 1, radii=radii, kind=self.kind, meta=meta,
                     contact=self.contact, static_force=self.static_force, striker=True)

    @property
    def energy(self) -> float:
        """Total energy, all kinetic at t = 0: m_1 v_1^2 / 2 (a wall, at rest, has none)."""
        return self.initial.energy(self.masses)

    @property
    def momentum(self) -> float:
        """Total momentum m_1 v_1 of the granules (conserved with free ends; with a wall the
        granules lose the wall's impulse, :attr:`granchain.PulseResult.wall_impulse`)."""
        return self.initial.momentum(self.masses)

    def with_wall(self, stiffness: float | None = None, *, material=None, granules=None) -> "Chain":
        """The same chain ending in a wall: one more granule, of infinite mass (it does not move).

        The wall contact's stiffness is ``stiffness`` or, for a chain built from radii,
        sqrt(2 R_M) (:func:`~granchain.model.spheres.wall_stiffness`, the limit of Eq. r-prime: a flat wall of the last
        granule's material). ``material`` (a :class:`granchain.units.Material`, or ``"rigid"`` for an
        infinitely stiff wall) makes it an elastic wall of its own material: Hertz's effective
        modulus of the pair and the sphere's radius (:func:`~granchain.model.spheres.material_wall_stiffness`), relative to the
        granules' material: that of a chain built with ``materials=``, else ``granules`` (the one
        material of the chain's granules, the material of its physical units). A chain without radii
        (e.g. an effective chain) needs ``stiffness``.
        """
        if self.wall:
            raise ValueError("this chain already ends in a wall")
        if stiffness is not None and material is not None:
            raise ValueError("give the wall's stiffness or its material, not both")
        if material is not None:
            if self.radii is None:
                raise ValueError(f"a {self.kind} chain has no radii to give an elastic wall its contact: pass stiffness=...")
            mats = self.meta.get("materials")
            if mats:
                if granules is not None:
                    raise ValueError("this chain was built with materials=...: its granules' materials are known, "
                                     "do not give granules=")
                ref, last = mats[0], mats[-1]
            elif granules is None:
                raise ValueError("a wall of another material is stiff relative to the granules' material: give it "
                                 "(with_wall(material=..., granules=...), the material of the chain's physical "
                                 "units), or build the chain with from_radii(radii, materials=...)")
            else:
                ref = last = _material(granules)
            stiffness = material_wall_stiffness(self.radii[-1], last, material, reference=ref)
        elif stiffness is None and self.meta.get("materials") and self.radii is not None:
            mats = self.meta["materials"]  # a flat wall of the last granule's material, relative to granule 1's
            stiffness = material_wall_stiffness(self.radii[-1], mats[-1], mats[-1], reference=mats[0])
        if stiffness is None:
            if self.radii is None:
                raise ValueError(f"a {self.kind} chain has no radii to give the wall contact its stiffness sqrt(2 R_M): "
                                 "pass stiffness=... (the prefactor c of the wall force c delta^(n-1))")
            stiffness = wall_stiffness(self.radii[-1])
        c_wall = finite_scalar("stiffness", stiffness, positive=True)
        radii = None if self.radii is None else np.append(self.radii, np.inf)
        meta = dict(self.meta)
        if material is not None:
            meta["wall_material"] = material
        return self.replace(masses=np.append(self.masses, np.inf), stiffness=np.append(self.stiffness, c_wall), radii=radii,
                            meta=meta)

    def yield_overlaps(self):
        """Each contact's yield overlap under the chain's law (``granchain.ElasticPlastic``): c_k^2 delta_y,ref for
        granules of one material, else from the radii and the materials' yield stresses
        (:meth:`granchain.ElasticPlastic.yield_overlaps`)."""
        return contact_yield_overlaps(self.contact, self.stiffness, self.radii, self.meta)

    def with_observed(self, observed) -> "Chain":
        """The same chain observing other granules (0-based indices of the arrays; a striker is 0)."""
        return self.replace(observed=observed)

    def describe_model(self) -> dict:
        """The chain's contact law, static load and initial state as a record (for stores and reports)."""
        return {**self.contact.describe(), **self.precompression.describe(), **self.initial.describe()}

    @property
    def model(self) -> ChainModel:
        """The chain's physics besides its arrays as one value (:class:`granchain.ChainModel`: contact law,
        static load, striker mass, wall), the value a family of such chains shares."""
        return ChainModel.of_chain(self)

    def with_model(self, model: ChainModel) -> "Chain":
        """This chain (struck on granule 1, the paper's contacts) with the physics of ``model``: its striker
        in front of granule 1, its contact law and static load, and a wall (:meth:`with_wall`, default
        stiffness) if the model has one and the chain has not. What a chain family does to each of its
        chains."""
        if not isinstance(model, ChainModel):
            raise ValueError(f"model must be a granchain.ChainModel, got {model!r}")
        if self.striker or not self.elastic:
            raise ValueError("with_model starts from the paper's chain (no striker, power-law contacts, no static load); "
                             "this chain already has its own: build it again without them")
        if self.wall and not model.wall:
            raise ValueError("the chain ends in a wall and the model has none: build the chain without its wall")
        model = model.for_exponent(self.n, "chain")
        chain = model.apply(self)
        return chain.with_wall() if model.wall and not chain.wall else chain

    def __repr__(self) -> str:
        extras = ""
        if self.contact.label():
            extras += f", {self.contact.label(6, '=')}"
        if self.precompression.applied:
            extras += f", static_force={self.static_force:.6g}"
        if self.striker:
            extras += f", striker of mass {self.masses[0]:.6g}"
        return (
            f"Chain(kind={self.kind!r}, M={self.size}{' (the last a wall)' if self.wall else ''}, n={self.n:g}, "
            f"initial_velocity={self.initial_velocity:g}, observed={self.observed.size} granules{extras})"
        )


def _largest_static_force(m: float, c: float, n: float, v: float) -> float:
    """The F0 at which :meth:`Precompression.resolvable` equals MIN_DYNAMIC_RATIO: D / delta0 =
    v sqrt(m / ((n-1) c)) delta0^(-n/2), solved for delta0 and F0 = c delta0^(n-1)."""
    from .contacts import MIN_DYNAMIC_RATIO

    d0 = (v * np.sqrt(m / ((n - 1.0) * c)) / MIN_DYNAMIC_RATIO) ** (2.0 / n)
    return float(c * d0 ** (n - 1.0))


def _masses_with_wall(masses) -> np.ndarray:
    """Positive finite masses within :data:`MASS_RANGE`, except that the last may be +inf (a wall)."""
    m = _masses_any(masses)
    _in_range("masses", m[np.isfinite(m)], MASS_RANGE, "units of the reference granule's mass",
              ": a granule that much lighter or heavier than the reference one has contact times and compressions "
              "that double precision and any step budget cannot integrate beside it")
    return m


def _masses_any(masses) -> np.ndarray:
    """Positive finite masses, except that the last may be +inf (a wall)."""
    try:
        a = np.array(masses, dtype=float).reshape(-1) if np.ndim(masses) <= 1 else None
    except (TypeError, ValueError):
        a = None
    if a is not None and a.size >= 2 and np.isinf(a[:-1]).any():
        i = int(np.flatnonzero(np.isinf(a[:-1]))[0])
        raise ValueError(f"masses: entry {i} is infinite; only the last granule may be infinitely heavy (a fixed wall)")
    if a is not None and a.size >= 2 and a[-1] == np.inf:
        return np.append(positive_array("masses", a[:-1], min_size=1), np.inf)
    return positive_array("masses", masses, min_size=2)


def _radii_with_wall(radii, wall: bool) -> np.ndarray:
    if wall:
        r = np.array(radii, dtype=float).reshape(-1)
        if r.size < 1 or r[-1] != np.inf:
            raise ValueError("radii of a chain ending in a wall must end with inf (the wall's radius)")
        return np.append(positive_array("radii", r[:-1]), np.inf)
    return positive_array("radii", radii)


def contact_yield_overlaps(law, stiffness, radii, meta):
    """Each contact's yield overlap under a law that yields (``ElasticPlastic.yield_overlaps``), from the
    prefactors, and for granules or a wall of several materials from the radii and materials too."""
    meta = meta or {}
    return law.yield_overlaps(stiffness, radii=radii, materials=meta.get("materials"),
                              wall_material=meta.get("wall_material"))


def _check_yielding(dy, stiffness, load) -> None:
    """Refuse a static load that has already yielded a contact under the elastic-plastic law
    (``granchain.ElasticPlastic``; yield overlaps ``dy``): the chain would not start in its elastic static state."""
    if load.force > 0.0:
        d0 = load.overlaps(stiffness, 2.5)
        if np.any(d0 >= dy):
            k = int(np.argmax(d0 / dy))
            raise ValueError(f"the static force F0 = {load.force:g} yields contact {k} before the chain is struck (static "
                             f"overlap {d0[k]:.4g} >= its yield overlap {dy[k]:.4g}): give a smaller F0 or a higher "
                             "yield speed, so that the chain starts elastic")


def from_radii(radii, *, n: float = HERTZ, initial_velocity: float = 1.0, observed=None, kind: str = "radii",
               wall: bool = False, materials=None, wall_material=None) -> Chain:
    """A chain of spheres from any list of radii.

    One material (the default): m_k = R_k^3 (paper Sec. II: M_k = M_1 m_k with equal density),
    stiffness from Eq. (r-prime). ``materials``: one :class:`granchain.units.Material` (or preset
    name) per granule, e.g. a steel-PTFE dimer chain: m_k = (rho_k / rho_1) R_k^3 and the stiffness
    of each pair from Hertz's effective modulus and radius (:func:`~granchain.model.spheres.material_stiffness`), in the
    rescaled units of granule 1's material (``granchain.units.scale`` of that material). All granules
    are observed unless ``observed`` says otherwise. ``wall=True`` ends the chain in a wall
    (:meth:`Chain.with_wall`): of the last granule's material, or of ``wall_material`` (a Material
    or ``"rigid"``).
    """
    r = positive_array("radii", radii, min_size=1)
    if r.size < 2:
        raise ValueError(f"a chain needs at least 2 granules, got {r.size} radius")
    _check_radii(r)
    if materials is None:
        if wall_material is not None:
            raise ValueError("wall_material needs the granules' materials=... (the wall's stiffness is relative to theirs)")
        chain = Chain(sphere_mass(r), sphere_stiffness(r), n, initial_velocity, observed, r, kind)
        return chain.with_wall() if wall else chain
    if n != HERTZ:
        raise ValueError(f"materials give Hertz contacts (n = 5/2); got n = {n:g}")
    mats = [_material(materials)] * r.size if not isinstance(materials, (list, tuple, np.ndarray)) else [_material(m) for m in materials]
    if len(mats) != r.size:
        raise ValueError(f"materials needs one material per granule ({r.size}), got {len(mats)}")
    ref = mats[0]
    rho = np.array([1.0 if m == ref else m.rho / ref.rho for m in mats])
    chain = Chain(rho * sphere_mass(r), material_stiffness(r, mats), n, initial_velocity, observed, r, kind,
                  {"materials": mats})
    if wall or wall_material is not None:
        return chain.with_wall(material=wall_material) if wall_material is not None else chain.with_wall()
    return chain


def monodisperse(size: int, *, n: float = HERTZ, initial_velocity: float = 1.0, wall: bool = False) -> Chain:
    """``size`` equal spheres of radius 1 (and a fixed wall after them with ``wall=True``)."""
    size = count("size", size, minimum=2)
    return from_radii(np.ones(size), n=n, initial_velocity=initial_velocity, kind="monodisperse", wall=wall)


def tapered(size: int, q: float, *, profile: str = "geometric", n: float = HERTZ, initial_velocity: float = 1.0,
            wall: bool = False) -> Chain:
    """A tapered chain starting from radius 1.

    ``profile="geometric"``: R_k = (1 - q)^(k-1); ``profile="linear"``:
    R_k = 1 - q (k-1). q > 0 tapers down, q < 0 grows (an "inverted" taper).
    """
    size = count("size", size, minimum=2)
    q = finite_scalar("q", q)
    k = np.arange(size, dtype=float)
    if profile == "geometric":
        if not q < 1.0:
            raise ValueError(f"q = {q!r} must be < 1 for a geometric taper R_k = (1 - q)^(k-1)")
        radii = (1.0 - q) ** k
    elif profile == "linear":
        radii = 1.0 - q * k
        if radii[-1] <= 0.0:
            raise ValueError(
                f"linear taper q = {q!r} makes radius {size} non-positive ({radii[-1]:.3g}); "
                f"need q < {1.0 / (size - 1):.6g} for {size} granules"
            )
    else:
        raise ValueError(f"profile must be 'geometric' or 'linear', got {profile!r}")
    return from_radii(radii, n=n, initial_velocity=initial_velocity, kind=f"tapered-{profile}", wall=wall)


def decorated(small_radii, *, large_radius=1.0, n: float = HERTZ, initial_velocity: float = 1.0, wall: bool = False) -> Chain:
    """N large granules with one small granule between each pair (paper Sec. III A).

    ``small_radii`` (N-1 values, in units of the reference radius) sit between
    large granules k and k+1. ``large_radius`` is one radius for all N large
    granules (the paper's monodisperse case, default 1) or N radii (e.g. a tapered
    decorated chain, :class:`granchain.TaperedDecorated`). A small granule may not
    be larger than its smaller neighbour (use :func:`from_radii` for any other
    chain). The chain has 2N-1 granules, both ends large, and observes the large
    granules (0-based indices 0, 2, ..., 2N-2). ``wall=True`` adds a fixed wall after
    large granule N (granule 2N, never observed).
    """
    s = positive_array("small_radii", small_radii, min_size=1)
    if np.ndim(large_radius) == 0:
        big = np.full(s.size + 1, finite_scalar("large_radius", large_radius, positive=True))
    else:
        big = positive_array("large_radius", large_radius)
        if big.size != s.size + 1:
            raise ValueError(f"large_radius needs one radius per large granule ({s.size + 1} for {s.size} small radii), got {big.size}")
    too_big = s > np.minimum(big[:-1], big[1:])
    if too_big.any():
        j = int(np.flatnonzero(too_big)[0])
        raise ValueError(
            f"small_radii[{j}] = {s[j]:g} is larger than its neighbouring large granules "
            f"({big[j]:g}, {big[j + 1]:g}): a decorated chain needs small granules no larger than the large ones; "
            "build any other chain with granchain.from_radii"
        )
    radii = np.empty(2 * s.size + 1)
    radii[0::2] = big
    radii[1::2] = s
    chain = from_radii(radii, n=n, initial_velocity=initial_velocity, observed=np.arange(0, radii.size, 2), kind="decorated")
    chain.meta["small_radii"] = s
    return chain.with_wall() if wall else chain


def regular_decorated(size: int, pattern, *, n: float = HERTZ, initial_velocity: float = 1.0, wall: bool = False) -> Chain:
    """A decorated chain of ``size`` large granules whose small radii repeat ``pattern``.

    ``pattern=(0.3,)`` puts R = 0.3 in every gap; ``(0.2, 0.4)`` alternates.
    """
    size = count("size", size, minimum=2)
    pat = positive_array("pattern", pattern, min_size=1)
    return decorated(np.resize(pat, size - 1), n=n, initial_velocity=initial_velocity, wall=wall)
