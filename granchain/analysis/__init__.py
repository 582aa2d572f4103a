"""Statistics of the paper's Sec. IV: decay fits, arrival times, histograms, KS distance.

* :func:`fit_stretched_exp` - v = a exp(-b x^c), paper Fig. 2 (x = granule k) and its
  inset (x = time t, parameters a', b', c');
* :func:`fit_linear` - arrival time versus k, paper Fig. 3 (t = 2.402 k - 1.181);
* :func:`histogram` - arrival-time densities with Poisson error bars, paper Fig. 4;
* :func:`ks_normal` - the KS distance d of the standardised sample to N(0, 1), paper
  Eq. (AD), with a Monte Carlo (Lilliefors) p-value;
* observables of an ensemble Dataset (the ``run_ensemble`` store schema) or of the store at a path
  (read with :func:`granchain.open_store`): the two
  different amplitudes :func:`mean_peak_amplitude` (<max_t v_k>) and
  :func:`averaged_pulse_peak` (max_t <v_k(t)>, the paper's Fig. 2), plus
  :func:`mean_arrival_time`, :func:`arrival_times`, :func:`out_of_order_peaks`;
* :func:`compare_curves` - fitted curves, not their strongly correlated parameters;
* robust statistics: :func:`quantile_skewness`; :func:`format_pvalue` (bounds at the Monte
  Carlo floor);
* jackknife errors over blocks of realisations or chunks of a store (:func:`block_jackknife`,
  :class:`ChunkSums`, :func:`chunk_jackknife`) and the paper's unweighted averaged-pulse fits
  with them (:func:`fit_averaged_decay`, :func:`fit_averaged_arrival`,
  :func:`paper_curve_agreement`, :func:`averaged_peak_gap`).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from scipy import optimize, special, stats

__all__ = [
    "PAPER_FIG2", "PAPER_FIG2_INSET", "PAPER_FIG3",
    "StretchedExpFit", "LinearFit", "Histogram", "KSResult", "PerGranule", "PulsePeak",
    "CurveComparison", "stretched_exp", "fit_stretched_exp", "fit_linear", "histogram",
    "ks_distance", "ks_normal", "skewness", "quantile_skewness", "format_pvalue", "pulse_peak", "mean_peak_amplitude", "averaged_pulse_peak",
    "mean_arrival_time", "arrival_times", "out_of_order_peaks", "compare_curves",
    # jackknife (granchain.analysis.jackknife) and averaged-pulse fits (granchain.analysis.pulsefits)
    "Jackknife", "ChunkSums", "block_labels", "jackknife_stderr", "block_jackknife", "chunk_jackknife",
    "PulseFit", "CurveAgreement", "pulse_means", "pulse_jackknife", "fit_averaged_decay", "fit_averaged_arrival",
    "paper_curve_agreement", "rounding_envelope", "averaged_peak_gap",
]

#: Paper Fig. 2: averaged-pulse peak v_k = a exp(-b k^c), N = 26, fit range about k = 4..25.
PAPER_FIG2 = (0.756, 0.067, 0.714)
#: Paper Fig. 2 inset: v(t) = a' exp(-b' t^c').
PAPER_FIG2_INSET = (0.744, 0.035, 0.714)
#: Paper Fig. 3: (slope, intercept) of t = 2.402 k - 1.181 (arrival of the averaged pulse).
PAPER_FIG3 = (2.402, -1.181)


def _frozen(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


def _xy(x, y, sigma, fit_range, what: str, min_points: int):
    """Validated 1-d arrays, restricted to the inclusive ``fit_range``; returns the indices used."""
    x = np.asarray(x, dtype=float).reshape(-1)
    y = np.asarray(y, dtype=float).reshape(-1)
    if x.shape != y.shape:
        raise ValueError(f"x and {what} must have the same length, got {x.size} and {y.size}")
    s = None if sigma is None else np.broadcast_to(np.asarray(sigma, dtype=float), x.shape)
    lo, hi = (np.nanmin(x), np.nanmax(x)) if fit_range is None else map(float, fit_range)
    if not lo <= hi:
        raise ValueError(f"fit_range = {fit_range!r} must be (x_min, x_max) with x_min <= x_max")
    keep = (x >= lo) & (x <= hi)
    for name, arr in (("x", x), (what, y), ("sigma", s)):
        if arr is not None and not np.all(np.isfinite(arr[keep])):
            i = int(np.flatnonzero(keep & ~np.isfinite(arr))[0])
            raise ValueError(f"{name} must be finite inside the fit range: entry {i} is {arr[i]!r}")
    if s is not None and np.any(s[keep] <= 0):
        raise ValueError("sigma must be > 0 (a standard error per point)")
    used = np.flatnonzero(keep)
    used.setflags(write=False)
    if used.size < min_points:
        raise ValueError(
            f"only {used.size} points lie in the fit range [{lo:g}, {hi:g}]; this fit needs at "
            f"least {min_points} (parameters + 1); widen fit_range"
        )
    return x[used], y[used], (None if s is None else s[used]), (float(lo), float(hi)), used


class _Fit:
    """Shared behaviour of :class:`StretchedExpFit` and :class:`LinearFit`."""

    @property
    def errors(self) -> tuple[float, ...]:
        """Standard errors of the parameters, sqrt(diag(covariance))."""
        return tuple(float(e) for e in np.sqrt(np.diag(self.covariance)))

    @property
    def correlation(self) -> np.ndarray:
        """Correlation matrix of the parameters (covariance / outer(errors, errors))."""
        e = np.sqrt(np.diag(self.covariance))
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.covariance / np.outer(e, e)

    @property
    def dof(self) -> int:
        return int(self.x.size - len(self.params))

    @property
    def chi2(self) -> float:
        """sum((residual / sigma)^2); NaN without sigmas."""
        return float(np.sum((self.residuals / self.sigma) ** 2)) if self.sigma is not None else float("nan")

    @property
    def reduced_chi2(self) -> float:
        """chi^2 / dof (expected near 1 if the sigmas are right); NaN without sigmas."""
        return self.chi2 / self.dof

    def stderr(self, x) -> np.ndarray:
        """Standard error of the fitted curve at x (delta method: sqrt(J C J^T))."""
        J = self._jac(np.asarray(x, dtype=float), *self.params)
        return np.sqrt(np.einsum("...i,ij,...j->...", J, self.covariance, J))

    def __call__(self, x):
        return self._model(np.asarray(x, dtype=float), *self.params)

    def _tail(self) -> str:
        lo, hi = self.fit_range
        chi = f"chi2/dof = {self.reduced_chi2:.3g} (dof {self.dof})" if self.sigma is not None else "no sigmas"
        return f"; fit range [{lo:g}, {hi:g}] ({self.x.size} points); {chi}"


def stretched_exp(x, a, b, c):
    """v = a exp(-b x^c), the paper's stretched exponential (Fig. 2)."""
    return a * np.exp(-b * np.power(x, c))


