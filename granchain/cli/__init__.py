"""``granchain`` command line: one sub-command per job.

Each sub-command lives in its own module of this package exposing
``add_parser(subparsers)``, which registers the sub-command and sets
``func`` (a callable taking the parsed namespace and returning an exit code).
"""

from __future__ import annotations

import argparse
import importlib
import re
import sys
import warnings

SUBCOMMANDS = ("pulse", "bca", "ensemble", "reproduce", "validity", "info", "export", "plot", "theory", "design")


def build_parser() -> argparse.ArgumentParser:
    from .. import __version__

    parser = argparse.ArgumentParser(
        prog="granchain",
        description="Pulse propagation in one-dimensional granular chains (Harbola, Rosas, Romero, Lindenberg).",
    )
    parser.add_argument("--version", action="version", version=f"granchain {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in SUBCOMMANDS:
        try:
            module = importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as exc:  # a sub-command not written yet
            if exc.name != f"{__name__}.{name}":
                raise
            continue
        module.add_parser(sub)
    return parser


def _warning_to_stderr(message, category, filename, lineno, file=None, line=None):
    print(f"warning: {message}", file=sys.stderr)


#: A value that starts like a negative number ("-1m/s", "-1e-3", "-.5GPa"): argparse would read it
#: as an option (it takes only plain "-1" and "-0.5" for numbers), and fail with "expected one argument".
_NEGATIVE_VALUE = re.compile(r"^-\.?\d")


def attach_negative_values(argv: list[str]) -> list[str]:
    """``--opt -1m/s`` -> ``--opt=-1m/s``, so a negative quantity reaches the option's own check
    (which says why it is refused) instead of argparse's "expected one argument". No option name
    starts with a digit, so the joined token cannot have meant anything else."""
    out = []
    for token in argv:
        if (out and _NEGATIVE_VALUE.match(token) and out[-1].startswith("--") and "=" not in out[-1]
                and len(out[-1]) > 2):
            out[-1] = f"{out[-1]}={token}"
        else:
            out.append(token)
    return out


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(attach_negative_values(list(sys.argv[1:] if argv is None else argv)))
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    warnings.showwarning = _warning_to_stderr
    from ._compile import compile_notice

    try:
        with compile_notice(quiet=bool(getattr(args, "quiet", False))):
            return int(args.func(args) or 0)
    except ValueError as exc:
        print(f"granchain {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"granchain {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader stopped early (e.g. `| head`): not an error of the command
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # Python docs: silence the flush at exit
        return 0
    except Exception as exc:  # noqa: BLE001 -- no raw tracebacks for users; GRANCHAIN_DEBUG=1 shows them
        import os

        from ._backend import is_unavailable

        if is_unavailable(exc):  # no GPU or no numba-cuda here: the user's choice to change, not a bug
            print(f"granchain {args.command}: error: {' '.join(str(exc).split())}", file=sys.stderr)
            return 2

        if os.environ.get("GRANCHAIN_DEBUG"):
            raise
        print(f"granchain {args.command}: error: {type(exc).__name__}: {exc}\n"
              "(unexpected: please report it with the command line; GRANCHAIN_DEBUG=1 shows the details)", file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
