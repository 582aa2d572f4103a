"""Draw the layers of granchain and who uses whom: docs/explanation/architecture.png.

    python docs/explanation/_architecture.py

Boxes are packages, an arrow points from a layer to one it uses (imports or calls); nothing
points upwards. Dashed boxes are loaded on first use (``import granchain`` does not load them).
The script checks its own picture before saving it: every text inside its box, no two texts
overlapping, so an edit that crowds a box fails here rather than in the rendered page.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch  # noqa: E402

OUT = Path(__file__).with_name("architecture.png")

# Colours by role (colour-blind safe pairs from the Okabe-Ito palette, lightened).
CORE = "#cfe3f3"      # the model, solving, backends: what every run goes through
RUN = "#d5efe2"       # ensembles and families: many chains
STATS = "#fbe3c8"     # statistics and theories: read results, never run the dynamics themselves
PAPER = "#f3d3e4"     # the paper's own reproduction
CLI = "#e4e4e4"       # the command line
UNITS = "#f4f1c9"     # physical units, beside everything

#: name -> (x0, y0, width, height, colour, lazily loaded, title, body)
BOXES = {
    "cli": (0.4, 11.55, 15.2, 1.05, CLI, True, "granchain.cli",
            "the granchain command: pulse, ensemble, bca, theory, validity, reproduce, info, export"),
    "paper": (0.4, 9.7, 15.2, 1.3, PAPER, True, "granchain.paper",
              "the founding paper's reproduction: reproduce, report, figures (one module per figure), validity, "
              "dephasing\nold paths granchain.figures, .validity, .dephasing: deprecated aliases of these"),
    "families": (0.4, 6.75, 4.5, 2.2, RUN, False, "granchain.families",
                 "realisation i -> one chain:\nRandomDecorated, TaperedDecorated,\nRandomRadii, BinaryRandom,\n"
                 "CustomFamily"),
    "ensembles": (5.5, 6.75, 4.9, 2.2, RUN, False, "granchain.ensembles",
                  "run: chunks, seeds from (seed, i), Dask\nschema: the one table of variables\nstore: write, resume, checksums\n"
                  "read: open_store; lock: one writer"),
    "stats": (11.0, 6.75, 4.6, 2.2, STATS, True, "statistics and theories",
              "granchain.analysis\n(+ pulsefits, jackknife)\ngranchain.bca (BCA)\ngranchain.theory"),
    "backends": (1.4, 4.15, 5.9, 1.95, CORE, False, "granchain.backends",
                 "get_backend('numba' | 'scipy' | 'cuda'), Backend.check,\neffective_integrator, integrator_as_run\n"
                 "numba_backend; scipy_backend (DOP853);\ncuda (the GPU backend, optional)"),
    "solve": (8.6, 4.15, 6.0, 1.95, CORE, False, "granchain.solve",
              "integrators: values with capabilities\n(DP5, RKN4, Verlet, DOP853; INTEGRATORS)\n"
              "simulate(chain) -> PulseResult"),
    "kernels": (1.4, 2.0, 5.2, 1.6, CORE, True, "granchain.backends.kernels (Numba)",
                "records (Params, Model, Method, Run, ...), forces,\nwindow, stop, peaks, dense, rkloop, observe, dp5,\n"
                "rkn4, verlet, dispatch, batch, aligned, memory, jit"),
    "units": (8.6, 2.0, 4.9, 1.6, UNITS, False, "granchain.units",
              "physical units (paper Sec. II\nrescaling): the units attributes\nof every result"),
    "model": (0.4, 0.2, 15.2, 1.3, CORE, False, "granchain.model",
              "what a chain is, as values: contacts (PowerLaw, Viscoelastic, Precompression, FreeEnd, LoadedEnd, "
              "FixedWall, Impulse, Striker),\ncollision (restitution), chain (Chain and its builders), effective, "
              "distributions, random (chains drawn from (seed, i))"),
}

#: (from, to, start (x, y), end (x, y), label, label position (x, y), label alignment)
ARROWS = [
    ("cli", "paper", (8.0, 11.55), (8.0, 11.0), "", None, "left"),
    ("paper", "families", (2.65, 9.7), (2.65, 8.95), "", None, "left"),
    ("paper", "ensembles", (7.95, 9.7), (7.95, 8.95), "", None, "left"),
    ("paper", "stats", (13.3, 9.7), (13.3, 8.95), "", None, "left"),
    ("ensembles", "families", (5.5, 7.85), (4.9, 7.85), "", None, "left"),
    ("ensembles", "solve", (9.6, 6.75), (9.6, 6.1), "", None, "left"),
    ("stats", "solve", (12.6, 6.75), (12.6, 6.1), "", None, "left"),
    ("solve", "backends", (8.6, 5.12), (7.3, 5.12), "integrator\n.backend", (7.95, 5.55), "center"),
    ("backends", "kernels", (4.0, 4.15), (4.0, 3.6), "grouped records", (4.15, 3.87), "left"),
    ("families", "model", (0.85, 6.75), (0.85, 1.5), "", None, "left"),
    ("backends", "model", (6.95, 4.15), (6.95, 1.5), "", None, "left"),
    ("solve", "model", (14.0, 4.15), (14.0, 1.5), "", None, "left"),
    ("stats", "model", (15.25, 6.75), (15.25, 1.5), "", None, "left"),
]


def draw():
    fig, ax = plt.subplots(figsize=(12.0, 9.6))
    ax.set_xlim(0.0, 16.0)
    ax.set_ylim(-0.55, 12.75)
    ax.set_axis_off()
    texts = []  # (text artist, its box name or None)
    for name, (x0, y0, w, h, colour, lazy, title, body) in BOXES.items():
        ax.add_patch(FancyBboxPatch((x0, y0), w, h, boxstyle="round,pad=0.0,rounding_size=0.12", facecolor=colour,
                                    edgecolor="#333333", linewidth=1.3, linestyle=(0, (5, 3)) if lazy else "solid",
                                    zorder=2))
        t = ax.text(x0 + 0.18, y0 + h - 0.14, title, ha="left", va="top", fontsize=11.5, fontweight="bold",
                    family="DejaVu Sans Mono", zorder=4)
        b = ax.text(x0 + 0.18, y0 + h - 0.55, body, ha="left", va="top", fontsize=9.3, linespacing=1.35, zorder=4)
        texts += [(t, name), (b, name)]
    for src, dst, start, end, label, at, align in ARROWS:
        ax.add_patch(FancyArrowPatch(start, end, arrowstyle="-|>", mutation_scale=16, color="#333333", linewidth=1.4,
                                     shrinkA=0, shrinkB=0, zorder=3))
        if label:
            texts.append((ax.text(*at, label, ha=align, va="center", fontsize=8.5, style="italic", zorder=4,
                                  linespacing=1.1, bbox=dict(facecolor="white", edgecolor="none", pad=1.0)), None))
    key = ("An arrow points from a layer to one it uses; nothing points upwards.   "
           "Dashed: loaded on first use, not by \"import granchain\".")
    texts.append((ax.text(8.0, -0.2, key, ha="center", va="center", fontsize=9.5), None))
    fig.subplots_adjust(left=0.01, right=0.99, bottom=0.01, top=0.99)
    check(fig, ax, texts)
    return fig


def check(fig, ax, texts):
    """Every box text lies inside its box, and no two texts overlap (in display pixels)."""
    renderer = fig.canvas.get_renderer()
    boxes = {name: ax.transData.transform([(x0, y0), (x0 + w, y0 + h)])
             for name, (x0, y0, w, h, *_rest) in BOXES.items()}
    extents = [(t.get_window_extent(renderer), name, t.get_text()) for t, name in texts]
    for bb, name, text in extents:
        if name is not None:
            (bx0, by0), (bx1, by1) = boxes[name]
            if not (bx0 <= bb.x0 and bb.x1 <= bx1 and by0 <= bb.y0 and bb.y1 <= by1):
                raise SystemExit(f"text {text[:40]!r} leaves its box {name!r}: {bb} not in {boxes[name]}")
    for i, (a, _, ta) in enumerate(extents):
        for b, _, tb in extents[i + 1:]:
            if a.overlaps(b):
                raise SystemExit(f"texts overlap: {ta[:40]!r} and {tb[:40]!r}")


if __name__ == "__main__":
    figure = draw()
    figure.savefig(OUT, dpi=120)
    print(f"wrote {OUT}")
