"""The two-body collision of viscoelastic spheres: the coefficient of restitution of the contact law
:class:`granchain.model.contacts.Viscoelastic`, and the damping that gives a chosen one.

Two spheres of masses m1, m2 meet at the relative speed v; their compression delta obeys

    mu delta'' = -c [delta^(n-1) + gamma delta^(n-2) delta'],   mu = m1 m2 / (m1 + m2),

from delta = 0, delta' = v, until the force vanishes (it is clamped at 0: the spheres then separate
freely, T. Poschel and T. Schwager, *Computational Granular Dynamics*, Springer 2005, Sec. 2.3). The
coefficient of restitution is e = -delta'(end) / v. :func:`restitution` integrates this with SciPy's
DOP853 (sharing no code with the chain kernels: the independent check of them);
:func:`restitution_leading_order` is its small-damping limit, which for n = 5/2 is the Kuwabara-Kono
law 1 - e ~ gamma v^(1/5) (Schwager & Poschel, Phys. Rev. E 57, 650 (1998); Ramirez et al., Phys. Rev.
E 60, 4465 (1999)).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["restitution", "gamma_for_restitution", "restitution_leading_order", "KUWABARA_KONO_C1"]

#: The first coefficient of the expansion 1 - e = C1 gamma (c / mu)^(2/5) v^(1/5) + ... for n = 5/2:
#: sqrt(pi) Gamma(3/5) / (2^(1/5) 5^(2/5) Gamma(21/10)) (Schwager & Poschel 1998; Ramirez et al. 1999,
#: whose expansion variable (3/2) A (rho / m_eff)^(2/5) is gamma (c / mu)^(2/5) here).
KUWABARA_KONO_C1 = math.sqrt(math.pi) * math.gamma(0.6) / (2.0**0.2 * 5.0**0.4 * math.gamma(2.1))


def _reduced_mass(mass) -> float:
    m = np.broadcast_to(np.asarray(mass, dtype=float), (2,))
    if not np.all(np.isfinite(m)) or np.any(m <= 0):
        raise ValueError(f"the colliding masses must be finite and > 0, got {mass!r}")
    return float(m[0] * m[1] / (m[0] + m[1]))


def restitution(gamma: float, speed: float = 1.0, *, n: float = 2.5, mass=1.0, stiffness: float = 1.0,
                rtol: float = 1e-12) -> float:
    """The coefficient of restitution of two spheres (masses ``mass``: one value for both, or a pair;
    contact prefactor ``stiffness``) meeting at relative ``speed``, with the viscoelastic law of
    damping time ``gamma``: the two-body problem above, integrated with SciPy's DOP853 to the
    vanishing of the force (an event), rescaled units."""
    from scipy.integrate import solve_ivp

    mu = _reduced_mass(mass)
    g, v, c = float(gamma), float(speed), float(stiffness)
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"the impact speed must be finite and > 0, got {speed!r}")
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
        return [w, -max(f, 0.0) / mu]

    def force_vanishes(t, y):  # d^(n-2) (d + gamma w) = 0 with d > 0: d + gamma w = 0
        return y[0] + g * y[1]

    force_vanishes.terminal = True
    force_vanishes.direction = -1
    sol = solve_ivp(rhs, (0.0, 200.0 * t_scale), [0.0, v], method="DOP853", rtol=rtol, atol=1e-14 * d_max,
                    events=force_vanishes, first_step=1e-6 * t_scale)
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

    mu = _reduced_mass(mass)
    v, c = float(speed), float(stiffness)
    d_max = (n * mu * v * v / (2.0 * c)) ** (1.0 / n)
    dE = 2.0 * c * gamma * v * d_max ** (n - 1.0) * beta((n - 1.0) / n, 1.5) / n
    return 1.0 - dE / (mu * v * v)


def gamma_for_restitution(restitution_coefficient: float, speed: float = 1.0, *, n: float = 2.5, mass=1.0,
                          stiffness: float = 1.0) -> float:
    """The damping time ``gamma`` whose two-body collision at ``speed`` has the coefficient of restitution
    ``restitution_coefficient`` (in (0, 1]; 1 gives 0): :func:`restitution` is decreasing in gamma, and
    ``scipy.optimize.brentq`` solves e(gamma) = e to 1e-12 relative, in a bracket found by doubling
    from the small-damping estimate."""
    from scipy.optimize import brentq

    try:
        e = float(restitution_coefficient)
    except (TypeError, ValueError):
        raise ValueError(f"the coefficient of restitution must be a number in (0, 1], got {restitution_coefficient!r}") from None
    if not (0.0 < e <= 1.0):
        raise ValueError(f"the coefficient of restitution must lie in (0, 1] (1: elastic), got {restitution_coefficient!r}")
    if not (math.isfinite(float(speed)) and float(speed) > 0):
        raise ValueError(f"the reference impact speed must be finite and > 0, got {speed!r}")
    if e == 1.0:
        return 0.0
    kw = dict(n=n, mass=mass, stiffness=stiffness)
    unit = 1.0 - restitution_leading_order(1.0, speed, **kw)  # 1 - e per unit gamma, to first order
    hi = (1.0 - e) / unit
    for _ in range(60):
        if restitution(hi, speed, **kw) < e:
            break
        hi *= 2.0
    else:
        raise ValueError(f"no damping gives a coefficient of restitution as low as {e:g} at speed {speed:g}")
    return float(brentq(lambda g: restitution(g, speed, **kw) - e, 0.0, hi, xtol=1e-15, rtol=1e-12))
