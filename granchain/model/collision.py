"""The two-body collision of viscoelastic spheres: the coefficient of restitution of the contact law
:class:`granchain.model.contacts.Viscoelastic`, and the damping that gives a chosen one.

Two spheres of masses m1, m2 meet at the relative speed v; their compression delta obeys

    mu delta'' = -c [delta^(n-1) + gamma delta^(n-2) delta'],   mu = m1 m2 / (m1 + m2),

from delta = 0, delta' = v, until the force vanishes (it is clamped at 0: the spheres then separate
freely, T. Poschel and T. Schwager, *Computational Granular Dynamics*, Springer 2005, Sec. 2.3) or,
for the unclamped law of the literature (``clamp=False``), until delta returns to 0 (the force pulls at
the end of the collision). The coefficient of restitution is e = -delta'(end) / v. The published values
(below) are for the unclamped law; the clamped one's e is higher (see
:class:`granchain.model.contacts.Viscoelastic`). :func:`restitution` integrates this with SciPy's
DOP853 (sharing no code with the chain kernels: the independent check of them);
:func:`restitution_leading_order` is its small-damping limit, which for n = 5/2 is the Kuwabara-Kono
law 1 - e ~ gamma v^(1/5) (Schwager & Poschel, Phys. Rev. E 57, 650 (1998); Ramirez et al., Phys. Rev.
E 60, 4465 (1999)).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["restitution", "gamma_for_restitution", "restitution_leading_order", "KUWABARA_KONO_C1", "MIN_RESTITUTION"]

#: The first coefficient of the expansion 1 - e = C1 gamma (c / mu)^(2/5) v^(1/5) + ... for n = 5/2:
#: sqrt(pi) Gamma(3/5) / (2^(1/5) 5^(2/5) Gamma(21/10)) (Schwager & Poschel 1998; Ramirez et al. 1999,
#: whose expansion variable (3/2) A (rho / m_eff)^(2/5) is gamma (c / mu)^(2/5) here).
KUWABARA_KONO_C1 = math.sqrt(math.pi) * math.gamma(0.6) / (2.0**0.2 * 5.0**0.4 * math.gamma(2.1))


def _reduced_mass(mass) -> float:
    try:
        m = np.broadcast_to(np.asarray(mass, dtype=float), (2,))
    except (TypeError, ValueError):
        raise ValueError(f"the colliding masses (mass: one value for both, or a pair) must be numbers, got {mass!r}") from None
    if not np.all(np.isfinite(m)) or np.any(m <= 0):
        raise ValueError(f"the colliding masses must be finite and > 0 (mass: one value for both, or a pair), got {mass!r}")
    return float(m[0] * m[1] / (m[0] + m[1]))


#: The range of the collision's dimensionless parameters in which the two-body problem is solved: the
#: contact prefactor over the reduced mass, and the impact speed, each within 1e-12..1e12 (rescaled
#: units: 1 is the reference granules' contact and the impact speed of the units). Outside it the
#: compression delta_m = (n mu v^2 / (2 c))^(1/n) and the collision time leave the range where the
#: integration's tolerances (atol ~ 1e-14 delta_m) mean anything.
_RANGE = (1e-12, 1e12)


def _checked(gamma, speed, n, mass, stiffness) -> tuple:
    """(gamma, v, n, mu, c) of the two-body problem, each checked with a message naming it."""
    from .._validate import finite_scalar

    g = finite_scalar("gamma (the damping time)", gamma)
    if g < 0:
        raise ValueError(f"gamma (the damping time) must be >= 0, got {gamma!r}")
    try:
        v = finite_scalar("speed", speed, positive=True)
    except ValueError:
        raise ValueError(f"the impact speed must be finite and > 0, got {speed!r}") from None
    n = finite_scalar("n (the contact exponent)", n)
    if n < 2.0:
        raise ValueError(f"n (the contact exponent) must be >= 2 for the viscoelastic contact, got {n!r}")
    mu = _reduced_mass(mass)
    c = finite_scalar("stiffness (the contact prefactor c)", stiffness, positive=True)
    lo, hi = _RANGE
    for name, x in (("stiffness / reduced mass (c / mu)", c / mu), ("the impact speed", v)):
        if not lo <= x <= hi:
            raise ValueError(f"{name} = {x:g} is outside {lo:g}..{hi:g} (rescaled units, where 1 is the reference "
                             "granules' contact and the units' impact speed): the collision's compression and duration "
                             "would leave the range the integration resolves")
    return g, v, n, mu, c


def restitution(gamma: float, speed: float = 1.0, *, n: float = 2.5, mass=1.0, stiffness: float = 1.0,
                rtol: float = 1e-12, clamp: bool = True) -> float:
    """The coefficient of restitution of two spheres (masses ``mass``: one value for both, or a pair;
    contact prefactor ``stiffness``) meeting at relative ``speed``, with the viscoelastic law of
    damping time ``gamma``: the two-body problem above, integrated with SciPy's DOP853 to the
    vanishing of the force (an event; ``clamp=False``: to the return of delta to 0, the force pulling
    before it), rescaled units."""
    from scipy.integrate import solve_ivp

    g, v, n, mu, c = _checked(gamma, speed, n, mass, stiffness)
    if g == 0.0:
        return 1.0
    # the collision's time scale, from the elastic maximum compression (the run is measured in it)
    d_max = (n * mu * v * v / (2.0 * c)) ** (1.0 / n)
    t_scale = d_max / v

    def rhs(t, y):
        d, w = y
        if d <= 0.0:
            return [w, 0.0]
        f = c * d ** (n - 2.0) * (d + g * w)
        return [w, -(max(f, 0.0) if clamp else f) / mu]

    def force_vanishes(t, y):  # d^(n-2) (d + gamma w) = 0 with d > 0: d + gamma w = 0
        return y[0] + g * y[1]

    def contact_opens(t, y):  # the unclamped law: the collision ends when the spheres separate, delta = 0
        return y[0] if t > 0.0 else 1.0

    end = force_vanishes if clamp else contact_opens
    end.terminal = True
    end.direction = -1
    sol = solve_ivp(rhs, (0.0, 200.0 * t_scale), [0.0, v], method="DOP853", rtol=rtol, atol=1e-14 * d_max,
                    events=end, first_step=1e-6 * t_scale)
    if sol.status != 1:
        raise RuntimeError(f"the two-body collision did not end within 200 collision times (gamma = {g:g}): "
                           "the damping is too strong for a bounce")
    return float(-sol.y_events[0][0][1] / v)


def restitution_leading_order(gamma: float, speed: float = 1.0, *, n: float = 2.5, mass=1.0,
                              stiffness: float = 1.0) -> float:
    """e to first order in ``gamma``: 1 - dE / (mu v^2), with dE the work of the damping force along the
    elastic collision,

        dE = 2 c gamma v delta_m^(n-1) B((n-1)/n, 3/2) / n,   delta_m = (n mu v^2 / (2 c))^(1/n),

    (the integral of c gamma delta^(n-2) delta'^2 dt over the elastic loading and unloading; B the
    Beta function). For n = 5/2 it is 1 - C1 gamma (c / mu)^(2/5) v^(1/5) with
    C1 = :data:`KUWABARA_KONO_C1` = 1.15345 (Schwager & Poschel 1998)."""
    from scipy.special import beta

    gamma, v, n, mu, c = _checked(gamma, speed, n, mass, stiffness)
    d_max = (n * mu * v * v / (2.0 * c)) ** (1.0 / n)
    dE = 2.0 * c * gamma * v * d_max ** (n - 1.0) * beta((n - 1.0) / n, 1.5) / n
    return 1.0 - dE / (mu * v * v)


#: The smallest coefficient of restitution :func:`gamma_for_restitution` calibrates: below it the damping
#: that gives it is so strong (the collision lasts > ~30 elastic collision times) that the law is outside
#: the quasi-static regime it is derived for (Brilliantov et al. 1996) and the two-body solve itself
#: becomes a creep toward rest.
MIN_RESTITUTION = 0.05


def gamma_for_restitution(restitution_coefficient: float, speed: float = 1.0, *, n: float = 2.5, mass=1.0,
                          stiffness: float = 1.0, clamp: bool = True) -> float:
    """The damping time ``gamma`` whose two-body collision at ``speed`` has the coefficient of restitution
    ``restitution_coefficient`` (in [0.05, 1]; 1 gives 0): :func:`restitution` (with ``clamp``) is
    decreasing in gamma, and ``scipy.optimize.brentq`` solves e(gamma) = e to 1e-12 relative, in a
    bracket found by doubling from the small-damping estimate at most 40 times (a bounded search: every
    argument is checked first, so a NaN cannot keep it going)."""
    from scipy.optimize import brentq

    from .._validate import finite_scalar

    try:
        e = finite_scalar("restitution", restitution_coefficient)
    except ValueError:
        e = math.nan
    if not (0.0 < e <= 1.0):
        raise ValueError(f"the coefficient of restitution must lie in (0, 1] (1: elastic), got {restitution_coefficient!r}")
    if e < MIN_RESTITUTION:
        raise ValueError(f"restitution = {e:g} is below {MIN_RESTITUTION:g}: so strong a damping is outside the "
                         "quasi-static viscoelastic regime the Kuwabara-Kono law holds in; give a coefficient of "
                         f"restitution in [{MIN_RESTITUTION:g}, 1]")
    _checked(0.0, speed, n, mass, stiffness)
    if not isinstance(clamp, (bool, np.bool_)):
        raise ValueError(f"clamp must be True or False, got {clamp!r}")
    if e == 1.0:
        return 0.0
    kw = dict(n=n, mass=mass, stiffness=stiffness, clamp=clamp)
    lead = dict(n=n, mass=mass, stiffness=stiffness)
    unit = 1.0 - restitution_leading_order(1.0, speed, **lead)  # 1 - e per unit gamma, to first order
    hi = (1.0 - e) / unit
    for _ in range(40):
        if restitution(hi, speed, **kw) < e:
            break
        hi *= 2.0
    else:  # pragma: no cover -- e >= MIN_RESTITUTION is reached within a few doublings
        raise ValueError(f"no damping gives a coefficient of restitution as low as {e:g} at speed {speed:g}")
    return float(brentq(lambda g: restitution(g, speed, **kw) - e, 0.0, hi, xtol=1e-15, rtol=1e-12))
