"""``granchain ensemble``: many random chains of one family into a resumable Zarr store."""

from __future__ import annotations

import argparse
import json
import sys

FAMILY_HELP = {
    "decorated": "the paper's chain: N large granules (R = 1), small radii U[alpha, beta] between them "
                 "(--large, --alpha, --beta; --chain decorated/effective/both)",
    "tapered-decorated": "large radii (1 - q)^(k-1), small radius = U[alpha, beta] x its smaller neighbour "
                         "(--large, --q, --alpha, --beta; --chain decorated/effective/both)",
    "polydisperse": "every radius i.i.d. U[alpha, beta], all granules observed (--size, --alpha, --beta)",
    "binary": "two species in random order, species b with probability p (--size, --radii RA,RB, --p)",
}
#: Default radius interval per family: small radii (decorated) or all radii (polydisperse).
DEFAULT_INTERVAL = {"decorated": (0.01, 0.4), "tapered-decorated": (0.01, 0.4), "polydisperse": (0.5, 1.0)}


def add_parser(subparsers) -> None:
    from ..solve.integrators import INTEGRATORS
    from .pulse import taking

    families = "\n".join(f"  {name:<18} {text}" for name, text in FAMILY_HELP.items())
    integrators = "\n".join(f"  {name:<18} {(cls.__doc__ or '').strip().splitlines()[0]}" for name, cls in INTEGRATORS.items())
    p = subparsers.add_parser(
        "ensemble",
        help="integrate many random chains of one family (default: the paper's random decorated chain) into a Zarr store",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=(
            "Draw the random parameters of each realisation (realisation i from SeedSequence(seed, spawn_key=(i,))),\n"
            "integrate its chains and write per-realisation peaks and the averaged pulse to a Zarr store that\n"
            "xarray.open_dataset(path, engine='zarr') reads. Finished chunks are saved as they complete; run the\n"
            "same command again with --resume to continue an interrupted run.\n\n"
            f"families (--family):\n{families}\n\nintegrators (--integrator):\n{integrators}"
        ),
    )
    fam = p.add_argument_group("chain family")
    fam.add_argument("--family", choices=tuple(FAMILY_HELP), default="decorated", help="the family of random chains (default decorated)")
    fam.add_argument("--large", type=int, default=26, help="decorated families: N, large granules per chain (default 26)")
    fam.add_argument("--size", type=int, default=26, help="polydisperse, binary: granules per chain (default 26)")
    fam.add_argument("--alpha", type=float, default=None, help="smallest radius of the uniform distribution (default 0.01; polydisperse 0.5)")
    fam.add_argument("--beta", type=float, default=None, help="largest radius of the uniform distribution (default 0.4; polydisperse 1.0)")
    fam.add_argument("--q", type=float, default=0.05, help="tapered-decorated: fraction by which each large radius shrinks, radii (1 - q)^(k-1) as in granchain.tapered "
                          "(default 0.05; 0 untapered, < 0 growing; before 0.5 this option was the ratio 1 - q)")
    fam.add_argument("--radii", default="1,0.5", metavar="RA,RB", help="binary: radii of species a and b (default 1,0.5)")
    fam.add_argument("--p", type=float, default=0.5, help="binary: probability of species b (default 0.5)")
    fam.add_argument("--n", type=float, default=2.5, help="contact exponent (default 2.5, Hertz)")
    fam.add_argument("--momentum-conserving", action="store_true",
                     help="decorated families: the effective chain starts with m_1/mu_1 instead of velocity 1")
    fam.add_argument("--wall", action="store_true",
                     help="end every chain in a fixed wall (a granule of infinite radius and mass): stores the wall's "
                          "peak force and its time per realisation (peak_wall_force, peak_wall_force_time)")
    p.add_argument("--chain", default="both", help="which chains: decorated, effective or both (decorated families; default both)")
    p.add_argument("--realizations", type=int, default=1000, help="number of random chains (default 1000)")
    p.add_argument("--seed", type=int, default=0, help="seed of the random parameters (default 0)")
    integ = p.add_argument_group("integrator")
    integ.add_argument("--integrator", choices=sorted(INTEGRATORS), default=None,
                       help="integrator (default: rkn4 for decorated chains, dp5 for the others)")
    integ.add_argument("--rtol", type=float, default=None,
                       help="relative tolerance, for every chain kind (defaults: decorated chains rkn4 3e-6, dp5 1e-6; "
                            "effective 1e-8; the others 2e-9, without the relaxed zone; dop853)")
    integ.add_argument("--atol", type=float, default=None,
                       help="absolute tolerance (defaults: decorated chains rkn4 3e-9, dp5 1e-9; effective 1e-11; the others "
                            "2e-12; dop853)")
    integ.add_argument("--error-control", choices=("windowed", "relaxed", "exact"), default=None,
                       help=f"{' and '.join(taking('relaxed_lag'))} only. Default: windowed for decorated and effective "
                            "chains, exact for the other kinds (their granules can peak after the pulse has passed). "
                            "windowed: looser tolerance for the granules the pulse has passed, and drop them from the "
                            "integration a few granules behind it (cost linear in N); each granule's averaged pulse is "
                            "kept in a window that holds the pulse of every realisation (see --pulse-window); "
                            "relaxed: the looser tolerance only, every granule integrated to the end (the wake long "
                            "after the pulse on the whole time grid); exact: every granule to the end at full tolerance "
                            "(--integrator dp5 --rtol 1e-6 --atol 1e-9: granchain < 0.3)")
    integ.add_argument("--pulse-window", choices=("auto", "full"), default=None,
                       help="with the trailing window (windowed): auto (default; a store is continued with the setting it "
                            "was started with) records each granule's averaged pulse in a "
                            "window of its own, set from the arrival times of the first 64 realisations, and NaN after it; "
                            "full: no such window, granules behind the trailing window report the velocity they left it "
                            "with (stores written with --error-control windowed before granchain 0.5). Without a trailing "
                            "window every granule is recorded on the whole grid")
    integ.add_argument("--step", type=float, default=None, help=f"time step ({', '.join(taking('dt'))}; default 1e-3)")
    p.add_argument("--chunk-size", type=int, default=None,
                   help="realisations per chunk, the unit of saving (default: a store's own; else the backend's, 500 on "
                        "the cpu, 30000 on cuda: the paper's ensemble in one launch)")
    p.add_argument("--t-end", type=float, default=None, help="end of the time grid of the averaged pulse (default: past the pulse's exit)")
    p.add_argument("--dt", type=float, default=0.1, help="spacing of the time grid of the averaged pulse (default 0.1)")
    p.add_argument("--out", required=True, help="Zarr store to write, e.g. runs/N26.zarr")
    p.add_argument("--resume", action=argparse.BooleanOptionalAction, default=True,
                   help="continue an existing store written with the same arguments (the default, as in the API: "
                        "finished chunks are verified, damaged ones recomputed, a larger --realizations extends it); "
                        "--no-resume refuses an existing store")
    p.add_argument("--scheduler", default=None, help="address of a Dask scheduler (e.g. tcp://10.0.0.5:8786) to run the chunks on")
    p.add_argument("--threads", type=int, default=None, help="Numba threads for a local run on the cpu (default: all cores)")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors and warnings (no progress, no summary; failed integrations are reported on stderr)")
    from ._backend import add_backend_arguments
    from ._contacts import add_contact_arguments
    from ._units import add_unit_arguments

    add_backend_arguments(p)
    add_contact_arguments(p)
    add_unit_arguments(p)
    p.set_defaults(func=run)


