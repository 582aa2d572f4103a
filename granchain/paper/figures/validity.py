"""Validity maps: heat maps over the small-radius range [alpha, beta] of how far the
effective chain and the BCA are from the decorated chain, with the 1 % and 5 % contours.

``compute(out, ...)`` runs (or resumes) :func:`granchain.paper.validity.validity_map`; ``plot(ds)`` draws
one panel per measure (rows) and N (columns).
"""

from __future__ import annotations

import numpy as np

from .. import validity

#: The measures drawn by default: (variable, colour-bar label, reference): |variable - reference| in %.
PANELS = (
    ("arrival_time_error_effective", "effective: mean arrival time error (%)", 0.0),
    ("averaged_pulse_peak_error_effective", r"effective: $\mathrm{max}_t\,\langle v_k\rangle$ error (%)", 0.0),
    ("mean_peak_error_effective", r"effective: $\langle \mathrm{max}_t\, v_k\rangle$ error (%)", 0.0),
    ("arrival_time_error_bca", "BCA: mean arrival time error (%)", 0.0),
    ("arrival_time_width_ratio_bca", "BCA: arrival-time width error (%)", 1.0),
)


def compute(out, **kwargs):
    """The validity map Dataset (``granchain.paper.validity.validity_map(out, **kwargs)``)."""
    return validity.validity_map(out, **kwargs)


def plot(ds, ax=None, panels=PANELS):
    """Heat maps of |measure - reference| (in %) vs (alpha, beta), with its 1 % and 5 % contours.

    ``ax``: an array of axes of shape (len(panels), n_large) or None (a new figure). Returns the figure.
    """
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    Ns = [int(n) for n in ds["n_large"].values]
    if ax is None:
        fig, ax = plt.subplots(len(panels), len(Ns), figsize=(4.2 * len(Ns), 3.2 * len(panels)), constrained_layout=True,
                               squeeze=False)
    else:
        ax = np.asarray(ax).reshape(len(panels), len(Ns))
        fig = ax[0, 0].figure
    a, b = ds["alpha"].values, ds["beta"].values
    for r, (name, label, ref) in enumerate(panels):
        vals = np.abs(ds[name].values - ref) * 100.0
        finite = vals[np.isfinite(vals) & (vals > 0)]
        norm = LogNorm(vmin=max(finite.min(), 1e-2), vmax=max(finite.max(), 10.0)) if finite.size else None
        for c, N in enumerate(Ns):
            axc = ax[r, c]
            z = vals[:, :, c].T  # (beta, alpha)
            mesh = axc.pcolormesh(a, b, np.ma.masked_invalid(z), shading="nearest", cmap="viridis", norm=norm)
            if np.sum(np.isfinite(z)) >= 4 and a.size > 1 and b.size > 1:
                with np.errstate(invalid="ignore"):
                    cs = axc.contour(a, b, np.where(np.isfinite(z), z, np.nan), levels=[1.0, 5.0], colors=["white", "red"],
                                     linewidths=1.5)
                axc.clabel(cs, fmt={1.0: "1%", 5.0: "5%"}, fontsize=7)
            axc.axhline(0.4, color="0.7", lw=0.8, ls=":")
            axc.set_xlabel(r"smallest small radius $\alpha$")
            axc.set_ylabel(r"largest small radius $\beta$")
            axc.set_title(f"N = {N}", fontsize=9)
            fig.colorbar(mesh, ax=axc, label=label)
    return fig
