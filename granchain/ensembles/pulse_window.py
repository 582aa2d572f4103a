"""The averaged pulse's window at each observed granule, so that ensembles can run with the trailing window.

The averaged pulse <v_k(t)> (paper Figs. 1-3: its maximum, its time and its shape) lives around the
pulse's passage at granule k. The wake long after it needs every granule behind the pulse integrated
to the end of the time grid, which makes a realisation cost O(N^2) in the chain's length N. With a
trailing window (``DP5.windowed``, ``RKN4.windowed``) a realisation drops the granules the pulse has
left behind, and costs O(N); the price is the wake: a dropped granule keeps the velocity it left
with. The ensembles reconcile the two with a window per observed granule, common to all
realisations: granule k stays integrated in every realisation until the end of its window
``t_end[k]`` (the trailing window waits for it: ``records.Run.pulse_end``), and <v_k(t)> is recorded
for t <= t_end[k], exactly (each realisation's granule k is integrated over the whole window), and
not after (``mean_velocity`` is NaN there: not computed).

The window must hold the whole averaged pulse: the pulse of every realisation, whose arrival times
spread with the randomness of the chain. It is set from the ensemble's own first
:data:`PILOT_REALIZATIONS` realisations (integrated once, peaks only, at linear cost), by the rule the
trailing window applies to one realisation (it drops a granule once the pulse is some granules on),
applied to the ensemble: granule k's window closes when the
pulse has passed granule k + :data:`AHEAD` in the slow realisations, i.e. at the pilot's mean arrival
time at granule k + AHEAD plus :data:`SPREAD` standard deviations of it. The last AHEAD granules keep
the whole grid.
The trailing window then stays :data:`BUFFER` observed granules behind the first window still open
(:func:`keep_until`), so that the contact it drops at its edge cannot reach a recorded velocity.

:func:`check` proves it on the ensemble itself: per granule, the latest arrival time of all the
realisations against the window's end, and how many realisations' pulses had not yet reached
granule k + AHEAD when the window closed.
"""

from __future__ import annotations

import dataclasses

import numpy as np

__all__ = ["PILOT_REALIZATIONS", "SPREAD", "AHEAD", "BUFFER", "AUTO", "FULL", "applies", "ends_from_arrivals", "keep_until", "window_ends",
           "check", "stored_setting"]

#: Realisations 0..PILOT_REALIZATIONS-1 of the ensemble (whatever its size: the same draws, so an
#: ensemble extended later gets the same windows) measure the arrival times the windows are built from.
PILOT_REALIZATIONS = 64
#: Standard deviations of the pilot's arrival times added to their mean. A realisation that arrives this
#: late has its pulse :data:`AHEAD` granules past k when the window closes; the rarer ones later still
#: (a very small granule is a weak contact: the arrival times have a long right tail) keep their maximum
#: and most of its fall inside, and :func:`check` counts them. Each standard deviation costs about
#: sigma/S more granules integrated behind the pulse (S the time per granule), and sigma grows as
#: sqrt(k) along the chain (with 4 a realisation of N = 101 cost ~5.2x one of N = 26, with 3 ~4.7x at
#: AHEAD = 7; linear is 4, the whole grid ~14: benchmarks/bench_scaling.py).
SPREAD = 3.0
#: Observed granules between the trailing window's edge and the first granule whose window is still open.
#: A cut drops the contact at the edge: a granule behind it that would have struck the edge granule again
#: (the rattling wake behind the pulse) no longer does, and that error travels forward collision by
#: collision. With this buffer the recorded windows are shielded from it: on 150 paper realisations
#: (N = 26) <v_k(t)> inside the windows is within 7e-5 (0.015 standard errors, at granule 22 near the
#: grid's end; 1e-6 or less up to granule 20) of the exact run without a trailing window with a buffer
#: of 3, and within 0.013 (2.9 standard errors, at the windows' ends) without one (tests/test_window.py).
BUFFER = 3