def _stretched_jac(x, a, b, c):
    xc = np.power(x, c)
    e = np.exp(-b * xc)
    with np.errstate(divide="ignore", invalid="ignore"):
        dc = np.where(x > 0, -a * b * xc * np.log(np.where(x > 0, x, 1.0)) * e, 0.0)
    return np.stack([e, -a * xc * e, dc], axis=-1)


@dataclass(frozen=True, eq=False)
class StretchedExpFit(_Fit):
    """Least-squares fit of v = a exp(-b x^c) (paper Fig. 2; the inset's a', b', c' versus t).

    The three parameters are strongly correlated (see :attr:`correlation`): compare fitted
    curves (:func:`compare_curves`, :meth:`stderr`) rather than parameters.
    ``used`` are the indices of the input points inside the inclusive ``fit_range``.
    """

    a: float
    b: float
    c: float
    covariance: np.ndarray
    x: np.ndarray
    y: np.ndarray
    sigma: np.ndarray | None
    residuals: np.ndarray
    fit_range: tuple[float, float]
    used: np.ndarray
    absolute_sigma: bool
    variable: str = "x"

    _model = staticmethod(stretched_exp)
    _jac = staticmethod(_stretched_jac)

    @property
    def params(self) -> tuple[float, float, float]:
        return (self.a, self.b, self.c)

    a_err = property(lambda self: self.errors[0])
    b_err = property(lambda self: self.errors[1])
    c_err = property(lambda self: self.errors[2])

    def summary(self) -> str:
        (ea, eb, ec), r = self.errors, self.correlation
        return (
            f"v = a exp(-b {self.variable}^c): a = {self.a:.4g} ± {ea:.2g}, b = {self.b:.4g} ± {eb:.2g}, "
            f"c = {self.c:.4g} ± {ec:.2g}; corr(a,b) = {r[0, 1]:.3f}, corr(b,c) = {r[1, 2]:.3f}" + self._tail()
        )


