"""Validate ``granchain.theory.predict`` against decorated-chain ensembles.

For each small-radius law (U[0.01, 0.4] the paper's, U[0.1, 0.4], U[0.01, 0.6], and the truncated
normal and bimodal mixture of ``granchain.paper.validity.default_distributions`` on [0.01, 0.4]) and
N = 26, 51: a 3000-realisation decorated ensemble (resumable Zarr store under --work, seed 11,
chunks of 250 for the jackknife) and the theory's prediction (which never sees the ensemble). Per
observable the max and rms relative error over k = 4..N-1 (arrival times: absolute error of the
mean, relative error of the std), with a delete-one-chunk jackknife error of the max error
(analysis.ChunkSums for the averaged pulse, blocks of realisations otherwise), and the negative
control (the theory without stiffness disorder) for <max_t v_k>. Writes theory-validation.md and
theory-validation.nc under --out.

    NUMBA_NUM_THREADS=1 python benchmarks/validate_theory.py --work /tmp/thv --out benchmarks/results
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np


def laws():
    import granchain as gc
    from granchain.paper.validity import default_distributions

    d = default_distributions(0.01, 0.4)
    return {"U[0.01, 0.4]": gc.Uniform(0.01, 0.4), "U[0.1, 0.4]": gc.Uniform(0.1, 0.4), "U[0.01, 0.6]": gc.Uniform(0.01, 0.6),
            "truncated normal": d["truncated normal"], "bimodal": d["bimodal"]}


def store_name(label: str, N: int) -> str:
    return "".join(ch if ch.isalnum() else "_" for ch in label) + f"_N{N}.zarr"


def ensemble(dist, N: int, work: Path, realizations: int):
    import granchain as gc

    t0 = time.perf_counter()
    ds = gc.run_ensemble(gc.RandomDecorated(N, dist), realizations=realizations, seed=11, chains="decorated",
                         out=work / store_name(dist.label(), N), chunk_size=250, progress=False)
    return ds, time.perf_counter() - t0


def measured(ds, store):
    """Per-granule measurements and a jackknife of any error statistic built from them."""
    from granchain import analysis

    sub = ds.sel(chain="decorated")
    P = analysis._valid(sub, "peak_velocity")
    T = analysis._valid(sub, "peak_time")
    sums = analysis.ChunkSums.from_store(store)
    ci = list(sums.chains).index("decorated")
    time_axis = sums.time
    return P, T, sums, ci, time_axis


def errors(pred, P, T, sums, ci, time_axis, k_lo: int):
    """{observable: (max |err|, rms err, jackknife se of the max)} over k = k_lo..N-1."""
    from granchain import analysis

    N = P.shape[1]
    sel = slice(k_lo - 1, N - 1)
    out = {}

    def stats(rel):
        r = np.asarray(rel)[sel]
        return float(np.max(np.abs(r))), float(np.sqrt(np.mean(r**2)))

    per_real = {
        "mean_peak_velocity": (lambda p, t: pred["mean_peak_velocity"] / np.nanmean(p, 0) - 1.0),
        "peak_velocity_std": (lambda p, t: pred["peak_velocity_std"] / np.nanstd(p, 0, ddof=1) - 1.0),
        "arrival_time_mean": (lambda p, t: pred["arrival_time_mean"] - np.nanmean(t, 0)),  # absolute (time units)
        "arrival_time_mean_rel": (lambda p, t: pred["arrival_time_mean"][...] / np.where(np.nanmean(t, 0) > 0, np.nanmean(t, 0), np.nan) - 1.0),
        "arrival_time_std": (lambda p, t: pred["arrival_time_std"] / np.nanstd(t, 0, ddof=1) - 1.0),
    }
    for name, f in per_real.items():
        with np.errstate(invalid="ignore", divide="ignore"):  # k = 1: spreads and times are 0
            jk = analysis.block_jackknife(lambda p, t, f=f: np.array(stats(f(p, t))), P, T, n_blocks=sums.chunks)
        out[name] = (float(jk.value[0]), float(jk.value[1]), float(jk.stderr[0]))

    def avg_stat(means):
        v, _, _, _ = analysis.pulse_peak(time_axis, means["decorated"])
        return np.array(stats(pred["averaged_peak_velocity"] / v - 1.0))

    jk = analysis.chunk_jackknife(avg_stat, sums)
    out["averaged_peak_velocity"] = (float(jk.value[0]), float(jk.value[1]), float(jk.stderr[0]))
    return out


def main(argv=None) -> int:
    import xarray as xr

    from granchain import EffectiveValidityWarning, theory

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--work", type=Path, default=Path("theory-validation-stores"))
    ap.add_argument("--out", type=Path, default=Path("."))
    ap.add_argument("--realizations", type=int, default=3000)
    ap.add_argument("--large", type=int, nargs="+", default=[26, 51])
    ap.add_argument("--only", nargs="*", default=None, help="law labels to run (default all)")
    args = ap.parse_args(argv)
    args.work.mkdir(parents=True, exist_ok=True)
    args.out.mkdir(parents=True, exist_ok=True)
    rows, records = [], []
    names = ("mean_peak_velocity", "averaged_peak_velocity", "arrival_time_mean", "arrival_time_std", "peak_velocity_std")
    for label, dist in laws().items():
        if args.only and label not in args.only:
            continue
        for N in args.large:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", EffectiveValidityWarning)
                ds, t_ens = ensemble(dist, N, args.work, args.realizations)
                t0 = time.perf_counter()
                pred = theory.predict(dist, N)
                t_pred = time.perf_counter() - t0
                ctrl = theory.predict(dist, N, stiffness_disorder=False)
            P, T, sums, ci, taxis = measured(ds, args.work / store_name(dist.label(), N))
            e = errors({k: pred[k].values for k in pred.data_vars}, P, T, sums, ci, taxis, 4)
            ec = errors({k: ctrl[k].values for k in ctrl.data_vars}, P, T, sums, ci, taxis, 4)
            rec = {"law": label, "N": N, "realizations": int(np.isfinite(P[:, 1]).sum()), "ensemble_s": t_ens,
                   "predict_s": t_pred, "tabulation_s": float(pred.attrs["tabulation_seconds"]),
                   "ctrl_mean_peak_max": ec["mean_peak_velocity"][0], "ctrl_averaged_max": ec["averaged_peak_velocity"][0]}
            for n in names:
                rec[f"{n}_max"], rec[f"{n}_rms"], rec[f"{n}_max_se"] = e[n]
            records.append(rec)
            print(rec, flush=True)
    pct = lambda x: f"{100 * x:.2f}"  # noqa: E731
    lines = ["| law | N | <max_t v_k> max / rms % | max_t <v_k(t)> max / rms % | mean arrival max / rms (time units) | "
             "arrival std max / rms % | peak std max / rms % | control (no stiffness disorder): <max_t v_k> / max_t <v_k(t)> max % | "
             "ensemble s | predict s (tables) |", "|" + "---|" * 10]
    for r in records:
        lines.append(
            f"| {r['law']} | {r['N']} | {pct(r['mean_peak_velocity_max'])} ± {pct(r['mean_peak_velocity_max_se'])} / {pct(r['mean_peak_velocity_rms'])} "
            f"| {pct(r['averaged_peak_velocity_max'])} ± {pct(r['averaged_peak_velocity_max_se'])} / {pct(r['averaged_peak_velocity_rms'])} "
            f"| {r['arrival_time_mean_max']:.3f} ± {r['arrival_time_mean_max_se']:.3f} / {r['arrival_time_mean_rms']:.3f} "
            f"| {pct(r['arrival_time_std_max'])} ± {pct(r['arrival_time_std_max_se'])} / {pct(r['arrival_time_std_rms'])} "
            f"| {pct(r['peak_velocity_std_max'])} / {pct(r['peak_velocity_std_rms'])} "
            f"| {pct(r['ctrl_mean_peak_max'])} / {pct(r['ctrl_averaged_max'])} | {r['ensemble_s']:.0f} | {r['predict_s']:.1f} ({r['tabulation_s']:.0f}) |")
    text = ("Theory vs decorated ensembles (3000 realisations, seed 11), errors over k = 4..N-1; ± is the jackknife "
            "standard error of the max (12 chunks / blocks of 250 realisations).\n\n" + "\n".join(lines) + "\n")
    (args.out / "theory-validation.md").write_text(text)
    table = xr.Dataset({k: ("case", np.array([r[k] for r in records])) for k in records[0] if k not in ("law",)},
                       coords={"law": ("case", [r["law"] for r in records])},
                       attrs={"description": "granchain.theory.predict vs run_ensemble(RandomDecorated(N, law)), k = 4..N-1"})
    table.to_netcdf(args.out / "theory-validation.nc")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
