"""Least-squares fits of the paper's Sec. IV curves, and how to compare fitted curves.

* :func:`fit_stretched_exp` - v = a exp(-b x^c), paper Fig. 2 (x = granule k) and its
  inset (x = time t, parameters a', b', c');
* :func:`fit_linear` - arrival time versus k, paper Fig. 3 (t = 2.402 k - 1.181);
* :func:`compare_curves` - fitted curves, not their strongly correlated parameters;
* the paper's own values (:data:`PAPER_FIG2`, :data:`PAPER_FIG2_INSET`, :data:`PAPER_FIG3`).

Re-exported by :mod:`granchain.analysis`.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from scipy import optimize

from ._arrays import _frozen

__all__ = ["PAPER_FIG2", "PAPER_FIG2_INSET", "PAPER_FIG3", "StretchedExpFit", "LinearFit", "CurveComparison",
           "stretched_exp", "fit_stretched_exp", "fit_linear", "compare_curves"]

#: Paper Fig. 2: averaged-pulse peak v_k = a exp(-b k^c), N = 26, fit range about k = 4..25.
PAPER_FIG2 = (0.756, 0.067, 0.714)
#: Paper Fig. 2 inset: v(t) = a' exp(-b' t^c').
PAPER_FIG2_INSET = (0.744, 0.035, 0.714)
#: Paper Fig. 3: (slope, intercept) of t = 2.402 k - 1.181 (arrival of the averaged pulse).
PAPER_FIG3 = (2.402, -1.181)


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
