"""Moved to :mod:`granchain.paper.validity` (this path warns; see :mod:`granchain._moved`)."""

from ._moved import alias

alias(__name__)