def check_arguments(args) -> None:
    """Refuse numbers that can never work, naming the option (before anything is computed)."""
    import math

    for flag, value, lo in (("--dt", args.dt, 0.0), ("--t-end", args.t_end, 0.0), ("--step", args.step, 0.0),
                            ("--rtol", args.rtol, 0.0), ("--atol", args.atol, 0.0)):
        if value is not None and not (math.isfinite(value) and value > lo):
            raise ValueError(f"{flag} must be a finite number > {lo:g}, got {value}")
    for flag, value, lo in (("--realizations", args.realizations, 1), ("--chunk-size", args.chunk_size, 1),
                            ("--seed", args.seed, 0), ("--threads", args.threads, 1), ("--large", args.large, 1),
                            ("--size", args.size, 1)):
        if value is not None and value < lo:
            raise ValueError(f"{flag} must be >= {lo}, got {value}")
    if not args.out.strip():
        raise ValueError("--out must be a path such as runs/N26.zarr, got an empty string")


def connect(address):
    """A Dask client for ``--scheduler`` (None without it), or a clear error if it cannot be reached."""
    if not address:
        return None
    from distributed import Client

    try:
        return Client(address, timeout="10s")
    except (OSError, TimeoutError, ValueError, TypeError) as exc:
        raise ValueError(f"--scheduler {address}: cannot connect ({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}); "
                         "check the address (e.g. tcp://10.0.0.5:8786) and that the scheduler runs, "
                         "or leave --scheduler out to run locally") from None


