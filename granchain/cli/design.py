"""``granchain design``: which chain of a design space protects best (granchain.design)."""

from __future__ import annotations

import json
import os
import sys

#: The ready spaces on the command line (a user's function needs the Python API: FunctionSpace).
SPACES = ("tapered", "decorated", "binary", "random-decorated")
#: The objectives on the command line, and the far end each is judged at by default.
OBJECTIVE_ENDS = {"wall-force": "wall", "transmitted-energy": "free", "impulse-duration": "wall",
                  "transmitted-momentum": "wall", "arrival-time": "wall"}
#: The default run: small enough to finish in seconds (a quick look; raise --budget for a real design).
DEFAULT_BUDGET = 60


def _pair(text: str, flag: str) -> tuple:
    parts = text.split(",")
    try:
        lo, hi = (float(p) for p in parts)
    except ValueError:
        raise ValueError(f"{flag} expects two comma-separated numbers LOW,HIGH, got {text!r}") from None
    return lo, hi


def add_parser(subparsers) -> None:
    from ._units import add_unit_arguments

    p = subparsers.add_parser(
        "design",
        help="optimise a chain that protects: the best tapered, decorated, binary or randomly decorated chain for an objective",
        description=(
            "Search a design space for the chain that minimises the force on a wall (or maximises the duration of its impulse, "
            "or minimises the energy it transmits): SciPy's differential evolution, each generation one batch of the compiled "
            "ensemble kernel, then a local refinement and, for one or two parameters, a final local polish; the summary says how "
            "sure the result is (the search's convergence, its last improvements, the polish's change). Rescaled units of the paper's Sec. II (granule 1 has radius 1 and is "
            "struck with velocity 1); with --material, --radius and --impact-speed the summary is in newtons and seconds too. "
            "Writes OUT/result.json (for programs), OUT/summary.md, OUT/design.png and the resumable history OUT/history.zarr: "
            "run the same command again to continue an interrupted run."),
    )
    p.add_argument("--space", choices=SPACES, default="tapered", help="the design space (default: tapered)")
    p.add_argument("--objective", choices=sorted(OBJECTIVE_ENDS), default="wall-force",
                   help="what to optimise (default: wall-force, the peak force on a fixed wall of the granules' material, "
                        "contact stiffness sqrt(2 R_M)); transmitted-energy is judged at a free end, the others against that "
                        "fixed wall")
    p.add_argument("--size", type=int, default=20,
                   help="granules of a tapered or binary chain; large granules of a (random) decorated chain (default: 20)")
    p.add_argument("--budget", type=int, default=None,
                   help=f"evaluations of designs in all (default: {DEFAULT_BUDGET}, or the run's minimum if larger)")
    p.add_argument("--out", required=True, metavar="DIR", help="directory of the result and the resumable history")
    p.add_argument("--seed", type=int, default=0, help="seed of the optimiser (and of the realisations of a random space)")
    p.add_argument("--popsize", type=int, default=10, help="differential evolution's population: POPSIZE x parameters (default 10)")
    p.add_argument("--local", choices=("powell", "nelder-mead", "none"), default="powell",
                   help="local refinement of the best design with a fifth of the budget (default: powell)")
    g = p.add_argument_group("design spaces")
    g.add_argument("--q", default="0,0.15", metavar="LOW,HIGH", help="tapered: bounds of q, radii (1-q)^(k-1) (default 0,0.15)")
    g.add_argument("--profile", choices=("geometric", "linear"), default="geometric", help="tapered: the profile (default geometric)")
    g.add_argument("--small-radii", dest="small_radii", default="0.05,0.6", metavar="LOW,HIGH",
                   help="decorated: bounds of the small radii (default 0.05,0.6)")
    g.add_argument("--motif", type=int, default=2,
                   help="decorated: a periodic motif of this many small radii (0: one radius per gap; default 2)")
    g.add_argument("--species-radius", dest="species_radius", type=float, default=0.5,
                   help="binary: the radius of species b (species a, granule 1's, has radius 1; default 0.5)")
    g.add_argument("--materials", metavar="A,B", help="binary: the materials of species a and b, e.g. steel,ptfe (default: one material)")
    g.add_argument("--alpha", default="0.01,0.3", metavar="LOW,HIGH", help="random-decorated: bounds of alpha (default 0.01,0.3)")
    g.add_argument("--beta", default="0.05,0.4", metavar="LOW,HIGH", help="random-decorated: bounds of beta (default 0.05,0.4)")
    g.add_argument("--realizations", type=int, default=32, help="random-decorated: realisations per design, common to all (default 32)")
    g.add_argument("--statistic", default="mean", help="random-decorated: 'mean' or a quantile such as 0.9 (default mean)")
    c = p.add_argument_group("constraints (rescaled units)")
    c.add_argument("--max-mass", dest="max_mass", type=float, help="the granules' total mass at most this (granule 1 has mass 1)")
    c.add_argument("--max-length", dest="max_length", type=float, help="the chain's length (sum of diameters) at most this")
    c.add_argument("--min-radius", dest="min_radius", type=float, help="every radius at least this")
    c.add_argument("--max-radius", dest="max_radius", type=float,
                   help="every radius at most this (granule 1, the struck one, has radius 1)")
    c.add_argument("--free-end", dest="free_end", action="store_true",
                   help="judge transmitted-momentum or arrival-time at a free far end instead of a wall")
    p.add_argument("--no-polish", dest="polish", action="store_false",
                   help="no final local polish of a one- or two-parameter design (it costs up to 60 or 110 evaluations "
                        "beyond the budget, and can only improve the result)")
    p.add_argument("--no-figure", dest="figure", action="store_false", help="do not draw OUT/design.png")
    p.add_argument("--quiet", action="store_true", help="no progress report")
    from ._backend import add_backend_arguments

    add_backend_arguments(p)
    from ._contacts import add_damping_arguments

    add_damping_arguments(p.add_argument_group(
        "dissipative contacts", "every chain of the run, designs and reference alike, with a damping contact law (a protector "
                                "that takes energy out of the pulse; integrated with DP5). Default: the paper's elastic contacts"))
    add_unit_arguments(p)
    p.set_defaults(func=run)


