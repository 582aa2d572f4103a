"""Goal-oriented error control in DP5 and RKN4: the relaxed zone and the trailing window.

``DP5.relaxed()`` / ``RKN4.relaxed()`` loosen the tolerance of the granules the pulse has passed; ``windowed()`` also drops
them from the integration a few granules behind the pulse (the ensembles' defaults: RKN4 for decorated
chains, DP5 for their effective chains). What is checked:

1. accuracy contract against DOP853 (rtol 1e-10, atol 1e-12) on seeded random N = 26 decorated
   chains and their effective chains, with the relaxed and the windowed integrator at each chain
   kind's ensemble default (``ensemble_integrator(kind)``: RKN4 at rtol 3e-6 for decorated chains,
   DP5 at 1e-8 for the others) and with ``DP5.relaxed()`` (rtol 1e-6) on the decorated chains:
   peak velocities within 1e-6 (relative), peak times within 1e-5 (absolute; the
   pulse reaches granule 26 at t ~ 60), peak contact forces within 1e-6 of the chain's largest
   force. 3 chains of each kind in the default suite, 20 under ``-m slow`` (DOP853 results cached
   per module). Negative control: the effective chain at the decorated tolerance misses it;
2. the averaged pulse <v_k(t)> of an N = 26 decorated ensemble (150 realisations; 500 under
   ``-m slow``): the relaxed integrators (RKN4, and DP5.relaxed()) within 1e-4 and within 0.1 standard
   error of the exact DP5(1e-6, 1e-9) on the whole grid; the default (windowed, with each granule's
   averaged-pulse window) the same inside the windows, NaN after them, and windows that hold every
   realisation's pulse (``granchain.ensembles.pulse_window.check``);
   the maxima max_t <v_k(t)> within 1e-6 (relative) for all of them; the trailing window without
   averaged-pulse windows agrees up to each granule's maximum but not in the tail (the negative
   control of the averaged-pulse criterion);
3. ensembles with ``DP5.windowed()``: bitwise the same per-realisation results and sums for chunk
   sizes 1/7/64 and 1 or 2 Numba threads (slow: a Dask cluster and a store), and without the
   averaged-pulse windows every row bitwise ``simulate(family.chain(seed, i), DP5.windowed())``;
4. exact mode: ``DP5()`` and ``DP5(1e-6, 1e-9)`` integrate every granule to the end (window start
   0), a relaxed zone with factor 1 is bitwise the exact run, the relaxed zone alone never cuts,
   the window really cuts on N = 26 and both take fewer steps than the exact run;
5. window semantics: a frozen granule reports the velocity it left with on the time grid (constant
   where the full dynamics is not), its position continues ballistically, the energy report is
   kinetic + integrated potential + frozen potential, energy drift < 1e-4 and momentum conserved
   to round-off; with a wall, relaxed and windowed are bitwise the exact DP5;
6. settings: validation names the parameter, ``describe()`` records, stores written with the exact
   DP5 are resumed with ``integrator=DP5(1e-6, 1e-9)`` (and refused with the relaxed default);
7. Hypothesis: windowed peaks equal the exact DP5's within 2e-6 / 2e-5 on random decorated chains
   of N = 8..20.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import xarray as xr
from conftest import completed, in_order
from hypothesis import given, settings
from hypothesis import strategies as hs

import granchain as gc
from granchain.backends.kernels.records import (
    INFO_FROZEN_POTENTIAL,
    INFO_STEPS,
    INFO_WINDOW_START,
)
from granchain.ensembles import run as ens
from granchain.solve.integrators import (
    RELAXED_FACTOR,
    RELAXED_LAG,
    WINDOW_LAG,
    RunControls,
    integrator_from_record,
)
from granchain.solve.simulation import default_t_max

N = 26
KINDS = ("decorated", "effective")
EXACT = gc.DP5(1e-6, 1e-9)  # the ensembles' integrator before granchain 0.3: every granule to the end
FAST_SEEDS = (0, 1, 2)
SWEEP_SEEDS = tuple(range(20))

# The accuracy contract (granchain.DP5's docstring)
PEAK_V_RTOL = 1e-6
PEAK_T_ATOL = 1e-5
PEAK_F_RTOL = 1e-6  # relative to the chain's largest peak force


def chain_of(seed: int, kind: str) -> gc.Chain:
    chain = gc.random_decorated(N, seed=seed)
    return chain if kind == "decorated" else gc.effective(chain)


def goal_integrators(kind: str) -> dict:
    """The relaxed integrator the ensembles use for ``kind``, the windowed one at the same method and
    tolerances, and (decorated chains) ``DP5.relaxed()``, the default before RKN4."""
    relaxed = ens.ensemble_integrator(kind, windowed=False)
    out = {"relaxed": relaxed, "windowed": ens.ensemble_integrator(kind)}
    if kind == "decorated":
        out["dp5-relaxed"] = gc.DP5.relaxed()
    return out


def integrate(chain, integrator, *, t_grid=(), t_max=None, stop_at_exit=True):
    """One run through the integrator seam: (status, info, final x, final v, grid velocities (T, K))."""
    x = np.zeros(chain.size)
    v = np.zeros(chain.size)
    v[0] = chain.initial_velocity
    status, info, _, _, grid_v, *_ = integrator.integrate(
        chain, x, v, t_grid=np.asarray(t_grid, dtype=float), t_max=default_t_max(chain) if t_max is None else t_max,
        stop_at_exit=stop_at_exit, controls=RunControls())
    return status, info, x, v, grid_v


def peak_errors(a, b) -> dict:
    """Largest deviations of run ``a`` from run ``b``: relative peak velocity, absolute peak time, peak
    force relative to b's largest peak force; and where (0-based observed granule / contact)."""
    np.testing.assert_array_equal(a.granule, b.granule)
    dv = np.abs(a.peak_velocity / b.peak_velocity - 1.0)
    dt = np.abs(a.peak_time - b.peak_time)
    df = np.abs(a.peak_force - b.peak_force) / np.max(b.peak_force)
    return {"v": float(dv.max()), "t": float(dt.max()), "f": float(df.max()),
            "where": (int(dv.argmax()), int(dt.argmax()), int(df.argmax()))}


