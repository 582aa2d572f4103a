"""Tests of granchain.analysis: fits, KS distance (Eq. AD), histograms, Dataset observables."""

import numpy as np
import pytest
import xarray as xr
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from granchain import analysis as A

K = np.arange(1, 27, dtype=float)  # N = 26 large granules, as in paper Fig. 2


def noisy_decay(seed, params=A.PAPER_FIG2, rel=0.01):
    v = A.stretched_exp(K, *params)
    sigma = rel * v * (1 + 0.5 * np.sin(K))  # uneven per-point errors
    return v + sigma * np.random.default_rng(seed).normal(size=K.size), sigma


# ------------------------------------------------------------------ stretched exponential


def test_stretched_exp_recovers_parameters_and_records_range():
    v, sigma = noisy_decay(0)
    fit = A.fit_stretched_exp(K, v, sigma, fit_range=(4, 25), variable="k")
    for p, true, err in zip(fit.params, A.PAPER_FIG2, fit.errors):
        assert abs(p - true) < 3 * err
    assert fit.fit_range == (4.0, 25.0)
    np.testing.assert_array_equal(fit.used, np.arange(3, 25))  # k = 4..25 inclusive
    assert fit.x[0] == 4 and fit.x[-1] == 25 and fit.dof == 19
    assert 0.3 < fit.reduced_chi2 < 2.0
    np.testing.assert_allclose(fit(K[fit.used]), fit.y - fit.residuals, rtol=1e-12)
    r = fit.correlation
    np.testing.assert_allclose(np.diag(r), 1.0)
    assert abs(r[1, 2]) > 0.9  # b and c strongly correlated: compare curves, not parameters
    assert "fit range [4, 25]" in fit.summary() and "k^c" in fit.summary()


def test_stretched_exp_pulls_have_unit_spread():
    pulls, curve_pulls = [], []
    for seed in range(50):
        v, sigma = noisy_decay(seed)
        fit = A.fit_stretched_exp(K, v, sigma, fit_range=(4, 25))
        pulls.append((np.array(fit.params) - A.PAPER_FIG2) / fit.errors)
        curve_pulls.append((fit(15.0) - A.stretched_exp(15.0, *A.PAPER_FIG2)) / fit.stderr(15.0))
    pulls = np.array(pulls)
    assert np.all(0.7 < pulls.std(axis=0)) and np.all(pulls.std(axis=0) < 1.35)
    assert np.all(np.abs(pulls.mean(axis=0)) < 0.5)
    assert 0.7 < np.std(curve_pulls) < 1.35


def test_stretched_exp_without_sigma_scales_errors_by_residuals():
    pulls = []
    for seed in range(50):
        v = A.stretched_exp(K, *A.PAPER_FIG2) + 0.004 * np.random.default_rng(seed).normal(size=K.size)
        fit = A.fit_stretched_exp(K, v, fit_range=(4, 25))
        assert fit.sigma is None and np.isnan(fit.reduced_chi2) and not fit.absolute_sigma
        pulls.append((fit.c - A.PAPER_FIG2[2]) / fit.c_err)
    assert 0.7 < np.std(pulls) < 1.4


def test_fit_range_is_honoured():
    v, sigma = noisy_decay(3)
    ref = A.fit_stretched_exp(K[3:25], v[3:25], sigma[3:25])
    junk = v.copy()
    junk[:3], junk[25:] = 50.0, -1.0  # outside the range: huge, and even non-positive
    fit = A.fit_stretched_exp(K, junk, sigma, fit_range=(4, 25))
    np.testing.assert_allclose(fit.params, ref.params, rtol=1e-10)
    np.testing.assert_allclose(fit.covariance, ref.covariance, rtol=1e-8)
    assert ref.fit_range == (4.0, 25.0)  # default range: the data's, recorded


def test_stretched_exp_rejects_bad_input():
    v, sigma = noisy_decay(1)
    with pytest.raises(ValueError, match="only 3 points"):
        A.fit_stretched_exp(K, v, fit_range=(4, 6))
    bad = v.copy()
    bad[10] = -0.1
    with pytest.raises(ValueError, match="v must be > 0"):
        A.fit_stretched_exp(K, bad, fit_range=(4, 25))
    with pytest.raises(ValueError, match="sigma must be > 0"):
        A.fit_stretched_exp(K, v, 0 * sigma)
    with pytest.raises(ValueError, match="same length"):
        A.fit_stretched_exp(K, v[:-1])
    with pytest.raises(ValueError, match="x must be > 0"):
        A.fit_stretched_exp(K - 5, v)
    with pytest.raises(ValueError, match="fit_range"):
        A.fit_stretched_exp(K, v, fit_range=(25, 4))


