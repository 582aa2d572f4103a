"""Paper Fig. 4: distributions of the arrival time of the pulse at large granule N-1
(decorated index 2N-3) for N = 6, 11, 16, 26; numerics (empty circles) versus the BCA
Monte Carlo distribution of Eq. (total-time) over the same realisations (filled circles),
shifted as the paper does (the shift is stated in the legend); and the KS distance d of
the standardised numerical sample to N(0, 1) (Eq. AD) versus N.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import analysis, bca
from ._style import COLORS, TIME_LABEL


@dataclass(frozen=True, eq=False)
class Fig4Panel:
    N: int
    granule: int
    numerics: np.ndarray
    theory: np.ndarray  # unshifted BCA sample (same realisations)
    shifted: "bca.ShiftedSample"
    hist_numerics: "analysis.Histogram"
    hist_theory: "analysis.Histogram"  # of the shifted theory sample
    ks: "analysis.KSResult"  # numerics
    ks_theory: "analysis.KSResult"


@dataclass(frozen=True, eq=False)
class Fig4Data:
    chain: str
    shift_method: str
    panels: tuple

    def to_dataset(self):
        import xarray as xr

        Ns = [p.N for p in self.panels]
        ds = xr.Dataset(coords={"N": Ns}, attrs={"figure": "paper Fig. 4", "chain": self.chain, "shift_method": self.shift_method})
        ds["ks_d"] = ("N", [p.ks.d for p in self.panels], {"long_name": "KS distance of the standardised arrival times to N(0,1), Eq. (AD)"})
        ds["ks_pvalue_lilliefors"] = ("N", [p.ks.pvalue for p in self.panels])
        ds["skewness"] = ("N", [p.ks.skewness for p in self.panels])
        ds["ks_d_bca"] = ("N", [p.ks_theory.d for p in self.panels])
        ds["bca_shift"] = ("N", [p.shifted.shift for p in self.panels], {"long_name": "shift applied to the BCA sample (numerics - theory)", "units": "rescaled time"})
        ds["mean_arrival_numerics"] = ("N", [float(np.mean(p.numerics)) for p in self.panels], {"units": "rescaled time"})
        ds["mean_arrival_bca"] = ("N", [float(np.mean(p.theory)) for p in self.panels], {"units": "rescaled time"})
        ds["std_arrival_numerics"] = ("N", [float(np.std(p.numerics, ddof=1)) for p in self.panels], {"units": "rescaled time"})
        ds["std_arrival_bca"] = ("N", [float(np.std(p.theory, ddof=1)) for p in self.panels], {"units": "rescaled time"})
        for p in self.panels:
            ds[f"hist_centres_N{p.N}"] = (f"bin_N{p.N}", p.hist_numerics.centres)
            ds[f"hist_numerics_N{p.N}"] = (f"bin_N{p.N}", p.hist_numerics.values)
            ds[f"hist_bca_shifted_N{p.N}"] = (f"bin_N{p.N}", p.hist_theory.values)
        return ds


def compute(datasets, chain: str = "decorated", shift: str = "mode", bins: int = 50, n_mc_samples: int = 500) -> Fig4Data:
    """Panels for each ensemble Dataset in ``datasets`` (a mapping N -> Dataset, or a sequence).

    ``shift``: "mode" (the paper: theory peak moved onto the numerical peak), "mean", or
    None (no shift). The BCA sample uses the Dataset's own small radii, so theory and
    numerics describe the same chains.
    """
    items = datasets.values() if hasattr(datasets, "values") else datasets
    panels = []
    for ds in sorted(items, key=lambda d: int(d.sizes["granule"])):
        N = int(ds.sizes["granule"])
        if N < 3:
            raise ValueError(f"Fig. 4 needs N >= 3 (arrival at granule N-1 > 1), got N = {N}")
        num = analysis.arrival_times(ds, chain, granule=N - 1)
        ok = (ds["status"].sel(chain=chain).values == 0) & np.all(np.isfinite(ds["small_radius"].values), axis=1)
        mc = bca.monte_carlo_arrival_times(N, small_radii=ds["small_radius"].values[ok], n=float(ds.attrs.get("n", 2.5)))
        theory = mc.at(N - 1)
        if shift is None:
            shifted = bca.ShiftedSample(theory, 0.0, "none", float("nan"), float("nan"))
        else:
            shifted = bca.shift_peak(theory, num, method=shift)
        lo = min(num.min(), shifted.sample.min())
        hi = max(num.max(), shifted.sample.max())
        hn = analysis.histogram(num, bins=bins, range=(lo, hi))
        ht = analysis.histogram(shifted.sample, bins=bins, range=(lo, hi))
        panels.append(Fig4Panel(N, N - 1, num, theory, shifted, hn, ht,
                                analysis.ks_normal(num, n_mc_samples=n_mc_samples),
                                analysis.ks_normal(theory, n_mc_samples=0)))
    return Fig4Data(chain, "none" if shift is None else shift, tuple(panels))


def plot(data: Fig4Data, ax=None):
    """Histogram panels (2 x 2 for four N) and d versus N; ``ax``: optional sequence of len(panels) + 1 axes."""
    import matplotlib.pyplot as plt

    P = len(data.panels)
    if ax is None:
        fig = plt.figure(figsize=(11.0, 6.8), constrained_layout=True)
        grid = fig.add_gridspec(2, 3, width_ratios=[1, 1, 0.8])
        cells = [grid[i // 2, i % 2] for i in range(min(P, 4))]
        axs = [fig.add_subplot(c) for c in cells] + [fig.add_subplot(grid[:, 2])]
        if P > 4:
            raise ValueError("the default layout has room for 4 chain lengths; pass ax with len(panels) + 1 axes")
    else:
        axs = list(ax)
        fig = axs[0].figure
    for a, p in zip(axs, data.panels):
        a.plot(p.hist_numerics.centres, p.hist_numerics.values, "o", mfc="none", color=COLORS["decorated"], ms=4,
               label=f"numerics ({data.chain}), n = {p.numerics.size}")
        a.plot(p.hist_theory.centres, p.hist_theory.values, "o", color=COLORS["bca"], ms=3,
               label=f"BCA Eq. (total-time), shifted by {p.shifted.shift:+.3f}")
        a.set_title(f"N = {p.N}: arrival at large granule {p.granule} (index {2 * p.N - 3}); d = {p.ks.d:.4f}", fontsize=9)
        a.set_xlabel(TIME_LABEL, fontsize=8)
        a.set_ylabel("probability density", fontsize=8)
        a.legend(fontsize=7, frameon=False)
    a = axs[-1]
    Ns = [p.N for p in data.panels]
    a.plot(Ns, [p.ks.d for p in data.panels], "o-", color=COLORS["decorated"], label="numerics")
    a.plot(Ns, [p.ks_theory.d for p in data.panels], "s--", color=COLORS["bca"], mfc="none", label="BCA (Eq. total-time)")
    a.set_xlabel(r"chain length $N$ (large granules)")
    a.set_ylabel(r"KS distance $d$ to $N(0,1)$ of the standardised sample")
    a.set_title("Approach to a Gaussian (Eq. AD)", fontsize=9)
    a.legend(fontsize=8, frameon=False)
    return fig
