"""Physical quantities on the command line: ``--material``, ``--E/--nu/--rho``, ``--radius``, ``--impact-speed``.

Any sub-command can take them: :func:`add_unit_arguments` registers the options on a
parser, :func:`scale_from_args` turns the parsed namespace into a
:class:`granchain.units.Scale` (or None when no unit option was given).

Why a small parser and not ``pint``: the command line needs four kinds of quantity
(length, speed, pressure, density) with a handful of spellings each, and the API takes
plain SI floats, so a unit library would only live at this boundary. A table of about
thirty units is about sixty lines, has no dependency and no import cost (pint adds four
packages and ~0.3 s to every ``granchain`` call), and its errors name the option and list
the units it knows (``--radius: unknown unit 'mmm' in '5 mmm'; use one of: m, cm, mm, ...``)
where pint raises ``UndefinedUnitError`` or ``DimensionalityError`` that would need
wrapping anyway. A bare number is taken in SI units (m, m/s, Pa, kg/m^3).
"""

from __future__ import annotations

import argparse
import re

__all__ = ["UNITS", "parse_quantity", "add_unit_arguments", "scale_from_args", "has_unit_arguments"]

# kind -> {spelling: factor to SI}. Spellings are matched exactly after removing spaces.
UNITS = {
    "length": {"m": 1.0, "cm": 1e-2, "mm": 1e-3, "um": 1e-6, "µm": 1e-6, "μm": 1e-6, "nm": 1e-9, "in": 0.0254},
    "speed": {"m/s": 1.0, "cm/s": 1e-2, "mm/s": 1e-3, "km/h": 1 / 3.6},
    "pressure": {"Pa": 1.0, "kPa": 1e3, "MPa": 1e6, "GPa": 1e9, "N/m^2": 1.0, "N/m2": 1.0},
    "density": {"kg/m^3": 1.0, "kg/m3": 1.0, "g/cm^3": 1e3, "g/cm3": 1e3, "g/cc": 1e3},
}
SI = {"length": "m", "speed": "m/s", "pressure": "Pa", "density": "kg/m^3"}

_NUMBER = re.compile(r"^\s*([+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)\s*(.*?)\s*$")


def _kind_of(unit: str) -> str | None:
    for kind, table in UNITS.items():
        if unit in table:
            return kind
    return None


def parse_quantity(text: str, kind: str, option: str = "value") -> float:
    """``text`` (``"5mm"``, ``"5 mm"``, ``"0.005"``, ``"1 m/s"``, ``"200GPa"``) in SI units.

    ``kind`` is one of ``length``, ``speed``, ``pressure``, ``density``. Raises
    ValueError with a message that names ``option`` and the units it accepts.
    """
    if kind not in UNITS:
        raise ValueError(f"unknown kind of quantity {kind!r}; choose one of {', '.join(UNITS)}")
    match = _NUMBER.match(str(text))
    if not match:
        raise ValueError(f"{option}: expected a number with a unit, e.g. '5 {SI[kind]}', got {text!r}")
    value, unit = float(match.group(1)), match.group(2).replace(" ", "")
    if not unit:
        factor = 1.0
    elif unit in UNITS[kind]:
        factor = UNITS[kind][unit]
    else:
        known = ", ".join(u for u in UNITS[kind] if u != "μm")  # (Greek mu: accepted, not listed twice)
        other = _kind_of(unit)
        if other is not None:
            raise ValueError(f"{option}: {text!r} is a {other}, expected a {kind} in {known}")
        raise ValueError(f"{option}: unknown unit {unit!r} in {text!r}; use one of: {known} (a bare number is in {SI[kind]})")
    result = value * factor
    if not result > 0:
        raise ValueError(f"{option}: must be > 0, got {text!r}")
    return result


def _type(kind: str, option: str):
    def convert(text: str) -> float:
        try:
            return parse_quantity(text, kind, option)
        except ValueError as exc:
            # argparse prefixes "argument --option:"; keep the rest of the message.
            raise argparse.ArgumentTypeError(str(exc).split(": ", 1)[1]) from None

    convert.__name__ = kind  # argparse names the type in some messages
    return convert


