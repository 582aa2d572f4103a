"""The first picture of a pulse: velocity (or force) traces of chosen granules, and the space-time diagram.

:func:`plot_pulse` draws a :class:`~granchain.PulseResult` (``result.plot(...)`` calls it);
:func:`granchain.analysis.plot_averaged_pulse` draws an ensemble's averaged pulse <v_k(t)> with the same
drawing functions (:func:`draw_traces`, :func:`draw_spacetime`), so both look alike.

* ``kind="traces"``: v_k(t) of a few granules, one line each, labelled by granule.
* ``kind="spacetime"``: granule against time, coloured by the velocity (a diverging map centred on 0:
  granules behind the pulse move backwards) or by the force (a sequential map: contacts only push).

What is drawn is what the result recorded on its time grid, nothing is re-integrated: velocities need
``simulate(..., t_grid=...)``; forces need sensors too, ``simulate(..., t_grid=..., sensors=force_sensors(chain))``.
The force of a granule is the mean of its two contact forces, what a gauge embedded in it reads
(``PulseResult.sensor_force``; C. Daraio et al., Phys. Rev. E 73, 026610 (2006)), so both quantities
have one row per granule. The struck granule and a free last granule have one contact only and no
such force.

Units: the paper's rescaled units (Sec. II), named as such on the axes, or SI with ``scale=``
(a :class:`granchain.units.Scale`): time in s/ms/us, velocity in m/s, force in N (prefixes chosen
for the data's size). matplotlib is imported when a figure is drawn, never by ``import granchain``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

__all__ = ["plot_pulse", "force_sensors", "granule_labels", "draw_traces", "draw_spacetime", "colormap", "Units",
           "check_figure_path", "FIGURE_FORMATS", "KINDS", "QUANTITIES"]

#: What ``kind`` may be.
KINDS = ("traces", "spacetime")
#: What ``quantity`` may be.
QUANTITIES = ("velocity", "force")
#: Figure files by extension (matplotlib writes each from the extension).
FIGURE_FORMATS = (".png", ".pdf", ".svg")
#: Traces drawn when no granules are chosen: enough to see the pulse travel and decay, few enough to read.
DEFAULT_TRACES = 7
#: Up to this many traces get a legend; more get a colour bar labelled by granule.
LEGEND_MAX = 10

_RESCALED = {
    "time": r"time $t$ (rescaled units, paper Sec. II)",
    "velocity": r"velocity $v_k$ (units of $V_1$, rescaled)",
    "force": r"granule force $F_k$ (units of $M_1 L/T^2$, rescaled)",
}
_NAMES = {"time": r"time $t$", "velocity": r"velocity $v_k$", "force": r"granule force $F_k$"}
_SI = {"time": "s", "velocity": "m/s", "force": "N"}
_PREFIXES = ((1e-9, "n"), (1e-6, "µ"), (1e-3, "m"), (1.0, ""), (1e3, "k"))


@dataclass(frozen=True)
class Units:
    """The SI size of one rescaled unit of time, velocity and force (s, m/s, N), or None for each
    to keep the paper's rescaled units. Made from a :class:`granchain.units.Scale`
    (:meth:`from_scale`) or from a store's ``physical_*`` attributes (``granchain ensemble --material``)."""

    time: float | None = None
    velocity: float | None = None
    force: float | None = None

    @classmethod
    def from_scale(cls, scale) -> "Units":
        """The units of a :class:`granchain.units.Scale` (None: rescaled)."""
        if scale is None:
            return cls()
        from ..units import Scale

        if not isinstance(scale, Scale):
            raise ValueError(f"scale must be a granchain.units.Scale (granchain.units.scale(material, radius, impact_speed)) "
                             f"or None for the paper's rescaled units, got {type(scale).__name__}")
        return cls(scale.time, scale.velocity, scale.force)

    def convert(self, kind: str, values, name: str | None = None):
        """(values in the display unit, axis label, display unit per rescaled unit): SI with a prefix
        fitting the data's size, or rescaled."""
        values = np.asarray(values, dtype=float)
        unit = getattr(self, kind)
        if unit is None:
            label = _RESCALED[kind] if name is None else _RESCALED[kind].replace(_NAMES[kind], name)
            return values, label, 1.0
        si = values * unit
        size = float(np.nanmax(np.abs(si))) if np.isfinite(si).any() else 1.0
        factor, prefix = 1.0, ""
        for f, p in _PREFIXES:  # the largest prefix that keeps the data's size >= 1 of it
            if size >= f:
                factor, prefix = f, p
        if kind != "time" and 1e-2 <= size < 1e4:  # 0.5 m/s and 80 N read better than 500 mm/s and 0.08 kN
            factor, prefix = 1.0, ""
        if kind == "velocity" and prefix not in ("", "m"):  # m/s and mm/s are what a reader expects of a speed
            factor, prefix = (1e-3, "m") if size < 1.0 else (1.0, "")
        return si / factor, f"{name or _NAMES[kind]} ({prefix}{_SI[kind]})", unit / factor