@settings(max_examples=40, deadline=None)
@given(
    a=st.floats(0.1, 10.0),
    b=st.floats(0.01, 0.5),
    c=st.floats(0.3, 1.5),
    start=st.integers(1, 5),
)
def test_noiseless_stretched_exp_is_recovered(a, b, c, start):
    b = min(b, 15.0 / 25.0**c)  # keep v(25) >= a e^-15 (no underflow)
    x = np.arange(start, 26, dtype=float)
    fit = A.fit_stretched_exp(x, A.stretched_exp(x, a, b, c))
    np.testing.assert_allclose(fit.params, (a, b, c), rtol=1e-6)


# ------------------------------------------------------------------ linear fit


def test_linear_fit_pulls_range_and_linregress():
    m, q = A.PAPER_FIG3
    pulls = []
    for seed in range(50):
        sig = 0.05 + 0.01 * K
        t = m * K + q + sig * np.random.default_rng(seed).normal(size=K.size)
        fit = A.fit_linear(K, t, sig, fit_range=(4, 25))
        pulls.append((np.array(fit.params) - (m, q)) / fit.errors)
    pulls = np.array(pulls)
    assert np.all(np.abs(pulls) < 4.5)
    assert np.all((0.7 < pulls.std(axis=0)) & (pulls.std(axis=0) < 1.35))
    # unweighted: same as scipy.stats.linregress; outside-range junk is ignored
    t = m * K + q + 0.1 * np.random.default_rng(9).normal(size=K.size)
    ref = stats.linregress(K[3:25], t[3:25])
    t[:3] = 1e6
    fit = A.fit_linear(K, t, fit_range=(4, 25))
    np.testing.assert_allclose([fit.slope, fit.intercept], [ref.slope, ref.intercept], rtol=1e-10)
    np.testing.assert_allclose([fit.slope_err, fit.intercept_err], [ref.stderr, ref.intercept_stderr], rtol=1e-8)
    np.testing.assert_allclose(fit.stderr(0.0), fit.intercept_err, rtol=1e-12)
    assert fit(2.0) == pytest.approx(2 * fit.slope + fit.intercept)
    assert "fit range [4, 25] (22 points)" in fit.summary()
    with pytest.raises(ValueError, match="only 2 points"):
        A.fit_linear(K, t, fit_range=(4, 5))
    with pytest.raises(ValueError, match="finite"):
        A.fit_linear(K, np.where(K == 10, np.nan, t))


@settings(max_examples=30, deadline=None)
@given(m=st.floats(-10, 10), q=st.floats(-10, 10))
def test_noiseless_line_is_recovered(m, q):
    fit = A.fit_linear(K, m * K + q)
    np.testing.assert_allclose(fit.params, (m, q), atol=1e-9)


# ------------------------------------------------------------------ KS distance, Eq. (AD)


def ecdf_distance(x):
    z = np.sort((x - x.mean()) / x.std(ddof=1))
    n, phi = z.size, stats.norm.cdf(z)
    return max(np.max(np.arange(1, n + 1) / n - phi), np.max(phi - np.arange(n) / n))


def test_ks_gaussian_and_negative_controls():
    n = 3000
    x = np.random.default_rng(1).normal(3.0, 2.0, size=n)
    r = A.ks_normal(x, n_mc_samples=200, rng=1)
    assert r.d == pytest.approx(ecdf_distance(x), rel=1e-12)
    z = (x - x.mean()) / x.std(ddof=1)
    assert r.d == pytest.approx(stats.kstest(z, "norm").statistic, rel=1e-12)
    assert r.d < 1.6 / np.sqrt(n) and r.pvalue > 0.02
    assert r.n == n and r.n_mc_samples == 200 and abs(r.mean - 3) < 0.1 and abs(r.std - 2) < 0.1
    assert abs(r.skewness) < 0.15 and abs(r.excess_kurtosis) < 0.3
    rng = np.random.default_rng(2)
    for skewed in (rng.exponential(size=n), rng.lognormal(0.0, 0.5, size=n)):
        bad = A.ks_normal(skewed, n_mc_samples=200, rng=1)
        assert bad.d > 4 / np.sqrt(n)
        assert bad.pvalue == pytest.approx(1 / 201)  # smallest possible: never exceeded by the null
        assert bad.skewness > 1.0


