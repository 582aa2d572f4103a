"""The model a chain carries besides its masses and stiffnesses, as small frozen values: the contact
law here; the static load, the far boundary and the initial state in :mod:`granchain.model.conditions`,
exported here too. Each declares the assumptions it licenses, so that the integrators and backends ask
once instead of re-deriving them from sentinels:

- :class:`PowerLaw` (paper Eq. hertz-1, Hertz for n = 5/2): forces depend on positions only
  (``conservative``: what licenses Nystrom methods, Verlet and a conserved energy) and vanish when a
  contact opens (an opened contact is where a pulse leaves granules behind).
- :class:`Viscoelastic` (Kuwabara & Kono 1987; Brilliantov et al. 1996): the Hertz force plus a
  damping term in the rate of compression; not conservative (only DP5 and DOP853 integrate it), and
  the energy it takes is integrated with the motion.
- :class:`Viscous` (Rosas, Romero, Nesterenko & Lindenberg 2007, 2008): the Hertz force plus a damping
  force proportional to the rate of compression, whatever the compression; not conservative either.
- :class:`ElasticPlastic` (Thornton 1997): Hertz until the contact yields, then a plastic loading line
  and a stiffer elastic unloading; each contact's largest overlap is state (``history``).
- :class:`Precompression`: a static force F0 compresses the chain before it is struck; the chain
  starts in exact static equilibrium and the pulse rides on it.
- :class:`FreeEnd`, :class:`LoadedEnd` and :class:`FixedWall`: whether the pulse leaves through the
  far end for good (``licenses_goal_control``: the granules behind the front will not see it again,
  so the relaxed zone and the trailing window of ``granchain.DP5`` are safe) and which rule ends the
  run (``has_exit``, :func:`ends_at_exit`).
- :class:`Impulse` (the paper's Sec. II) and :class:`Striker`: granule 1, or a free striker in front
  of it, struck with a velocity, every other granule exactly at rest in the static state
  (``rest_ahead``: what licenses integrating only the granules the pulse has reached, bitwise the same
  as integrating all).

A :class:`granchain.Chain` holds these as ``chain.contact``, ``chain.precompression``,
``chain.boundary`` and ``chain.initial``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

from .._validate import real_number
from .conditions import (MAX_STATIC_FORCE, MIN_DYNAMIC_RATIO, FixedWall, FreeEnd, Impulse, LoadedEnd, Precompression, Striker,
                         ends_at_exit, far_end)

__all__ = ["ContactLaw", "PowerLaw", "Viscoelastic", "Viscous", "ElasticPlastic", "Precompression", "FreeEnd", "LoadedEnd", "FixedWall", "far_end", "ends_at_exit", "Impulse", "Striker",
           "MAX_STATIC_FORCE", "MIN_DYNAMIC_RATIO", "law_from_record"]


class ContactLaw:
    """What every contact law answers, so that the chain, the families, the stores, the CLI and the
    backends ask the law instead of re-deriving its physics:

    - ``record_name`` (its ``describe()["law"]``; :func:`law_from_record` rebuilds it from that record)
      and ``form``, the name of its force in the compiled kernels (a backend declares the forms it has
      code for, ``Backend.law_forms``);
    - :attr:`conservative` (forces of positions only) and :attr:`dissipates`;
    - ``gamma`` and ``clamp``, the kernels' damping parameters (0 and True for an elastic law);
    - :meth:`force` (NumPy, any shape) and :meth:`force_rate` (its time derivative at one contact,
      where the force peaks), the law itself for the reference backend and the two-body collision;
    - :meth:`label`, a short text for reports.

    A new law is a subclass here with these, and its force in the kernels
    (``granchain.backends.kernels.forces.LAW_FORMS``)."""

    record_name: ClassVar[str] = ""
    form: ClassVar[str] = ""
    #: The force depends on the contact's past too (a per-contact state the integration carries, e.g. the
    #: largest overlap of :class:`ElasticPlastic`); only code that carries it runs such a law.
    history: ClassVar[bool] = False
    _registry: ClassVar[dict] = {}

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if cls.__dict__.get("record_name"):
            ContactLaw._registry[cls.record_name] = cls

    @property
    def conservative(self) -> bool:
        """Forces of positions only (x'' = f(x)): what licenses Nystrom methods, Verlet and a conserved energy."""
        return self.gamma == 0.0

    @property
    def dissipates(self) -> bool:
        """The contacts take energy from the motion (integrated as ``dissipated_energy``)."""
        return not self.conservative

    def elastic_force(self, compression, stiffness):
        """c delta^(n-1) for delta > 0, else 0 (NumPy, any shape): the law's conservative part."""
        import numpy as np

        d = np.asarray(compression, dtype=float)
        return np.where(d > 0.0, stiffness * np.abs(d) ** (self.n - 1.0), 0.0)

    def force(self, compression, stiffness, rate=0.0):
        raise NotImplementedError

    def force_rate(self, d: float, w: float, dw: float, c: float) -> float:
        """d/dt of the force of one contact at compression ``d``, rate ``w`` = d(delta)/dt and relative
        acceleration ``dw``; 0 where the force is <= 0 (open, clamped or pulling: no peak there)."""
        raise NotImplementedError

    def label(self, digits: int = 6, eq: str = " = ") -> str:
        """A short description for reports, numbers to ``digits`` significant digits ("" for an elastic law)."""
        return ""

    def describe(self) -> dict:
        raise NotImplementedError