def check_figure_path(path, option: str = "path") -> str:
    """``path`` as a string, after checking that a figure can be written there: a known extension
    (:data:`FIGURE_FORMATS`) and an existing, writable directory. Checked before any run, so a long
    integration does not end in a failed save."""
    try:
        text = os.fsdecode(os.fspath(path))
    except TypeError:
        raise ValueError(f"{option} must be a file name such as pulse.png, got {type(path).__name__}") from None
    ext = os.path.splitext(text)[1].lower()
    if ext not in FIGURE_FORMATS:
        raise ValueError(f"{option} = {text!r}: the extension picks the format; end the name in "
                         f"{', '.join(FIGURE_FORMATS)} (e.g. pulse.png)")
    if os.path.isdir(text):
        raise ValueError(f"{option} = {text!r} is a directory; give a file name such as {os.path.join(text, 'pulse' + ext)}")
    folder = os.path.dirname(os.path.abspath(text))
    if not os.path.isdir(folder):
        raise ValueError(f"{option} = {text!r}: the directory {folder} does not exist; create it or write elsewhere")
    if not os.access(folder, os.W_OK) or (os.path.exists(text) and not os.access(text, os.W_OK)):
        raise ValueError(f"{option} = {text!r}: cannot write there (permission denied); choose a writable place")
    return text


def force_sensors(chain) -> list[int]:
    """The observed granules that have a contact on each side, as ``simulate(..., sensors=...)`` takes
    them: pass it with ``t_grid`` to record every granule force a force plot draws. Not the struck
    granule 1 (no contact behind it, unless a striker hits it) nor a free last granule."""
    last = chain.size - 1 - int(chain.wall)  # the last granule that moves (array index)
    idx = np.asarray(chain.observed)
    ok = (idx >= 1) & ((idx < last) | ((idx == last) & bool(chain.wall)))
    return [int(k) for k in chain.labels[ok]]


def granule_labels(chain, labels):
    """(display labels, axis name) for 1-based chain labels: a decorated chain's large granules are
    numbered k = 1..N (chain index 2k - 1), as its tables, ensembles and the paper number them."""
    labels = np.asarray(labels, dtype=np.int64)
    wall = int(chain.wall)
    large = np.arange(0, chain.size - wall, 2)
    if chain.kind == "decorated" and not chain.striker and np.array_equal(np.asarray(chain.observed), large):
        return (labels + 1) // 2, r"large granule $k$"
    return labels, "granule"


def _check_choice(name: str, value, choices) -> str:
    if not isinstance(value, str) or value not in choices:
        raise ValueError(f"{name} must be one of {', '.join(repr(c) for c in choices)}, got {value!r}")
    return value