def contract_violation(a, b) -> str | None:
    e = peak_errors(a, b)
    if e["v"] <= PEAK_V_RTOL and e["t"] <= PEAK_T_ATOL and e["f"] <= PEAK_F_RTOL:
        return None
    return (f"peak velocity {e['v']:.2e} (limit {PEAK_V_RTOL:g}), peak time {e['t']:.2e} (limit {PEAK_T_ATOL:g}), "
            f"peak force {e['f']:.2e} (limit {PEAK_F_RTOL:g}); worst at (0-based) observed granule {e['where'][0]} (velocity), {e['where'][1]} (time), contact {e['where'][2]} (force)")


#: The DOP853 references by (seed, kind), kept for the process: pytest tears a module fixture down whenever the
#: next test is in another module, and pytest-xdist's workers (the slow suite runs on two) interleave modules.
_DOP853 = {}


@pytest.fixture
def dop853(reference):
    """``dop853(seed, kind)``: the DOP853 (rtol 1e-10) result of chain_of(seed, kind), computed once."""

    def get(seed, kind):
        if (seed, kind) not in _DOP853:
            result = gc.simulate(chain_of(seed, kind), reference)
            assert result.ok, result.message
            _DOP853[seed, kind] = result
        return _DOP853[seed, kind]

    return get


# -- 1. accuracy contract against DOP853 ------------------------------------------------------------
def test_ensemble_defaults_are_the_windowed_integrators():
    """The integrators of section 1 are the ensembles' defaults: RKN4.windowed() for decorated chains, the
    windowed DP5 at tight tolerances for the others (effective); with ``windowed=False`` (run_ensemble's
    pulse_window="full") the relaxed ones at the same tolerances."""
    assert ens.ensemble_integrator() == ens.ensemble_integrator("decorated") == gc.RKN4.windowed()
    assert ens.ensemble_integrator("decorated", windowed=False) == gc.RKN4.relaxed()
    assert gc.RKN4.relaxed() == gc.RKN4(gc.ENSEMBLE_RTOL, gc.ENSEMBLE_ATOL, relaxed_lag=RELAXED_LAG,
                                        relaxed_factor=RELAXED_FACTOR)
    assert ens.ensemble_integrator("effective") == gc.DP5.windowed(gc.SMOOTH_RTOL, gc.SMOOTH_ATOL)
    assert ens.ensemble_integrator("effective", windowed=False) == gc.DP5.relaxed(gc.SMOOTH_RTOL, gc.SMOOTH_ATOL)
    assert gc.DP5.relaxed() == gc.DP5(1e-6, 1e-9, relaxed_lag=RELAXED_LAG, relaxed_factor=RELAXED_FACTOR)
    # the validated tolerances (benchmarks/validate_tolerances.py: the loosest within half the contract)
    assert (gc.ENSEMBLE_RTOL, gc.ENSEMBLE_ATOL, gc.SMOOTH_RTOL, gc.SMOOTH_ATOL) == (3e-6, 3e-9, 1e-8, 1e-11)
    for cls, rtol, atol in ((gc.DP5, 1e-6, 1e-9), (gc.RKN4, 3e-6, 3e-9)):
        assert cls.windowed() == cls(rtol, atol, relaxed_lag=RELAXED_LAG, relaxed_factor=RELAXED_FACTOR,
                                     window_lag=WINDOW_LAG)
    for kind in KINDS:
        windowed, relaxed = ens.ensemble_integrator(kind), ens.ensemble_integrator(kind, windowed=False)
        assert windowed == type(windowed).windowed(windowed.rtol, windowed.atol)
        assert relaxed == type(relaxed).relaxed(relaxed.rtol, relaxed.atol) and not relaxed.is_exact
        assert relaxed.window_lag is None


def test_random_binary_chains_default_to_dp5_without_the_relaxed_zone(reference):
    """Chain kinds other than the paper's two (polydisperse, binary, a user's) default to DP5 at
    RANDOM_RTOL without the relaxed zone: waves reflected at every change of mass give some granules
    their largest velocity after the front has passed, where the relaxed zone loosens the tolerance.
    On this binary chain (BinaryRandom(26), seed 7, realisation 4) the relaxed DP5 at rtol 5e-8, the
    default before, misses the contract (peak velocity 4.1e-6 off, measured) and the default meets it
    (3.5e-7): the check fails both ways."""
    family = gc.BinaryRandom(26)
    default = ens.ensemble_integrator(family.chains[0])
    assert default == gc.DP5(gc.RANDOM_RTOL, gc.RANDOM_ATOL) and default.is_exact
    assert ens.ensemble_integrator("polydisperse") == default
    chain = family.chain(7, 4)
    ref = gc.simulate(chain, reference)
    assert contract_violation(gc.simulate(chain, default), ref) is None
    assert contract_violation(gc.simulate(chain, gc.DP5.relaxed(5e-8, 5e-11)), ref) is not None


