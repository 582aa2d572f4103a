"""Why the averaged pulse decays: dephasing of realisations (the paper's open "remedy").

The paper's Fig. 2 amplitude is the peak of the ensemble-averaged pulse, max_t <v_k(t)>. Each
realisation's pulse reaches granule k at its own time t_k (spread s_k) with its own peak P_k;
averaging pulses that are out of phase flattens them. Write v_k(t) ~= P_k S_k(t - t_k) with one
pulse *shape* S_k per granule (S_k(0) = 1). Then

    <v_k(t)> ~= < P_k S_k(t - t_k) >                                              (1)

which this module evaluates at three levels:

1. :func:`predict_from_ensemble` - Eq. (1) with the ensemble's own arrival times and peaks and the
   *aligned* pulse A_k(tau) = <v_k(t_k + tau)> (``run_ensemble(..., lags=...)``) as the shape,
   S_k = A_k / A_k(0). The correlation of P_k and t_k is kept (``weighted=False``: P_k -> <P_k>).
2. :func:`predict_closed_form` - t_k Gaussian of spread s_k and independent of P_k:
   <v_k(t)> ~= <P_k> (S_k * G_{s_k})(t), peak = <P_k> max_t (S_k * G_{s_k}), with S_k the measured
   aligned shape or a Nesterenko-type cos^4 of fitted width (the long-wave solitary wave of a
   Hertz chain, n = 5/2: v ~ cos^(2/(n-2)) = cos^4, V. F. Nesterenko, J. Appl. Mech. Tech. Phys. 24,
   733 (1983)), and s_k measured or from the BCA (:func:`arrival_spread`: the Gaussian limit,
   Eq. (dist-1), or the BCA sum Eq. (total-time-1) / (total-time) on the ensemble's actual radii).
3. :func:`predict_mean_peak` - the remaining input <P_k> = <max_t v_k>: tried from the BCA's
   velocities Eq. (vk) on the effective chain's random masses.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from .. import analysis, bca
from .._validate import EffectiveValidityWarning

__all__ = ["Prediction", "aligned_shape", "predict_from_ensemble", "predict_closed_form", "arrival_spread",
           "cos4_shape", "fit_cos4_width", "predict_mean_peak", "summary"]


@dataclass(frozen=True, eq=False)
class Prediction:
    """A prediction of max_t <v_k(t)> per granule, and the numerics it is compared with."""

    method: str
    granule: np.ndarray
    predicted: np.ndarray
    measured: np.ndarray
    measured_stderr: np.ndarray

    @property
    def relative_error(self) -> np.ndarray:
        return self.predicted / self.measured - 1.0

    def error_in(self, k_range=(4, 25)) -> tuple[float, float]:
        """(max |relative error|, rms relative error) over granules k_range[0]..k_range[1]."""
        sel = (self.granule >= k_range[0]) & (self.granule <= k_range[1])
        e = self.relative_error[sel]
        return float(np.max(np.abs(e))), float(np.sqrt(np.mean(e**2)))


def _need_aligned(ds):
    if "aligned_velocity" not in ds.variables:
        raise ValueError("the Dataset has no aligned pulse: run the ensemble with lags, e.g. "
                         "run_ensemble(family, ..., lags=numpy.arange(-12, 12.01, 0.1))")


def aligned_shape(ds, chain: str = "decorated") -> tuple[np.ndarray, np.ndarray]:
    """(lags (L,), S (K, L)): the aligned pulse normalised to 1 at lag 0 (interpolated if 0 is no lag)."""
    _need_aligned(ds)
    a = ds["aligned_velocity"].sel(chain=chain).transpose("granule", "lag").values
    lags = ds["lag"].values.astype(float)
    a0 = np.array([np.interp(0.0, lags, row) for row in a])
    return lags, a / a0[:, None]


def _valid(ds, chain):
    sub = ds.sel(chain=chain)
    ok = sub["status"].values == 0
    return sub["peak_velocity"].transpose("realization", "granule").values[ok], \
        sub["peak_time"].transpose("realization", "granule").values[ok]


def _peak_of(f, t_lo, t_hi, n: int = 801) -> float:
    """max of f(t) on [t_lo, t_hi] (fine grid, then a parabola through the best three samples)."""
    t = np.linspace(t_lo, t_hi, n)
    y = f(t)
    i = int(np.clip(np.argmax(y), 1, n - 2))
    y0, y1, y2 = y[i - 1 : i + 2]
    curv = y0 - 2 * y1 + y2
    off = 0.5 * (y0 - y2) / curv if curv < 0 else 0.0
    return float(y1 - 0.25 * (y0 - y2) * off)


def predict_from_ensemble(ds, chain: str = "decorated", *, weighted: bool = True) -> Prediction:
    """Level 1: Eq. (1) from the ensemble's own (t_k, P_k) and its aligned pulse shape.

    ``weighted=False`` replaces P_k by <P_k> (drops the P-t correlation)."""
    lags, S = aligned_shape(ds, chain)
    P, T = _valid(ds, chain)
    ks = ds["granule"].values
    pred = np.full(ks.size, np.nan)
    for q in range(ks.size):
        p = P[:, q] if weighted else np.full(P.shape[0], P[:, q].mean())
        t = T[:, q]

        def f(tt, p=p, t=t, s=S[q]):
            return np.array([np.mean(p * np.interp(x - t, lags, s, left=0.0, right=0.0)) for x in tt])

        lo, hi = np.percentile(t, 2), np.percentile(t, 98)
        pred[q] = _peak_of(f, lo - 1.0, hi + 1.0, 241)
    return _compare(ds, chain, "ensemble (t_k, P_k) x aligned shape" + ("" if weighted else ", unweighted"), ks, pred)


def _compare(ds, chain, method, ks, pred) -> Prediction:
    meas = analysis.averaged_pulse_peak(ds, chain)
    return Prediction(method, np.asarray(ks), pred, np.asarray(meas.velocity), np.asarray(meas.velocity_stderr))


def cos4_shape(tau, width):
    """Nesterenko-type pulse cos^4(pi tau / width) for |tau| < width/2, else 0 (Hertz, n = 5/2)."""
    tau = np.asarray(tau, dtype=float)
    return np.where(np.abs(tau) < 0.5 * width, np.cos(np.pi * tau / width) ** 4, 0.0)


def fit_cos4_width(lags, shape) -> float:
    """Full width W of the cos^4 pulse that best fits (least squares) an aligned shape where it is > 0.05."""
    from scipy.optimize import minimize_scalar

    sel = shape > 0.05
    res = minimize_scalar(lambda w: np.sum((cos4_shape(lags[sel], w) - shape[sel]) ** 2), bounds=(1.0, 40.0), method="bounded")
    return float(res.x)


def _smeared_peak(lags, shape, s) -> float:
    """max_t (shape * Gaussian(0, s))(t) by quadrature on the lag grid."""
    if not s > 0:
        return float(np.max(shape))
    dt = float(np.median(np.diff(lags)))
    half = int(math.ceil(5 * s / dt))
    u = np.arange(-half, half + 1) * dt
    g = np.exp(-0.5 * (u / s) ** 2)
    g /= g.sum()
    fine = np.arange(lags[0], lags[-1] + 0.5 * dt, dt)
    y = np.convolve(np.interp(fine, lags, shape, left=0.0, right=0.0), g, mode="same")
    i = int(np.clip(np.argmax(y), 1, y.size - 2))
    y0, y1, y2 = y[i - 1 : i + 2]
    curv = y0 - 2 * y1 + y2
    off = 0.5 * (y0 - y2) / curv if curv < 0 else 0.0
    return float(y1 - 0.25 * (y0 - y2) * off)


def arrival_spread(ds, source: str = "measured", chain: str = "decorated") -> np.ndarray:
    """s_k, the spread of the arrival time at every large granule k (k = 1: 0).

    ``source``: "measured" (std of the ensemble's peak times), "gaussian" (the BCA's Gaussian limit,
    Eq. dist-1, std sqrt(k-1) P sigma), "equal-mass" (std over the ensemble's radii of the BCA sum
    Eq. total-time-1), "full" (of Eq. total-time on the effective chain).
    """
    from ..families import family_from_dataset

    ks = ds["granule"].values
    if source == "measured":
        _, T = _valid(ds, chain)
        return T.std(axis=0, ddof=1)
    fam = family_from_dataset(ds)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", EffectiveValidityWarning)
        if source == "gaussian":
            return np.array([0.0 if k == 1 else bca.gaussian_limit(fam.distribution, int(k), fam.n).std for k in ks])
        if source in ("equal-mass", "full"):
            ok = ds["status"].sel(chain=chain).values == 0
            t = bca.arrival_times(ds["small_radius"].values[ok], fam.n, approximation=source)
            return t.std(axis=0, ddof=1)
    raise ValueError(f"source must be 'measured', 'gaussian', 'equal-mass' or 'full', got {source!r}")


def predict_closed_form(ds, chain: str = "decorated", *, spread: str = "measured", shape: str = "aligned",
                        mean_peak=None) -> Prediction:
    """Level 2: <P_k> max_t (S_k * G_{s_k}) with s_k from :func:`arrival_spread` (``spread``) and S_k
    the measured aligned shape (``shape="aligned"``) or a cos^4 of width fitted to it (``"cos4"``).
    ``mean_peak`` (K,) replaces the measured <max_t v_k> (e.g. :func:`predict_mean_peak`)."""
    lags, S = aligned_shape(ds, chain)
    P, _ = _valid(ds, chain)
    mp = P.mean(axis=0) if mean_peak is None else np.asarray(mean_peak, dtype=float)
    s = arrival_spread(ds, spread, chain)
    ks = ds["granule"].values
    pred = np.full(ks.size, np.nan)
    for q in range(ks.size):
        prof = S[q] if shape == "aligned" else cos4_shape(lags, fit_cos4_width(lags, S[q]))
        if shape not in ("aligned", "cos4"):
            raise ValueError(f"shape must be 'aligned' or 'cos4', got {shape!r}")
        pred[q] = mp[q] * _smeared_peak(lags, prof, s[q])
    return _compare(ds, chain, f"closed form: {shape} shape, s_k {spread}", ks, pred)


def predict_mean_peak(ds, calibrate_at: int | None = None, window: int = 1) -> np.ndarray:
    """Level 3: <max_t v_k> from the BCA velocities Eq. (vk), v_k = prod 2 M_{j,j+1} / mu_{j+1}, on each
    realisation's effective masses mu (Eq. renorm-mass), averaged over the ensemble.

    The BCA transmits the whole pulse at each collision (v = 1 for equal masses), while the
    solitary wave carries ~0.7 of it: ``calibrate_at`` = k scales the prediction to the measured
    <max_t v_k> at that granule (one constant). ``window`` > 1 first averages mu over that many
    neighbouring granules (a crude "renormalisation" by the pulse's width)."""
    from ..model.effective import effective_parameters

    ok = np.all(ds["status"].values == 0, axis=0)
    r = ds["small_radius"].values[ok]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", EffectiveValidityWarning)
        mu, c = effective_parameters(np.ones((r.shape[0], r.shape[1] + 1)), r, float(ds.attrs["n"]))
    if window > 1:
        kern = np.ones(window) / window
        mu = np.array([np.convolve(np.pad(m, (window // 2, window - 1 - window // 2), mode="edge"), kern, mode="valid") for m in mu])
    v = bca._bca(mu, c, float(ds.attrs["n"]), np.ones(mu.shape[0]))[1]  # Eq. (vk)
    pred = v.mean(axis=0)
    if calibrate_at is not None:
        ks = list(ds["granule"].values)
        q = ks.index(calibrate_at)
        P, _ = _valid(ds, "decorated")
        pred = pred * P[:, q].mean() / pred[q]
    return pred


def summary(ds, chain: str = "decorated", k_range=(4, 25)) -> str:
    """Markdown table: every prediction's max and rms relative error over ``k_range``."""
    rows = [predict_from_ensemble(ds, chain), predict_from_ensemble(ds, chain, weighted=False)]
    for spread in ("measured", "gaussian", "equal-mass", "full"):
        rows.append(predict_closed_form(ds, chain, spread=spread))
    rows.append(predict_closed_form(ds, chain, spread="measured", shape="cos4"))
    P, _ = _valid(ds, chain)
    meas_mp = P.mean(axis=0)
    lines = [f"max_t <v_k(t)> predicted vs the numerics ({chain} chain, N = {ds.sizes['granule']}, "
             f"{int((ds['status'].sel(chain=chain) == 0).sum())} realisations), relative errors over k = {k_range[0]}..{k_range[1]}:", "",
             "| prediction | max abs error | rms error | max abs vs the paper's a exp(-b k^c) |", "|---|---|---|---|"]
    sel = (ds["granule"].values >= k_range[0]) & (ds["granule"].values <= k_range[1])
    paper = analysis.stretched_exp(ds["granule"].values.astype(float), *analysis.PAPER_FIG2)
    vs_paper = lambda x: f"{100 * np.max(np.abs(x[sel] / paper[sel] - 1.0)):.2f} %"  # noqa: E731
    lines.append(f"| (the numerics themselves) | - | - | {vs_paper(rows[0].measured)} |")
    for p in rows:
        mx, rms = p.error_in(k_range)
        lines.append(f"| {p.method} | {100 * mx:.2f} % | {100 * rms:.2f} % | {vs_paper(p.predicted)} |")
    for label, kw in (("BCA Eq. (vk) on effective masses", {}), ("same, calibrated at k = 2", {"calibrate_at": 2}),
                      ("same, mu averaged over 5 granules, calibrated at k = 2", {"calibrate_at": 2, "window": 5})):
        e = predict_mean_peak(ds, **kw)[sel] / meas_mp[sel] - 1.0
        lines.append(f"| <max_t v_k> from the {label} | {100 * np.max(np.abs(e)):.2f} % | {100 * np.sqrt(np.mean(e**2)):.2f} % | - |")
    return "\n".join(lines)


def _split_builder(n_large: int, distribution, keep: str):
    """build(rng) -> the effective chain of RandomDecorated(n_large, distribution)'s radii (the same
    draw, so the same realisations for the same seed) with only one kind of disorder kept."""
    from ..model.chain import Chain
    from ..model.effective import effective_parameters

    def build(rng):
        r = distribution.sample(rng, n_large - 1)  # exactly RandomDecorated.draw
        mu, c = effective_parameters(np.ones(n_large), r, 2.5)
        if keep == "stiffness":
            mu = np.ones(n_large)  # Hertz: uniform masses; the stiffnesses r_k / 2^(n-1) stay random
        elif keep == "mass":
            c = np.full(n_large - 1, 1.0)  # uniform stiffness (its value only rescales time)
        return Chain(mu, c, 2.5, 1.0, np.arange(n_large), kind=f"effective, {keep} disorder only")

    return build


def disorder_split(n_large: int = 26, distribution=None, realizations: int = 1000, seed: int = 0, progress: bool = False) -> dict:
    """<max_t v_k> of the effective chain with only its mass disorder, or only its stiffness disorder
    (Hertz, n = 5/2), on the radii RandomDecorated(n_large, distribution) draws for ``seed``: which
    disorder makes single-realisation peaks decay? Returns {"mass": PerGranule, "stiffness": PerGranule}."""
    from ..ensembles.run import run_ensemble
    from ..families import CustomFamily
    from ..model.distributions import small_radius_distribution

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", EffectiveValidityWarning)
        dist = small_radius_distribution(distribution)
    out = {}
    for keep in ("mass", "stiffness"):
        fam = CustomFamily(_split_builder(n_large, dist, keep), name=keep)
        ds = run_ensemble(fam, realizations=realizations, seed=seed, progress=progress)
        out[keep] = analysis.mean_peak_amplitude(ds, keep)
    return out
