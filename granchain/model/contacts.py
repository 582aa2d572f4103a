"""The model a chain carries besides its masses and stiffnesses, as small frozen values: the contact
law, the static load, the far boundary and the initial state. Each declares the assumptions it
licenses, so that the integrators and backends ask once, here, instead of re-deriving them from
sentinels:

- :class:`PowerLaw` (paper Eq. hertz-1, Hertz for n = 5/2): forces depend on positions only
  (``conservative``: what licenses Nystrom methods, Verlet and a conserved energy) and vanish when a
  contact opens (``tensionless``: an opened contact is where a pulse leaves granules behind).
- :class:`Viscoelastic` (Kuwabara & Kono 1987; Brilliantov et al. 1996): the Hertz force plus a
  damping term in the rate of compression; not conservative (only DP5 and DOP853 integrate it), and
  the energy it takes is integrated with the motion.
- :class:`Precompression`: a static force F0 compresses the chain before it is struck; the chain
  starts in exact static equilibrium and the pulse rides on it.
- :class:`FreeEnd`, :class:`LoadedEnd` and :class:`RigidWall`: whether the pulse leaves through the
  far end for good (``licenses_goal_control``: the granules behind the front will not see it again,
  so the relaxed zone and the trailing window of ``granchain.DP5`` are safe) and which rule ends the
  run (``has_exit``).
- :class:`Impulse` (the paper's Sec. II) and :class:`Striker`: granule 1, or a free striker in front
  of it, struck with a velocity, every other granule exactly at rest in the static state
  (``rest_ahead``: what licenses integrating only the granules the pulse has reached, bitwise the same
  as integrating all).

A :class:`granchain.Chain` holds these as ``chain.contact``, ``chain.precompression``,
``chain.boundary`` and ``chain.initial``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

__all__ = ["PowerLaw", "Viscoelastic", "Precompression", "FreeEnd", "LoadedEnd", "RigidWall", "Impulse", "Striker"]


@dataclass(frozen=True)
class PowerLaw:
    """Contact force c delta^(n-1) for compression delta > 0, else 0 (Eq. motion_rescaled)."""

    n: float = 2.5

    #: Forces depend on positions only (x'' = f(x)).
    conservative: ClassVar[bool] = True
    #: No force across an open contact (no tension, no precompression).
    tensionless: ClassVar[bool] = True

    #: No damping: the kernels' ``Params.gamma``.
    gamma: ClassVar[float] = 0.0

    def force(self, compression, stiffness, rate=None):
        """c delta^(n-1) for delta > 0, else 0 (NumPy, any shape; ``rate`` is not read)."""
        import numpy as np

        d = np.asarray(compression, dtype=float)
        return np.where(d > 0.0, stiffness * np.abs(d) ** (self.n - 1.0), 0.0)

    def describe(self) -> dict:
        return {"law": "power-law", "n": self.n}


@dataclass(frozen=True)
class Viscoelastic:
    """The viscoelastic Hertz contact: for compression delta > 0 closing at the rate d(delta)/dt,

        F = c [delta^(n-1) + gamma delta^(n-2) d(delta)/dt],   clamped at F >= 0,

    and 0 for delta <= 0 (rescaled units; ``gamma`` is a time). For n = 5/2 this is the force of
    G. Kuwabara and K. Kono, Jpn. J. Appl. Phys. 26, 1230 (1987), derived from the viscoelastic
    continuum by N. V. Brilliantov, F. Spahn, J.-M. Hertzsch and T. Poschel, Phys. Rev. E 53, 5382
    (1996), whose F = rho (xi^(3/2) + (3/2) A xi^(1/2) dxi/dt) is this law with gamma = 3 A / 2. The
    clamp: a contact never pulls (while the spheres separate faster than the damping allows the force
    is 0; T. Poschel and T. Schwager, *Computational Granular Dynamics*, Springer 2005, Sec. 2.3).

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

    tensionless: ClassVar[bool] = True

    @property
    def conservative(self) -> bool:
        """Forces of positions only: only without damping (gamma = 0, the power law itself)."""
        return self.gamma == 0.0

    def __post_init__(self):
        import math

        try:
            g = float(self.gamma)
        except (TypeError, ValueError):
            raise ValueError(f"gamma (the damping time of the viscoelastic contact) must be a number, got {self.gamma!r}") from None
        if not math.isfinite(g) or g < 0.0:
            raise ValueError(f"gamma (the damping time of the viscoelastic contact) must be finite and >= 0, got {self.gamma!r}; "
                             "gamma = 0 is the elastic contact")
        n = float(self.n)
        if not n >= 2.0:
            raise ValueError(f"the viscoelastic contact needs an exponent n >= 2, got n = {self.n!r}: its damping term "
                             "gamma delta^(n-2) d(delta)/dt would diverge as a contact closes")
        object.__setattr__(self, "gamma", g)
        object.__setattr__(self, "n", n)

    @classmethod
    def from_restitution(cls, restitution: float, speed: float = 1.0, *, n: float = 2.5, mass: float = 1.0,
                         stiffness: float = 1.0) -> "Viscoelastic":
        """The law whose two-sphere collision at impact speed ``speed`` has the coefficient of
        restitution ``restitution`` (in (0, 1]; 1 is elastic).

        The pair is two reference granules by default (masses ``mass`` = 1, contact prefactor
        ``stiffness`` = 1: two spheres of radius 1, Eq. r-prime); ``gamma`` solves
        e(gamma) = restitution, with e from the two-body problem integrated by SciPy's DOP853
        (:func:`granchain.model.collision.restitution`)."""
        from .collision import gamma_for_restitution

        return cls(gamma_for_restitution(restitution, speed, n=n, mass=mass, stiffness=stiffness), n)

    def force(self, compression, stiffness, rate=0.0):
        """The force of the law (NumPy, any shape): c [d^(n-1) + gamma d^(n-2) rate] for d > 0,
        clamped at 0; 0 for d <= 0."""
        import numpy as np

        d = np.asarray(compression, dtype=float)
        dp = np.where(d > 0.0, d, 0.0)
        f = stiffness * dp ** (self.n - 2.0) * (dp + self.gamma * np.asarray(rate, dtype=float))
        return np.where(d > 0.0, np.maximum(f, 0.0), 0.0)

    def describe(self) -> dict:
        return {"law": "viscoelastic", "n": self.n, "gamma": self.gamma}