@pytest.mark.parametrize("realization", [23735, 4822])
def test_the_free_end_of_effective_chains(reference, realization):
    """Two N = 6 effective realisations of the paper's set (seed 1000 * 2026 + 6) where the effective
    chains' default before, ``DP5.windowed(5e-8, 5e-11)``, puts the last granule's peak velocity 2.96e-6
    and 2.92e-6 from DOP853 (measured; it missed the contract on 170 of the paper set's 120,000
    effective realisations, all at the last granule): the default (rtol 1e-8) keeps it within 3e-8."""
    chain = gc.RandomDecorated(6).chain(1000 * 2026 + 6, realization, "effective")
    ref = gc.simulate(chain, reference)
    assert contract_violation(gc.simulate(chain, ens.ensemble_integrator("effective")), ref) is None
    assert peak_errors(gc.simulate(chain, gc.DP5.windowed(5e-8, 5e-11)), ref)["v"] > PEAK_V_RTOL


def test_the_peak_forces_of_decorated_chains(reference):
    """Peak contact forces set the decorated chains' tolerance: on this N = 26 chain
    (``RandomDecorated(26).chain(2026, 82)``) the default before, ``RKN4.windowed(1e-5, 1e-8)``, puts the
    force of the last contact 1.11x the contract from DOP853 at the pulse front (measured; 3 of the 102
    chains of benchmarks/validate_tolerances.py, 21 of 2,000 more), the default (rtol 3e-6) 0.36x."""
    chain = gc.RandomDecorated(26).chain(2026, 82, "decorated")
    ref = gc.simulate(chain, reference)
    assert contract_violation(gc.simulate(chain, ens.ensemble_integrator("decorated")), ref) is None
    assert peak_errors(gc.simulate(chain, gc.RKN4.windowed(1e-5, 1e-8)), ref)["f"] > PEAK_F_RTOL


GOAL_CASES = [("decorated", "relaxed"), ("decorated", "windowed"), ("decorated", "dp5-relaxed"),
              ("effective", "relaxed"), ("effective", "windowed")]


@pytest.mark.parametrize("kind, name", GOAL_CASES)
@pytest.mark.parametrize("seed", FAST_SEEDS)
def test_peaks_match_dop853(dop853, seed, kind, name):
    integrator = goal_integrators(kind)[name]
    a = gc.simulate(chain_of(seed, kind), integrator)
    assert a.ok, a.message
    problem = contract_violation(a, dop853(seed, kind))
    assert problem is None, f"{name} {integrator.name}, {kind} chain of seed {seed}: {problem}"


@pytest.mark.slow
@pytest.mark.parametrize("kind, name", GOAL_CASES)
def test_peaks_match_dop853_sweep(dop853, kind, name):
    """20 seeded chains of each kind (DOP853 takes ~2.5 s per decorated chain; cached for all integrators)."""
    integrator = goal_integrators(kind)[name]
    failures = []
    for seed in SWEEP_SEEDS:
        a = gc.simulate(chain_of(seed, kind), integrator)
        assert a.ok, f"seed {seed}: {a.message}"
        problem = contract_violation(a, dop853(seed, kind))
        if problem:
            failures.append(f"seed {seed}: {problem}")
    assert not failures, f"{name} {integrator.name} on {kind} chains:\n" + "\n".join(failures)


@pytest.mark.parametrize("n_large, realization", [(6, 23394), (16, 25779)])
def test_the_last_granule_of_the_paper_set_worst_cases(reference, n_large, realization):
    """The two decorated realisations of the paper's set (seed 1000 * 2026 + N) where a relaxed lag of
    3 put the last granule's peak 2.3e-6 and 1.3e-6 from DOP853 (the pulse piles up against the free
    end): the default lag keeps them within the contract (DP5 and the default RKN4), lag 3 does not
    (the control)."""
    family = gc.RandomDecorated(n_large)
    chain = family.chain(1000 * 2026 + n_large, realization, "decorated")
    ref = gc.simulate(chain, reference)
    assert contract_violation(gc.simulate(chain, gc.DP5.relaxed()), ref) is None
    assert contract_violation(gc.simulate(chain, ens.ensemble_integrator()), ref) is None
    lag3 = gc.simulate(chain, gc.DP5(1e-6, 1e-9, relaxed_lag=3))
    assert peak_errors(lag3, ref)["v"] > PEAK_V_RTOL


@pytest.mark.parametrize("realization", [17887, 15820])
def test_the_free_end_of_short_chains(reference, realization):
    """Two N = 6 decorated realisations of the paper's set (seed 1000 * 2026 + 6) where the pulse piles
    up against the free end and DP5.relaxed() (rtol 1e-6, 0.3's default) puts the last granule's
    peak 1.9e-6 and 1.4e-6 from DOP853: the default RKN4 keeps it within the contract (measured
    3e-8, 6e-8 at its rtol 1e-5 of then); DP5.relaxed() does not (the control)."""
    chain = gc.RandomDecorated(6).chain(1000 * 2026 + 6, realization, "decorated")
    ref = gc.simulate(chain, reference)
    assert contract_violation(gc.simulate(chain, ens.ensemble_integrator()), ref) is None
    assert peak_errors(gc.simulate(chain, gc.DP5.relaxed()), ref)["v"] > PEAK_V_RTOL


def test_the_contract_can_fail(dop853):
    """Negative control: the effective chain of seed 0 at the decorated chains' tolerance (rtol 1e-6)
    accumulates ~2e-6 of error along the chain (the reason for its tighter ensemble tolerance)."""
    a = gc.simulate(chain_of(0, "effective"), gc.DP5.relaxed())
    e = peak_errors(a, dop853(0, "effective"))
    assert e["v"] > PEAK_V_RTOL or e["t"] > PEAK_T_ATOL, e
    assert contract_violation(a, dop853(0, "effective")) is not None