#: Observed granules the pulse has passed, in the realisations :data:`SPREAD` standard deviations slower
#: than the mean, when granule k's window closes. A single realisation's velocity at k has fallen below a
#: tenth of its maximum when the front is 5 granules on in 95 % of the paper's realisations and granules
#: (below 5 %: median 2, 90th percentile 6; 40 chains of N = 26 measured), and the realisations of
#: average speed are SPREAD sigma / S granules further on still. 7 (the trailing window's own lag, under
#: which a realisation's peaks are final) cost a realisation of N = 101 ~4.7-5.0x one of N = 26, 5 ~4.4x.
AHEAD = 5

#: The settings of ``run_ensemble(pulse_window=...)``.
AUTO = "auto"
FULL = "full"


def window_lag(integrator, family) -> int:
    """The trailing window's lag (in observed granules) of ``integrator`` as it runs on the family's
    chains (0: it has none, or the family's boundary switches it off)."""
    from ..backends import effective_integrator

    ran = effective_integrator(integrator, family.model.boundary)
    return int(getattr(ran, "window_lag", None) or 0)


def applies(spec) -> tuple:
    """The chain kinds of ``spec`` (an ``EnsembleSpec``) whose integrator runs a trailing window on the
    family's chains, and so get averaged-pulse windows (with ``pulse_window="auto"``)."""
    return tuple(kind for kind, integ in spec.chain_integrators.items() if window_lag(integ, spec.family) > 0)


def ends_from_arrivals(arrivals: np.ndarray, extra: float = 0.0) -> np.ndarray:
    """Window ends (K,) from arrival times (R, K) of R realisations at the K observed granules: for
    granule q, the mean arrival time at q + :data:`AHEAD` plus :data:`SPREAD` standard deviations
    (+ ``extra``, e.g. the aligned pulse's largest lag); ``inf`` for the last AHEAD granules. Made
    non-decreasing along the chain (a window never closes before the one of a granule behind it)."""
    arrivals = np.asarray(arrivals, dtype=float)
    K = arrivals.shape[1]
    ends = np.full(K, np.inf)
    if K > AHEAD:
        later = arrivals[:, AHEAD:]
        ends[:K - AHEAD] = np.nanmean(later, axis=0) + SPREAD * np.nanstd(later, axis=0, ddof=1) + extra
    return np.maximum.accumulate(ends)


def keep_until(ends: np.ndarray) -> np.ndarray:
    """The time until which each observed granule stays integrated (``records.Run.pulse_end``): the end of
    the window :data:`BUFFER` observed granules ahead (so that no cut comes within BUFFER granules of an
    open window)."""
    ends = np.asarray(ends, dtype=float)
    ahead = np.minimum(np.arange(ends.size) + BUFFER, ends.size - 1)
    return np.ascontiguousarray(ends[ahead])


def window_ends(spec, compute_rows) -> dict:
    """{chain kind: window ends (K,)} for the kinds of ``spec`` that get a window (:func:`applies`), from
    the pilot: realisations 0..PILOT_REALIZATIONS-1 of each such kind, integrated by ``compute_rows(pilot
    spec)`` (which returns the chunk's results: ``ensembles.chunks._compute_chunk``) on a one-point grid
    (peaks only: the pilot itself costs linearly in N). Raises if too few pilot realisations succeed
    to estimate a spread."""
    from .._status import SUCCESS

    extra = max(0.0, float(spec.lags[-1])) if spec.lags is not None else 0.0
    out = {}
    for kind in applies(spec):
        pilot = dataclasses.replace(spec, realizations=PILOT_REALIZATIONS, chunk_size=PILOT_REALIZATIONS, chains=(kind,),
                                    t_grid=np.zeros(1), lags=None, pulse_window=FULL, pulse_ends=None)
        res = compute_rows(pilot)
        ok = np.asarray(res["status"][0]) == SUCCESS
        if ok.sum() < 8:
            raise RuntimeError(f"only {int(ok.sum())} of the {PILOT_REALIZATIONS} pilot realisations of the {kind} chains "
                               "succeeded, too few to set the averaged pulse's windows: run with pulse_window='full' "
                               "(CLI: --pulse-window full) and look at the realisations' status")
        out[kind] = ends_from_arrivals(np.asarray(res["peak_time"][0])[ok], extra)
    return out