def checked_law(law, n: float | None = None, owner: str = "chain"):
    """``law`` if it is a contact law (None, the paper's default, passes), of exponent ``n`` where given; else a
    ValueError that says what to give (``owner``: whose exponent n is, for the message). The one check of a
    law that a chain, a family's model and a design run are given."""
    if law is None:
        return None
    if not isinstance(law, ContactLaw):
        raise ValueError(f"contact must be a contact law (granchain.PowerLaw, granchain.Viscoelastic, ...: a "
                         f"granchain.model.contacts.ContactLaw) or None, got {law!r}")
    if n is not None and law.n != n:
        raise ValueError(f"the contact law's exponent n = {law.n:g} differs from the {owner}'s n = {n:g}: give the same n")
    return law


def law_from_record(record: dict) -> ContactLaw:
    """The contact law a ``describe()`` record names (as stored in a family's record)."""
    try:
        cls = ContactLaw._registry[record.get("law")]
    except (KeyError, AttributeError, TypeError):
        raise ValueError(f"unknown contact law in the stored record: {record!r}; "
                         f"known: {sorted(ContactLaw._registry)}") from None
    return cls(**{k: v for k, v in record.items() if k != "law"})


@dataclass(frozen=True)
class PowerLaw(ContactLaw):
    """Contact force c delta^(n-1) for compression delta > 0, else 0 (Eq. motion_rescaled)."""

    n: float = 2.5

    record_name: ClassVar[str] = "power-law"
    form: ClassVar[str] = "power-law"

    #: Forces depend on positions only (x'' = f(x)).
    conservative: ClassVar[bool] = True

    #: No damping: the kernels' ``Params.gamma``.
    gamma: ClassVar[float] = 0.0
    clamp: ClassVar[bool] = True

    def force(self, compression, stiffness, rate=None):
        """c delta^(n-1) for delta > 0, else 0 (NumPy, any shape; ``rate`` is not read)."""
        return self.elastic_force(compression, stiffness)

    def force_rate(self, d, w, dw, c):
        """c (n-1) delta^(n-2) w where the contact is closed."""
        return c * (self.n - 1.0) * d ** (self.n - 2.0) * w if d > 0.0 else 0.0

    def describe(self) -> dict:
        return {"law": "power-law", "n": self.n}