def _stretched_start(x, v, s):
    """Starting values: for each c on a grid, log v = log a - b x^c is linear; keep the best c."""
    w = np.ones_like(v) if s is None else v / s  # weights of log v
    best = (np.inf, None)
    for c in np.geomspace(0.05, 4.0, 81):
        A = np.stack([np.ones_like(x), -np.power(x, c)], axis=1)
        (loga, b), *_ = np.linalg.lstsq(A * w[:, None], np.log(v) * w, rcond=None)
        r = (v - stretched_exp(x, np.exp(loga), b, c)) / (1.0 if s is None else s)
        cost = float(np.sum(r * r))
        if cost < best[0]:
            best = (cost, (float(np.exp(loga)), float(b), float(c)))
    return best[1]


def fit_stretched_exp(x, v, sigma=None, *, fit_range=None, absolute_sigma=True, variable="x") -> StretchedExpFit:
    """Fit v = a exp(-b x^c) by ``scipy.optimize.curve_fit`` (paper Fig. 2 and its inset).

    ``fit_range = (x_min, x_max)`` is inclusive, in x units; None uses every point and records
    the data range. The paper fits the averaged-pulse peak over k = 4..25 for N = 26: k = 1
    (struck, v = 1 at t = 0) and k = N (free end) are special. ``sigma`` are per-point
    standard errors; with ``absolute_sigma`` they set the parameter errors directly,
    otherwise (and without sigma) the covariance is scaled by the residual variance.
    Starting values come from a linear fit of log v on x^c over a grid of c.
    Raises ValueError for fewer than 4 points in range or v <= 0 there.
    """
    if np.size(x) < 4 or np.size(v) < 4:
        raise ValueError(f"fit_stretched_exp needs x and v with at least 4 points each, got {np.size(x)} and {np.size(v)}")
    x, v, s, rng, used = _xy(x, v, sigma, fit_range, "v", 4)
    if np.any(v <= 0):
        raise ValueError("v must be > 0 inside the fit range for a stretched exponential")
    if np.any(x <= 0):
        raise ValueError("x must be > 0 inside the fit range (x^c with x <= 0 is undefined for c < 1)")
    p0 = _stretched_start(x, v, s)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", optimize.OptimizeWarning)
        try:
            p, cov = optimize.curve_fit(
                stretched_exp, x, v, p0=p0, sigma=s, absolute_sigma=bool(absolute_sigma and s is not None),
                jac=lambda x, *p: _stretched_jac(x, *p), maxfev=20000,
            )
        except RuntimeError as exc:
            raise RuntimeError(f"stretched-exponential fit did not converge from {p0}: {exc}") from None
    return StretchedExpFit(
        *map(float, p), covariance=_frozen(cov), x=_frozen(x), y=_frozen(v),
        sigma=None if s is None else _frozen(s), residuals=_frozen(v - stretched_exp(x, *p)),
        fit_range=rng, used=used, absolute_sigma=bool(absolute_sigma and s is not None), variable=variable,
    )


