"""The figure of a design run: (a) convergence, (b) the best design's wall force against monodisperse chains
(one of the same number of granules, the run's reference; one of the same length and the same mass behind
the same struck granule, :func:`length_and_mass_chain`).

``compute(result)`` returns the data (re-running the best chain and the references with
:func:`granchain.simulate`), ``plot(result)`` draws it; with a :class:`granchain.units.Scale` the axes
are in microseconds and newtons (or metres per second).
"""

from __future__ import annotations

import numpy as np

from ..model.chain import from_radii
from ..solve.simulation import simulate

__all__ = ["compute", "length_and_mass_chain", "plot"]


def length_and_mass_chain(result):
    """The same impact on a monodisperse protector of the same length and the same mass as the best design.

    Granule 1 is the struck granule of every design (radius 1, struck with velocity 1: the same input
    energy); behind it come K equal spheres of granule 1's material whose total mass is that of the
    best design's granules 2..M and whose total length (sum of diameters) is that of granules 2..M as
    nearly as a whole number of spheres allows: K r = L and K r^3 = m give r = sqrt(m / L), K the
    nearest integer to L / r, then r = (m / K)^(1/3) so that the mass is exact. Returns (chain, K, r,
    relative length mismatch). Comparing with a chain whose *every* granule is lighter would also lower
    the input energy m_1 v_1^2 / 2, so granule 1 is kept."""
    m = (result.chain.masses[:-1] if result.chain.wall else result.chain.masses)[1:]
    half = np.asarray(result.best_radii, dtype=float)[1:]
    mass, length = float(m.sum()), float(half.sum())  # length: sum of radii (half the sum of diameters)
    k = max(1, int(round(length / np.sqrt(mass / length))))
    radius = (mass / k) ** (1.0 / 3.0)
    radii = np.concatenate(([1.0], np.full(k, radius)))
    chain = from_radii(radii, n=result.chain.n, kind="monodisperse", wall=result.chain.wall)
    if result.chain.contact.dissipates:  # the run's contact law, as the design and the reference have it
        chain = chain.replace(contact=result.chain.contact)
    return chain, k, radius, k * radius / length - 1.0


def compute(result, dt: float = 0.02) -> dict:
    """Data of :func:`plot`: the history's values, and the force on the wall (for a chain with a wall;
    else the last granule's velocity) of the best chain and of the two monodisperse references."""
    same, k, radius, mismatch = length_and_mass_chain(result)
    size = result.reference_chain.size - int(result.reference_chain.wall)
    chains = {"design found": result.chain, f"monodisperse, {size} granules of radius 1 (same number)": result.reference_chain,
              f"granule 1 + {k} of radius {radius:.3g}: same mass and length ({mismatch:+.1%})": same}
    integ = result.integrator
    t_end = max(float(simulate(ch, integ).t_end) for ch in chains.values())
    grid = np.arange(0.0, t_end + dt / 2, dt)
    curves = {}
    for name, ch in chains.items():
        res = simulate(ch, integ, t_grid=grid)
        curves[name] = res.wall_force if ch.wall else res.velocities[:, -1] if res.velocities.ndim == 2 else res.velocity[-1]
    h = result.history
    value = np.asarray(h["value"].values, dtype=float)
    f = np.where(np.isfinite(value), result.objective.sense * value, np.inf)
    best = result.objective.sense * np.minimum.accumulate(f)
    return {"evaluation": np.arange(1, value.size + 1), "value": value, "best_so_far": best, "t": grid, "curves": curves,
            "wall": result.chain.wall, "reference": result.reference_value}


def plot(result, scale=None, fig=None, data=None):
    """Two panels: (a) every evaluation's objective and the best so far, with the monodisperse
    reference; (b) the best design's wall force against a monodisperse chain of the same number of
    granules and one of the same length and mass behind the same struck granule. Physical units with ``scale`` (a :class:`granchain.units.Scale`)."""
    import matplotlib.pyplot as plt

    d = compute(result) if data is None else data
    obj = result.objective
    if fig is None:
        fig = plt.figure(figsize=(10, 4.2), layout="constrained")
    ax1, ax2 = fig.subplots(1, 2)

    def conv(v, kind):
        if scale is None or kind == "1":
            return v, "rescaled" if kind != "1" else ""
        from ..units import SI_UNITS

        si = scale.to_si(np.asarray(v, dtype=float), kind)
        if kind == "time":
            return si * 1e6, "µs"
        return si, SI_UNITS[kind]

    vals, unit = conv(d["value"], obj.kind)
    best, _ = conv(d["best_so_far"], obj.kind)
    ref, _ = conv(d["reference"], obj.kind)
    ax1.plot(d["evaluation"], vals, ".", ms=3, color="0.6", label="each evaluation")
    ax1.plot(d["evaluation"], best, "-", color="C0", lw=2, label="best so far")
    ax1.axhline(ref, color="C3", ls="--", label="monodisperse, same number of granules")
    ax1.set_xlabel("evaluation")
    ax1.set_ylabel(f"{obj.long_name}" + (f" ({unit})" if unit else ""))
    ax1.set_title("(a) convergence", loc="left")
    ax1.legend(fontsize=8)
    t, tunit = conv(d["t"], "time")
    kind = "force" if d["wall"] else "velocity"
    for (name, y), style in zip(d["curves"].items(), ("-", "--", ":")):
        yy, yunit = conv(y, kind)
        ax2.plot(t, yy, style, lw=1.6, label=name)
    ax2.set_xlabel(f"time ({tunit})")
    ax2.set_ylabel(("force on the wall" if d["wall"] else "velocity of the last granule") + f" ({yunit})")
    ax2.set_title("(b) " + ("what the wall feels" if d["wall"] else "what leaves the chain"), loc="left")
    ax2.legend(fontsize=8)
    return fig
