"""The averaged-pulse decay as dephasing (issue 13, part 3): predictions of max_t <v_k(t)> from the
ensemble's own arrival times and peaks with its aligned pulse, and in closed form."""

from __future__ import annotations

import numpy as np
import pytest

import granchain as gc
from granchain.paper import dephasing

LAGS = np.arange(-12.0, 12.001, 0.1)


@pytest.fixture(scope="module")
def n11():
    """N = 11, 300 decorated realisations with the aligned pulse (~15 s on 2 shared cores)."""
    return gc.run_ensemble(gc.RandomDecorated(11), realizations=300, seed=5, chains="decorated", lags=LAGS, progress=False)


def test_dephasing_from_the_ensembles_own_data_n11(n11):
    """Level 1 at N = 11 (300 realisations): within 1.5 % for k = 4..10 (measured: max 0.9 %, the
    prediction a little low, most at small k where the peak-time jitter of a flat-topped pulse
    matters most against the small spread s_k)."""
    p = dephasing.predict_from_ensemble(n11)
    mx, rms = p.error_in((4, 10))
    assert mx < 0.015 and rms < 0.01, p.relative_error
    # the mechanism, not a tautology: without dephasing (perfect alignment) the prediction is <P_k>,
    # which overshoots the averaged pulse by far more than that
    P, _ = dephasing._valid(n11, "decorated")
    sel = slice(3, 10)
    assert np.all(P.mean(0)[sel] / p.measured[sel] - 1.0 > 0.04)


def test_weighting_by_the_peak_matters(n11):
    """Arrival time and peak are anti-correlated (fast pulses are strong): dropping the weights
    (P_k -> <P_k>) makes the prediction worse."""
    P, T = dephasing._valid(n11, "decorated")
    r = [np.corrcoef(P[:, q], T[:, q])[0, 1] for q in range(3, 10)]
    assert np.all(np.array(r) < -0.2), r
    w = dephasing.predict_from_ensemble(n11).error_in((4, 10))[1]
    u = dephasing.predict_from_ensemble(n11, weighted=False).error_in((4, 10))[1]
    assert w < u


def test_closed_forms_n11(n11):
    """Level 2 at N = 11 within the accuracies measured there (k = 4..10): measured s_k and the
    aligned shape 2.5 %; BCA spreads 3.5 %; a cos^4 pulse of fitted width 4 %."""
    for spread, tol in (("measured", 0.025), ("gaussian", 0.035), ("equal-mass", 0.035), ("full", 0.035)):
        mx, _ = dephasing.predict_closed_form(n11, spread=spread).error_in((4, 10))
        assert mx < tol, (spread, mx)
    mx, _ = dephasing.predict_closed_form(n11, shape="cos4").error_in((4, 10))
    assert mx < 0.04, mx


def test_arrival_spreads(n11):
    """s_k from the BCA vs measured: the same order, growing like sqrt(k-1) (Gaussian limit exactly)."""
    s_meas = dephasing.arrival_spread(n11, "measured")
    s_g = dephasing.arrival_spread(n11, "gaussian")
    assert s_g[0] == 0.0 and np.allclose(s_g[1:] / np.sqrt(np.arange(1, 11)), s_g[1])
    ratio = s_g[3:10] / s_meas[3:10]
    assert np.all((ratio > 0.8) & (ratio < 1.3)), ratio
    with pytest.raises(ValueError, match="source"):
        dephasing.arrival_spread(n11, "nope")


def test_cos4_and_smearing():
    lags = np.arange(-10, 10.001, 0.05)
    shape = dephasing.cos4_shape(lags, 8.0)
    assert dephasing.fit_cos4_width(lags, shape) == pytest.approx(8.0, rel=1e-4)
    assert dephasing._smeared_peak(lags, shape, 0.0) == 1.0
    # small spread: 1 - s^2 |S''(0)| / 2 with S''(0) = -4 pi^2 / W^2 for cos^4(pi t / W)
    s = 0.1
    assert dephasing._smeared_peak(lags, shape, s) == pytest.approx(1 - 0.5 * s**2 * 4 * np.pi**2 / 64, abs=2e-5)


def test_needs_the_aligned_pulse():
    ds = gc.run_ensemble(gc.RandomDecorated(4), realizations=3, progress=False)
    with pytest.raises(ValueError, match="lags"):
        dephasing.predict_from_ensemble(ds)


def test_single_realisation_peaks_decay_by_stiffness_disorder_not_mass_disorder():
    """The remaining piece, <max_t v_k>: the effective chain with only its random masses (uniform
    stiffness) stops decaying after a few granules; with only its random stiffnesses (unit masses) it
    follows the decorated chain (N = 11, 300 realisations: within 1.5 %, measured 0.6 %)."""
    split = dephasing.disorder_split(11, None, 300, seed=5)
    ds = gc.run_ensemble(gc.RandomDecorated(11), realizations=300, seed=5, chains="decorated", progress=False)
    dec = gc.analysis.mean_peak_amplitude(ds, "decorated").value
    stiff, mass = split["stiffness"].value, split["mass"].value
    assert np.max(np.abs(stiff[3:10] / dec[3:10] - 1.0)) < 0.015
    # mass disorder alone: nearly a plateau (from k = 6 to 10 it decays < 1/3 as much as the decorated
    # chain), far above the decorated peaks at k = 10
    assert 1.0 - mass[9] / mass[5] < (1.0 - dec[9] / dec[5]) / 3
    assert mass[9] / dec[9] - 1.0 > 0.04
    # the BCA's Eq. (vk) on the effective masses transmits nearly everything: no decay to speak of
    v = dephasing.predict_mean_peak(ds)
    assert np.all(v[1:10] > 0.99)


@pytest.mark.slow
def test_dephasing_from_the_ensembles_own_data_n26():
    """The issue's check: N = 26, 3000 realisations, level 1 within 1 % for k = 4..25 (81 s to 3 min on 2
    shared cores). Measured (seed 2026): max 0.77 %, rms 0.39 %; closed forms: s_k measured max 1.44 %,
    Gaussian-limit s_k 3.57 %, BCA Eq. (total-time-1) s_k on the actual radii 3.74 % (rms 1.60 %)."""
    ds = gc.run_ensemble(gc.RandomDecorated(26), realizations=3000, seed=2026, chains="decorated", lags=LAGS, progress=False)
    p = dephasing.predict_from_ensemble(ds)
    mx, rms = p.error_in((4, 25))
    assert mx < 0.01, p.relative_error
    for spread, tol in (("measured", 0.02), ("gaussian", 0.04), ("equal-mass", 0.045)):
        mx, _ = dephasing.predict_closed_form(ds, spread=spread).error_in((4, 25))
        assert mx < tol, (spread, mx)
