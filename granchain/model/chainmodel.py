"""A chain's physics as one value: :class:`ChainModel` (the contact law, the static load, the striker and the
far end), what a family of random chains shares besides its random arrays.

The chain families (``granchain.families``) carry it as ``family.model``, the ensemble runner, the store's
records and the design evaluator pass it on whole, and a backend makes each row's :class:`granchain.Chain`
from it (:meth:`ChainModel.chain_keywords`). Each part answers for its own physics (the law's
``conservative``, ``dissipates``, ``history``; the load's static state; the boundary's exit rule): this
value only holds them together and says what the paper's chain is (:attr:`ChainModel.elastic`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import finite_scalar
from .contacts import ContactLaw, PowerLaw, Precompression, checked_law, ends_at_exit, far_end, law_from_record

__all__ = ["ChainModel"]


@dataclass(frozen=True)
class ChainModel:
    """What the chains of a family share besides their masses and stiffnesses.

    Parameters
    ----------
    contact : ContactLaw or None
        The contact law (None: ``PowerLaw(n)``, the paper's, whatever the chains' exponent n).
    static_force : float or Precompression
        The precompression F0 >= 0 (rescaled; 0: none).
    striker_mass : float or None
        A free sphere of this mass (rescaled) struck in front of granule 1 (None: granule 1 struck, the
        paper's initial state).
    wall : bool
        Whether the chains end in a fixed wall.
    """

    contact: ContactLaw | None = None
    static_force: float = 0.0
    striker_mass: float | None = None
    wall: bool = False

    def __post_init__(self):
        checked_law(self.contact)
        load = Precompression.of(self.static_force)
        object.__setattr__(self, "static_force", load.force)
        if self.striker_mass is not None:
            object.__setattr__(self, "striker_mass", finite_scalar("striker_mass", self.striker_mass, positive=True))
        if not isinstance(self.wall, (bool, np.bool_)):
            raise ValueError(f"wall must be True or False, got {self.wall!r}")
        object.__setattr__(self, "wall", bool(self.wall))

    def for_exponent(self, n: float, owner: str = "family") -> "ChainModel":
        """This model checked for chains of exponent ``n`` (the law's exponent must be n; a static load
        needs n > 1; ``owner``: whose n it is, for the message), with the paper's law given as ``PowerLaw(n)``
        recorded as the default (None), so that stores of the paper's chains keep their record."""
        law = checked_law(self.contact, n, owner)
        if isinstance(law, PowerLaw):
            law = None
        if self.precompression.applied and n <= 1.0:
            raise ValueError(f"precompression needs an exponent n > 1, got n = {n:g}")
        return ChainModel(law, self.static_force, self.striker_mass, self.wall)

    @classmethod
    def of_chain(cls, chain) -> "ChainModel":
        """The model of one :class:`granchain.Chain` (its law, static load, striker mass and wall)."""
        law = None if isinstance(chain.contact, PowerLaw) else chain.contact
        return cls(law, chain.static_force, float(chain.masses[0]) if chain.striker else None, chain.wall)

    # -- what it is -----------------------------------------------------------------------
    def law(self, n: float) -> ContactLaw:
        """The contact law of chains of exponent ``n``."""
        return PowerLaw(n) if self.contact is None else self.contact

    @property
    def precompression(self) -> Precompression:
        """The static load as its model value (its static state: ``overlaps``, ``linear_stiffness``)."""
        return Precompression(self.static_force)

    @property
    def elastic(self) -> bool:
        """The paper's contacts: the power law, no static load, no striker (a wall aside)."""
        return self.contact is None and not self.precompression.applied and self.striker_mass is None

    @property
    def boundary(self) -> type:
        """The kind of the chains' far end (``FixedWall``, ``LoadedEnd`` or ``FreeEnd``, the class: a wall's
        stiffness is each chain's), which says whether goal-oriented error control is licensed."""
        return far_end(self.wall, self.precompression)

    @property
    def ends_at_exit(self) -> bool:
        """Whether the chains' runs can end at the pulse's exit (not under a static load: they run to a
        time bounding the pulse's crossing instead)."""
        return ends_at_exit(self.boundary, self.precompression)

    @property
    def conservative(self) -> bool:
        """Forces of positions only (the law's answer): what licenses RKN4, Verlet and a conserved energy."""
        return self.contact is None or self.contact.conservative

    @property
    def dissipates(self) -> bool:
        """Whether the contacts take energy out of the pulse (the law's answer)."""
        return self.contact is not None and self.contact.dissipates

    @property
    def history(self) -> bool:
        """Whether each contact carries state of its own (a law with memory, such as yielding contacts)."""
        return self.contact is not None and self.contact.history

    # -- what it gives ------------------------------------------------------------------
    def chain_keywords(self, n: float) -> dict:
        """The :class:`granchain.Chain` keywords of a row whose arrays already hold the striker and the wall
        (the batches of the families): ``contact``, ``static_force``, ``striker``."""
        return {"contact": self.law(n), "static_force": self.static_force, "striker": self.striker_mass is not None}

    def apply(self, chain):
        """``chain`` (free end, struck on granule 1, the paper's contacts) with this model's striker and
        contacts (a chain family's single chain: bitwise a row of its batch). The wall is the builder's
        (the chain families build it into the arrays)."""
        if self.striker_mass is not None:
            chain = chain.with_striker(mass=self.striker_mass)
        if self.contact is not None or self.precompression.applied:
            chain = chain.replace(contact=self.law(chain.n), static_force=self.static_force)
        return chain

    def record(self) -> dict:
        """The parts of a family's record that differ from the paper's chain, in the order stores have
        written them (``wall``, then ``contact``, ``static_force``, ``striker_mass``): records of the
        paper's chains stay as before, so their stores resume unchanged."""
        out = {"wall": True} if self.wall else {}
        if self.contact is not None:
            out["contact"] = self.contact.describe()
        if self.precompression.applied:
            out["static_force"] = self.static_force
        if self.striker_mass is not None:
            out["striker_mass"] = self.striker_mass
        return out

    @classmethod
    def from_record(cls, record: dict) -> "ChainModel":
        """The model a family record (:meth:`record`) holds; the paper's where it holds none of its keys."""
        law = record.get("contact")
        # (records of the viscoelastic law written before its clamp option hold no "clamp": they were all
        # clamped, its default)
        return cls(None if law is None else law_from_record(law), float(record.get("static_force") or 0.0),
                   None if record.get("striker_mass") is None else float(record["striker_mass"]),
                   bool(record.get("wall", False)))

    def label(self) -> str:
        """The model for titles: ", against a fixed wall, <law>, precompressed F0 = ..., striker of mass ..."
        ("" for the paper's chain)."""
        parts = ["against a fixed wall"] if self.wall else []
        if self.contact is not None:
            parts.append(self.contact.label(4))
        if self.precompression.applied:
            parts.append(f"precompressed F0 = {self.static_force:.4g}")
        if self.striker_mass is not None:
            parts.append(f"striker of mass {self.striker_mass:.4g}")
        return (", " + ", ".join(parts)) if parts else ""
