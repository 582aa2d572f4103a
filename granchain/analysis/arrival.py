"""Arrival times of the pulse per realisation, paper Figs. 3 and 4, and the out-of-order peaks that
flag rare double peaks.

* :func:`mean_arrival_time` - the mean per-realisation peak time at each large granule k;
* :func:`arrival_times` - the per-realisation peak times at one granule (default k = N - 1, Fig. 4);
* :func:`out_of_order_peaks` - realisations whose peak at k comes after the one at k + 1.

Each takes an ensemble Dataset or the path of a store. Re-exported by :mod:`granchain.analysis`.
"""

from __future__ import annotations

import numpy as np

from ._arrays import _frozen
from ._read import _chain, _valid
from .amplitude import PerGranule, _per_granule

__all__ = ["mean_arrival_time", "arrival_times", "out_of_order_peaks"]


def mean_arrival_time(ds, chain="decorated") -> PerGranule:
    """Mean over valid realisations of the per-realisation peak time at each granule k."""
    return _per_granule(ds, chain, "peak_time", "mean_peak_time")


def arrival_times(ds, chain="decorated", granule=None) -> np.ndarray:
    """Valid per-realisation peak times at large granule k (default k = N - 1, paper Fig. 4)."""
    sub = _chain(ds, chain, ("status", "peak_time"))
    ks = [int(k) for k in sub["granule"].values]
    k = ks[-2] if granule is None else granule
    if k not in ks:
        raise ValueError(f"granule = {k!r} is not in the Dataset (k = {ks[0]}..{ks[-1]})")
    t = _valid(sub, "peak_time")[:, ks.index(k)]
    return t[np.isfinite(t)]


def out_of_order_peaks(ds, chain="decorated") -> PerGranule:
    """Per granule k < N: count of valid realisations with peak_time[k] > peak_time[k + 1].

    A proxy for the rare genuine double peaks (a granule hit twice): a later, higher hump at k
    moves max_t v_k after the pulse has already reached k + 1. It misses double peaks that
    stay in order. It is the only count granchain has: the kernels record one maximum per
    granule (with the tie rule of ``peak_rtol``) and do not count separate humps. ``value`` is the count,
    ``stderr`` its Poisson error sqrt(count); the last granule has count 0 by definition.
    """
    sub = _chain(ds, chain, ("status", "peak_time"))
    t = _valid(sub, "peak_time")
    late = np.zeros(t.shape[1])
    with np.errstate(invalid="ignore"):
        late[:-1] = np.sum(t[:, :-1] > t[:, 1:], axis=0)
    n = np.sum(np.isfinite(t), axis=0)
    return PerGranule("out_of_order_peaks", chain, _frozen(sub["granule"].values), _frozen(late),
                      _frozen(np.sqrt(late)), n)
