"""The model a chain carries besides its masses and stiffnesses, as small frozen values: the contact
law, the far boundary and the initial state. Each declares the assumptions it licenses, so that the
integrators and backends ask once, here, instead of re-deriving them from sentinels:

- :class:`PowerLaw` (paper Eq. hertz-1, Hertz for n = 5/2): forces depend on positions only
  (``conservative``: what licenses Nystrom methods, Verlet and a conserved energy) and vanish when a
  contact opens (``tensionless``: an opened contact is where a pulse leaves granules behind).
- :class:`FreeEnd` and :class:`RigidWall`: whether the pulse leaves through the far end for good
  (``licenses_goal_control``: the granules behind the front will not see it again, so the relaxed
  zone and the trailing window of ``granchain.DP5`` are safe) and which rule ends the run.
- :class:`Impulse` (the paper's Sec. II): granule 1 struck with a velocity, every other granule
  exactly at rest and uncompressed (``rest_ahead``: what licenses integrating only the granules the
  pulse has reached, bitwise the same as integrating all).

A :class:`granchain.Chain` derives these from its arrays (a last mass ``inf`` is the wall) and
exposes them as ``chain.contact``, ``chain.boundary``, ``chain.initial``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

__all__ = ["PowerLaw", "FreeEnd", "RigidWall", "Impulse"]


@dataclass(frozen=True)
class PowerLaw:
    """Contact force c delta^(n-1) for compression delta > 0, else 0 (Eq. motion_rescaled)."""

    n: float = 2.5

    #: Forces depend on positions only (x'' = f(x)).
    conservative: ClassVar[bool] = True
    #: No force across an open contact (no tension, no precompression).
    tensionless: ClassVar[bool] = True

    def force(self, compression, stiffness):
        """c delta^(n-1) for delta > 0, else 0 (NumPy, any shape)."""
        import numpy as np

        d = np.asarray(compression, dtype=float)
        return np.where(d > 0.0, stiffness * np.abs(d) ** (self.n - 1.0), 0.0)


@dataclass(frozen=True)
class FreeEnd:
    """The far end is free: the pulse leaves through the last granule. The run ends when it has left
    (last contact open, the last granule outrunning every heavy granule: the kernels' ``stop``)."""

    #: The pulse does not come back: the granules behind the front may be integrated more loosely.
    licenses_goal_control: ClassVar[bool] = True
    wall: ClassVar[bool] = False


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
