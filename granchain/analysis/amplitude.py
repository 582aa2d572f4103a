"""The two different amplitudes of an ensemble, per large granule k (docs: explanation/physics).

* :func:`mean_peak_amplitude` - the mean of per-realisation peaks <max_t v_k>;
* :func:`averaged_pulse_peak` - the peak of the ensemble-averaged pulse max_t <v_k(t)> and its time,
  the paper's Figs. 2 and 3 (:func:`pulse_peak` locates it on any time grid);
* :class:`PerGranule` - a per-granule ensemble statistic with its standard error, which
  :mod:`~granchain.analysis.arrival` shares.

Each takes an ensemble Dataset (the ``run_ensemble`` store schema) or the path of a store, read with
:func:`granchain.open_store`. Re-exported by :mod:`granchain.analysis`.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from ._arrays import _frozen
from ._read import _chain, _dataset, _valid

__all__ = ["PerGranule", "PulsePeak", "pulse_peak", "mean_peak_amplitude", "averaged_pulse_peak"]


@dataclass(frozen=True, eq=False)
class PerGranule:
    """An ensemble statistic per large granule k with its standard error (std / sqrt(n)).

    ``n`` counts the valid realisations used at each granule (status 0, finite value).
    """

    quantity: str
    chain: str
    granule: np.ndarray
    value: np.ndarray
    stderr: np.ndarray
    n: np.ndarray


def _per_granule(ds, chain, name, quantity) -> PerGranule:
    sub = _chain(ds, chain, ("status", name))
    v = _valid(sub, name)
    n = np.sum(np.isfinite(v), axis=0)
    with warnings.catch_warnings(), np.errstate(invalid="ignore", divide="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)
        mean = np.nanmean(v, axis=0)
        err = np.nanstd(v, axis=0, ddof=1) / np.sqrt(n)
    return PerGranule(quantity, chain, _frozen(sub["granule"].values), _frozen(mean), _frozen(err), n)


def mean_peak_amplitude(ds, chain="decorated") -> PerGranule:
    """Mean of per-realisation peaks <max_t v_k> (docs: explanation/physics, the two amplitudes).

    Not the paper's Fig. 2 amplitude (that is :func:`averaged_pulse_peak`): it decays much
    more weakly, since it ignores realisations drifting out of phase.
    """
    return _per_granule(ds, chain, "peak_velocity", "mean_peak_velocity")


@dataclass(frozen=True, eq=False)
class PulsePeak:
    """Peak of the ensemble-averaged pulse, max_t <v_k(t)>, and its time (paper Figs. 2, 3).

    Located between grid points by the parabola through the three samples around the grid
    maximum; ``refined`` is False where that was impossible (maximum at the grid's edge, as
    for the struck granule k = 1, or a flat top). ``velocity_stderr`` is mean_velocity_stderr
    interpolated at the peak time. No time uncertainty is given: neighbouring samples share
    realisations, so it cannot be derived from the stored mean and stderr.
    """

    chain: str
    granule: np.ndarray
    velocity: np.ndarray
    velocity_stderr: np.ndarray
    time: np.ndarray
    refined: np.ndarray


def pulse_peak(time, mean, stderr=None):
    """max_t and argmax_t of averaged pulses ``mean`` (granule, time) on the grid ``time``.

    The maximum is located between grid points by the parabola through the three samples
    around the grid maximum. Returns (velocity, time, refined, velocity_stderr) arrays per
    granule; ``refined`` is False where that was impossible (maximum at the grid's edge, as
    for the struck granule k = 1, or a flat top); ``velocity_stderr`` is ``stderr``
    interpolated at the peak time (NaN without ``stderr``).
    """
    t = np.asarray(time, dtype=float)
    v = np.asarray(mean, dtype=float)
    e = np.full_like(v, np.nan) if stderr is None else np.asarray(stderr, dtype=float)
    if t.size < 3 or np.any(np.diff(t) <= 0):
        raise ValueError("the time grid must be strictly increasing with at least 3 points")
    rows = np.arange(v.shape[0])
    finite = np.isfinite(v).any(axis=1)
    i = np.where(finite, np.argmax(np.where(np.isfinite(v), v, -np.inf), axis=1), 0)
    tp, vp = t[i], v[rows, i]
    ep = e[rows, i]
    refined = np.zeros(rows.size, dtype=bool)
    inner = finite & (i > 0) & (i < t.size - 1)
    j = np.clip(i, 1, t.size - 2)
    t0, t1, t2 = t[j - 1], t[j], t[j + 1]
    v0, v1, v2 = v[rows, j - 1], v[rows, j], v[rows, j + 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        d01, d12 = (v1 - v0) / (t1 - t0), (v2 - v1) / (t2 - t1)
        curv = (d12 - d01) / (t2 - t0)  # p(t) = v0 + d01 (t - t0) + curv (t - t0)(t - t1)
        ts = 0.5 * (t0 + t1) - d01 / (2.0 * curv)
        ok = inner & (curv < 0) & np.isfinite(ts)
    ts = np.where(ok, ts, tp)
    refined[ok] = True
    vp = np.where(ok, v0 + d01 * (ts - t0) + curv * (ts - t0) * (ts - t1), vp)
    lo = np.where(ts >= t1, j, j - 1)  # linear interpolation of the stderr at the peak time
    frac = (ts - t[lo]) / (t[lo + 1] - t[lo])
    ep = np.where(ok, e[rows, lo] + frac * (e[rows, lo + 1] - e[rows, lo]), ep)
    nan = np.where(finite, 1.0, np.nan)
    return vp * nan, ts * nan, refined, ep * nan


def averaged_pulse_peak(ds, chain="decorated") -> PulsePeak:
    """max_t <v_k(t)> and argmax_t, per granule, with quadratic refinement (paper Fig. 2)."""
    ds = _dataset(ds)
    if not hasattr(ds, "data_vars") or "mean_velocity" not in ds:
        raise ValueError(f"ds must be an ensemble Dataset with mean_velocity (from run_ensemble or "
                         f"granchain.open_store(path)) or the path of a store, got {type(ds).__name__}")
    sub = _chain(ds, chain, ("mean_velocity", "mean_velocity_stderr"))
    v = sub["mean_velocity"].transpose("granule", "time").values.astype(float)
    e = sub["mean_velocity_stderr"].transpose("granule", "time").values.astype(float)
    vp, ts, refined, ep = pulse_peak(sub["time"].values, v, e)
    return PulsePeak(chain, _frozen(sub["granule"].values), _frozen(vp), _frozen(ep), _frozen(ts), refined)
