"""Real contacts on the command line: a static load, dissipation (Kuwabara-Kono or viscous), yielding
contacts (Thornton's elastic-plastic law), a striker and the wall's material.

``granchain pulse`` and ``granchain ensemble`` take them (:func:`add_contact_arguments`), ``granchain
design`` the dissipative laws (:func:`add_damping_arguments`);
:func:`model_from_args` reads them back as one :class:`granchain.ChainModel` (the contact law, the static
load, the striker, the wall), which a chain family takes whole and :func:`apply_to_chain` puts on one chain,
in the paper's rescaled units. A bare number is rescaled; a
quantity with a unit (``2N``, ``5g``, ``3mm``, ``1m/s``, ``2us``) is physical and needs the
physical-unit options (``--material``, ``--radius``, ``--impact-speed``: ``granchain.units``),
which fix the force, mass, length, velocity and time units.
"""

from __future__ import annotations

__all__ = ["add_contact_arguments", "add_damping_arguments", "model_from_args", "apply_to_chain"]


def add_contact_arguments(parser, *, sensor: bool = False) -> None:
    """Register the real-contact options on ``parser`` (group "real contacts")."""
    g = parser.add_argument_group(
        "real contacts",
        "the paper's chain is elastic, unloaded and struck by an initial velocity; these make it a laboratory chain "
        "(granchain.model.contacts). A bare number is in the paper's rescaled units; a value with a unit ('2N', '5g', "
        "'3mm', '1m/s', '2us') is physical and needs --material (or --E/--nu/--rho), --radius and --impact-speed.")
    load = g.add_mutually_exclusive_group()
    load.add_argument("--precompression", metavar="F0", help=(
        "static compressive force F0 (rescaled; or a force such as 2N): the chain starts in static equilibrium, "
        "loaded at the struck end and held at the far end by the wall (with --wall) or by the same force"))
    load.add_argument("--static-force", dest="precompression", metavar="FORCE", help="the same as --precompression")
    add_damping_arguments(g)
    strike = g.add_mutually_exclusive_group()
    strike.add_argument("--striker-mass", metavar="M", help=(
        "strike the chain with a free sphere of this mass (rescaled: the reference granule's mass is 1; or a mass "
        "such as 5g) at the impact speed, instead of an initial velocity on granule 1"))
    strike.add_argument("--striker-radius", metavar="R", help="the same, a sphere of this radius (rescaled; or e.g. 3mm)")
    g.add_argument("--wall-material", metavar="NAME", help=(
        "with --wall: the wall's material (a preset name, or 'rigid'); default: the last granule's own material"))
    if sensor:
        g.add_argument("--sensor", metavar="K1,K2,...", help=(
            "record the force inside these granules (1-based labels; the mean of each one's two contact forces, "
            "as an embedded gauge measures it) and print its peak and time"))


def add_damping_arguments(group) -> None:
    """Register the dissipative contact laws (``--dissipation``, ``--viscous-damping``, ``--restitution``,
    one at most) on ``group`` (an argument group or parser): the real contacts ``granchain design`` takes."""
    damp = group.add_mutually_exclusive_group()
    damp.add_argument("--dissipation", metavar="GAMMA", help=(
        "viscoelastic (Kuwabara-Kono) contacts F = c [d^(n-1) + GAMMA d^(n-2) dd/dt], clamped at 0 (a contact never "
        "pulls; the published restitution tables are for the unclamped law, whose e is lower: granchain.Viscoelastic"
        "(clamp=False) in Python): GAMMA, the damping time (rescaled; or a time such as 2us)"))
    damp.add_argument("--viscous-damping", metavar="GAMMA", help=(
        "viscous contacts (Rosas, Romero, Nesterenko & Lindenberg 2007): F = c d^(n-1) + GAMMA dd/dt while two grains "
        "touch, a damping force proportional to their relative velocity, which may pull as they separate (their form; "
        "granchain.Viscous(gamma, clamp=True) in Python never pulls): GAMMA, the damping coefficient (rescaled, in "
        "units of M_1/T; or a quantity such as 0.5kg/s)"))
    damp.add_argument("--yield-speed", metavar="V", help=(
        "elastic-plastic contacts (Thornton 1997): Hertz up to a limiting contact pressure, then a force growing "
        "linearly with the overlap, and Hertzian unloading from each contact's largest overlap; V, the relative impact "
        "speed at which two equal granules first yield (rescaled: the struck granule's speed is 1; or a speed such as "
        "0.1m/s, with the physical-unit options). Hardened steel on steel yields near 0.1 m/s"))
    damp.add_argument("--restitution", metavar="E@V", help=(
        "viscoelastic contacts (clamped, as --dissipation) calibrated to a coefficient of restitution E in [0.05, 1] of "
        "two reference granules colliding at speed V (rescaled; or a speed such as 1m/s), e.g. 0.9@1 or 0.9@1m/s"))