@dataclass(frozen=True, eq=False)
class LinearFit(_Fit):
    """Weighted least-squares line y = slope x + intercept (paper Fig. 3: t = 2.402 k - 1.181)."""

    slope: float
    intercept: float
    covariance: np.ndarray
    x: np.ndarray
    y: np.ndarray
    sigma: np.ndarray | None
    residuals: np.ndarray
    fit_range: tuple[float, float]
    used: np.ndarray
    absolute_sigma: bool

    _model = staticmethod(lambda x, m, q: m * x + q)
    _jac = staticmethod(lambda x, m, q: np.stack([x, np.ones_like(x)], axis=-1))

    @property
    def params(self) -> tuple[float, float]:
        return (self.slope, self.intercept)

    slope_err = property(lambda self: self.errors[0])
    intercept_err = property(lambda self: self.errors[1])

    def summary(self) -> str:
        em, eq = self.errors
        return f"y = ({self.slope:.5g} ± {em:.2g}) x + ({self.intercept:.5g} ± {eq:.2g})" + self._tail()


def fit_linear(x, y, sigma=None, *, fit_range=None, absolute_sigma=True) -> LinearFit:
    """Fit y = slope x + intercept with weights 1/sigma^2 (paper Fig. 3, arrival time vs k).

    ``fit_range`` is inclusive in x units (None: all points, recorded). Covariance
    (X^T W X)^-1, scaled by chi^2/dof unless ``absolute_sigma`` and sigma are given.
    Raises ValueError for fewer than 3 points in range.
    """
    x, y, s, rng, used = _xy(x, y, sigma, fit_range, "y", 3)
    w = np.ones_like(x) if s is None else 1.0 / s**2
    X = np.stack([x, np.ones_like(x)], axis=1)
    if np.ptp(x) == 0:
        raise ValueError("all x in the fit range are equal: the slope is undefined")
    cov = np.linalg.inv(X.T @ (X * w[:, None]))
    p = cov @ (X.T @ (w * y))
    r = y - X @ p
    absolute = bool(absolute_sigma and s is not None)
    if not absolute:
        cov = cov * float(np.sum(w * r * r)) / (x.size - 2)
    return LinearFit(
        float(p[0]), float(p[1]), covariance=_frozen(cov), x=_frozen(x), y=_frozen(y),
        sigma=None if s is None else _frozen(s), residuals=_frozen(r), fit_range=rng, used=used,
        absolute_sigma=absolute,
    )


def _sample(sample, min_size: int) -> np.ndarray:
    x = np.asarray(sample, dtype=float).reshape(-1)
    if x.size < min_size:
        raise ValueError(f"the sample needs at least {min_size} values, got {x.size}")
    if not np.all(np.isfinite(x)):
        raise ValueError("the sample must be finite (drop failed realisations first)")
    if np.ptp(x) == 0:
        raise ValueError("the sample is constant: its standard deviation is zero")
    return x


@dataclass(frozen=True, eq=False)
class Histogram:
    """Binned sample (paper Fig. 4): ``values`` is a density if ``density`` else counts.

    ``errors`` are Poisson, sqrt(count) in the same normalisation. If ``standardized``
    the bins are in z = (x - mean) / std (ddof = 1, Eq. (AD)), to compare with N(0, 1).
    """

    centres: np.ndarray
    edges: np.ndarray
    counts: np.ndarray
    values: np.ndarray
    errors: np.ndarray
    n: int
    mean: float
    std: float
    density: bool
    standardized: bool


