"""An ensemble's averaged pulse <v_k(t)> as a space-time diagram (granule against time) or as traces.

:func:`averaged_pulse` reads the store's averaged pulse (``mean_velocity`` and ``mean_velocity_stderr``, as the
store's schema names them, ``AVERAGED`` in ``granchain.ensembles.schema``) for one chain of the ensemble;
:func:`plot_averaged_pulse` draws it with the drawing functions of a single pulse
(:mod:`granchain.solve.plot`), so an ensemble and one chain look alike. The averaged pulse is what the
paper's Figs. 2 and 3 fit (:func:`granchain.analysis.averaged_pulse_peak` locates its maxima): it
spreads and decays along the chain mostly because the realisations drift out of phase.

Times where the store has no average (after a granule's pulse window closed, ``pulse_window_end``)
are NaN and drawn grey.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["AveragedPulse", "averaged_pulse", "plot_averaged_pulse"]

_NAME = r"averaged velocity $\langle v_k \rangle$"


@dataclass(frozen=True, eq=False)
class AveragedPulse:
    """<v_k(t)> of one chain of an ensemble: ``velocity`` and ``stderr`` (granule, time, rescaled units of
    V_1), ``granule`` the store's granule labels (for decorated families the large-granule index k),
    ``time`` (rescaled), ``n_valid`` the successful realisations averaged. ``units``: the physical scale
    the store recorded (``granchain ensemble --material``), or rescaled units."""

    chain: str
    granule: np.ndarray
    time: np.ndarray
    velocity: np.ndarray
    stderr: np.ndarray
    n_valid: int
    granule_name: str
    units: object  # granchain.solve.plot.Units


def _stored_units(ds):
    """The ``physical_*`` scale a store recorded (``granchain ensemble --material``), as plot Units."""
    from ..solve.plot import Units

    t, v, f = (ds.attrs.get(f"physical_{k}") for k in ("time_unit_s", "velocity_unit_m_s", "force_unit_N"))
    if t is None or v is None:
        return Units()
    return Units(float(t), float(v), None if f is None else float(f))


def averaged_pulse(ds, chain: str | None = None, *, scale=None) -> AveragedPulse:
    """The averaged pulse <v_k(t)> of one chain of an ensemble.

    Parameters
    ----------
    ds : xarray.Dataset or path
        An ensemble Dataset (``run_ensemble``, :func:`granchain.open_store`) or the path of a store.
    chain : str, optional
        Which chain of the ensemble ("decorated" or "effective" for decorated families); default the
        store's first.
    scale : granchain.units.Scale, False or None
        SI axes with this scale; False: the paper's rescaled units; None (default): the scale the store
        recorded (``granchain ensemble --material``) if any, else rescaled units.
    """
    from ._read import _chain, _dataset
    from ..solve.plot import Units

    ds = _dataset(ds)
    if not hasattr(ds, "data_vars") or "mean_velocity" not in ds.variables:
        raise ValueError(f"ds must be an ensemble Dataset with mean_velocity (from run_ensemble or granchain.open_store(path)) "
                         f"or the path of a store, got {type(ds).__name__}")
    names = [str(c) for c in ds["chain"].values] if "chain" in ds.coords else []
    if chain is None and names:
        chain = names[0]
    if not isinstance(chain, str):
        raise ValueError(f"chain must be the name of one of the store's chains ({', '.join(names)}), got {chain!r}")
    sub = _chain(ds, chain, ("mean_velocity", "mean_velocity_stderr"))
    if scale is False:
        units = Units()
    elif scale is None:
        units = _stored_units(ds)
    else:
        units = Units.from_scale(scale)
    v = sub["mean_velocity"].transpose("granule", "time").values.astype(float)
    e = sub["mean_velocity_stderr"].transpose("granule", "time").values.astype(float)
    n_valid = int(sub["n_valid"].values) if "n_valid" in sub.variables else -1
    if n_valid == 0 or not np.isfinite(v).any():
        raise ValueError(f"the store has no averaged pulse for chain {chain!r} yet (no successful realisation, or the run "
                         "has not finished: resume it with `granchain ensemble --out PATH` or run_ensemble(out=PATH))")
    granule = np.asarray(sub["granule"].values, dtype=np.int64)
    long_name = str(sub["granule"].attrs.get("long_name", ""))
    name = r"large granule $k$" if "large" in long_name else "granule"
    return AveragedPulse(chain, granule, np.asarray(sub["time"].values, dtype=float), v, e, n_valid, name, units)


def plot_averaged_pulse(pulse, kind: str = "spacetime", granules=None, ax=None, *, chain: str | None = None, scale=None,
                        time_range=None, cmap=None, stderr: bool = True, title: bool = True):
    """Draw an ensemble's averaged pulse <v_k(t)>: the space-time diagram or traces of chosen granules.

    Parameters
    ----------
    pulse : AveragedPulse, xarray.Dataset or path
        From :func:`averaged_pulse`, or what it reads (then ``chain`` and ``scale`` are passed to it).
    kind : "spacetime" or "traces"
        Granule against time coloured by <v_k(t)> (diverging map centred on 0), or one line per granule.
    granules : int or list of int, optional
        Granule labels as stored (large-granule index k for decorated families). Default: every granule
        in the diagram, about seven spread along the chain as traces.
    ax : matplotlib Axes, optional
        Where to draw (a new figure if None).
    time_range : (start, end), optional
        Only these times (rescaled, like the store's ``time``).
    cmap : str or Colormap, optional
        The diagram's colour map (default ``RdBu_r``).
    stderr : bool
        Traces: shade +- one standard error of the mean.
    title : bool
        Say which chain and how many realisations in the title.

    Returns
    -------
    matplotlib.axes.Axes
    """
    from ..solve.plot import KINDS, _axes, _check_choice, _pick, _time_window, colormap, draw_spacetime, draw_traces

    kind = _check_choice("kind", kind, KINDS)
    cmap = colormap(cmap)
    if not isinstance(pulse, AveragedPulse):
        pulse = averaged_pulse(pulse, chain, scale=scale)
    elif chain is not None or scale is not None:
        raise ValueError("chain and scale apply when reading a Dataset or a store; an AveragedPulse already has them "
                         "(pass them to averaged_pulse)")
    for name, flag in (("stderr", stderr), ("title", title)):
        if not isinstance(flag, bool):
            raise ValueError(f"{name} must be True or False, got {flag!r}")
    rows = np.arange(pulse.granule.size) if kind == "spacetime" and granules is None else \
        _pick(granules, pulse.granule, "averaged velocity: stored granules")
    keep = _time_window(pulse.time, time_range)
    ax = _axes(ax, (6.4, 4.0) if kind == "traces" else (6.4, 4.4))
    v = pulse.velocity[rows][:, keep]
    if kind == "traces":
        draw_traces(ax, pulse.time[keep], v, pulse.granule[rows], quantity="velocity", granule_name=pulse.granule_name,
                    units=pulse.units, stderr=pulse.stderr[rows][:, keep] if stderr else None, name=_NAME)
    else:
        order = np.argsort(pulse.granule[rows])
        draw_spacetime(ax, pulse.time[keep], v[order], pulse.granule[rows][order], quantity="velocity",
                       granule_name=pulse.granule_name, units=pulse.units, cmap=cmap, name=_NAME,
                       missing="grey: not averaged (the granule's pulse window had closed)" if granules is None
                       else "grey: not chosen, or not averaged (pulse window closed)")
    if title:
        n = f"{pulse.n_valid} realisations" if pulse.n_valid > 0 else "ensemble"
        ax.set_title(f"averaged pulse, {pulse.chain} chains ({n})", fontsize="medium")
    return ax
