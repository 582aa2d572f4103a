"""Physical units: from a material, a radius and an impact speed to SI (paper Sec. II).

granchain integrates the paper's rescaled equation of motion, Eq. (motion_rescaled), in
which the reference granule (rescaled radius 1, mass 1) is struck with velocity 1. This
module maps those rescaled numbers back to a real chain of spheres of one material:

>>> import granchain as gc
>>> s = gc.units.scale(gc.units.STEEL, radius=5e-3, impact_speed=1.0)
>>> round(s.time * 1e6, 2), round(s.force, 1)        # microseconds, newtons
(12.58, 326.8)

Everything here is a plain function of SI floats; the rescaled data of a
:class:`~granchain.PulseResult` or an ensemble Dataset are never changed, the helpers
:func:`pulse_to_physical` and :func:`dataset_to_physical` return new objects.

The rescaling (paper Sec. II)
-----------------------------
Granules of one material (density rho) repel through the potential of Eq. (hertz-1),
V = (a/n) r'_k abs(y_k - y_{k+1})^n, so the contact force is F = a r'_k delta^(n-1) with::

    r'_k = sqrt(2 R'_k R'_{k+1} / (R'_k + R'_{k+1}))                       (r' of Sec. II)

(R'_k the physical radii, so r' has units m^(1/2) and a has units N m^(1/2 - n)).
With M_k = (4/3) pi rho R'_k^3 and the dimensionless::

    alpha = M_1 V_1^2 / (a R'_1^(n + 1/2))                                  (Sec. II)

the substitutions y = R'_1 alpha^(1/n) x, tau = (R'_1 / V_1) alpha^(1/n) t,
R'_k = R'_1 R_k, M_k = M_1 m_k turn Eq. (EOM-1) into Eq. (motion_rescaled). The units of
the rescaled variables are therefore::

    length    L = R'_1 alpha^(1/n)             (displacements x, compressions delta)
    time      T = (R'_1 / V_1) alpha^(1/n)     (t, peak times)
    velocity  L / T = V_1                      ("simply V_1 times", paper Sec. II)
    force     F_u = M_1 L / T^2 = M_1 V_1^2 / L = a R'_1^(n - 1/2) alpha^((n-1)/n)
    energy    M_1 V_1^2                        (E = sum m v^2/2 + sum (r/n) delta^n)
    mass      M_1,  radius R'_1.

The force unit follows from Eq. (motion_rescaled): m_k x'' = r_k delta^(n-1) in rescaled
units is M_k y'' = F in SI when F = (M_1 L / T^2) r_k delta^(n-1); inserting alpha gives
a R'_1^(1/2) L^(n-1), which is the physical a r' (L delta)^(n-1) with r' = R'_1^(1/2) r_k.
The energy unit follows the same way: (a/n) r' (L delta)^n = M_1 V_1^2 (r/n) delta^n.

Which ``a`` (Hertz, n = 5/2)
----------------------------
Two elastic spheres of one material pressed together by delta repel with the Hertz force
(Landau & Lifshitz, *Theory of Elasticity*, Sec. 9; K. L. Johnson, *Contact Mechanics*,
Cambridge 1985, Sec. 4.2)::

    F = (4/3) E* R_eff^(1/2) delta^(3/2),   1/E* = 2 (1 - nu^2) / E,
    R_eff = R'_k R'_{k+1} / (R'_k + R'_{k+1}).

Eq. (r-prime) has r' = sqrt(2 R_eff), so matching F = a r' delta^(3/2) gives::

    a = (4/3) E* / sqrt(2) = (4/3) E / (2 sqrt(2) (1 - nu^2)) = sqrt(2) E / (3 (1 - nu^2)),

:func:`hertz_prefactor`. For equal spheres (r' = R^(1/2)) this is Nesterenko's
F = E (2R)^(1/2) / (3 (1 - nu^2)) delta^(3/2) (V. F. Nesterenko, *Dynamics of
Heterogeneous Materials*, Springer 2001, Ch. 1). Hertz's law fixes n = 5/2 for spheres;
for any other n (other shapes, empirical laws) ``a`` is not a material constant and
:func:`scale` needs it given explicitly (``a=...``, in N m^(1/2 - n)).

Consequences for n = 5/2: alpha = (M_1 / R'_1^3) V_1^2 / a does not depend on the radius
and goes as V_1^2, so L ~ R V_1^(4/5), T ~ R V_1^(-1/5), F_u ~ R^2 V_1^(6/5),
energy ~ R^3 V_1^2.

Quantities with units (pint)
----------------------------
Every SI argument here (a material's E and rho, a radius, an impact speed, the prefactor ``a``)
also takes a ``pint.Quantity`` or a string pint parses (``"200 GPa"``, ``"7.85 g/cm^3"``,
``"3/16 in"``, ``"50 cm/s"``): ``scale("steel", "5 mm", "1 m/s")``. A bare number is SI.
:meth:`Scale.to_quantity` returns rescaled results as ``pint.Quantity`` objects. pint is the
scientific Python ecosystem's unit library (pint-xarray, MetPy and cf-xarray speak it), so
quantities pass between granchain and the user's own code without conversions by hand; it is
imported only when a quantity is parsed, so a run without units does not pay its ~0.2 s
import. The quantities use pint's application registry (``pint.get_application_registry()``),
the one ``pint.Quantity`` itself uses, so a user's quantities convert without mixing registries.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np

__all__ = [
    "Material",
    "MATERIALS",
    "STEEL",
    "STAINLESS_STEEL",
    "BRASS",
    "ALUMINIUM",
    "GLASS",
    "PTFE",
    "get_material",
    "hertz_prefactor",
    "Scale",
    "scale",
    "PhysicalPulse",
    "pulse_to_physical",
    "dataset_to_physical",
    "to_physical",
    "QUANTITIES",
    "SI_UNITS",
    "VARIABLE_KINDS",
    "DIMENSIONS",
    "si_value",
    "registry",
    "RESCALED",
    "rescaled_attrs",
]

HERTZ = 2.5

#: The SI unit of each kind of physical input or output (what a bare number means).
DIMENSIONS = {"length": "m", "radius": "m", "speed": "m/s", "velocity": "m/s", "pressure": "Pa",
              "density": "kg/m^3", "time": "s", "force": "N", "energy": "J", "mass": "kg", "dimensionless": ""}

# Words for messages: "--E needs a pressure (Young's modulus), got 5 m (a length)".
_WORDS = {"length": "a length", "radius": "a length", "speed": "a speed", "velocity": "a speed",
          "pressure": "a pressure", "density": "a density", "time": "a time", "force": "a force",
          "energy": "an energy", "mass": "a mass", "dimensionless": "a dimensionless number"}


def registry():
    """pint's application registry, the one ``pint.Quantity`` uses (imported on first call)."""
    import pint

    return pint.get_application_registry()


