"""Tests of the binary collision approximation (granchain.bca, paper Sec. III B)."""

from __future__ import annotations

import json
import math
import time
import warnings

import numpy as np
import pytest
import scipy.stats as st
from hypothesis import given, settings
from hypothesis import strategies as hs
from scipy import integrate

import granchain as gc
from granchain import bca
from granchain.cli import main

HERTZ = 2.5


# -- known values ---------------------------------------------------------------
def test_paper_values():
    assert round(bca.A(2.5), 5) == 2.43884  # Eq. (an)
    assert round(bca.slope_uniform(0.01, 0.4), 4) == 2.3482  # Eq. (slope); paper 2.348


@pytest.mark.parametrize("n", [2.2, 2.5, 3.0, 4.0])
def test_A_is_the_general_formula_with_effective_stiffness(n):
    # A(n) [M/r]^(1/n) v^(2/n-1) is the two-body time for stiffness c = r / 2^(n-1).
    M, r, v = 0.37, 0.8, 1.3
    general = bca.time_to_max_compression(M, r / 2 ** (n - 1), v, n)
    assert general == pytest.approx(bca.A(n) * (M / r) ** (1 / n) * v ** (2 / n - 1), rel=1e-13)
    assert bca.time_to_max_compression(M, r, v, n) == pytest.approx(bca.A_plain(n) * (M / r) ** (1 / n) * v ** (2 / n - 1), rel=1e-13)
    assert bca.A(n) / bca.A_plain(n) == pytest.approx(2 ** ((n - 1) / n), rel=1e-13)


# -- the two-body time against direct integration --------------------------------
def _integrated_time(m1, m2, c, v, n):
    """Time at which the relative velocity of two colliding masses vanishes."""

    def rhs(t, y):
        f = c * max(y[0] - y[1], 0.0) ** (n - 1)
        return [y[2], y[3], -f / m1, f / m2]

    def max_compression(t, y):
        return y[2] - y[3]

    max_compression.terminal, max_compression.direction = True, -1
    sol = integrate.solve_ivp(rhs, (0, 100), [0, 0, v, 0], method="DOP853", rtol=1e-12, atol=1e-14, events=max_compression)
    assert sol.status == 1
    return sol.t_events[0][0]


@pytest.mark.parametrize(
    "m1, m2, c, v, n",
    [(1.0, 1.0, 1.0, 1.0, 2.5), (1.0, 0.3, 2.0, 0.7, 2.5), (2.0, 5.0, 0.5, 1.3, 3.0), (1.0, 1e-3, 0.6, 2.0, 2.2), (0.5, 0.8, 1.0, 1.0, 1.5)],
)
def test_two_body_time_against_integration(m1, m2, c, v, n):
    M = m1 * m2 / (m1 + m2)
    assert bca.time_to_max_compression(M, c, v, n) == pytest.approx(_integrated_time(m1, m2, c, v, n), rel=1e-8)


def test_plain_chain_needs_A_plain_not_A():
    chain = gc.monodisperse(2)  # two unit spheres: c = 1, M = 1/2
    M, c = 0.5, float(chain.stiffness[0])
    t_num = _integrated_time(*chain.masses, c, 1.0, HERTZ)
    assert bca.A_plain() * (M / c) ** (1 / HERTZ) == pytest.approx(t_num, rel=1e-8)
    assert bca.travel_times(chain).travel_time[0] == pytest.approx(t_num, rel=1e-8)
    off = bca.A() * (M / c) ** (1 / HERTZ) / t_num - 1
    assert off == pytest.approx(2**0.6 - 1, rel=1e-6) and 0.51 < off < 0.53


def test_effective_pair_is_the_paper_form():
    # A two-granule effective chain: integration agrees with A(n) [M/r]^(1/n).
    R = 0.25
    eff = gc.effective(gc.decorated([R]))
    r = math.sqrt(2 * R / (1 + R))  # Eq. (zetak)
    mu1, mu2 = eff.masses
    M = mu1 * mu2 / (mu1 + mu2)
    t_num = _integrated_time(mu1, mu2, float(eff.stiffness[0]), 1.0, HERTZ)
    assert bca.A() * (M / r) ** (1 / HERTZ) == pytest.approx(t_num, rel=1e-8)