import math
import re

#: A number followed by a unit ("2N", "5 g", "1.5e-3 m/s", "3/16 in"): what "has a unit" means.
_NUMBER_THEN_UNIT = re.compile(r"^\s*[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?(\s*/\s*\d+)?\s*[A-Za-z\u00b5\u03bc].*$")


def _number(text: str) -> float | None:
    """``text`` as a bare number, or None when it is not one."""
    try:
        return float(text)
    except ValueError:
        return None


def _quantity(text: str, kind: str, option: str, units, unit_of, syntax: str):
    """``text`` in rescaled units: a bare number as it is, a quantity through ``units`` (``unit_of(units)``
    is the SI size of the rescaled unit). ``syntax`` is what the option takes, for the messages."""
    from ..units import si_value

    if text is None:
        return None
    if not text.strip():
        raise ValueError(f"{option} is empty: give {syntax}")
    x = _number(text)
    if x is None:
        if not _NUMBER_THEN_UNIT.match(text):
            raise ValueError(f"{option} {text!r} is neither a number nor a quantity: give {syntax}")
        if units is None:
            raise ValueError(f"{option} {text!r} has a unit: give the physical-unit options too (--material, --radius, "
                             f"--impact-speed), which fix the rescaled units, or a bare number in rescaled units")
        x = si_value(text, kind, option) / unit_of(units)
    if not math.isfinite(x):
        raise ValueError(f"{option} must be finite, got {text!r}: give {syntax}")
    return x


def _restitution(text: str, units) -> tuple[float, float]:
    if text is None:
        return None
    syntax = ("E@V: a coefficient of restitution E in (0, 1] and the impact speed V it was measured at, "
              "e.g. 0.9@1 (rescaled) or 0.9@1m/s")
    if text.count("@") != 1:
        raise ValueError(f"--restitution takes {syntax}; got {text!r}")
    e_text, _, v = text.partition("@")
    if not e_text.strip() or not v.strip():
        raise ValueError(f"--restitution takes {syntax}; got {text!r}")
    e = _number(e_text)
    if e is None or not math.isfinite(e):
        raise ValueError(f"--restitution: E = {e_text!r} is not a finite number ({syntax})")
    if not 0.0 < e <= 1.0:
        raise ValueError(f"--restitution: E = {e_text!r} must lie in (0, 1] (1: elastic; {syntax})")
    speed = _quantity(v.strip(), "speed", "--restitution's speed V", units, lambda s: s.velocity,
                      "a speed (rescaled, e.g. 1, or with a unit such as 1m/s)")
    if not (speed > 0):
        raise ValueError(f"--restitution: the impact speed V must be > 0, got {v!r}")
    return e, speed


def _checked(option: str, text: str, make):
    """``make()``, its ValueError told with the user's own ``text`` (the value they typed, not its rescaled
    number)."""
    try:
        return make()
    except ValueError as exc:
        raise ValueError(f"{option} {text!r}: {exc}") from None


