"""One representation for every chain, and the builders that make one.

A :class:`Chain` is granules 1..M on a line, just touching (no precompression),
all at rest except granule 1 which moves with ``initial_velocity``. Neighbours
k, k+1 repel with the power-law potential (c_k / n) delta^n while
delta = x_k - x_{k+1} > 0 (paper Eq. hertz-1 in the rescaled form of Eq.
motion_rescaled). Everything the integrators need is in ``masses``,
``stiffness``, ``n`` and ``initial_velocity``; ``observed`` names the granules
whose peak velocity and peak time are recorded.

A rigid wall at the far end is the same representation: a last granule of
infinite radius and mass (``masses[-1] = inf``, inverse mass 0) whose contact
stiffness is the limit of Eq. (r-prime) for R_{M} -> infinity, sqrt(2 R_{M-1})
(:func:`wall_stiffness`). Build one with ``wall=True`` on the builders or
:meth:`Chain.with_wall`; the free end stays the default (the paper's case).

Units are the paper's rescaled ones (Sec. II): radii in units of the radius of
the reference (first, large) granule, masses m = R^3 in units of its mass, time
and displacement as in Eq. (motion_rescaled).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._validate import count, exponent, finite_scalar, positive_array
from .contacts import FreeEnd, Impulse, PowerLaw, RigidWall

__all__ = [
    "Chain",
    "from_radii",
    "monodisperse",
    "tapered",
    "decorated",
    "regular_decorated",
    "sphere_mass",
    "sphere_stiffness",
    "wall_stiffness",
]

HERTZ = 2.5


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class Chain:
    """A granular chain in rescaled units (paper Eq. motion_rescaled).

    Parameters
    ----------
    masses : (M,) array, M >= 2
        Granule masses m_k > 0. The last may be ``numpy.inf``: a rigid wall (it never
        moves, is never observed, and takes the pulse's impulse; see :attr:`wall`).
    stiffness : (M-1,) array
        Contact prefactors c_k > 0: the force between k and k+1 is
        c_k * delta^(n-1) for delta > 0 (paper: r_k for spheres, Eq. r-prime;
        r_k / 2^(n-1) in the effective chain, Eq. effec-int).
    n : float
        Exponent of the contact potential (c/n) delta^n; n > 1. Hertz: 2.5.
    initial_velocity : float
        Velocity of granule 1 at t = 0 (the impulse); 1 in the paper's units.
    observed : (K,) int array, optional
        0-based indices of the granules whose pulse is recorded, ascending
        (default: all). For decorated chains these are the large granules.
    radii : (M,) array or None
        Radii the chain was built from (None for an effective chain); ``inf`` for a wall.
    kind : str
        A short description ("radii", "decorated", "effective", ...).

    Attributes
    ----------
    contact : granchain.model.contacts.PowerLaw
        The contact law (exponent ``n``).
    boundary : granchain.model.contacts.FreeEnd or granchain.model.contacts.RigidWall
        The far end (a wall when the last mass is infinite).
    initial : granchain.model.contacts.Impulse
        The initial state: granule 1 struck with ``initial_velocity``, the rest at rest.
    """

    masses: np.ndarray
    stiffness: np.ndarray
    n: float = HERTZ
    initial_velocity: float = 1.0
    observed: np.ndarray | None = None
    radii: np.ndarray | None = None
    kind: str = "custom"
    meta: dict = field(default_factory=dict, repr=False)
    contact: PowerLaw = field(init=False, repr=False)
    boundary: FreeEnd | RigidWall = field(init=False, repr=False)
    initial: Impulse = field(init=False, repr=False)

    def __post_init__(self):
        m = _masses_with_wall(self.masses)
        c = positive_array("stiffness", self.stiffness)
        if c.size != m.size - 1:
            raise ValueError(
                f"stiffness needs one entry per contact (len(masses) - 1 = {m.size - 1}), got {c.size}"
            )
        n = exponent(self.n)
        v0 = finite_scalar("initial_velocity", self.initial_velocity, positive=True)
        wall = bool(np.isinf(m[-1]))
        if self.observed is None:
            obs = np.arange(m.size - wall, dtype=np.int64)
        else:
            obs = np.asarray(self.observed)
            if obs.ndim != 1 or obs.size == 0 or not np.issubdtype(obs.dtype, np.integer):
                raise ValueError("observed must be a non-empty 1-d sequence of 0-based granule indices")
            obs = obs.astype(np.int64)
            if obs.min() < 0 or obs.max() >= m.size:
                raise ValueError(f"observed indices must lie in 0..{m.size - 1} (0-based), got {obs.tolist()}")
            if np.any(np.diff(obs) <= 0):
                raise ValueError("observed indices must be strictly increasing (no repeats)")
            if wall and obs[-1] == m.size - 1:
                raise ValueError(f"observed includes granule {m.size - 1} (0-based), the wall (infinite mass), which never moves: "
                                 f"observe granules 0..{m.size - 2}")
        radii = None if self.radii is None else _radii_with_wall(self.radii, wall)
        if radii is not None and radii.size != m.size:
            raise ValueError(f"radii has {radii.size} entries for {m.size} granules")
        object.__setattr__(self, "masses", _frozen(m))
        object.__setattr__(self, "stiffness", _frozen(c))
        object.__setattr__(self, "n", n)
        object.__setattr__(self, "initial_velocity", v0)
        object.__setattr__(self, "observed", _frozen(obs))
        object.__setattr__(self, "radii", None if radii is None else _frozen(radii))
        object.__setattr__(self, "contact", PowerLaw(n))
        object.__setattr__(self, "boundary", RigidWall(float(c[-1])) if wall else FreeEnd())
        object.__setattr__(self, "initial", Impulse(v0))

    # -- derived quantities -------------------------------------------------
    @property
    def size(self) -> int:
        """Number of granules M."""
        return int(self.masses.size)

    @property
    def wall(self) -> bool:
        """Whether the far end is a rigid wall (:attr:`boundary`; the last granule has infinite mass)."""
        return self.boundary.wall

    @property
    def energy(self) -> float:
        """Total energy, all kinetic at t = 0: m_1 v_1^2 / 2 (a wall, at rest, has none)."""
        return self.initial.energy(self.masses)

    @property
    def momentum(self) -> float:
        """Total momentum m_1 v_1 of the granules (conserved with free ends; with a wall the
        granules lose the wall's impulse, :attr:`granchain.PulseResult.wall_impulse`)."""
        return self.initial.momentum(self.masses)

    def with_wall(self, stiffness: float | None = None) -> "Chain":
        """The same chain ending in a rigid wall: one more granule, of infinite mass.

        The wall contact's stiffness is ``stiffness`` or, for a chain built from radii,
        sqrt(2 R_M) (:func:`wall_stiffness`, the limit of Eq. r-prime). A chain without
        radii (e.g. an effective chain) needs ``stiffness``.
        """
        if self.wall:
            raise ValueError("this chain already ends in a wall")
        if stiffness is None:
            if self.radii is None:
                raise ValueError(f"a {self.kind} chain has no radii to give the wall contact its stiffness sqrt(2 R_M): "
                                 "pass stiffness=... (the prefactor c of the wall force c delta^(n-1))")
            stiffness = wall_stiffness(self.radii[-1])
        c_wall = finite_scalar("stiffness", stiffness, positive=True)
        radii = None if self.radii is None else np.append(self.radii, np.inf)
        return Chain(np.append(self.masses, np.inf), np.append(self.stiffness, c_wall), self.n, self.initial_velocity,
                     self.observed, radii, self.kind, dict(self.meta))

    def with_observed(self, observed) -> "Chain":
        """The same chain observing other granules (0-based indices)."""
        return Chain(self.masses, self.stiffness, self.n, self.initial_velocity, observed, self.radii, self.kind, dict(self.meta))

    def __repr__(self) -> str:
        return (
            f"Chain(kind={self.kind!r}, M={self.size}{' (the last a wall)' if self.wall else ''}, n={self.n:g}, "
            f"initial_velocity={self.initial_velocity:g}, observed={self.observed.size} granules)"
        )


def _masses_with_wall(masses) -> np.ndarray:
    """Positive finite masses, except that the last may be +inf (a wall)."""
    try:
        a = np.array(masses, dtype=float).reshape(-1) if np.ndim(masses) <= 1 else None
    except (TypeError, ValueError):
        a = None
    if a is not None and a.size >= 2 and np.isinf(a[:-1]).any():
        i = int(np.flatnonzero(np.isinf(a[:-1]))[0])
        raise ValueError(f"masses: entry {i} is infinite; only the last granule may be infinitely heavy (a rigid wall)")
    if a is not None and a.size >= 2 and a[-1] == np.inf:
        return np.append(positive_array("masses", a[:-1], min_size=1), np.inf)
    return positive_array("masses", masses, min_size=2)


def _radii_with_wall(radii, wall: bool) -> np.ndarray:
    if wall:
        r = np.array(radii, dtype=float).reshape(-1)
        if r.size < 1 or r[-1] != np.inf:
            raise ValueError("radii of a chain ending in a wall must end with inf (the wall's radius)")
        return np.append(positive_array("radii", r[:-1]), np.inf)
    return positive_array("radii", radii)


def wall_stiffness(radius) -> np.ndarray:
    """Contact prefactor of a sphere of radius R against a rigid wall: sqrt(2 R).

    The limit of Eq. (r-prime), sqrt(2 R_k R_{k+1} / (R_k + R_{k+1})), for R_{k+1} -> infinity
    (a flat wall of the same material). Works on arrays (a batch of last radii).
    """
    return np.sqrt(2.0 * np.asarray(radius, dtype=float))  # Eq. (r-prime), R_{k+1} -> inf


def sphere_mass(radii: np.ndarray) -> np.ndarray:
    """m = R^3 (equal density, paper Sec. II), written as a product so that arrays of any
    shape (one chain or a batch of chains) give bitwise the same masses."""
    r = np.asarray(radii, dtype=float)
    return r * r * r


def sphere_stiffness(radii: np.ndarray) -> np.ndarray:
    """Contact prefactor of neighbouring spheres, r_k = sqrt(2 R_k R_{k+1} / (R_k + R_{k+1})).

    Paper Eq. (r-prime); radii in units of the reference radius, along the last axis.
    """
    r = np.asarray(radii, dtype=float)
    return np.sqrt(2.0 * r[..., :-1] * r[..., 1:] / (r[..., :-1] + r[..., 1:]))  # Eq. (r-prime)


def from_radii(radii, *, n: float = HERTZ, initial_velocity: float = 1.0, observed=None, kind: str = "radii",
               wall: bool = False) -> Chain:
    """A chain of spheres of one material from any list of radii.

    m_k = R_k^3 (paper Sec. II: M_k = M_1 m_k with equal density), stiffness from
    Eq. (r-prime). All granules are observed unless ``observed`` says otherwise.
    ``wall=True`` ends the chain in a rigid wall (:meth:`Chain.with_wall`).
    """
    r = positive_array("radii", radii, min_size=1)
    if r.size < 2:
        raise ValueError(f"a chain needs at least 2 granules, got {r.size} radius")
    chain = Chain(sphere_mass(r), sphere_stiffness(r), n, initial_velocity, observed, r, kind)
    return chain.with_wall() if wall else chain


def monodisperse(size: int, *, n: float = HERTZ, initial_velocity: float = 1.0, wall: bool = False) -> Chain:
    """``size`` equal spheres of radius 1 (and a rigid wall after them with ``wall=True``)."""
    size = count("size", size, minimum=2)
    return from_radii(np.ones(size), n=n, initial_velocity=initial_velocity, kind="monodisperse", wall=wall)


def tapered(size: int, q: float, *, profile: str = "geometric", n: float = HERTZ, initial_velocity: float = 1.0,
            wall: bool = False) -> Chain:
    """A tapered chain starting from radius 1.

    ``profile="geometric"``: R_k = (1 - q)^(k-1); ``profile="linear"``:
    R_k = 1 - q (k-1). q > 0 tapers down, q < 0 grows (an "inverted" taper).
    """
    size = count("size", size, minimum=2)
    q = finite_scalar("q", q)
    k = np.arange(size, dtype=float)
    if profile == "geometric":
        if not q < 1.0:
            raise ValueError(f"q = {q!r} must be < 1 for a geometric taper R_k = (1 - q)^(k-1)")
        radii = (1.0 - q) ** k
    elif profile == "linear":
        radii = 1.0 - q * k
        if radii[-1] <= 0.0:
            raise ValueError(
                f"linear taper q = {q!r} makes radius {size} non-positive ({radii[-1]:.3g}); "
                f"need q < {1.0 / (size - 1):.6g} for {size} granules"
            )
    else:
        raise ValueError(f"profile must be 'geometric' or 'linear', got {profile!r}")
    return from_radii(radii, n=n, initial_velocity=initial_velocity, kind=f"tapered-{profile}", wall=wall)


def decorated(small_radii, *, large_radius=1.0, n: float = HERTZ, initial_velocity: float = 1.0, wall: bool = False) -> Chain:
    """N large granules with one small granule between each pair (paper Sec. III A).

    ``small_radii`` (N-1 values, in units of the reference radius) sit between
    large granules k and k+1. ``large_radius`` is one radius for all N large
    granules (the paper's monodisperse case, default 1) or N radii (e.g. a tapered
    decorated chain, :class:`granchain.TaperedDecorated`). A small granule may not
    be larger than its smaller neighbour (use :func:`from_radii` for any other
    chain). The chain has 2N-1 granules, both ends large, and observes the large
    granules (0-based indices 0, 2, ..., 2N-2). ``wall=True`` adds a rigid wall after
    large granule N (granule 2N, never observed).
    """
    s = positive_array("small_radii", small_radii, min_size=1)
    if np.ndim(large_radius) == 0:
        big = np.full(s.size + 1, finite_scalar("large_radius", large_radius, positive=True))
    else:
        big = positive_array("large_radius", large_radius)
        if big.size != s.size + 1:
            raise ValueError(f"large_radius needs one radius per large granule ({s.size + 1} for {s.size} small radii), got {big.size}")
    too_big = s > np.minimum(big[:-1], big[1:])
    if too_big.any():
        j = int(np.flatnonzero(too_big)[0])
        raise ValueError(
            f"small_radii[{j}] = {s[j]:g} is larger than its neighbouring large granules "
            f"({big[j]:g}, {big[j + 1]:g}): a decorated chain needs small granules no larger than the large ones; "
            "build any other chain with granchain.from_radii"
        )
    radii = np.empty(2 * s.size + 1)
    radii[0::2] = big
    radii[1::2] = s
    chain = from_radii(radii, n=n, initial_velocity=initial_velocity, observed=np.arange(0, radii.size, 2), kind="decorated")
    chain.meta["small_radii"] = s
    return chain.with_wall() if wall else chain


def regular_decorated(size: int, pattern, *, n: float = HERTZ, initial_velocity: float = 1.0, wall: bool = False) -> Chain:
    """A decorated chain of ``size`` large granules whose small radii repeat ``pattern``.

    ``pattern=(0.3,)`` puts R = 0.3 in every gap; ``(0.2, 0.4)`` alternates.
    """
    size = count("size", size, minimum=2)
    pat = positive_array("pattern", pattern, min_size=1)
    return decorated(np.resize(pat, size - 1), n=n, initial_velocity=initial_velocity, wall=wall)
