"""Decorated chain -> effective (undecorated) chain (paper Sec. III A).

Each small granule is treated as a massless spring of two Hertz contacts in
series between its large neighbours; half its mass goes to each neighbour.
"""

from __future__ import annotations

import numpy as np

from .._validate import warn_effective_validity
from .chain import Chain, sphere_mass, sphere_stiffness

__all__ = ["effective", "effective_parameters"]


def effective_parameters(large_radii: np.ndarray, small_radii: np.ndarray, n: float) -> tuple[np.ndarray, np.ndarray]:
    """Masses mu_k and stiffnesses of the effective chain.

    Masses, Eq. (renorm-mass): mu_k = m_k + (s_{k-1} + s_k)/2, s_j = R_j^3, the
    end granules taking half of their single neighbour ("left"/"right").

    Interactions, Eq. (effec-int): two contacts in series carry the same force
    F = c_l d_l^(n-1) = c_r d_r^(n-1) with d_l + d_r = delta, so
    F = c_eff delta^(n-1), c_eff = (c_l^(-1/(n-1)) + c_r^(-1/(n-1)))^(-(n-1)).
    For equal sides (monodisperse large granules of radius 1) this is
    c / 2^(n-1) with c = r_k = sqrt(2 R_k / (1 + R_k)), Eq. (zetak), exactly the
    paper's V_eff = r_k / (n 2^(n-1)) delta^n. The general form also serves
    decorated chains whose large granules differ (e.g. tapered).

    Works along the last axis (one chain, or a batch of chains with the same N), with
    bitwise the same values either way.
    """
    big = np.asarray(large_radii, dtype=float)
    s = np.asarray(small_radii, dtype=float)
    small_mass = sphere_mass(s)
    mu = sphere_mass(big)  # Eq. (renorm-mass)
    mu[..., :-1] += 0.5 * small_mass
    mu[..., 1:] += 0.5 * small_mass
    radii = np.empty(s.shape[:-1] + (2 * s.shape[-1] + 1,))
    radii[..., 0::2] = big
    radii[..., 1::2] = s
    c = sphere_stiffness(radii)  # Eq. (r-prime) on each side of every small granule
    cl, cr = c[..., 0::2], c[..., 1::2]
    p = 1.0 / (n - 1.0)
    with np.errstate(all="ignore"):
        series = (cl**-p + cr**-p) ** -(n - 1.0)  # two contacts in series
    c_eff = np.where(cl == cr, cl * 2.0 ** -(n - 1.0), series)  # Eq. (effec-int): r_k / 2^(n-1)
    return mu, c_eff


def effective(chain: Chain, *, momentum_conserving: bool = False) -> Chain:
    """The effective chain of a decorated chain (paper Eqs. renorm-mass, effec-int, zetak).

    ``chain`` must alternate large and small granules with both ends large (as
    built by :func:`granchain.decorated`). The effective chain has the N large
    granules, all observed. Its granule 1 starts with velocity 1 (the decorated
    chain's impulse, the default: best arrival times) or, with
    ``momentum_conserving=True``, with m_1 v_1 / mu_1 so that momentum matches.
    Warns (:class:`granchain.EffectiveValidityWarning`) when a small radius
    exceeds 0.4 of its neighbours. A decorated chain ending in a wall gives an effective
    chain ending in the same wall: large granule N touches it directly, with the decorated
    chain's wall stiffness sqrt(2 R_N).
    """
    if not isinstance(chain, Chain):
        raise ValueError(f"effective() needs a decorated granchain.Chain, got {type(chain).__name__}")
    if chain.wall:
        free = Chain(chain.masses[:-1], chain.stiffness[:-1], chain.n, chain.initial_velocity, chain.observed,
                     chain.radii[:-1] if chain.radii is not None else None, chain.kind, dict(chain.meta))
        return effective(free, momentum_conserving=momentum_conserving).with_wall(float(chain.stiffness[-1]))
    if chain.radii is None or chain.size % 2 == 0 or chain.size < 3:
        raise ValueError(
            "effective() needs a decorated chain built from radii with an odd number of granules "
            "(large, small, large, ..., large), e.g. granchain.decorated(small_radii)"
        )
    big, small = chain.radii[0::2], chain.radii[1::2]
    ratio = small / np.minimum(big[:-1], big[1:])
    if np.any(ratio >= 1.0):
        j = int(np.argmax(ratio >= 1.0))
        raise ValueError(
            f"granule {2 * j + 2} (1-based) is not smaller than its neighbours (ratio {ratio[j]:.3g}): "
            "effective() needs a decorated chain whose even (1-based) granules are the small ones"
        )
    warn_effective_validity(float(ratio.max()), what="the decorated chain", stacklevel=3)
    mu, c_eff = effective_parameters(big, small, chain.n)
    v0 = chain.initial_velocity
    if momentum_conserving:
        v0 = chain.masses[0] * chain.initial_velocity / mu[0]
    out = Chain(mu, c_eff, chain.n, v0, None, None, "effective")
    out.meta["small_radii"] = np.array(small)
    out.meta["momentum_conserving"] = bool(momentum_conserving)
    return out
