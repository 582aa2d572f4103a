"""Every registered integrator: declared order measured, conservation, registry contract.

Smooth test problem with an exact solution: two unit spheres, n = 2 (linear force while in
contact). During contact the relative compression is exactly sinusoidal,
delta(t) = (v/omega) sin(omega t), omega = sqrt(c / M_red), and the centre of mass moves
uniformly. The force is smooth for delta > 0, so integrating to 0.7 of the half-period
(inside the contact) with fixed steps shows each method's full order.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as hs

import granchain as gc

# How to make each registered integrator take fixed steps of size h. A new integrator added to
# the registry must be listed here (or in ADAPTIVE_ONLY), so its order gets measured.
FIXED_STEP = {
    "dp5": lambda h: gc.DP5(fixed_step=h),
    "rkn4": lambda h: gc.RKN4(fixed_step=h),
    "verlet": lambda h: gc.Verlet(dt=h),
}
ADAPTIVE_ONLY = {"dop853"}  # SciPy's DOP853: no fixed-step mode; checked for a tiny error instead

DIVISIONS = (8, 16, 32, 64)


def harmonic_two_body():
    chain = gc.from_radii([1.0, 1.0], n=2.0)
    m1, m2 = chain.masses
    c = float(chain.stiffness[0])
    M = m1 * m2 / (m1 + m2)
    omega = math.sqrt(c / M)
    v0 = chain.initial_velocity
    t_end = 0.7 * math.pi / omega

    def exact(t):
        d = v0 / omega * math.sin(omega * t)
        dd = v0 * math.cos(omega * t)
        vcm = m1 * v0 / (m1 + m2)
        x = np.array([vcm * t + m2 / (m1 + m2) * d, vcm * t - m1 / (m1 + m2) * d])
        v = np.array([vcm + m2 / (m1 + m2) * dd, vcm - m1 / (m1 + m2) * dd])
        return x, v

    return chain, t_end, exact


def state_error(result, exact, t):
    x, v = exact(t)
    return max(np.max(np.abs(result.positions - x)), np.max(np.abs(result.velocities - v)))


def test_registry():
    assert set(gc.INTEGRATORS) == set(FIXED_STEP) | ADAPTIVE_ONLY, "register a fixed-step factory for every integrator"
    for name, cls in gc.INTEGRATORS.items():
        assert cls.name == name
        assert isinstance(cls.order, int) and cls.order >= 2
        assert gc.get_integrator(name) == cls()
        assert gc.get_integrator(name.upper()).name == name
    assert isinstance(gc.get_integrator(None), gc.DP5)
    custom = gc.DP5(rtol=1e-7)
    assert gc.get_integrator(custom) is custom


def test_every_runge_kutta_scheme_has_its_integrator_and_the_other_way_round():
    """The compiled step loop's schemes (``kernels.schemes``) and the adaptive integrators are one list: each
    scheme is the method of a registered integrator of the same name and order (whose error estimate is one
    order lower), run under a StepControl; DP5 and RKN4 are siblings, not parent and child."""
    from granchain.backends.kernels.schemes import SCHEMES
    from granchain.solve.integrators import AdaptiveRK, StepControl

    adaptive = {name: cls for name, cls in gc.INTEGRATORS.items() if issubclass(cls, AdaptiveRK)}
    assert {s.name for s in SCHEMES.values()} == set(adaptive) == {"dp5", "rkn4"}
    for s in SCHEMES.values():
        assert adaptive[s.name].order == s.order and s.error_order == s.order
        integ = adaptive[s.name](rtol=1e-7, relaxed_lag=4)
        assert integ.step_control == StepControl(rtol=1e-7, relaxed_lag=4) and integ.goal_oriented
    assert not isinstance(gc.RKN4(), gc.DP5) and not isinstance(gc.DP5(), gc.RKN4)
    assert gc.RKN4.windowed().describe()["rtol"] == 3e-6 and gc.DP5.windowed().describe()["rtol"] == 1e-6
    with pytest.raises(ValueError, match="relaxed_factor"):
        StepControl(relaxed_factor=0.5)


def test_a_scheme_is_refused_without_its_parts():
    """A scheme lacking one of the functions the step loop calls, or of a kind the root searches have no
    dense output for (its peaks would be located on another method's), is refused when registered."""
    import types

    from granchain.backends.kernels import dp5, schemes

    partial = types.SimpleNamespace(**{k: getattr(dp5, k) for k in dir(dp5) if k != "dense_data"})
    with pytest.raises(TypeError, match="lacks \\['dense_data'\\]"):
        schemes.scheme("partial", schemes.DP5.kind, partial)
    with pytest.raises(TypeError, match="no branch"):
        schemes.scheme("unknown", 99, dp5)
    assert schemes.scheme("dp5", schemes.DP5.kind, dp5) == schemes.DP5


@pytest.mark.parametrize("name", sorted(gc.INTEGRATORS))
def test_convergence_order(name):
    chain, T, exact = harmonic_two_body()
    cls = gc.INTEGRATORS[name]
    if name in ADAPTIVE_ONLY:
        r = gc.simulate(chain, cls(), t_max=T, stop="t_max")
        assert r.ok and r.t_end == T
        assert state_error(r, exact, T) < 1e-9
        return
    assert name in FIXED_STEP, f"no fixed-step factory for integrator {name!r}"
    hs, errs = [], []
    for k in DIVISIONS:
        h = T / k
        r = gc.simulate(chain, FIXED_STEP[name](h), t_max=T, stop="t_max")
        assert r.ok and r.t_end == T and r.n_rejected == 0
        hs.append(h)
        errs.append(state_error(r, exact, T))
    order = np.polyfit(np.log(hs), np.log(errs), 1)[0]
    print(f"{name}: observed order {order:.3f} (declared {cls.order}); errors {errs}")
    low = cls.order - max(0.2, 0.1 * cls.order)  # DP5: 4.5, Verlet: 1.8
    high = cls.order + max(0.2, 0.12 * cls.order)  # DP5: 5.6, Verlet: 2.2
    assert low <= order <= high, (order, errs)


@pytest.mark.parametrize("name", sorted(gc.INTEGRATORS))
def test_conservation_for_every_integrator(name):
    chains = [gc.monodisperse(10), gc.tapered(8, 0.1), gc.effective(gc.random_decorated(8, seed=1)), gc.from_radii([1.0, 0.4, 1.0, 0.2, 1.0])]
    for chain in chains:
        r = gc.simulate(chain, gc.INTEGRATORS[name]())
        assert r.ok, (chain, r.message)
        assert abs(r.momentum_error) < 1e-12, (chain, r.momentum_error)
        assert abs(r.energy_error) < 1e-5, (chain, r.energy_error)


def test_verlet_observables_are_second_order():
    """Peak velocities, peak times and grid velocities from Verlet converge like h^2."""
    chain = gc.monodisperse(10)
    t_grid = np.linspace(0.0, 10.0, 41)
    ref = gc.simulate(chain, gc.DP5(rtol=1e-12, atol=1e-14), t_grid=t_grid)
    errs = []
    for dt in (4e-3, 2e-3, 1e-3):
        r = gc.simulate(chain, gc.Verlet(dt=dt), t_grid=t_grid)
        errs.append(
            [
                np.max(np.abs(r.peak_velocity - ref.peak_velocity)),
                np.max(np.abs(r.peak_time - ref.peak_time)[:-1]),  # last granule: plateau, time is the exit
                np.max(np.abs(r.velocity - ref.velocity)),
            ]
        )
    rates = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all((rates > 1.7) & (rates < 2.3)), rates
    assert errs[-1][0] < 1e-6


def test_dp5_error_follows_rtol():
    """DP5's error on the observables falls with rtol and stays within ~50 rtol (max-norm control)."""
    chain = gc.monodisperse(10)
    ref = gc.simulate(chain, gc.DP5(rtol=1e-12, atol=1e-14))
    errs = []
    for rtol in (1e-6, 1e-8, 1e-10):
        r = gc.simulate(chain, gc.DP5(rtol=rtol, atol=rtol * 1e-2))
        err = np.max(np.abs(r.peak_velocity - ref.peak_velocity))
        assert err < 50 * rtol, (rtol, err)
        errs.append(err)
    assert errs[0] > errs[1] > errs[2]


# -- DP5 kernel pieces ---------------------------------------------------------------------------
def error_norm(scheme, x, v, xs, vs, Kx, Kv, h, hi, relaxed, factor, rtol, atol, ratio):
    """The step loop's error norm of ``scheme`` (``kernels.schemes``): its error ratios into ``ratio``, then
    their maximum (``rkloop.max_ratio``)."""
    from granchain.backends.kernels.rkloop import max_ratio

    scheme.module.error_ratios(x, v, xs, vs, Kx, Kv, h, hi, relaxed, factor, rtol, atol, ratio)
    return max_ratio(ratio, hi)


def _error_norm_case(scheme, seed, hi=50):
    """Random state and stages of ``hi`` granules: (hi, Kx, Kv, ratio, norm), ``norm()`` the error
    norm of ``scheme`` on the arrays as they are when called (its ratios left in ``ratio``)."""
    rng = np.random.default_rng(seed)
    x, v, xs, vs = (rng.random(hi) for _ in range(4))
    Kx, Kv = rng.random((7, hi)), rng.random((7, hi))
    ratio = np.zeros(2 * hi)
    return hi, Kx, Kv, ratio, lambda: error_norm(scheme, x, v, xs, vs, Kx, Kv, 1e-3, hi, 0, 1.0, 1e-6, 1e-9, ratio)


@pytest.mark.parametrize("where", [0, 1, 5, 40, 99])
def test_dp5_error_norm_keeps_a_nan(where):
    """A NaN ratio anywhere makes the error norm infinite (the step is refused as non-finite), also when
    finite ratios follow it (the max loop once let a later finite ratio overwrite the NaN); with all
    ratios finite the norm is their maximum, wherever it is."""
    from granchain.backends.kernels.schemes import DP5

    hi, Kx, Kv, ratio, norm = _error_norm_case(DP5, where)
    err = norm()
    assert err == ratio.max() and math.isfinite(err)
    (Kx if where < hi else Kv)[3, where % hi] = np.nan
    assert norm() == math.inf
    assert np.isnan(ratio[where]) and np.isfinite(np.delete(ratio, where)).all()


@pytest.mark.parametrize("where", [0, 1, 17, 49])
def test_rkn4_error_norm_keeps_a_nan(where):
    """The same for RKN4's error estimate, which reads the stage accelerations Kv[0..3] only: a NaN
    there makes both the position and the velocity ratio of that granule NaN and the norm infinite."""
    from granchain.backends.kernels.schemes import RKN4

    hi, Kx, Kv, ratio, norm = _error_norm_case(RKN4, where)
    err = norm()
    assert err == ratio.max() and math.isfinite(err)
    Kx[:, where] = np.nan  # not read by RKN4
    Kv[4:, where] = np.nan
    assert norm() == err
    Kv[3, where] = np.nan
    assert norm() == math.inf
    assert np.isnan(ratio[where]) and np.isnan(ratio[hi + where])


@settings(max_examples=60, deadline=None)
@given(seed=hs.integers(0, 2**32 - 1), hi=hs.integers(1, 60), relaxed=hs.integers(0, 60),
       exponent=hs.integers(-1080, 1030))
def test_dp5_error_norm_is_the_float_maximum(seed, hi, relaxed, exponent):
    """The error norm takes the maximum of the ratios as an integer maximum of their bit patterns; it
    must be exactly the floating-point maximum of |error| / scale computed independently (NumPy, the
    same operations in the same order), from subnormal to overflowing errors (inf: refused step)."""
    from granchain.backends.kernels import dp5
    from granchain.backends.kernels.schemes import DP5

    rng = np.random.default_rng(seed)
    x, v, xs, vs = (rng.standard_normal(hi) for _ in range(4))
    Kx, Kv = rng.standard_normal((7, hi)), rng.standard_normal((7, hi))
    Kx[:, rng.random(hi) < 0.2] = 0.0  # exact zeros (resting granules)
    with np.errstate(over="ignore", under="ignore"):
        Kx = np.ldexp(Kx, exponent)  # scaled by 2^exponent: subnormal ... inf
    h, rtol, atol, factor = 1e-3, 1e-6, 1e-9, 1000.0
    err = error_norm(DP5, x, v, xs, vs, Kx, Kv, h, hi, relaxed, factor, rtol, atol, np.zeros(2 * hi))

    E = (dp5.E1, dp5.E3, dp5.E4, dp5.E5, dp5.E6, dp5.E7)
    rows = (0, 2, 3, 4, 5, 6)
    w = np.where(np.arange(hi) < relaxed, factor, 1.0)
    with np.errstate(all="ignore"):
        ratios = []
        for K, y, ys in ((Kx, x, xs), (Kv, v, vs)):
            acc = E[0] * K[rows[0]]
            for e, r in zip(E[1:], rows[1:]):
                acc = acc + e * K[r]
            ratios.append(np.abs(h * acc) / ((atol + rtol * np.maximum(np.abs(y), np.abs(ys))) * w))
        ratios = np.concatenate(ratios)
    expected = ratios.max() if np.isfinite(ratios).all() else math.inf
    assert err == expected


PADDING_SCRIPT = """
import json, numba, numpy as np, granchain as gc
from granchain.solve.integrators import RunControls
from granchain.backends.kernels import rkloop
assert numba.config.DISABLE_JIT
cases = {f"decorated N={k}": gc.decorated([0.3, 0.2, 0.35, 0.25, 0.3, 0.22][: k - 1]) for k in (2, 3, 4, 5, 6, 7)}
cases.update({f"monodisperse {k}": gc.monodisperse(k) for k in (2, 4, 6, 8, 9)})
integrators = {"exact": gc.DP5(1e-6, 1e-9), "windowed": gc.DP5(1e-6, 1e-9, relaxed_lag=1, window_lag=2),
               "rkn4": gc.RKN4(1e-5, 1e-8), "rkn4-windowed": gc.RKN4(1e-5, 1e-8, relaxed_lag=1, window_lag=2)}
def run(chain, integ):
    x, v = np.zeros(chain.size), np.zeros(chain.size)
    v[0] = chain.initial_velocity
    status, info, *arrays = integ.integrate(chain, x, v, t_grid=np.linspace(0.0, 12.0, 25), t_max=1e3,
                                            stop_at_exit=True, controls=RunControls())
    return [int(status), info.tolist(), x.tolist(), v.tolist()] + [np.asarray(a).tolist() for a in arrays]
padded = {f"{c}/{i}": run(chain, integ) for c, chain in cases.items() for i, integ in integrators.items()}
widths = sorted({rkloop.padded_width(hw) for hw in range(1, 20)})
rkloop.padded_width = lambda hw: hw  # the loops end at the window's end: the unpadded layout
plain = {f"{c}/{i}": run(chain, integ) for c, chain in cases.items() for i, integ in integrators.items()}
print(json.dumps(dict(padded=padded, plain=plain, widths=widths)))
"""


def test_padded_loops_are_bitwise_the_window(run_without_jit):
    """The DP5 loops run to the next multiple of ``rkloop.LANES`` past the window (padded layout); the
    extra granules (at rest ahead of the pulse, or padding with zero stiffness and inverse mass) must
    change nothing: with the loops ending at the window's end instead, every output is bitwise the
    same. Pure-Python kernels (NUMBA_DISABLE_JIT) so that the loop length can be swapped; chains of
    2 to 13 granules (every remainder mod 8, and the chain's end inside the padding), exact and with
    trailing-window cuts (which shift the stage arrays)."""
    from granchain.backends.kernels.records import INFO_WINDOW_START

    out = run_without_jit(PADDING_SCRIPT, timeout=600)
    assert out["widths"] == [8, 16, 24]
    assert out["padded"].keys() == out["plain"].keys()
    cut = 0
    for key, got in out["padded"].items():
        assert got[0] == 0, key
        assert got == out["plain"][key], f"{key}: the padded loops changed the result"
        cut += got[1][INFO_WINDOW_START] > 0  # the trailing window did cut
    assert cut >= 4, "too few runs with a trailing-window cut to test the shifted stage arrays"


def test_borrowed_views_share_memory():
    """The DP5 step loop runs on borrowed views (no reference counting): they must be views of the
    very arrays the caller passed, so the kernel's writes reach them."""
    from numba import njit

    from granchain.backends.kernels.memory import borrowed, keep_alive

    @njit
    def fill(a, b):
        owned = np.zeros(3)
        va, vb, vo = borrowed(a), borrowed(b), borrowed(owned)
        for i in range(a.shape[0]):
            va[i] = 2.0 * i
        vb[1, 2] = 7.0
        vo[1] = 5.0
        total = vo.sum()
        keep_alive(owned)
        return total

    a, b = np.zeros(4), np.zeros((2, 3))
    assert fill(a, b) == 5.0
    np.testing.assert_array_equal(a, [0.0, 2.0, 4.0, 6.0])
    assert b[1, 2] == 7.0 and b.sum() == 7.0
