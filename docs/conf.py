"""Sphinx configuration for the granchain documentation (``docs/build`` runs it).

Sphinx rather than MkDocs: the docstrings are numpydoc, which Sphinx reads natively
(numpydoc extension); ``-W --keep-going`` turns every warning into a failure; and myst-nb
executes the tutorials (MyST Markdown notebooks, plain text in git) at build time, failing
the build on any cell error.
"""

from __future__ import annotations

import inspect
import os
import sys
from pathlib import Path

import granchain

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE.parent))

project = "granchain"
author = "granchain developers"
copyright = "granchain developers"
release = version = granchain.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "numpydoc",
    "myst_nb",
]

# --- the notebooks (tutorials/*.md with a kernelspec) are executed on every build -------------
nb_execution_mode = "force"
nb_execution_raise_on_error = True      # a failing cell fails the build
nb_execution_timeout = 180              # seconds per cell; every tutorial is meant to take < 30 s
nb_execution_show_tb = True
nb_merge_streams = True
myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence"]
os.environ.setdefault("TQDM_DISABLE", "1")

# --- API reference from the numpydoc docstrings ----------------------------------------------
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": False}
autodoc_member_order = "bysource"
autodoc_typehints = "none"              # the signatures say it; numpydoc's Parameters say the rest
numpydoc_show_class_members = False     # members are listed by autodoc, not as numpydoc tables
numpydoc_class_members_toctree = False
numpydoc_validation_checks = set()      # no style linting of the docstrings in the build
numpydoc_xref_param_type = False

exclude_patterns = ["_build", "jupyter_execute", "**.ipynb_checkpoints", "build"]
source_suffix = {".rst": "restructuredtext", ".md": "myst-nb"}
html_theme = "furo"
html_title = f"granchain {release}"
html_static_path = []
suppress_warnings = ["mystnb.unknown_mime_type"]


def _write_top_level_api() -> None:
    """docs/api/generated/granchain.rst: one entry per name of ``granchain.__all__``.

    Generated at every build from ``__all__`` so the reference can never miss a public name.
    """
    lines = [
        "The ``granchain`` namespace",
        "===========================",
        "",
        "Everything in ``granchain.__all__``, generated from the docstrings at build time.",
        "",
        ".. currentmodule:: granchain",
        "",
    ]
    from granchain.solve.integrators import AdaptiveRK

    for name in sorted(granchain.__all__, key=str.lower):
        obj = getattr(granchain, name)
        if inspect.isclass(obj):
            lines += [f".. autoclass:: {name}", "   :members:"]
            if issubclass(obj, AdaptiveRK):  # DP5, RKN4: their step control and goal-oriented constructors are the base's
                lines += ["   :inherited-members: Integrator"]
            lines += [""]
        elif callable(obj):
            lines += [f".. autofunction:: {name}", ""]
        else:
            lines += [f".. autodata:: {name}", "   :annotation:", ""]
    out = HERE / "api" / "generated" / "granchain.rst"
    out.parent.mkdir(exist_ok=True)
    text = "\n".join(lines)
    if not out.exists() or out.read_text() != text:
        out.write_text(text)


_write_top_level_api()

# --- docstring problems in modules the docs do not own, handled here (see the lead's list) ------
# Cross-references the docstrings make to names Sphinx cannot resolve. nitpicky mode (-n in
# docs/build) reports every unresolved reference; these are known and harmless:
nitpick_ignore = [
    ("py:class", "enum.IntEnum"),                     # Status's base: no intersphinx (the build runs offline)
    ("py:class", "granchain.analysis.fits._Fit"),     # private base class of the fit results (analysis/fits.py)
    ("py:class", "granchain.model.distributions._Base"),   # private base class of Uniform/Truncated (model/distributions.py)
    ("py:class", "granchain.families.decorated_families._Decorated"),  # private base of RandomDecorated/TaperedDecorated
    ("py:class", "granchain.families.radii_families._RadiiFamily"),    # private base of RandomRadii/BinaryRandom
    ("py:attr", "correlation"),                       # analysis.StretchedExpFit: backquoted attribute names
    ("py:meth", "stderr"),                            # analysis.StretchedExpFit / compare_curves: idem
]


def _escape_bars(app, what, name, obj, options, lines):
    """Absolute values written |x| in docstrings (analysis.ks_distance, ks_normal,
    compare_curves) are reStructuredText substitution references, an error for docutils.
    Escape every '|' that does not start a line (no docstring here uses line blocks or grid
    tables)."""
    for i, line in enumerate(lines):
        stripped = line.lstrip()
        if "|" in line and not stripped.startswith(("|", "+")):
            lines[i] = line.replace("\\|", "|").replace("|", "\\|")


def _resolve_in_enclosing_packages(app, env, node, contnode):
    """Resolve a short name the way a reader of the module reads it.

    A module's docstring names things by their short names: ``granchain.model.chain`` writes
    :func:`wall_stiffness` and :meth:`Chain.with_wall`, ``granchain.backends.scipy_backend`` writes
    :meth:`Backend.integrate_batch`, ``granchain.bca`` writes ``Chain``. The reference documents them
    where they are public: re-exported by an enclosing package (``granchain.wall_stiffness``,
    ``granchain.Chain.with_wall``, ``granchain.backends.Backend.integrate_batch``). Python's own
    lookup stops at the module, so retry an unresolved name in each enclosing package, innermost
    first; a name found nowhere stays unresolved and fails the build (-n)."""
    if node.get("refdomain") != "py" or node.get("refspecific"):
        return None
    target, module = node["reftarget"], node.get("py:module") or ""
    domain = env.get_domain("py")
    parts = module.split(".")
    scopes = [".".join(parts[:i]) for i in range(len(parts) - 1, 0, -1)]
    # A docstring documented under a re-exported name (``granchain.Chain.with_striker``) is read in
    # the module that wrote it (``granchain.model.chain``), where its short names live: autodoc
    # records that origin in the node's source ("...:docstring of granchain.model.chain.Chain.with_striker").
    origin = (node.source or "").rpartition("docstring of ")[2].split(".") if "docstring of " in (node.source or "") else []
    scopes += [".".join(origin[:i]) for i in range(len(origin) - 1, 0, -1)]
    for scope in dict.fromkeys(scopes):
        candidate = f"{scope}.{target}"
        if candidate in domain.objects:
            return domain.resolve_xref(env, node["refdoc"], app.builder, node["reftype"], candidate, node, contnode)
    return None


def _skip_namedtuple_fields(app, what, name, obj, skip, options):
    """The kernels' records (granchain.backends.kernels.records) are named tuples: their fields are
    named in the class signature and described in its docstring, so skip the "Alias for field number
    N" entries Python generates for each."""
    if (getattr(obj, "__doc__", None) or "").startswith("Alias for field number"):
        return True
    return None


def setup(app):
    app.connect("autodoc-process-docstring", _escape_bars, priority=400)
    app.connect("autodoc-skip-member", _skip_namedtuple_fields)
    app.connect("missing-reference", _resolve_in_enclosing_packages)