def test_ks_statistic_is_goodness_of_fit_statistic():
    x = np.random.default_rng(4).gamma(20.0, size=500)
    res = stats.goodness_of_fit(stats.norm, x, statistic="ks", n_mc_samples=20, rng=0)
    assert A.ks_distance(x) == pytest.approx(res.statistic, rel=1e-12)  # scipy's fit uses ddof = 1 too


def _goodness_of_fit_pvalue(x, n_mc_samples, rng, batch=100):
    """The Lilliefors p-value as ks_normal computed it before its screen: scipy.stats.goodness_of_fit's null
    distribution in batches, (1 + #{null >= d}) / (B + 1)."""
    d, gen, null = A.ks_distance(x), np.random.default_rng(rng), []
    for k in np.diff(np.r_[0:n_mc_samples:batch, n_mc_samples]):
        null.append(stats.goodness_of_fit(stats.norm, x, statistic=A._ks_statistic, n_mc_samples=int(k), rng=gen).null_distribution)
    return (1.0 + np.count_nonzero(np.concatenate(null) >= d * (1 - 1e-12))) / (n_mc_samples + 1.0)


def test_lilliefors_screen_gives_goodness_of_fit_pvalues():
    """ks_normal sorts only the resamples its O(n) bound cannot rule out: its resamples are
    goodness_of_fit's (bitwise), the bound never falls below the statistic, and the p-values are
    goodness_of_fit's, near the 5 % point (where every resample counts) and at the floor."""
    x = np.random.default_rng(3).gamma(20.0, size=400)
    loc, scale = np.mean(x), np.std(x, ddof=1)
    null = stats.goodness_of_fit(stats.norm, x, statistic=A._ks_statistic, n_mc_samples=50, rng=np.random.default_rng(5))
    data = np.random.default_rng(5).standard_normal((50, x.size)) * scale + loc
    assert np.array_equal(A._ks_statistic(None, data), null.null_distribution)
    assert np.all(A._ks_upper_bound(data) >= A._ks_statistic(None, data))
    assert np.array_equal(A._ks_statistic(None, data[[4, 17]]), null.null_distribution[[4, 17]])  # rows alone: the same bits
    samples = [np.random.default_rng(s).standard_t(15, size=500) for s in range(5)] + [np.random.default_rng(9).exponential(size=60)]
    for x in samples:
        assert A.ks_normal(x, n_mc_samples=250, rng=3).pvalue == _goodness_of_fit_pvalue(x, 250, 3)


def test_lilliefors_pvalues_are_calibrated_where_plain_ks_is_not():
    lil, plain = [], []
    for seed in range(40):
        x = np.random.default_rng(seed).normal(size=100)
        lil.append(A.ks_normal(x, n_mc_samples=200, rng=seed).pvalue)
        plain.append(stats.kstest((x - x.mean()) / x.std(ddof=1), "norm").pvalue)
    assert abs(np.mean(lil) - 0.5) < 0.13  # uniform under H0
    assert np.mean(plain) > 0.7  # estimated mean/std make the plain KS p-value far too large


def test_lilliefors_pvalues_do_not_depend_on_threads():
    """Fig. 4 runs the Monte Carlo of its panels in threads (figures/fig4.py): every panel must get
    the p-value it gets alone. Samples near the 5-10 % point, where p depends on every resample."""
    from concurrent.futures import ThreadPoolExecutor

    samples = [np.random.default_rng(s).standard_t(15, size=500) for s in range(4)]
    alone = [A.ks_normal(x, n_mc_samples=300) for x in samples]
    with ThreadPoolExecutor(max_workers=4) as pool:
        threaded = list(pool.map(lambda x: A.ks_normal(x, n_mc_samples=300), samples))
    assert threaded == alone
    assert len({r.pvalue for r in alone}) > 1 and all(1 / 301 < r.pvalue < 1 for r in alone)  # not all at a bound


def test_d_falls_like_inverse_sqrt_n_for_gaussian_samples():
    d = {n: np.mean([A.ks_distance(np.random.default_rng(s).normal(size=n)) for s in range(20)])
         for n in (400, 6400)}
    assert 2.8 < d[400] / d[6400] < 5.5  # sqrt(6400 / 400) = 4


@settings(max_examples=40, deadline=None)
@given(
    alpha=st.floats(1e-3, 1e3) | st.floats(-1e3, -1e-3),
    beta=st.floats(-1e3, 1e3),
    seed=st.integers(0, 2**16),
)
def test_d_is_invariant_under_affine_maps(alpha, beta, seed):
    x = np.random.default_rng(seed).exponential(size=200)
    assert A.ks_distance(alpha * x + beta) == pytest.approx(A.ks_distance(x), abs=1e-9)


