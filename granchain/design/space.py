"""Design spaces: a parametrisation ``params -> Chain`` with bounds and the designer's constraints.

A design space turns a vector of D real parameters into a chain, and a generation of P vectors into
one batch of P chains of the same size (:meth:`DesignSpace.batch`, built with NumPy and the same
functions as the single-chain builders, so that a row is the :class:`granchain.Chain` of
:meth:`DesignSpace.chain`). The optimisers see only the bounds, the constraints and the batch.

Units are the paper's rescaled ones (Sec. II): radii in units of the struck granule's radius (granule
1 has radius 1 in every ready space), masses R^3 (one material), granule 1 starts with velocity 1.
The ready spaces: :class:`TaperedSpace`, :class:`DecoratedSpace`, :class:`BinarySpace`,
:class:`granchain.design.RandomDecoratedSpace` (robust design over the realisations of a random
decoration, in ``robust``) and :class:`granchain.design.FunctionSpace` (a user's function, in
``function_space``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import count, finite_scalar
from ..families import ChainBatch
from ..solve.defaults import LIGHT_GRANULES, REFLECTING
from ..model.chain import (
    HERTZ,
    Chain,
    from_radii,
    material_stiffness,
    sphere_mass,
    sphere_stiffness,
    wall_stiffness,
)

__all__ = [
    "BinarySpace",
    "Constraints",
    "DecoratedSpace",
    "DesignSpace",
    "TaperedSpace",
]


def _bounds(name: str, value) -> tuple:
    """(low, high) with low < high, both finite; else an error that says what to change."""
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"the bounds of {name} must be a pair (low, high) of numbers, got {value!r}") from None
    if not (np.isfinite(lo) and np.isfinite(hi)):
        raise ValueError(f"the bounds of {name} must be finite, got ({lo:g}, {hi:g})")
    if lo == hi:
        raise ValueError(f"the bounds of {name} are empty ({lo:g}, {hi:g}): give low < high, or fix {name} in the space instead")
    if lo > hi:
        raise ValueError(f"the bounds of {name} are inverted ({lo:g} > {hi:g}): give them as (low, high) = ({hi:g}, {lo:g})")
    return lo, hi


@dataclass(frozen=True)
class Constraints:
    """What a designer may not exceed, all optional (None: no limit), in rescaled units.

    ``max_mass``: total mass of the granules (sum of R^3 for one material; the wall excluded);
    ``max_length``: total length of the chain, the sum of the diameters 2 R_k; ``min_radius`` and
    ``max_radius``: every granule's radius (what can be machined or bought). A design that violates
    one is infeasible: the global optimiser keeps it out of its population (SciPy's
    ``differential_evolution`` with ``NonlinearConstraint``, Lampinen's feasibility rules), the local
    refinement treats it as a barrier."""

    max_mass: float | None = None
    max_length: float | None = None
    min_radius: float | None = None
    max_radius: float | None = None

    def __post_init__(self):
        for name in ("max_mass", "max_length", "min_radius", "max_radius"):
            v = getattr(self, name)
            if v is not None:
                object.__setattr__(self, name, finite_scalar(name, v, positive=True))
        if self.min_radius is not None and self.max_radius is not None and self.min_radius >= self.max_radius:
            raise ValueError(f"min_radius = {self.min_radius:g} must be below max_radius = {self.max_radius:g}")

    @property
    def active(self) -> bool:
        return any(getattr(self, n) is not None for n in ("max_mass", "max_length", "min_radius", "max_radius"))

    def violation(self, radii: np.ndarray, masses: np.ndarray) -> np.ndarray:
        """(P,) the largest relative excess over every limit (<= 0: feasible) of P designs."""
        out = np.full(radii.shape[0], -np.inf)
        if self.max_mass is not None:
            out = np.maximum(out, masses.sum(axis=1) / self.max_mass - 1.0)
        if self.max_length is not None:
            out = np.maximum(out, 2.0 * radii.sum(axis=1) / self.max_length - 1.0)
        if self.min_radius is not None:
            out = np.maximum(out, 1.0 - radii.min(axis=1) / self.min_radius)
        if self.max_radius is not None:
            out = np.maximum(out, radii.max(axis=1) / self.max_radius - 1.0)
        return out

    def describe(self) -> dict:
        return {k: getattr(self, k) for k in ("max_mass", "max_length", "min_radius", "max_radius") if getattr(self, k) is not None}


class DesignSpace:
    """Base of every design space. Subclasses set ``names`` (tuple of parameter names), ``lower`` and
    ``upper`` (arrays), ``wall``, ``n``, ``constraints`` and implement :meth:`radii` (P, M) and
    :meth:`describe`; :meth:`batch` and :meth:`chain` follow for chains of spheres of one material."""

    names: tuple
    lower: np.ndarray
    upper: np.ndarray
    wall: bool = True
    n: float = HERTZ
    constraints: Constraints = Constraints()
    kind: str = "space"
    #: Whether parameters are integers (SciPy's ``integrality``; a binary space).
    integer: bool = False
    #: Realisations averaged per design (1: a deterministic space).
    realizations: int = 1
    #: The kind of chain the batches hold ("decorated" chains get the decorated chains' integrator).
    chain_kind: str = "radii"

    @property
    def character(self) -> str:
        """What the space's chains are like for step control, as a family says it (``ChainFamily.character``;
        :data:`granchain.solve.defaults.CHARACTERS`): decorated chains have light granules between heavy ones,
        which set the step; any other list of radii may jump at random ("reflecting")."""
        return LIGHT_GRANULES if self.chain_kind == "decorated" else REFLECTING

    @property
    def dim(self) -> int:
        return len(self.names)

    @property
    def bounds(self) -> list:
        """[(low, high), ...] per parameter, as SciPy's optimisers take them."""
        return list(zip(self.lower.tolist(), self.upper.tolist()))

    @property
    def granules(self) -> int:
        """Granules of each chain of the space (the wall excluded)."""
        return int(self.radii(0.5 * (self.lower + self.upper)[None]).shape[1])

    @property
    def random(self) -> bool:
        return self.realizations > 1

    def as_array(self, params) -> np.ndarray:
        """(P, D) parameter vectors from a dict by name, one vector (D,) or an array (P, D)."""
        if isinstance(params, dict):
            missing = [n for n in self.names if n not in params]
            if missing:
                raise ValueError(f"the parameters {missing} are missing; this space has {list(self.names)}")
            params = [params[n] for n in self.names]
        X = np.atleast_2d(np.asarray(params, dtype=float))
        if X.shape[1] != self.dim:
            raise ValueError(f"a design of this space has {self.dim} parameters {list(self.names)}, got {X.shape[1]}")
        return X

    def params(self, x) -> dict:
        """The parameters of one design by name."""
        x = self.as_array(x)[0]
        return {n: (int(round(v)) if self.integer else float(v)) for n, v in zip(self.names, x)}

    def check_within(self, X: np.ndarray) -> None:
        bad = np.any((X < self.lower - 1e-12) | (X > self.upper + 1e-12), axis=1)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise ValueError(f"design {self.params(X[i])} lies outside the bounds {dict(zip(self.names, self.bounds))}")

    def random_designs(self, count_: int, seed: int = 0) -> np.ndarray:
        """``count_`` designs drawn uniformly within the bounds (seeded; integers rounded)."""
        rng = np.random.default_rng(seed)
        X = self.lower + (self.upper - self.lower) * rng.random((count_, self.dim))
        return np.round(X) if self.integer else X

    # -- chains ---------------------------------------------------------------------------
    def radii(self, X: np.ndarray) -> np.ndarray:
        """(P, M) radii of P designs (the wall excluded)."""
        raise NotImplementedError

    def observed(self, size: int) -> np.ndarray:
        return np.arange(size)

    def masses_and_stiffness(self, X: np.ndarray, radii: np.ndarray) -> tuple:
        """(masses (P, M), stiffness (P, M-1)) of chains of one material: Eq. (r-prime), m = R^3."""
        return sphere_mass(radii), sphere_stiffness(radii)

    def batch(self, X) -> ChainBatch:
        """The chains of P designs as one batch (a last column of infinite mass for the wall)."""
        X = self.as_array(X)
        radii = self.radii(X)
        masses, stiffness = self.masses_and_stiffness(X, radii)
        P, M = radii.shape
        if self.wall:
            masses = np.concatenate((masses, np.full((P, 1), np.inf)), axis=1)
            stiffness = np.concatenate((stiffness, self.wall_stiffness(X, radii)[:, None]), axis=1)
        return ChainBatch(masses, stiffness, np.ones(P), self.observed(M), self.n)

    def wall_stiffness(self, X, radii) -> np.ndarray:
        """Wall contact of the last granule: sqrt(2 R_M), the limit of Eq. (r-prime) (a wall of the same material)."""
        return wall_stiffness(radii[:, -1])

    def chain(self, params) -> Chain:
        """One design's :class:`granchain.Chain` (the row of :meth:`batch`, with its radii)."""
        X = self.as_array(params)[:1]
        b = self.batch(X)
        radii = self.radii(X)[0]
        if self.wall:
            radii = np.append(radii, np.inf)
        return Chain(b.masses[0], b.stiffness[0], self.n, 1.0, b.observed, radii, f"design-{self.kind}",
                     {"design": self.params(X)})

    def violation(self, X) -> np.ndarray:
        """(P,) constraint violation of P designs (<= 0 feasible)."""
        X = self.as_array(X)
        radii = self.radii(X)
        masses, _ = self.masses_and_stiffness(X, radii)
        return self.constraints.violation(radii, masses)

    def reference_chain(self) -> Chain:
        """The reference a design is judged against: a monodisperse chain of the same number of granules,
        of the struck granule's radius 1, with the same end."""
        size = self.radii(0.5 * (self.lower + self.upper)[None]).shape[1]
        return from_radii(np.ones(size), n=self.n, kind="monodisperse", wall=self.wall)

    def _common(self) -> dict:
        return {"space": self.kind, "parameters": list(self.names), "bounds": [list(b) for b in self.bounds],
                "wall": self.wall, "n": self.n, "constraints": self.constraints.describe()}

    def describe(self) -> dict:
        raise NotImplementedError

    def label(self) -> str:
        return self.kind