def model_from_args(args, units, n: float):
    """The chains' physics the options ask for, as one :class:`granchain.ChainModel` (law, static load,
    striker mass, ``--wall``) in rescaled units, checked for chains of exponent ``n`` (errors say what to
    change, quoting what was typed). The wall's material is a property of one chain's wall, not of the
    model: :func:`wall_material_from_args`."""
    from ..model.chainmodel import ChainModel
    from ..model.contacts import ElasticPlastic, Precompression, Viscoelastic, Viscous

    text = getattr(args, "precompression", None)
    force = _quantity(text, "force", "--precompression", units, lambda s: s.force,
                      "a static force >= 0 (rescaled, e.g. 0.1, or with a unit such as 2N)")
    if force is not None and force < 0:
        raise ValueError(f"--precompression must be finite and >= 0 (a compressive force; 0: none), got {text!r}")
    load = Precompression(0.0) if force is None else _checked("--precompression", text, lambda: Precompression(force))
    if load.applied and n <= 1.0:
        raise ValueError(f"--precompression needs an exponent n > 1 (--n), got {n:g}")
    law = None
    text = getattr(args, "dissipation", None)
    gamma = _quantity(text, "time", "--dissipation", units, lambda s: s.time,
                      "a damping time >= 0 (rescaled, e.g. 0.05, or with a unit such as 2us)")
    if gamma is not None:
        if gamma < 0:
            raise ValueError(f"--dissipation must be finite and >= 0 (a damping time; 0: elastic), got {text!r}")
        law = _checked("--dissipation", text, lambda: Viscoelastic(gamma, n))
    text = getattr(args, "viscous_damping", None)
    if text is not None:
        syntax = "a damping coefficient >= 0 (rescaled, e.g. 0.1, or with a unit such as 0.5kg/s)"
        gamma = _number(text)
        if gamma is None and _NUMBER_THEN_UNIT.match(text) and units is not None:
            from ..units import si_value

            # force per relative speed: the rescaled unit is M_1 / T (Eq. motion_rescaled)
            gamma = si_value(text, "damping", "--viscous-damping", unit="kg/s") / (units.mass / units.time)
        gamma = _quantity(text, "time", "--viscous-damping", units, lambda s: s.time, syntax) if gamma is None else gamma
        if not (math.isfinite(gamma) and gamma >= 0):
            raise ValueError(f"--viscous-damping must be finite and >= 0 (a damping coefficient; 0: elastic), got {text!r}")
        law = _checked("--viscous-damping", text, lambda: Viscous(gamma, n))
    text = getattr(args, "yield_speed", None)
    if text is not None:
        speed = _quantity(text, "speed", "--yield-speed", units, lambda s: s.velocity,
                          "a speed > 0 (rescaled, e.g. 0.1, or with a unit such as 0.1m/s)")
        if not speed > 0:
            raise ValueError(f"--yield-speed must be > 0 (a speed at which contacts first yield), got {text!r}")
        law = _checked("--yield-speed", text, lambda: ElasticPlastic(speed, n))
    rest = _restitution(getattr(args, "restitution", None), units)
    if rest is not None:
        law = _checked("--restitution", args.restitution, lambda: Viscoelastic.from_restitution(rest[0], rest[1], n=n))
    text = getattr(args, "striker_mass", None)
    mass = _quantity(text, "mass", "--striker-mass", units, lambda s: s.mass,
                     "a mass > 0 (rescaled: the reference granule's mass is 1; or with a unit such as 5g)")
    if mass is not None and not mass > 0:
        raise ValueError(f"--striker-mass must be > 0 (a striker of no mass strikes nothing), got {text!r}")
    rtext = getattr(args, "striker_radius", None)
    radius = _quantity(rtext, "length", "--striker-radius", units, lambda s: s.radius,
                       "a radius > 0 (rescaled: the reference granule's radius is 1; or with a unit such as 3mm)")
    if radius is not None:
        if not radius > 0:
            raise ValueError(f"--striker-radius must be > 0, got {rtext!r}")
        from ..model.spheres import _check_radii

        _checked("--striker-radius", rtext, lambda: _check_radii(__import__("numpy").array([radius]), "striker radius"))
        mass = radius**3  # a sphere of the chain's material (rescaled mass R^3)
    wall_material_from_args(args)
    return ChainModel(law, load, mass, bool(getattr(args, "wall", False))).for_exponent(n, "command line")


def wall_material_from_args(args):
    """The wall's material ``--wall-material`` names (None: the granules' own), which needs ``--wall``."""
    wall_material = getattr(args, "wall_material", None)
    if wall_material is not None and not getattr(args, "wall", False):
        raise ValueError("--wall-material needs --wall")
    return wall_material


def apply_to_chain(chain, model, args=None):
    """``chain`` with the striker, law and static load of ``model`` (:func:`model_from_args`; its wall is
    the caller's, which builds it with its material); a refusal quotes the option's text in ``args``
    (what the user typed), not its rescaled value."""
    said = {k: getattr(args, k, None) for k in ("precompression", "striker_mass", "striker_radius")}
    if model.striker_mass is not None:
        option = "--striker-radius" if said.get("striker_radius") is not None else "--striker-mass"
        chain = _checked(option, said.get(option[2:].replace("-", "_")),
                         lambda: chain.with_striker(mass=model.striker_mass))
    if model.contact is not None or model.precompression.applied:
        change = dict(contact=model.law(chain.n), static_force=model.static_force)
        chain = (_checked("--precompression", said["precompression"], lambda: chain.replace(**change))
                 if said.get("precompression") is not None else chain.replace(**change))
    return chain