def test_ks_and_skewness_reject_bad_samples():
    with pytest.raises(ValueError, match="at least 5"):
        A.ks_normal([1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="finite"):
        A.ks_normal([1.0, 2.0, np.nan, 4.0, 5.0, 6.0])
    with pytest.raises(ValueError, match="constant"):
        A.ks_distance(np.ones(10))
    with pytest.raises(ValueError, match="n_mc_samples"):
        A.ks_normal(np.arange(10.0), n_mc_samples=-1)
    x = np.random.default_rng(0).exponential(size=50)
    assert A.skewness(x, bias=True) == pytest.approx(stats.skew(x))
    assert A.skewness(x) == pytest.approx(stats.skew(x, bias=False))
    assert np.isnan(A.ks_normal(x, n_mc_samples=0).pvalue)


# ------------------------------------------------------------------ histogram


def test_histogram_density_and_poisson_errors():
    x = np.random.default_rng(5).gamma(4.0, size=4000)
    h = A.histogram(x, bins=30)
    widths = np.diff(h.edges)
    assert np.sum(h.values * widths) == pytest.approx(1.0)
    np.testing.assert_allclose(h.errors, np.sqrt(h.counts) / (h.n * widths))
    np.testing.assert_allclose(h.centres, 0.5 * (h.edges[1:] + h.edges[:-1]))
    c = A.histogram(x, bins=30, density=False)
    np.testing.assert_array_equal(c.values, c.counts)
    np.testing.assert_allclose(c.errors, np.sqrt(c.counts))
    z = A.histogram(x, bins=np.linspace(-4, 4, 41), standardize=True)
    assert z.standardized and z.mean == pytest.approx(x.mean())
    assert np.average(z.centres, weights=z.counts) == pytest.approx(0.0, abs=0.02)


# ------------------------------------------------------------------ ensemble Dataset

N, R, DT = 6, 300, 0.25
TIME = np.arange(0.0, 20.0 + DT / 2, DT)
PEAK_T = 2.4 * np.arange(1, N + 1) - 1.2 + 0.0937  # off the grid for k >= 2
PEAK_V = 0.8 * np.exp(-0.1 * np.arange(N))
FAILED = [7, 123]


def make_dataset():
    rng = np.random.default_rng(11)
    pv = PEAK_V[None, None, :] + [[[0.0]], [[0.3]]] + 0.05 * rng.normal(size=(2, R, N))
    pt = PEAK_T[None, None, :] + [[[0.0]], [[1.0]]] + 0.3 * rng.normal(size=(2, R, N))
    pt[0, 5, 2] = pt[0, 5, 3] + 4.0  # two planted out-of-order peaks at k = 3
    pt[0, 9, 2] = pt[0, 9, 3] + 1.0
    status = np.zeros((2, R), dtype=int)
    status[:, FAILED] = 2
    pv[:, FAILED], pt[:, FAILED] = 1e3, -1e3  # would ruin every mean if not excluded
    pv[0, 20, 4] = np.nan  # one missing value in a valid realisation
    tk = np.where(np.arange(N) == 0, 0.0, PEAK_T)  # k = 1: struck, maximum at t = 0
    mv = PEAK_V[:, None] * np.exp(-((TIME[None, :] - tk[:, None]) ** 2) / 2.0)
    return xr.Dataset(
        {
            "small_radius": (("realization", "gap"), rng.uniform(0.01, 0.4, (R, N - 1))),
            "peak_velocity": (("chain", "realization", "granule"), pv),
            "peak_time": (("chain", "realization", "granule"), pt),
            "status": (("chain", "realization"), status),
            "energy_error": (("chain", "realization"), np.zeros((2, R))),
            "n_steps": (("chain", "realization"), np.ones((2, R), dtype=int)),
            "mean_velocity": (("chain", "granule", "time"), np.stack([mv, 1.1 * mv])),
            "mean_velocity_stderr": (("chain", "granule", "time"), np.broadcast_to(0.01 + 0.001 * TIME, (2, N, TIME.size))),
        },
        coords={"chain": ["decorated", "effective"], "realization": np.arange(R), "granule": np.arange(1, N + 1),
                "gap": np.arange(1, N), "time": TIME},
        attrs={"n_large": N, "realizations": R, "seed": 11},
    )


@pytest.fixture(scope="module")
def ds():
    return make_dataset()


def test_mean_peak_amplitude_and_arrival_time_exclude_failures(ds):
    ok = np.setdiff1d(np.arange(R), FAILED)
    for i, chain in enumerate(["decorated", "effective"]):
        pv = ds.peak_velocity.values[i, ok]
        amp = A.mean_peak_amplitude(ds, chain)
        np.testing.assert_allclose(amp.value, np.nanmean(pv, axis=0), rtol=1e-12)
        np.testing.assert_allclose(amp.stderr, np.nanstd(pv, axis=0, ddof=1) / np.sqrt(amp.n), rtol=1e-12)
        expected_n = np.full(N, ok.size) - (np.arange(N) == 4) * (chain == "decorated")
        np.testing.assert_array_equal(amp.n, expected_n)
        assert amp.chain == chain and amp.quantity == "mean_peak_velocity"
        arr = A.mean_arrival_time(ds, chain)
        np.testing.assert_allclose(arr.value, ds.peak_time.values[i, ok].mean(axis=0), rtol=1e-12)
        assert np.all(np.abs(arr.value - PEAK_T - i) < 4 * arr.stderr + 0.05)
    t = A.arrival_times(ds)  # default k = N - 1 (paper Fig. 4)
    np.testing.assert_array_equal(t, ds.peak_time.values[0, ok, N - 2])
    assert A.arrival_times(ds, "effective", granule=1).size == ok.size


def test_averaged_pulse_peak_refines_between_grid_points(ds):
    peak = A.averaged_pulse_peak(ds)
    assert not peak.refined[0] and peak.time[0] == 0.0 and peak.velocity[0] == pytest.approx(PEAK_V[0])
    assert np.all(peak.refined[1:])
    err_t = np.abs(peak.time[1:] - PEAK_T[1:])
    grid_err = np.abs(TIME[np.argmin(np.abs(TIME[None, :] - PEAK_T[1:, None]), axis=1)] - PEAK_T[1:])
    assert np.all(err_t < 0.1 * DT) and np.all(err_t < 0.2 * grid_err)
    np.testing.assert_allclose(peak.velocity[1:], PEAK_V[1:], rtol=2e-3)
    np.testing.assert_allclose(peak.velocity_stderr[1:], 0.01 + 0.001 * peak.time[1:], rtol=1e-9)
    eff = A.averaged_pulse_peak(ds, "effective")
    np.testing.assert_allclose(eff.velocity, 1.1 * peak.velocity, rtol=1e-12)
    # Fig. 2/3 pipeline: the decay and the arrival line come out of the averaged pulse
    line = A.fit_linear(peak.granule, peak.time, fit_range=(2, N))
    assert line.slope == pytest.approx(2.4, abs=0.02)
    decay = A.fit_stretched_exp(peak.granule, peak.velocity, peak.velocity_stderr, fit_range=(2, N))
    assert A.compare_curves(decay, lambda k: 0.8 * np.exp(-0.1 * (k - 1)), peak.granule[1:]).max_relative < 0.01


def test_out_of_order_peaks_counts_planted_inversions(ds):
    c = A.out_of_order_peaks(ds)
    assert c.value[2] >= 2 and c.value[-1] == 0
    clean = ds.copy(deep=True)
    clean["peak_time"][:] = np.where(ds.status.values[:, :, None] == 0, PEAK_T[None, None, :], -1e3)
    np.testing.assert_array_equal(A.out_of_order_peaks(clean, "effective").value, 0)


def test_dataset_functions_reject_bad_requests(ds):
    with pytest.raises(ValueError, match="choose one of"):
        A.mean_peak_amplitude(ds, "monodisperse")
    with pytest.raises(ValueError, match="lacks"):
        A.averaged_pulse_peak(ds.drop_vars("mean_velocity_stderr"))
    with pytest.raises(ValueError, match="granule = 99"):
        A.arrival_times(ds, granule=99)


# ------------------------------------------------------------------ curve comparison


def test_compare_curves():
    k = np.arange(4, 26.0)
    paper = lambda x: A.stretched_exp(x, *A.PAPER_FIG2)  # noqa: E731
    same = A.compare_curves(paper, paper, k)
    assert same.max_relative == 0 and same.max_absolute == 0 and np.isnan(same.max_pull)
    scaled = A.compare_curves(lambda x: 1.02 * paper(x), paper, k)
    assert scaled.max_relative == pytest.approx(0.02)
    # different (a, b, c), nearly the same curve: the correlated parameters trade off
    v, sigma = noisy_decay(0, rel=0.002)
    fit = A.fit_stretched_exp(K, v, sigma, fit_range=(4, 25))
    cmp = A.compare_curves(fit, paper, k)
    assert cmp.max_relative < 0.01 and np.isfinite(cmp.max_pull) and cmp.max_pull < 4
    with pytest.raises(ValueError):
        A.compare_curves(paper, paper, [])
