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
    assert {"resume", "dask", "export-netcdf", "units", "long-chains"} <= stems


def test_build_script_is_executable_and_strict():
    build = DOCS / "build"
    assert os.access(build, os.X_OK)
    text = build.read_text()
    assert re.search(r"sphinx -W --keep-going", text) and 'pip install --quiet -e ".[docs]"' in text
    assert "nb_execution_raise_on_error = True" in (DOCS / "conf.py").read_text()
