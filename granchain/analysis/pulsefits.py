"""Fits of the ensemble-averaged pulse as the paper does them, with jackknife errors.

Re-exported by :mod:`granchain.analysis`. The paper's Fig. 2 (v_k = a exp(-b k^c)) and Fig. 3
(t = slope k + intercept) are unweighted least-squares fits to the peak max_t <v_k(t)> of the
averaged pulse and to its time. Their uncertainties come from a jackknife over the store's
chunks of realisations (:class:`~granchain.analysis.jackknife.ChunkSums`): every replicate refits the
leave-one-chunk-out averaged pulse, so the correlation between granules is included. Without
per-chunk sums (an in-memory Dataset) the errors fall back to the fit residuals, and
``method`` says so: residual errors measure how well the model describes the curve, not the
sampling noise.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from .amplitude import averaged_pulse_peak, pulse_peak
from .fits import PAPER_FIG2, fit_linear, fit_stretched_exp, stretched_exp
from .jackknife import ChunkSums, Jackknife, chunk_jackknife, jackknife_stderr

__all__ = ["PulseFit", "CurveAgreement", "pulse_means", "pulse_jackknife", "fit_averaged_decay",
           "fit_averaged_arrival", "paper_curve_agreement", "rounding_envelope", "averaged_peak_gap"]

RESIDUALS = "fit residuals (no per-chunk sums: an in-memory Dataset; not a sampling error)"


def pulse_means(ds) -> dict:
    """<v_k(t)> per chain as stored: dict chain -> (granule, time) array."""
    mv = ds["mean_velocity"].transpose("chain", "granule", "time")
    return {str(c): mv.sel(chain=c).values.astype(float) for c in ds["chain"].values}


def pulse_jackknife(ds, statistic, sums: ChunkSums | None = None) -> Jackknife:
    """``statistic(means)`` on the Dataset's averaged pulse, with a chunk jackknife if ``sums``.

    Without ``sums`` the stderr is NaN and ``groups`` 0. The value always comes from the
    Dataset's ``mean_velocity`` (identical to the mean of the chunk sums).
    """
    value = np.asarray(statistic(pulse_means(ds)), dtype=float)
    if sums is None:
        return Jackknife(value, np.full(value.shape, np.nan), np.empty((0,) + value.shape), 0, "none")
    jk = chunk_jackknife(statistic, sums)
    return Jackknife(value, jk.stderr, jk.replicates, jk.groups, jk.method)


@dataclass(frozen=True, eq=False)
class PulseFit:
    """An unweighted fit of the averaged pulse with its range and error method.

    ``fit`` is the fit on the whole ensemble (:class:`StretchedExpFit` or :class:`LinearFit`);
    ``stderr`` the jackknife errors of ``params`` (or the residual errors, see ``method``);
    ``correlation`` the parameter correlation from the jackknife replicates (or the fit);
    ``replicates`` the leave-one-chunk-out parameters (chunks, parameters), NaN where a replicate's fit
    did not converge (no rows without per-chunk sums); ``variable`` what the fit's x is ("k" or "t").
    """

    quantity: str
    chain: str
    fit_range: tuple
    params: tuple
    stderr: tuple
    method: str
    fit: object
    correlation: np.ndarray
    replicates: np.ndarray | None = None
    variable: str = "k"


def _range_mask(granule, fit_range):
    g = np.asarray(granule)
    return (g >= fit_range[0]) & (g <= fit_range[1])


def _pulse_fit(ds, quantity, chain, fit_range, stat, sums, variable="k") -> PulseFit:
    fit = stat(pulse_means(ds), full=True)

    def replicate(m):
        try:
            return stat(m, full=False)
        except RuntimeError:  # a replicate whose fit does not converge: its stderr becomes NaN, never silently small
            return np.full(len(fit.params), np.nan)

    jk = pulse_jackknife(ds, replicate, sums)
    if sums is None:
        err, method, corr = fit.errors, RESIDUALS, fit.correlation
    else:
        err, method = tuple(float(e) for e in jk.stderr), jk.method
        corr = np.corrcoef(jk.replicates, rowvar=False)
    return PulseFit(quantity, chain, tuple(int(x) for x in fit_range), tuple(float(p) for p in fit.params),
                    tuple(float(e) for e in err), method, fit, corr, jk.replicates, variable)


def _check_chain(ds, chain):
    names = [str(c) for c in ds["chain"].values]
    if chain not in names:
        raise ValueError(f"chain = {chain!r} is not in the Dataset; choose one of {names}")


def fit_averaged_decay(ds, chain="effective", fit_range=(4, 25), sums: ChunkSums | None = None,
                       variable="k") -> PulseFit:
    """Paper Fig. 2: unweighted fit of max_t <v_k(t)> = a exp(-b x^c) over k in ``fit_range``.

    ``variable="k"``: x = granule k (a, b, c); ``"t"``: x = the peak's time (inset: a', b', c'),
    over the same granules. Errors: jackknife over the store's chunks (``sums``), else the
    fit residuals.
    """
    _check_chain(ds, chain)
    granule, time = ds["granule"].values, ds["time"].values.astype(float)

    def stat(means, full):
        v, t, _, _ = pulse_peak(time, means[chain])
        if variable == "k":
            f = fit_stretched_exp(granule, v, fit_range=fit_range, variable="k")
        else:
            sel = _range_mask(granule, fit_range)
            f = fit_stretched_exp(t[sel], v[sel], variable="t")
        return f if full else f.params

    q = "max_t <v_k(t)> = a exp(-b k^c)" if variable == "k" else "max_t <v_k(t)> = a' exp(-b' t^c')"
    return _pulse_fit(ds, q, chain, fit_range, stat, sums, variable)


def fit_averaged_arrival(ds, chain="effective", fit_range=(2, 25), sums: ChunkSums | None = None) -> PulseFit:
    """Paper Fig. 3: unweighted line argmax_t <v_k(t)> = slope k + intercept over ``fit_range``."""
    _check_chain(ds, chain)
    granule, time = ds["granule"].values, ds["time"].values.astype(float)

    def stat(means, full):
        _, t, _, _ = pulse_peak(time, means[chain])
        f = fit_linear(granule, t, fit_range=fit_range)
        return f if full else f.params

    return _pulse_fit(ds, "argmax_t <v_k(t)> = slope k + intercept", chain, fit_range, stat, sums)


def rounding_envelope(x, params, half_units) -> np.ndarray:
    """max |f(x; p') / f(x; p) - 1| over the corners p' = p +- half_units of the printed digits.

    How far the paper's stretched exponential can move when its parameters are known only to
    the digits printed (a = 0.756 means 0.7555..0.7565).
    """
    x = np.asarray(x, dtype=float)
    base = stretched_exp(x, *params)
    dev = np.zeros_like(base)
    for signs in itertools.product((-1, 1), repeat=len(params)):
        p = [q + s * h for q, s, h in zip(params, signs, half_units)]
        dev = np.maximum(dev, np.abs(stretched_exp(x, *p) / base - 1))
    return dev


@dataclass(frozen=True, eq=False)
class CurveAgreement:
    """Fitted curve f_k versus the paper's curve p_k over the fit range, granule by granule.

    ``deviation`` = f_k / p_k - 1 with its ``stderr`` (jackknife, or the fit's delta method
    with residual errors, see ``method``); ``envelope`` how far p_k moves within the paper's
    printed digits. The curves agree if |deviation| <= envelope + 2 stderr at every k.
    """

    chain: str
    fit_range: tuple
    granule: np.ndarray
    deviation: np.ndarray
    stderr: np.ndarray
    envelope: np.ndarray
    method: str

    @property
    def worst(self) -> int:
        """Index of the largest |deviation|."""
        return int(np.argmax(np.abs(self.deviation)))

    @property
    def max_relative(self) -> float:
        return float(np.abs(self.deviation[self.worst]))

    @property
    def agrees(self) -> bool:
        return bool(np.all(np.abs(self.deviation) <= self.envelope + 2 * self.stderr))


def paper_curve_agreement(ds, chain="effective", fit_range=(4, 25), sums: ChunkSums | None = None,
                          paper=PAPER_FIG2, half_units=(5e-4, 5e-4, 5e-4), fit: PulseFit | None = None) -> CurveAgreement:
    """The headline comparison of Fig. 2: our fitted curve against the paper's, per granule.

    ``fit``: the :func:`fit_averaged_decay` of the same Dataset, chain, range and ``sums`` (variable
    "k"), if already at hand: its fit and its leave-one-chunk-out parameters give the curves, instead of
    fitting every replicate again (the same numbers; a replicate whose fit did not converge gives NaN
    errors rather than an exception).
    """
    _check_chain(ds, chain)
    granule, time = ds["granule"].values, ds["time"].values.astype(float)
    k = granule[_range_mask(granule, fit_range)].astype(float)
    ref = stretched_exp(k, *paper)
    if fit is not None:
        groups = 0 if fit.replicates is None else fit.replicates.shape[0]
        if (fit.chain, fit.variable, tuple(fit.fit_range)) != (chain, "k", tuple(int(x) for x in fit_range)) or \
                groups != (0 if sums is None else sums.chunks):
            raise ValueError(f"fit must be fit_averaged_decay(ds, {chain!r}, {tuple(fit_range)}, sums) of the same "
                             f"sums, variable 'k'; got the {fit.chain!r} chain's fit over {fit.fit_range} (variable {fit.variable!r})")
        value = fit.fit(k) / ref - 1
        if sums is None:
            jk = Jackknife(value, np.full(value.shape, np.nan), np.empty((0,) + value.shape), 0, "none")
        else:
            reps = np.stack([stretched_exp(k, *p) / ref - 1 for p in fit.replicates])
            jk = Jackknife(value, jackknife_stderr(reps), reps, reps.shape[0], fit.method)
    else:
        def stat(means):
            v, _, _, _ = pulse_peak(time, means[chain])
            return fit_stretched_exp(granule, v, fit_range=fit_range)(k) / ref - 1

        jk = pulse_jackknife(ds, stat, sums)
    err, method = jk.stderr, jk.method
    if sums is None:
        full = (fit if fit is not None else fit_averaged_decay(ds, chain, fit_range)).fit
        err, method = full.stderr(k) / ref, RESIDUALS
    return CurveAgreement(chain, tuple(int(x) for x in fit_range), k.astype(int), jk.value, np.asarray(err),
                          rounding_envelope(k, paper, half_units), method)


def averaged_peak_gap(ds, granule=None, sums: ChunkSums | None = None) -> Jackknife:
    """max_t <v_k> of the decorated chain over that of the effective chain, minus 1, at ``granule``.

    Default k = N - 1, the last granule before the free end. Both chains come from the same
    realisations, so the jackknife over chunks includes their correlation; without ``sums``
    the stderr combines the stored per-chain errors as if independent (labelled in ``method``).
    """
    for c in ("decorated", "effective"):
        _check_chain(ds, c)
    ks = [int(k) for k in ds["granule"].values]
    k = ks[-2] if granule is None else int(granule)
    i = ks.index(k)
    time = ds["time"].values.astype(float)

    def stat(means):
        vd = pulse_peak(time, means["decorated"][i:i + 1])[0][0]
        ve = pulse_peak(time, means["effective"][i:i + 1])[0][0]
        return vd / ve - 1.0

    jk = pulse_jackknife(ds, stat, sums)
    if sums is not None:
        return jk
    d, e = averaged_pulse_peak(ds, "decorated"), averaged_pulse_peak(ds, "effective")
    r = d.velocity[i] / e.velocity[i]
    err = r * np.hypot(d.velocity_stderr[i] / d.velocity[i], e.velocity_stderr[i] / e.velocity[i])
    return Jackknife(jk.value, np.asarray(err), jk.replicates, 0,
                     "stored per-granule errors combined as independent (no per-chunk sums: an in-memory Dataset)")