def _pair(text: str) -> tuple:
    try:
        values = tuple(float(s) for s in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 2:
        raise ValueError(f"--radii needs two comma-separated radii RA,RB, got {text!r}")
    return values


def build_family(args, units=None):
    """The chain family the arguments describe (``units``: the physical scale, for real-contact options
    given with units)."""
    from ..families import BinaryRandom, RandomDecorated, RandomRadii, TaperedDecorated
    from ..model.distributions import Uniform
    from ._contacts import model_from_args, wall_material_from_args

    model = model_from_args(args, units, args.n)  # the chains' physics, --wall included
    if wall_material_from_args(args) is not None:
        raise ValueError("--wall-material applies to granchain pulse; an ensemble's wall is of the granules' own material")
    lo, hi = DEFAULT_INTERVAL.get(args.family, (None, None))
    if args.family == "binary":
        if args.alpha is not None or args.beta is not None:
            raise ValueError("--alpha/--beta do not apply to --family binary (it takes --radii RA,RB and --p)")
        return BinaryRandom(args.size, _pair(args.radii), args.p, n=args.n, model=model)
    dist = Uniform(lo if args.alpha is None else args.alpha, hi if args.beta is None else args.beta)
    if args.family == "polydisperse":
        return RandomRadii(args.size, dist, n=args.n, model=model)
    if args.family == "tapered-decorated":
        return TaperedDecorated(args.large, q=args.q, distribution=dist, n=args.n, momentum_conserving=args.momentum_conserving,
                                model=model)
    return RandomDecorated(args.large, dist, n=args.n, momentum_conserving=args.momentum_conserving, model=model)


def build_integrator(args, family, chains):
    """The integrator the arguments name, with its settings. Without --integrator (or with dp5 or rkn4)
    and without --rtol/--atol: a {chain kind: integrator} dict of each kind's default, which the
    family names by the chain's character (``granchain.ensembles.run.family_integrator``: rkn4 for
    decorated chains, dp5 for the others), or of the named method at that kind's settings, with the
    --error-control settings. --rtol/--atol without --integrator set DP5's (as ``run_ensemble(rtol=...)``)."""
    import dataclasses

    from ..ensembles.run import family_integrator
    from ..solve.integrators import DP5, INTEGRATORS, RELAXED_LAG, WINDOW_LAG

    cls = None if args.integrator is None else INTEGRATORS[args.integrator]
    given = {"rtol": args.rtol, "atol": args.atol, "dt": args.step}
    fields = {f.name for f in dataclasses.fields(cls or DP5)}
    wrong = [f"--{'step' if k == 'dt' else k}" for k, v in given.items() if v is not None and k not in fields]
    adaptive = cls is None or cls.supports_goal_control  # DP5 and RKN4: the goal-oriented settings
    if args.error_control is not None and not adaptive:
        wrong.append("--error-control")
    if wrong:
        named = args.integrator or "rkn4/dp5 (the default)"
        raise ValueError(f"{', '.join(wrong)} does not apply to --integrator {named}")
    if not adaptive:
        return cls(**{k: v for k, v in given.items() if v is not None})
    windowed = args.pulse_window != "full"  # the defaults' trailing window, unless the whole grid is asked
    # The zones asked for (relaxed zone and trailing window); without --error-control each kind's default.
    zones = {None: None, "relaxed": {"relaxed_lag": RELAXED_LAG, "window_lag": None},
             "windowed": {"relaxed_lag": RELAXED_LAG, "window_lag": WINDOW_LAG},
             "exact": {"relaxed_lag": None, "window_lag": None}}[args.error_control]

    def with_zones(base):
        # A kind whose default has no relaxed zone (reflecting chains: their granules can peak after the
        # pulse has passed) keeps it without with "relaxed" too.
        if zones is None or (args.error_control == "relaxed" and not base.relaxed_lag):
            return base
        return dataclasses.replace(base, **zones)

    if args.rtol is None and args.atol is None:  # each kind's default, or the named method at its settings
        return {c: with_zones(family_integrator(family, c, windowed=windowed, method=cls)) for c in chains}
    cls = cls or DP5  # --rtol/--atol alone set DP5's, as run_ensemble(rtol=..., atol=...) does
    base = cls.windowed() if windowed else cls.relaxed()  # as run_ensemble(rtol=..., pulse_window=...)
    return dataclasses.replace(base, **{k: v for k, v in given.items() if v is not None}, **(zones or {}))


def _store_scale(path, scale) -> None:
    """Record the physical scale in the store's attributes (``physical_*``, as
    granchain.units.dataset_to_physical names them); the rescaled data are unchanged."""
    import zarr

    group = zarr.open_group(path, mode="r+")
    group.attrs.update({f"physical_{k}": v for k, v in scale.as_dict().items()})
    zarr.consolidate_metadata(path)


def _physical_summary(ds, scale) -> str:
    """Mean (over successful realisations) of the largest contact force and of the wall's peak force, in N."""
    ok = ds["status"] == 0
    parts = []
    for chain in ds["chain"].values:
        sel = ds.sel(chain=chain).where(ok.sel(chain=chain))
        text = f"{chain}: largest contact force {float(sel['peak_force'].max('contact').mean()) * scale.force:.6g} N"
        if "peak_wall_force" in ds:
            text += (f", peak wall force {float(sel['peak_wall_force'].mean()) * scale.force:.6g} N"
                     f" at {float(sel['peak_wall_force_time'].mean()) * scale.time:.4g} s")
        parts.append(text + " (means over realisations)")
    return "physical units (" + str(scale).split(":")[0] + "): " + "; ".join(parts)


def run(args) -> int:
    import numpy as np

    from ..ensembles.run import run_ensemble
    from ._backend import backend_of, check_usable
    from ._units import scale_from_args

    check_arguments(args)
    check_usable(args)
    units = scale_from_args(args)  # None without unit options; checked before integrating
    family = build_family(args, units)
    grid = family.default_time_grid(args.dt)
    if args.t_end is not None:
        if not args.t_end > 0:
            raise ValueError(f"--t-end must be > 0, got {args.t_end}")
        grid = np.round(np.arange(0.0, args.t_end + 0.5 * args.dt, args.dt), 12)
    if args.pulse_window is None:  # a store is continued as it was started (without windows before granchain 0.5)
        from ..ensembles.pulse_window import stored_setting

        args.pulse_window = stored_setting(args.out) if args.resume else "auto"
    chains = tuple(c.strip() for c in args.chain.split(","))
    if chains == ("both",) or len(family.chains) == 1 and args.chain == "both":
        chains = "both"
    integrator = None
    if args.resume and args.out and all(getattr(args, k) is None for k in ("integrator", "rtol", "atol", "step", "error_control")):
        from ..ensembles.run import stored_integrators

        integrator = stored_integrators(args.out)  # a store is continued with the integrators it was started with
    if integrator is None:
        integrator = build_integrator(args, family, family.chains if chains == "both" else chains)
    client = connect(args.scheduler)
    try:
        ds = run_ensemble(
            family, realizations=args.realizations, seed=args.seed, chains=chains, integrator=integrator, t_grid=grid,
            chunk_size=args.chunk_size, out=args.out, resume=args.resume, client=client, progress=not args.quiet,
            threads=args.threads, pulse_window=args.pulse_window, backend=backend_of(args),
            switch_backend=args.switch_backend,
        )
    except KeyboardInterrupt:
        print(f"granchain ensemble: interrupted; finished chunks are saved in {args.out}. "
              "Run the same command again (--resume is the default) to continue.", file=sys.stderr)
        return 130
    finally:
        if client is not None:
            client.close()
    failed = int((ds["status"] != 0).sum())
    if units is not None:
        _store_scale(args.out, units)
    if args.quiet:
        if failed:
            print(f"granchain ensemble: warning: {failed} integrations did not succeed (see status in {args.out})", file=sys.stderr)
        return 0
    print(f"wrote {args.out}: {family.label()}; {ds.sizes['realization']} realisations x {ds.sizes['chain']} chains "
          f"({', '.join(ds['chain'].values)}), {ds.sizes['granule']} observed granules, integrator "
          f"{json.loads(ds.attrs['granchain_integrator'])['name']}; failed integrations: {failed}")
    if units is not None:
        print(_physical_summary(ds, units))
        print("the store's attributes physical_* hold the scale; granchain.units.dataset_to_physical(ds, scale) adds SI variables")
    return 0