# -- 2. the averaged pulse ---------------------------------------------------------------------------
def _averaged_pulses(realizations: int) -> dict:
    family = gc.RandomDecorated(N)
    kw = dict(realizations=realizations, seed=9, chains="decorated", chunk_size=realizations, progress=False)
    out = {}
    # "windowed": the trailing window without averaged-pulse windows (pulse_window="full", the 0.4 behaviour);
    # "default": the ensembles' default, the same integrator with each granule's averaged-pulse window.
    cases = (("exact", EXACT, "full"), ("relaxed", ens.ensemble_integrator(windowed=False), "full"),
             ("windowed", gc.RKN4.windowed(), "full"), ("dp5-relaxed", gc.DP5.relaxed(), "full"),
             ("default", None, "auto"))
    for name, integrator, window in cases:
        ds = gc.run_ensemble(family, integrator=integrator, pulse_window=window, **kw).isel(chain=0)
        assert int(ds["n_valid"]) == realizations, f"{name}: failed integrations"
        out[name] = ds
    return out


@pytest.fixture(scope="module")
def pulses_150():
    return _averaged_pulses(150)


@pytest.fixture(scope="module")
def pulses_500():
    return _averaged_pulses(500)


def _pulses(request, realizations):
    return request.getfixturevalue(f"pulses_{realizations}")


def pulse_deviation(ds, ref, upto_maximum: bool = False) -> tuple:
    """(max |<v> - <v>_ref|, max of that over ref's standard error where the error is > 0); with
    ``upto_maximum`` only at times up to the maximum of ref's <v_k(t)>, granule by granule."""
    diff = np.abs(ds["mean_velocity"] - ref["mean_velocity"])
    se = ref["mean_velocity_stderr"]
    if upto_maximum:
        diff = diff.where(diff["time"] <= ref["mean_velocity"].idxmax("time"), 0.0)
    return float(diff.max()), float((diff / se).where(se > 0, 0.0).max())


AVERAGED = [pytest.param(150, id="R150"), pytest.param(500, id="R500", marks=pytest.mark.slow)]


@pytest.mark.parametrize("realizations", AVERAGED)
@pytest.mark.parametrize("name", ["relaxed", "dp5-relaxed"])
def test_relaxed_keeps_the_averaged_pulse(request, realizations, name):
    """Measured at R = 500 (DP5.relaxed): max difference ~5e-6, ~0.002 standard errors."""
    p = _pulses(request, realizations)
    np.testing.assert_array_equal(p[name]["time"].values, p["exact"]["time"].values)
    worst, in_stderr = pulse_deviation(p[name], p["exact"])
    assert worst < 1e-4, f"max |<v>_{name} - <v>_exact| = {worst:.3g}"
    assert in_stderr < 0.1, f"max |<v>_{name} - <v>_exact| / stderr = {in_stderr:.3g}"


@pytest.mark.parametrize("realizations", AVERAGED)
def test_default_keeps_the_averaged_pulse_in_each_granules_window(request, realizations):
    """The default (trailing window, each granule's averaged-pulse window): wherever <v_k(t)> is recorded
    (t <= pulse_window_end) it passes the relaxed criterion against the exact DP5 (granule k is integrated
    there in every realisation), after it it is NaN (not computed), and the windows hold the pulse: the
    averaged pulse's maximum inside, every realisation's arrival before the window's end, and at most 2 %
    of them not yet at granule k + AHEAD when the window closes (pulse_window.check). The windows are
    finite for every granule but the last AHEAD."""
    from granchain.ensembles import pulse_window

    p = _pulses(request, realizations)
    ds, ref = p["default"], p["exact"]
    ends = ds["pulse_window_end"]
    assert int(ds["pulse_window_ahead"]) == pulse_window.AHEAD
    assert np.all(np.isfinite(ends[:N - pulse_window.AHEAD])) and np.all(np.isinf(ends[N - pulse_window.AHEAD:]))
    inside = ds["time"] <= ends
    assert bool(ds["mean_velocity"].where(~inside).isnull().all()), "values recorded past a window's end"
    assert bool(ds["mean_velocity"].where(inside, 0.0).notnull().all()), "a value missing inside a window"
    worst, in_stderr = pulse_deviation(ds.fillna(ref), ref)  # outside the windows: ref itself, no difference
    assert worst < 1e-4 and in_stderr < 0.1, (worst, in_stderr)
    check = pulse_window.check(ds.expand_dims("chain"))
    assert bool(check["peak_inside"].all()) and float(check["margin"].min()) > 0.0
    # the slowest realisations' pulses may not have reached k + AHEAD yet (measured: 16 of 150 x 21 windows)
    assert int(check["unfinished"].max()) <= 0.02 * realizations, check["unfinished"].values
    # negative control: the trailing window alone (granules report the velocity they left with) fails it
    assert pulse_deviation(p["windowed"], ref)[0] > 1e-4


@pytest.mark.parametrize("realizations", AVERAGED)
@pytest.mark.parametrize("name", ["relaxed", "windowed", "dp5-relaxed", "default"])
def test_averaged_pulse_maxima_are_kept(request, realizations, name):
    """max_t <v_k(t)> within 1e-6 (relative) of the exact DP5's (measured ~1e-8)."""
    p = _pulses(request, realizations)
    peak, ref = p[name]["mean_velocity"].max("time"), p["exact"]["mean_velocity"].max("time")
    rel = float(np.abs(peak / ref - 1.0).max())
    assert rel < 1e-6, f"{name}: averaged-pulse maxima differ by {rel:.3g} (relative)"


