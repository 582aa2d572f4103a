"""What a chain carries besides its masses, stiffnesses and contact law: the static load, the far end and the
initial state, as small frozen values, each declaring what it licenses (the contact laws are in
:mod:`granchain.model.contacts`, which exports these values too):

- :class:`Precompression`: a static force F0 compresses the chain before it is struck; the chain
  starts in exact static equilibrium and the pulse rides on it.
- :class:`FreeEnd`, :class:`LoadedEnd` and :class:`FixedWall`: whether the pulse leaves through the
  far end for good (``licenses_goal_control``: the granules behind the front will not see it again,
  so the relaxed zone and the trailing window of ``granchain.DP5`` are safe) and which rule ends the
  run (``has_exit``, :func:`ends_at_exit`); :func:`far_end` says which end a chain has.
- :class:`Impulse` (the paper's Sec. II) and :class:`Striker`: granule 1, or a free striker in front
  of it, struck with a velocity, every other granule exactly at rest in the static state
  (``rest_ahead``: what licenses integrating only the granules the pulse has reached, bitwise the same
  as integrating all).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

from .._validate import real_number

__all__ = ["Precompression", "FreeEnd", "LoadedEnd", "FixedWall", "far_end", "ends_at_exit", "Impulse", "Striker",
           "MAX_STATIC_FORCE", "MIN_DYNAMIC_RATIO"]

#: The largest static force :class:`Precompression` takes (rescaled units, whatever the chain): a reference
#: contact (prefactor 1, mass 1) struck at speed 1 under it has a dynamic compression 3e-13 of its static
#: overlap, which double precision (eps = 2.2e-16) no longer resolves.
MAX_STATIC_FORCE = 1e12

#: The smallest ratio of the dynamic compression to the static overlap at the struck contact that a chain
#: accepts (:meth:`Precompression.resolvable`): delta0 + D in double precision keeps D to 2.2e-16 / 1e-7
#: = 2e-9 relative, well inside the accuracy contract (1e-6) of the peaks.
MIN_DYNAMIC_RATIO = 1e-7


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

        f = real_number(self.force, "the static force F0")
        if not math.isfinite(f) or f < 0.0:
            raise ValueError(f"the static force F0 must be finite and >= 0 (0: no precompression), got {self.force!r}")
        if f > MAX_STATIC_FORCE:
            raise ValueError(
                f"the static force F0 = {f:g} (rescaled) exceeds {MAX_STATIC_FORCE:g}: in rescaled units the struck "
                "granule moves at speed 1 against contacts of prefactor ~1, so under such a load its dynamic compression "
                "is below 1e-12 of the static overlap and vanishes in the rounding of double precision (the pulse would "
                "be invisible); give F0 in 0..1e12 (a chain refuses a smaller one too when its dynamic part is not "
                "resolvable, granchain.Chain)")
        object.__setattr__(self, "force", f)

    @classmethod
    def of(cls, load) -> "Precompression":
        """``load`` as the static load's value: itself if it is one, else the static force F0 it gives (checked)."""
        return load if isinstance(load, cls) else cls(load)

    @property
    def applied(self) -> bool:
        """Whether the chain is loaded (F0 > 0; 0 is the paper's unloaded chain)."""
        return self.force > 0.0

    def resolvable(self, mass: float, stiffness: float, n: float, velocity: float) -> float:
        """D / delta0 at a contact of prefactor ``stiffness`` whose granule of ``mass`` is struck with
        ``velocity``: the dynamic compression D = v sqrt(m / k0) of a linear oscillation about the static
        state (k0 = (n-1) c delta0^(n-2), :meth:`linear_stiffness`) over the static overlap delta0 (inf
        without a load). The kernels add D to delta0 in double precision, which keeps D only to
        eps delta0 / D: below ``MIN_DYNAMIC_RATIO`` the pulse is lost to rounding."""
        if self.force == 0.0:
            return math.inf
        d0 = float(self.overlaps(stiffness, n))
        k0 = float(self.linear_stiffness(stiffness, n))
        return velocity * math.sqrt(mass / k0) / d0

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

    @classmethod
    def of(cls, stiffness, load: Precompression) -> "FreeEnd":
        """The free end of any chain (``stiffness`` and ``load`` as for the other ends)."""
        return cls()


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

    @classmethod
    def of(cls, stiffness, load: Precompression) -> "LoadedEnd":
        """The end of a chain loaded by ``load``, held by its force F0."""
        return cls(load.force)


