"""Moved to :mod:`granchain.paper.figures` (this path and its submodules warn; see :mod:`granchain._moved`)."""

from .._moved import alias

alias(__name__, submodules=("_style", "fig1", "fig2", "fig3", "fig4", "theory", "validity"))