@dataclass(frozen=True)
class Viscoelastic(ContactLaw):
    """The viscoelastic Hertz contact: for compression delta > 0 closing at the rate d(delta)/dt,

        F = c [delta^(n-1) + gamma delta^(n-2) d(delta)/dt],   clamped at F >= 0 (``clamp=True``),

    and 0 for delta <= 0 (rescaled units; ``gamma`` is a time). For n = 5/2 this is the force of
    G. Kuwabara and K. Kono, Jpn. J. Appl. Phys. 26, 1230 (1987), derived from the viscoelastic
    continuum by N. V. Brilliantov, F. Spahn, J.-M. Hertzsch and T. Poschel, Phys. Rev. E 53, 5382
    (1996), whose F = rho (xi^(3/2) + (3/2) A xi^(1/2) dxi/dt) is this law with gamma = 3 A / 2.

    The clamp (``clamp=True``, the default): a contact never pulls; while the spheres separate faster
    than the damping allows, the force is 0 (T. Poschel and T. Schwager, *Computational Granular
    Dynamics*, Springer 2005, Sec. 2.3). The published coefficients of restitution of this law (1 - e =
    1.7302 A rho^(2/5) g^(1/5) + ..., T. Schwager and T. Poschel, Phys. Rev. E 57, 650 (1998);
    R. Ramirez, T. Poschel, N. V. Brilliantov and T. Schwager, Phys. Rev. E 60, 4465 (1999)) are for
    the UNCLAMPED force, which pulls at the end of a collision and so gives a lower e: the clamped law's
    e is higher (two unit spheres at unit speed: by 0.08 %, 0.4 % and 2.2 % at A = 0.05, 0.1 and 0.2,
    gamma = 3 A / 2; ``tests/test_real_contacts.py``). ``clamp=False`` lets the force pull (it is still 0 for delta <= 0, where the
    spheres have separated), as the published model does: it reproduces those tables.

    Not ``conservative`` (for gamma > 0): the force depends on velocities, so the methods for
    x'' = f(x) (RKN4, Verlet) refuse it; DP5 and DOP853 integrate it, and the energy the contacts
    dissipate is integrated with the motion (``PulseResult.dissipated_energy``; its error steers DP5's
    steps like any other component), so that E_kin + E_pot + E_dissipated = E_0 is the run's energy
    check. With a trailing window (``DP5.windowed()``) the granules left behind stop interacting, so
    the energy their contacts would still dissipate is not counted (measured: 9 % less on a 40-granule
    chain; the peaks ahead are unaffected within the accuracy contract).

    ``gamma`` is the same for every contact (a property of the material at the paper's rescaling).
    Give it directly, or calibrate it from a coefficient of restitution with :meth:`from_restitution`.
    """

    gamma: float
    n: float = 2.5
    clamp: bool = True

    record_name: ClassVar[str] = "viscoelastic"
    form: ClassVar[str] = "kuwabara-kono"

    def __post_init__(self):
        import math

        import numpy as np

        g = real_number(self.gamma, "gamma (the damping time of the viscoelastic contact)")
        if not math.isfinite(g) or g < 0.0:
            raise ValueError(f"gamma (the damping time of the viscoelastic contact) must be finite and >= 0, got {self.gamma!r}; "
                             "gamma = 0 is the elastic contact")
        try:
            n = float(self.n)
        except (TypeError, ValueError):
            raise ValueError(f"n (the exponent of the viscoelastic contact) must be a number, got {self.n!r}") from None
        if not (math.isfinite(n) and n >= 2.0):
            raise ValueError(f"the viscoelastic contact needs an exponent n >= 2 (finite), got n = {self.n!r}: its damping term "
                             "gamma delta^(n-2) d(delta)/dt would diverge as a contact closes")
        if not isinstance(self.clamp, (bool, np.bool_)):
            raise ValueError(f"clamp must be True (the force never pulls, the default) or False (the published, "
                             f"unclamped law), got {self.clamp!r}")
        object.__setattr__(self, "gamma", g)
        object.__setattr__(self, "n", n)
        object.__setattr__(self, "clamp", bool(self.clamp))

    @classmethod
    def from_restitution(cls, restitution: float, speed: float = 1.0, *, n: float = 2.5, mass: float = 1.0,
                         stiffness: float = 1.0, clamp: bool = True) -> "Viscoelastic":
        """The law whose two-sphere collision at impact speed ``speed`` has the coefficient of
        restitution ``restitution`` (in (0, 1]; 1 is elastic).

        The pair is two reference granules by default (masses ``mass`` = 1, contact prefactor
        ``stiffness`` = 1: two spheres of radius 1, Eq. r-prime); ``gamma`` solves
        e(gamma) = restitution, with e from the two-body problem integrated by SciPy's DOP853
        (:func:`granchain.model.collision.restitution`) with the same ``clamp``: the clamped law needs a
        little more damping than the published (unclamped) one for the same e."""
        from .collision import gamma_for_restitution

        return cls(gamma_for_restitution(restitution, speed, n=n, mass=mass, stiffness=stiffness, clamp=clamp), n, clamp)

    def force(self, compression, stiffness, rate=0.0):
        """The force of the law (NumPy, any shape): c [d^(n-1) + gamma d^(n-2) rate] for d > 0,
        clamped at 0 unless ``clamp`` is False; 0 for d <= 0."""
        import numpy as np

        d = np.asarray(compression, dtype=float)
        dp = np.where(d > 0.0, d, 0.0)
        f = stiffness * dp ** (self.n - 2.0) * (dp + self.gamma * np.asarray(rate, dtype=float))
        return np.where(d > 0.0, np.maximum(f, 0.0) if self.clamp else f, 0.0)

    def force_rate(self, d, w, dw, c):
        """d/dt of c d^(n-2) (d + gamma w): c [(n-1) d^(n-2) w + gamma ((n-2) d^(n-3) w^2 + d^(n-2) dw)]."""
        n, gamma = self.n, self.gamma
        if d <= 0.0 or d + gamma * w <= 0.0:
            return 0.0
        return c * ((n - 1.0) * d ** (n - 2.0) * w + gamma * ((n - 2.0) * d ** (n - 3.0) * w * w + d ** (n - 2.0) * dw))

    def label(self, digits: int = 6, eq: str = " = ") -> str:
        return f"viscoelastic gamma{eq}{self.gamma:.{digits}g}{'' if self.clamp else ' (unclamped)'}" if self.gamma > 0 else ""

    def describe(self) -> dict:
        """The law as a record; ``"clamp": False`` only for the unclamped law, so that records written
        before the option existed (all clamped) read as clamped and compare equal."""
        return {"law": "viscoelastic", "n": self.n, "gamma": self.gamma, **({} if self.clamp else {"clamp": False})}


