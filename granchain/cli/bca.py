"""``granchain bca``: binary collision approximation numbers (paper Sec. III B).

Prints A(n) (Eq. an), the slope S (Eq. slope), kappa and sigma of
X = R^(-1/(2n)) (Eq. dist-1) and the Gaussian prediction (mean, std) of the
arrival time at a large granule (default N-1, the paper's Fig. 4), for small
radii uniform on [alpha, beta]. ``--realizations R`` adds a Monte Carlo of the
full Eq. (total-time) over R random chains (seeded per realisation).
"""

from __future__ import annotations

import json

import numpy as np


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "bca",
        help="binary collision approximation: A(n), slope S, kappa, sigma, Gaussian arrival time",
        description=__doc__,
    )
    p.add_argument("--alpha", type=float, default=0.01, help="smallest small radius (default 0.01)")
    p.add_argument("--beta", type=float, default=0.4, help="largest small radius (default 0.4)")
    p.add_argument("--large", type=int, default=26, help="number N of large granules (default 26)")
    p.add_argument("--granule", type=int, default=None, help="large granule k to predict, 1-based (default N-1)")
    p.add_argument("--n", type=float, default=2.5, help="contact exponent, n > 2 (default 2.5, Hertz)")
    p.add_argument("--realizations", type=int, default=0, help="also run a Monte Carlo of Eq. (total-time) over R chains")
    p.add_argument("--seed", type=int, default=0, help="seed of the Monte Carlo (default 0)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=run)


def run(args) -> int:
    import math

    from .. import Uniform, bca
    from .._validate import count

    N = count("--large", args.large, minimum=2)
    k = N - 1 if args.granule is None else args.granule
    if not 1 <= k <= N:
        raise ValueError(f"--granule must be in 1..{N} (1-based large granule), got {k}")
    if args.realizations < 0:
        raise ValueError(f"--realizations must be >= 0, got {args.realizations}")
    if args.seed < 0:
        raise ValueError(f"--seed must be >= 0, got {args.seed}")
    if not (math.isfinite(args.alpha) and math.isfinite(args.beta) and 0.0 < args.alpha < args.beta <= 1.0):
        raise ValueError(f"--alpha and --beta need 0 < alpha < beta <= 1 (small radii uniform on [alpha, beta], in units "
                         f"of the large radius), got --alpha {args.alpha:g} --beta {args.beta:g}")
    if not (math.isfinite(args.n) and args.n > 2.0):
        raise ValueError(f"--n must be a finite exponent with n > 2 (the binary collision approximation needs a solitary pulse; "
                         f"Hertz: 2.5), got {args.n:g}")
    dist = Uniform(args.alpha, args.beta)
    g = bca.gaussian_limit(dist, k, args.n)
    out = {
        "alpha": dist.alpha,
        "beta": dist.beta,
        "n": g.n,
        "large": N,
        "granule": k,
        "terms": g.terms,
        "A": bca.A(g.n),
        "A_plain": bca.A_plain(g.n),
        "prefactor": g.prefactor,
        "slope": bca.slope_uniform(dist.alpha, dist.beta, g.n),
        "kappa": g.kappa,
        "sigma": g.sigma,
        "mean": g.mean,
        "std": g.std,
    }
    if args.realizations:
        mc = bca.monte_carlo_arrival_times(N, dist, args.realizations, args.seed, n=g.n)
        t = mc.at(k)
        out["monte_carlo"] = {
            "approximation": "full",
            "realizations": int(args.realizations),
            "seed": int(args.seed),
            "mean": float(np.mean(t)),
            "std": float(np.std(t, ddof=1)) if t.size > 1 else 0.0,
        }
    if args.json:
        print(json.dumps(out))
        return 0
    print(f"binary collision approximation, R ~ U[{dist.alpha:g}, {dist.beta:g}], n = {g.n:g}, N = {N}")
    print(f"  A(n)        = {out['A']:.6f}   (Eq. an, effective chain; plain chain: {out['A_plain']:.6f})")
    print(f"  S           = {out['slope']:.6f}   (Eq. slope: <t_k> ~ S (k-1))")
    print(f"  P           = {g.prefactor:.6f}   (A(n) (m/2)^(1/n) 2^(-1/2n), Eq. total-time-2)")
    print(f"  kappa       = {g.kappa:.6f}   (mean of X = R^(-1/2n), Eq. dist-1)")
    print(f"  sigma       = {g.sigma:.6f}   (std of X)")
    print(f"  t_{k} (Gaussian limit, {g.terms} terms): mean = {g.mean:.6f}, std = {g.std:.6f}")
    if args.realizations:
        mc = out["monte_carlo"]
        print(f"  t_{k} (Monte Carlo of Eq. total-time, {mc['realizations']} chains, seed {mc['seed']}): "
              f"mean = {mc['mean']:.6f}, std = {mc['std']:.6f}")
    return 0
