"""Module paths that moved in 0.5, kept working with a :class:`DeprecationWarning`.

The paper's research modules moved under :mod:`granchain.paper` so that the package's layout shows
what is library (model, solving, backends, ensembles, statistics, families) and what is the paper's
own reproduction. An old path imports the new module itself (one module object under both names, so
``isinstance`` checks and module state agree) and warns once, when first imported.
"""

from __future__ import annotations

import importlib
import sys
import warnings

#: Old module path -> new module path.
MOVED = {
    "granchain.figures": "granchain.paper.figures",
    "granchain.validity": "granchain.paper.validity",
    "granchain.dephasing": "granchain.paper.dephasing",
}


def alias(old: str, submodules: tuple = ()) -> None:
    """Make ``old`` (a module being imported) the module it moved to, with a DeprecationWarning that
    names the new path. ``submodules`` are aliased too (``granchain.figures.fig1``), so that
    importing them by the old path gives the same module objects."""
    new = MOVED[old]
    warnings.warn(f"{old} moved to {new} in granchain 0.5; import it from there (the old path will be removed)",
                  DeprecationWarning, stacklevel=3)
    module = importlib.import_module(new)
    sys.modules[old] = module  # the import statement that loaded the shim returns this module
    for name in submodules:
        sys.modules[f"{old}.{name}"] = importlib.import_module(f"{new}.{name}")