def build_space(args):
    from ..design import (
        BinarySpace,
        Constraints,
        DecoratedSpace,
        RandomDecoratedSpace,
        TaperedSpace,
    )

    wall = OBJECTIVE_ENDS[args.objective] == "wall" and not args.free_end
    if args.free_end and args.objective in ("wall-force", "impulse-duration"):
        raise ValueError(f"--objective {args.objective} is judged at a wall: drop --free-end")
    constraints = Constraints(args.max_mass, args.max_length, args.min_radius, args.max_radius)
    if args.space != "binary" and args.materials:
        raise ValueError("--materials is for --space binary (species of two materials)")
    if args.space == "tapered":
        return TaperedSpace(args.size, _pair(args.q, "--q"), profile=args.profile, wall=wall, constraints=constraints)
    if args.space == "decorated":
        return DecoratedSpace(args.size, _pair(args.small_radii, "--small-radii"), motif=args.motif or None, wall=wall,
                              constraints=constraints)
    if args.space == "binary":
        materials = None if not args.materials else tuple(m.strip() for m in args.materials.split(","))
        return BinarySpace(args.size, (1.0, args.species_radius), materials=materials, wall=wall, constraints=constraints)
    return RandomDecoratedSpace(args.size, _pair(args.alpha, "--alpha"), _pair(args.beta, "--beta"),
                                realizations=args.realizations, seed=args.seed, wall=wall, constraints=constraints)


def _statistic(text: str):
    if text == "mean":
        return text
    try:
        return float(text)
    except ValueError:
        raise ValueError(f"--statistic must be 'mean' or a quantile in (0, 1) such as 0.9, got {text!r}") from None


def run(args) -> int:
    from ..design import minimum_budget, optimize
    from ..design.preflight import output_directory
    from ._backend import backend_of, check_usable
    from ._units import scale_from_args

    check_usable(args)
    out = output_directory(args.out, "--out")  # checked before any work: a run's result must have somewhere to go
    units = scale_from_args(args, n=2.5)  # checked before any integration
    from ._contacts import model_from_args

    contact = model_from_args(args, units, 2.5).contact
    space = build_space(args)
    local = None if args.local == "none" else args.local
    budget = args.budget if args.budget is not None else max(DEFAULT_BUDGET, minimum_budget(space, args.popsize, local))
    try:
        result = optimize(space, args.objective, budget=budget, seed=args.seed, popsize=args.popsize, local=local,
                          statistic=_statistic(args.statistic), out=out, progress=not args.quiet, polish=args.polish,
                          backend=backend_of(args), switch_backend=args.switch_backend, contact=contact)
    except KeyboardInterrupt:
        print(f"granchain design: interrupted; the evaluations so far are saved in {args.out}. Run the same command again to "
              "continue.", file=sys.stderr)
        return 130
    record = result.to_dict()
    if units is not None:
        from ..units import SI_UNITS

        kind = result.objective.kind
        record["physical"] = {"scale": units.as_dict()}
        if kind != "1":
            record["physical"].update({"unit": SI_UNITS[kind], "best_value": float(units.to_si(result.value, kind)),
                                       "reference_value": float(units.to_si(result.reference_value, kind))})
            if space.random:
                record["physical"]["best_stderr"] = float(units.to_si(result.stderr, kind))
    with open(os.path.join(out, "result.json"), "w") as fh:
        json.dump(record, fh, indent=2)
    summary = result.summary(units)
    if args.figure:
        fig = result.plot(scale=units)
        fig.savefig(os.path.join(out, "design.png"), dpi=110)
        import matplotlib.pyplot as plt

        plt.close(fig)
        summary += f"\n![convergence and wall force]({'design.png'})\n"
    with open(os.path.join(out, "summary.md"), "w") as fh:
        fh.write(summary)
    print(summary, end="")
    return 0