def histogram(sample, bins=40, *, range=None, density=True, standardize=False) -> Histogram:
    """Histogram with Poisson error bars; ``bins``/``range`` as in ``numpy.histogram``."""
    x = _sample(sample, 2)
    mean, std = float(x.mean()), float(x.std(ddof=1))
    if standardize:
        x = (x - mean) / std
    counts, edges = np.histogram(x, bins=bins, range=range)
    norm = np.full(counts.shape, 1.0) if not density else 1.0 / (x.size * np.diff(edges))
    return Histogram(
        centres=_frozen(0.5 * (edges[1:] + edges[:-1])), edges=_frozen(edges), counts=_frozen(counts),
        values=_frozen(counts * norm), errors=_frozen(np.sqrt(counts) * norm), n=int(x.size),
        mean=mean, std=std, density=bool(density), standardized=bool(standardize),
    )


def _ks_statistic(dist, data, axis=-1):
    """sup |F_z - Phi| of z = (x - mean)/std(ddof=1) along ``axis`` (``dist`` ignored)."""
    data = np.moveaxis(np.asarray(data, dtype=float), axis, -1)
    z = (data - data.mean(axis=-1, keepdims=True)) / data.std(axis=-1, ddof=1, keepdims=True)
    cdf = special.ndtr(np.sort(z, axis=-1))  # Phi: what stats.norm.cdf evaluates, without its argument checks
    n = z.shape[-1]
    i = np.arange(1, n + 1)
    return np.maximum((i / n - cdf).max(axis=-1), (cdf - (i - 1) / n).max(axis=-1))


def ks_distance(sample) -> float:
    """Paper Eq. (AD): d = sup |F_z - Phi| with z = (x - mean) / std (ddof = 1).

    Equal to ``scipy.stats.kstest(z, 'norm').statistic``; invariant under x -> alpha x + beta.
    """
    return float(_ks_statistic(None, _sample(sample, 3)))


def skewness(sample, *, bias=False) -> float:
    """Sample skewness (``scipy.stats.skew``); ``bias=False`` gives the corrected G1.

    The third moment is dominated by a few outliers in a long tail; see
    :func:`quantile_skewness` for a robust companion.
    """
    return float(stats.skew(_sample(sample, 3), bias=bias))


def quantile_skewness(sample, p=0.25) -> float:
    """Robust (quantile) skewness (Q(1-p) + Q(p) - 2 Q(1/2)) / (Q(1-p) - Q(p)).

    Bowley's coefficient for p = 1/4 (Hinkley 1975 for general p): in [-1, 1], 0 for any
    symmetric distribution, insensitive to the outermost fraction p of each tail. For a
    normal sample it is 0; for an exponential one (p = 1/4) it is ln(4/3) / ln 3 = 0.2619.
    """
    x = _sample(sample, 3)
    if not 0 < p < 0.5:
        raise ValueError(f"p must lie in (0, 1/2), got {p!r}")
    lo, med, hi = np.quantile(x, [p, 0.5, 1 - p])
    if hi == lo:
        raise ValueError(f"the {p:g} and {1 - p:g} quantiles coincide: quantile skewness undefined")
    return float((hi + lo - 2 * med) / (hi - lo))


def format_pvalue(p, n_mc_samples) -> str:
    """A Monte Carlo p-value as text: a bound "< 1/(B+1)" at the Monte Carlo floor.

    With B resamples the smallest estimate is 1/(B+1) (no resample reached the observed
    statistic): the p-value is then only known to be below about that, and printing
    "0.000999" would claim a precision the test does not have.
    """
    B = int(n_mc_samples)
    if B <= 0 or not np.isfinite(p):
        return "not computed"
    floor = 1.0 / (B + 1)
    if p <= floor * (1 + 1e-9):
        return f"< 1/(B+1) = {floor:.2g} (B = {B})"
    return f"{p:.2g} (B = {B})"