# -- chains ---------------------------------------------------------------------------
def test_effective_chain_equals_paper_form():
    small = np.array([0.05, 0.3, 0.12, 0.4, 0.01, 0.2])
    eff = gc.effective(gc.decorated(small))
    res = bca.travel_times(eff)
    mu = eff.masses
    M = mu[:-1] * mu[1:] / (mu[:-1] + mu[1:])
    v = np.concatenate([[1.0], np.cumprod(2 * M / mu[1:])])  # Eq. (vk)
    r = np.sqrt(2 * small / (1 + small))
    np.testing.assert_allclose(res.travel_time, bca.A() * (M / r) ** (1 / HERTZ) * v[:-1] ** (2 / HERTZ - 1), rtol=1e-12)
    np.testing.assert_allclose(res.velocity, v, rtol=1e-14)
    # a decorated chain is mapped first; the vectorised path agrees
    np.testing.assert_allclose(bca.travel_times(gc.decorated(small)).arrival_time, res.arrival_time, rtol=1e-14)
    np.testing.assert_allclose(bca.arrival_times(small), res.arrival_time, rtol=1e-12)


def test_monodisperse_closed_form():
    N = 9
    res = bca.travel_times(gc.monodisperse(N))
    T = bca.A_plain() * 0.5 ** (1 / HERTZ)  # c = 1, M = 1/2, v = 1
    np.testing.assert_allclose(res.velocity, 1.0, rtol=0, atol=1e-15)
    np.testing.assert_allclose(res.travel_time, T, rtol=1e-14)
    np.testing.assert_allclose(res.arrival_time, T * np.arange(N), rtol=1e-14)


@pytest.mark.parametrize("momentum_conserving", [False, True])
def test_regular_decorated_closed_form(momentum_conserving):
    N, R, n = 7, 0.3, HERTZ
    s = R**3
    me, mi = 1 + s / 2, 1 + s  # end and interior effective masses, Eq. (renorm-mass)
    v1 = 1 / me if momentum_conserving else 1.0
    Me, Mi = me * mi / (me + mi), mi / 2
    ve = 2 * me / (me + mi)  # end -> interior mismatch; interior pairs pass v on unchanged
    v = v1 * np.array([1, ve, ve, ve, ve, ve, ve * 2 * mi / (me + mi)])
    c = math.sqrt(2 * R / (1 + R)) / 2 ** (n - 1)
    M = np.array([Me, Mi, Mi, Mi, Mi, Me])
    T = math.sqrt(math.pi) * math.gamma(1 + 1 / n) / math.gamma(0.5 + 1 / n) * (n * M / (2 * c)) ** (1 / n) * v[:-1] ** (2 / n - 1)
    res = bca.travel_times(gc.regular_decorated(N, (R,)), momentum_conserving=momentum_conserving)
    np.testing.assert_allclose(res.velocity, v, rtol=1e-14)
    np.testing.assert_allclose(res.travel_time, T, rtol=1e-13)
    np.testing.assert_allclose(res.arrival_time, np.concatenate([[0], np.cumsum(T)]), rtol=1e-13)
    assert res.chain.kind == "effective"


def test_further_approximations_closed_forms():
    small = np.array([[0.05, 0.3, 0.12], [0.4, 0.01, 0.2]])
    pre = bca.A() * 0.5 ** (1 / HERTZ)
    t1 = bca.arrival_times(small, approximation="equal-mass")
    t2 = bca.arrival_times(small, approximation="small-radius")
    np.testing.assert_allclose(np.diff(t1, axis=1), pre * ((1 + small) / (2 * small)) ** (1 / 5), rtol=1e-13)
    np.testing.assert_allclose(np.diff(t2, axis=1), pre * (2 * small) ** (-1 / 5), rtol=1e-13)
    assert t1.shape == t2.shape == (2, 4) and np.all(t1[:, 0] == 0)
    # neglecting R in the numerator shortens every hop; full <-> equal-mass within a few %
    assert np.all(t2[:, 1:] < t1[:, 1:])
    np.testing.assert_allclose(bca.arrival_times(small)[:, 1:], t1[:, 1:], rtol=0.05)


@settings(max_examples=50, deadline=None)
@given(hs.lists(hs.floats(0.01, 0.4), min_size=1, max_size=30), hs.floats(2.05, 5.0))
def test_arrival_times_increase(small, n):
    for approx in bca.APPROXIMATIONS:
        assert np.all(np.diff(bca.arrival_times(small, n, approximation=approx)) > 0)


