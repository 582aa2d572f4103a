"""Paper Fig. 2: decay of the pulse amplitude along the chain, N = 26.

The amplitude is the peak of the ensemble-averaged pulse, max_t <v_k(t)> (DESIGN.md
Sec. 2), fitted with v_k = a exp(-b k^c) over k = 4..N-1 (the paper's range for N = 26);
the inset fits the same peaks against their times, v = a' exp(-b' t^c'). The mean of
per-realisation peaks <max_t v_k> is drawn too: it is a different quantity and decays
much more weakly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import analysis
from ._style import COLORS, VELOCITY_UNITS, axes


@dataclass(frozen=True, eq=False)
class Fig2Data:
    chains: tuple
    peaks: dict  # chain -> analysis.PulsePeak
    mean_peaks: dict  # chain -> analysis.PerGranule
    fit_k: dict  # chain -> StretchedExpFit (v vs k)
    fit_t: dict  # chain -> StretchedExpFit (v vs t)
    fit_range: tuple
    realizations: int

    def to_dataset(self):
        import xarray as xr

        ds = xr.Dataset(attrs={"figure": "paper Fig. 2", "fit_range_k": list(self.fit_range), "realizations": self.realizations})
        for c in self.chains:
            p, m = self.peaks[c], self.mean_peaks[c]
            ds = ds.assign_coords(granule=p.granule)
            ds[f"{c}_averaged_pulse_peak"] = ("granule", p.velocity, {"long_name": f"max_t <v_k(t)>, {c}", "units": "V_1"})
            ds[f"{c}_averaged_pulse_peak_stderr"] = ("granule", p.velocity_stderr, {"units": "V_1"})
            ds[f"{c}_averaged_pulse_peak_time"] = ("granule", p.time, {"long_name": f"argmax_t <v_k(t)>, {c}", "units": "rescaled time"})
            ds[f"{c}_mean_peak_velocity"] = ("granule", m.value, {"long_name": f"<max_t v_k>, {c}", "units": "V_1"})
            for name, fit in (("k", self.fit_k[c]), ("t", self.fit_t[c])):
                ds.attrs[f"{c}_fit_{name}_abc"] = list(fit.params)
                ds.attrs[f"{c}_fit_{name}_abc_stderr"] = list(fit.errors)
        return ds


def _range(ds, fit_range):
    N = int(ds.sizes["granule"])
    lo, hi = fit_range if fit_range is not None else (4, N - 1)
    return (max(2, int(lo)), min(N - 1, int(hi)))


def compute(ds, fit_range=(4, 25)) -> Fig2Data:
    """Averaged-pulse peaks, per-realisation mean peaks and both stretched-exponential fits.

    ``fit_range`` (inclusive, in k) is clipped to 2..N-1: k = 1 is the struck granule and
    k = N the free end, which flies off.
    """
    rng = _range(ds, fit_range)
    chains = tuple(str(c) for c in ds["chain"].values)
    peaks, means, fk, ft = {}, {}, {}, {}
    for c in chains:
        p = analysis.averaged_pulse_peak(ds, c)
        peaks[c] = p
        means[c] = analysis.mean_peak_amplitude(ds, c)
        sel = (p.granule >= rng[0]) & (p.granule <= rng[1])
        fk[c] = analysis.fit_stretched_exp(p.granule, p.velocity, p.velocity_stderr, fit_range=rng, variable="k")
        ft[c] = analysis.fit_stretched_exp(p.time[sel], p.velocity[sel], p.velocity_stderr[sel], variable="t")
    return Fig2Data(chains, peaks, means, fk, ft, rng, int(ds.sizes["realization"]))


def _fit_label(prefix, fit, primes=""):
    return (fr"{prefix}: $a{primes}$={fit.a:.3f}±{fit.a_err:.3f}, $b{primes}$={fit.b:.3f}±{fit.b_err:.3f}, "
            fr"$c{primes}$={fit.c:.3f}±{fit.c_err:.3f}")


def plot(data: Fig2Data, ax=None):
    fig, ax = axes(ax, figsize=(7.0, 5.0))
    markers = {"decorated": "o", "effective": "s"}
    for c in data.chains:
        p = data.peaks[c]
        face = COLORS[c] if c == "decorated" else "none"
        ax.errorbar(p.granule, p.velocity, p.velocity_stderr, fmt=markers[c], ms=5, mfc=face, color=COLORS[c],
                    label=fr"$\max_t\langle v_k\rangle$, {c} chain")
        m = data.mean_peaks[c]
        ax.plot(m.granule, m.value, ls="--", lw=1, color=COLORS[c], alpha=0.7,
                label=fr"$\langle\max_t v_k\rangle$ (mean of per-realisation peaks), {c}")
    k = np.linspace(data.fit_range[0], data.fit_range[1], 200)
    main = "effective" if "effective" in data.chains else data.chains[0]
    fit = data.fit_k[main]
    ax.plot(k, fit(k), color="tab:orange", lw=2, label=_fit_label(f"fit ({main}, k = {data.fit_range[0]}..{data.fit_range[1]})", fit))
    ax.plot(k, analysis.stretched_exp(k, *analysis.PAPER_FIG2), color=COLORS["paper"], ls=":", lw=2,
            label="paper: a=0.756, b=0.067, c=0.714")
    ax.set_xlabel(r"large-granule index $k$")
    ax.set_ylabel(r"pulse amplitude " + VELOCITY_UNITS)
    ax.set_title(f"Amplitude decay, N = {len(data.peaks[main].granule)} ({data.realizations} realisations)", fontsize=10)
    ax.legend(loc="upper right", fontsize=7, frameon=False)
    ax.set_ylim(0, 1.05)
    inset = ax.inset_axes([0.09, 0.09, 0.36, 0.30])
    p = data.peaks[main]
    sel = (p.granule >= data.fit_range[0]) & (p.granule <= data.fit_range[1])
    inset.plot(p.time[sel], p.velocity[sel], "o", ms=3, color=COLORS[main])
    ft = data.fit_t[main]
    t = np.linspace(p.time[sel].min(), p.time[sel].max(), 200)
    inset.plot(t, ft(t), color="tab:orange", lw=1.5)
    inset.plot(t, analysis.stretched_exp(t, *analysis.PAPER_FIG2_INSET), color=COLORS["paper"], ls=":", lw=1.5)
    inset.set_xlabel(r"peak time $t$", fontsize=7)
    inset.set_ylabel(r"$\max_t\langle v\rangle$", fontsize=7)
    inset.tick_params(labelsize=6)
    inset.set_title(fr"$a'$={ft.a:.3f}, $b'$={ft.b:.4f}, $c'$={ft.c:.3f}", fontsize=7)
    return fig
