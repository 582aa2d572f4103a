"""The model: what a chain *is*, as values, before anything integrates it.

- :mod:`~granchain.model.contacts`: the contact law (:class:`ContactLaw`: :class:`PowerLaw`, paper Eq. hertz-1,
  the dissipative :class:`Viscoelastic` and :class:`Viscous`, the yielding :class:`ElasticPlastic`);
- :mod:`~granchain.model.conditions`: the static load (:class:`Precompression`), the far boundary
  (:class:`FreeEnd`, :class:`LoadedEnd`, :class:`FixedWall`; :func:`far_end`, :func:`ends_at_exit`) and the
  initial state (:class:`Impulse`, :class:`Striker`); these and the laws are small frozen values that
  declare the assumptions they license (forces depend on positions only, the granules ahead of the pulse
  are exactly at rest, the pulse leaves for good), all exported by ``contacts`` and here;
- ``granchain.model.chainmodel``: :class:`~granchain.ChainModel`, the values above that a family of
  chains shares (law, static load, striker, wall), as one value;
- :mod:`~granchain.model.collision`: the two-body collision of the viscoelastic law (its coefficient
  of restitution, and the damping that gives one);
- :mod:`~granchain.model.spheres`: spheres' masses and contact prefactors (paper Sec. II, Eq. r-prime), against
  a wall and between materials, and the ranges double precision integrates;
- :mod:`~granchain.model.chain`: :class:`~granchain.Chain` (masses, stiffnesses, exponent, the values
  above) and its builders from radii;
- :mod:`~granchain.model.effective`: the decorated chain's effective chain (paper Sec. III A);
- :mod:`~granchain.model.distributions`: small-radius distributions;
- :mod:`~granchain.model.random`: random decorated chains drawn from (seed, realisation).

Everything here is NumPy and SciPy (no compiled code): solving (:mod:`granchain.solve`) and the
compiled code (:mod:`granchain.backends`) read these values, never the other way round.
"""

from . import contacts as _contacts
from .contacts import *  # noqa: F401,F403 (the model's values: a new contact law is exported by its own module)

__all__ = list(_contacts.__all__)


def __getattr__(name):
    if name == "RigidWall":  # renamed FixedWall: "rigid" means an infinitely stiff wall material
        from . import contacts

        return contacts.__getattr__(name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