@dataclass(frozen=True)
class KSResult:
    """KS distance d of the standardised sample to N(0, 1) (paper Eq. (AD)) and its context.

    ``pvalue`` is the Monte Carlo Lilliefors p-value (NaN if ``n_mc_samples`` = 0), resolution
    1/(n_mc_samples + 1). Skewness and excess kurtosis are bias-corrected.
    """

    d: float
    pvalue: float
    n: int
    mean: float
    std: float
    skewness: float
    excess_kurtosis: float
    n_mc_samples: int

    @property
    def at_floor(self) -> bool:
        """True if no Monte Carlo resample reached d: the p-value is a bound, < 1/(B+1)."""
        return self.n_mc_samples > 0 and self.pvalue <= (1 + 1e-9) / (self.n_mc_samples + 1)

    @property
    def pvalue_text(self) -> str:
        """:func:`format_pvalue` of this p-value."""
        return format_pvalue(self.pvalue, self.n_mc_samples)


#: The screen of ``_null_count``: bins of width 16/8192 in z over [-8, 8] (one bin holds at most
#: 0.4 * 16/8192 = 7.8e-4 of N(0, 1)), the two outer bins reaching to -inf and +inf.
_SCREEN_HALF_WIDTH, _SCREEN_BINS = 8.0, 8192
_SCREEN_EDGES = np.concatenate([[-np.inf], np.linspace(-_SCREEN_HALF_WIDTH, _SCREEN_HALF_WIDTH, _SCREEN_BINS + 1), [np.inf]])
_SCREEN_CDF = special.ndtr(_SCREEN_EDGES)


def _ks_upper_bound(data) -> np.ndarray:
    """An upper bound, in O(n) per row, of :func:`_ks_statistic` of each row of ``data`` (no sort).

    The standardised values z (computed as the statistic computes them) are counted in the bins of
    ``_SCREEN_EDGES``; the assignment is monotone in z, so a value of rank i in bin b has
    C_b < i <= C_(b+1) (C_b: values in the bins below b). With Phi of the edges one bin further out on
    each side (an assignment can be one bin off where z lies within rounding of an edge),
    i/n - Phi(z) <= C_(b+1)/n - Phi(e_(b-1)) and Phi(z) - (i-1)/n <= Phi(e_(b+2)) - C_b/n; the maximum
    over the bins bounds the statistic. For a normal sample of 30,000 it exceeds the statistic by
    about 2e-3 (two bins of probability), far below the d of a non-Gaussian sample.
    """
    data = np.asarray(data, dtype=float)
    rows, n = data.shape
    z = (data - data.mean(axis=-1, keepdims=True)) / data.std(axis=-1, ddof=1, keepdims=True)
    nb = _SCREEN_BINS + 2  # bin 0 is (-inf, -8), bin nb - 1 is [8, inf)
    b = np.floor((z + _SCREEN_HALF_WIDTH) * (_SCREEN_BINS / (2 * _SCREEN_HALF_WIDTH)))
    np.clip(b, -1, _SCREEN_BINS, out=b)
    b = b.astype(np.int64) + 1
    b += (np.arange(rows) * nb)[:, None]
    counts = np.bincount(b.ravel(), minlength=rows * nb).reshape(rows, nb)
    below = np.zeros((rows, nb + 1))
    np.cumsum(counts, axis=1, out=below[:, 1:])
    below /= n  # below[:, b] = C_b / n, b = 0 .. nb
    cdf = _SCREEN_CDF  # Phi(e_b) for the nb + 1 edges e_0 = -inf .. e_nb = +inf
    lo = np.concatenate([[0.0], cdf[:-2]])  # Phi(e_(b-1)) for bin b
    hi = np.concatenate([cdf[2:], [1.0]])  # Phi(e_(b+2)) for bin b
    return np.maximum(below[:, 1:] - lo, hi - below[:, :-1]).max(axis=1)


