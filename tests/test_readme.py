"""The README is a front door that works: its set-up commands are the ones CI runs, and its
quickstart (Python and shell) runs as written, from an empty directory."""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


def _blocks(lang: str, text: str = README) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", text, flags=re.S)


def _section(title: str) -> str:
    match = re.search(rf"^## {re.escape(title)}\n(.*?)(?=^## |\Z)", README, flags=re.S | re.M)
    assert match, f"README has no section '## {title}'"
    return match.group(1)


def test_readme_is_a_front_door():
    """Short, and the two set-up commands come first."""
    assert len(README.encode()) < 10_240, f"README is {len(README.encode())} bytes: move detail to docs/"
    first_two = _blocks("bash")[:2]
    assert [b.strip() for b in first_two] == ['pip install . && granchain reproduce',
                                              'pip install -e ".[test]" && python -m pytest']
    for title in ("Quickstart", "What is in it", "Documentation", "What granchain will not do", "How to cite"):
        assert f"## {title}\n" in README
    assert "Harbola" in _section("How to cite") and "shared/paper" not in README  # a reference, not a path


def test_ci_runs_the_readme_test_command():
    ci = (ROOT / ".ci" / "run").read_text()
    assert _blocks("bash")[1].strip() in ci


def test_readme_links_resolve():
    """Every relative link of the README points at a file of the repository."""
    for target in re.findall(r"\]\(([^)#]+)\)", README):
        if "://" not in target:
            assert (ROOT / target).exists(), f"README links to a missing file: {target}"


@pytest.fixture()
def empty_dir(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_python_quickstart_runs(empty_dir, capsys):
    code = _blocks("python", _section("Quickstart"))
    assert len(code) == 1 and len(code[0].strip().splitlines()) <= 12, "the quickstart is ten lines or so"
    exec(compile(code[0], "README.md quickstart", "exec"), {"__name__": "__readme__"})
    printed = capsys.readouterr().out
    assert "2.348" in printed  # the BCA slope the paper quotes
    assert (empty_dir / "N11.zarr").is_dir()


def _shell_lines() -> list[list[str]]:
    lines = []
    for raw in _blocks("bash", _section("Quickstart"))[0].splitlines():
        command = raw.split("#", 1)[0].strip()
        if command:
            lines.append(shlex.split(command))
    return lines


def test_shell_quickstart_lines_are_granchain_commands():
    lines = _shell_lines()
    assert 4 <= len(lines) <= 10 and all(argv[0] == "granchain" for argv in lines)


def test_shell_quickstart_runs(empty_dir):
    """Each line, as written, through the installed ``granchain`` entry point, in order (``info``
    reads the store that ``ensemble`` wrote)."""
    exe = shutil.which("granchain") or pytest.skip("the granchain entry point is not on PATH")
    env = dict(os.environ, TQDM_DISABLE="1")
    for argv in _shell_lines():
        proc = subprocess.run([exe, *argv[1:]], cwd=empty_dir, env=env, capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, f"{shlex.join(argv)} failed:\n{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}"
    assert (empty_dir / "quick-look" / "report.html").exists()
    assert (empty_dir / "pulse.png").stat().st_size > 10_000  # the pictures of a pulse and of the averaged one
    assert (empty_dir / "N11-pulse.png").stat().st_size > 10_000
    assert sys.executable  # (the entry point belongs to the interpreter running the tests)
