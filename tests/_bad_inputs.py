"""The one way a bad input is judged, for every surface (API and command line).

Each ``tests/test_bad_inputs_<surface>.py`` lists its cases as :class:`Api` or :class:`Cli` values in a
module-level ``CASES`` list and runs them through :func:`outcome`. A case passes when its outcome is
``"refused"``: a clear error that names what to change. The other outcomes are what a sweep counts
(``python tests/_bad_inputs.py`` prints the counts per surface), and each is a defect:

- ``silent``: the input was accepted (no error), though it was listed as meaningless;
- ``raw``: it failed, but with an exception type or words that do not say what to change
  (a ``ZeroDivisionError``, SciPy's words, the CLI's "unexpected: please report it");
- ``hang``: it ran past :data:`LIMIT` seconds.

A new surface adds a file with its ``CASES``; nothing here changes.
"""

from __future__ import annotations

import contextlib
import importlib.util
import io
import re
import signal
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

#: Seconds one bad input may take before it counts as a hang (a refusal is immediate; the longest
#: legitimate refusals compile a kernel first, ~20 s on a cold cache).
LIMIT = 60


@dataclass(frozen=True)
class Api:
    """A call of the Python API that must raise ``error`` with a message matching ``words`` (a regex,
    case-insensitive). ``call`` takes the test's temporary directory (a ``pathlib.Path``)."""

    id: str
    call: Callable
    words: str
    error: type | tuple = ValueError


@dataclass(frozen=True)
class Cli:
    """A command line that must exit with ``code`` and a ``granchain CMD: error: ...`` line matching
    ``words`` (a regex, case-insensitive) on stderr, without a traceback. ``{tmp}`` in an argument is the
    test's temporary directory; ``files`` are written there first (name -> text)."""

    id: str
    argv: list
    words: str
    code: int = 2
    files: dict = field(default_factory=dict)


class _Hang(Exception):
    pass


@contextlib.contextmanager
def _time_limit(seconds: int):
    if not hasattr(signal, "SIGALRM"):  # pragma: no cover -- Windows: no limit
        yield
        return

    def stop(signum, frame):
        raise _Hang()

    old = signal.signal(signal.SIGALRM, stop)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


#: Words that mark an error as raw even when its type is right: a library's message that the user
#: cannot act on, or the command line's catch-all for unexpected exceptions.
RAW_WORDS = re.compile(r"unexpected: please report|Traceback|map-like callable|first_step must be positive"
                       r"|complex|division by zero|blosc|codec", re.I)


def outcome(case, tmp: Path) -> tuple[str, str]:
    """(``"refused"`` | ``"silent"`` | ``"raw"`` | ``"hang"``, what was seen) for one case."""
    tmp = Path(tmp)
    if isinstance(case, Api):
        try:
            with _time_limit(LIMIT):
                case.call(tmp)
        except _Hang:
            return "hang", f"still running after {LIMIT} s"
        except case.error as exc:
            text = f"{type(exc).__name__}: {exc}"
            if re.search(case.words, str(exc), re.I) and not RAW_WORDS.search(str(exc)):
                return "refused", text
            return "raw", text
        except Exception as exc:  # noqa: BLE001 -- any other exception is a raw one
            return "raw", f"{type(exc).__name__}: {exc}"
        return "silent", "accepted"
    from granchain.cli import main

    for name, text in case.files.items():
        (tmp / name).write_text(text)
    argv = [str(a).replace("{tmp}", str(tmp)) for a in case.argv]
    out, err = io.StringIO(), io.StringIO()
    try:
        with _time_limit(LIMIT), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = main(argv)
    except _Hang:
        return "hang", f"still running after {LIMIT} s"
    except SystemExit as exc:  # argparse's own refusals exit 2 with a usage line
        code = exc.code
    except Exception as exc:  # noqa: BLE001
        return "raw", f"{type(exc).__name__}: {exc}"
    stderr = err.getvalue()
    if code == 0:
        return "silent", f"exit 0; stdout: {out.getvalue()[-300:]!r}"
    if code == case.code and re.search(case.words, stderr, re.I) and not RAW_WORDS.search(stderr) \
            and "error" in stderr:
        return "refused", stderr.strip()
    return "raw", f"exit {code}: {stderr.strip()[-500:]}"


def check(case, tmp: Path) -> None:
    """Assert that ``case`` is refused clearly (pytest shows what was seen otherwise)."""
    kind, seen = outcome(case, tmp)
    assert kind == "refused", f"{case.id}: {kind}: {seen}\n(expected words: {case.words!r})"


def surfaces() -> dict:
    """{surface: CASES} of every ``tests/test_bad_inputs_<surface>.py``."""
    here = Path(__file__).parent
    found = {}
    for path in sorted(here.glob("test_bad_inputs_*.py")):
        spec = importlib.util.spec_from_file_location(path.stem, path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        found[path.stem.removeprefix("test_bad_inputs_")] = module.CASES
    return found


def main() -> int:  # pragma: no cover -- the sweep the closing notes quote
    import tempfile
    import warnings

    warnings.simplefilter("ignore")
    totals: dict = {}
    print(f"{'surface':<14} {'cases':>5} {'refused':>7} {'silent':>6} {'raw':>4} {'hang':>4}")
    for surface, cases in surfaces().items():
        counts = dict(refused=0, silent=0, raw=0, hang=0)
        for case in cases:
            with tempfile.TemporaryDirectory() as tmp:
                kind, seen = outcome(case, Path(tmp))
            counts[kind] += 1
            if kind != "refused":
                print(f"  {surface}/{case.id}: {kind}: {seen[:300]}")
        for k, v in counts.items():
            totals[k] = totals.get(k, 0) + v
        print(f"{surface:<14} {len(cases):>5} {counts['refused']:>7} {counts['silent']:>6} {counts['raw']:>4} {counts['hang']:>4}")
    print(f"{'all':<14} {sum(totals.values()):>5} {totals['refused']:>7} {totals['silent']:>6} {totals['raw']:>4} {totals['hang']:>4}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    # The case tables import this module as ``_bad_inputs``: run that one, so that isinstance() sees
    # the classes they built (run as a script, this file is a second module, ``__main__``).
    sys.path.insert(0, str(Path(__file__).parent))
    import _bad_inputs

    sys.exit(_bad_inputs.main())