def _init(self, names, lower, upper, *, wall, n, constraints, kind):
    object.__setattr__(self, "names", tuple(names))
    object.__setattr__(self, "lower", np.asarray(lower, dtype=float))
    object.__setattr__(self, "upper", np.asarray(upper, dtype=float))
    if not isinstance(wall, (bool, np.bool_)):
        raise ValueError(f"wall must be True or False, got {wall!r}")
    object.__setattr__(self, "wall", bool(wall))
    object.__setattr__(self, "n", finite_scalar("n", n, positive=True))
    if constraints is None:
        constraints = Constraints()
    if not isinstance(constraints, Constraints):
        raise ValueError(f"constraints must be a granchain.design.Constraints, got {constraints!r}")
    object.__setattr__(self, "constraints", constraints)
    object.__setattr__(self, "kind", kind)


@dataclass(frozen=True, init=False)
class TaperedSpace(DesignSpace):
    """Tapered chains of ``size`` granules, R_k = (1 - q)^(k-1) (``profile="geometric"``) or 1 - q (k-1)
    (``"linear"``), the convention of :func:`granchain.tapered`; one parameter ``q`` within ``q``
    bounds (q > 0 shrinks towards the far end, q < 0 grows)."""

    size: int = 20
    profile: str = "geometric"

    def __init__(self, size: int = 20, q=(0.0, 0.15), *, profile: str = "geometric", wall: bool = True, n: float = HERTZ,
                 constraints: Constraints | None = None):
        lo, hi = _bounds("q", q)
        size = count("size", size, minimum=2)
        if profile not in ("geometric", "linear"):
            raise ValueError(f"profile must be 'geometric' or 'linear', got {profile!r}")
        if profile == "geometric" and not hi < 1.0:
            raise ValueError(f"q < 1 for a geometric taper (radii (1 - q)^(k-1)): lower the upper bound {hi:g}")
        if profile == "linear" and not hi < 1.0 / (size - 1):
            raise ValueError(f"a linear taper 1 - q (k-1) needs q < 1/(size - 1) = {1.0 / (size - 1):.6g} for {size} granules; "
                             f"lower the upper bound {hi:g}")
        object.__setattr__(self, "size", size)
        object.__setattr__(self, "profile", profile)
        _init(self, ("q",), [lo], [hi], wall=wall, n=n, constraints=constraints, kind="tapered")

    def radii(self, X) -> np.ndarray:
        q = self.as_array(X)[:, :1]
        k = np.arange(self.size, dtype=float)[None]
        return (1.0 - q) ** k if self.profile == "geometric" else 1.0 - q * k

    def describe(self) -> dict:
        return {**self._common(), "size": self.size, "profile": self.profile}

    def label(self) -> str:
        return f"tapered ({self.profile}), {self.size} granules"