@settings(max_examples=50, deadline=None)
@given(hs.floats(1e-3, 10), hs.floats(1e-3, 10), hs.floats(1e-2, 10), hs.floats(0.1, 10), hs.floats(1.1, 6.0))
def test_two_body_scaling(M, c, v, lam, n):
    t = bca.time_to_max_compression(M, c, v, n)
    assert bca.time_to_max_compression(M, c, lam * v, n) == pytest.approx(lam ** (2 / n - 1) * t, rel=1e-12)
    assert bca.time_to_max_compression(lam * M, lam * c, v, n) == pytest.approx(t, rel=1e-12)


@settings(max_examples=30, deadline=None)
@given(hs.lists(hs.floats(0.01, 0.4), min_size=1, max_size=12), hs.floats(0.2, 5.0))
def test_chain_travel_times_scale_with_impulse(small, v0):
    base = bca.travel_times(gc.decorated(small))
    fast = bca.travel_times(gc.decorated(small, initial_velocity=v0))
    np.testing.assert_allclose(fast.travel_time, v0 ** (2 / HERTZ - 1) * base.travel_time, rtol=1e-12)
    np.testing.assert_allclose(fast.velocity, v0 * base.velocity, rtol=1e-12)


# -- slope ---------------------------------------------------------------------------
@pytest.mark.parametrize("alpha, beta, n", [(0.01, 0.4, 2.5), (0.05, 0.2, 2.5), (0.1, 0.35, 3.0), (0.001, 0.3, 2.2)])
def test_slope_quadrature_equals_closed_form(alpha, beta, n):
    d = gc.Uniform(alpha, beta)
    assert bca.slope(d, n) == pytest.approx(bca.slope_uniform(alpha, beta, n), rel=1e-10)
    assert bca.slope(d, n, m=2.0) == pytest.approx(bca.slope_uniform(alpha, beta, n, m=2.0), rel=1e-10)
    g = bca.gaussian_limit(d, 11, n)
    assert g.mean == pytest.approx(10 * bca.slope_uniform(alpha, beta, n), rel=1e-12)


def test_slope_truncated_scipy_against_sample_average():
    d = gc.Truncated(st.beta(2, 8), upper=0.4)
    r = d.sample(np.random.default_rng(1), 200_000)
    pre = bca.A() * 0.5 ** (1 / HERTZ)
    for numerator, terms in [(False, (2 * r) ** (-1 / 5)), (True, ((1 + r) / (2 * r)) ** (1 / 5))]:
        mean, se = pre * terms.mean(), pre * terms.std() / math.sqrt(r.size)
        assert abs(bca.slope(d, numerator=numerator) - mean) < 4 * se
    assert bca.slope(d, numerator=True) > bca.slope(d)
    # a distribution with different mass gives a clearly different slope (control)
    assert abs(bca.slope(gc.Truncated(st.beta(2, 3), upper=0.4)) - pre * ((2 * r) ** (-1 / 5)).mean()) > 100 * se


# -- the distribution of X = R^(-1/2n) ----------------------------------------------------
def test_x_pdf_normalised_and_moments():
    x = bca.XDistribution(0.01, 0.4, HERTZ)
    lo, hi = x.support
    assert integrate.quad(x.pdf, lo, hi, epsrel=1e-12)[0] == pytest.approx(1.0, rel=1e-10)
    assert integrate.quad(lambda s: s * x.pdf(s), lo, hi, epsrel=1e-12)[0] == pytest.approx(x.kappa, rel=1e-10)
    var = integrate.quad(lambda s: (s - x.kappa) ** 2 * x.pdf(s), lo, hi, epsrel=1e-12)[0]
    assert var == pytest.approx(x.sigma**2, rel=1e-9)
    assert x.cdf(lo) == 0 and x.cdf(hi) == 1 and x.pdf(lo - 1e-9) == 0
    assert integrate.quad(x.pdf, lo, 1.4)[0] == pytest.approx(x.cdf(1.4), rel=1e-10)


