"""The figure of the tutorial *Design a protector*: docs/tutorials/design-a-protector.png.

    python docs/tutorials/_design_a_protector.py

A steel bead of radius 5 mm strikes, at 1 m/s, a column of 20 steel beads standing on a fixed steel wall (immovable, of the beads' material)
(the bead struck first is granule 1). Which geometric taper R_k = (1 - q)^(k-1), q in [0, 0.2],
transmits the smallest peak force to the wall? ``compute()`` runs the design (SciPy's differential
evolution and a Powell refinement over batches of the compiled kernel) and returns the result;
``plot(result)`` draws its convergence and the wall force of the design found against a monodisperse
chain of the same number of beads and one of the same length and mass, in newtons and microseconds. The script checks its
picture before saving it: every axis labelled with its unit, a legend on every panel.
"""

from __future__ import annotations

from pathlib import Path

import granchain as gc
from granchain import design

OUT = Path(__file__).with_name("design-a-protector.png")

SIZE = 20
Q_BOUNDS = (0.0, 0.2)
BUDGET = 80
MATERIAL, RADIUS, IMPACT_SPEED = "steel", "5 mm", "1 m/s"


def compute():
    """The design run (deterministic: seed 0)."""
    return design.optimize(design.TaperedSpace(SIZE, Q_BOUNDS), "wall-force", budget=BUDGET, seed=0)


def plot(result):
    return result.plot(scale=gc.scale(MATERIAL, RADIUS, IMPACT_SPEED))


def check(fig) -> None:
    for ax in fig.axes:
        assert ax.get_xlabel() and ax.get_ylabel(), "every axis needs a label"
        assert ax.get_legend() is not None, "every panel needs a legend"
    assert "(N)" in fig.axes[1].get_ylabel() and "µs" in fig.axes[1].get_xlabel()


if __name__ == "__main__":
    import matplotlib

    matplotlib.use("Agg")
    fig = plot(compute())
    check(fig)
    fig.savefig(OUT, dpi=110)
    print(f"wrote {OUT}")