@dataclass(frozen=True, init=False)
class DecoratedSpace(DesignSpace):
    """Decorated chains (paper Sec. III A): ``n_large`` large granules of radius 1 and a small granule
    in each gap, of radius r_j within ``radius`` bounds. ``motif=None``: one radius per gap (N-1
    parameters r1..r{N-1}); ``motif=L``: L radii m1..mL repeated along the chain (a periodic
    decoration). The chain has 2N-1 granules and observes the large ones."""

    n_large: int = 10
    motif: int | None = None

    def __init__(self, n_large: int = 10, radius=(0.05, 0.6), *, motif: int | None = None, wall: bool = True,
                 n: float = HERTZ, constraints: Constraints | None = None):
        lo, hi = _bounds("radius", radius)
        if lo <= 0 or hi > 1:
            raise ValueError(f"small radii must lie in (0, 1] (no larger than the large granules): got ({lo:g}, {hi:g})")
        n_large = count("n_large", n_large, minimum=2)
        if motif is None:
            names = tuple(f"r{j}" for j in range(1, n_large))
        else:
            motif = count("motif", motif, minimum=1)
            if motif > n_large - 1:
                raise ValueError(f"a motif of {motif} radii is longer than the {n_large - 1} gaps: give motif <= {n_large - 1}")
            names = tuple(f"m{j}" for j in range(1, motif + 1))
        object.__setattr__(self, "n_large", n_large)
        object.__setattr__(self, "motif", motif)
        object.__setattr__(self, "chain_kind", "decorated")
        _init(self, names, [lo] * len(names), [hi] * len(names), wall=wall, n=n, constraints=constraints, kind="decorated")

    def small_radii(self, X) -> np.ndarray:
        X = self.as_array(X)
        return X[:, np.arange(self.n_large - 1) % self.motif] if self.motif else X  # the motif repeated along each row

    def radii(self, X) -> np.ndarray:
        small = self.small_radii(X)
        P = small.shape[0]
        radii = np.ones((P, 2 * self.n_large - 1))
        radii[:, 1::2] = small
        return radii

    def observed(self, size: int) -> np.ndarray:
        return np.arange(0, size, 2)

    def describe(self) -> dict:
        return {**self._common(), "n_large": self.n_large, "motif": self.motif}

    def label(self) -> str:
        return f"decorated, {self.n_large} large granules" + (f", motif of {self.motif}" if self.motif else "")