def _is_quantity(value) -> bool:
    # without importing pint: a pint Quantity is the only object here with these three
    return all(hasattr(value, attr) for attr in ("magnitude", "units", "dimensionality"))


def _dimension_word(ureg, dimensionality) -> str:
    for kind, unit in DIMENSIONS.items():
        if ureg.get_dimensionality(unit) == dimensionality:
            return _WORDS[kind]
    return f"a quantity of dimension {dimensionality}"


def si_value(value, kind: str, name: str = "value", *, unit: str | None = None) -> float:
    """``value`` in SI units of ``kind`` (a key of :data:`DIMENSIONS`) as a float.

    ``value`` is a number (taken as SI), a ``pint.Quantity``, or a string pint parses
    (``"5 mm"``, ``"3/16 in"``, ``"7.85 g/cm^3"``, ``"200 GPa"``, ``"50 cm/s"``; a string
    without a unit is SI). ``unit`` overrides the SI unit of ``kind`` (the prefactor ``a``'s
    N m^(1/2 - n)). Raises ValueError naming ``name``, the dimension it needs and the one it
    got ("--radius needs a length, got 5 s (a time)") or the unit pint does not know.
    """
    x = _si_value(value, kind, name, unit)
    if not math.isfinite(x):
        raise ValueError(f"{name} must be finite, got {value!r}: a physical quantity (a size, a speed, a force, ...) "
                         "is a finite number")
    return x


