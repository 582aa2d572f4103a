"""Thornton's elastic-perfectly plastic contact (C. Thornton, J. Appl. Mech. 64, 383 (1997);
``granchain.ElasticPlastic``): Hertz to a limiting contact pressure, then a force linear in the overlap,
Hertzian unloading from each contact's largest overlap (a per-contact history the integration carries).

What is checked, and how each check could fail:
(a) the law's own formulas: the plastic work equals the loading work less the unloading curve's energy,
    both integrated numerically here (an error in c_p or delta_p breaks it); the compiled force equals the
    NumPy force on every branch;
(b) two spheres: the coefficient of restitution of the kernels (DP5) and of the SciPy reference (DOP853,
    switches located as events) equals Thornton's closed form within 1e-5 over v / v_y in [1.1, 1000], is 1
    below yield, and falls as v^(-1/4) (fitted exponent over the top decade within 0.01);
(c) a 20-granule chain with a wall: kernels and reference agree on peaks, wall force and plastic work, and
    kinetic + elastic + plastic = initial within 1e-8 (tight tolerances); the energy check sees a wrong
    history (negative control: the final state's energy with the contacts' histories forgotten is off);
    momentum is conserved without a wall; an enormous yield speed is the elastic chain;
(d) the material's yield speed, precompression below yield, refusals, records, stores and the CLI.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.integrate import quad

import granchain as gc
from granchain.model.contacts import ElasticPlastic, law_from_record

TIGHT = gc.DP5(rtol=1e-12, atol=1e-14)
REFERENCE = gc.DOP853(rtol=1e-12, atol=1e-14)
LAW = ElasticPlastic(1.0)


def restitution(speed, integrator, law=LAW):
    """e of two reference granules (masses 1, prefactor 1) meeting at ``speed``, from their velocities after
    the collision (run to a time well past it: a Hertz collision lasts ~3 v^(-1/5))."""
    chain = gc.Chain(np.array([1.0, 1.0]), np.array([1.0]), 2.5, speed, contact=law)
    res = gc.simulate(chain, integrator, stop="t_max", t_max=30.0 * speed**-0.2)
    assert res.ok, res.message
    assert abs(res.momentum_error) < 1e-13
    return (res.velocities[1] - res.velocities[0]) / speed, res


def test_closed_form_is_one_at_yield_and_falls_as_a_quarter_power():
    """Thornton's e(r), r = v_y / v: 1 at r = 1 (continuous with the elastic branch) and
    sqrt(6 sqrt(3) / 5) (2 sqrt(6/5))^(-1/4) r^(1/4) as r -> 0."""
    assert ElasticPlastic.restitution_ratio(1.0) == 1.0
    assert ElasticPlastic.restitution_ratio(1.0 - 1e-12) == pytest.approx(1.0, abs=1e-9)
    r = 1e-8
    lead = math.sqrt(6.0 * math.sqrt(3.0) / 5.0) * (2.0 * math.sqrt(1.2)) ** -0.25
    assert ElasticPlastic.restitution_ratio(r) == pytest.approx(lead * r**0.25, rel=1e-7)


@pytest.mark.parametrize("m_over_dy", [1.0, 1.3, 4.0, 50.0])
def test_plastic_work_is_loading_work_less_what_unloading_gives_back(m_over_dy):
    """W_p(delta_m) = int_0^delta_m F_load - int_delta_p^delta_m F_unload, both by quadrature of the law's force."""
    c = 1.7
    dy = float(LAW.yield_overlaps(c))
    m = m_over_dy * dy
    loading = quad(lambda d: float(LAW.force(d, c)), 0.0, m, points=[dy], epsabs=1e-15, epsrel=1e-13)[0]
    unloaded = quad(lambda d: float(LAW.force(d, c, history=m)), 0.0, m, epsabs=1e-15, epsrel=1e-13)[0]
    assert float(LAW.plastic_work(m, c)) == pytest.approx(loading - unloaded, rel=1e-9, abs=1e-15)
    # the energy given back from delta_m is the unloading curve's (2/5) c_p (delta_m - delta_p)^(5/2)
    assert float(LAW.stored_energy(m, c, history=m)) == pytest.approx(unloaded, rel=1e-9, abs=1e-15)


