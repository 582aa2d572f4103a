"""``granchain ensemble``: many random decorated chains into a resumable Zarr store."""

from __future__ import annotations

import sys


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "ensemble",
        help="integrate many random decorated chains (and/or their effective chains) into a Zarr store",
        description=(
            "Draw the small radii of each realisation uniformly on [alpha, beta] (realisation i from "
            "SeedSequence(seed, spawn_key=(i,))), integrate the decorated chain and/or its effective chain, and "
            "write per-realisation peaks and the averaged pulse to a Zarr store that xarray.open_dataset reads. "
            "Finished chunks are saved as they complete; run again with --resume to continue an interrupted run."
        ),
    )
    p.add_argument("--large", type=int, default=26, help="N, large granules per chain (default 26)")
    p.add_argument("--realizations", type=int, default=1000, help="number of random chains (default 1000)")
    p.add_argument("--alpha", type=float, default=0.01, help="smallest small radius (default 0.01)")
    p.add_argument("--beta", type=float, default=0.4, help="largest small radius (default 0.4)")
    p.add_argument("--seed", type=int, default=0, help="seed of the random radii (default 0)")
    p.add_argument("--chain", choices=("decorated", "effective", "both"), default="both", help="which chains to integrate (default both, paired)")
    p.add_argument("--n", type=float, default=2.5, help="contact exponent (default 2.5, Hertz)")
    p.add_argument("--rtol", type=float, default=None, help="DP5 relative tolerance (default 1e-6)")
    p.add_argument("--atol", type=float, default=None, help="DP5 absolute tolerance (default 1e-9)")
    p.add_argument("--chunk-size", type=int, default=500, help="realisations per chunk, the unit of saving (default 500)")
    p.add_argument("--t-end", type=float, default=None, help="end of the time grid of the averaged pulse (default: past the pulse's exit)")
    p.add_argument("--dt", type=float, default=0.1, help="spacing of the time grid (default 0.1)")
    p.add_argument("--out", required=True, help="Zarr store to write, e.g. runs/N26.zarr")
    p.add_argument("--resume", action="store_true", help="continue an existing store written with the same arguments")
    p.add_argument("--scheduler", default=None, help="address of a Dask scheduler (e.g. tcp://10.0.0.5:8786) to run the chunks on")
    p.add_argument("--threads", type=int, default=None, help="Numba threads for a local run (default: all cores)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args) -> int:
    import numpy as np

    from .._ensemble import ENSEMBLE_ATOL, ENSEMBLE_RTOL, default_time_grid, run_ensemble
    from .._distributions import Uniform

    grid = default_time_grid(args.large, args.dt)
    if args.t_end is not None:
        if not args.t_end > 0:
            raise ValueError(f"--t-end must be > 0, got {args.t_end}")
        grid = np.round(np.arange(0.0, args.t_end + 0.5 * args.dt, args.dt), 12)
    client = None
    if args.scheduler:
        from distributed import Client

        client = Client(args.scheduler)
    try:
        ds = run_ensemble(
            args.large, Uniform(args.alpha, args.beta), args.realizations, args.seed, args.chain, n=args.n,
            rtol=ENSEMBLE_RTOL if args.rtol is None else args.rtol, atol=ENSEMBLE_ATOL if args.atol is None else args.atol,
            t_grid=grid, chunk_size=args.chunk_size, out=args.out, resume=args.resume, client=client,
            progress=not args.quiet, threads=args.threads,
        )
    except KeyboardInterrupt:
        print(f"granchain ensemble: interrupted; finished chunks are saved in {args.out}. "
              "Run the same command with --resume to continue.", file=sys.stderr)
        return 130
    finally:
        if client is not None:
            client.close()
    failed = int((ds["status"] != 0).sum())
    print(f"wrote {args.out}: {ds.sizes['realization']} realisations x {ds.sizes['chain']} chains "
          f"({', '.join(ds['chain'].values)}), N = {ds.sizes['granule']}; failed integrations: {failed}")
    return 0