def _si_value(value, kind: str, name: str, unit: str | None) -> float:
    if not isinstance(kind, str) or (kind not in DIMENSIONS and unit is None):
        raise ValueError(f"unknown kind of quantity {kind!r}; choose one of {', '.join(DIMENSIONS)}")
    target = DIMENSIONS.get(kind, "") if unit is None else unit
    if isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool):
        return float(value)
    if isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "iuf":
        return float(value)
    if not (isinstance(value, str) or _is_quantity(value)):
        raise ValueError(f"{name} must be a number (SI: {target or 'dimensionless'}), a pint.Quantity or a string "
                         f"such as '5 mm', got {type(value).__name__}")
    ureg = registry()
    import pint

    if isinstance(value, str):
        text = value.strip()
        try:
            q = ureg.Quantity(text)
        except pint.UndefinedUnitError as exc:
            raise ValueError(f"{name}: unknown unit in {value!r} ({exc}); write e.g. '5 {target or '1'}' "
                             f"(a bare number is SI: {target or 'dimensionless'})") from None
        except Exception:  # noqa: BLE001 -- pint's tokenizer raises several kinds for text it cannot read
            raise ValueError(f"{name}: cannot read {value!r} as a quantity; write a number and a unit, "
                             f"e.g. '5 {target or '1'}'") from None
        if not _is_quantity(q):  # pint returns a plain number for unitless text
            return float(q)
        if q.dimensionless and q.units == ureg.dimensionless:
            return float(q.magnitude)  # "0.005": a bare number is SI
    else:
        q = value
        if not isinstance(q, ureg.Quantity):  # a quantity of another registry: same magnitude, same unit name
            q = ureg.Quantity(q.magnitude, str(q.units))
    try:
        return float(q.to(target or "dimensionless").magnitude)
    except pint.DimensionalityError:
        want = _WORDS.get(kind, f"units of {target}")
        raise ValueError(f"{name} needs {want}, got {value} ({_dimension_word(ureg, q.dimensionality)})") from None
    except TypeError:
        raise ValueError(f"{name} must be a single value, got {value!r}") from None


def _positive(name: str, value, kind: str = "dimensionless", unit: str | None = None) -> float:
    x = si_value(value, kind, name, unit=unit)
    if not math.isfinite(x) or x <= 0:
        raise ValueError(f"{name} must be finite and > 0 (SI units), got {value!r}")
    return x


@dataclass(frozen=True)
class Material:
    """An isotropic elastic material in SI units.

    Parameters
    ----------
    E : float, str or pint.Quantity
        Young's modulus; a number is Pa (steel: about 2e11), or ``"200 GPa"``.
    nu : float
        Poisson's ratio, -1 < nu < 1/2 (dimensionless).
    rho : float, str or pint.Quantity
        Density; a number is kg/m^3, or ``"7.85 g/cm^3"``.
    name : str
        A label (used in reports and Dataset attributes).
    source : str
        Where the values come from.
    yield_stress : float, str or pint.Quantity, optional
        The uniaxial yield stress (a number is Pa, or ``"1.5 GPa"``): where spheres of this material stop
        being elastic (:attr:`limiting_pressure`, :attr:`yield_speed`, ``granchain.ElasticPlastic``).
        None (the presets): not given; the contacts stay elastic.
    """

    E: float
    nu: float
    rho: float
    name: str = "custom"
    source: str = field(default="", repr=False)
    yield_stress: float | None = None

    def __post_init__(self):
        object.__setattr__(self, "E", _positive("E (Young's modulus, Pa)", self.E, "pressure"))
        object.__setattr__(self, "rho", _positive("rho (density, kg/m^3)", self.rho, "density"))
        nu = si_value(self.nu, "dimensionless", "nu (Poisson's ratio)")
        if not (-1.0 < nu < 0.5):
            raise ValueError(f"nu (Poisson's ratio) must lie in (-1, 0.5) for an isotropic elastic solid, got {self.nu!r}")
        object.__setattr__(self, "nu", nu)
        if self.E < 1e5 or self.E > 2e12:
            raise ValueError(f"E = {self.E:g} Pa is outside 1e5..2e12 Pa: give Young's modulus in Pa (200 GPa = 2e11)")
        if self.rho < 50.0 or self.rho > 3e4:  # catches g/cm^3 given as kg/m^3
            raise ValueError(f"rho = {self.rho:g} kg/m^3 is outside 50..30000 kg/m^3: give the density in kg/m^3 (steel: 7850)")
        if self.yield_stress is not None:
            object.__setattr__(self, "yield_stress", _positive("yield_stress (Pa)", self.yield_stress, "pressure"))
            if self.yield_stress >= self.E:
                raise ValueError(f"yield_stress = {self.yield_stress:g} Pa is not below Young's modulus E = {self.E:g} Pa: "
                                 "give the yield stress in Pa (hardened steel: about 1.5e9)")

    @property
    def limiting_pressure(self) -> float:
        """Thornton's limiting contact pressure p_y, Pa: the maximum Hertz pressure at which two spheres of
        this material first yield, p_y = 1.60 sigma_y (K. L. Johnson, *Contact Mechanics*, Cambridge 1985,
        Sec. 6.2, Tresca or von Mises with nu = 0.3; C. Thornton, J. Appl. Mech. 64, 383 (1997))."""
        if self.yield_stress is None:
            raise ValueError(f"the material {self.name!r} has no yield_stress: give Material(..., yield_stress=...) "
                             "(e.g. dataclasses.replace(granchain.units.STEEL, yield_stress=\"1.5 GPa\"))")
        return 1.60 * self.yield_stress

    @property
    def yield_speed(self) -> float:
        """The relative impact speed, m/s, at which two equal spheres of this material first yield (any
        size): (1/2) (m/2) V_y^2 = (2/5) K delta_y^(5/2) with delta_y = (pi p_y / (2 E*))^2 R/2, i.e.
        V_y = (pi^2 / sqrt(160)) (p_y^5 / (E*^4 rho))^(1/2); half of Thornton's 1.56 (p_y^5 / (E*^4 rho))^(1/2)
        for a sphere on a rigid wall of the same E* (C. Thornton, J. Appl. Mech. 64, 383 (1997))."""
        p, e = self.limiting_pressure, self.effective_modulus
        return math.pi**2 / math.sqrt(160.0) * math.sqrt(p**5 / (e**4 * self.rho))

    @property
    def effective_modulus(self) -> float:
        """E* of two spheres of this material, 1/E* = 2 (1 - nu^2) / E (K. L. Johnson, Contact Mechanics, Sec. 4.2)."""
        return self.E / (2.0 * (1.0 - self.nu**2))