@pytest.mark.parametrize("realizations", AVERAGED)
def test_windowed_averaged_pulse_is_right_up_to_its_maximum_only(request, realizations):
    """Up to each granule's maximum the windowed <v_k(t)> passes the relaxed criterion; its tail does
    not (frozen granules report their exit velocity: measured ~0.06, 13-20 standard errors). The
    tail's failure is the negative control of the averaged-pulse criterion."""
    p = _pulses(request, realizations)
    worst, in_stderr = pulse_deviation(p["windowed"], p["exact"], upto_maximum=True)
    assert worst < 1e-4 and in_stderr < 0.1, (worst, in_stderr)
    worst, in_stderr = pulse_deviation(p["windowed"], p["exact"])
    assert worst > 1e-4 and in_stderr > 0.1, f"the windowed tail should differ: {worst:.3g}, {in_stderr:.3g} stderr"
    # ... and it is the tail: the last grid time, long after the pulse has passed granule 1
    tail = np.abs(p["windowed"]["mean_velocity"] - p["exact"]["mean_velocity"]).isel(time=-1)
    assert float(tail.max()) > 1e-4


# -- 3. windowed ensembles: bitwise reproducible, rows are simulate() ---------------------------------
SEED = 11
R = 20
PER_REALISATION = ("peak_velocity", "peak_time", "peak_force", "peak_force_time", "status", "energy_error", "n_steps", "t_end")
SUMS = ("mean_velocity", "mean_velocity_stderr", "n_valid")


def _windowed_ensemble(**kw):
    """DP5.windowed() with the averaged-pulse windows (the default ``pulse_window="auto"``)."""
    args = dict(realizations=R, seed=SEED, chunk_size=7, threads=2, integrator=gc.DP5.windowed(), progress=False) | kw
    return gc.run_ensemble(gc.RandomDecorated(N), **args)


def assert_same_results(a, b, names=PER_REALISATION + SUMS):
    for name in names:
        np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=name)


@pytest.fixture(scope="module")
def windowed_ensemble():
    return _windowed_ensemble()


@pytest.mark.parametrize("chunk_size, threads", [(1, 2), (64, 2), (7, 1), (64, 1)])
def test_windowed_ensemble_does_not_depend_on_chunks_or_threads(windowed_ensemble, chunk_size, threads):
    assert_same_results(_windowed_ensemble(chunk_size=chunk_size, threads=threads), windowed_ensemble)


def test_windowed_ensemble_rows_are_simulate():
    """Without averaged-pulse windows (``pulse_window="full"``) a windowed ensemble's rows are simulate's."""
    ds = _windowed_ensemble(pulse_window="full")
    assert "pulse_window_end" not in ds
    family = gc.RandomDecorated(N)
    assert json.loads(ds.attrs["granchain_integrator"]) == gc.DP5.windowed().describe()
    for name in family.chains:
        traces = []
        for i in range(R):
            res = gc.simulate(family.chain(SEED, i, name), gc.DP5.windowed(), t_grid=ds["time"].values)
            contacts = family.build(family.draw_batch(SEED, [i]), name).recorded_contacts()
            row = ds.sel(chain=name).isel(realization=i)
            assert int(row["status"]) == int(res.status) == 0
            np.testing.assert_array_equal(row["peak_velocity"].values, res.peak_velocity)
            np.testing.assert_array_equal(row["peak_time"].values, res.peak_time)
            np.testing.assert_array_equal(row["peak_force"].values, res.peak_force[contacts])
            np.testing.assert_array_equal(row["peak_force_time"].values, res.peak_force_time[contacts])
            assert int(row["n_steps"]) == res.n_steps and float(row["t_end"]) == res.t_end
            assert float(row["energy_error"]) == res.energy_error  # the same final_energy bookkeeping
            traces.append(res.velocity)
        # the sums are those of the simulate() traces, to the fixed-point resolution 2^-40
        np.testing.assert_allclose(ds["mean_velocity"].sel(chain=name).values, np.mean(traces, axis=0), rtol=0, atol=2.0**-39)
    # and the goal settings reached the batch kernel: fewer steps than the exact DP5
    exact = gc.simulate(family.chain(SEED, 0, "decorated"), EXACT, t_grid=ds["time"].values)
    assert int(ds["n_steps"].sel(chain="decorated").isel(realization=0)) < exact.n_steps


@pytest.mark.slow
def test_windowed_ensemble_on_dask_and_in_a_store(windowed_ensemble, tmp_path):
    from distributed import Client, LocalCluster

    store = tmp_path / "windowed.zarr"
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, Client(cluster) as client:
        assert_same_results(_windowed_ensemble(client=client, out=store), windowed_ensemble)
    reread = xr.open_dataset(store, engine="zarr")
    assert_same_results(reread, windowed_ensemble)
    assert integrator_from_record(json.loads(reread.attrs["granchain_integrator"])) == gc.DP5.windowed()
    # a finished store is resumed (a no-op) with the integrator it names
    assert_same_results(_windowed_ensemble(out=store), windowed_ensemble)


