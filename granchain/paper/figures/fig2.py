"""Paper Fig. 2: decay of the pulse amplitude along the chain, N = 26.

The amplitude is the peak of the ensemble-averaged pulse, max_t <v_k(t)> (docs: the two amplitudes),
fitted as the paper does, by unweighted least squares, with v_k = a exp(-b k^c) over
k = 4..25 (k = 1 is the struck granule and k = N the free end); the inset fits the same
peaks against their times, v = a' exp(-b' t^c'). Errors: jackknife over the store's chunks
of realisations when ``sums`` (:class:`granchain.analysis.ChunkSums`) are given, else the
fit residuals (labelled). The lower panel compares the fitted curves with the paper's,
granule by granule, against the band the paper's printed digits allow: a, b, c are nearly
degenerate (|corr| > 0.99), the curve is what the data pin down. The mean of
per-realisation peaks <max_t v_k> is drawn too: a different quantity that decays much more
weakly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ... import analysis
from ...units import rescaled_attrs
from ._style import COLORS, MARKERS, VELOCITY_UNITS, panel_pair


@dataclass(frozen=True, eq=False)
class Fig2Data:
    chains: tuple
    main: str  # the chain the paper fits (effective)
    peaks: dict  # chain -> analysis.PulsePeak
    mean_peaks: dict  # chain -> analysis.PerGranule
    fit_k: dict  # chain -> analysis.PulseFit (v vs k)
    fit_t: dict  # chain -> analysis.PulseFit (v vs t)
    agreement: dict  # chain -> analysis.CurveAgreement with the paper's curve
    fit_range: tuple
    realizations: int

    def to_dataset(self):
        import xarray as xr

        ds = xr.Dataset(attrs={"figure": "paper Fig. 2", "fit_range_k": list(self.fit_range), "realizations": self.realizations,
                               "fit": "unweighted least squares", "main_chain": self.main})
        for c in self.chains:
            p, m = self.peaks[c], self.mean_peaks[c]
            ds = ds.assign_coords(granule=("granule", p.granule, {"long_name": "large granule index k (1-based)", "units": "1"}))
            ds[f"{c}_averaged_pulse_peak"] = ("granule", p.velocity, {"long_name": f"max_t <v_k(t)>, {c}", **rescaled_attrs("velocity")})
            ds[f"{c}_averaged_pulse_peak_stderr"] = ("granule", p.velocity_stderr, rescaled_attrs("velocity"))
            ds[f"{c}_averaged_pulse_peak_time"] = ("granule", p.time, {"long_name": f"argmax_t <v_k(t)>, {c}", **rescaled_attrs("time")})
            ds[f"{c}_mean_peak_velocity"] = ("granule", m.value, {"long_name": f"<max_t v_k>, {c}", **rescaled_attrs("velocity")})
            for name, fit in (("k", self.fit_k[c]), ("t", self.fit_t[c])):
                ds.attrs[f"{c}_fit_{name}_abc"] = list(fit.params)
                ds.attrs[f"{c}_fit_{name}_abc_stderr"] = list(fit.stderr)
                ds.attrs[f"{c}_fit_{name}_error_method"] = fit.method
        return ds


def _range(ds, fit_range):
    N = int(ds.sizes["granule"])
    lo, hi = fit_range if fit_range is not None else (4, N - 1)
    return (max(2, int(lo)), min(N - 1, int(hi)))


def compute(ds, fit_range=(4, 25), sums=None) -> Fig2Data:
    """Averaged-pulse peaks, per-realisation mean peaks, unweighted fits and the curve comparison.

    ``fit_range`` (inclusive, in k) is clipped to 2..N-1. ``sums``: the store's per-chunk sums
    (:meth:`granchain.analysis.ChunkSums.from_store`) for jackknife errors.
    """
    rng = _range(ds, fit_range)
    chains = tuple(str(c) for c in ds["chain"].values)
    main = "effective" if "effective" in chains else chains[0]
    peaks, means, fk, ft, agree = {}, {}, {}, {}, {}
    for c in chains:
        peaks[c] = analysis.averaged_pulse_peak(ds, c)
        means[c] = analysis.mean_peak_amplitude(ds, c)
        fk[c] = analysis.fit_averaged_decay(ds, c, rng, sums, variable="k")
        ft[c] = analysis.fit_averaged_decay(ds, c, rng, sums, variable="t")
        agree[c] = analysis.paper_curve_agreement(ds, c, rng, sums, fit=fk[c])  # the curves of fit_k's replicates
    return Fig2Data(chains, main, peaks, means, fk, ft, agree, rng, int(ds.sizes["realization"]))


def _fit_label(prefix, fit, primes=""):
    (a, b, c), (ea, eb, ec) = fit.params, fit.stderr
    return fr"{prefix}: $a{primes}$={a:.3f}({ea * 1e3:.0f}), $b{primes}$={b:.4f}({eb * 1e4:.0f}), $c{primes}$={c:.3f}({ec * 1e3:.0f})"


def plot(data: Fig2Data, ax=None):
    """Main panel (amplitude vs k, inset vs time) over a panel of deviations from the paper's curve.

    ``ax``: optional pair (main, lower) of axes.
    """
    fig, ax, low = panel_pair(ax, figsize=(7.4, 7.6), height_ratios=(2.3, 1))
    lo, hi = data.fit_range
    main = data.main
    for c in data.chains:
        p = data.peaks[c]
        inside = (p.granule >= lo) & (p.granule <= hi)
        face = COLORS[c] if c == "decorated" else "white"
        ax.errorbar(p.granule[inside], p.velocity[inside], p.velocity_stderr[inside], fmt=MARKERS[c], ms=5, mfc=face,
                    color=COLORS[c], label=fr"$\mathrm{{max}}_t\langle v_k\rangle$, {c} chain (fitted)", zorder=3)
        ax.plot(p.granule[~inside], p.velocity[~inside], MARKERS[c], ms=5, mfc="none", color="0.6",
                label=f"not fitted ({c}): k = 1 struck, k = N free end" if c == main else None)
        m = data.mean_peaks[c]
        ax.plot(m.granule, m.value, ls="--" if c == "decorated" else "-.", marker=".", ms=3, lw=1, color=COLORS[c],
                label=fr"$\langle\mathrm{{max}}_t v_k\rangle$ (mean of per-realisation peaks), {c}")
    k = np.linspace(lo, hi, 200)
    fit = data.fit_k[main]
    ax.plot(k, fit.fit(k), color=COLORS["fit"], lw=2, label=_fit_label(f"fit, {main}, k = {lo}..{hi}", fit))
    ax.plot(k, analysis.stretched_exp(k, *analysis.PAPER_FIG2), color=COLORS["paper"], ls=":", lw=2.2,
            label="paper: a = 0.756, b = 0.067, c = 0.714")
    ax.set_ylabel(r"pulse amplitude $\mathrm{max}_t\langle v_k(t)\rangle$ " + VELOCITY_UNITS)
    N = len(data.peaks[main].granule)
    ax.set_title(f"Amplitude decay of the averaged pulse, N = {N} ({data.realizations} realisations)", fontsize=10)
    ax.set_ylim(0, 1.12)
    ax.legend(loc="upper right", fontsize=7, frameon=False, ncols=1)
    ax.tick_params(labelbottom=True)
    ax.set_xlabel(r"large-granule index $k$")

    inset = ax.inset_axes([0.08, 0.07, 0.34, 0.33])
    p = data.peaks[main]
    sel = (p.granule >= lo) & (p.granule <= hi)
    inset.errorbar(p.time[sel], p.velocity[sel], p.velocity_stderr[sel], fmt=MARKERS[main], ms=2.5, mfc="white",
                   color=COLORS[main], lw=0.8, label=main)
    ft = data.fit_t[main]
    t = np.linspace(p.time[sel].min(), p.time[sel].max(), 200)
    inset.plot(t, ft.fit(t), color=COLORS["fit"], lw=1.5, label=fr"fit: $a'$={ft.params[0]:.3f}, $b'$={ft.params[1]:.4f}, $c'$={ft.params[2]:.3f}")
    inset.plot(t, analysis.stretched_exp(t, *analysis.PAPER_FIG2_INSET), color=COLORS["paper"], ls=":", lw=1.8,
               label="paper: 0.744, 0.035, 0.714")
    inset.set_xlabel(r"peak time $t$ (rescaled)", fontsize=7)
    inset.set_ylabel(r"$\mathrm{max}_t\langle v\rangle$", fontsize=7)
    inset.tick_params(labelsize=6)
    inset.legend(fontsize=5.5, frameon=False, loc="upper right")
    inset.set_ylim(None, inset.get_ylim()[1] + 0.45 * np.ptp(inset.get_ylim()))

    for c in data.chains:
        g = data.agreement[c]
        p = data.peaks[c]
        sel = (p.granule >= lo) & (p.granule <= hi)
        ref = analysis.stretched_exp(p.granule[sel].astype(float), *analysis.PAPER_FIG2)
        face = COLORS[c] if c == "decorated" else "white"
        low.errorbar(p.granule[sel], 100 * (p.velocity[sel] / ref - 1), 100 * p.velocity_stderr[sel] / ref, fmt=MARKERS[c],
                     ms=4, mfc=face, color=COLORS[c], lw=0.8, label=f"data, {c}")
        low.plot(g.granule, 100 * g.deviation, color=COLORS[c], lw=1.5, ls="-" if c == main else "--",
                 label=f"unweighted fit, {c}: max {100 * g.max_relative:.2f} % at k = {g.granule[g.worst]}")
        if c == main:
            low.fill_between(g.granule, 100 * (g.deviation - 2 * g.stderr), 100 * (g.deviation + 2 * g.stderr),
                             color=COLORS["fit"], alpha=0.3, lw=0, label=f"fit, {c}: ±2 s.e. ({'jackknife' if 'jackknife' in g.method else 'fit residuals'})")
    g = data.agreement[main]
    low.fill_between(g.granule, -100 * g.envelope, 100 * g.envelope, facecolor="none", edgecolor=COLORS["paper"], hatch="////", lw=0,
                     label="paper's curve within its printed digits (±0.0005 each)")
    low.axhline(0, color=COLORS["paper"], ls=":", lw=1.5)
    low.set_xlabel(r"large-granule index $k$")
    low.set_ylabel("relative to the paper's\ncurve (%)")
    low.legend(fontsize=6.5, frameon=False, loc="upper left", ncols=2)
    ylo, yhi = low.get_ylim()
    low.set_ylim(ylo, yhi + 0.7 * (yhi - ylo))
    return fig