# Handbook values. The metals' E and nu are those of W. D. Callister and D. G. Rethwisch,
# "Materials Science and Engineering: An Introduction" (Wiley), Table 6.1 (room-temperature
# elastic moduli and Poisson's ratios of metal alloys), densities from its Appendix B.
STEEL = Material(200e9, 0.30, 7850.0, "steel", source=(
    "Nominal carbon/chrome steel, the round values used throughout the granular-chain literature; "
    "Callister & Rethwisch, Table 6.1, list E = 207 GPa, nu = 0.30 for steel and Appendix B 7.85 g/cm^3."))
"""Steel: E = 200 GPa, nu = 0.30, rho = 7850 kg/m^3 (nominal; Callister & Rethwisch Table 6.1 gives 207 GPa, 0.30)."""

STAINLESS_STEEL = Material(193e9, 0.30, 8000.0, "stainless steel", source=(
    "AISI 316 stainless steel beads as used by C. Daraio, V. F. Nesterenko, E. B. Herbold and S. Jin, "
    "Phys. Rev. E 73, 026610 (2006) (E = 193 GPa, nu = 0.3, rho = 8000 kg/m^3)."))
"""Stainless steel (AISI 316): E = 193 GPa, nu = 0.30, rho = 8000 kg/m^3 (Daraio et al., PRE 73, 026610 (2006))."""

BRASS = Material(97e9, 0.34, 8530.0, "brass", source=(
    "Cartridge brass (70Cu-30Zn): Callister & Rethwisch, Table 6.1 (E = 97 GPa, nu = 0.34) and Appendix B (8.53 g/cm^3)."))
"""Brass (70Cu-30Zn): E = 97 GPa, nu = 0.34, rho = 8530 kg/m^3 (Callister & Rethwisch, Table 6.1, App. B)."""

ALUMINIUM = Material(69e9, 0.33, 2710.0, "aluminium", source=(
    "Aluminium alloy: Callister & Rethwisch, Table 6.1 (E = 69 GPa, nu = 0.33) and Appendix B (2.71 g/cm^3)."))
"""Aluminium: E = 69 GPa, nu = 0.33, rho = 2710 kg/m^3 (Callister & Rethwisch, Table 6.1, App. B)."""

GLASS = Material(69e9, 0.23, 2500.0, "glass", source=(
    "Soda-lime glass: Callister & Rethwisch, Table 12.5 / Appendix B (E = 69 GPa, nu = 0.23, 2.5 g/cm^3)."))
"""Soda-lime glass: E = 69 GPa, nu = 0.23, rho = 2500 kg/m^3 (Callister & Rethwisch, Appendix B)."""

PTFE = Material(1.46e9, 0.46, 2200.0, "PTFE", source=(
    "PTFE (Teflon) beads: C. Daraio, V. F. Nesterenko, E. B. Herbold and S. Jin, Phys. Rev. E 72, 016603 (2005), "
    "E = 1.46 GPa (the dynamic modulus at the strain rates of a solitary wave; the static handbook value is "
    "about 0.5 GPa), nu = 0.46, rho = 2200 kg/m^3."))
