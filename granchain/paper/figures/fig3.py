"""Paper Fig. 3: arrival time of the pulse versus granule k, N = 26, with the linear fit
t = slope k + intercept (paper: 2.402 k - 1.181) and the BCA slope S (Eq. slope).

The arrival time is that of the ensemble-averaged pulse, argmax_t <v_k(t)> (docs: the
two amplitudes), fitted as the paper does by unweighted least squares over k = 2..25: this range
reproduces the paper's intercept; k = 1 is the struck granule (its "arrival" is t = 0 by
construction) and k = N the free end (a plateau, not a peak). Errors: jackknife over the
store's chunks of realisations when ``sums`` are given (they measure sampling noise), else
the fit residuals (which measure the curvature of t(k), not statistics; labelled). The
lower panel shows the residuals about the fit, where the curves differ visibly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ... import analysis, bca
from ...units import rescaled_attrs
from ._style import COLORS, MARKERS, panel_pair


def _bca_slope(ds) -> float:
    """The BCA slope S (Eq. slope) for the small-radius distribution of the store's family
    (read from the stored record, :func:`granchain.family_from_dataset`): the closed form for a
    uniform distribution, quadrature (:func:`granchain.bca.slope`) for any other. NaN for a
    family Eq. (slope) does not describe (it assumes unit large granules: undecorated and tapered
    families)."""
    from ...families import RandomDecorated, family_from_dataset
    from ...model.distributions import Uniform

    family = family_from_dataset(ds)
    if not isinstance(family, RandomDecorated):
        return float("nan")
    dist = family.distribution
    if isinstance(dist, Uniform):
        return bca.slope_uniform(dist.alpha, dist.beta, n=family.n)
    return bca.slope(dist, n=family.n)


@dataclass(frozen=True, eq=False)
class Fig3Data:
    chains: tuple
    main: str
    granule: np.ndarray
    pulse_time: dict  # chain -> argmax_t <v_k(t)>
    pulse_time_stderr: dict  # chain -> jackknife stderr per granule (NaN without sums)
    mean_time: dict  # chain -> analysis.PerGranule (mean of per-realisation peak times)
    fit: dict  # chain -> analysis.PulseFit of pulse_time vs k
    fit_range: tuple
    S: float  # Eq. (slope)
    bca_mean: np.ndarray  # mean over the same realisations of the full Eq. (total-time)
    realizations: int

    def to_dataset(self):
        import xarray as xr

        ds = xr.Dataset(coords={"granule": ("granule", self.granule, {"long_name": "large granule index k (1-based)", "units": "1"})},
                        attrs={"figure": "paper Fig. 3", "fit_range_k": list(self.fit_range), "S_eq_slope": self.S,
                               "realizations": self.realizations, "fit": "unweighted least squares"})
        ds["bca_mean_arrival_time"] = ("granule", self.bca_mean, {"long_name": "mean of Eq. (total-time) over the realisations", **rescaled_attrs("time")})
        for c in self.chains:
            ds[f"{c}_averaged_pulse_time"] = ("granule", self.pulse_time[c], {"long_name": f"argmax_t <v_k(t)>, {c}", **rescaled_attrs("time")})
            ds[f"{c}_averaged_pulse_time_stderr"] = ("granule", self.pulse_time_stderr[c], rescaled_attrs("time"))
            ds[f"{c}_mean_peak_time"] = ("granule", self.mean_time[c].value, {"long_name": f"<t_k> over realisations, {c}", **rescaled_attrs("time")})
            ds.attrs[f"{c}_fit_slope_intercept"] = list(self.fit[c].params)
            ds.attrs[f"{c}_fit_slope_intercept_stderr"] = list(self.fit[c].stderr)
            ds.attrs[f"{c}_fit_error_method"] = self.fit[c].method
        return ds


def compute(ds, fit_range=(2, 25), sums=None) -> Fig3Data:
    """Averaged-pulse arrival times, their unweighted line over ``fit_range`` (clipped to
    2..N-1) with jackknife errors (``sums``), the BCA slope S and the BCA mean arrival times."""
    N = int(ds.sizes["granule"])
    rng = (max(2, int(fit_range[0])), min(N - 1, int(fit_range[1])))
    chains = tuple(str(c) for c in ds["chain"].values)
    time = ds["time"].values.astype(float)
    pulse, perr, means, fits = {}, {}, {}, {}
    for c in chains:
        jk = analysis.pulse_jackknife(ds, lambda m, c=c: analysis.pulse_peak(time, m[c])[1], sums)
        pulse[c], perr[c] = jk.value, jk.stderr
        means[c] = analysis.mean_arrival_time(ds, c)
        fits[c] = analysis.fit_averaged_arrival(ds, c, rng, sums)
    n = float(ds.attrs.get("n", 2.5))
    radii = ds["small_radius"].values
    radii = radii[np.all(np.isfinite(radii), axis=1)]
    mc = bca.monte_carlo_arrival_times(N, small_radii=radii, n=n)
    main = "effective" if "effective" in chains else chains[0]
    return Fig3Data(chains, main, ds["granule"].values, pulse, perr, means, fits, rng, _bca_slope(ds),
                    mc.arrival_time.mean(axis=0), int(ds.sizes["realization"]))


def plot(data: Fig3Data, ax=None):
    """Arrival time vs k (top) and residuals about the fit (bottom); ``ax``: optional pair of axes."""
    fig, ax, low = panel_pair(ax, figsize=(7.0, 7.0), height_ratios=(1.4, 1))
    lo, hi = data.fit_range
    inner = slice(0, -1)  # k = N, the free end, flies off: its "arrival" is a plateau, not a peak
    f = data.fit[data.main]
    m, q = f.params
    em, eq = f.stderr
    err_kind = "jackknife" if "jackknife" in f.method else "fit residuals"
    for a in (ax, low):  # hatch what lies outside the fit range
        a.axvspan(0.3, lo - 0.5, facecolor="none", edgecolor="0.8", hatch="///", lw=0, zorder=0)
        if hi < data.granule[-1] - 1:
            a.axvspan(hi + 0.5, data.granule[-1] - 0.5, facecolor="none", edgecolor="0.8", hatch="///", lw=0, zorder=0)
        a.axvline(lo - 0.5, color="0.6", lw=0.8)
        a.axvline(hi + 0.5, color="0.6", lw=0.8)
    k = np.linspace(lo, hi, 100)
    for c in data.chains:
        face = COLORS[c] if c == "decorated" else "white"
        ax.plot(data.granule[inner], data.pulse_time[c][inner], MARKERS[c], ms=4.5, mfc=face, color=COLORS[c],
                label=fr"$\mathrm{{argmax}}_t\langle v_k\rangle$, {c} chain")
        r = data.pulse_time[c] - f.fit(data.granule)
        e = data.pulse_time_stderr[c]
        res = slice(1, -1)  # k = 1 arrives at t = 0 by construction; k = N is the free end
        low.errorbar(data.granule[res], r[res], None if np.all(np.isnan(e)) else e[res], fmt=MARKERS[c], ms=4,
                     mfc=face, color=COLORS[c], lw=0.8, label=f"{c} chain" + (" (±1 s.e., jackknife)" if c == data.main and np.any(np.isfinite(e)) else ""))
    ax.plot(k, f.fit(k), color=COLORS["fit"], lw=1.8,
            label=f"fit ({data.main}, k = {lo}..{hi}, {err_kind}): t = {m:.4f}({em * 1e4:.0f}) k {'+' if q >= 0 else '−'} {abs(q):.3f}({eq * 1e3:.0f})")
    ax.plot(k, analysis.PAPER_FIG3[0] * k + analysis.PAPER_FIG3[1], color=COLORS["paper"], ls=":", lw=2, label="paper: t = 2.402 k - 1.181")
    ax.plot(data.granule[inner], data.bca_mean[inner], "x", color=COLORS["bca"], ms=5, label="BCA mean arrival time, Eq. (total-time)")
    ax.set_ylabel("arrival time of the averaged pulse\n" + r"$t$ (rescaled units)")
    ax.set_title(f"Pulse arrival time, N = {len(data.granule)} ({data.realizations} realisations); "
                 f"fit range k = {lo}..{hi} between the vertical lines", fontsize=9.5)
    ax.legend(loc="upper left", fontsize=7, frameon=False)
    ax.tick_params(labelbottom=True)
    ax.set_xlabel(r"large-granule index $k$")

    kk = data.granule[1:-1].astype(float)
    low.plot(kk, analysis.PAPER_FIG3[0] * kk + analysis.PAPER_FIG3[1] - f.fit(kk), color=COLORS["paper"], ls=":", lw=2,
             label="paper's line minus the fit")
    low.plot(kk, data.S * kk + (m - data.S) * 0.5 * (lo + hi) + q - f.fit(kk), color=COLORS["bca"], ls="--", lw=1.4,
             label=f"BCA slope S = {data.S:.4f} (Eq. slope) through the fit's centre, minus the fit")
    low.axhline(0, color=COLORS["fit"], lw=1.5)
    low.set_xlabel(r"large-granule index $k$")
    low.set_ylabel("residual about the fit\n" + r"$t - t_\mathrm{fit}$ (rescaled units)")
    ax.set_xlim(0.3, data.granule[-1] - 0.5)
    low.legend(loc="lower left", fontsize=7, frameon=False)
    ylo, yhi = low.get_ylim()
    low.set_ylim(ylo - 0.45 * (yhi - ylo), yhi)
    return fig
