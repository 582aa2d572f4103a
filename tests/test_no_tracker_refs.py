"""Users never see the development tracker: code, help texts, reports and docs say why, not
which ticket asked for it."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: "issue 13", "issue #9", "issues 8, 10", "(issue", "item 5", "ticket 3" and the like.
TRACKER = re.compile(r"\b(?:issues?|tickets?)\s*#?\s*\d+|\bitem\s+\d+\b|\(issue\b|\bissue\s+(?:\"|')", re.I)
SKIP_PARTS = {"_build", "generated", "__pycache__", "jupyter_execute"}


def _user_facing_files():
    yield ROOT / "README.md"
    for top in ("granchain", "docs", "benchmarks"):
        for path in sorted((ROOT / top).rglob("*")):
            if path.is_file() and path.suffix in {".py", ".md", ".rst", ".txt", ".toml", ""} and not SKIP_PARTS & set(path.parts):
                yield path


def test_pattern_catches_what_it_should():
    for text in ("validity maps (issue 13)", "issue 9, item 5", "issues 8, 10-13", "see issue #4", "Ticket 2"):
        assert TRACKER.search(text), text
    for text in ("a warning is issued when", "re-issued at the caller", "the item at hand"):
        assert not TRACKER.search(text), text


def test_no_tracker_references_in_package_docs_and_readme():
    hits = []
    for path in _user_facing_files():
        try:
            text = path.read_text()
        except UnicodeDecodeError:
            continue
        for no, line in enumerate(text.splitlines(), 1):
            if TRACKER.search(line):
                hits.append(f"{path.relative_to(ROOT)}:{no}: {line.strip()[:120]}")
    assert not hits, "say why, not which ticket:\n" + "\n".join(hits)
