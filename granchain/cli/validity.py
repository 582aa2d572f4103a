"""``granchain validity``: where the effective chain and the BCA hold.

Runs paired decorated/effective ensembles over a grid of small-radius ranges [alpha, beta]
(uniform radii) and N, one resumable Zarr store per point under ``--out``/points, and writes the
map as netCDF (``validity.nc``), heat maps (``validity.png``/``.pdf``) and a markdown section
(``validity.md``). ``--distributions`` adds the comparison of non-uniform distributions on
[0.01, 0.4] (``distributions.nc``). Run again with the same arguments to resume.

Run times on the 2-core development machine (shared): ``--quick`` (2 x 4 grid, N = 6, 26,
100 realisations) 52 s; the default (4 x 8 grid, 62 points with alpha < beta, N = 6, 26, 400
realisations per point) 12 minutes; ``--distributions`` 75 s more.
"""

from __future__ import annotations


def _floats(text: str) -> tuple:
    try:
        return tuple(float(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise ValueError(f"expected comma-separated numbers, e.g. 0.01,0.1,0.2; got {text!r}") from None


def _ints(text: str) -> tuple:
    try:
        return tuple(int(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise ValueError(f"--large expects comma-separated integers, e.g. 6,26; got {text!r}") from None


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("validity", help="validity maps of the effective chain and the BCA", description=__doc__)
    p.add_argument("--out", required=True, help="output directory (resumed if it exists)")
    p.add_argument("--quick", action="store_true", help="a coarse map in a couple of minutes")
    p.add_argument("--realizations", type=int, default=None, help="realisations per point (default 400; quick 100)")
    p.add_argument("--alphas", type=_floats, default=None, help="comma-separated alpha values (default 0.01,0.05,0.1,0.2)")
    p.add_argument("--betas", type=_floats, default=None, help="comma-separated beta values (default 0.2,0.3,...,0.9)")
    p.add_argument("--large", type=_ints, default=None, help="comma-separated N values (default 6,26)")
    p.add_argument("--seed", type=int, default=0, help="the map's seed (default 0)")
    p.add_argument("--blocks", type=int, default=10, help="jackknife blocks = chunks per point (default 10)")
    p.add_argument("--distributions", action="store_true", help="also compare non-uniform distributions on [0.01, 0.4]")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    from ._backend import add_backend_arguments

    add_backend_arguments(p)
    p.set_defaults(func=run)


def run(args) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..paper import validity
    from ..paper.figures import save
    from ..paper.figures import validity as figure
    from ._backend import backend_of, check_usable

    check_usable(args)
    on = {"backend": backend_of(args), "switch_backend": args.switch_backend}

    base = dict(validity.QUICK) if args.quick else {"alphas": validity.DEFAULT_ALPHAS, "betas": validity.DEFAULT_BETAS,
                                                    "n_large": (6, 26), "realizations": validity.DEFAULT_REALIZATIONS}
    for key, value in (("alphas", args.alphas), ("betas", args.betas), ("n_large", args.large), ("realizations", args.realizations)):
        if value is not None:
            base[key] = value
    out = validity.output_directory(args.out, "--out", create=False)  # refused before the map starts
    if args.seed < 0:
        raise ValueError(f"--seed must be >= 0, got {args.seed}")
    ds = figure.compute(out, seed=args.seed, blocks=args.blocks, progress=not args.no_progress, **on, **base)
    fig = figure.plot(ds)
    paths = save(fig, out / "validity")
    plt.close(fig)
    dist = None
    if args.distributions:
        dist = validity.compare_distributions(out, n_large=base["n_large"], realizations=base["realizations"], seed=args.seed,
                                              blocks=args.blocks, progress=not args.no_progress, **on)
    text = validity.report_section(ds, dist)
    (out / "validity.md").write_text(text + "\n")
    print(text)
    print(f"\nwrote {out / 'validity.nc'}, {', '.join(str(p) for p in paths)}, {out / 'validity.md'}")
    return 0
