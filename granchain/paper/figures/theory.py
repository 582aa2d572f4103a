"""The pulse-decay theory against the numerics: <max_t v_k>, max_t <v_k(t)> and the arrival spread.

``compute`` runs :func:`granchain.theory.predict` (and its negative control without stiffness
disorder) and gathers measured values from a ``run_ensemble`` store or Dataset; without one, for
the paper's law U[0.01, 0.4] at N = 26, the bundled reference (3000 decorated realisations, the
ensemble its ``source`` attribute names, ``granchain/_data/theory_reference_U001_04_N26.nc``): a netCDF3
file, which SciPy's reader opens, so that a base install (no netCDF4, no h5netcdf) draws the figure.
It also fits the paper's stretched exponential v_k = a exp(-b k^c) to the predicted
max_t <v_k(t)> over k = 4..N-1, so the theory's a, b, c sit next to the paper's.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ... import analysis
from ._style import COLORS, VELOCITY_UNITS

REFERENCE = Path(__file__).resolve().parents[2] / "_data" / "theory_reference_U001_04_N26.nc"


@dataclass(frozen=True, eq=False)
class TheoryFigureData:
    prediction: object  # xarray.Dataset of theory.predict
    control: object  # the same without stiffness disorder
    measured: dict | None  # name -> (values, stderr) per granule, and "source"
    fit: object  # analysis.StretchedExpFit of the predicted averaged peaks
    fit_range: tuple


def _from_dataset(ds, source: str) -> dict:
    chain = "decorated" if "decorated" in [str(c) for c in ds["chain"].values] else str(ds["chain"].values[0])
    mp = analysis.mean_peak_amplitude(ds, chain)
    ap = analysis.averaged_pulse_peak(ds, chain)
    T = analysis._valid(ds.sel(chain=chain), "peak_time")
    n = np.sum(np.isfinite(T), axis=0)
    sd = np.nanstd(T, axis=0, ddof=1)
    return {"mean_peak_velocity": (mp.value, mp.stderr), "averaged_peak_velocity": (ap.velocity, ap.velocity_stderr),
            "arrival_time_std": (sd, sd / np.sqrt(2.0 * np.maximum(n - 1, 1))), "source": f"{source} ({int(n[-1])} realisations, {chain})"}


def _measured(measured, distribution, n_large):
    import xarray as xr

    if measured is None:
        from ...model.distributions import Uniform

        if REFERENCE.exists() and distribution == Uniform(0.01, 0.4) and n_large == 26:
            # netCDF3 (64-bit offset): SciPy reads it, so a base install draws the figure without netCDF4 or h5netcdf
            with xr.open_dataset(REFERENCE, engine="scipy") as opened:
                ref = opened.load()
            found = re.search(r"realizations=(\d+)", ref.attrs["source"])  # the legend names the size, not the call
            size = f", {found.group(1)} realisations" if found else ""
            return {name: (ref[name].values, ref[f"{name}_stderr"].values) for name in
                    ("mean_peak_velocity", "averaged_peak_velocity", "arrival_time_std")} | {"source": f"granchain ensemble{size}"}
        return None
    if isinstance(measured, (str, Path)):
        from ...ensembles.read import open_store

        return _from_dataset(open_store(measured), f"store {Path(measured).name}")
    return _from_dataset(measured, "ensemble")


def compute(distribution=None, n_large: int = 26, *, n: float = 2.5, prediction=None, measured=None,
            fit_range=None) -> TheoryFigureData:
    """Prediction, negative control, measured values (store path, Dataset, or the bundled reference
    for U[0.01, 0.4], N = 26) and the stretched-exponential fit of the predicted averaged peaks."""
    from ... import theory
    from ...model.distributions import as_distribution

    dist = as_distribution(distribution)
    pred = theory.predict(dist, n_large, n) if prediction is None else prediction
    # the control with the prediction's own window, nodes and samples: the two differ only in the stiffness disorder
    same = {key: int(pred.attrs[key]) for key in ("memory", "lookahead", "nodes", "samples", "seed", "profile_windows")
            if key in pred.attrs}
    ctrl = theory.predict(dist, n_large, n, stiffness_disorder=False, **same)
    N = int(pred.sizes["granule"])
    rng = (4, N - 1) if fit_range is None else tuple(fit_range)
    k = pred["granule"].values.astype(float)
    fit = None  # a three-parameter law through fewer than six points would fit anything
    if rng[1] - rng[0] >= 5:
        fit = analysis.fit_stretched_exp(k, pred["averaged_peak_velocity"].values, fit_range=rng, variable="k")
    return TheoryFigureData(pred, ctrl, _measured(measured, dist, N), fit, rng)


def plot(data: TheoryFigureData, ax=None):
    """Three panels: <max_t v_k>, max_t <v_k(t)> (with the paper's and the theory's stretched
    exponentials), and the arrival-time spread, theory (lines) against the numerics (markers).
    ``ax``: optional sequence of three axes."""
    import matplotlib.pyplot as plt

    if ax is None:
        fig, ax = plt.subplots(3, 1, figsize=(6.8, 9.6), sharex=True, layout="constrained")
    else:
        fig = ax[0].figure
    pred, ctrl, meas = data.prediction, data.control, data.measured
    k = pred["granule"].values
    inner = (k >= 2) & (k <= k[-1] - 1)
    label_meas = "numerics" + (f": {meas['source']}" if meas else "")
    panels = (("mean_peak_velocity", r"$\langle \mathrm{max}_t\, v_k\rangle$ " + VELOCITY_UNITS),
              ("averaged_peak_velocity", r"$\mathrm{max}_t \langle v_k(t)\rangle$ " + VELOCITY_UNITS),
              ("arrival_time_std", r"std of the arrival time $t_k$ (rescaled time)"))
    for a, (name, ylabel) in zip(ax, panels):
        a.plot(k[inner], pred[name].values[inner], color=COLORS["effective"], lw=1.8, label="theory (granchain.theory.predict)")
        a.plot(k[inner], ctrl[name].values[inner], color=COLORS["bca"], lw=1.2, ls="--",
               label="negative control: no stiffness disorder")
        if meas is not None:
            v, e = meas[name]
            a.errorbar(k[inner], np.asarray(v)[inner], np.asarray(e)[inner], fmt="o", ms=4, mfc="white",
                       color=COLORS["decorated"], lw=0.8, label=label_meas)
        a.set_ylabel(ylabel)
        a.legend(fontsize=7, frameon=False)
    kk = np.linspace(*data.fit_range, 200)
    if pred.attrs.get("distribution_label") == "U[0.01, 0.4]":  # the paper's fit belongs to the paper's law only
        ax[1].plot(kk, analysis.stretched_exp(kk, *analysis.PAPER_FIG2), color=COLORS["paper"], ls=":", lw=2,
                   label="paper's fit: a = 0.756, b = 0.067, c = 0.714")
    if data.fit is not None:
        (fa, fb, fc) = data.fit.params
        ax[1].plot(kk, data.fit(kk), color=COLORS["fit"], lw=1, label=f"fit to the theory, k = {data.fit_range[0]}..{data.fit_range[1]}: "
                   f"a = {fa:.3f}, b = {fb:.3f}, c = {fc:.3f}")
    ax[1].legend(fontsize=7, frameon=False)
    ax[-1].set_xlabel(r"large-granule index $k$")
    what = "Theory vs numerics" if meas is not None else "Theory (no numerics given)"
    ax[0].set_title(f"{what}, {pred.attrs['distribution_label']}, N = {int(pred.sizes['granule'])}", fontsize=10)
    return fig


__all__ = ["TheoryFigureData", "compute", "plot"]
