"""granchain's modules import each other without a cycle.

A cycle makes the result of an import depend on which module is imported first (a name used at
module level may not exist yet). The graph is read from the source with ``ast``: module-level
imports only; imports inside functions are deliberate lazy imports (pint, matplotlib, Numba and the
kernels) and run after every module has loaded. Which layer may import which is ``tests/test_layers.py``'s.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "granchain"


def module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def resolve(module: str, is_package: bool, level: int, target: str | None) -> str:
    base = module.split(".") if is_package else module.split(".")[:-1]
    if level > 1:
        base = base[: len(base) - (level - 1)]
    return ".".join(base + ([target] if target else []))


def import_graph(package: Path = PACKAGE) -> dict[str, set[str]]:
    """{module: modules of the package it imports at module level}."""
    files = {module_name(p): p for p in package.rglob("*.py")}
    graph = {name: set() for name in files}
    for name, path in files.items():
        is_package = path.name == "__init__.py"
        for node in ast.parse(path.read_text()).body:  # module level only, no function bodies
            nodes = [node]
            if isinstance(node, (ast.If, ast.Try)):  # `if TYPE_CHECKING:` / try-imports at module level
                nodes = [n for n in ast.walk(node) if isinstance(n, (ast.Import, ast.ImportFrom))]
            for n in nodes:
                if isinstance(n, ast.Import):
                    targets = [a.name for a in n.names]
                elif isinstance(n, ast.ImportFrom):
                    base = resolve(name, is_package, n.level, n.module) if n.level else (n.module or "")
                    # `from . import x` may name a submodule
                    targets = [base] + [f"{base}.{a.name}" for a in n.names]
                else:
                    continue
                # a module's own parent packages are already being imported when it runs: not an edge
                ancestors = {".".join(name.split(".")[:i]) for i in range(1, name.count(".") + 1)}
                graph[name] |= {t for t in targets if t in files and t != name and t not in ancestors}
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of ``graph`` as a list of nodes (first == last), or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node):
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state:
                found = visit(nxt)
                if found:
                    return found
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state:
            found = visit(node)
            if found:
                return found
    return None


def test_the_cycle_finder_finds_cycles():
    """Negative control: a known cycle (the one analysis and _pulsefits once had) is found."""
    assert find_cycle({"a": {"b"}, "b": {"a"}}) == ["a", "b", "a"]
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": set()}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b", "c"}, "b": {"c"}, "c": set()}) is None


def test_the_graph_sees_relative_imports():
    graph = import_graph()
    assert {"granchain.ensembles.store", "granchain.families", "granchain.solve.integrators"} <= graph["granchain.ensembles.run"]
    assert {"granchain.analysis", "granchain.bca"} <= graph["granchain.paper.dephasing"]  # `from .. import analysis, bca`
    assert "granchain.analysis" not in graph["granchain.analysis.pulsefits"]  # a parent package is not an edge


def test_granchain_imports_have_no_cycle():
    cycle = find_cycle(import_graph())
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


@pytest.mark.parametrize("name", ["fit_averaged_decay", "PulseFit", "paper_curve_agreement", "ChunkSums"])
def test_analysis_still_offers_the_fits(name):
    import granchain.analysis as analysis
    import granchain.analysis.pulsefits as pulsefits

    assert name in analysis.__all__ and name in dir(analysis)
    assert getattr(analysis, name) is getattr(pulsefits, name, getattr(analysis, name))
    with pytest.raises(AttributeError, match="no attribute 'no_such_fit'"):
        analysis.no_such_fit  # noqa: B018


def test_research_modules_load_on_first_use():
    """``import granchain`` does not load the statistics and the paper's research modules (a run of
    the dynamics does not pay for them); each is there as an attribute when asked for."""
    import subprocess
    import sys

    code = ("import sys, granchain as gc; lazy = gc._LAZY_MODULES; "
            "print(sorted(m for m in lazy if f'granchain.{m}' in sys.modules)); "
            "print(all(getattr(gc, m).__name__ == f'granchain.{m}' for m in lazy))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split("\n")
    assert out[0] == "[]", out
    assert out[1] == "True", out


MOVED = {"granchain.figures": "granchain.paper.figures", "granchain.validity": "granchain.paper.validity",
         "granchain.dephasing": "granchain.paper.dephasing", "granchain.figures.fig1": "granchain.paper.figures.fig1"}


@pytest.mark.parametrize("old", sorted(MOVED))
def test_moved_module_paths_warn_and_give_the_new_module(old):
    """The paper's research modules moved under ``granchain.paper`` in 0.5: the old import paths still
    work, warn once with the new path, and give the very module object of the new path (one module
    under two names, so its state and classes agree). Run in a fresh interpreter, so the warning is
    the first import's."""
    import subprocess
    import sys

    code = ("import importlib, warnings; warnings.simplefilter('always'); "
            "import sys\n"
            "with warnings.catch_warnings(record=True) as w:\n"
            f"    warnings.simplefilter('always'); old = importlib.import_module({old!r})\n"
            f"new = importlib.import_module({MOVED[old]!r})\n"
            "print(old is new, [str(x.message) for x in w if x.category is DeprecationWarning])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    same, messages = out.split(" ", 1)
    assert same == "True", out
    parent = ".".join(old.split(".")[:2])
    assert f"{parent} moved to {MOVED[parent]}" in messages, messages


@pytest.mark.parametrize("name", ["figures", "validity", "dephasing"])
def test_moved_modules_as_attributes_warn(name):
    """``granchain.validity`` as an attribute (``gc.validity.run_validity(...)``) still works and
    warns, naming the caller's line."""
    import granchain as gc

    with pytest.warns(DeprecationWarning, match=f"granchain.{name} moved to granchain.paper.{name}") as record:
        module = getattr(gc, name)
    assert module.__name__ == f"granchain.paper.{name}"
    assert any(r.filename == __file__ for r in record)


def _loaded_after(code: str) -> list[str]:
    """The Numba and kernel modules loaded in a fresh interpreter after ``code`` ran."""
    import subprocess
    import sys

    probe = (f"{code}\nimport sys\n"
             "print(sorted(m for m in sys.modules if m == 'numba' or m.startswith('numba.') "
             "or m == 'granchain.backends.kernels' or m.startswith('granchain.backends.kernels.')))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True).stdout
    return eval(out.strip().splitlines()[-1])  # a printed list of module names


def test_import_granchain_loads_neither_numba_nor_the_kernels():
    """``import granchain`` does not import Numba (about 0.3 s) nor the kernels (nor hash their sources to
    choose the per-user cache directory, which ``granchain.backends.kernels`` does when it is imported):
    they load on the first run (``simulate``, ``run_ensemble``, a design evaluation). Negative control:
    after one ``simulate`` in the same fresh interpreter both are there, so the probe does see them."""
    assert _loaded_after("import granchain") == []
    loaded = _loaded_after("import granchain\ngranchain.simulate(granchain.monodisperse(3))")
    assert "numba" in loaded and "granchain.backends.kernels" in loaded, loaded
    assert "granchain.backends.kernels.dispatch" in loaded, loaded


def test_info_slots_are_offered_by_the_backends():
    """The ``info`` record's slots are read through ``granchain.backends`` (loaded on first access)
    and are the kernels' own."""
    import granchain.backends as backends
    from granchain.backends.kernels import records

    for name in backends.INFO_SLOTS:
        assert getattr(backends, name) == getattr(records, name)
    with pytest.raises(AttributeError, match="no attribute 'INFO_NOTHING'"):
        backends.INFO_NOTHING  # noqa: B018
