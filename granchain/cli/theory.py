"""``granchain theory``: predict the pulse along a random decorated chain from the radius law alone.

Prints, per large granule k, the theory's mean single-realisation peak <max_t v_k>, the peak of
the averaged pulse max_t <v_k(t)>, and the mean and spread of the arrival (peak) time, for small
radii uniform on [alpha, beta] (``granchain.theory.predict``: a windowed transfer map of the
effective chain, tabulated from short chains and composed as a Markov chain; no ensemble of the
chain is run). The first run for a law tabulates ~4x10^4 short chains (about 10-40 s on one
core) and caches them; later runs take a few seconds. ``--compare STORE`` adds the measured
values of a ``granchain ensemble`` store (decorated chain) and the relative errors. ``--out DIR``
writes theory.nc, theory.md and theory.png/.pdf there.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("theory", help="predict the pulse amplitude and arrival times from the radius law alone",
                              description=__doc__)
    p.add_argument("--alpha", type=float, default=0.01, help="smallest small radius (default 0.01)")
    p.add_argument("--beta", type=float, default=0.4, help="largest small radius (default 0.4)")
    p.add_argument("--large", type=int, default=26, help="number N of large granules (default 26)")
    p.add_argument("--n", type=float, default=2.5, help="contact exponent, n > 2 (default 2.5, Hertz)")
    p.add_argument("--samples", type=int, default=20_000, help="Monte Carlo samples of the composition (default 20000)")
    p.add_argument("--seed", type=int, default=0, help="seed of the Monte Carlo (default 0)")
    p.add_argument("--memory", type=int, default=4,
                   help="contacts behind the one the transfer map steps over (default 4; 2 tabulates nodes^2 = 25x fewer short "
                        "chains, less accurately)")
    p.add_argument("--lookahead", type=int, default=1, help="contacts ahead of it (default 1)")
    p.add_argument("--nodes", type=int, default=5, help="quadrature nodes per contact (default 5; tables hold nodes^(memory+lookahead+1) chains)")
    p.add_argument("--no-stiffness-disorder", action="store_true",
                   help="the negative control: every contact at the median stiffness (the model then cannot decay)")
    p.add_argument("--compare", default=None, help="a run_ensemble Zarr store of the same law and N to compare with")
    p.add_argument("--out", default=None, help="directory for theory.nc, theory.md and the figure")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=run)


def _measured(store, N: int, dist_label: str) -> dict:
    from .. import analysis
    from ..ensembles.read import open_store

    path = Path(store)
    if not str(store).strip():
        raise ValueError("--compare must be the path of a granchain ensemble store, got an empty string")
    if not path.exists():
        raise ValueError(f"--compare: no store at {store}; run e.g. `granchain ensemble --large {N} --out {store}` first")
    ds = open_store(path)
    if int(ds.sizes["granule"]) != N:
        raise ValueError(f"--compare: the store has N = {ds.sizes['granule']} large granules, the prediction N = {N}; "
                         "pass the same --large")
    chain = "decorated" if "decorated" in [str(c) for c in ds["chain"].values] else str(ds["chain"].values[0])
    mp = analysis.mean_peak_amplitude(ds, chain)
    ap = analysis.averaged_pulse_peak(ds, chain)
    at = analysis.mean_arrival_time(ds, chain)
    T = analysis._valid(ds.sel(chain=chain), "peak_time")
    return {"chain": chain, "realizations": int(mp.n[1]) if mp.n.size > 1 else int(mp.n[0]),
            "mean_peak_velocity": mp.value, "averaged_peak_velocity": ap.velocity, "arrival_time_mean": at.value,
            "arrival_time_std": np.nanstd(T, axis=0, ddof=1), "law": dist_label}


def table(pred, meas=None) -> str:
    """Markdown table of the prediction (and the measured values and relative errors)."""
    k = pred["granule"].values
    cols = ["k", "<max_t v_k>", "max_t <v_k(t)>", "<t_k>", "std t_k"]
    if meas is not None:
        cols += ["measured <max_t v_k>", "err %", "measured max_t <v_k>", "err %", "measured <t_k>", "diff", "measured std t_k", "err %"]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for q in range(k.size):
        row = [f"{k[q]}", f"{pred['mean_peak_velocity'].values[q]:.4f}", f"{pred['averaged_peak_velocity'].values[q]:.4f}",
               f"{pred['arrival_time_mean'].values[q]:.3f}", f"{pred['arrival_time_std'].values[q]:.3f}"]
        if meas is not None:
            rel = lambda name: 100 * (pred[name].values[q] / meas[name][q] - 1) if meas[name][q] else 0.0  # noqa: E731
            row += [f"{meas['mean_peak_velocity'][q]:.4f}", f"{rel('mean_peak_velocity'):+.2f}",
                    f"{meas['averaged_peak_velocity'][q]:.4f}", f"{rel('averaged_peak_velocity'):+.2f}",
                    f"{meas['arrival_time_mean'][q]:.3f}", f"{pred['arrival_time_mean'].values[q] - meas['arrival_time_mean'][q]:+.3f}",
                    f"{meas['arrival_time_std'][q]:.3f}", f"{rel('arrival_time_std'):+.1f}"]
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


def _summary(pred, meas, k_lo: int = 4) -> str:
    N = int(pred.sizes["granule"])
    sel = slice(k_lo - 1, N - 1)
    parts = []
    for name in ("mean_peak_velocity", "averaged_peak_velocity", "arrival_time_std"):
        rel = pred[name].values[sel] / meas[name][sel] - 1.0
        parts.append(f"{name}: max {100 * np.max(np.abs(rel)):.2f} %, rms {100 * np.sqrt(np.mean(rel**2)):.2f} %")
    d = pred["arrival_time_mean"].values[sel] - meas["arrival_time_mean"][sel]
    parts.append(f"arrival_time_mean: max |diff| {np.max(np.abs(d)):.3f} time units")
    return f"errors over k = {k_lo}..{N - 1} against {meas['realizations']} realisations ({meas['chain']} chain): " + "; ".join(parts)


def run(args) -> int:
    from .. import Uniform, theory
    from .._validate import count
    from ..design.preflight import output_directory

    N = count("--large", args.large, minimum=2)
    dist = Uniform(args.alpha, args.beta)
    # Everything that can be checked without the prediction is checked first: a prediction of a new law
    # tabulates for tens of seconds, and its result must not be lost to a path that cannot be written.
    out_dir = None if args.out is None else output_directory(args.out, "--out")
    meas = _measured(args.compare, N, dist.label()) if args.compare is not None else None
    pred = theory.predict(dist, N, args.n, samples=args.samples, seed=args.seed, memory=args.memory,
                          lookahead=args.lookahead, nodes=args.nodes, stiffness_disorder=not args.no_stiffness_disorder)
    if args.json:
        out = {name: pred[name].values.tolist() for name in pred.data_vars}
        out.update({k: v for k, v in pred.attrs.items() if isinstance(v, (int, float, str))})
        if meas is not None:
            out["measured"] = {k: np.asarray(v).tolist() for k, v in meas.items()}
        print(json.dumps(out))
        return 0
    text = (f"granchain theory: small radii {dist.label()}, N = {N}, n = {pred.attrs['n']:g} "
            f"({pred.attrs['samples']} Monte Carlo samples, window {pred.attrs['memory']} behind / {pred.attrs['lookahead']} ahead, "
            f"{pred.attrs['nodes']} quadrature nodes; {pred.attrs['seconds']:.1f} s)\n\n" + table(pred, meas))
    if meas is not None:
        text += "\n\n" + _summary(pred, meas)
    print(text)
    if out_dir is not None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from ..paper.figures import save
        from ..paper.figures import theory as figure

        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        pred.to_netcdf(out / "theory.nc")
        (out / "theory.md").write_text(text + "\n")
        fig = figure.plot(figure.compute(dist, N, n=args.n, prediction=pred, measured=args.compare))
        paths = save(fig, out / "theory")
        plt.close(fig)
        print(f"\nwrote {out / 'theory.nc'}, {out / 'theory.md'}, {', '.join(str(p) for p in paths)}")
    return 0
