"""Shared figure helpers: one look for every figure, saved as PNG and PDF."""

from __future__ import annotations

from pathlib import Path

TIME_LABEL = r"time $t$ (rescaled units, paper Sec. II)"
VELOCITY_UNITS = r"(units of $V_1$)"
COLORS = {"decorated": "tab:blue", "effective": "black", "bca": "tab:red", "paper": "tab:gray", "fit": "tab:orange"}
MARKERS = {"decorated": "o", "effective": "s"}


def axes(ax=None, figsize=(6.4, 4.4)):
    """``ax`` if given, else a new figure's axes."""
    import matplotlib.pyplot as plt

    if ax is not None:
        return ax.figure, ax
    fig, ax = plt.subplots(figsize=figsize, layout="constrained")
    return fig, ax


def panel_pair(ax=None, figsize=(7.0, 7.0), height_ratios=(1.4, 1)):
    """(figure, main axes, lower axes): a main panel over a residual panel sharing x, or the
    pair ``ax`` = (main, lower) if given."""
    import matplotlib.pyplot as plt

    if ax is not None:
        main, low = ax
        return main.figure, main, low
    fig, (main, low) = plt.subplots(2, 1, figsize=figsize, sharex=True, height_ratios=list(height_ratios), layout="constrained")
    return fig, main, low


def save(fig, stem) -> list[Path]:
    """Write ``stem``.png (200 dpi) and ``stem``.pdf; return the paths.

    The PDF is drawn with the layout the PNG was drawn with: a layout engine (constrained layout)
    runs once, not once per format (it is ~40 % of a draw; the PDF's own layout would move the axes
    by < 1 pt, text measured at 72 instead of 200 dpi). The figure keeps its engine afterwards.
    """
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    paths = [stem.with_suffix(".png"), stem.with_suffix(".pdf")]
    fig.savefig(paths[0], dpi=200)
    engine = fig.get_layout_engine()
    if engine is None:
        fig.savefig(paths[1])
        return paths
    fig.set_layout_engine("none")
    try:
        fig.savefig(paths[1])
    finally:
        fig.set_layout_engine(engine)
    return paths


def text_overlaps(fig, include_ticks=True) -> list[tuple[str, str]]:
    """Pairs of visible, non-empty text artists of ``fig`` whose window extents overlap.

    Draws the canvas first. Legends count as one box each (their texts are inside them by
    design); tick labels of one axis are compared with everything else.
    """
    from matplotlib.legend import Legend
    from matplotlib.text import Text

    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    legends = [a for a in fig.findobj(Legend) if a.get_visible()]
    inside_legend = {id(t) for lg in legends for t in lg.findobj(Text)}
    boxes = [(f"legend {i}", lg.get_window_extent(renderer)) for i, lg in enumerate(legends)]
    from matplotlib.axes import Axes

    tick_ids, drawn = set(), []
    for ax in fig.findobj(Axes):
        for axis in ax._axis_map.values():
            for tick in axis.majorTicks + axis.minorTicks:
                tick_ids.update((id(tick.label1), id(tick.label2)))
            if include_ticks and ax.get_visible() and axis.get_visible():
                for tick in axis._update_ticks():  # the ticks actually drawn (inside the view limits)
                    drawn += [t for t in (tick.label1, tick.label2) if t.get_visible()]
    for t in [t for t in fig.findobj(Text) if id(t) not in tick_ids] + drawn:
        if id(t) in inside_legend or not t.get_visible() or not t.get_text().strip():
            continue
        bb = t.get_window_extent(renderer)
        if bb.width > 0 and bb.height > 0:
            boxes.append((repr(t.get_text()), bb))
    hits = []
    for i in range(len(boxes)):
        for j in range(i + 1, len(boxes)):
            a, b = boxes[i][1], boxes[j][1]
            if a.x0 < b.x1 - 0.5 and b.x0 < a.x1 - 0.5 and a.y0 < b.y1 - 0.5 and b.y0 < a.y1 - 0.5:
                hits.append((boxes[i][0], boxes[j][0]))
    return hits
