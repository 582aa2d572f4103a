"""Cheap checks of the documentation sources (the full build is ``docs/build``, run by CI)."""

from __future__ import annotations

import os
import re
from pathlib import Path

DOCS = Path(__file__).resolve().parent.parent / "docs"


def test_every_page_is_in_the_toctree():
    """Tutorials, how-to guides and explanation pages are all reachable from the landing page."""
    index = (DOCS / "index.md").read_text()
    for part in ("tutorials", "howto", "explanation"):
        pages = sorted((DOCS / part).glob("*.md"))
        assert pages, f"docs/{part} is empty"
        for md in pages:
            assert f"{part}/{md.stem}" in index, f"{part}/{md.name} is not in docs/index.md's toctree"


def test_every_tutorial_is_executed():
    for md in sorted((DOCS / "tutorials").glob("*.md")):
        head = md.read_text().split("---")[1]
        assert "file_format: mystnb" in head and "kernelspec" in head, f"{md.name} would not be executed"


def test_how_to_guides_cover_the_common_tasks():
    stems = {md.stem for md in (DOCS / "howto").glob("*.md")}
    assert {"resume", "dask", "export-netcdf", "units", "long-chains", "gpu"} <= stems


def test_build_script_is_executable_and_strict():
    build = DOCS / "build"
    assert os.access(build, os.X_OK)
    text = build.read_text()
    assert re.search(r"sphinx -W --keep-going", text) and 'pip install --quiet -e ".[docs]"' in text
    assert "nb_execution_raise_on_error = True" in (DOCS / "conf.py").read_text()


def test_gpu_guide_commands_are_the_command_lines_own():
    """The GPU how-to is not executed (the documentation is built without a GPU): each of its ``granchain``
    lines must parse with the command line's parser as written (an option renamed or dropped fails here), each
    Python block must compile, and the backend it names must be one ``run_ensemble`` accepts."""
    import ast
    import shlex

    import pytest

    from granchain.cli import build_parser
    from granchain.ensembles.backend import choices

    text = (DOCS / "howto" / "gpu.md").read_text()
    lines = [shlex.split(line.split("#")[0]) for block in re.findall(r"```bash\n(.*?)```", text, flags=re.S)
             for line in block.splitlines() if line.startswith("granchain ")]
    assert len(lines) >= 4 and any("--switch-backend" in argv for argv in lines)
    parser = build_parser()
    for argv in lines:
        try:
            parser.parse_args(argv[1:])
        except SystemExit:
            pytest.fail(f"docs/howto/gpu.md: `{shlex.join(argv)}` does not parse")
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert len(blocks) >= 2
    for code in blocks:
        ast.parse(code)
    named = set(re.findall(r'backend="([^"]*)"', "".join(blocks)))
    assert "cuda" in named and named <= set(choices()), named
    # the negative control: a misspelt option is caught
    with pytest.raises(SystemExit):
        parser.parse_args(["ensemble", "--backends", "cuda", "--out", "x.zarr"])
