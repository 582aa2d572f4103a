"""The figure of the tutorial *A real experiment*: docs/tutorials/real-experiment.png.

    python docs/tutorials/_real_experiment.py

A column of 20 stainless-steel beads (radius 2.38 mm) stands on a wall of the same steel, under a
static load of 2 N, and is struck by a bead of the same kind at 0.5 m/s. The figure shows the force
measured inside three beads (an embedded gauge reads the mean of a bead's two contact forces) and the
force on the wall, in newtons against microseconds: elastic contacts (dashed) and viscoelastic ones
(solid) whose two-bead coefficient of restitution is 0.95 at the impact speed.

``compute()`` builds the two chains and runs them; ``plot(data)`` draws what ``compute()`` (or the
tutorial, with its own runs) returns. The script checks its own picture before saving it: every
axis labelled with its unit, a legend on every panel, no two texts overlapping.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

import granchain as gc
from granchain import units

OUT = Path(__file__).with_name("real-experiment.png")

BEADS = 20                 # beads in the column, the wall below the last
RADIUS = "2.38 mm"         # D = 4.76 mm (3/16 in)
IMPACT_SPEED = "0.5 m/s"   # the striker's speed
STATIC_FORCE = "2 N"       # the static load
RESTITUTION = 0.95         # two beads colliding at the impact speed
SENSORS = (5, 10, 15)      # beads with a gauge (1-based; bead 1 is the one the striker hits)
T_END = 80.0               # rescaled time units (about 560 us here)
DT = 0.01


def build(scale: units.Scale, *, dissipative: bool) -> gc.Chain:
    """The column: beads on the wall, the static load, a striker bead; viscoelastic if asked."""
    chain = gc.from_radii(np.ones(BEADS), materials="stainless-steel", wall=True)
    chain = chain.with_precompression(scale.to_rescaled(STATIC_FORCE, "force")).with_striker(radius=1.0)
    if dissipative:  # rescaled speed 1 is the impact speed of the scale
        chain = chain.with_dissipation(restitution=RESTITUTION, speed=1.0)
    return chain


def compute(t_end: float = T_END, dt: float = DT) -> dict:
    """Run the elastic and the dissipative column; the results and their scale."""
    scale = units.scale(units.STAINLESS_STEEL, RADIUS, IMPACT_SPEED)
    t = np.arange(0.0, t_end + dt / 2, dt)
    runs = {name: gc.simulate(build(scale, dissipative=name == "dissipative"), t_grid=t, sensors=list(SENSORS))
            for name in ("elastic", "dissipative")}
    return {"scale": scale, **runs}


def plot(data: dict, axes=None):
    """Sensor forces (top) and the wall force (bottom) in N against time in us."""
    import matplotlib.pyplot as plt

    scale = data["scale"]
    if axes is None:
        fig, axes = plt.subplots(2, 1, figsize=(7.2, 6.4), sharex=True)
    else:
        fig = axes[0].figure
    colours = ("#0072B2", "#D55E00", "#009E73")  # Okabe-Ito: colour-blind safe
    styles = {"elastic": dict(ls="--", lw=1.1), "dissipative": dict(ls="-", lw=1.6)}
    for name in ("elastic", "dissipative"):
        res = data[name]
        t_us = res.t_grid * scale.time * 1e6
        for colour, k, f in zip(colours, res.sensor_granule, res.sensor_force):
            axes[0].plot(t_us, f * scale.force, color=colour, label=f"bead {k}, {name}", **styles[name])
        axes[1].plot(t_us, res.wall_force * scale.force, color="#333333", label=f"wall, {name}", **styles[name])
    static = data["elastic"].static_force * scale.force
    for ax in axes:
        ax.axhline(static, color="#999999", lw=0.8, ls=":", label=f"static load {static:g} N")
        ax.set_ylabel("force (N)")
        ax.grid(alpha=0.3)
    axes[0].set_title("force inside the gauge beads", fontsize=10)
    axes[1].set_title("force on the wall", fontsize=10)
    axes[1].set_xlabel(r"time after impact ($\mu$s)")
    for ax, room in zip(axes, (1.45, 1.25)):  # room for the legend above the curves
        top = max(np.max(line.get_ydata()) for line in ax.get_lines())
        ax.set_ylim(-0.05 * top, room * top)
        ax.legend(fontsize=7.5, ncol=3, loc="upper center")
    axes[1].set_xlim(0.0, t_us[-1])
    fig.tight_layout()
    return fig


def check(fig) -> None:
    """Every axis labelled (with a unit in parentheses), a legend on every panel, no two texts overlapping."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    texts = []
    for ax in fig.axes:
        if not ax.get_ylabel().endswith(")") or (ax.get_xlabel() and not ax.get_xlabel().endswith(")")):
            raise SystemExit(f"axis without a unit: {ax.get_xlabel()!r}, {ax.get_ylabel()!r}")
        if ax.get_legend() is None:
            raise SystemExit(f"panel {ax.get_title()!r} has no legend")
        texts += [ax.title, ax.yaxis.label, ax.xaxis.label, ax.get_legend()]
    boxes = [(t.get_window_extent(renderer), t) for t in texts if (getattr(t, "get_text", None) is None or t.get_text())]
    for i, (a, ta) in enumerate(boxes):
        for b, tb in boxes[i + 1:]:
            if a.overlaps(b):
                raise SystemExit(f"texts overlap: {ta} and {tb}")


if __name__ == "__main__":
    import matplotlib

    matplotlib.use("Agg")
    figure = plot(compute())
    check(figure)
    figure.savefig(OUT, dpi=120)
    print(f"wrote {OUT}")