def test_x_pdf_matches_sample():
    rng = np.random.default_rng(2024)
    X = gc.Uniform(0.01, 0.4).sample(rng, 20_000) ** (-1 / (2 * HERTZ))
    assert st.kstest(X, bca.XDistribution(0.01, 0.4, HERTZ).cdf).pvalue > 0.01
    # histogram against the pdf, bin by bin within 5 standard errors
    x = bca.XDistribution(0.01, 0.4, HERTZ)
    counts, edges = np.histogram(X, bins=30, range=x.support)
    expect = X.size * np.diff(x.cdf(edges))
    assert np.all(np.abs(counts - expect) < 5 * np.sqrt(expect) + 1)
    # negative controls: wrong beta, wrong exponent
    assert st.kstest(X, bca.XDistribution(0.01, 0.3, HERTZ).cdf).pvalue < 1e-6
    assert st.kstest(X, bca.XDistribution(0.01, 0.4, 3.0).cdf).pvalue < 1e-6


def test_gaussian_limit_uniform_closed_form_equals_quadrature():
    u = bca.gaussian_limit(gc.Uniform(0.01, 0.4), 25)
    assert (u.granule, u.terms) == (25, 24)
    assert u.prefactor == pytest.approx(bca.A() * 0.5**0.4 * 2**-0.2, rel=1e-14)
    q = bca.gaussian_limit(gc.Truncated(st.uniform(0.01, 0.39), 0.0, 1.0), 25)
    for f in ("kappa", "sigma", "mean", "std"):
        assert getattr(q, f) == pytest.approx(getattr(u, f), rel=1e-8)


def test_monte_carlo_sum_has_gaussian_limit_moments():
    N, R = 101, 20_000
    mc = bca.monte_carlo_arrival_times(N, gc.Uniform(0.01, 0.4), R, seed=7, approximation="small-radius", stream="single")
    t = mc.at(N)
    g = bca.gaussian_limit(gc.Uniform(0.01, 0.4), N)
    assert g.terms == N - 1
    se_mean = t.std(ddof=1) / math.sqrt(R)
    assert abs(t.mean() - g.mean) < 4 * se_mean
    m4 = np.mean((t - t.mean()) ** 4)
    se_var = math.sqrt((m4 - t.var() ** 2) / R)
    assert abs(t.var(ddof=1) - g.variance) < 4 * se_var
    # and it is near-Gaussian: KS distance to the standardised normal is small
    z = (t - g.mean) / g.std
    assert st.kstest(z, "norm").statistic < 0.03
    # control: a short chain is visibly skewed
    short = (mc.at(3) - mc.at(3).mean()) / mc.at(3).std()
    assert st.skew(short) > 5 * st.skew(z) and st.skew(short) > 0.3


# -- Monte Carlo ensemble -----------------------------------------------------------------
def test_monte_carlo_rows_are_the_numerics_chains():
    d = gc.Uniform(0.01, 0.4)
    mc = bca.monte_carlo_arrival_times(8, d, [0, 5, 11], seed=3)
    for row, i in enumerate([0, 5, 11]):
        chain = gc.random_decorated(8, d, seed=3, realization=i)
        np.testing.assert_array_equal(mc.small_radii[row], chain.meta["small_radii"])
        np.testing.assert_allclose(mc.arrival_time[row], bca.travel_times(chain).arrival_time, rtol=1e-13)
    given_ = bca.monte_carlo_arrival_times(8, small_radii=mc.small_radii)
    np.testing.assert_array_equal(given_.arrival_time, mc.arrival_time)
    assert given_.stream == "given" and mc.stream == "per-realization"


def test_monte_carlo_speed_and_slope():
    t0 = time.perf_counter()
    mc = bca.monte_carlo_arrival_times(26, gc.Uniform(0.01, 0.4), 30_000, seed=0)
    elapsed = time.perf_counter() - t0
    assert mc.arrival_time.shape == (30_000, 26)
    assert elapsed < 3.0, f"30,000 chains took {elapsed:.2f} s"
    t0 = time.perf_counter()
    fast = bca.monte_carlo_arrival_times(26, gc.Uniform(0.01, 0.4), 30_000, seed=0, stream="single")
    assert time.perf_counter() - t0 < 0.5
    # the full Eq. (total-time) is slower than Eq. (slope) by the mass corrections: a few %
    for m in (mc, fast):
        ratio = m.at(25).mean() / (24 * bca.slope_uniform(0.01, 0.4))
        assert 1.0 < ratio < 1.06


