"""Cheap checks of the documentation sources (the full build is ``docs/build``, run by CI)."""

from __future__ import annotations

import os
import re
from pathlib import Path

DOCS = Path(__file__).resolve().parent.parent / "docs"


def test_every_tutorial_is_in_the_toctree_and_executed():
    index = (DOCS / "index.md").read_text()
    for md in sorted((DOCS / "tutorials").glob("*.md")):
        assert f"tutorials/{md.stem}" in index, f"{md.name} is not in docs/index.md's toctree"
        head = md.read_text().split("---")[1]
        assert "file_format: mystnb" in head and "kernelspec" in head, f"{md.name} would not be executed"
    assert "tutorials/families" in index  # a chain family of your own (issue 12 asks for it)


def test_build_script_is_executable_and_strict():
    build = DOCS / "build"
    assert os.access(build, os.X_OK)
    text = build.read_text()
    assert re.search(r"sphinx -W --keep-going", text) and 'pip install --quiet -e ".[docs]"' in text
    assert "nb_execution_raise_on_error = True" in (DOCS / "conf.py").read_text()