"""PTFE (Teflon): E = 1.46 GPa (dynamic), nu = 0.46, rho = 2200 kg/m^3 (Daraio et al., PRE 72, 016603 (2005))."""

MATERIALS = {m.name.replace(" ", "-").lower(): m for m in (STEEL, STAINLESS_STEEL, BRASS, ALUMINIUM, GLASS, PTFE)}
"""Presets by name: steel, stainless-steel, brass, aluminium, glass, ptfe."""

_ALIASES = {"aluminum": "aluminium", "teflon": "ptfe", "stainless": "stainless-steel", "ss316": "stainless-steel"}


def get_material(name: str) -> Material:
    """The preset called ``name`` (case-insensitive; '-', '_' and ' ' are the same)."""
    key = str(name).strip().lower().replace("_", "-").replace(" ", "-")
    key = _ALIASES.get(key, key)
    if key not in MATERIALS:
        raise ValueError(f"unknown material {name!r}; choose one of {', '.join(MATERIALS)} (or give E, nu and rho)")
    return MATERIALS[key]


def hertz_prefactor(material: Material) -> float:
    """The paper's ``a`` of Eq. (hertz-1) for spheres of one material, in N/m^2 (n = 5/2).

    a = (4/3) E* / sqrt(2) = sqrt(2) E / (3 (1 - nu^2)): the Hertz force
    (4/3) E* R_eff^(1/2) delta^(3/2) written as a r' delta^(3/2) with r' = sqrt(2 R_eff)
    (Eq. r-prime). See the module docstring for the derivation.
    """
    return math.sqrt(2.0) * material.E / (3.0 * (1.0 - material.nu**2))


QUANTITIES = ("time", "length", "velocity", "force", "energy", "mass", "radius")
"""Kinds of rescaled quantity :meth:`Scale.to_si` converts."""

SI_UNITS = {"time": "s", "length": "m", "velocity": "m/s", "force": "N", "energy": "J", "mass": "kg", "radius": "m"}
"""The SI unit of each kind in :data:`QUANTITIES`."""


@dataclass(frozen=True)
class Scale:
    """The units of the paper's rescaled variables for one material, radius and impact speed.

    Made by :func:`scale`; every attribute is an SI float. ``radius`` (R'_1) and ``mass``
    (M_1) are those of the reference granule (rescaled radius and mass 1; the struck,
    first granule of every granchain builder), ``impact_speed`` is V_1 (rescaled velocity 1).

    Attributes
    ----------
    a : float
        Contact prefactor of Eq. (hertz-1), N m^(1/2 - n) (N/m^2 for n = 5/2).
    alpha : float
        The dimensionless M_1 V_1^2 / (a R'_1^(n + 1/2)) of Sec. II.
    time, length, velocity, force, energy : float
        The units T, L, V_1, M_1 L / T^2 and M_1 V_1^2 (s, m, m/s, N, J).
    """

    material: Material
    radius: float
    impact_speed: float
    n: float
    a: float
    mass: float
    alpha: float
    time: float
    length: float
    velocity: float
    force: float
    energy: float

    def to_si(self, value, kind: str):
        """``value`` (rescaled, scalar or array) times the unit of ``kind`` (one of :data:`~granchain.units.QUANTITIES`)."""
        if not isinstance(kind, str) or kind not in SI_UNITS:
            raise ValueError(f"unknown quantity {kind!r}; choose one of {', '.join(QUANTITIES)}")
        return value * getattr(self, kind)

    def to_rescaled(self, value, kind: str) -> float:
        """A physical ``value`` (a number in the SI unit of ``kind``, a ``pint.Quantity`` or a string such
        as ``"2 N"``, ``"5 g"``, ``"1 m/s"``, ``"2 us"``) in the paper's rescaled units: what a static
        force, a striker's mass or a damping time is in the units the chains are integrated in
        (``scale.to_rescaled("2 N", "force")``). The inverse of :meth:`to_si`."""
        if not isinstance(kind, str) or kind not in SI_UNITS:
            raise ValueError(f"unknown quantity {kind!r}; choose one of {', '.join(QUANTITIES)}")
        word = {"velocity": "speed", "radius": "length"}.get(kind, kind)
        return si_value(value, word, f"a {kind}") / getattr(self, kind)

    def wave_speed_si(self, granules_per_time: float, spacing: float = 2.0) -> float:
        """A speed in granules per unit time (``PulseResult.wave_speed``) in m/s: ``spacing`` is the
        distance between neighbouring granules' centres in units of the reference radius (2 for a
        monodisperse chain of the reference granules; the static overlaps, ~1e-4 of it, are neglected)."""
        return granules_per_time * spacing * self.radius / self.time

    def to_quantity(self, value, kind: str):
        """``value`` (rescaled, scalar or array) as a ``pint.Quantity`` in the SI unit of ``kind``:
        ``scale.to_quantity(result.peak_time, "time").to("us")``."""
        return registry().Quantity(self.to_si(value, kind), SI_UNITS[kind])

    def as_dict(self) -> dict:
        """The numbers (and the material) as a flat, JSON-ready dict with SI unit suffixes."""
        m = self.material
        return {
            "material": m.name, "E_Pa": m.E, "nu": m.nu, "rho_kg_m3": m.rho,
            "radius_m": self.radius, "impact_speed_m_s": self.impact_speed, "n": self.n,
            "a": self.a, "alpha": self.alpha, "mass_kg": self.mass,
            "time_unit_s": self.time, "length_unit_m": self.length, "velocity_unit_m_s": self.velocity,
            "force_unit_N": self.force, "energy_unit_J": self.energy,
        }

    def __str__(self) -> str:
        return (
            f"{self.material.name} (E = {self.material.E:.4g} Pa, nu = {self.material.nu:g}, rho = {self.material.rho:g} kg/m^3), "
            f"R = {self.radius:g} m, V1 = {self.impact_speed:g} m/s, n = {self.n:g}: alpha = {self.alpha:.4g}; "
            f"units: time {self.time:.4g} s, length {self.length:.4g} m, velocity {self.velocity:.4g} m/s, "
            f"force {self.force:.4g} N, energy {self.energy:.4g} J"
        )


