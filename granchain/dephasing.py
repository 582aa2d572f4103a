"""Moved to :mod:`granchain.paper.dephasing` (this path warns; see :mod:`granchain._moved`)."""

from ._moved import alias

alias(__name__)