def _poisson(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a dimensionless number such as 0.3, got {text!r}") from None


_OPTIONS = ("material", "E", "nu", "rho", "radius", "impact_speed", "contact_prefactor")


def add_unit_arguments(parser) -> None:
    """Register ``--material``, ``--E``, ``--nu``, ``--rho``, ``--radius``, ``--impact-speed`` on ``parser``.

    They go into an argument group "physical units"; all default to None (no physical
    output). :func:`scale_from_args` reads them back.
    """
    from ..units import MATERIALS

    g = parser.add_argument_group(
        "physical units",
        "print physical values alongside the rescaled ones (paper Sec. II rescaling; granchain.units). Give "
        "--material NAME or all of --E --nu --rho, and --radius and --impact-speed. Quantities take units "
        "('5mm', '5 mm', '1m/s', '100 cm/s', '200GPa', '7850 kg/m^3'); a bare number is SI.",
    )
    g.add_argument("--material", metavar="NAME", help=f"a preset material: {', '.join(MATERIALS)}")
    g.add_argument("--E", dest="E", metavar="MODULUS", type=_type("pressure", "--E"), help="Young's modulus, e.g. 200GPa")
    g.add_argument("--nu", dest="nu", metavar="RATIO", type=_poisson, help="Poisson's ratio, e.g. 0.3")
    g.add_argument("--rho", dest="rho", metavar="DENSITY", type=_type("density", "--rho"), help="density, e.g. 7850kg/m^3 or 7.85g/cm^3")
    g.add_argument("--radius", metavar="LENGTH", type=_type("length", "--radius"),
                   help="radius of the reference (struck, large) granule, e.g. 5mm")
    g.add_argument("--impact-speed", dest="impact_speed", metavar="SPEED", type=_type("speed", "--impact-speed"),
                   help="speed of the struck granule, e.g. 1m/s")
    g.add_argument("--contact-prefactor", dest="contact_prefactor", metavar="A", type=float,
                   help="the paper's a in N m^(1/2 - n) (force a r' delta^(n-1)); default: Hertz from E and nu, n = 5/2 only")


def has_unit_arguments(args) -> bool:
    """Whether any of the physical-unit options was given."""
    return any(getattr(args, name, None) is not None for name in _OPTIONS)


def scale_from_args(args, n: float | None = None):
    """The :class:`granchain.units.Scale` the options ask for, or None if none was given.

    ``n`` defaults to ``args.n`` when the namespace has it, else 5/2 (Hertz). Raises
    ValueError (naming the missing or conflicting options) for an incomplete set.
    """
    from ..units import Material, get_material, scale

    if not has_unit_arguments(args):
        return None
    custom = {name: getattr(args, name, None) for name in ("E", "nu", "rho")}
    given = [f"--{k}" for k, v in custom.items() if v is not None]
    if getattr(args, "material", None) is not None:
        if given:
            raise ValueError(f"give --material or --E, --nu and --rho, not both (got --material and {', '.join(given)})")
        material = get_material(args.material)
    elif len(given) == 3:
        material = Material(custom["E"], custom["nu"], custom["rho"], "custom")
    else:
        missing = [f"--{k}" for k, v in custom.items() if v is None]
        raise ValueError(f"physical units need a material: --material NAME, or --E, --nu and --rho (missing {', '.join(missing)})")
    missing = [opt for opt, name in (("--radius", "radius"), ("--impact-speed", "impact_speed")) if getattr(args, name, None) is None]
    if missing:
        raise ValueError(f"physical units need {' and '.join(missing)} (e.g. --radius 5mm --impact-speed 1m/s)")
    if n is None:
        n = getattr(args, "n", None) or 2.5
    return scale(material, args.radius, args.impact_speed, n=n, a=getattr(args, "contact_prefactor", None))