def scale(material: Material | str, radius, impact_speed, n: float = HERTZ, *, a=None) -> Scale:
    """The paper's Sec. II rescaling for spheres of one material.

    Parameters
    ----------
    material : Material or str
        The material (or a preset name, see :data:`~granchain.units.MATERIALS`).
    radius : float, str or pint.Quantity
        Radius R'_1 of the reference granule; a number is m, or ``"5 mm"``, ``"3/16 in"``
        (rescaled radius 1: the struck granule and, in a decorated chain, every large granule).
    impact_speed : float, str or pint.Quantity
        V_1, the struck granule's initial speed; a number is m/s, or ``"50 cm/s"``
        (rescaled velocity 1).
    n : float
        Exponent of the potential of Eq. (hertz-1). Hertz (spheres): 5/2.
    a : float, str or pint.Quantity, optional
        Contact prefactor; a number is N m^(1/2 - n). Default (n = 5/2 only): Hertz,
        :func:`~granchain.units.hertz_prefactor`. Required for any other n.

    Returns
    -------
    Scale
        alpha = M_1 V_1^2 / (a R'_1^(n+1/2)), T = (R'_1/V_1) alpha^(1/n),
        L = R'_1 alpha^(1/n), F_u = M_1 L / T^2, energy M_1 V_1^2 (module docstring).
    """
    if isinstance(material, str):
        material = get_material(material)
    if not isinstance(material, Material):
        raise ValueError(f"material must be a granchain.units.Material or a preset name, got {type(material).__name__}")
    radius = _positive("radius (m)", radius, "length")
    impact_speed = _positive("impact_speed (m/s)", impact_speed, "speed")
    n = _positive("n", n)
    if n <= 1:
        raise ValueError(f"n must be > 1 (potential (a/n) r' delta^n), got {n}")
    if radius > 10.0:
        raise ValueError(f"radius = {radius:g} m: give the radius in metres (5 mm = 0.005)")
    if a is None:
        if n != HERTZ:
            raise ValueError(
                f"n = {n:g}: only n = 5/2 is Hertz's law for spheres, where a follows from E and nu; "
                "for another n give the contact prefactor a (force a r' delta^(n-1), in N m^(1/2 - n)) explicitly: "
                "scale(..., a=...) or, on the command line, --contact-prefactor"
            )
        a = hertz_prefactor(material)
    else:
        a = _positive("a (contact prefactor, N m^(1/2 - n))", a, unit=f"N * m ** ({0.5 - n!r})")
    mass = 4.0 / 3.0 * math.pi * material.rho * radius**3          # M_1 = (4/3) pi rho R'_1^3 (Sec. II)
    alpha = mass * impact_speed**2 / (a * radius ** (n + 0.5))     # alpha (Sec. II)
    length = radius * alpha ** (1.0 / n)                           # y = R'_1 alpha^(1/n) x
    time = radius / impact_speed * alpha ** (1.0 / n)              # tau = (R'_1/V_1) alpha^(1/n) t
    force = mass * length / time**2                                # M_1 L / T^2 (Eq. motion_rescaled)
    return Scale(material, radius, impact_speed, n, a, mass, alpha, time, length, impact_speed, force, mass * impact_speed**2)


