"""A batch of chains in the one chain representation, and the edits every family applies to it.

A family builds R realisations at once as one :class:`ChainBatch` (masses, stiffnesses, initial
velocities, observed granules): the arrays the ensemble kernels take. The edits here (a fixed wall
after the last granule, a free striker before the first) use the very expressions of
:meth:`granchain.Chain.with_wall` and :meth:`granchain.Chain.with_striker`, so that every row stays
bitwise the single chain :meth:`ChainFamily.chain <granchain.ChainFamily.chain>` builds. They live
apart from the families so that the design spaces (``granchain.design``), which build batches of
their own, share the same type.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..model.chain import sphere_stiffness, wall_stiffness


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


def _stack(params: dict, name: str) -> np.ndarray:
    try:
        a = np.asarray(params[name], dtype=float)
    except KeyError:
        raise ValueError(f"build() needs the parameter {name!r}; got {sorted(params)}") from None
    return a[None] if a.ndim == 1 else a
