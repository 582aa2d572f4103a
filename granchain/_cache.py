"""Where granchain keeps what it computes once and reuses between sessions: the compiled kernels
(``granchain.backends.kernels``) and the theory's tables (``granchain.theory``).

Always a per-user cache directory, never the installed package: an installed package may be
read-only, and a file written next to its sources is one that pip does not know about, so pip
leaves it behind on ``pip uninstall`` (or on a reinstall as editable), and the left-over directory
then shadows the package that is really installed.
"""

from __future__ import annotations

import os
from pathlib import Path


def user_cache_dir() -> Path:
    """granchain's per-user cache directory: ``$GRANCHAIN_CACHE`` if set, else ``granchain`` under
    ``$XDG_CACHE_HOME`` (the XDG base-directory convention; only an absolute path counts) or
    ``~/.cache``. Nothing is created here."""
    own = os.environ.get("GRANCHAIN_CACHE")
    if own:
        return Path(own)
    xdg = os.environ.get("XDG_CACHE_HOME", "")
    base = Path(xdg) if xdg and os.path.isabs(xdg) else Path.home() / ".cache"
    return base / "granchain"
