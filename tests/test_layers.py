"""granchain's layers import only what docs/explanation/architecture.md says they may.

The page ("Which way the dependencies point") states which layer may use which; :data:`RULES` holds
that table once, each row quoting the page. Every module of the package is read with ``ast`` (walking
the package, so modules added or split later are read too), with its module-level and function-level
imports (a lazy import inside a function is still a dependency: it only runs later), absolute and
relative, each resolved to the ``granchain.*`` module it names. A failure lists the offending
``module -> imported module`` pairs.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "granchain"

#: The private base modules every layer may use (``_status``: outcome codes, ``_validate``: argument
#: checks, ``_version``, ``_cache``: the per-user cache directory, ``_moved``: the deprecated aliases).
BASE = "base"
#: ``granchain/__init__.py`` (the public API re-exports every layer), ``python -m granchain`` and the
#: deprecated aliases of moved modules (``granchain.figures``, ``.validity``, ``.dephasing``).
API = "api"

#: layer -> {layer it may import: None (any of its modules) or the only modules of it it may import}.
#: A layer imports itself freely. Quoted from docs/explanation/architecture.md.
RULES: dict[str, dict[str, frozenset | None]] = {
    # "Beneath every layer sit a few private modules any layer may use: _status ..., _validate ...,
    # _version, _cache ... and _moved"
    BASE: {},
    # "units imports no other layer: the model's builders, the results' units attributes and the command
    # line all use it."
    "units": {BASE: None},
    # "model uses no other layer but granchain.units, whose materials its builders take"
    "model": {BASE: None, "units": None},
    # "solve uses the model. It reaches code only through the package granchain.backends ..., never
    # through the Numba backend, the SciPy backend or the kernels."
    "solve": {BASE: None, "units": None, "model": None, "backends": frozenset({"granchain.backends"})},
    # "backends read the model's values and the integrator's settings and capabilities. They import
    # nothing from granchain.solve"
    "backends": {BASE: None, "units": None, "model": None, "kernels": None},
    # "kernels import nothing of granchain but each other, the outcome codes (_status) and the cache
    # directory (_cache)."
    "kernels": {BASE: None},
    # "families use the model ... A family asks the BCA for the length of its default time grid, its only
    # sideways step, and a family rebuilt from a store given by its path opens it with
    # granchain.open_store (ensembles.read), the one reader that verifies a store."
    "families": {BASE: None, "units": None, "model": None, "bca": None,
                 "ensembles": frozenset({"granchain.ensembles.read"})},
    # "ensembles use families, the model and the integrator seam (granchain.solve, and of the backends
    # only the package granchain.backends)."
    "ensembles": {BASE: None, "units": None, "model": None, "families": None, "solve": None,
                  "backends": frozenset({"granchain.backends"})},
    # "granchain.analysis reads Datasets and stores, and imports from granchain only the stores' readers
    # (ensembles.read, .verify, .schema ...) and the drawing of a result (solve.plot ...), never what
    # runs the dynamics"
    "analysis": {BASE: None, "units": None,
                 "ensembles": frozenset({"granchain.ensembles.read", "granchain.ensembles.verify",
                                         "granchain.ensembles.schema"}),
                 "solve": frozenset({"granchain.solve.plot"})},
    # "granchain.bca is formulas over model chains"
    "bca": {BASE: None, "units": None, "model": None},
    # "granchain.theory runs its short chains through the same integrator seam as everything else."
    "theory": {BASE: None, "units": None, "model": None, "solve": None},
    # "design evaluates candidate chains through simulate, the families' batches and the ensembles'
    # integrators; of the backends it uses only the package granchain.backends."
    "design": {BASE: None, "units": None, "model": None, "families": None, "solve": None,
               "ensembles": None, "backends": frozenset({"granchain.backends"})},
    # "the paper uses everything below it"
    "paper": {BASE: None, "units": None, "model": None, "solve": None, "backends": frozenset({"granchain.backends"}),
              "families": None, "ensembles": None, "analysis": None, "bca": None, "theory": None, "design": None},
    # "the command line sits on top."
    "cli": {layer: None for layer in ("base", "units", "model", "solve", "families", "ensembles", "analysis", "bca",
                                      "theory", "design", "paper", API)} | {"backends": frozenset({"granchain.backends"})},
    API: {layer: None for layer in ("base", "units", "model", "solve", "families", "ensembles", "analysis", "bca",
                                    "theory", "design", "paper", "cli")} | {"backends": frozenset({"granchain.backends"})},
}

#: Known breaches, each with why it stays for now: (importing module or package, imported module or
#: package, why). Prefixes: a module split later into several is still covered.
EXCEPTIONS: list = []


def module_name(path: Path, package: Path = PACKAGE) -> str:
    parts = list(path.relative_to(package.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def layer(module: str) -> str:
    """The layer ``module`` (a granchain.* name) belongs to."""
    parts = module.split(".")
    if module == "granchain" or parts[1] in ("__main__", "figures", "validity", "dephasing"):
        return API
    if parts[1].startswith("_"):
        return BASE
    if parts[1] == "backends" and len(parts) > 2 and parts[2] == "kernels":
        return "kernels"
    return parts[1]


def imports(package: Path = PACKAGE) -> set[tuple[str, str]]:
    """{(module, granchain module it imports)}: every import statement of every module (module level,
    inside functions and classes, under ``if``/``try``), relative ones resolved; ``from p import x`` names
    the module ``p.x`` when that is a module, else ``p``."""
    files = {module_name(p, package): p for p in package.rglob("*.py")}
    found = set()
    for name, path in files.items():
        is_package = path.name == "__init__.py"
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = name.split(".") if is_package else name.split(".")[:-1]
                    base = base[: len(base) - (node.level - 1)]
                    base = ".".join(base + ([node.module] if node.module else []))
                else:
                    base = node.module or ""
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in files else base for a in node.names]
            else:
                continue
            found |= {(name, t) for t in targets if t.split(".")[0] == "granchain" and t != name}
    return found


def excepted(module: str, target: str) -> bool:
    return any((module == m or module.startswith(m + ".")) and (target == t or target.startswith(t + "."))
               for m, t, _ in EXCEPTIONS)


def breaches(pairs, rules=RULES) -> list[str]:
    """``module -> imported module`` for every import the rules do not allow."""
    out = []
    for module, target in sorted(pairs):
        src, dst = layer(module), layer(target)
        if src == dst:
            continue
        allowed = rules[src]
        if dst in allowed and (allowed[dst] is None or target in allowed[dst]):
            continue
        if not excepted(module, target):
            out.append(f"{module} -> {target}  ({src} may not use {dst}" + (
                "" if dst not in allowed else f" beyond {', '.join(sorted(allowed[dst]))}") + ")")
    return out


def test_every_layer_is_ruled():
    layers = {layer(m) for pair in imports() for m in pair}
    assert layers <= set(RULES), f"layers without a rule in RULES (add them here and on the page): {layers - set(RULES)}"


def test_imports_follow_the_layers():
    found = breaches(imports())
    assert not found, "imports that break the layer rules of docs/explanation/architecture.md:\n" + "\n".join(found)


def test_exceptions_are_still_needed():
    """An exception whose import has gone is removed here, so that the list says what remains."""
    pairs = imports()
    for m, t, why in EXCEPTIONS:
        assert any((a == m or a.startswith(m + ".")) and (b == t or b.startswith(t + ".")) for a, b in pairs), (
            f"no import {m} -> {t} is left: remove its exception ({why})")


def test_the_checker_sees_breaches():
    """Negative controls: the reader sees function-level and relative imports, and the rules catch an
    upward import, a caller reaching around the backend seam, and an import into the kernels."""
    pairs = imports()
    assert ("granchain.solve.integrators", "granchain.backends") in pairs  # `from ..backends import ...` in a function
    assert ("granchain.model.spheres", "granchain.units") in pairs  # function level
    found = breaches({("granchain.model.chain", "granchain.solve.simulation"),
                      ("granchain.solve.simulation", "granchain.backends.numba_backend"),
                      ("granchain.solve.simulation", "granchain.backends"),
                      ("granchain.backends.kernels.forces", "granchain.model.chain"),
                      ("granchain.backends.numba_backend", "granchain.solve.integrators"),
                      ("granchain.analysis", "granchain.ensembles.run")})
    assert [f.split("  ")[0] for f in found] == [
        "granchain.analysis -> granchain.ensembles.run",
        "granchain.backends.kernels.forces -> granchain.model.chain",
        "granchain.backends.numba_backend -> granchain.solve.integrators",
        "granchain.model.chain -> granchain.solve.simulation",
        "granchain.solve.simulation -> granchain.backends.numba_backend",
    ], found