def test_compiled_force_is_the_laws_force():
    """forces.plastic_force (kernels) against ElasticPlastic.force (NumPy) on the loading line, the
    unloading curve, below the plastic overlap and on virgin contacts."""
    from numba import njit

    from granchain.backends.kernels.forces import plastic_force as internal

    plastic_force = njit(lambda d, m, c, dy: internal(d, m, c, dy))  # (the kernels' helper has no Python wrapper)
    rng = np.random.default_rng(3)
    for _ in range(200):
        c = rng.uniform(0.3, 2.0)
        dy = float(LAW.yield_overlaps(c)) * rng.uniform(0.5, 2.0)  # (any yield overlap: several materials)
        m = dy * rng.choice([1.0, rng.uniform(1.0, 30.0)])
        d = rng.uniform(-0.1, 1.5) * m
        expected = float(LAW.force(d, c, history=m, yield_overlap=dy))
        assert plastic_force(d, m, c, dy) == pytest.approx(expected, rel=1e-13, abs=1e-300)


RATIOS = [1.1, 1.5, 3.0, 10.0, 30.0, 100.0, 300.0, 1000.0]


@pytest.mark.parametrize("integrator", [gc.DP5(), REFERENCE], ids=["dp5-defaults", "dop853-reference"])
def test_two_sphere_restitution_is_thorntons(integrator):
    """Within 1e-5 of the closed form over v / v_y in [1.1, 1000] (measured: DP5 at its defaults within
    7.3e-7, DOP853 at 1e-12 within 3e-11); below yield 1 within the accuracy contract (1e-6; DP5 at its
    defaults measured 1.1e-8 off, its integration error) with no plastic work at all."""
    for ratio in RATIOS:
        v = ratio * LAW.yield_speed
        e, _ = restitution(v, integrator)
        assert e == pytest.approx(LAW.restitution(v), rel=1e-5), ratio
    for ratio in (0.3, 0.9, 0.999):
        e, res = restitution(ratio * LAW.yield_speed, integrator)
        assert e == pytest.approx(1.0, abs=1e-6)
        assert res.dissipated_energy == 0.0


def test_restitution_falls_as_the_inverse_quarter_power_of_the_speed():
    """The exponent of e vs v fitted over the top decade (v / v_y from 100 to 1000) is -1/4 within 0.01;
    the elastic chain (negative control) has e = 1, exponent 0."""
    v = np.geomspace(100.0, 1000.0, 5) * LAW.yield_speed
    e = np.array([restitution(s, TIGHT)[0] for s in v])
    slope = np.polyfit(np.log(v), np.log(e), 1)[0]
    assert slope == pytest.approx(-0.25, abs=0.01)
    elastic = [restitution(s, TIGHT, law=gc.PowerLaw())[0] for s in v[[0, -1]]]
    assert np.allclose(elastic, 1.0, atol=1e-9)


def wall_chain(law=ElasticPlastic(0.1)):
    rng = np.random.default_rng(1)
    return gc.from_radii(np.r_[1.0, rng.uniform(0.6, 1.4, 19)]).replace(contact=law).with_wall()


