"""Paper Fig. 4: distributions of the arrival time of the pulse at large granule N-1
(decorated index 2N-3) for N = 6, 11, 16, 26, panels in the paper's order (N = 6 upper left,
then clockwise: 11 upper right, 16 lower right, 26 lower left); numerics versus the BCA
Monte Carlo distribution of Eq. (total-time) over the same realisations, the BCA sample
shifted by the stated amount as the paper does. Histograms are steps over a common range per
panel, the central 99.9 % of both samples (the few values outside are counted in the panel).
A side column shows the KS distance d of the standardised numerical sample to N(0, 1)
(Eq. AD) and the skewness (moment and quantile) versus N.

Sign convention: ``shift`` = numerical mode - BCA mode. A positive shift means the BCA
arrives *earlier* than the numerics (the paper's text says its theory gives later peak
positions). ``width_ratio`` = std(BCA) / std(numerics). Errors: jackknife over
``n_blocks`` contiguous blocks of realisations (numerics and BCA of the same chains
together, so their correlation is kept).
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from ... import analysis, bca
from ._style import COLORS, TIME_LABEL

#: Grid cells (row, column) of the paper's panel order: upper left, then clockwise.
CLOCKWISE = ((0, 0), (0, 1), (1, 1), (1, 0))


@dataclass(frozen=True, eq=False)
class Fig4Panel:
    N: int
    granule: int
    numerics: np.ndarray  # per valid realisation
    theory: np.ndarray  # unshifted BCA sample, same realisations, same order
    shifted: "bca.ShiftedSample"
    hist_numerics: "analysis.Histogram"
    hist_theory: "analysis.Histogram"  # of the shifted theory sample
    outside: tuple  # (numerics, theory) counts outside the histogram range
    ks: "analysis.KSResult"  # numerics
    ks_theory: "analysis.KSResult"
    stats: dict  # name -> analysis.Jackknife: shift, width_ratio, mean/std numerics and BCA, skewness, quantile_skewness, d


@dataclass(frozen=True, eq=False)
class Fig4Data:
    chain: str
    shift_method: str
    coverage: float
    panels: tuple

    def to_dataset(self):
        import xarray as xr

        Ns = [p.N for p in self.panels]
        ds = xr.Dataset(coords={"N": Ns}, attrs={"figure": "paper Fig. 4", "chain": self.chain, "shift_method": self.shift_method,
                                                 "histogram_range": f"central {self.coverage:.1%} of both samples",
                                                 "shift_sign": "numerics - BCA; > 0: the BCA arrives earlier"})
        ds["ks_d"] = ("N", [p.ks.d for p in self.panels], {"long_name": "KS distance of the standardised arrival times to N(0,1), Eq. (AD)"})
        ds["ks_pvalue_lilliefors"] = ("N", [p.ks.pvalue for p in self.panels], {"note": "1/(B+1) means < 1/(B+1)"})
        ds["ks_d_bca"] = ("N", [p.ks_theory.d for p in self.panels])
        for name, st in self.panels[0].stats.items():
            ds[name] = ("N", [float(p.stats[name].value) for p in self.panels])
            ds[f"{name}_stderr"] = ("N", [float(p.stats[name].stderr) for p in self.panels], {"method": st.method})
        for p in self.panels:
            ds[f"hist_edges_N{p.N}"] = (f"edge_N{p.N}", p.hist_numerics.edges)
            ds[f"hist_numerics_N{p.N}"] = (f"bin_N{p.N}", p.hist_numerics.values)
            ds[f"hist_bca_shifted_N{p.N}"] = (f"bin_N{p.N}", p.hist_theory.values)
        return ds


def _shift(method):
    def f(num, th):
        return bca.shift_peak(th, num, method=method).shift
    return f


STATISTICS = {
    "mean_numerics": lambda num, th: np.mean(num),
    "mean_bca": lambda num, th: np.mean(th),
    "std_numerics": lambda num, th: np.std(num, ddof=1),
    "std_bca": lambda num, th: np.std(th, ddof=1),
    "width_ratio": lambda num, th: np.std(th, ddof=1) / np.std(num, ddof=1),
    "iqr_ratio": lambda num, th: np.subtract(*np.quantile(th, [0.75, 0.25])) / np.subtract(*np.quantile(num, [0.75, 0.25])),
    "skewness": lambda num, th: analysis.skewness(num),
    "quantile_skewness": lambda num, th: analysis.quantile_skewness(num),
    "skewness_bca": lambda num, th: analysis.skewness(th),
    "quantile_skewness_bca": lambda num, th: analysis.quantile_skewness(th),
    "ks_d": lambda num, th: analysis.ks_distance(num),
}


def compute(datasets, chain: str = "decorated", shift: str = "mode", bins: int = 60, n_mc_samples: int = 500,
            coverage: float = 0.999, n_blocks: int = 20) -> Fig4Data:
    """Panels for each ensemble Dataset in ``datasets`` (a mapping N -> Dataset, or a sequence).

    ``shift``: "mode" (the paper: theory peak moved onto the numerical peak), "mean", or None.
    The BCA sample uses the Dataset's own small radii, so theory and numerics describe the
    same chains (realisations with a failed integration are left out of both).
    """
    if not 0 < coverage <= 1:
        raise ValueError(f"coverage must lie in (0, 1], got {coverage!r}")
    items = datasets.values() if hasattr(datasets, "values") else datasets
    stats = dict(STATISTICS, shift=_shift("mode" if shift is None else shift))
    parts = []
    for ds in sorted(items, key=lambda d: int(d.sizes["granule"])):
        N = int(ds.sizes["granule"])
        if N < 3:
            raise ValueError(f"Fig. 4 needs N >= 3 (arrival at granule N-1 > 1), got N = {N}")
        sub = ds.sel(chain=chain)
        t_all = sub["peak_time"].sel(granule=N - 1).values.astype(float)
        radii = ds["small_radius"].values
        ok = (sub["status"].values == 0) & np.isfinite(t_all) & np.all(np.isfinite(radii), axis=1)
        num = t_all[ok]
        mc = bca.monte_carlo_arrival_times(N, small_radii=radii[ok], n=float(ds.attrs.get("n", 2.5)))
        theory = mc.at(N - 1)
        if shift is None:
            shifted = bca.ShiftedSample(theory, 0.0, "none", float("nan"), float("nan"))
        else:
            shifted = bca.shift_peak(theory, num, method=shift)
        tail = 0.5 * (1 - coverage)
        lo, hi = np.quantile(np.concatenate([num, shifted.sample]), [tail, 1 - tail])
        hn = analysis.histogram(num, bins=bins, range=(lo, hi))
        ht = analysis.histogram(shifted.sample, bins=bins, range=(lo, hi))
        outside = (int(num.size - hn.counts.sum()), int(theory.size - ht.counts.sum()))
        g = max(2, min(int(n_blocks), num.size // 2))
        jk = {name: analysis.block_jackknife(f, num, theory, n_blocks=g) for name, f in stats.items()}
        parts.append((N, num, theory, shifted, hn, ht, outside, jk))
    # The Lilliefors Monte Carlo (~0.5 s per panel at 30,000 values and B = 1000) on every core: its
    # sampling, sorting and normal CDF run in NumPy and SciPy without the GIL, and each panel's
    # resamples come from their own seeded generator, so the p-values do not depend on the threads.
    with ThreadPoolExecutor(max_workers=max(1, min(len(parts), os.cpu_count() or 1))) as pool:
        ks = list(pool.map(lambda part: analysis.ks_normal(part[1], n_mc_samples=n_mc_samples), parts))
    panels = tuple(Fig4Panel(N, N - 1, num, theory, shifted, hn, ht, outside, ks_num, analysis.ks_normal(theory, n_mc_samples=0), jk)
                   for (N, num, theory, shifted, hn, ht, outside, jk), ks_num in zip(parts, ks))
    return Fig4Data(chain, "none" if shift is None else shift, float(coverage), panels)


def plot(data: Fig4Data, ax=None):
    """Histogram panels in the paper's clockwise order, d and skewness versus N on the right.

    ``ax``: optional sequence of len(panels) + 2 axes (histograms in panel order, then the
    d-vs-N and skewness-vs-N axes).
    """
    import matplotlib.pyplot as plt

    P = len(data.panels)
    if ax is None:
        if P > 4:
            raise ValueError("the default layout has room for 4 chain lengths; pass ax with len(panels) + 2 axes")
        fig = plt.figure(figsize=(12.0, 7.6), layout="constrained")
        grid = fig.add_gridspec(2, 3, width_ratios=[1, 1, 0.75])
        axs = [fig.add_subplot(grid[r, c]) for r, c in CLOCKWISE[:P]]
        axs += [fig.add_subplot(grid[0, 2]), fig.add_subplot(grid[1, 2])]
    else:
        axs = list(ax)
        fig = axs[0].figure
    for a, p in zip(axs, data.panels):
        hn, ht = p.hist_numerics, p.hist_theory
        a.stairs(ht.values, ht.edges, fill=True, color=COLORS["bca"], alpha=0.25, lw=0)
        a.stairs(ht.values, ht.edges, color=COLORS["bca"], lw=1.2, label="BCA, Eq. (total-time), shifted" if p is data.panels[0] else None)
        a.stairs(hn.values, hn.edges, color=COLORS["decorated"], lw=1.6, label=f"numerics ({data.chain} chain)" if p is data.panels[0] else None)
        s, w = p.stats["shift"], p.stats["width_ratio"]
        text = (f"n = {p.numerics.size}\nBCA shifted by {s.value:+.3f} ± {s.stderr:.3f}\n"
                f"({'BCA arrives earlier' if s.value > 0 else 'BCA arrives later'})\n"
                f"width BCA / numerics = {w.value:.3f} ± {w.stderr:.3f}\n"
                f"outside the range: {p.outside[0]} | {p.outside[1]}")
        a.text(0.98, 0.97, text, transform=a.transAxes, ha="right", va="top", fontsize=7, linespacing=1.3)
        a.set_title(f"N = {p.N}: arrival at large granule {p.granule} (index {2 * p.N - 3}), d = {p.ks.d:.4f}", fontsize=9)
        a.set_xlabel(TIME_LABEL, fontsize=8)
        a.set_ylabel("probability density\n(1 / rescaled time)", fontsize=8)
        a.set_ylim(0, 1.55 * max(hn.values.max(), ht.values.max()))
        a.set_xlim(hn.edges[0], hn.edges[-1])
    handles, labels = axs[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside upper center", ncols=2, fontsize=9, frameon=False,
               title=f"arrival-time densities; step histograms over the central {data.coverage:.1%} of both samples",
               title_fontsize=9)
    Ns = [p.N for p in data.panels]
    a = axs[P]
    a.errorbar(Ns, [p.ks.d for p in data.panels], [p.stats["ks_d"].stderr for p in data.panels], fmt="o-",
               color=COLORS["decorated"], label="numerics")
    a.plot(Ns, [p.ks_theory.d for p in data.panels], "s--", color=COLORS["bca"], mfc="white", label="BCA, Eq. (total-time)")
    a.set_xlabel(r"chain length $N$ (large granules)")
    a.set_ylabel(r"KS distance $d$ to $N(0,1)$")
    a.set_title("Approach to a Gaussian, Eq. (AD)", fontsize=9)
    a.set_ylim(0, None)
    a.legend(fontsize=7, frameon=False)
    a = axs[P + 1]
    for key, style, label in (("skewness", "o-", "moment skewness (G1)"), ("quantile_skewness", "D-", "quantile skewness (Bowley)")):
        a.errorbar(Ns, [p.stats[key].value for p in data.panels], [p.stats[key].stderr for p in data.panels], fmt=style,
                   color=COLORS["decorated"], mfc="white" if key == "quantile_skewness" else None, label=f"{label}, numerics")
        a.plot(Ns, [p.stats[key + "_bca"].value for p in data.panels], style.replace("-", "--"), color=COLORS["bca"],
               mfc="white" if key == "quantile_skewness" else None, ms=4, label=f"{label}, BCA")
    a.axhline(0, color="0.6", lw=0.8)
    a.set_xlabel(r"chain length $N$ (large granules)")
    a.set_ylabel("skewness of the arrival times")
    a.set_title("Asymmetry (± jackknife s.e.)", fontsize=9)
    a.legend(fontsize=6.5, frameon=False)
    return fig
