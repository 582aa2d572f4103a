"""Shared figure helpers: one look for every figure, saved as PNG and PDF."""

from __future__ import annotations

from pathlib import Path

TIME_LABEL = r"time $t$ (rescaled units, paper Sec. II)"
VELOCITY_UNITS = r"(units of $V_1$)"
COLORS = {"decorated": "tab:blue", "effective": "black", "bca": "tab:red", "paper": "tab:gray"}


def axes(ax=None, figsize=(6.4, 4.4)):
    """``ax`` if given, else a new figure's axes."""
    import matplotlib.pyplot as plt

    if ax is not None:
        return ax.figure, ax
    fig, ax = plt.subplots(figsize=figsize, constrained_layout=True)
    return fig, ax


def save(fig, stem) -> list[Path]:
    """Write ``stem``.png (200 dpi) and ``stem``.pdf; return the paths."""
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    paths = [stem.with_suffix(".png"), stem.with_suffix(".pdf")]
    fig.savefig(paths[0], dpi=200)
    fig.savefig(paths[1])
    return paths