def test_kernels_agree_with_the_reference_on_a_chain_with_a_wall():
    """20 granules against a wall, struck at 10 yield speeds: DP5 (the per-contact history in the step loop)
    and DOP853 (its own NumPy law, switches as events) agree on every peak, the wall's peak force and the
    plastic work within the accuracy contract (1e-6; measured ~1e-9 at these tolerances)."""
    chain = wall_chain()
    res = gc.simulate(chain, gc.DP5(rtol=1e-11, atol=1e-13))
    ref = gc.simulate(chain, gc.DOP853(rtol=1e-11, atol=1e-13))
    assert res.ok and ref.ok
    np.testing.assert_allclose(res.peak_velocity, ref.peak_velocity, rtol=1e-6)
    np.testing.assert_allclose(res.peak_time, ref.peak_time, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(res.peak_force, ref.peak_force, rtol=1e-6, atol=1e-9)
    assert res.peak_wall_force == pytest.approx(ref.peak_wall_force, rel=1e-6)
    assert res.dissipated_energy == pytest.approx(ref.dissipated_energy, rel=1e-6)
    # yielding caps the wall force: the elastic chain's is far higher
    elastic = gc.simulate(chain.replace(contact=gc.PowerLaw()), gc.DP5())
    assert res.peak_wall_force < 0.5 * elastic.peak_wall_force


@pytest.mark.parametrize("integrator", [gc.DP5(rtol=1e-11, atol=1e-13), gc.DOP853(rtol=1e-12, atol=1e-14)],
                         ids=["dp5", "dop853"])
def test_energy_balance_with_plastic_work(integrator):
    """kinetic + elastic (the unloading curves through each contact's state) + plastic work = initial within
    1e-8 (measured 2e-10 for DP5, 2.3e-10 for DOP853); most of the energy goes into plastic work here.
    DOP853 runs at rtol 1e-12: it restarts at every branch switch, and at 1e-11 its global error (about
    steps x rtol, 1,197 steps) read 2.5e-9 when this test was written and 1.4e-8 on a later machine, over the
    bound (the same 1.4e-8 there with SciPy 1.16 and 1.17, NumPy 2.4.4 and 2.4.6)."""
    chain = wall_chain()
    res = gc.simulate(chain, integrator)
    assert res.ok, res.message
    assert 0.5 * chain.energy < res.dissipated_energy < chain.energy
    assert abs(res.energy_error) < 1e-8


def test_the_energy_check_sees_a_forgotten_history():
    """Negative control: the final state's energy with every contact's history reset to virgin (the elastic
    energy of Hertz's curve instead of the unloading curves') misses the balance by far more than 1e-8."""
    from granchain.backends import final_energy_momentum, get_backend
    from granchain.backends.kernels.records import INFO_DISSIPATED
    from granchain.solve.simulation import RunControls

    chain = gc.monodisperse(6, wall=True).replace(contact=ElasticPlastic(0.2))
    controls = RunControls(3.0, 10_000_000, 1e-6)
    run = get_backend("numba").run(gc.DP5(rtol=1e-11, atol=1e-13), chain, t_grid=np.zeros(0), t_max=3.0,
                                   stop_at_exit=False, controls=controls)
    info = np.zeros(8)
    info[INFO_DISSIPATED] = run.dissipated_energy
    virgin = chain.contact.yield_overlaps(chain.stiffness)
    right = (run.energy - chain.energy) / chain.energy
    wrong = (final_energy_momentum(chain, run.positions, run.velocities, info, virgin)[0] - chain.energy) / chain.energy
    assert abs(right) < 1e-8
    assert abs(wrong) > 1e-4


def test_momentum_is_conserved_and_a_huge_yield_speed_is_the_elastic_chain():
    chain = gc.random_decorated(6, gc.Uniform(0.1, 0.4), seed=3)
    plastic = gc.simulate(chain.replace(contact=ElasticPlastic(0.05)), gc.DP5())
    assert plastic.ok and abs(plastic.momentum_error) < 1e-13
    assert plastic.dissipated_energy > 0.1 * chain.energy
    never = gc.simulate(chain.replace(contact=ElasticPlastic(1e6)), gc.DP5())
    elastic = gc.simulate(chain, gc.DP5(relaxed_lag=None, window_lag=None))
    assert never.dissipated_energy == 0.0
    np.testing.assert_allclose(never.peak_velocity, elastic.peak_velocity, rtol=1e-12)


def test_precompression_below_yield_and_a_striker():
    """A statically loaded chain below yield starts in equilibrium (granules ahead exactly at rest) and
    balances its energy; a striker yields the first contact; a static load that yields is refused."""
    law = ElasticPlastic(0.2)
    chain = gc.monodisperse(12, wall=True).replace(contact=law).with_precompression(1e-3)
    for integrator in (gc.DP5(rtol=1e-11, atol=1e-13), gc.DOP853(rtol=1e-11, atol=1e-13)):
        res = gc.simulate(chain, integrator, stop="t_max", t_max=40.0)
        assert res.ok and abs(res.energy_error) < 1e-8 and res.dissipated_energy > 0
    struck = gc.simulate(gc.monodisperse(8).replace(contact=law).with_striker(mass=3.0), gc.DP5())
    assert struck.ok and struck.dissipated_energy > 0 and abs(struck.energy_error) < 1e-6
    with pytest.raises(ValueError, match="yields contact"):
        gc.monodisperse(12).replace(contact=ElasticPlastic(0.01)).with_precompression(1.0)


def test_yield_speed_of_a_material():
    """Material.yield_speed from its definition, computed here with Hertz's formulas in SI: two equal spheres
    of radius R first yield when (1/2)(m/2) V^2 = (2/5) K delta_y^(5/2), delta_y = (pi p_y / (2 E*))^2 R / 2,
    K = (4/3) E* (R / 2)^(1/2), whatever R; and the law built from it yields two reference granules there."""
    steel = dataclasses.replace(gc.units.STEEL, yield_stress="1 GPa")
    e_star, p_y = steel.effective_modulus, 1.6e9
    for radius in (1e-3, 1e-2):
        dy = (math.pi * p_y / (2 * e_star)) ** 2 * radius / 2
        k = 4.0 / 3.0 * e_star * math.sqrt(radius / 2)
        m = 4.0 / 3.0 * math.pi * steel.rho * radius**3
        assert steel.yield_speed == pytest.approx(math.sqrt(8.0 / 5.0 * k * dy**2.5 / m), rel=1e-12)
    assert 0.05 < steel.yield_speed < 0.1  # hardened steel on steel: of the order of 0.1 m/s
    law = ElasticPlastic.from_material(steel, "2 m/s")
    assert law.yield_speed == pytest.approx(steel.yield_speed / 2.0)
    e_below, _ = restitution(0.99 * law.yield_speed, gc.DP5(), law=law)
    e_above, _ = restitution(1.2 * law.yield_speed, gc.DP5(), law=law)
    assert e_below == pytest.approx(1.0, abs=1e-6) and e_above < 0.999
    with pytest.raises(ValueError, match="yield_stress"):
        gc.units.STEEL.yield_speed


@pytest.mark.parametrize("bad, match", [
    (dict(yield_speed=0.0), "yield_speed must be finite and > 0"),
    (dict(yield_speed=-1.0), "yield_speed must be finite and > 0"),
    (dict(yield_speed="fast"), "must be a number"),
    (dict(yield_speed=0.1, n=3.0), "n = 5/2"),
])
def test_bad_laws_say_what_to_change(bad, match):
    with pytest.raises(ValueError, match=match):
        ElasticPlastic(**bad)


def test_methods_and_backends_without_the_history_refuse_it():
    """RKN4 and Verlet (methods for x'' = f(x)) refuse a force with memory, saying so (not that it reads
    velocities); a backend that carries no per-contact state refuses the law, naming the reference that runs it.
    The GPU backend carries the histories: it accepts the law with DP5 and refuses it with RKN4, as the CPU does."""
    from granchain.backends import Backend

    chain = gc.monodisperse(5).replace(contact=ElasticPlastic(0.1))
    for integrator in (gc.RKN4(), gc.Verlet(0.001)):
        with pytest.raises(ValueError, match="positions only; the contact law .* remembers each contact's largest overlap"):
            gc.simulate(chain, integrator)

    class Forgetful(Backend):
        name = "forgetful"
        law_forms = None

    with pytest.raises(ValueError, match="carries no per-contact history.*DOP853"):
        Forgetful().check(gc.DP5(), chain)
    Forgetful().check(gc.DP5(), gc.monodisperse(5))  # (negative control: an elastic chain needs no history)
    from granchain.backends.cuda import CudaBackend

    gpu = CudaBackend.__new__(CudaBackend)  # (its checks only: no GPU needed)
    CudaBackend.check(gpu, gc.DP5(), chain)
    with pytest.raises(ValueError, match="positions only"):
        CudaBackend.check(gpu, gc.RKN4(), chain)


def test_record_family_store_and_resume(tmp_path):
    """The law's record rebuilds it; an ensemble of a family with yielding contacts records the law, stores
    the plastic work per realisation (both chains: decorated and effective) and refuses to be resumed with
    another yield speed."""
    import json

    import xarray as xr

    law = ElasticPlastic(0.15)
    assert law_from_record(law.describe()) == law
    assert "elastic-plastic" in law.label()
    out = str(tmp_path / "plastic.zarr")
    ds = gc.run_ensemble(gc.RandomDecorated(5, contact=law), realizations=6, chunk_size=3, out=out, progress=False)
    assert np.all(ds["status"].values == 0)
    assert np.all(ds["dissipated_energy"].values > 0)
    assert np.all(np.abs(ds["energy_error"].values) < 1e-5)
    with xr.open_dataset(out, engine="zarr") as stored:
        model = json.loads(stored.attrs["granchain_contact_model"])
        assert model["law"] == "elastic-plastic" and model["yield_speed"] == 0.15
    with pytest.raises(ValueError, match="yield_speed"):
        gc.run_ensemble(gc.RandomDecorated(5, contact=ElasticPlastic(0.3)), realizations=6, chunk_size=3, out=out,
                        progress=False)


def test_cli_pulse_yield_speed(capsys):
    from granchain.cli import main

    assert main(["pulse", "--radii", "1,1,1,1,1,1", "--wall", "--yield-speed", "0.1"]) in (0, None)
    out = capsys.readouterr().out
    assert "plastic work" in out
    assert main(["pulse", "--radii", "1,1,1,1", "--yield-speed", "0.05m/s", "--material", "steel", "--radius", "5mm",
                 "--impact-speed", "1m/s"]) in (0, None)
    with pytest.raises(SystemExit):  # one contact law at a time
        main(["pulse", "--radii", "1,1,1", "--yield-speed", "0.1", "--dissipation", "0.1"])
    assert main(["pulse", "--radii", "1,1,1", "--yield-speed", "-1"]) == 2
    assert "--yield-speed must be > 0" in capsys.readouterr().err


def test_error_control_keeps_the_contract_across_the_kinks():
    """DP5 lets steps straddle the yield point (where the force is C^1) and reloading past a contact's history
    (a kink in the force law); only the turn from loading to unloading ends a step. The error control keeps the
    contract there: against the event-located reference, the plastic chain's peak errors shrink with the
    tolerance as the elastic chain's do (measured at rtol 1e-8: 2.1e-6 vs 4.6e-7 elastic; at 1e-10: 1.5e-8
    vs 2.0e-8)."""
    chain = wall_chain()
    errors = {}
    for law in (gc.PowerLaw(), ElasticPlastic(0.1)):
        ref = gc.simulate(chain.replace(contact=law), gc.DOP853(rtol=1e-12, atol=1e-14))
        for rtol in (1e-8, 1e-10):
            res = gc.simulate(chain.replace(contact=law), gc.DP5(rtol=rtol, atol=rtol * 1e-2))
            errors[law.history, rtol] = np.max(np.abs(res.peak_velocity / ref.peak_velocity - 1))
    assert errors[True, 1e-10] < 1e-7
    assert errors[True, 1e-10] < errors[True, 1e-8] / 10
    assert errors[True, 1e-8] < 10 * errors[False, 1e-8]


def test_several_materials_yield_at_their_own_pressure():
    """A chain of steel and brass beads against a rigid wall: each contact's yield overlap equals
    R* (pi p / (2 E*))^2 in SI units (p the softer material's limiting pressure, E* the pair's modulus),
    computed here with Hertz's formulas and divided by the length unit of the chain's rescaling; kernels and
    reference agree on the run, and the energy balances. A material without a yield stress is refused with the
    reason; so is a two-material design space (its batches carry no materials)."""
    from granchain import design

    steel = dataclasses.replace(gc.units.STEEL, yield_stress="1.5 GPa")
    brass = dataclasses.replace(gc.units.BRASS, yield_stress="0.4 GPa")
    radius, speed = 2.5e-3, 2.0
    law = ElasticPlastic.from_material(steel, speed)
    radii = np.array([1.0, 0.8, 1.0, 0.6, 1.2, 1.0])
    mats = [steel, brass, steel, brass, brass, steel]
    chain = gc.from_radii(radii, materials=mats).with_wall(material="rigid").replace(contact=law)
    unit = gc.units.scale(steel, radius, speed).length
    expected = []
    for k in range(len(radii)):
        a = mats[k]
        if k + 1 < len(radii):
            b = mats[k + 1]
            r_star = radius * radii[k] * radii[k + 1] / (radii[k] + radii[k + 1])
            e_star = 1.0 / ((1 - a.nu**2) / a.E + (1 - b.nu**2) / b.E)
            p = 1.6 * min(a.yield_stress, b.yield_stress)
        else:  # the rigid wall: R* = R, E* = E / (1 - nu^2), only the sphere yields
            r_star, e_star, p = radius * radii[k], a.E / (1 - a.nu**2), 1.6 * a.yield_stress
        expected.append(r_star * (math.pi * p / (2 * e_star)) ** 2 / unit)
    np.testing.assert_allclose(chain.yield_overlaps(), expected, rtol=1e-10)
    res = gc.simulate(chain, gc.DP5(rtol=1e-11, atol=1e-13))
    ref = gc.simulate(chain, gc.DOP853(rtol=1e-11, atol=1e-13))
    assert res.ok and ref.ok and res.dissipated_energy > 0.1 * chain.energy
    assert abs(res.energy_error) < 1e-8 and abs(ref.energy_error) < 1e-8
    np.testing.assert_allclose(res.peak_velocity, ref.peak_velocity, rtol=1e-6)
    assert res.dissipated_energy == pytest.approx(ref.dissipated_energy, rel=1e-6)
    # one material given as materials= is the one-material chain, bit for bit
    one = gc.from_radii(radii, materials=steel).replace(contact=law)
    np.testing.assert_array_equal(one.yield_overlaps(), law.yield_overlaps(one.stiffness))
    with pytest.raises(ValueError, match="yield stress"):
        gc.from_radii(np.ones(4), materials=["steel", "ptfe", "steel", "steel"]).replace(contact=law)
    with pytest.raises(ValueError, match="one material"):
        design.BatchEvaluator(design.BinarySpace(6, (1.0, 1.0), materials=("steel", "ptfe")), "wall-force", contact=law)