@dataclass(frozen=True)
class FixedWall:
    """The chain ends in a fixed wall: an immovable flat wall (a last granule of infinite mass) with contact
    stiffness ``stiffness``, sqrt(2 R_M) for a sphere against a wall of the same material (the limit
    R_{M+1} -> infinity of Eq. r-prime), or that of another material (``Chain.with_wall(material=...)``).
    The pulse comes back from it; the run ends when the wall contact has opened for good.

    "Rigid" means one thing in granchain: an infinitely stiff wall *material* (``material="rigid"``,
    1/E* = (1 - nu_M^2)/E_M), which is one kind of fixed wall. This class was called ``RigidWall`` before
    0.5; that name still works and warns."""

    stiffness: float

    #: The pulse comes back through the granules behind the front: no relaxed zone, no trailing window.
    licenses_goal_control: ClassVar[bool] = False
    #: What an integrator's record says when its goal-oriented control was switched off here.
    why_no_goal_control: ClassVar[str] = ("the chain ends in a fixed wall, whose reflected pulse comes back through the "
                                          "granules behind the front")
    wall: ClassVar[bool] = True
    #: The run can end when the pulse has come back from the wall (not under precompression: the
    #: wall contact carries the static load and does not open; ``Chain.ends_at_exit``).
    has_exit: ClassVar[bool] = True

    @classmethod
    def of(cls, stiffness, load: Precompression) -> "FixedWall":
        """The wall of a chain whose last contact prefactor (the wall contact) is ``stiffness[-1]``."""
        return cls(float(stiffness[-1]))


def far_end(wall: bool, load: Precompression) -> type:
    """The kind of a chain's far end (the class; :meth:`FixedWall.of` and the others make the value of a
    chain): a wall if it ends in one; else held by the static force F0 (:class:`LoadedEnd`) when loaded,
    else free."""
    return FixedWall if wall else (LoadedEnd if load.applied else FreeEnd)


def ends_at_exit(end: type, load: Precompression) -> bool:
    """Whether a run can end at the pulse's exit (or its return from a wall): where the far end has one,
    and not under a static load, whose contacts do not open (such a run ends at a time instead,
    ``granchain.solve.simulation.default_t_max``)."""
    return end.has_exit and not load.applied


@dataclass(frozen=True)
class Impulse:
    """Granule ``granule`` (0-based) struck with ``velocity``; every other granule at rest, every
    contact just touching (paper Sec. II)."""

    velocity: float = 1.0
    granule: int = 0

    #: Granules ahead of the pulse are exactly at rest and uncompressed.
    rest_ahead: ClassVar[bool] = True

    def __post_init__(self):
        v = real_number(self.velocity, "velocity (the struck granule's initial speed)")
        if not (math.isfinite(v) and v > 0.0):
            raise ValueError(f"velocity (the struck granule's initial speed) must be finite and > 0, got {self.velocity!r}: "
                             "the chain is struck toward +x, into its granules (to strike the other end, reverse the chain)")
        g = self.granule
        if isinstance(g, bool) or not float(real_number(g, "granule")).is_integer() or int(g) < 0:
            raise ValueError(f"granule (the 0-based index of the struck granule) must be a whole number >= 0, got {g!r}")
        object.__setattr__(self, "velocity", v)
        object.__setattr__(self, "granule", int(g))

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

    def __post_init__(self):
        super().__post_init__()
        m = real_number(self.mass, "the striker's mass")
        if not (math.isfinite(m) and m > 0.0):
            raise ValueError(f"the striker's mass must be finite and > 0 (rescaled: the reference granule's mass is 1), "
                             f"got {self.mass!r}")
        object.__setattr__(self, "mass", m)
        if self.radius is not None:
            r = real_number(self.radius, "the striker's radius")
            if not (math.isfinite(r) and r > 0.0):
                raise ValueError(f"the striker's radius must be finite and > 0 (rescaled: the reference granule's radius "
                                 f"is 1), or None, got {self.radius!r}")
            object.__setattr__(self, "radius", r)

    def describe(self) -> dict:
        return {"initial": "striker", "velocity": self.velocity, "striker_mass": self.mass,
                **({"striker_radius": self.radius} if self.radius is not None else {})}