# -- peak shift -----------------------------------------------------------------------------
def test_shift_peak_mode_and_mean():
    rng = np.random.default_rng(5)
    numerical = rng.gumbel(5.0, 1.0, 30_000)
    theory = rng.gumbel(6.0, 1.0, 30_000)  # mode 6 vs 5
    s = bca.shift_peak(theory, numerical, "mode")
    assert s.shift == pytest.approx(-1.0, abs=0.15)  # scatter ~0.04 (see shift_peak)
    np.testing.assert_allclose(s.sample, theory + s.shift)
    assert s.numerical_location == pytest.approx(5.0, abs=0.15) and s.theory_location == pytest.approx(6.0, abs=0.15)
    m = bca.shift_peak(theory, numerical, "mean")
    assert m.shift == pytest.approx(numerical.mean() - theory.mean(), rel=1e-12)
    exact = bca.shift_peak(numerical + 0.7, numerical)
    assert exact.shift == pytest.approx(-0.7, abs=1e-6)
    sample, shift, *_ = exact
    assert shift == exact.shift


# -- validation ---------------------------------------------------------------------------
@pytest.mark.parametrize(
    "call, words",
    [
        (lambda: bca.A(2.0), "n > 2"),
        (lambda: bca.A_plain(1.5), "n > 2"),
        (lambda: bca.travel_times(gc.monodisperse(4, n=1.8)), "n > 2"),
        (lambda: bca.slope_uniform(0.4, 0.4), "alpha"),
        (lambda: bca.slope_uniform(0.3, 0.1), "beta"),
        (lambda: bca.slope_uniform(0.01, 0.4, m=0), "m"),
        (lambda: bca.XDistribution(0.2, 0.1), "alpha < beta"),
        (lambda: bca.time_to_max_compression(-1.0, 1.0, 1.0), "reduced_mass"),
        (lambda: bca.time_to_max_compression(1.0, 0.0, 1.0), "stiffness"),
        (lambda: bca.time_to_max_compression(1.0, 1.0, [1.0, 0.0]), "speed"),
        (lambda: bca.arrival_times([0.1, -0.2]), "small_radii"),
        (lambda: bca.arrival_times([0.1], approximation="exact"), "approximation"),
        (lambda: bca.gaussian_limit(None, 0), "granule"),
        (lambda: bca.monte_carlo_arrival_times(5, small_radii=np.ones((3, 2)) * 0.1), "small_radii"),
        (lambda: bca.monte_carlo_arrival_times(5, realizations=3, stream="fast"), "stream"),
        (lambda: bca.shift_peak([1.0, 2.0], [1.0, 2.0], "median"), "method"),
        (lambda: bca.shift_peak([1.0, 2.0], [1.0, 2.0], smoothing=0), "smoothing"),
        (lambda: bca.travel_times("chain"), "Chain"),
    ],
)
def test_bad_input_raises(call, words):
    with pytest.raises(ValueError, match=words):
        call()


def test_large_radii_warn():
    with pytest.warns(gc.EffectiveValidityWarning):
        bca.slope_uniform(0.01, 0.5)
    with pytest.warns(gc.EffectiveValidityWarning):
        bca.arrival_times([0.1, 0.45])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        bca.arrival_times([0.1, 0.4])


# -- CLI ------------------------------------------------------------------------------------
def test_cli_json(capsys):
    assert main(["bca", "--json", "--alpha", "0.01", "--beta", "0.4", "--large", "26"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert round(out["A"], 5) == 2.43884 and round(out["slope"], 4) == 2.3482
    assert (out["granule"], out["terms"]) == (25, 24)
    x = bca.XDistribution(0.01, 0.4, 2.5)
    assert out["kappa"] == pytest.approx(x.kappa) and out["sigma"] == pytest.approx(x.sigma)
    assert out["mean"] == pytest.approx(24 * out["slope"], rel=1e-12)
    assert out["std"] == pytest.approx(math.sqrt(24) * out["prefactor"] * x.sigma, rel=1e-12)


def test_cli_text_exponent_and_errors(capsys):
    assert main(["bca", "--n", "3", "--large", "11", "--realizations", "200"]) == 0
    text = capsys.readouterr().out
    assert "A(n)" in text and f"{bca.A(3.0):.6f}" in text and "Monte Carlo" in text
    assert main(["bca", "--alpha", "0.5", "--beta", "0.4"]) == 2
    assert "alpha" in capsys.readouterr().err
    assert main(["bca", "--n", "2"]) == 2
    assert "n > 2" in capsys.readouterr().err