@dataclass(frozen=True)
class Viscous(ContactLaw):
    """The viscous contact of Rosas, Romero, Nesterenko and Lindenberg: for compression delta > 0
    closing at the rate d(delta)/dt,

        F = c delta^(n-1) + gamma d(delta)/dt,

    and 0 for delta <= 0 (rescaled units; ``gamma`` is a force per relative speed, the same for every
    contact). A. Rosas, A. H. Romero, V. F. Nesterenko and K. Lindenberg, Phys. Rev. Lett. 98, 164301
    (2007) and Phys. Rev. E 78, 051303 (2008): a damping force proportional to the relative velocity of
    two grains while they touch. In their form (the default, ``clamp=False``) the damping may pull at
    the end of a collision, while the grains separate; ``clamp=True`` holds the force at >= 0, so a
    contact never pulls (the spheres then separate freely once the damping would win).

    Unlike the Kuwabara-Kono law (:class:`Viscoelastic`, whose damping grows as delta^(n-2) and vanishes
    as a contact opens), the damping here does not depend on how far the contact is compressed. The
    authors' result for a monodisperse chain: at low viscosity a struck granule sends a leading solitary
    pulse that decays as it goes, followed by a shock-like secondary pulse; above a critical viscosity
    only one non-oscillatory pulse travels.

    Not ``conservative`` for gamma > 0: DP5 and DOP853 integrate it, and the energy it takes is
    integrated with the motion (``PulseResult.dissipated_energy``, as for :class:`Viscoelastic`).
    """

    gamma: float
    n: float = 2.5
    clamp: bool = False

    record_name: ClassVar[str] = "viscous"
    form: ClassVar[str] = "viscous"

    def __post_init__(self):
        import numpy as np

        g = real_number(self.gamma, "gamma (the viscous damping coefficient)")
        if not math.isfinite(g) or g < 0.0:
            raise ValueError(f"gamma (the viscous damping coefficient) must be finite and >= 0, got {self.gamma!r}; "
                             "gamma = 0 is the elastic contact")
        n = real_number(self.n, "n (the exponent of the viscous contact)")
        if not (math.isfinite(n) and n > 1.0):
            raise ValueError(f"the viscous contact needs a finite exponent n > 1, got n = {self.n!r}")
        if not isinstance(self.clamp, (bool, np.bool_)):
            raise ValueError(f"clamp must be False (the force may pull while the grains separate, the authors' form, "
                             f"the default) or True (never pulls), got {self.clamp!r}")
        object.__setattr__(self, "gamma", g)
        object.__setattr__(self, "n", n)
        object.__setattr__(self, "clamp", bool(self.clamp))

    def force(self, compression, stiffness, rate=0.0):
        """c d^(n-1) + gamma rate for d > 0 (clamped at 0 if ``clamp``), 0 for d <= 0 (NumPy, any shape)."""
        import numpy as np

        d = np.asarray(compression, dtype=float)
        f = self.elastic_force(d, stiffness) + self.gamma * np.asarray(rate, dtype=float)
        return np.where(d > 0.0, np.maximum(f, 0.0) if self.clamp else f, 0.0)

    def force_rate(self, d, w, dw, c):
        """d/dt of c d^(n-1) + gamma w: c (n-1) d^(n-2) w + gamma dw, where the force is > 0."""
        if d <= 0.0 or c * d ** (self.n - 1.0) + self.gamma * w <= 0.0:
            return 0.0
        return c * (self.n - 1.0) * d ** (self.n - 2.0) * w + self.gamma * dw

    def label(self, digits: int = 6, eq: str = " = ") -> str:
        return f"viscous gamma{eq}{self.gamma:.{digits}g}{' (clamped)' if self.clamp else ''}" if self.gamma > 0 else ""

    def describe(self) -> dict:
        """The law as a record (``"clamp": True`` only for the clamped variant)."""
        return {"law": "viscous", "n": self.n, "gamma": self.gamma, **({"clamp": True} if self.clamp else {})}


