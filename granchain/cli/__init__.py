"""``granchain`` command line: one sub-command per job.

Each sub-command lives in its own module of this package exposing
``add_parser(subparsers)``, which registers the sub-command and sets
``func`` (a callable taking the parsed namespace and returning an exit code).
"""

from __future__ import annotations

import argparse
import importlib
import sys
import warnings

SUBCOMMANDS = ("pulse", "bca", "ensemble", "reproduce", "validity", "info", "export", "theory")


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


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    warnings.showwarning = _warning_to_stderr
    try:
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

        if os.environ.get("GRANCHAIN_DEBUG"):
            raise
        print(f"granchain {args.command}: error: {type(exc).__name__}: {exc}\n"
              "(unexpected: please report it with the command line; GRANCHAIN_DEBUG=1 shows the details)", file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
