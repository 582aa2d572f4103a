"""``granchain plot STORE --out FILE``: an ensemble's averaged pulse as a figure; and ``granchain pulse --plot``.

The averaged pulse <v_k(t)> of one chain of a store (:func:`granchain.analysis.plot_averaged_pulse`), as
the space-time diagram (granule against time, coloured by velocity) or as traces of a few granules. The
format follows the file's extension (PNG, PDF, SVG). A store written with physical units (``granchain
ensemble --material ...``) is drawn in s and m/s unless ``--rescaled`` is given.

This module also holds the ``--plot`` options of ``granchain pulse`` (:func:`add_pulse_plot_arguments`,
:func:`pulse_plot_request`, :func:`write_pulse_plot`), so one module says how a figure is requested,
checked and written.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Figure sizes (inches) by kind, and the resolution of a PNG: a one-column figure at print quality.
FIGSIZE = {"traces": (6.4, 4.0), "spacetime": (6.4, 4.4)}
DPI = 200
#: Grid samples of a pulse plot at most (and the finest step): enough for the pulse's shape (a few time
#: units wide) without a space-time image of millions of cells.
PLOT_SAMPLES = 4000
PLOT_STEP = 0.02


def add_parser(subparsers) -> None:
    from ..solve.plot import KINDS

    p = subparsers.add_parser(
        "plot",
        help="draw an ensemble's averaged pulse <v_k(t)> from a store: space-time diagram or traces",
        description="Read an ensemble store (granchain ensemble --out STORE, or run_ensemble(out=STORE)) and draw the "
                    "averaged pulse <v_k(t)> of one of its chains: the space-time diagram (granule against time, "
                    "coloured by the averaged velocity) or the traces of a few granules with their standard errors. "
                    "The file's extension picks the format (.png, .pdf, .svg).",
    )
    p.add_argument("store", help="the Zarr store (or an exported netCDF file), e.g. runs/N26.zarr")
    p.add_argument("--out", required=True, metavar="FILE", help="the figure to write: FILE.png, FILE.pdf or FILE.svg")
    p.add_argument("--chain", help="which chain of the ensemble (decorated families: decorated or effective); "
                                   "default the store's first")
    p.add_argument("--kind", default="spacetime", choices=KINDS, help="space-time diagram (default) or traces")
    p.add_argument("--granules", metavar="K1,K2,...", help="the granules to draw, as stored (decorated families: "
                                                           "large-granule index k); default every granule in the diagram, "
                                                           "about seven as traces")
    p.add_argument("--t-max", type=float, metavar="T", help="draw times up to T only (rescaled, like the store's time)")
    p.add_argument("--rescaled", action="store_true", help="rescaled units even if the store recorded a physical scale")
    p.set_defaults(func=run)


def parse_granules(text: str | None, flag: str = "--granules"):
    """``"1,5,9"`` -> [1, 5, 9] (None stays None)."""
    if text is None:
        return None
    fields = [f.strip() for f in text.split(",")]
    if not text.strip() or any(not f for f in fields):
        raise ValueError(f"{flag} has an empty field in {text!r}: give comma-separated granule numbers such as 1,5,9")
    try:
        return [int(f) for f in fields]
    except ValueError:
        raise ValueError(f"{flag} expects comma-separated whole granule numbers such as 1,5,9, got {text!r}") from None


def _time_range(t_max, flag: str = "--t-max"):
    if t_max is None:
        return None
    if not np.isfinite(t_max) or t_max <= 0:
        raise ValueError(f"{flag} must be a time > 0 (rescaled units), got {t_max!r}")
    return (0.0, float(t_max))


def _new_axes(kind: str):
    """Axes on a figure made without pyplot: the command line never opens a window or keeps figures."""
    from matplotlib.figure import Figure

    return Figure(figsize=FIGSIZE[kind], layout="constrained").add_subplot()


def _save(ax, path: str) -> None:
    ax.figure.savefig(path, dpi=DPI)


def run(args) -> int:
    from ..analysis.spacetime import averaged_pulse, plot_averaged_pulse
    from ..ensembles.read import open_store
    from ..solve.plot import check_figure_path

    out = check_figure_path(args.out, "--out")  # before reading anything
    granules = parse_granules(args.granules)
    time_range = _time_range(args.t_max)
    pulse = averaged_pulse(open_store(args.store), args.chain, scale=False if args.rescaled else None)
    if granules is not None:
        from ..solve.plot import _pick

        try:
            _pick(granules, pulse.granule, "averaged velocity: stored granules")
        except ValueError as exc:
            raise ValueError(f"--granules: {exc}") from None
    ax = plot_averaged_pulse(pulse, args.kind, granules, _new_axes(args.kind), time_range=time_range)
    _save(ax, out)
    units = "rescaled units" if pulse.units.time is None else "SI units (the store's physical scale)"
    print(f"wrote {out}: averaged pulse of the {pulse.chain} chains ({pulse.n_valid} realisations), {args.kind}, {units}")
    return 0


# ------------------------------------------------------------------ granchain pulse --plot FILE


def add_pulse_plot_arguments(parser) -> None:
    """``--plot FILE``, ``--plot-kind``, ``--plot-quantity`` on ``granchain pulse``."""
    from ..solve.plot import KINDS, QUANTITIES

    g = parser.add_argument_group("figure", "draw the pulse (the time grid, and the gauges a force plot needs, are "
                                            "recorded automatically; physical-unit options give SI axes)")
    g.add_argument("--plot", metavar="FILE", help="write a figure of the pulse: FILE.png, FILE.pdf or FILE.svg")
    g.add_argument("--plot-kind", choices=KINDS,
                   help="space-time diagram of every observed granule (default) or traces of a few granules")
    g.add_argument("--plot-quantity", choices=QUANTITIES,
                   help="velocity of each granule (default) or the force inside it (mean of its two contact forces)")
    g.add_argument("--plot-granules", metavar="K1,K2,...", help="the granules to draw (decorated chains: large-granule "
                                                                "index k), default every one in the diagram, about seven as traces")


@dataclass(frozen=True)
class PulsePlot:
    """What ``granchain pulse --plot`` asked for, checked before the run, and what the run must record."""

    path: str
    kind: str
    quantity: str
    granules: list | None
    grid: np.ndarray
    sensors: list | None


def passage_time(chain) -> float:
    """The end of a time grid over the pulse's passage through ``chain``: 2.5 time units per granule
    plus 20 (the decorated chains' slope is ~2.4 per large granule), or for a chain without an exit to end
    at (precompressed: the pulse comes back from its loaded end) the time it runs to
    (``granchain.solve.simulation.default_t_max``)."""
    from ..solve.simulation import default_t_max

    return 2.5 * chain.size + 20.0 if chain.ends_at_exit else default_t_max(chain)


def pulse_plot_request(args, chain, grid, sensors):
    """None without ``--plot``; else the checked request, with the time grid (``grid`` if one is already
    asked for, else one over the pulse's passage) and the sensors (``sensors`` if given, else every observed
    granule with two contacts when forces are drawn) that ``simulate`` must record."""
    if getattr(args, "plot", None) is None:
        for flag in ("plot_kind", "plot_quantity", "plot_granules"):
            if getattr(args, flag, None) is not None:
                raise ValueError(f"--{flag.replace('_', '-')} applies to a figure: add --plot FILE.png")
        return None
    from ..solve.plot import _pick, check_figure_path, force_sensors, granule_labels

    path = check_figure_path(args.plot, "--plot")
    kind, quantity = args.plot_kind or "spacetime", args.plot_quantity or "velocity"
    granules = parse_granules(args.plot_granules, "--plot-granules")
    if grid is None:  # the pulse's passage (as for sensors), sampled finely enough for its shape
        t_end = passage_time(chain)
        grid = np.linspace(0.0, t_end, int(min(PLOT_SAMPLES, np.ceil(t_end / PLOT_STEP))) + 1)
    if quantity == "force" and sensors is None:
        sensors = force_sensors(chain)
        if not sensors:
            raise ValueError("--plot-quantity force: no observed granule has a contact on each side to read a force "
                             "in; plot the velocity instead (--plot-quantity velocity)")
    if granules is not None:  # checked now, not after the run
        available = granule_labels(chain, chain.labels if quantity == "velocity" else sensors)[0]
        what = "velocity: observed granules" if quantity == "velocity" else "force: sensor granules"
        try:
            _pick(granules, available, what)
        except ValueError as exc:
            raise ValueError(f"--plot-granules: {exc}") from None
    return PulsePlot(path, kind, quantity, granules, grid, sensors)


def write_pulse_plot(request: PulsePlot, result, scale=None) -> str:
    """Draw ``result`` as ``request`` says (SI axes with ``scale``) and write the file; returns its path.
    Times after the pulse has left the chain (plus a margin) are cut: the granules then only drift apart."""
    from ..solve.plot import plot_pulse

    t = result.t_grid
    end = t[-1]
    if result.exit_time > 0:
        end = min(end, 1.1 * result.exit_time + 5.0)
    ax = plot_pulse(result, request.kind, request.quantity, request.granules, _new_axes(request.kind), scale=scale,
                    time_range=(t[0], end))
    _save(ax, request.path)
    return request.path
