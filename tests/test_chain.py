"""Chains, builders, effective chains, distributions, and input validation.

Paper: Harbola, Rosas, Romero & Lindenberg, "Pulse propagation in decorated
random chains", Sec. II (Eq. r-prime) and Sec. III A (Eqs. renorm-mass,
effec-int, zetak). No integration here except the effective-vs-decorated
arrival times at the end.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
import scipy.stats as st
from scipy import optimize

import granchain as gc
from granchain import _validate, bca

HERTZ = 2.5


# -- from_radii, monodisperse, tapered ------------------------------------------------
def test_from_radii_masses_and_stiffness():
    R = np.array([1.0, 0.5, 2.0, 0.3])
    c = gc.from_radii(R)
    np.testing.assert_allclose(c.masses, R**3, rtol=1e-15)  # m = R^3 (Sec. II)
    expected = [math.sqrt(2 * a * b / (a + b)) for a, b in zip(R[:-1], R[1:])]  # Eq. (r-prime)
    np.testing.assert_allclose(c.stiffness, expected, rtol=1e-15)
    assert c.n == HERTZ and c.initial_velocity == 1.0
    np.testing.assert_array_equal(c.observed, np.arange(4))
    np.testing.assert_array_equal(c.radii, R)
    assert c.energy == pytest.approx(0.5) and c.momentum == pytest.approx(1.0)


def test_chain_arrays_are_frozen():
    c = gc.from_radii([1.0, 1.0, 1.0])
    with pytest.raises(ValueError):
        c.masses[0] = 2.0
    with pytest.raises(ValueError):
        c.stiffness[0] = 2.0


def test_monodisperse():
    c = gc.monodisperse(7, n=3.0, initial_velocity=2.0)
    np.testing.assert_array_equal(c.masses, np.ones(7))
    np.testing.assert_allclose(c.stiffness, np.ones(6), rtol=1e-15)  # sqrt(2*1*1/2) = 1
    assert (c.size, c.n, c.initial_velocity, c.energy) == (7, 3.0, 2.0, 2.0)


@pytest.mark.parametrize("q", [0.1, -0.05])
def test_tapered_geometric(q):
    c = gc.tapered(6, q)
    R = (1 - q) ** np.arange(6)
    np.testing.assert_allclose(c.radii, R, rtol=1e-15)
    np.testing.assert_allclose(c.masses, R**3, rtol=1e-14)
    np.testing.assert_allclose(c.stiffness, gc.sphere_stiffness(R), rtol=1e-15)


def test_tapered_linear():
    c = gc.tapered(5, 0.1, profile="linear")
    np.testing.assert_allclose(c.radii, [1.0, 0.9, 0.8, 0.7, 0.6], rtol=1e-15)
    assert c.kind == "tapered-linear"


# -- decorated builders -----------------------------------------------------------------
def test_decorated_layout():
    s = [0.2, 0.35, 0.01]
    c = gc.decorated(s)
    assert c.size == 7
    np.testing.assert_allclose(c.radii, [1, 0.2, 1, 0.35, 1, 0.01, 1], rtol=1e-15)
    np.testing.assert_array_equal(c.observed, [0, 2, 4, 6])  # the large granules, 0-based
    np.testing.assert_allclose(c.masses[1::2], np.array(s) ** 3, rtol=1e-15)
    r = np.sqrt(2 * np.array(s) / (1 + np.array(s)))  # Eq. (r-prime) with R_large = 1
    np.testing.assert_allclose(c.stiffness[0::2], r, rtol=1e-15)
    np.testing.assert_allclose(c.stiffness[1::2], r, rtol=1e-15)
    np.testing.assert_allclose(c.meta["small_radii"], s)


def test_regular_decorated_pattern():
    c = gc.regular_decorated(6, (0.2, 0.4))
    np.testing.assert_allclose(c.radii[1::2], [0.2, 0.4, 0.2, 0.4, 0.2], rtol=1e-15)
    np.testing.assert_allclose(c.radii[0::2], np.ones(6))
    c1 = gc.regular_decorated(4, (0.3,))
    np.testing.assert_allclose(c1.radii[1::2], [0.3, 0.3, 0.3])


# -- random decorated chains: determinism ---------------------------------------------
def test_random_decorated_is_deterministic_per_realization():
    a = gc.random_decorated(12, seed=5, realization=3)
    b = gc.random_decorated(12, seed=5, realization=3)
    np.testing.assert_array_equal(a.radii, b.radii)
    other_real = gc.random_decorated(12, seed=5, realization=4)
    other_seed = gc.random_decorated(12, seed=6, realization=3)
    assert not np.any(a.radii[1::2] == other_real.radii[1::2])
    assert not np.any(a.radii[1::2] == other_seed.radii[1::2])
    small = a.radii[1::2]
    assert small.size == 11 and np.all((small >= 0.01) & (small <= 0.4))  # paper's U[0.01, 0.4]


def test_realization_stream_independent_of_batching():
    """Row i depends only on (seed, i): the same as SeedSequence(seed).spawn(i + 1)[i]."""
    dist = gc.Uniform(0.01, 0.4)
    batch = gc.draw_small_radii(dist, 9, 11, [0, 1, 2, 3])
    for i in range(4):
        np.testing.assert_array_equal(batch[i], gc.draw_small_radii(dist, 9, 11, [i])[0])
        spawned = np.random.default_rng(np.random.SeedSequence(11).spawn(i + 1)[i])
        np.testing.assert_array_equal(batch[i], dist.sample(spawned, 9))
    np.testing.assert_array_equal(gc.random_decorated(10, dist, seed=11, realization=2).radii[1::2], batch[2])


# -- distributions ------------------------------------------------------------------------
def test_truncated_beta_support_and_ks():
    d = gc.Truncated(st.beta(2, 5), upper=0.4)
    x = d.sample(np.random.default_rng(1), 4000)
    assert np.all(x > 0.0) and np.all(x <= 0.4)
    assert d.support == (0.0, 0.4)
    assert d.expect(lambda r: np.ones_like(r)) == pytest.approx(1.0, abs=1e-10)  # normalised pdf
    # Seeded KS test with a negative control (samples of another law must be rejected).
    assert st.kstest(x, d.cdf).pvalue > 1e-3
    wrong = gc.Uniform(0.01, 0.4).sample(np.random.default_rng(1), 4000)
    assert st.kstest(wrong, d.cdf).pvalue < 1e-6


def test_uniform_distribution_functions():
    d = gc.Uniform(0.01, 0.4)
    assert d.cdf(0.205) == pytest.approx(0.5, abs=1e-15)
    assert d.ppf(0.5) == pytest.approx(0.205, abs=1e-15)
    assert d.expect(lambda r: r) == pytest.approx(0.205, rel=1e-12)
    x = d.sample(np.random.default_rng(0), 1000)
    assert x.min() >= 0.01 and x.max() <= 0.4


# -- the effective chain (Sec. III A) ------------------------------------------------
@pytest.mark.parametrize("n", [2.5, 3.0])
def test_effective_masses_and_stiffness(n):
    s = np.array([0.2, 0.35, 0.01, 0.4])
    eff = gc.effective(gc.decorated(s, n=n))
    m = s**3
    mu = np.array([1 + m[0] / 2, 1 + (m[0] + m[1]) / 2, 1 + (m[1] + m[2]) / 2, 1 + (m[2] + m[3]) / 2, 1 + m[3] / 2])
    np.testing.assert_allclose(eff.masses, mu, rtol=1e-15)  # Eq. (renorm-mass)
    r = np.sqrt(2 * s / (1 + s))  # Eq. (zetak)
    np.testing.assert_allclose(eff.stiffness, r / 2 ** (n - 1), rtol=1e-13)  # Eq. (effec-int)
    assert eff.n == n and eff.initial_velocity == 1.0 and eff.radii is None
    np.testing.assert_array_equal(eff.observed, np.arange(5))
    np.testing.assert_allclose(eff.meta["small_radii"], s)


def test_effective_momentum_conserving_velocity():
    s = [0.3, 0.2]
    eff = gc.effective(gc.decorated(s), momentum_conserving=True)
    assert eff.initial_velocity == pytest.approx(1.0 / (1 + 0.3**3 / 2), rel=1e-15)
    assert eff.momentum == pytest.approx(1.0, rel=1e-15)  # mu_1 v_0 = m_1 * 1
    fast = gc.effective(gc.decorated(s, initial_velocity=2.0))
    assert fast.initial_velocity == 2.0


def test_effective_series_stiffness_general():
    """Unequal large neighbours: c_eff delta^(n-1) is the force of the two contacts in series."""
    n = 2.5
    chain = gc.from_radii([1.0, 0.2, 0.8, 0.1, 1.3], n=n)
    eff = gc.effective(chain)
    c = chain.stiffness
    for j, delta in ((0, 0.013), (1, 0.002)):
        cl, cr = c[2 * j], c[2 * j + 1]
        # split delta = d_l + d_r with equal forces, then compare the force
        dl = optimize.brentq(lambda d: cl * d ** (n - 1) - cr * (delta - d) ** (n - 1), 0.0, delta, xtol=1e-16)
        assert eff.stiffness[j] * delta ** (n - 1) == pytest.approx(cl * dl ** (n - 1), rel=1e-10)


def test_effective_arrival_times_close_to_decorated():
    """Effective chain (velocity 1 on granule 1) vs the exact decorated dynamics, N = 11."""
    N, R = 11, 6
    dec, eff, eff_mc = [], [], []
    for r in range(R):
        chain = gc.random_decorated(N, seed=7, realization=r)
        dec.append(gc.simulate(chain).peak_time)
        eff.append(gc.simulate(gc.effective(chain)).peak_time)
        eff_mc.append(gc.simulate(gc.effective(chain, momentum_conserving=True)).peak_time)
    dec, eff, eff_mc = map(np.array, (dec, eff, eff_mc))
    assert np.max(np.abs(dec - eff)) < 0.3  # per realisation
    assert np.max(np.abs(dec.mean(0) - eff.mean(0))) < 0.1  # mean arrival times
    assert np.max(np.abs(dec.mean(0) - eff_mc.mean(0))) < 0.2
    # DESIGN.md Sec. 1: velocity 1 matches the decorated arrival times better than 1/mu_1
    assert abs(dec.mean(0)[-2] - eff.mean(0)[-2]) < abs(dec.mean(0)[-2] - eff_mc.mean(0)[-2])


# -- every bad input, one table --------------------------------------------------------
def _chain():
    return gc.from_radii([1.0, 1.0, 1.0])


BAD_INPUTS = [
    # radii
    ("zero radius", lambda: gc.from_radii([1.0, 0.0]), r"radii must be > 0"),
    ("negative radius", lambda: gc.from_radii([1.0, -0.5]), r"radii must be > 0"),
    ("NaN radius", lambda: gc.from_radii([1.0, math.nan]), r"radii must be finite"),
    ("inf radius", lambda: gc.from_radii([1.0, math.inf]), r"radii must be finite"),
    ("2-d radii", lambda: gc.from_radii([[1.0, 1.0], [1.0, 1.0]]), r"radii must be one-dimensional"),
    ("text radii", lambda: gc.from_radii("abc"), r"radii must be"),
    ("one granule", lambda: gc.from_radii([1.0]), r"at least 2 granules"),
    ("monodisperse size 1", lambda: gc.monodisperse(1), r"size must be >= 2"),
    ("fractional size", lambda: gc.monodisperse(2.5), r"size must be a whole number"),
    ("negative small radius", lambda: gc.decorated([0.2, -0.1]), r"small_radii must be > 0"),
    ("no small radius", lambda: gc.decorated([]), r"small_radii needs at least 1"),
    ("empty pattern", lambda: gc.regular_decorated(4, []), r"pattern needs at least 1"),
    ("random size 1", lambda: gc.random_decorated(1), r"size must be >= 2"),
    ("geometric q >= 1", lambda: gc.tapered(5, 1.0), r"q = 1.0 must be < 1"),
    ("linear taper too steep", lambda: gc.tapered(5, 0.3, profile="linear"), r"linear taper q"),
    ("unknown profile", lambda: gc.tapered(5, 0.1, profile="cubic"), r"profile must be"),
    # exponent
    ("n = 1", lambda: gc.from_radii([1, 1], n=1.0), r"n = 1\.0 is not allowed.*n > 1"),
    ("n < 1", lambda: gc.monodisperse(3, n=0.5), r"n = 0\.5 is not allowed"),
    ("n NaN", lambda: gc.monodisperse(3, n=math.nan), r"n must be finite"),
    ("theory n <= 2", lambda: _validate.exponent(2.0, minimum=2.0), r"n = 2\.0 is not allowed.*n > 2"),
    ("bca.A(2)", lambda: bca.A(2.0), r"n = 2\.0 is not allowed.*n > 2"),
    ("bca.slope_uniform n=2", lambda: bca.slope_uniform(0.01, 0.4, n=2.0), r"n = 2\.0 is not allowed.*n > 2"),
    # Chain itself
    ("stiffness length", lambda: gc.Chain([1.0, 1.0, 1.0], [1.0]), r"stiffness needs one entry per contact"),
    ("negative stiffness", lambda: gc.Chain([1.0, 1.0, 1.0], [1.0, -1.0]), r"stiffness must be > 0"),
    ("one mass", lambda: gc.Chain([1.0], []), r"masses needs at least 2"),
    ("radii length", lambda: gc.Chain([1.0, 1.0], [1.0], radii=[1.0, 1.0, 1.0]), r"radii has 3 entries"),
    ("negative initial velocity", lambda: gc.from_radii([1, 1], initial_velocity=-1.0), r"initial_velocity must be > 0"),
    ("zero initial velocity", lambda: gc.monodisperse(3, initial_velocity=0.0), r"initial_velocity must be > 0"),
    ("observed out of range", lambda: gc.from_radii([1, 1, 1], observed=[3]), r"observed indices must lie in 0\.\.2"),
    ("observed negative", lambda: gc.from_radii([1, 1, 1], observed=[-1]), r"observed indices must lie"),
    ("observed repeated", lambda: gc.from_radii([1, 1, 1], observed=[1, 1]), r"observed indices must be strictly increasing"),
    ("observed descending", lambda: gc.from_radii([1, 1, 1], observed=[2, 0]), r"observed indices must be strictly increasing"),
    ("observed empty", lambda: gc.from_radii([1, 1, 1], observed=[]), r"observed must be a non-empty"),
    ("observed floats", lambda: gc.from_radii([1, 1, 1], observed=[0.5]), r"observed must be"),
    # distributions
    ("alpha >= beta", lambda: gc.Uniform(0.3, 0.2), r"alpha = 0\.3 must be < beta"),
    ("alpha = beta", lambda: gc.Uniform(0.2, 0.2), r"alpha = 0\.2 must be < beta"),
    ("alpha = 0", lambda: gc.Uniform(0.0, 0.4), r"alpha = 0\.0 must be > 0"),
    ("alpha < 0", lambda: gc.Uniform(-0.1, 0.4), r"alpha = -0\.1 must be > 0"),
    ("small radii beyond 1", lambda: gc.RandomDecorated(6, gc.Uniform(0.1, 1.2)), r"reaches radius 1\.2 > 1"),
    ("small beyond large", lambda: gc.decorated([2.0]), r"larger than its neighbouring large granules"),
    ("alpha NaN", lambda: gc.Uniform(math.nan, 0.4), r"alpha must be finite"),
    ("truncation bounds", lambda: gc.Truncated(st.beta(2, 5), lower=0.5, upper=0.4), r"lower < upper"),
    ("not a distribution", lambda: gc.Truncated("beta"), r"dist must be a frozen scipy\.stats"),
    ("no mass on interval", lambda: gc.Truncated(st.uniform(2, 1)), r"puts no probability"),
    ("dist and alpha", lambda: gc.as_distribution(gc.Uniform(), alpha=0.1), r"either dist or alpha/beta"),
    # integrators
    ("negative rtol", lambda: gc.DP5(rtol=-1e-9), r"rtol must be > 0"),
    ("negative atol", lambda: gc.DP5(atol=-1e-12), r"atol must be > 0"),
    ("zero rtol DOP853", lambda: gc.DOP853(rtol=0.0), r"rtol must be > 0"),
    ("negative atol DOP853", lambda: gc.DOP853(atol=-1.0), r"atol must be > 0"),
    ("rtol below double precision", lambda: gc.DP5(rtol=1e-16), r"rtol = 1e-16"),
    ("negative first_step", lambda: gc.DP5(first_step=-1e-3), r"first_step must be > 0"),
    ("zero fixed_step", lambda: gc.DP5(fixed_step=0.0), r"fixed_step must be > 0"),
    ("negative Verlet dt", lambda: gc.Verlet(dt=-1e-3), r"dt must be > 0"),
    ("unknown integrator name", lambda: gc.simulate(_chain(), "rk4"), r"unknown integrator 'rk4'"),
    ("integrator not an integrator", lambda: gc.get_integrator(42), r"integrator must be a name"),
    # effective()
    ("effective of a plain even chain", lambda: gc.effective(gc.from_radii([1, 1])), r"effective\(\) needs a decorated chain"),
    ("effective of equal granules", lambda: gc.effective(gc.monodisperse(3)), r"not smaller than its neighbours"),
    ("effective of an effective chain", lambda: gc.effective(gc.effective(gc.decorated([0.2, 0.3]))), r"effective\(\) needs a decorated chain built from radii"),
    ("effective of a non-chain", lambda: gc.effective([1.0, 0.2, 1.0]), r"effective\(\) needs a decorated granchain\.Chain"),
    # simulate()
    ("simulate a non-chain", lambda: gc.simulate([1.0, 1.0]), r"simulate\(\) needs a granchain\.Chain"),
    ("t_grid decreasing", lambda: gc.simulate(_chain(), t_grid=[0.0, 2.0, 1.0]), r"t_grid must be .*strictly increasing"),
    ("t_grid repeated", lambda: gc.simulate(_chain(), t_grid=[0.0, 1.0, 1.0]), r"t_grid must be .*strictly increasing"),
    ("t_grid negative", lambda: gc.simulate(_chain(), t_grid=[-1.0, 1.0]), r"t_grid must be .*>= 0"),
    ("t_grid NaN", lambda: gc.simulate(_chain(), t_grid=[0.0, math.nan]), r"t_grid must be finite"),
    ("t_grid beyond t_max", lambda: gc.simulate(_chain(), t_grid=[0.0, 20.0], t_max=10.0, stop="t_max"), r"t_grid ends at 20"),
    ("unknown stop", lambda: gc.simulate(_chain(), stop="never"), r"stop must be 'exit' or 't_max'"),
    ("negative t_max", lambda: gc.simulate(_chain(), t_max=-1.0), r"t_max must be > 0"),
    ("negative exit_margin", lambda: gc.simulate(_chain(), exit_margin=-1.0), r"exit_margin must be >= 0"),
    ("zero max_steps", lambda: gc.simulate(_chain(), max_steps=0), r"max_steps must be >= 1"),
    ("negative peak_rtol", lambda: gc.simulate(_chain(), peak_rtol=-1e-6), r"peak_rtol must be >= 0"),
]


@pytest.mark.parametrize("make, match", [b[1:] for b in BAD_INPUTS], ids=[b[0] for b in BAD_INPUTS])
def test_bad_input_raises_value_error_naming_it(make, match):
    with pytest.raises(ValueError, match=match):
        make()


# -- the effective description's validity (~0.4) --------------------------------------
@pytest.mark.parametrize(
    "make",
    [
        lambda: gc.RandomDecorated(6, gc.Uniform(0.01, 0.6)),
        lambda: gc.RandomDecorated(6, gc.Truncated(st.beta(2, 5))),  # mass up to 1
        lambda: gc.effective(gc.decorated([0.5, 0.2])),
        lambda: gc.effective(gc.from_radii([1.0, 0.45, 1.0])),
    ],
    ids=["RandomDecorated Uniform beta 0.6", "RandomDecorated Truncated beta(2,5) to 1", "effective R=0.5", "effective R=0.45"],
)
def test_beyond_validity_warns(make):
    with pytest.warns(gc.EffectiveValidityWarning, match=r"> 0\.4"):
        make()


@pytest.mark.parametrize(
    "make",
    [
        lambda: gc.RandomDecorated(6, gc.Uniform(0.01, 0.4)),
        lambda: gc.RandomDecorated(6, gc.Truncated(st.beta(2, 5), upper=0.4)),
        lambda: gc.effective(gc.decorated([0.4, 0.2])),
        # radii beyond 0.4 are no small granules outside decorated families: no warning
        lambda: gc.Uniform(0.01, 0.6),
        lambda: gc.Truncated(st.beta(2, 5)),
        lambda: gc.RandomRadii(6, gc.Uniform(0.5, 1.5)),
    ],
    ids=["Uniform to 0.4", "Truncated to 0.4", "effective R=0.4", "bare Uniform", "bare Truncated", "RandomRadii"],
)
def test_within_validity_is_silent(make):
    with warnings.catch_warnings():
        warnings.simplefilter("error", gc.EffectiveValidityWarning)
        make()


@pytest.mark.parametrize(
    "make",
    [lambda: gc.RandomDecorated(6, gc.Uniform(0.01, 0.6)), lambda: gc.TaperedDecorated(6, q=0.1, distribution=gc.Truncated(st.beta(2, 5))),
     lambda: gc.effective(gc.decorated([0.5, 0.2])), lambda: gc.random_decorated(6, gc.Uniform(0.01, 0.6)),
     lambda: gc.run_ensemble(3, gc.Uniform(0.3, 0.5), realizations=1, chains="effective", progress=False)],
    ids=["RandomDecorated", "TaperedDecorated", "effective", "random_decorated", "run_ensemble"],
)
def test_validity_warning_points_at_the_callers_line(make):
    """The warning must be attributed to the user's code (stacklevel), not to package internals."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        make()
    found = [w for w in caught if issubclass(w.category, gc.EffectiveValidityWarning)]
    assert len(found) == 1
    assert found[0].filename == __file__, f"warning attributed to {found[0].filename}:{found[0].lineno}"
