"""The viscous contact law of Rosas, Romero, Nesterenko & Lindenberg (Phys. Rev. Lett. 98, 164301
(2007); Phys. Rev. E 78, 051303 (2008)): F = c delta^(n-1) + gamma d(delta)/dt while two grains touch
(``granchain.Viscous``).

What is checked, and how each check could fail:
(a) two spheres: the coefficient of restitution of the kernels equals an independent two-body solve
    by SciPy's DOP853 written here (1e-9), and for n = 2 the damped oscillator's closed form;
(b) a chain: momentum is conserved to round-off, E_kin + E_pot + E_dissipated = E_0, and the kernels
    agree with the SciPy reference (its own NumPy code of the law) on peaks and dissipated energy;
(c) the authors' two-wave structure: at low viscosity a leading solitary pulse followed by a slower
    secondary pulse (two maxima in a granule's velocity), above a critical viscosity one pulse with a
    single maximum; the elastic chain (negative control) has one pulse and no secondary one;
(d) stores, records and the command line carry the law, and bad input says what to change.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.signal import find_peaks

import granchain as gc
from granchain.model.contacts import Viscous, law_from_record

TIGHT = gc.DP5(rtol=1e-12, atol=1e-14)


def two_body_restitution(gamma, speed, *, n=2.5, mu=0.5, c=1.0, clamp=False):
    """e of two spheres of reduced mass ``mu`` and contact prefactor ``c`` meeting at ``speed``, from
    mu delta'' = -(c delta^(n-1) + gamma delta') integrated by DOP853 from delta = 0, delta' = speed to
    the end of the collision: delta back to 0 (unclamped), or the force reaching 0 (clamped: the grains
    then separate freely). Independent of granchain."""

    def rhs(t, y):
        d, w = y
        f = c * max(d, 0.0) ** (n - 1.0) + gamma * w if d > 0.0 else 0.0
        return [w, -(max(f, 0.0) if clamp else f) / mu]

    def end(t, y):
        if t == 0.0:
            return 1.0
        return c * max(y[0], 0.0) ** (n - 1.0) + gamma * y[1] if clamp else y[0]

    end.terminal, end.direction = True, -1
    sol = solve_ivp(rhs, (0.0, 100.0), [0.0, speed], method="DOP853", rtol=1e-13, atol=1e-16, events=end,
                    first_step=1e-8)
    assert sol.status == 1
    return -sol.y_events[0][0][1] / speed


def kernel_restitution(gamma, speed, *, n=2.5, clamp=False, integrator=TIGHT):
    """e of two unit spheres (masses 1, prefactor 1) run by ``simulate`` (the compiled kernels)."""
    chain = gc.from_radii([1.0, 1.0], n=n, initial_velocity=speed).replace(contact=Viscous(gamma, n, clamp=clamp))
    res = gc.simulate(chain, integrator)
    assert res.ok, res.message
    assert abs(res.momentum_error) < 1e-14
    return (res.velocities[1] - res.velocities[0]) / speed


# -- (a) two spheres -------------------------------------------------------------------------------
@pytest.mark.parametrize("clamp", [False, True])
@pytest.mark.parametrize("gamma, speed", [(0.02, 1.0), (0.1, 1.0), (0.3, 0.5), (0.1, 2.0)])
def test_two_sphere_restitution_is_the_two_body_solution(gamma, speed, clamp):
    """The kernels' e equals the independent two-body solve (measured within 1e-11; tolerance 1e-9).
    It could fail by a damping term scaled by the compression (the Kuwabara-Kono form), a missing
    clamp, or a force left on at the end of the collision."""
    ref = two_body_restitution(gamma, speed, clamp=clamp)
    assert 0.0 < ref < 1.0
    assert kernel_restitution(gamma, speed, clamp=clamp) == pytest.approx(ref, abs=1e-9)


def test_the_clamp_keeps_more_energy():
    """A clamped contact never pulls: the pull at the end of the unclamped collision takes energy the
    clamp leaves in the motion, so e(clamped) > e(unclamped) (and both below 1)."""
    free, clamped = two_body_restitution(0.2, 1.0), two_body_restitution(0.2, 1.0, clamp=True)
    assert free < clamped < 1.0
    assert kernel_restitution(0.2, 1.0) < kernel_restitution(0.2, 1.0, clamp=True)


@pytest.mark.parametrize("gamma", [0.1, 0.5])
def test_linear_viscous_contact_is_the_damped_oscillator(gamma):
    """n = 2: the collision is a damped harmonic oscillator mu delta'' + gamma delta' + c delta = 0,
    delta = (v / w_d) exp(-beta t) sin(w_d t) with beta = gamma / (2 mu), w_d = sqrt(c / mu - beta^2);
    it ends at t = pi / w_d with e = exp(-pi beta / w_d), whatever the speed. The two-body solve gives it
    within 1e-10 and the kernels within 1e-9 (measured 8e-13 and 9e-11)."""
    mu = 0.5
    beta = gamma / (2 * mu)
    exact = math.exp(-math.pi * beta / math.sqrt(1.0 / mu - beta**2))
    assert two_body_restitution(gamma, 1.0, n=2.0) == pytest.approx(exact, abs=1e-10)
    for v in (0.5, 1.0):
        assert kernel_restitution(gamma, v, n=2.0) == pytest.approx(exact, abs=1e-9)


# -- (b) chains ------------------------------------------------------------------------------------
CHAINS = {
    "decorated random": lambda law: gc.random_decorated(8, gc.Uniform(0.1, 0.4), seed=5).replace(contact=law),
    "monodisperse + wall": lambda law: gc.monodisperse(12, wall=True).replace(contact=law),
}


@pytest.mark.parametrize("clamp", [False, True])
@pytest.mark.parametrize("name", list(CHAINS))
def test_energy_balance_and_momentum(name, clamp):
    """E_kin + E_pot + E_dissipated = E_0 (``energy_error``; measured at most 3.6e-8 at the defaults,
    and 3e-13 tight for the authors' law, 2.5e-10 for the clamped one, whose force has a kink where the
    clamp starts) and, without a wall, momentum to round-off. A damping force on the padding after the
    last granule (no contact there) broke momentum by 30 % before it was excluded: the test that caught it."""
    chain = CHAINS[name](Viscous(0.1, clamp=clamp))
    for integrator, tol in [(gc.DP5(), 1e-6), (TIGHT, 1e-9 if clamp else 1e-11)]:
        res = gc.simulate(chain, integrator)
        assert res.ok, res.message
        assert 0.05 < res.dissipated_energy < chain.energy
        assert abs(res.energy_error) < tol
        if not chain.wall:
            assert abs(res.momentum_error) < 1e-13


@pytest.mark.parametrize("clamp", [False, True])
@pytest.mark.parametrize("name", list(CHAINS))
def test_kernels_agree_with_the_scipy_reference(name, clamp):
    """The kernels (DP5) and the SciPy backend (DOP853 on the law's own NumPy force) give the same
    peak velocities, peak times, peak forces and dissipated energy (tolerance 1e-6, the accuracy
    contract; measured: peaks within 1e-12 relative, peak times 1.1e-11, dissipated energy 6.5e-12 for
    the authors' law). The reference shares no force code with the kernels. Tight tolerances: the
    clamped law's dissipated energy converges slowly through the kink where the clamp starts (on the
    decorated chain DP5 at rtol 1e-10 is 4e-6 off; DOP853 at 1e-11, 1e-12 and 1e-13 moves by up to
    2.5e-6, not monotonically; DP5 at 1e-12 and DOP853 at 1e-13 differ by 3.8e-7)."""
    chain = CHAINS[name](Viscous(0.15, clamp=clamp))
    res = gc.simulate(chain, TIGHT)
    ref = gc.simulate(chain, gc.DOP853(rtol=1e-13, atol=1e-15))
    assert res.ok and ref.ok
    np.testing.assert_allclose(res.peak_velocity, ref.peak_velocity, rtol=1e-6)
    np.testing.assert_allclose(res.peak_time, ref.peak_time, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(res.peak_force, ref.peak_force, rtol=1e-6, atol=1e-9)
    assert res.dissipated_energy == pytest.approx(ref.dissipated_energy, rel=1e-6)


def test_viscous_law_is_not_the_kuwabara_kono_law():
    """The same gamma in the two laws damps differently (a check that the law reaches the kernels: the
    two dissipated energies differ by far more than the accuracy contract)."""
    chain = gc.monodisperse(10)
    a = gc.simulate(chain.replace(contact=Viscous(0.1)), gc.DP5())
    b = gc.simulate(chain.replace(contact=gc.Viscoelastic(0.1, clamp=False)), gc.DP5())
    assert abs(a.dissipated_energy - b.dissipated_energy) > 0.05


# -- (c) the two-wave structure --------------------------------------------------------------------
def velocity_maxima(gamma, granule=29, N=80):
    """The local maxima (prominence 2e-4) of granule ``granule``'s velocity in a struck monodisperse
    chain of N granules with the viscous law (gamma = 0: elastic), and that velocity history."""
    grid = np.linspace(0.0, 70.0, 1401)
    chain = gc.monodisperse(N) if gamma == 0 else gc.monodisperse(N).replace(contact=Viscous(gamma))
    with warnings.catch_warnings():  # the run ends at t_max by design (T_MAX): the window of time observed
        warnings.simplefilter("ignore", RuntimeWarning)
        res = gc.simulate(chain, gc.DP5(), t_grid=grid, t_max=grid[-1])
    assert res.t_end == grid[-1]
    v = res.velocity[granule]
    peaks, _ = find_peaks(v, prominence=2e-4)
    return v[peaks], v


def test_two_wave_structure_at_low_viscosity():
    """gamma = 0.02: a primary solitary pulse (measured 0.48 at granule 30) and, behind it, a secondary
    pulse (0.016, prominence 9e-4) after a dip: two maxima. The elastic chain (negative control) has one maximum and the
    granule comes back to rest: the secondary pulse is the damping's."""
    low, _ = velocity_maxima(0.02)
    assert low.size == 2 and low[0] > 10 * low[1] > 0.0
    elastic, v = velocity_maxima(0.0)
    assert elastic.size == 1 and v[-1] < 1e-3 * elastic[0]


@pytest.mark.parametrize("gamma", [0.3, 1.0])
def test_one_non_oscillatory_pulse_above_the_critical_viscosity(gamma):
    """gamma above the crossover (measured between 0.07 and 0.1 at granule 30): one maximum; the
    velocity rises and falls monotonically and never turns negative."""
    peaks, v = velocity_maxima(gamma)
    assert peaks.size == 1
    top = int(np.argmax(v))
    assert np.all(np.diff(v[: top + 1]) >= -1e-12) and np.all(np.diff(v[top:]) <= 1e-12)
    assert v.min() >= -1e-12


# -- (d) records, stores, the command line ----------------------------------------------------------
@pytest.mark.parametrize("law", [Viscous(0.1), Viscous(0.25, 2.0, clamp=True)])
def test_record_round_trip(law):
    assert law_from_record(law.describe()) == law
    assert law.describe()["law"] == "viscous" and (("clamp" in law.describe()) == law.clamp)


def test_ensemble_store_records_and_resumes_the_law(tmp_path):
    """An ensemble of random decorated chains with the viscous law: its store records the law, reads
    back into the same family, holds the dissipated energy, and resumes; asked with the other damping
    law, it refuses."""
    family = gc.RandomDecorated(4, gc.Uniform(0.1, 0.4), contact=Viscous(0.1))
    path = tmp_path / "viscous.nc"
    ds = gc.run_ensemble(family, realizations=6, chunk_size=3, seed=2, out=path, progress=False)
    assert (ds["status"].values == 0).all() and (ds["dissipated_energy"].values > 0).all()
    assert gc.family_from_dataset(ds).contact == family.contact
    more = gc.run_ensemble(family, realizations=9, chunk_size=3, seed=2, out=path, progress=False)
    np.testing.assert_array_equal(more["peak_velocity"].isel(realization=slice(0, 6)).values, ds["peak_velocity"].values)
    other = gc.RandomDecorated(4, gc.Uniform(0.1, 0.4), contact=gc.Viscoelastic(0.1))
    with pytest.raises(ValueError, match="different contact settings"):
        gc.run_ensemble(other, realizations=9, chunk_size=3, seed=2, out=path, progress=False)


def test_pulse_command_line(capsys):
    """``granchain pulse --viscous-damping`` runs the law (its dissipated energy printed) and equals the
    Python API's numbers."""
    from granchain.cli import main

    assert main(["pulse", "--radii", "1,1,1,1,1,1", "--viscous-damping", "0.1"]) == 0
    out = capsys.readouterr().out
    res = gc.simulate(gc.from_radii([1.0] * 6).replace(contact=Viscous(0.1)), gc.DP5())
    assert f"# dissipated energy {res.dissipated_energy:.6g}" in out


@pytest.mark.parametrize("argv, message", [
    (["--viscous-damping", "-0.1"], "must be finite and >= 0"),
    (["--viscous-damping", "nan"], "must be finite"),
    (["--viscous-damping", "0.5kg/s"], "has a unit: give the physical-unit options"),
    (["--viscous-damping", "fast"], "neither a number nor a quantity"),
])
def test_pulse_command_line_refuses_bad_damping(argv, message, capsys):
    from granchain.cli import main

    assert main(["pulse", "--radii", "1,1,1"] + argv) != 0
    assert message in capsys.readouterr().err


def test_command_line_refuses_two_damping_laws(capsys):
    from granchain.cli import main

    with pytest.raises(SystemExit):
        main(["pulse", "--radii", "1,1,1", "--viscous-damping", "0.1", "--dissipation", "0.1"])
    assert "not allowed with argument" in capsys.readouterr().err


@pytest.mark.parametrize("kwargs, message", [
    ({"gamma": -1.0}, "must be finite and >= 0"),
    ({"gamma": float("inf")}, "must be finite and >= 0"),
    ({"gamma": "0.1"}, "must be a number"),
    ({"gamma": 0.1, "n": 1.0}, "exponent n > 1"),
    ({"gamma": 0.1, "clamp": "yes"}, "clamp must be False"),
])
def test_bad_laws_say_what_to_change(kwargs, message):
    with pytest.raises(ValueError, match=message):
        Viscous(**kwargs)


def test_methods_for_conservative_forces_refuse_it():
    chain = gc.monodisperse(5).replace(contact=Viscous(0.1))
    for integrator in (gc.RKN4(), gc.Verlet(dt=1e-3)):
        with pytest.raises(ValueError, match="positions only"):
            gc.simulate(chain, integrator)


# -- (e) designing a protector that dissipates --------------------------------------------------------
def test_design_with_a_viscous_law_reports_what_simulate_gives(tmp_path):
    """``optimize(..., contact=Viscous(0.1))``: every chain of the run, the design and the reference, has
    the law; the reported values are exactly what ``simulate`` (DP5, the default for a law that reads
    velocities) gives for them; damping lowers the wall force of the same design below the elastic one;
    the run is recorded with its law and is not continued with another one."""
    from granchain.design import TaperedSpace, optimize

    law = Viscous(0.1)
    space = TaperedSpace(8, q=(0.0, 0.1))
    res = optimize(space, "wall-force", budget=12, popsize=3, local=None, polish=False, seed=1, contact=law,
                   out=tmp_path / "run")
    assert res.chain.contact == law and res.reference_chain.contact == law
    assert res.integrator.name == "dp5"
    assert res.value == gc.simulate(res.chain, gc.DP5()).peak_wall_force
    assert res.reference_value == gc.simulate(res.reference_chain, gc.DP5()).peak_wall_force
    elastic = gc.simulate(space.chain(res.x), gc.DP5()).peak_wall_force
    assert res.value < 0.9 * elastic
    assert res.to_dict()["contact"] == law.describe()
    with pytest.raises(ValueError, match="other arguments"):
        optimize(space, "wall-force", budget=12, popsize=3, local=None, polish=False, seed=1, contact=Viscous(0.2),
                 out=tmp_path / "run")


def test_design_refuses_a_method_for_conservative_forces_and_another_exponent():
    from granchain.design import BatchEvaluator, TaperedSpace

    space = TaperedSpace(6)
    with pytest.raises(ValueError, match="positions only"):
        BatchEvaluator(space, "wall-force", integrator=gc.RKN4(), contact=Viscous(0.1))
    with pytest.raises(ValueError, match="differs from the design space's n"):
        BatchEvaluator(space, "wall-force", contact=Viscous(0.1, n=3.0))


def test_design_command_line_takes_the_damping_laws(tmp_path, capsys):
    from granchain.cli import main

    assert main(["design", "--size", "6", "--budget", "12", "--popsize", "3", "--local", "none", "--no-polish",
                 "--no-figure", "--quiet", "--viscous-damping", "0.1", "--out", str(tmp_path / "d")]) == 0
    assert "- contacts: viscous gamma = 0.1" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["design", "--out", str(tmp_path / "e"), "--viscous-damping", "0.1", "--dissipation", "0.1"])