@dataclass(frozen=True)
class ElasticPlastic(ContactLaw):
    """Thornton's elastic-perfectly plastic sphere contact (C. Thornton, J. Appl. Mech. 64, 383 (1997)):
    a contact with memory, for Hertz spheres (n = 5/2).

    Below the yield overlap delta_y a contact is Hertzian, F = c delta^(3/2). Hertz's maximum contact
    pressure p0 = (2 E* / pi) (delta / R*)^(1/2) reaches the limiting pressure p_y there; beyond it the
    pressure is capped at p_y and the force grows linearly with the overlap, with the Hertz slope at
    delta_y (Thornton's F = F_y + pi p_y R* (delta - delta_y); in granchain's notation
    pi p_y R* = (3/2) c delta_y^(1/2)):

        F_load(delta) = c delta_y^(1/2) (3 delta - delta_y) / 2,            delta >= delta_y.

    Unloading from the largest overlap delta_m reached (force F* = F_load(delta_m)) is Hertzian with an
    enlarged radius of curvature R_p = R* (2 f + 1)^(3/2) / (3^(3/2) f), f = F* / F_y (Thornton's
    unloading radius, written with the yield force F_y = c delta_y^(3/2)), so that

        F_unload(delta) = c_p (delta - delta_p)^(3/2),   c_p = c ((2 f + 1) / 3)^(3/4) f^(-1/2),
        delta_p = delta_m - (F* / c_p)^(2/3),

    and 0 below the plastic overlap delta_p (the dent left). Reloading follows the unloading curve up to
    delta_m, then the loading line again. Each contact remembers delta_m (its history, carried by the
    integration as part of the state); a contact that never passed delta_y is Hertzian throughout.

    The energy the contact does not give back is the plastic work W_p(delta_m) = W_load(delta_m)
    - (2/5) F* (delta_m - delta_p) (:meth:`plastic_work`), reported as the run's ``dissipated_energy``;
    kinetic + elastic (:meth:`stored_energy`) + plastic = initial is the run's energy check.

    Parametrisation (rescaled units): ``yield_speed`` v_y, the relative impact speed at which two
    reference granules (radius 1, mass 1, prefactor 1) first yield: (1/2)(1/2) v_y^2 = (2/5) delta_y^(5/2).
    For spheres of one material the yield speed of a pair of equal spheres does not depend on their size,
    and each contact's yield overlap follows from its prefactor: delta_y,k = c_k^2 delta_y,ref (the limiting
    pressure is a property of the material; :meth:`yield_overlaps`, which also gives those of a chain of several
    materials, each yielding at the softer material's pressure). From a material's yield stress, in SI
    units: :meth:`from_material`. The two-sphere coefficient of restitution has Thornton's closed form
    (:meth:`restitution`): 1 below v_y, falling as v^(-1/4) far above it.
    """

    yield_speed: float
    n: float = 2.5

    record_name: ClassVar[str] = "elastic-plastic"
    form: ClassVar[str] = "thornton"
    #: Positions alone give the force only with the contact's history: not conservative, and it dissipates.
    conservative: ClassVar[bool] = False
    #: The force depends on the contact's past (its largest overlap), a per-contact state the integration
    #: carries; an integrator or backend without that state refuses the law.
    history: ClassVar[bool] = True
    gamma: ClassVar[float] = 0.0
    clamp: ClassVar[bool] = True

    def __post_init__(self):
        v = real_number(self.yield_speed, "yield_speed (the relative impact speed at which two reference granules first yield)")
        if not (math.isfinite(v) and v > 0.0):
            raise ValueError(f"yield_speed must be finite and > 0 (rescaled: the struck granule's speed is 1), got "
                             f"{self.yield_speed!r}; an elastic contact is granchain.PowerLaw")
        n = real_number(self.n, "n (the exponent of the contact)")
        if n != 2.5:
            raise ValueError(f"Thornton's elastic-plastic contact is Hertz's (n = 5/2) up to yield: its limiting contact "
                             f"pressure is that of two elastic spheres; got n = {self.n!r} (give n = 2.5)")
        object.__setattr__(self, "yield_speed", v)
        object.__setattr__(self, "n", 2.5)

    @classmethod
    def from_material(cls, material, impact_speed) -> "ElasticPlastic":
        """The law of spheres of ``material`` (a ``granchain.units.Material`` with a ``yield_stress``, or a
        preset name) for a chain struck at ``impact_speed`` (m/s, or a quantity such as ``"5 m/s"``): the
        rescaled yield speed is V_y / V_1, with V_y of :meth:`granchain.units.Material.yield_speed`."""
        from ..units import get_material, si_value

        mat = get_material(material) if isinstance(material, str) else material
        v1 = si_value(impact_speed, "speed", "the impact speed")
        if not (math.isfinite(v1) and v1 > 0.0):
            raise ValueError(f"the impact speed must be finite and > 0, got {impact_speed!r}")
        return cls(mat.yield_speed / v1)

    @property
    def reference_yield_overlap(self) -> float:
        """delta_y of two reference granules (reduced mass 1/2, prefactor 1): (5 v_y^2 / 8)^(2/5)."""
        return (0.625 * self.yield_speed**2) ** 0.4

    def yield_overlaps(self, stiffness, *, radii=None, materials=None, wall_material=None):
        """Each contact's yield overlap (NumPy). For spheres of one material, c_k^2 delta_y,ref: c_k = sqrt(2 R*_k)
        (Eq. r-prime) and delta_y = R* (pi p_y / (2 E*))^2 grows as R* (a wall of the granules' material,
        c = sqrt(2 R), included). For a chain of several materials (``materials``, one per granule, the
        reference granule 1's; ``wall_material`` a wall of its own, or ``"rigid"``) with its ``radii``:

            delta_y,k = delta_y,ref (2 R*_k)^2 / c_k^2 (p_k / p_ref)^2,

        since c_k = (E*_k / E*_ref) sqrt(2 R*_k) (``granchain.model.spheres.material_stiffness``) and the pair's
        limiting pressure p_k is the softer material's (it yields first), 1.60 times its yield stress
        (``Material.limiting_pressure``); a rigid wall does not yield. Every material then needs a
        ``yield_stress``."""
        import numpy as np

        c = np.asarray(stiffness, dtype=float)
        one = c * c * self.reference_yield_overlap
        distinct = {getattr(m, "name", m) for m in (materials or ())}
        if radii is None or (len(distinct) <= 1 and wall_material is None):
            return one
        r = np.asarray(radii, dtype=float)
        a, b = r[:-1], r[1:]
        reduced = np.where(np.isinf(b), a, a * b / (a + np.where(np.isinf(b), 0.0, b)))  # R*; a flat wall: R
        geometric = self.reference_yield_overlap * (2.0 * reduced) ** 2 / (c * c)
        if not materials:  # one material, a wall of another: the spheres yield (their yield stress unknown here)
            return geometric

        def pressure(m):
            if isinstance(m, str) and m == "rigid":
                return math.inf
            if m.yield_stress is None:
                raise ValueError(f"the elastic-plastic contact of a chain of several materials needs each material's "
                                 f"yield stress: {m.name!r} has none (Material(..., yield_stress=...))")
            return m.limiting_pressure

        from ..units import get_material

        mats = [get_material(m) if isinstance(m, str) else m for m in materials]
        p = [pressure(m) for m in mats]
        pair = [min(p[k], p[k + 1]) for k in range(len(mats) - 1)]
        if c.size == len(mats):  # a wall after the last granule
            wall = wall_material if wall_material is not None else mats[-1]
            wall = get_material(wall) if isinstance(wall, str) and wall != "rigid" else wall
            pair.append(min(p[-1], pressure(wall)))
        return geometric * (np.asarray(pair) / p[0]) ** 2

    def _branches(self, d, c, history, dy=None):
        """(m, c_p, delta_p, dy) for compressions ``d``: the largest overlap m (the history, moved to d where d
        reaches it: the loading line), the unloading curve's c_p and delta_p from it, and the yield overlaps ``dy``
        (None: :meth:`yield_overlaps` of one material)."""
        import numpy as np

        d = np.asarray(d, dtype=float)
        c = np.asarray(c, dtype=float)
        dy = self.yield_overlaps(c) if dy is None else np.asarray(dy, dtype=float)
        m = dy if history is None else np.maximum(np.asarray(history, dtype=float), dy)
        m = np.maximum(m, d)  # loading past the history moves it
        f = 1.5 * m / dy - 0.5  # F* / F_y
        cp = c * ((2.0 * f + 1.0) / 3.0) ** 0.75 / np.sqrt(f)
        dp = m - f * dy * np.sqrt(3.0 / (2.0 * f + 1.0))  # delta_m - (F* / c_p)^(2/3)
        return m, cp, dp, dy

    def plastic_overlap(self, history, stiffness, yield_overlap=None):
        """delta_p, the compression at which a contact whose largest overlap is ``history`` unloads to zero force
        (the dent it keeps; 0 for a contact that never yielded). Its spheres touch, with no force, down to it.
        ``yield_overlap``: the contacts' yield overlaps (None: one material, :meth:`yield_overlaps`)."""
        m, cp, dp, dy = self._branches(0.0, stiffness, history, yield_overlap)
        return dp

    def force(self, compression, stiffness, rate=None, history=None, yield_overlap=None):
        """The force at compression ``compression`` (NumPy, any shape) of contacts whose largest overlap so
        far is ``history`` (None: virgin contacts): the loading line where the compression reaches the
        history, else the unloading curve from it; Hertz's c delta^(3/2) below yield. ``rate`` is not read;
        ``yield_overlap`` as in :meth:`plastic_overlap`."""
        import numpy as np

        d = np.asarray(compression, dtype=float)
        m, cp, dp, dy = self._branches(d, stiffness, history, yield_overlap)
        e = np.maximum(d - dp, 0.0)
        return np.where(d > 0.0, cp * e * np.sqrt(e), 0.0)

    def stored_energy(self, compression, stiffness, history=None, yield_overlap=None):
        """The elastic energy a contact gives back if unloaded from ``compression``: (2/5) c_p
        (delta - delta_p)^(5/2) of the unloading curve through it (Hertz's (2/5) c delta^(5/2) below yield)."""
        import numpy as np

        d = np.asarray(compression, dtype=float)
        m, cp, dp, dy = self._branches(d, stiffness, history, yield_overlap)
        e = np.maximum(d - dp, 0.0)
        return np.where(d > 0.0, 0.4 * cp * e * e * np.sqrt(e), 0.0)

    def plastic_work(self, history, stiffness, yield_overlap=None):
        """The energy a contact whose largest overlap is ``history`` has dissipated plastically:
        W_load(delta_m) - (2/5) F* (delta_m - delta_p), 0 below yield (NumPy)."""
        import numpy as np

        c = np.asarray(stiffness, dtype=float)
        dy = self.yield_overlaps(c) if yield_overlap is None else np.asarray(yield_overlap, dtype=float)
        m = np.maximum(np.asarray(history, dtype=float), dy)
        u = m / dy - 1.0
        fy_dy = c * dy * dy * np.sqrt(dy)  # F_y delta_y
        loading = fy_dy * (0.4 + u + 0.75 * u * u)  # the work along Hertz to delta_y, then the loading line
        f = 1.0 + 1.5 * u
        returned = 0.4 * fy_dy * f * f * np.sqrt(3.0 / (2.0 * f + 1.0))  # (2/5) F* (delta_m - delta_p)
        return np.where(c > 0.0, loading - returned, 0.0)

    def force_rate(self, d, w, dw, c):
        """dF/dt on the loading branch (the force peaks with the compression on either branch)."""
        if d <= 0.0:
            return 0.0
        dy = float(self.yield_overlaps(c))
        slope = 1.5 * c * math.sqrt(d) if d < dy else 1.5 * c * math.sqrt(dy)
        return slope * w

    @staticmethod
    def restitution_ratio(ratio: float) -> float:
        """Thornton's coefficient of restitution of two spheres at r = v_y / v (impact speed v):
        e = sqrt(6 sqrt(3) / 5) sqrt(1 - r^2 / 6) [r / (r + 2 sqrt(6/5 - r^2 / 5))]^(1/4) for r < 1, and 1
        for r >= 1 (Thornton 1997; derived again in ``docs/explanation/contacts.md``)."""
        r = float(ratio)
        if r >= 1.0:
            return 1.0
        return math.sqrt(6.0 * math.sqrt(3.0) / 5.0) * math.sqrt(1.0 - r * r / 6.0) * (
            r / (r + 2.0 * math.sqrt(1.2 - 0.2 * r * r))) ** 0.25

    def restitution(self, speed: float, *, mass: float = 1.0, stiffness: float = 1.0, other_mass: float | None = None) -> float:
        """The closed-form coefficient of restitution of two spheres colliding at relative speed ``speed``:
        :meth:`restitution_ratio` at r = v_y,pair / speed, where the pair's yield speed follows from its
        reduced mass and prefactor (the reference pair by default: two granules of mass 1, prefactor 1)."""
        mu = mass * (mass if other_mass is None else other_mass) / (mass + (mass if other_mass is None else other_mass))
        dy = float(self.yield_overlaps(stiffness))
        vy = math.sqrt(0.8 * stiffness * dy * dy * math.sqrt(dy) / mu)  # (1/2) mu v_y^2 = (2/5) c delta_y^(5/2)
        return self.restitution_ratio(vy / speed)

    def label(self, digits: int = 6, eq: str = " = ") -> str:
        return f"elastic-plastic v_y{eq}{self.yield_speed:.{digits}g}"

    def describe(self) -> dict:
        return {"law": "elastic-plastic", "n": self.n, "yield_speed": self.yield_speed}


def __getattr__(name):
    # The boundary was called RigidWall, though its wall is of the granules' own material by default;
    # "rigid" now means only an infinitely stiff wall material.
    if name == "RigidWall":
        import warnings

        warnings.warn("granchain.model.contacts.RigidWall is now FixedWall (an immovable wall, of the granules' "
                      "material unless another is given; \"rigid\" means an infinitely stiff wall material)",
                      DeprecationWarning, stacklevel=2)
        return FixedWall
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