# -- 4. exact mode is unchanged; the goal settings really act ------------------------------------------
@pytest.mark.parametrize("seed", FAST_SEEDS)
def test_exact_integrates_every_granule_and_the_window_cuts(seed):
    chain = chain_of(seed, "decorated")
    runs = {name: integrate(chain, integ) for name, integ in
            (("default", gc.DP5()), ("exact", EXACT), ("relaxed", gc.DP5.relaxed()), ("windowed", gc.DP5.windowed()))}
    for name, (status, info, *_) in runs.items():
        assert status == 0, name
    for name in ("default", "exact", "relaxed"):
        info = runs[name][1]
        assert info[INFO_WINDOW_START] == 0 and info[INFO_FROZEN_POTENTIAL] == 0.0, name
    info = runs["windowed"][1]
    assert info[INFO_WINDOW_START] > 0, "DP5.windowed() did not cut on an N = 26 decorated chain"
    assert info[INFO_FROZEN_POTENTIAL] >= 0.0 and math.isfinite(info[INFO_FROZEN_POTENTIAL])
    steps = {name: runs[name][1][INFO_STEPS] for name in runs}
    assert steps["relaxed"] < steps["exact"] and steps["windowed"] < steps["exact"], steps
    assert gc.DP5().is_exact and EXACT.is_exact
    assert not gc.DP5.relaxed().is_exact and not gc.DP5.windowed().is_exact and not gc.DP5(window_lag=4).is_exact


