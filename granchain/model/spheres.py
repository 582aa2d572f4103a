"""Spheres in the paper's rescaled units: their masses and contact prefactors (Eq. r-prime), against a
wall and between several materials, and the ranges of them that double precision can integrate.

These are formulas over radii and materials, with no chain in them: :mod:`granchain.model.chain`
builds chains from them, and the families build whole batches of chains with the same functions,
so that one chain and a batch give bitwise the same numbers.
"""

from __future__ import annotations

import numpy as np

__all__ = ["sphere_mass", "sphere_stiffness", "wall_stiffness", "material_stiffness", "material_wall_stiffness",
           "MASS_RANGE", "RADIUS_RANGE", "STIFFNESS_RANGE", "VELOCITY_RANGE", "RIGID"]

#: The range of rescaled masses a chain takes (units of the reference granule's mass): a granule 1e-18
#: times lighter (radius 1e-6) than the reference has contact times and compressions ~1e-6 of the
#: others', which no step budget reaches and which sink toward the rounding of the positions.
MASS_RANGE = (1e-18, 1e18)
#: The range of radii (units of the reference radius): the cube roots of :data:`MASS_RANGE`.
RADIUS_RANGE = (1e-6, 1e6)
#: The range of contact prefactors (units of the reference pair's, sqrt(2 R R' / (R + R'))).
STIFFNESS_RANGE = (1e-12, 1e12)
#: The range of the struck granule's initial speed (units of the impact speed of the rescaling).
VELOCITY_RANGE = (1e-8, 1e8)


def _in_range(name: str, a: np.ndarray, bounds: tuple, what: str, why: str = "") -> None:
    lo, hi = bounds
    bad = (a < lo) | (a > hi)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"{name}[{i}] = {float(a[i]):g} is outside {lo:g}..{hi:g} ({what}){why or ': double precision cannot integrate granules and contacts that far from the reference one (rescaled units, paper Sec. II)'}")


def _check_radii(r: np.ndarray, name: str = "radii") -> None:
    """Radii within :data:`RADIUS_RANGE` (units of the reference radius), checked before the masses R^3
    they give, so that the message names the radius."""
    lo, hi = RADIUS_RANGE
    bad = (r < lo) | (r > hi)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        which = "small" if r[i] < lo else "large"
        raise ValueError(f"{name}[{i}] = {float(r[i]):g} is too {which}: radii must lie in {lo:g}..{hi:g} (units of the "
                         f"reference radius), because a sphere of radius R has mass R^3 and a mass ratio beyond "
                         f"{MASS_RANGE[1]:g} gives contact times and compressions that double precision and any step "
                         "budget cannot integrate beside the reference granule")


def wall_stiffness(radius) -> np.ndarray:
    """Contact prefactor of a sphere of radius R against a fixed wall: sqrt(2 R).

    The limit of Eq. (r-prime), sqrt(2 R_k R_{k+1} / (R_k + R_{k+1})), for R_{k+1} -> infinity
    (a flat wall of the same material). Works on arrays (a batch of last radii).
    """
    return np.sqrt(2.0 * np.asarray(radius, dtype=float))  # Eq. (r-prime), R_{k+1} -> inf


RIGID = "rigid"


def _material(m, *, rigid: bool = False):
    """The one lookup of a material: a :class:`granchain.units.Material` as it is, a preset name through
    ``granchain.units.get_material`` (case-insensitive), and, where a wall's material is meant
    (``rigid=True``), ``"rigid"`` in any case (an infinitely stiff wall: :data:`RIGID`)."""
    from ..units import Material, get_material

    if isinstance(m, Material):
        return m
    if isinstance(m, str):
        if m.strip().lower() == RIGID:
            if rigid:
                return RIGID
            raise ValueError(f"{m!r} is a wall's material only (an infinitely stiff wall): a granule or striker needs a "
                             "granchain.units.Material or a preset name (steel, stainless-steel, brass, aluminium, glass, ptfe)")
        return get_material(m)
    raise ValueError(f"a material must be a granchain.units.Material or a preset name (steel, stainless-steel, brass, "
                     f"aluminium, glass, ptfe{', or rigid for a wall' if rigid else ''}), got {m!r}")


def _pair_modulus(a, b) -> float:
    """Hertz's effective modulus of two spheres (or a sphere and a flat) of materials a and b:
    1/E* = (1 - nu_a^2)/E_a + (1 - nu_b^2)/E_b (K. L. Johnson, *Contact Mechanics*, Sec. 4.2); b may be
    ``"rigid"`` (E_b infinite)."""
    if isinstance(b, str) and b == RIGID:
        return a.E / (1.0 - a.nu**2)
    return 1.0 / ((1.0 - a.nu**2) / a.E + (1.0 - b.nu**2) / b.E)


def material_stiffness(radii, materials, *, reference=None) -> np.ndarray:
    """Contact prefactors of neighbouring spheres of several materials, in the rescaled units of
    ``reference`` (default: the first granule's material):

        c_k = (E*_k,k+1 / E*_ref) sqrt(2 R_k R_{k+1} / (R_k + R_{k+1})),

    Hertz's force (4/3) E* R_eff^(1/2) delta^(3/2) with the pair's effective modulus E* and radius
    R_eff (K. L. Johnson, *Contact Mechanics*, Sec. 4.2) divided by the reference pair's, so that
    one material gives Eq. (r-prime) bit for bit (the ratio is then exactly 1)."""
    r = np.asarray(radii, dtype=float)
    mats = [_material(m) for m in materials]
    ref = mats[0] if reference is None else _material(reference)
    e_ref = _pair_modulus(ref, ref)
    ratio = np.array([1.0 if (a == ref and b == ref) else _pair_modulus(a, b) / e_ref for a, b in zip(mats[:-1], mats[1:])])
    return ratio * sphere_stiffness(r)


def material_wall_stiffness(radius, material, wall_material, *, reference) -> float:
    """Contact prefactor of a sphere of ``radius`` and ``material`` against a flat wall of
    ``wall_material`` (a Material, or ``"rigid"``): (E*_sphere,wall / E*_ref) sqrt(2 R), the
    limit R_wall -> infinity of :func:`material_stiffness` (:func:`wall_stiffness` when all are
    one material)."""
    a, ref = _material(material), _material(reference)
    b = _material(wall_material, rigid=True)
    ratio = 1.0 if (a == ref and b == ref) else _pair_modulus(a, b) / _pair_modulus(ref, ref)
    return float(ratio * wall_stiffness(radius))


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