@dataclass(frozen=True)
class Precompression:
    """A static compressive force F0 (rescaled force units, the unit of ``granchain.units.Scale.force``)
    that holds the chain together before it is struck.

    The chain starts in static equilibrium: every contact k carries F0 at the overlap

        delta0_k = (F0 / c_k)^(1/(n-1))

    (V. F. Nesterenko, *Dynamics of Heterogeneous Materials*, Springer 2001, Sec. 1.1). Boundary
    convention: the load is applied at the struck end (on granule 1, or on a striker resting against
    it) and held at the far end either by a wall (``chain.with_wall()``: the wall contact carries F0
    too, the experiments' arrangement of a column of beads on a sensor) or by the same constant force F0
    (free far end: :class:`LoadedEnd`). The kernels integrate displacements from the static state with
    each contact's force less its static force (``granchain.backends.kernels.forces.static_state``),
    which is exactly 0 at rest: the initial state is an exact equilibrium in floating point, and the
    granules ahead of the pulse stay exactly at rest until it reaches them.

    Velocities are measured as without load; contact forces are reported in total (static load
    included: what a sensor measures) and dynamic (less F0). A linear wave travels at the sound speed
    c0 = sqrt((n-1) c delta0^(n-2) / m) granules per unit time (:meth:`sound_speed`); the pulse's
    contacts never open under a small pulse, so the run ends at a time (``has_exit``), not at the
    pulse's exit.
    """

    force: float

    def __post_init__(self):
        import math

        try:
            f = float(self.force)
        except (TypeError, ValueError):
            raise ValueError(f"the static force F0 must be a number, got {self.force!r}") from None
        if not math.isfinite(f) or f < 0.0:
            raise ValueError(f"the static force F0 must be finite and >= 0 (0: no precompression), got {self.force!r}")
        object.__setattr__(self, "force", f)

    def overlaps(self, stiffness, n: float):
        """delta0_k = (F0 / c_k)^(1/(n-1)) for each contact prefactor c_k (NumPy)."""
        import numpy as np

        c = np.asarray(stiffness, dtype=float)
        return (self.force / c) ** (1.0 / (n - 1.0)) if self.force > 0 else np.zeros_like(c)

    def linear_stiffness(self, stiffness, n: float):
        """The contacts' stiffness for small motions about the static state: (n-1) c delta0^(n-2)."""
        import numpy as np

        c = np.asarray(stiffness, dtype=float)
        return (n - 1.0) * c * self.overlaps(c, n) ** (n - 2.0)

    def sound_speed(self, stiffness: float = 1.0, mass: float = 1.0, n: float = 2.5) -> float:
        """c0 = sqrt((n-1) c delta0^(n-2) / m), granules per unit time, of a monodisperse chain
        (Nesterenko 2001, Sec. 1.1): the speed of long linear waves."""
        import math

        return math.sqrt(float(self.linear_stiffness(stiffness, n)) / mass)

    def describe(self) -> dict:
        return {"static_force": self.force}