@dataclass(frozen=True, init=False)
class BinarySpace(DesignSpace):
    """Binary sequences: ``size`` granules, each of species a (radius ``radii[0]``, material
    ``materials[0]``) or b; parameters s2..sM in {0, 1} say which (granule 1, the struck one, is
    species a: the unit of the rescaled variables). With ``materials`` (two
    :class:`granchain.units.Material` or preset names) masses are (rho / rho_a) R^3 and contacts
    Hertz's for the pair (:func:`granchain.model.spheres.material_stiffness`), relative to species a."""

    size: int = 20
    species_radii: tuple = (1.0, 0.5)
    materials: tuple | None = None

    def __init__(self, size: int = 20, radii=(1.0, 0.5), *, materials=None, wall: bool = True, n: float = HERTZ,
                 constraints: Constraints | None = None):
        size = count("size", size, minimum=2)
        try:
            ra, rb = (finite_scalar("radii", r, positive=True) for r in radii)
        except (TypeError, ValueError):
            raise ValueError(f"radii must be two positive radii (R_a, R_b), got {radii!r}") from None
        if ra != 1.0:
            raise ValueError(f"species a is granule 1's (the struck granule, radius 1 in rescaled units): give radii = (1, R_b), got R_a = {ra:g}")
        if materials is not None:
            from ..model.spheres import _material

            materials = tuple(_material(m) for m in materials)
            if len(materials) != 2:
                raise ValueError(f"materials must be two materials (species a, b), got {len(materials)}")
            if n != HERTZ:
                raise ValueError("materials give Hertz contacts (n = 5/2)")
        object.__setattr__(self, "size", size)
        object.__setattr__(self, "species_radii", (ra, rb))
        object.__setattr__(self, "materials", materials)
        object.__setattr__(self, "integer", True)
        names = tuple(f"s{k}" for k in range(2, size + 1))
        _init(self, names, [0.0] * len(names), [1.0] * len(names), wall=wall, n=n, constraints=constraints, kind="binary")

    def species(self, X) -> np.ndarray:
        X = self.as_array(X)
        s = np.zeros((X.shape[0], self.size), dtype=np.int64)
        s[:, 1:] = np.round(X) > 0.5
        return s

    def radii(self, X) -> np.ndarray:
        return np.where(self.species(X) == 1, self.species_radii[1], self.species_radii[0]).astype(float)

    def masses_and_stiffness(self, X, radii) -> tuple:
        if self.materials is None:
            return super().masses_and_stiffness(X, radii)
        a, b = self.materials
        s = self.species(X)
        rho = np.where(s == 1, b.rho / a.rho, 1.0)
        stiffness = np.empty((radii.shape[0], radii.shape[1] - 1))
        for p in range(radii.shape[0]):  # Hertz's effective modulus per pair, relative to a-a
            stiffness[p] = material_stiffness(radii[p], [self.materials[k] for k in s[p]], reference=a)
        return rho * sphere_mass(radii), stiffness

    def wall_stiffness(self, X, radii) -> np.ndarray:
        if self.materials is None:
            return super().wall_stiffness(X, radii)
        from ..model.chain import material_wall_stiffness

        s = self.species(X)[:, -1]
        return np.array([material_wall_stiffness(r, self.materials[k], self.materials[k], reference=self.materials[0])
                         for r, k in zip(radii[:, -1], s)])

    def describe(self) -> dict:
        return {**self._common(), "size": self.size, "radii": list(self.species_radii),
                "materials": None if self.materials is None else [m.name for m in self.materials]}

    def label(self) -> str:
        mats = "" if self.materials is None else f" ({self.materials[0].name}/{self.materials[1].name})"
        return f"binary, {self.size} granules of radius {self.species_radii[0]:g} or {self.species_radii[1]:g}{mats}"