def _null_count(x, d: float, m: int, gen, batch: int) -> int:
    """How many of ``m`` Lilliefors resamples of ``x`` reach ``d``: their statistic >= d (1 - 1e-12).

    The resamples are those of ``scipy.stats.goodness_of_fit(norm, x, statistic=_ks_statistic,
    n_mc_samples=k, rng=gen)`` called once per batch of k <= ``batch`` (the normal fitted to x with
    ddof = 1, ``gen.standard_normal((k, n)) * scale + loc``), and the statistic of a resample that may
    reach d is :func:`_ks_statistic` of that resample: the count equals the count over goodness_of_fit's
    null distribution (tests/test_analysis.py compares them). Only the resamples whose
    :func:`_ks_upper_bound` reaches d are sorted: for a sample far from normal none is, and the Monte
    Carlo costs a third of the full one.
    """
    loc, scale = np.mean(x, axis=-1), np.std(x, ddof=1, axis=-1)
    threshold = d * (1 - 1e-12)
    hits = 0
    for k in np.diff(np.r_[0:m:int(batch), m]):
        data = gen.standard_normal((int(k), x.size)) * scale + loc
        maybe = np.flatnonzero(_ks_upper_bound(data) >= threshold - 1e-9)  # the margin covers Phi's rounding
        if maybe.size:
            hits += int(np.count_nonzero(_ks_statistic(None, data[maybe]) >= threshold))
    return hits


def ks_normal(sample, *, n_mc_samples=500, rng=0, batch=100) -> KSResult:
    """KS distance to the normal with estimated mean and std, paper Eq. (AD), and a p-value.

    d = sup |F_z - Phi| with z = (x - mean)/std, std with ddof = 1. Because mean and std are
    estimated from the sample, the plain KS p-value (``kstest``) is far too large; the
    p-value here is Lilliefors', by Monte Carlo: the resamples and the statistic of
    ``scipy.stats.goodness_of_fit(norm)`` with this statistic as a callable (identical to scipy's
    ``'ks'``, whose normal fit also uses ddof = 1), called in batches of ``batch`` resamples, and
    the same p-value, (1 + #{resamples reaching d}) / (B + 1). A resample is sorted only where a
    bound computed without sorting cannot rule out that it reaches d (``_null_count``), so a
    sample far from normal (every sample of the paper's Fig. 4) costs ~0.6 s for 30,000 values at
    B = 1000 instead of ~2 s, with ~100 MB peak memory per batch of 100. ``rng`` seeds the resamples.

    With ~30,000 samples any real (non-Gaussian) distribution is rejected: the p-value says
    little. Report d and how it falls with chain length N (paper Sec. IV). For a Gaussian
    sample d is of order 0.5-1/sqrt(n) (Lilliefors' 5 % critical value ~0.89/sqrt(n)).
    """
    x = _sample(sample, 5)
    d = float(_ks_statistic(None, x))
    m = int(n_mc_samples)
    if m < 0 or m != n_mc_samples or int(batch) < 1:
        raise ValueError(f"n_mc_samples must be a whole number >= 0 and batch >= 1, got {n_mc_samples!r}, {batch!r}")
    pvalue = float("nan")
    if m:
        pvalue = (1.0 + _null_count(x, d, m, np.random.default_rng(rng), int(batch))) / (m + 1.0)
    return KSResult(
        d=d, pvalue=float(pvalue), n=int(x.size), mean=float(x.mean()), std=float(x.std(ddof=1)),
        skewness=float(stats.skew(x, bias=False)), excess_kurtosis=float(stats.kurtosis(x, bias=False)),
        n_mc_samples=m,
    )


# ---------------------------------------------------------------- ensemble Dataset observables

_NEEDED = ("status", "peak_velocity", "peak_time", "mean_velocity", "mean_velocity_stderr")


