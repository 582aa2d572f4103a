"""Paper Fig. 3: arrival time of the pulse versus granule k, N = 26, with the linear fit
t = slope k + intercept (paper: 2.402 k - 1.181) and the BCA slope S (Eq. slope).

The arrival time is that of the ensemble-averaged pulse, argmax_t <v_k(t)> (DESIGN.md
Sec. 2); the mean of per-realisation peak times is shown as well.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import analysis, bca
from ._style import COLORS, TIME_LABEL, axes


@dataclass(frozen=True, eq=False)
class Fig3Data:
    chains: tuple
    granule: np.ndarray
    pulse_time: dict  # chain -> argmax_t <v_k(t)>
    mean_time: dict  # chain -> analysis.PerGranule (mean of per-realisation peak times)
    fit: dict  # chain -> LinearFit of pulse_time vs k
    fit_range: tuple
    S: float  # Eq. (slope)
    bca_mean: np.ndarray  # mean over the same realisations of the full Eq. (total-time)
    realizations: int

    def to_dataset(self):
        import xarray as xr

        ds = xr.Dataset(coords={"granule": self.granule},
                        attrs={"figure": "paper Fig. 3", "fit_range_k": list(self.fit_range), "S_eq_slope": self.S,
                               "realizations": self.realizations})
        ds["bca_mean_arrival_time"] = ("granule", self.bca_mean, {"long_name": "mean of Eq. (total-time) over the realisations", "units": "rescaled time"})
        for c in self.chains:
            ds[f"{c}_averaged_pulse_time"] = ("granule", self.pulse_time[c], {"long_name": f"argmax_t <v_k(t)>, {c}", "units": "rescaled time"})
            ds[f"{c}_mean_peak_time"] = ("granule", self.mean_time[c].value, {"long_name": f"<t_k> over realisations, {c}", "units": "rescaled time"})
            ds.attrs[f"{c}_fit_slope_intercept"] = [self.fit[c].slope, self.fit[c].intercept]
            ds.attrs[f"{c}_fit_slope_intercept_stderr"] = [self.fit[c].slope_err, self.fit[c].intercept_err]
        return ds


def compute(ds, fit_range=(4, 25)) -> Fig3Data:
    """Averaged-pulse arrival times, their linear fit over ``fit_range`` (clipped to 2..N-1),
    the BCA slope S for the Dataset's distribution and the BCA mean arrival times."""
    N = int(ds.sizes["granule"])
    rng = (max(2, int(fit_range[0])), min(N - 1, int(fit_range[1])))
    chains = tuple(str(c) for c in ds["chain"].values)
    pulse, means, fits = {}, {}, {}
    for c in chains:
        p = analysis.averaged_pulse_peak(ds, c)
        pulse[c] = p.time
        means[c] = analysis.mean_arrival_time(ds, c)
        fits[c] = analysis.fit_linear(p.granule, p.time, fit_range=rng)
    alpha, beta = float(ds.attrs.get("alpha", 0.01)), float(ds.attrs.get("beta", 0.4))
    n = float(ds.attrs.get("n", 2.5))
    S = bca.slope_uniform(alpha, beta, n=n)
    radii = ds["small_radius"].values
    radii = radii[np.all(np.isfinite(radii), axis=1)]
    mc = bca.monte_carlo_arrival_times(N, small_radii=radii, n=n)
    return Fig3Data(chains, ds["granule"].values, pulse, means, fits, rng, S, mc.arrival_time.mean(axis=0), int(ds.sizes["realization"]))


def plot(data: Fig3Data, ax=None):
    fig, ax = axes(ax, figsize=(6.4, 4.6))
    markers = {"decorated": "o", "effective": "s"}
    inner = slice(0, -1)  # k = N, the free end, flies off: its "arrival" is a plateau, not a peak
    for c in data.chains:
        face = COLORS[c] if c == "decorated" else "none"
        ax.plot(data.granule[inner], data.pulse_time[c][inner], markers[c], ms=5, mfc=face, color=COLORS[c],
                label=fr"$\mathrm{{argmax}}_t\langle v_k\rangle$, {c} chain (k < N)")
    main = "effective" if "effective" in data.chains else data.chains[0]
    f = data.fit[main]
    k = np.linspace(1, data.granule[-2], 100)
    ax.plot(k, f(k), color="tab:orange", lw=1.8,
            label=fr"fit ({main}, k = {data.fit_range[0]}..{data.fit_range[1]}): t = ({f.slope:.4f}±{f.slope_err:.4f}) k {f.intercept:+.3f}")
    ax.plot(k, data.S * k + f.intercept, color=COLORS["bca"], ls="--", lw=1.4,
            label=fr"BCA slope S = {data.S:.4f} (Eq. slope), same intercept")
    ax.plot(data.granule[inner], data.bca_mean[inner], "x", color=COLORS["bca"], ms=5, label="BCA mean arrival time, Eq. (total-time)")
    ax.plot(k, analysis.PAPER_FIG3[0] * k + analysis.PAPER_FIG3[1], color=COLORS["paper"], ls=":", lw=1.5, label="paper: t = 2.402 k - 1.181")
    ax.set_xlabel(r"large-granule index $k$")
    ax.set_ylabel("arrival time of the averaged pulse\n" + TIME_LABEL)
    ax.set_title(f"Pulse arrival time, N = {len(data.granule)} ({data.realizations} realisations)", fontsize=10)
    ax.legend(loc="upper left", fontsize=7, frameon=False)
    return fig