# --- conversion helpers -------------------------------------------------------------------

# Rescaled variable name -> kind of quantity. One table for results and Datasets; names that
# a later granchain may add (contact and wall forces) are here so they convert as soon as
# they exist. Anything not listed is left alone.
VARIABLE_KINDS = {
    "peak_velocity": "velocity",
    "peak_time": "time",
    "t_end": "time",
    "exit_time": "time",
    "mean_velocity": "velocity",
    "mean_velocity_stderr": "velocity",
    "velocity": "velocity",
    "small_radius": "radius",
    "peak_force": "force",
    "peak_force_time": "time",
    "wall_force": "force",
    "sensor_force": "force",
    "peak_wall_force": "force",
    "peak_wall_force_time": "time",
}
"""Rescaled variable name -> kind of quantity (see :data:`QUANTITIES`)."""

#: What each rescaled quantity counts (paper Sec. II): the ``units_description`` of stored variables.
RESCALED = {
    "velocity": "rescaled velocity, in units of V_1 (the struck granule's initial speed; paper Sec. II)",
    "time": "rescaled time, in units of T = (R'_1 / V_1) alpha^(1/n) (paper Sec. II)",
    "force": "rescaled force, in units of M_1 L / T^2 (paper Eq. motion_rescaled)",
    "energy": "rescaled energy, in units of M_1 V_1^2 (paper Sec. II)",
    "length": "rescaled length, in units of L = R'_1 alpha^(1/n) (paper Sec. II)",
    "radius": "rescaled radius, in units of R'_1 (the reference, large granule's radius)",
    "mass": "rescaled mass, in units of M_1 (the reference granule's mass)",
}


def rescaled_attrs(kind: str) -> dict:
    """Attributes of a stored rescaled variable: ``units`` "1" (the paper's rescaled numbers are
    dimensionless, so pint, pint-xarray's ``quantify()`` and UDUNITS read them), the kind of
    quantity in ``rescaled_quantity`` (``Scale.<kind>`` converts it to SI: :func:`dataset_to_physical`)
    and what it counts in ``units_description``."""
    if kind not in RESCALED:
        raise ValueError(f"unknown rescaled quantity {kind!r}; choose one of {', '.join(RESCALED)}")
    return {"units": "1", "rescaled_quantity": kind, "units_description": RESCALED[kind]}


SUFFIX = "_si"
"""Suffix of the SI variables :func:`dataset_to_physical` adds (``peak_time`` -> ``peak_time_si``)."""


@dataclass(frozen=True, eq=False)
class PhysicalPulse:
    """A :class:`~granchain.PulseResult` in SI units (made by :func:`pulse_to_physical`).

    ``granule`` as in the result; ``peak_velocity`` (m/s), ``peak_time``, ``t_end``,
    ``exit_time`` (s); ``t_grid`` (s) and ``velocity`` (m/s) when the result has a grid;
    ``peak_force`` (N) and ``peak_force_time`` (s) when the result records contact forces
    (per contact), else None; ``dissipated_energy`` (J) of a viscoelastic chain, ``static_force`` (N)
    of a precompressed one, ``sensor_force`` (N, sensor x time) when sensors were recorded (else
    None). ``scale`` holds the units used.
    """

    scale: Scale
    granule: np.ndarray
    peak_velocity: np.ndarray
    peak_time: np.ndarray
    t_end: float
    exit_time: float
    t_grid: np.ndarray | None = None
    velocity: np.ndarray | None = None
    peak_force: np.ndarray | None = None
    peak_force_time: np.ndarray | None = None
    dissipated_energy: float | None = None
    static_force: float | None = None
    sensor_force: np.ndarray | None = None

    def as_dict(self) -> dict:
        """JSON-ready: arrays as lists, SI unit suffixes on the keys, ``None`` fields omitted."""
        units = {"peak_velocity": "m_s", "peak_time": "s", "t_end": "s", "exit_time": "s", "t_grid": "s",
                 "velocity": "m_s", "peak_force": "N", "peak_force_time": "s", "dissipated_energy": "J",
                 "static_force": "N", "sensor_force": "N"}
        out = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name in ("scale", "granule") or value is None:
                continue
            out[f"{f.name}_{units[f.name]}"] = np.asarray(value).tolist()
        return out