def _pick(granules, available: np.ndarray, what: str) -> np.ndarray:
    """Row indices of the chosen granule labels (default: a readable, evenly spread subset)."""
    if granules is None:
        n = available.size
        return np.unique(np.round(np.linspace(0, n - 1, min(n, DEFAULT_TRACES))).astype(int))
    chosen = np.atleast_1d(np.asarray(granules, dtype=object))
    ok = chosen.ndim == 1 and chosen.size > 0 and all(
        isinstance(g, (int, np.integer)) and not isinstance(g, (bool, np.bool_)) for g in chosen)
    if not ok:
        raise ValueError(f"granules must be a non-empty list of integer granule labels ({what}: "
                         f"{_span(available)}), got {granules!r}")
    rows = []
    for g in chosen:
        hit = np.flatnonzero(available == int(g))
        if hit.size == 0:
            raise ValueError(f"granule {int(g)} has no recorded {what.split(':')[0]}; choose among {_span(available)}")
        rows.append(int(hit[0]))
    if len(set(rows)) != len(rows):
        raise ValueError(f"granules lists a granule twice: {granules!r}")
    return np.array(rows)


def _span(labels) -> str:
    labels = np.asarray(labels)
    if labels.size and np.array_equal(labels, np.arange(labels[0], labels[0] + labels.size)):
        return f"{labels[0]}..{labels[-1]}"
    return ", ".join(str(int(k)) for k in labels[:12]) + (", ..." if labels.size > 12 else "")


def _axes(ax, figsize):
    import matplotlib.pyplot as plt
    from matplotlib.axes import Axes

    if ax is None:
        fig, ax = plt.subplots(figsize=figsize, layout="constrained")
        return ax
    if not isinstance(ax, Axes):
        raise ValueError(f"ax must be a matplotlib Axes (or None for a new figure), got {type(ax).__name__}")
    return ax


def _time_window(t, time_range):
    """A mask over ``t`` keeping ``time_range`` = (start, end) (rescaled, like ``t_grid``)."""
    if time_range is None:
        return np.ones(t.size, dtype=bool)
    try:
        lo, hi = (float(x) for x in time_range)
    except (TypeError, ValueError):
        raise ValueError(f"time_range must be (start, end) in rescaled time units, got {time_range!r}") from None
    if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
        raise ValueError(f"time_range = {time_range!r} must be two finite times with start < end")
    keep = (t >= lo) & (t <= hi)
    if keep.sum() < 2:
        raise ValueError(f"time_range = {time_range!r} holds fewer than 2 grid times; the grid spans "
                         f"{t[0]:g}..{t[-1]:g} (rescaled)")
    return keep


def colormap(cmap):
    """``cmap`` (a name or a Colormap) as a matplotlib Colormap, or None left as None; checked."""
    if cmap is None:
        return None
    import matplotlib as mpl

    if isinstance(cmap, str):
        if cmap not in mpl.colormaps:
            raise ValueError(f"cmap = {cmap!r} is not a matplotlib colour map; give a name such as 'RdBu_r', 'coolwarm', "
                             "'viridis' or 'magma' (matplotlib.colormaps lists them), or a Colormap")
        return mpl.colormaps[cmap]
    if not isinstance(cmap, mpl.colors.Colormap):
        raise ValueError(f"cmap must be a colour map's name or a matplotlib Colormap, got {type(cmap).__name__}")
    return cmap