def _dataset(ds):
    """An ensemble Dataset as given, or the store at a path (str or os.PathLike) read with
    :func:`granchain.open_store` (records and metadata of earlier versions in today's form)."""
    import os

    if isinstance(ds, (str, os.PathLike)):
        from ..ensembles.read import open_store
        from ..ensembles.verify import StoreDamagedError

        try:
            return open_store(ds)
        except StoreDamagedError:  # a store, damaged: its own message names the chunk and the remedy
            raise
        except ValueError as exc:
            raise ValueError(f"ds = {os.fspath(ds)!r} is neither an ensemble Dataset nor a store it can read: {exc}") from None
    return ds


def _chain(ds, chain: str, need: tuple[str, ...]):
    ds = _dataset(ds)
    missing = [v for v in need if v not in ds.variables]
    if missing:
        raise ValueError(f"the Dataset lacks {missing}; expected the run_ensemble schema ({', '.join(_NEEDED)})")
    names = [str(c) for c in ds["chain"].values]
    if chain not in names:
        raise ValueError(f"chain = {chain!r} is not in the Dataset; choose one of {names}")
    return ds.sel(chain=chain)


def _valid(sub, name: str) -> np.ndarray:
    """(realization, granule) values of ``name`` with failed realisations (status != 0) as NaN."""
    values = sub[name].transpose("realization", "granule").values.astype(float)
    ok = sub["status"].transpose("realization").values == 0
    return np.where(ok[:, None], values, np.nan)


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


@dataclass(frozen=True)
class CurveComparison:
    """Differences between two curves on a grid of x (see :func:`compare_curves`)."""

    max_relative: float
    x_at_max_relative: float
    max_absolute: float
    max_pull: float


def compare_curves(f, g, x) -> CurveComparison:
    """Max |f - g| / |g| over x (and max absolute difference) of two fitted curves.

    The three stretched-exponential parameters are strongly correlated, so two fits can
    differ in (a, b, c) by many errors yet describe the same curve: compare curves. ``f`` and
    ``g`` are callables (fits, or e.g. ``lambda k: stretched_exp(k, *PAPER_FIG2)``).
    ``max_pull`` is max |f - g| / sqrt(se_f^2 + se_g^2) using the fits' :meth:`stderr`
    (a plain callable counts as exact); NaN if neither has one.
    """
    x = np.asarray(x, dtype=float).reshape(-1)
    if x.size == 0 or not np.all(np.isfinite(x)):
        raise ValueError("x must be a non-empty array of finite values")
    fx, gx = np.asarray(f(x), dtype=float), np.asarray(g(x), dtype=float)
    diff = np.abs(fx - gx)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = diff / np.abs(gx)
        var = sum(h.stderr(x) ** 2 for h in (f, g) if hasattr(h, "stderr"))
        pull = float(np.max(diff / np.sqrt(var))) if np.ndim(var) else float("nan")
    i = int(np.nanargmax(rel))
    return CurveComparison(float(rel[i]), float(x[i]), float(np.max(diff)), pull)


# The jackknife (granchain.analysis.jackknife, which needs nothing from here) is re-exported as it is. The
# averaged-pulse fits (granchain.analysis.pulsefits) build on the functions above, so they are offered
# here lazily (PEP 562 module __getattr__): importing this module does not import them, and the
# package's import graph has no cycle (tests/test_imports.py).
from .jackknife import (  # noqa: E402
    ChunkSums,
    Jackknife,
    block_jackknife,
    block_labels,
    chunk_jackknife,
    jackknife_stderr,
)
from .spacetime import AveragedPulse, averaged_pulse, plot_averaged_pulse, __all__ as _SPACETIME  # noqa: E402
__all__ += _SPACETIME  # the averaged pulse as a space-time diagram (granchain.analysis.spacetime)

_PULSEFITS = ("CurveAgreement", "PulseFit", "averaged_peak_gap", "fit_averaged_arrival", "fit_averaged_decay",
              "paper_curve_agreement", "pulse_jackknife", "pulse_means", "rounding_envelope")


def __getattr__(name):
    if name in _PULSEFITS:
        from . import pulsefits as _pulsefits

        return getattr(_pulsefits, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_PULSEFITS))
