"""Paper Fig. 1: averaged velocity profile <v_k(t)> of the large granules, N = 11,
decorated chain with its effective chain overlaid (black continuous curves)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...units import rescaled_attrs
from ._style import COLORS, TIME_LABEL, VELOCITY_UNITS, axes


@dataclass(frozen=True, eq=False)
class Fig1Data:
    time: np.ndarray
    granule: np.ndarray
    decorated: np.ndarray  # (granule, time)
    effective: np.ndarray | None
    realizations: int

    def to_dataset(self):
        import xarray as xr

        ds = xr.Dataset(coords={"granule": ("granule", self.granule, {"long_name": "large granule index k (1-based)", "units": "1"}), "time": ("time", self.time, rescaled_attrs("time"))},
                        attrs={"figure": "paper Fig. 1", "realizations": self.realizations})
        ds["decorated"] = (("granule", "time"), self.decorated, {"long_name": "<v_k(t)>, decorated chain", **rescaled_attrs("velocity")})
        if self.effective is not None:
            ds["effective"] = (("granule", "time"), self.effective, {"long_name": "<v_k(t)>, effective chain", **rescaled_attrs("velocity")})
        return ds


def compute(ds, granules=None) -> Fig1Data:
    """<v_k(t)> of the granules (default: all) from an ensemble Dataset (``run_ensemble``)."""
    sel = ds if granules is None else ds.sel(granule=list(granules))
    mv = sel["mean_velocity"].transpose("chain", "granule", "time")
    chains = list(sel["chain"].values)
    if "decorated" not in chains:
        raise ValueError("Fig. 1 needs the decorated chain in the Dataset (run_ensemble(..., chains='both'))")
    eff = mv.sel(chain="effective").values if "effective" in chains else None
    return Fig1Data(sel["time"].values, sel["granule"].values, mv.sel(chain="decorated").values, eff, int(ds.sizes["realization"]))


def plot(data: Fig1Data, ax=None):
    """<v_k(t)> per granule, colour coded by k (colour bar), effective chain in thin black; a bar where a
    granule's averaged-pulse window ends (ensembles with windows: NaN after it)."""
    import matplotlib as mpl

    fig, ax = axes(ax, figsize=(7.4, 4.6))
    cmap = mpl.colormaps["viridis"]
    K = len(data.granule)
    norm = mpl.colors.Normalize(vmin=float(data.granule[0]), vmax=float(data.granule[-1]))
    ended = False
    for i, k in enumerate(data.granule):
        ax.plot(data.time, data.decorated[i], color=cmap(norm(k)), lw=1.8)
        recorded = np.flatnonzero(np.isfinite(data.decorated[i]))
        if recorded.size and recorded[-1] < data.time.size - 1:  # the granule's averaged-pulse window closed there
            last = recorded[-1]
            ax.plot(data.time[last], data.decorated[i, last], marker="|", ms=7, mew=1.2, color=cmap(norm(k)))
            ended = True
        if data.effective is not None:
            ax.plot(data.time, data.effective[i], color=COLORS["effective"], lw=0.7, ls="-")
        j = int(np.nanargmax(data.decorated[i]))
        if K <= 30:
            ax.annotate(f"{k}", (data.time[j], data.decorated[i, j]), textcoords="offset points", xytext=(0 if j else 5, 3),
                        ha="center" if j else "left", fontsize=7)
    # legend: one entry per kind of curve (the colour of each granule is on the colour bar)
    ax.plot([], [], color=cmap(0.5), lw=1.8, label="decorated chain (colour: granule k)")
    if data.effective is not None:
        ax.plot([], [], color=COLORS["effective"], lw=0.7, label="effective chain (black)")
    if ended:
        ax.plot([], [], ls="", marker="|", ms=7, mew=1.2, color="0.3", label="end of the granule's averaged-pulse window")
    ax.set_xlabel(TIME_LABEL)
    ax.set_ylabel(r"averaged velocity $\langle v_k(t)\rangle$ " + VELOCITY_UNITS)
    ax.set_title(f"Averaged velocity of the large granules, N = {K} ({data.realizations} realisations)", fontsize=10)
    span = data.time[-1] - data.time[0]
    ax.set_xlim(data.time[0] - 0.01 * span, data.time[-1])
    low = np.nanmin([np.nanmin(data.decorated)] + ([] if data.effective is None else [np.nanmin(data.effective)]))
    ax.set_ylim(min(-0.02, low - 0.03), 1.12)
    ax.legend(loc="upper left", bbox_to_anchor=(0.12, 1.0), frameon=False, fontsize=8)  # above the peaks, right of the struck granule
    cb = fig.colorbar(mpl.cm.ScalarMappable(norm=norm, cmap=cmap), ax=ax, pad=0.01)
    cb.set_label("large-granule index $k$ (label at each peak)")
    return fig