def draw_traces(ax, t, values, labels, *, quantity: str, granule_name: str, units: Units, stderr=None, name=None):
    """One line per row of ``values`` (granule, time) against ``t`` (rescaled), labelled by granule.
    ``stderr`` (same shape): a shaded band of +- one standard error (an ensemble average). ``name``
    replaces the quantity's name in the axis label (e.g. an average)."""
    import matplotlib as mpl

    tt, xlabel, _ = units.convert("time", t)
    vv, ylabel, factor = units.convert(quantity, values, name)
    # viridis without its yellow end, too pale for a line on white
    cmap = mpl.colors.ListedColormap(mpl.colormaps["viridis"](np.linspace(0.0, 0.9, 256)), name="viridis_lines")
    lo, hi = float(np.min(labels)), float(np.max(labels))
    norm = mpl.colors.Normalize(lo, hi if hi > lo else lo + 1.0)
    for row, k in enumerate(labels):
        colour = cmap(norm(k))
        ax.plot(tt, vv[row], color=colour, lw=1.2, label=f"{k}")
        if stderr is not None:
            e = np.asarray(stderr[row], dtype=float) * factor
            ax.fill_between(tt, vv[row] - e, vv[row] + e, color=colour, alpha=0.25, lw=0)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_xlim(tt[0], tt[-1])
    if quantity == "velocity" and np.nanmin(vv) < 0:
        ax.axhline(0.0, color="0.6", lw=0.6, zorder=0)
    if len(labels) <= LEGEND_MAX:
        ax.legend(title=granule_name, ncols=2 if len(labels) > 5 else 1, fontsize="small", title_fontsize="small",
                  loc="best", frameon=False)
    else:
        sm = mpl.cm.ScalarMappable(norm=norm, cmap=cmap)
        ax.figure.colorbar(sm, ax=ax, label=granule_name, pad=0.02)
    return ax


def draw_spacetime(ax, t, values, labels, *, quantity: str, granule_name: str, units: Units, cmap=None, name=None,
                   missing: str = "grey: not recorded"):
    """The space-time diagram: granule (rows of ``values``, labelled ``labels``) against time ``t``
    (rescaled), coloured by ``quantity``, with a labelled colour bar. Granules between the given
    labels and times that were not recorded (NaN) are drawn in grey and said so (``missing``)."""
    import matplotlib as mpl

    tt, xlabel, _ = units.convert("time", t)
    vv, clabel, _ = units.convert(quantity, values, name)
    labels = np.asarray(labels, dtype=np.int64)
    rows = np.arange(labels.min(), labels.max() + 1)  # every label in the span, one row each
    full = np.full((rows.size, tt.size), np.nan)
    full[labels - rows[0]] = vv
    finite = full[np.isfinite(full)]
    lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
    if quantity == "velocity":
        # diverging, centred on 0 and symmetric (a colour's strength is the speed's size on either side):
        # behind the pulse granules move backwards (v < 0)
        cmap = cmap or "RdBu_r"
        top = max(abs(lo), abs(hi)) or 1.0
        norm = mpl.colors.Normalize(vmin=-top, vmax=top)
    else:
        # sequential from 0: contacts only push
        cmap = cmap or "viridis"
        norm = mpl.colors.Normalize(vmin=min(0.0, lo), vmax=hi if hi > min(0.0, lo) else min(0.0, lo) + 1.0)
    cm = colormap(cmap).with_extremes(bad="0.85")
    # rasterized: a 26 x 14000 mesh written as vector quads would make a PDF/SVG of tens of MB
    mesh = ax.pcolormesh(tt, rows, np.ma.masked_invalid(full), shading="nearest", cmap=cm, norm=norm, rasterized=True)
    bar = ax.figure.colorbar(mesh, ax=ax, pad=0.02)
    bar.set_label(clabel)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(granule_name)
    ax.yaxis.set_major_locator(mpl.ticker.MaxNLocator(nbins=8, integer=True))
    if not np.isfinite(full).all():
        ax.text(0.99, 0.01, missing, transform=ax.transAxes, ha="right", va="bottom", fontsize="x-small",
                color="0.3")
    return ax


def _title(result, quantity: str) -> str:
    chain = result.chain
    if granule_labels(chain, chain.labels)[1] != "granule":  # a decorated chain: N large granules of M
        desc = f"decorated chain, N = {chain.labels.size} (M = {chain.size}), n = {chain.n:g}"
    else:
        desc = f"{chain.kind} chain, M = {chain.size}, n = {chain.n:g}"
    return f"{desc}: velocity" if quantity == "velocity" else f"{desc}: granule force\n(the mean of its two contact forces)"