def check(ds) -> "xarray.Dataset":  # noqa: F821
    """How well each observed granule's averaged-pulse window holds the pulse of every realisation of
    the ensemble ``ds`` (a ``run_ensemble`` result or an opened store), per chain kind and granule:

    - ``window_end``: the window's end (inf: the whole grid);
    - ``latest_arrival``: the latest arrival time (peak time) of all successful realisations;
    - ``margin``: window_end - latest_arrival (every realisation's peak at k lies inside when > 0);
    - ``unfinished``: realisations whose pulse had not yet reached granule k + A (A the store's
      ``pulse_window_ahead``) when the window closed: the slowest, 0.5-1.9 % per granule in the paper's
      ensembles (30,000 realisations at N = 6, 11, 16, 26), whose maximum at k still lies inside (the
      latest arrival there was 8.4 time units or more before the window's end) and whose velocity there
      is then mostly down to its tail;
    - ``peak_inside``: the averaged pulse's maximum lies strictly inside the window.

    Empty (no variable) for an ensemble run without windows."""
    import xarray as xr

    if "pulse_window_end" not in ds:
        return xr.Dataset()
    from .._status import SUCCESS

    ends = ds["pulse_window_end"]
    ok = ds["status"] == SUCCESS
    arrival = ds["peak_time"].where(ok)
    latest = arrival.max("realization")
    K = ds.sizes["granule"]
    ahead = np.broadcast_to(np.asarray(ds["pulse_window_ahead"].values, dtype=np.int64), (ds.sizes["chain"],))
    t = arrival.transpose("chain", "realization", "granule").values
    e = ends.transpose("chain", "granule").values
    unfinished = np.zeros((ds.sizes["chain"], K), dtype=np.int64)
    for c, a in enumerate(ahead):
        for q in range(K - a if a > 0 else 0):
            unfinished[c, q] = np.sum(t[c, :, q + a] > e[c, q])
    t_peak = ds["mean_velocity"].fillna(-np.inf).idxmax("time")
    inside = (t_peak < ends) | ~np.isfinite(ends)
    return xr.Dataset({"window_end": ends, "latest_arrival": latest, "margin": ends - latest,
                       "unfinished": (("chain", "granule"), unfinished), "peak_inside": inside})


def record(spec) -> dict:
    """The windows' part of the ensemble's parameter record (compared on resume, so that a store is only
    ever continued with the windows it was started with): the rule, and the ends once set (JSON: inf
    as null)."""
    rec = {"rule": AUTO, "pilot_realizations": PILOT_REALIZATIONS, "spread": SPREAD, "ahead": AHEAD, "buffer": BUFFER}
    if spec.pulse_ends is not None:
        rec["ends"] = {kind: [None if not np.isfinite(x) else float(x) for x in e] for kind, e in spec.pulse_ends.items()}
    return rec


def ends_of_record(record: dict | None) -> dict | None:
    """{chain kind: ends} from a parameter record's ``"pulse_window"`` entry (None: the record has none)."""
    if not isinstance(record, dict) or "ends" not in record:
        return None
    return {kind: np.array([np.inf if x is None else x for x in e], dtype=float) for kind, e in record["ends"].items()}


def stored_record(out) -> dict | None:
    """The parameter record of the store ``out`` (None: no store there, or no readable record: the store's
    own checks then say what is wrong with it)."""
    import json
    import os

    if not os.path.isdir(os.fspath(out)):
        return None
    from .store import stored_parameters

    try:
        rec = json.loads(stored_parameters(os.fspath(out)) or "null")
    except (ValueError, OSError):
        return None
    return rec if isinstance(rec, dict) else None


def stored_setting(out) -> str:
    """The ``pulse_window`` setting the store ``out`` was started with: "auto" if its record has windows, or
    has none because no integrator of the run kept a trailing window on its chains (a wall or a static
    load switches it off) although it had one (the windowed defaults); "full" for a store whose
    integrators have no trailing window (the relaxed defaults of every store before granchain 0.5, or
    pulse_window="full"); "auto" where there is no store yet."""
    rec = stored_record(out)
    if rec is None or "pulse_window" in rec:
        return AUTO
    integrators = list((rec.get("chain_integrators") or {}).values()) + [rec.get("integrator")]
    return AUTO if any(isinstance(r, dict) and r.get("window_lag") for r in integrators) else FULL