@pytest.mark.parametrize("kind", KINDS)
def test_relaxed_zone_with_factor_one_is_the_exact_run(kind):
    """The zone only scales the error norm: a factor of 1 is bitwise the exact DP5 (steps, peaks, grid)."""
    chain = chain_of(1, kind)
    grid = np.arange(0.0, 70.0, 0.5)
    a = gc.simulate(chain, gc.DP5(1e-6, 1e-9, relaxed_lag=RELAXED_LAG, relaxed_factor=1.0), t_grid=grid)
    b = gc.simulate(chain, EXACT, t_grid=grid)
    assert a.n_steps == b.n_steps and a.n_rejected == b.n_rejected
    for name in ("peak_velocity", "peak_time", "peak_force", "peak_force_time", "velocity", "positions", "velocities"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert a.energy_error == b.energy_error
    # while the validated factor does change the run
    assert gc.simulate(chain, gc.DP5.relaxed()).n_steps != b.n_steps


# -- 5. window semantics ---------------------------------------------------------------------------------
@pytest.mark.parametrize("seed", FAST_SEEDS)
def test_frozen_granules_report_their_exit_velocity(seed):
    """A granule frozen by time T - 2 (window start of a run stopped at T - 2: every step before its
    last is the full run's) shows the velocity it left with at every grid time >= T: bitwise
    constant, where the exact run's velocity still changes (negative control)."""
    chain = chain_of(seed, "decorated")
    grid = gc.default_time_grid(N)
    status, info, x, v, grid_v = integrate(chain, gc.DP5.windowed(), t_grid=grid)
    assert status == 0
    res = gc.simulate(chain, gc.DP5.windowed(), t_grid=grid)  # the same run, through simulate()
    np.testing.assert_array_equal(res.velocity, grid_v.T)
    np.testing.assert_array_equal(res.velocities, v)
    exact = gc.simulate(chain, EXACT, t_grid=grid)
    lo = int(info[INFO_WINDOW_START])
    frozen = [q for q, k in enumerate(chain.observed) if k < lo]
    assert len(frozen) >= 10, f"only {len(frozen)} observed granules left the window"
    for q in frozen:  # the last grid time reports the velocity it left with; its peak came before
        k = chain.observed[q]
        assert res.velocity[q, -1] == res.velocities[k], f"granule {k + 1}"
        assert res.peak_velocity[q] >= res.velocities[k], f"granule {k + 1}"
    still_moving = 0
    for T in (30.0, 40.0, 50.0, 60.0, 70.0):
        lo_T = int(integrate(chain, gc.DP5.windowed(), t_max=T - 2.0, stop_at_exit=False)[1][INFO_WINDOW_START])
        assert lo_T <= lo
        after = grid >= T
        for q in [q for q, k in enumerate(chain.observed) if k < lo_T]:
            k = chain.observed[q]
            np.testing.assert_array_equal(res.velocity[q, after], res.velocities[k], err_msg=f"granule {k + 1}, t >= {T}")
            assert res.peak_time[q] < T - 2.0, f"granule {k + 1} left before its peak"
            still_moving += np.ptp(exact.velocity[q, after]) > 1e-3
    assert still_moving > 0, "the exact run's granules are in free flight too: the check above proves nothing"


def test_frozen_granules_move_ballistically():
    """Runs to fixed end times T1 < T2 (stop="t_max") share every step before T1: a granule frozen
    before T0 < T1 has the same velocity in both and moved by v (T2 - T1). The exact run's granules
    do not (negative control)."""
    chain = chain_of(0, "decorated")
    T0, T1, T2 = 40.0, 45.0, 60.0
    lo = int(integrate(chain, gc.DP5.windowed(), t_max=T0, stop_at_exit=False)[1][INFO_WINDOW_START])
    assert lo >= 10, lo
    runs = {T: integrate(chain, gc.DP5.windowed(), t_max=T, stop_at_exit=False) for T in (T1, T2)}
    (_, i1, x1, v1, _), (_, i2, x2, v2, _) = runs[T1], runs[T2]
    assert i1[0] == T1 and i2[0] == T2  # the runs end at T exactly
    assert np.all(np.isfinite(x2)) and np.all(np.isfinite(v2))
    np.testing.assert_array_equal(v1[:lo], v2[:lo])
    np.testing.assert_allclose(x2[:lo] - x1[:lo], v1[:lo] * (T2 - T1), rtol=0, atol=1e-12)
    # negative control: integrated to the end, the same granules are not in free flight
    e1, e2 = (integrate(chain, EXACT, t_max=T, stop_at_exit=False) for T in (T1, T2))
    assert np.abs(e2[2][:lo] - e1[2][:lo] - e1[3][:lo] * (T2 - T1)).max() > 1e-3


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("seed", FAST_SEEDS)
def test_windowed_energy_report_and_momentum(seed, kind):
    """The report is sum m v^2/2 (all granules) + potential of the contacts still integrated at the end
    + the frozen contacts' potential when they left (info[6]); its drift < 1e-4. Momentum: every
    granule keeps its velocity and the cut contact is open, so it is conserved to round-off."""
    chain = chain_of(seed, kind)
    integ = goal_integrators(kind)["windowed"]
    status, info, x, v, _ = integrate(chain, integ)
    assert status == 0
    lo = int(info[INFO_WINDOW_START])
    if kind == "decorated":
        assert lo > 0
    d = x[lo:-1] - x[lo + 1:]
    potential = np.sum(chain.stiffness[lo:] / chain.n * np.clip(d, 0.0, None) ** chain.n)
    energy = 0.5 * np.sum(chain.masses * v * v) + potential + info[INFO_FROZEN_POTENTIAL]
    res = gc.simulate(chain, integ)
    np.testing.assert_array_equal(res.velocities, v)
    assert res.energy_error == pytest.approx((energy - chain.energy) / chain.energy, rel=0, abs=1e-13)
    assert abs(res.energy_error) < 1e-4, res.energy_error
    assert abs(res.momentum_error) < 1e-12, res.momentum_error
    assert abs(float(np.sum(chain.masses * v)) / chain.momentum - 1.0) < 1e-12


def test_energy_errors_of_rows_are_each_runs():
    """``kernels.forces.energy_errors``, the energy balance of rows integrated elsewhere (the GPU backend's final
    states), is each run's own report (``simulate``'s) bitwise: windowed decorated rows (granules behind the trailing window, the
    frozen potential), a precompressed row against a wall (the potential from the static state) and a damped one
    (the dissipated energy). Negative controls: the rows' frozen potentials, static load or dissipated energies
    left out change the balance by far more than its drift."""
    from granchain.backends import final_energy_momentum, history_state
    from granchain.backends.kernels.forces import energy_errors
    from granchain.backends.kernels.records import INFO_DISSIPATED
    from granchain.backends.numba_backend import model_params

    def rows_of(chains, integ):
        runs = [integrate(chain, integ) for chain in chains]
        assert all(status == 0 for status, *_ in runs)
        # each run's report as ``simulate`` makes it (``final_energy_momentum``), E_0 = m_1 v_0^2 / 2
        e0 = [0.5 * chain.masses[0] * chain.initial_velocity * chain.initial_velocity for chain in chains]
        reported = [(final_energy_momentum(chain, x, v, info)[0] - e) / e for chain, e, (_, info, x, v, _) in zip(chains, e0, runs)]
        stack = [np.array([r[k] for r in runs]) for k in (2, 3)]
        info = np.array([r[1] for r in runs])
        return (stack, np.array([c.masses for c in chains]), np.array([c.stiffness for c in chains]),
                info[:, INFO_WINDOW_START].astype(np.int64), info[:, INFO_FROZEN_POTENTIAL], info[:, INFO_DISSIPATED],
                np.array([c.initial_velocity for c in chains]), np.array(reported))

    def balance(chain, rows, frozen=None, dissipated=None):
        (x, v), m, c, lo, fr, di, v0, _ = rows
        out = np.empty(len(v0))
        assert not history_state(chain)
        energy_errors(x, v, m, c, model_params(chain), lo, fr if frozen is None else frozen,
                      di if dissipated is None else dissipated, np.zeros((len(v0), 0)), v0, out)
        return out

    windowed = [chain_of(seed, "decorated") for seed in FAST_SEEDS]
    rows = rows_of(windowed, goal_integrators("decorated")["windowed"])
    assert np.all(rows[3] > 0), "the trailing window did not cut"
    np.testing.assert_array_equal(balance(windowed[0], rows), rows[-1])
    assert np.min(np.abs(balance(windowed[0], rows, frozen=np.zeros(3)) - rows[-1])) > 1e-3

    loaded = [chain_of(seed, "decorated").with_wall().with_precompression(0.01) for seed in FAST_SEEDS]
    rows = rows_of(loaded, gc.RKN4())
    np.testing.assert_array_equal(balance(loaded[0], rows), rows[-1])
    assert np.min(np.abs(balance(loaded[0].with_precompression(0.0), rows) - rows[-1])) > 1e-3  # (no static state)

    damped = [chain_of(seed, "effective").replace(contact=gc.Viscoelastic(0.05)) for seed in FAST_SEEDS]
    rows = rows_of(damped, gc.DP5())
    np.testing.assert_array_equal(balance(damped[0], rows), rows[-1])
    assert np.min(np.abs(balance(damped[0], rows, dissipated=np.zeros(3)) - rows[-1])) > 1e-3


@pytest.mark.parametrize("seed", [1, 4])
def test_a_wall_switches_the_goal_settings_off(seed):
    """The pulse comes back from a wall: relaxed and windowed are bitwise the exact DP5 there."""
    chain = gc.random_decorated(N, seed=seed).with_wall()
    assert chain.wall
    grid = np.arange(0.0, 150.0, 0.5)
    b = gc.simulate(chain, EXACT, t_grid=grid)
    assert b.ok, b.message
    for integ in (gc.DP5.relaxed(), gc.DP5.windowed()):
        a = gc.simulate(chain, integ, t_grid=grid)
        assert a.n_steps == b.n_steps and a.n_rejected == b.n_rejected and a.t_end == b.t_end
        for name in ("peak_velocity", "peak_time", "peak_force", "peak_force_time", "velocity", "wall_force",
                     "positions", "velocities"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
        assert a.energy_error == b.energy_error and a.wall_impulse == b.wall_impulse
        status, info, *_ = integrate(chain, integ)
        assert info[INFO_WINDOW_START] == 0


# -- 6. settings -------------------------------------------------------------------------------------------
@pytest.mark.parametrize("kw, words", [
    (dict(relaxed_lag=0), "relaxed_lag"),
    (dict(window_lag=-1), "window_lag"),
    (dict(window_lag=2.5), "window_lag"),
    (dict(relaxed_factor=0.5), "relaxed_factor"),
    (dict(relaxed_factor=math.nan), "relaxed_factor"),
    (dict(relaxed_lag=7, window_lag=3), "relaxed_lag.*window_lag"),
    (dict(relaxed_lag=3, window_lag=3), "relaxed_lag.*window_lag"),
])
def test_bad_goal_settings_name_the_parameter(kw, words):
    with pytest.raises(ValueError, match=words):
        gc.DP5(**kw)


def test_describe_records_the_goal_settings_only_when_used():
    old_keys = {"name", "rtol", "atol", "first_step", "fixed_step"}  # the record before granchain 0.3
    assert set(gc.DP5().describe()) == set(EXACT.describe()) == old_keys
    windowed = gc.DP5.windowed().describe()
    assert windowed["window_lag"] == WINDOW_LAG and windowed["relaxed_lag"] == RELAXED_LAG
    assert windowed["relaxed_factor"] == RELAXED_FACTOR
    relaxed = gc.DP5.relaxed().describe()
    assert relaxed["window_lag"] is None and relaxed["relaxed_lag"] == RELAXED_LAG
    for integ in (EXACT, gc.DP5.relaxed(), gc.DP5.windowed()):
        assert integrator_from_record(json.loads(json.dumps(integ.describe()))) == integ


def test_store_written_exact_is_resumed_with_the_exact_dp5(tmp_path):
    """A store written with the exact DP5 (an interrupted run: one chunk of two done; then one extended)
    is continued with the integrator its record names, without naming it, to bitwise a fresh run (and
    with integrator=DP5(1e-6, 1e-9) named); another integrator named, today's default, is refused with
    a hint naming the exact DP5."""
    from granchain.ensembles.store import ZarrSink

    family = gc.RandomDecorated(8)
    kw = dict(seed=3, chunk_size=5, progress=False, integrator=gc.DP5(1e-6, 1e-9))
    fresh = gc.run_ensemble(family, realizations=10, **kw)
    store = tmp_path / "interrupted.zarr"
    spec = ens.EnsembleSpec(family, 10, 3, integrator=gc.DP5(1e-6, 1e-9), chunk_size=5)
    sink = ZarrSink(spec, store)
    sink.write(ens.compute_chunk(spec, 1))  # realisations 5..9 only, then "interrupted"
    sink.close()
    stored = json.loads(xr.open_zarr(store).attrs["granchain_integrator"])
    assert set(stored) == {"name", "rtol", "atol", "first_step", "fixed_step"}  # the pre-issue-9 record
    with pytest.raises(ValueError, match=r"DP5\(1e-6, 1e-9\)"):
        gc.run_ensemble(family, realizations=10, out=store, seed=3, chunk_size=5, progress=False,
                        integrator=ens.ensemble_integrator("decorated"))
    assert_same_results(gc.run_ensemble(family, realizations=10, out=store, seed=3, chunk_size=5, progress=False), fresh)
    assert_same_results(gc.run_ensemble(family, realizations=10, out=store, **kw), fresh)
    assert_same_results(xr.open_dataset(store, engine="zarr"), fresh)
    # extended to more realisations with the exact DP5: a fresh run of the larger size
    grown = gc.run_ensemble(family, realizations=20, out=store, **kw)
    assert_same_results(grown, gc.run_ensemble(family, realizations=20, **kw))


# -- 7. property: windowed peaks are the exact DP5's ---------------------------------------------------------
small_radii = hs.integers(8, 20).flatmap(lambda n: hs.lists(hs.floats(0.01, 0.4), min_size=n - 1, max_size=n - 1))


@settings(max_examples=6, deadline=None)
@given(radii=small_radii)
def test_windowed_peaks_equal_exact_on_random_decorated_chains(radii):
    chain = gc.decorated(radii)
    a = gc.simulate(chain, gc.DP5.windowed())
    b = gc.simulate(chain, EXACT)
    assert completed(a) and completed(b)  # (a late hump may end a run still rising: PEAK_AT_END, left out below)
    # out-of-order peaks are chaotic late humps (conftest.in_order): on [0.25, 0.0117, 0.375, 0.031,
    # 0.25, 0.0156, 0.25] granule 7 peaks after granule 8 and the two runs differ there by 1.1e-5
    ok = in_order(b)
    assert ok[:2].all() and ok.sum() >= 0.5 * ok.size, b.peak_time
    np.testing.assert_allclose(a.peak_velocity[ok], b.peak_velocity[ok], rtol=2e-6, atol=0)
    np.testing.assert_allclose(a.peak_time[ok], b.peak_time[ok], rtol=0, atol=2e-5)
    assert abs(a.momentum_error) < 1e-12 and abs(a.energy_error) < 1e-4