def plot_pulse(result, kind: str = "traces", quantity: str = "velocity", granules=None, ax=None, *, scale=None,
               time_range=None, cmap=None, title: bool = True):
    """Draw one simulated pulse: traces of chosen granules or the space-time diagram.

    Parameters
    ----------
    result : PulseResult
        From ``simulate(chain, t_grid=...)`` (velocity) or ``simulate(chain, t_grid=..., sensors=
        force_sensors(chain))`` (force).
    kind : "traces" or "spacetime"
        Lines of the chosen granules against time, or granule against time coloured by ``quantity``.
    quantity : "velocity" or "force"
        The velocity v_k(t) of the observed granules, or the force inside each sensor granule (the mean
        of its two contact forces, static load included).
    granules : int or list of int, optional
        Which granules to draw, by the labels on the axis: for a decorated chain the large-granule index
        k = 1..N (chain index 2k - 1), else the chain's labels (``result.granule``). Default: traces of
        about seven granules spread along the chain; the space-time diagram shows every recorded granule.
    ax : matplotlib Axes, optional
        Where to draw (a new figure if None).
    scale : granchain.units.Scale, optional
        Axes in SI units (s, m/s, N with fitting prefixes); default: the paper's rescaled units, named so.
    time_range : (start, end), optional
        Only these times of the grid (rescaled, like ``t_grid``).
    cmap : str or Colormap, optional
        The space-time diagram's colour map (default: ``RdBu_r`` centred on 0 for velocity,
        ``viridis`` for force).
    title : bool
        Say which chain and quantity in the title.

    Returns
    -------
    matplotlib.axes.Axes
        The axes drawn on (``ax.figure`` is the figure).
    """
    kind = _check_choice("kind", kind, KINDS)
    quantity = _check_choice("quantity", quantity, QUANTITIES)
    units = Units.from_scale(scale)
    cmap = colormap(cmap)  # (checked before a figure is made)
    if not isinstance(title, bool):
        raise ValueError(f"title must be True or False, got {title!r}")
    if result.t_grid is None:
        raise ValueError("this result has no time grid: pass t_grid=... to simulate() (e.g. "
                         "t_grid=numpy.linspace(0, 60, 1201)), which records every observed granule on it")
    if quantity == "velocity":
        chain_labels, values = np.asarray(result.granule), np.asarray(result.velocity, dtype=float)
    else:
        if result.sensor_force is None:
            raise ValueError("this result recorded no granule forces: pass sensors=granchain.solve.plot.force_sensors(chain) "
                             "(with t_grid=...) to simulate(), which records the force inside every such granule")
        chain_labels, values = np.asarray(result.sensor_granule), np.asarray(result.sensor_force, dtype=float)
    labels, name = granule_labels(result.chain, chain_labels)
    what = "velocity: observed granules" if quantity == "velocity" else "force: sensor granules"
    if kind == "spacetime" and granules is None:
        rows = np.arange(labels.size)
    else:
        rows = _pick(granules, labels, what)
    t = np.asarray(result.t_grid, dtype=float)
    keep = _time_window(t, time_range)
    ax = _axes(ax, (6.4, 4.0) if kind == "traces" else (6.4, 4.4))
    if kind == "traces":
        draw_traces(ax, t[keep], values[rows][:, keep], labels[rows], quantity=quantity, granule_name=name, units=units)
    else:
        order = np.argsort(labels[rows])
        draw_spacetime(ax, t[keep], values[rows[order]][:, keep], labels[rows[order]], quantity=quantity,
                       granule_name=name, units=units, cmap=cmap,
                       missing="grey: not recorded" if granules is None else "grey: not among the chosen granules")
    if title:
        ax.set_title(_title(result, quantity), fontsize="medium")
    return ax