@dataclass(frozen=True)
class FreeEnd:
    """The far end is free: the pulse leaves through the last granule. The run ends when it has left
    (last contact open, the last granule outrunning every heavy granule: the kernels' ``stop``)."""

    #: The pulse does not come back: the granules behind the front may be integrated more loosely.
    licenses_goal_control: ClassVar[bool] = True
    wall: ClassVar[bool] = False
    #: The run can end at the pulse's exit.
    has_exit: ClassVar[bool] = True


@dataclass(frozen=True)
class LoadedEnd:
    """The far end of a precompressed chain without a wall, held by the constant static force
    ``force`` = F0 (:class:`Precompression`). The pulse is reflected there and its contacts never open
    under a small pulse: the run ends at a time, not at the pulse's exit."""

    force: float

    #: The pulse comes back, and contacts behind the front stay closed: no relaxed zone, no window.
    licenses_goal_control: ClassVar[bool] = False
    why_no_goal_control: ClassVar[str] = ("the chain is precompressed: its loaded far end reflects the pulse back through "
                                          "the granules behind the front, whose contacts stay closed")
    wall: ClassVar[bool] = False
    has_exit: ClassVar[bool] = False


@dataclass(frozen=True)
class RigidWall:
    """The chain ends in a rigid wall (a last granule of infinite mass, contact stiffness ``stiffness``,
    sqrt(2 R_M) for a sphere against a flat wall of the same material, the limit of Eq. r-prime).
    The pulse comes back from it; the run ends when the wall contact has opened for good."""

    stiffness: float

    #: The pulse comes back through the granules behind the front: no relaxed zone, no trailing window.
    licenses_goal_control: ClassVar[bool] = False
    #: What an integrator's record says when its goal-oriented control was switched off here.
    why_no_goal_control: ClassVar[str] = ("the chain ends in a rigid wall, whose reflected pulse comes back through the "
                                          "granules behind the front")
    wall: ClassVar[bool] = True
    #: The run can end when the pulse has come back from the wall (not under precompression: the
    #: wall contact carries the static load and does not open; ``Chain.ends_at_exit``).
    has_exit: ClassVar[bool] = True


@dataclass(frozen=True)
class Impulse:
    """Granule ``granule`` (0-based) struck with ``velocity``; every other granule at rest, every
    contact just touching (paper Sec. II)."""

    velocity: float = 1.0
    granule: int = 0

    #: Granules ahead of the pulse are exactly at rest and uncompressed.
    rest_ahead: ClassVar[bool] = True

    def energy(self, masses) -> float:
        """The energy of the state, all kinetic: m v^2 / 2 of the struck granule."""
        return 0.5 * float(masses[self.granule]) * self.velocity**2

    def momentum(self, masses) -> float:
        return float(masses[self.granule]) * self.velocity

    def describe(self) -> dict:
        return {"initial": "impulse", "velocity": self.velocity}


@dataclass(frozen=True)
class Striker(Impulse):
    """A free sphere of mass ``mass`` (and radius ``radius``, if built from one) that strikes granule 1
    with ``velocity``: the chain's granule 0 in the arrays (``Chain.striker``), at rest against granule 1
    and carrying the static load of a precompressed chain, launched at t = 0. The experiments' way of
    making a pulse (a bead or a rod dropped on the chain; e.g. C. Daraio et al., Phys. Rev. E 73, 026610
    (2006)): a heavy striker sends a train of pulses, a light one a single pulse of less energy than it
    carries. The striker is not observed unless asked (``chain.with_observed``)."""

    mass: float = 1.0
    radius: float | None = None

    def describe(self) -> dict:
        return {"initial": "striker", "velocity": self.velocity, "striker_mass": self.mass,
                **({"striker_radius": self.radius} if self.radius is not None else {})}