def _optional(scale: Scale, obj, name: str):
    value = getattr(obj, name, None)
    return None if value is None else scale.to_si(np.asarray(value, dtype=float), VARIABLE_KINDS[name])


def pulse_to_physical(result, scale: Scale) -> PhysicalPulse:
    """The observables of a :class:`~granchain.PulseResult` in SI units (a new object; the result is unchanged).

    Times are multiplied by ``scale.time``, velocities by ``scale.velocity`` (= V_1) and,
    when the result has them, contact forces by ``scale.force`` (paper Sec. II; module
    docstring).
    """
    _check_scale(scale)
    return PhysicalPulse(
        scale=scale,
        granule=np.asarray(result.granule),
        peak_velocity=scale.to_si(np.asarray(result.peak_velocity, dtype=float), "velocity"),
        peak_time=scale.to_si(np.asarray(result.peak_time, dtype=float), "time"),
        t_end=float(scale.to_si(result.t_end, "time")),
        exit_time=float(scale.to_si(result.exit_time, "time")),
        t_grid=None if getattr(result, "t_grid", None) is None else scale.to_si(np.asarray(result.t_grid), "time"),
        velocity=_optional(scale, result, "velocity"),
        peak_force=_optional(scale, result, "peak_force"),
        peak_force_time=_optional(scale, result, "peak_force_time"),
        dissipated_energy=float(scale.to_si(result.dissipated_energy, "energy")) if getattr(result, "dissipated_energy", 0.0) else None,
        static_force=float(scale.to_si(result.static_force, "force")) if getattr(result, "static_force", 0.0) else None,
        sensor_force=_optional(scale, result, "sensor_force"),
    )


def _check_scale(scale) -> None:
    if not isinstance(scale, Scale):
        raise ValueError(f"scale must be a granchain.units.Scale (from granchain.units.scale(...)), got {type(scale).__name__}")


def dataset_to_physical(ds, scale: Scale):
    """A new ``xarray.Dataset``: ``ds`` plus SI copies of its rescaled variables.

    For each rescaled variable of ``ds`` (named by its ``rescaled_quantity`` attribute; in
    stores written before that attribute existed, the names of :data:`VARIABLE_KINDS`:
    ``peak_time``, ``peak_velocity``, ``mean_velocity``, ``small_radius``, ..., and contact or
    wall forces when present) a variable ``<name>_si`` with SI ``units`` is added, and the
    ``time`` coordinate gets a companion ``time_si`` coordinate. The rescaled variables and
    ``ds`` itself are untouched (lazy, Dask-backed data stay lazy). The scale is recorded in
    attributes ``physical_*``.
    """
    _check_scale(scale)
    new = {}
    for name, var in ds.data_vars.items():
        # the kind a variable records (stores written since units became "1"), else the table (older stores)
        kind = var.attrs.get("rescaled_quantity") or VARIABLE_KINDS.get(name)
        if kind not in SI_UNITS or name.endswith(SUFFIX):
            continue
        attrs = {
            "units": SI_UNITS[kind],
            "long_name": f"{var.attrs.get('long_name', name)} (SI)",
            "rescaled_variable": name,
        }
        new[name + SUFFIX] = (var * getattr(scale, kind)).assign_attrs(attrs)
    out = ds.assign(new)
    if "time" in ds.coords:
        out = out.assign_coords(time_si=("time", np.asarray(ds["time"].values, dtype=float) * scale.time,
                                         {"units": "s", "long_name": "time (SI)"}))
    out.attrs.update({f"physical_{k}": v for k, v in scale.as_dict().items()})
    return out


def to_physical(obj, scale: Scale):
    """:func:`~granchain.units.dataset_to_physical` for an ``xarray.Dataset``, :func:`~granchain.units.pulse_to_physical` otherwise."""
    import xarray as xr

    if isinstance(obj, xr.Dataset):
        return dataset_to_physical(obj, scale)
    if hasattr(obj, "peak_velocity") and hasattr(obj, "peak_time"):
        return pulse_to_physical(obj, scale)
    raise ValueError(f"to_physical needs a PulseResult or an xarray.Dataset, got {type(obj).__name__}")
