"""A user's family: :class:`CustomFamily`, any chain a function ``build(rng)`` returns.

The function is named in the family's record with the SHA-256 of its source
(:func:`function_fingerprint`, shared with the design spaces of ``granchain.design``), so that a
store resumed with an edited function is refused; it cannot be rebuilt from its record.
"""

from __future__ import annotations

import hashlib
import inspect
from dataclasses import dataclass, field
from typing import Callable, ClassVar

import numpy as np

from .._validate import exponent
from ..model.chain import HERTZ, Chain, from_radii, sphere_mass, sphere_stiffness
from ..model.chainmodel import ChainModel
from ..model.random import realization_rng
from .base import _RADIUS_UNITS, ChainFamily, RandomParameter
from .batch import ChainBatch, _stack


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
    _model: ChainModel = field(repr=False, compare=False)

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
        object.__setattr__(self, "_model", ChainModel.of_chain(probe))  # (asked for every chunk and record)

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
    def model(self) -> ChainModel:
        """The physics of the chains the function returns (that of the first call: every realisation must
        have the same), as one value."""
        return self._model

    @property
    def contact(self):
        return self.model.contact

    @property
    def static_force(self) -> float:
        return self.model.static_force

    @property
    def striker_mass(self) -> float | None:
        return self.model.striker_mass

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
