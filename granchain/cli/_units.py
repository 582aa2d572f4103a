"""Physical quantities on the command line: ``--material``, ``--E/--nu/--rho``, ``--radius``, ``--impact-speed``.

Any sub-command can take them: :func:`add_unit_arguments` registers the options on a
parser, :func:`scale_from_args` turns the parsed namespace into a
:class:`granchain.units.Scale` (or None when no unit option was given).

The values are read by pint (:func:`granchain.units.si_value`), so every unit pint knows
works: ``5mm``, ``"3/16 in"``, ``"50 cm/s"``, ``200GPa``, ``"7.85 g/cm^3"``; a bare number is
SI (m, m/s, Pa, kg/m^3). pint is imported only when one of these options is given.
"""

from __future__ import annotations

import argparse

__all__ = ["parse_quantity", "add_unit_arguments", "scale_from_args", "has_unit_arguments"]

#: Why a quantity must be positive, for the message that refuses a negative or zero value.
_WHY_POSITIVE = {
    "length": "a radius is a size",
    "speed": "the impact speed is the struck granule's speed into the chain (granchain strikes the first "
             "granule; to strike the other end, reverse the list of radii)",
    "pressure": "Young's modulus of a stable elastic solid is positive",
    "density": "a density is positive",
}


def parse_quantity(text, kind: str, option: str = "value") -> float:
    """``text`` (``"5mm"``, ``"3/16 in"``, ``"0.005"``, ``"1 m/s"``, ``"200GPa"``) in SI units, > 0.

    ``kind`` is ``length``, ``speed``, ``pressure`` or ``density`` (see
    :data:`granchain.units.DIMENSIONS`). Raises ValueError with a message that names
    ``option``, the dimension it needs and, for a value <= 0, why it must be positive.
    """
    from ..units import si_value

    value = si_value(text, kind, option)
    if not value > 0:
        why = _WHY_POSITIVE.get(kind, "it must be positive")
        raise ValueError(f"{option} must be > 0, got {text!r}: {why}")
    return value


def _type(kind: str, option: str):
    def convert(text: str) -> float:
        try:
            return parse_quantity(text, kind, option)
        except ValueError as exc:
            # argparse prefixes "argument --option: "; drop our own copy of the option's name.
            message = str(exc)
            raise argparse.ArgumentTypeError(message[len(option):].lstrip(": ") if message.startswith(option) else message) from None

    convert.__name__ = kind  # argparse names the type in some messages
    return convert


def _poisson(text: str) -> float:
    from ..units import si_value

    try:
        return si_value(text, "dimensionless", "--nu")
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
        "--material NAME or all of --E --nu --rho, and --radius and --impact-speed. Quantities take any unit "
        "pint knows ('5mm', '3/16in', '50cm/s', '200GPa', '7.85g/cm^3'; quote a value with spaces: "
        "'3/16 in'); a bare number is SI.",
    )
    g.add_argument("--material", metavar="NAME", help=f"a preset material: {', '.join(MATERIALS)}")
    g.add_argument("--E", dest="E", metavar="MODULUS", type=_type("pressure", "--E"), help="Young's modulus, e.g. 200GPa")
    g.add_argument("--nu", dest="nu", metavar="RATIO", type=_poisson, help="Poisson's ratio, e.g. 0.3")
    g.add_argument("--rho", dest="rho", metavar="DENSITY", type=_type("density", "--rho"), help="density, e.g. 7850kg/m^3 or 7.85g/cm^3")
    g.add_argument("--radius", metavar="LENGTH", type=_type("length", "--radius"),
                   help="radius of the reference (struck, large) granule, e.g. 5mm or '3/16 in'")
    g.add_argument("--impact-speed", dest="impact_speed", metavar="SPEED", type=_type("speed", "--impact-speed"),
                   help="speed of the struck granule, e.g. 1m/s or '50 cm/s'")
    g.add_argument("--contact-prefactor", dest="contact_prefactor", metavar="A",
                   help="the paper's a (force a r' delta^(n-1)); a number is N m^(1/2 - n); default: Hertz from E and nu, "
                        "n = 5/2 only")


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
    # --contact-prefactor: a number (N m^(1/2 - n)) or a quantity string; scale() reads both
    return scale(material, args.radius, args.impact_speed, n=n, a=getattr(args, "contact_prefactor", None))
