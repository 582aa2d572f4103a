"""``granchain reproduce``: the paper's experiment with one command."""

from __future__ import annotations


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "reproduce",
        help="run the paper's experiment: ensembles, Figures 1-4, data and a report",
        description=(
            "Run 30,000 realisations (default) of random decorated chains and their effective chains for "
            "N = 6, 11, 16, 26 (small radii uniform on [0.01, 0.4], n = 5/2), make Figures 1-4 (PNG, PDF), "
            "write their data (netCDF) and report.md / report.html comparing every number the paper reports. "
            "Ensembles already in --out are reused and resumed."
        ),
    )
    p.add_argument("--realizations", type=int, default=30_000, help="realisations per chain length (default 30000, the paper's)")
    p.add_argument("--out", default="granchain-results", help="output directory (default granchain-results)")
    p.add_argument("--quick", action="store_true", help="a small run (600 realisations) for a first look in about a minute")
    p.add_argument("--seed", type=int, default=2026, help="base seed (chain length N uses 1000*seed + N)")
    p.add_argument("--scheduler", default=None, help="address of a Dask scheduler to run the ensembles on")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    from ._backend import add_backend_arguments

    add_backend_arguments(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from ..paper.reproduce import MIN_REALIZATIONS, reproduce
    from ..paper.validity import output_directory
    from ._backend import backend_of, check_usable
    from .ensemble import connect

    check_usable(args)

    if args.realizations < MIN_REALIZATIONS:
        raise ValueError(f"--realizations must be >= {MIN_REALIZATIONS} for the report's statistics, got {args.realizations} "
                         "(use --quick for a small first run)")
    if args.seed < 0:
        raise ValueError(f"--seed must be >= 0, got {args.seed}")
    output_directory(args.out, "--out")
    client = connect(args.scheduler)
    try:
        reproduce(args.out, args.realizations, quick=args.quick, seed=args.seed, client=client, progress=not args.quiet,
                  backend=backend_of(args), switch_backend=args.switch_backend)
    finally:
        if client is not None:
            client.close()
    return 0
