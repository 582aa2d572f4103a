"""Real contacts on the command line: a static load, dissipation, a striker and the wall's material.

``granchain pulse`` and ``granchain ensemble`` take them (:func:`add_contact_arguments`);
:func:`contacts_from_args` reads them back as the keywords of a chain family (``contact``,
``static_force``, ``striker_mass``) in the paper's rescaled units. A bare number is rescaled; a
quantity with a unit (``2N``, ``5g``, ``3mm``, ``1m/s``, ``2us``) is physical and needs the
physical-unit options (``--material``, ``--radius``, ``--impact-speed``: ``granchain.units``),
which fix the force, mass, length, velocity and time units.
"""

from __future__ import annotations

__all__ = ["add_contact_arguments", "contacts_from_args", "apply_to_chain"]


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
    damp = g.add_mutually_exclusive_group()
    damp.add_argument("--dissipation", metavar="GAMMA", help=(
        "viscoelastic (Kuwabara-Kono) contacts F = c [d^(n-1) + GAMMA d^(n-2) dd/dt]: GAMMA, the damping time "
        "(rescaled; or a time such as 2us)"))
    damp.add_argument("--restitution", metavar="E@V", help=(
        "viscoelastic contacts calibrated to a coefficient of restitution E in (0, 1] of two reference granules "
        "colliding at speed V (rescaled; or a speed such as 1m/s), e.g. 0.9@1 or 0.9@1m/s"))
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


def _has_unit(text: str) -> bool:
    try:
        float(text)
        return False
    except ValueError:
        return True


def _quantity(text: str, kind: str, option: str, units, unit_of):
    """``text`` in rescaled units: a bare number as it is, a quantity through ``units`` (``unit_of(units)``
    is the SI size of the rescaled unit)."""
    from ..units import si_value

    if text is None:
        return None
    if not _has_unit(text):
        return float(text)
    if units is None:
        raise ValueError(f"{option} {text!r} has a unit: give the physical-unit options too (--material, --radius, "
                         f"--impact-speed), which fix the rescaled units, or a bare number in rescaled units")
    return si_value(text, kind, option) / unit_of(units)


def _restitution(text: str, units) -> tuple[float, float]:
    if text is None:
        return None
    e, sep, v = text.partition("@")
    if not sep or not e.strip() or not v.strip():
        raise ValueError(f"--restitution needs E@V (a coefficient of restitution and the impact speed it was measured at), "
                         f"e.g. 0.9@1 or 0.9@1m/s; got {text!r}")
    try:
        e = float(e)
    except ValueError:
        raise ValueError(f"--restitution: {e!r} is not a number (E@V, e.g. 0.9@1m/s)") from None
    speed = _quantity(v.strip(), "speed", "--restitution speed", units, lambda s: s.velocity)
    if not (speed > 0):
        raise ValueError(f"--restitution: the impact speed must be > 0, got {v!r}")
    return e, speed


def contacts_from_args(args, units, n: float) -> dict:
    """The real contacts the options ask for: {"contact": law or None, "static_force": F0,
    "striker_mass": M or None, "wall_material": name or None} in rescaled units (errors say what to
    change)."""
    from ..model.contacts import Precompression, Viscoelastic

    force = _quantity(getattr(args, "precompression", None), "force", "--precompression", units, lambda s: s.force)
    load = Precompression(0.0 if force is None else force)
    if load.force > 0 and n <= 1.0:
        raise ValueError(f"--precompression needs an exponent n > 1 (--n), got {n:g}")
    law = None
    gamma = _quantity(getattr(args, "dissipation", None), "time", "--dissipation", units, lambda s: s.time)
    if gamma is not None:
        law = Viscoelastic(gamma, n)
    rest = _restitution(getattr(args, "restitution", None), units)
    if rest is not None:
        law = Viscoelastic.from_restitution(rest[0], rest[1], n=n)
    mass = _quantity(getattr(args, "striker_mass", None), "mass", "--striker-mass", units, lambda s: s.mass)
    radius = _quantity(getattr(args, "striker_radius", None), "length", "--striker-radius", units, lambda s: s.radius)
    if radius is not None:
        if not radius > 0:
            raise ValueError(f"--striker-radius must be > 0, got {args.striker_radius!r}")
        mass = radius**3  # a sphere of the chain's material (rescaled mass R^3)
    if mass is not None and not mass > 0:
        raise ValueError(f"--striker-mass must be > 0 (a striker of no mass strikes nothing), got {args.striker_mass!r}")
    wall_material = getattr(args, "wall_material", None)
    if wall_material is not None and not getattr(args, "wall", False):
        raise ValueError("--wall-material needs --wall")
    return {"contact": law, "static_force": load.force, "striker_mass": mass, "wall_material": wall_material}


def apply_to_chain(chain, contacts: dict):
    """``chain`` with the real contacts of :func:`contacts_from_args` (striker, law, static load)."""
    if contacts["striker_mass"] is not None:
        chain = chain.with_striker(mass=contacts["striker_mass"])
    if contacts["contact"] is not None or contacts["static_force"] > 0:
        chain = chain.replace(contact=contacts["contact"] or chain.contact, static_force=contacts["static_force"])
    return chain
