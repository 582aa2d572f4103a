"""Chain families: how realisation i of an ensemble becomes a chain.

An ensemble (:func:`granchain.run_ensemble`) is a *family* of random chains of one
size. A family says

* which random parameters realisation i draws from its generator
  ``realization_rng(seed, i)`` (:meth:`ChainFamily.parameters <granchain.ChainFamily.parameters>`,
  :meth:`ChainFamily.draw <granchain.ChainFamily.draw>`, :class:`RandomParameter`;
  they are stored per realisation, so any row of a store can be rebuilt);
* how a batch of those parameters becomes the one chain representation, batched
  (:meth:`ChainFamily.build <granchain.ChainFamily.build>`: masses, stiffnesses, initial
  velocities, observed granules), with the same functions the single-chain builders use, so that
  a row is bitwise the :class:`~granchain.Chain` of
  :meth:`ChainFamily.chain <granchain.ChainFamily.chain>`;
* which chains it can build: the exact chain and, for decorated families, the effective
  chain of paper Sec. III A (:attr:`ChainFamily.chains <granchain.ChainFamily.chains>`);
* its record for the store (:meth:`ChainFamily.describe <granchain.ChainFamily.describe>`;
  :func:`family_from_record <granchain.family_from_record>` rebuilds it).

Families: :class:`RandomDecorated <granchain.RandomDecorated>` (the paper's chain),
:class:`TaperedDecorated <granchain.TaperedDecorated>`, :class:`RandomRadii <granchain.RandomRadii>`
(polydisperse), :class:`BinaryRandom <granchain.BinaryRandom>` (two species) and
:class:`CustomFamily <granchain.CustomFamily>` (a user's function). Every family but the custom one takes
``wall=True``: its chains then end in a fixed wall (a last granule of infinite mass,
:meth:`granchain.Chain.with_wall`), how protectors are tested; the free end is the
default. Every family but the custom one also takes the real contacts of
``granchain.model.contacts``: ``contact=granchain.Viscoelastic(gamma)`` (dissipation),
``static_force=F0`` (precompression) and ``striker_mass=M`` (a free striker in front of
granule 1); a custom family's chains bring their own. Units are the paper's rescaled ones (Sec. II):
radii in units of the reference (large) radius, masses R^3, the struck granule starts
with velocity 1.

The package holds one concept per module; every public name is imported from here, its one
public path (the classes and functions are documented under ``granchain``, which names them too):

* ``base``: the contract, :class:`ChainFamily <granchain.ChainFamily>` (with what every family
  shares: the real contacts, the wall's record, drawing a batch of realisations, the default time
  grid) and :class:`RandomParameter`;
* ``batch``: :class:`ChainBatch`, the batched chain arrays, with the wall and the striker every
  family adds to a batch by the expressions of the single-chain builders;
* ``decorated_families``: :class:`RandomDecorated <granchain.RandomDecorated>` and
  :class:`TaperedDecorated <granchain.TaperedDecorated>`, which share the decorated chain and its
  effective chain;
* ``radii_families``: :class:`RandomRadii <granchain.RandomRadii>` and
  :class:`BinaryRandom <granchain.BinaryRandom>`, which draw every radius;
* ``custom``: :class:`CustomFamily <granchain.CustomFamily>` and the fingerprint of a user's
  function that its record holds;
* ``record``: :data:`FAMILIES <granchain.FAMILIES>`,
  :func:`family_from_record <granchain.family_from_record>` and
  :func:`family_from_dataset <granchain.family_from_dataset>`: a family read back from its record or
  from an ensemble's attributes (records of earlier versions in their own meaning), without the
  ensemble store, so that the families do not depend on the ensembles that use them.
"""

from __future__ import annotations

from .base import ChainFamily, RandomParameter
from .batch import ChainBatch
from .custom import CustomFamily, function_fingerprint
from .decorated_families import RandomDecorated, TaperedDecorated
from .radii_families import BinaryRandom, RandomRadii
from .record import FAMILIES, family_from_dataset, family_from_record

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
