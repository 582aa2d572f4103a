"""A fixed wall at the far end (issue 12, item 2): a last granule of infinite mass.

1. the representation: only the last granule may be infinitely heavy, it is never observed, its
   contact stiffness is sqrt(2 R) (the limit of Eq. r-prime), builders and effective chains;
2. exact results: one granule bouncing off the wall (closed-form peak force, impulse 2 m v);
3. a monodisperse (and a decorated) chain against the wall: the peak wall force agrees with DOP853,
   energy is conserved, the granule next to the wall leaves it with the reflected pulse, the wall's
   impulse is the time integral of the wall force;
4. families with ``wall=True``: records, rows bitwise ``simulate``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import granchain as gc
from granchain import bca


# -- 1. representation ----------------------------------------------------------------------------
def test_wall_is_a_last_granule_of_infinite_mass():
    free = gc.from_radii([1.0, 0.5, 0.8])
    walled = gc.from_radii([1.0, 0.5, 0.8], wall=True)
    assert walled.wall and not free.wall and walled.size == 4
    assert walled.masses[-1] == math.inf and walled.radii[-1] == math.inf
    np.testing.assert_array_equal(walled.masses[:-1], free.masses)
    np.testing.assert_array_equal(walled.stiffness[:-1], free.stiffness)
    assert walled.stiffness[-1] == math.sqrt(2 * 0.8)
    # the limit of Eq. (r-prime) for R_{k+1} -> infinity
    big = gc.sphere_stiffness(np.array([0.8, 1e12]))[0]
    assert big == pytest.approx(walled.stiffness[-1], rel=1e-11)
    np.testing.assert_array_equal(walled.observed, [0, 1, 2])  # the wall is not observed
    np.testing.assert_array_equal(free.with_wall().masses, walled.masses)
    np.testing.assert_array_equal(free.with_wall().stiffness, walled.stiffness)


@pytest.mark.parametrize("masses, words", [
    ([1.0, np.inf, 1.0], "only the last granule may be infinitely heavy"),
    ([np.inf, np.inf], "only the last granule"),
    ([1.0, np.nan], "finite"),
])
def test_only_the_last_granule_may_be_a_wall(masses, words):
    with pytest.raises(ValueError, match=words):
        gc.Chain(masses, np.ones(len(masses) - 1))


def test_the_wall_cannot_be_observed_and_walls_do_not_stack():
    with pytest.raises(ValueError, match="the wall"):
        gc.Chain([1.0, 1.0, np.inf], [1.0, 1.0], observed=[0, 2])
    with pytest.raises(ValueError, match="already ends in a wall"):
        gc.monodisperse(3, wall=True).with_wall()
    with pytest.raises(ValueError, match="stiffness"):
        gc.Chain([1.0, 2.0], [1.0]).with_wall()  # no radii: say which stiffness


def test_decorated_and_effective_chains_with_a_wall():
    dec = gc.decorated([0.2, 0.3], wall=True)
    assert dec.size == 6 and dec.wall
    np.testing.assert_array_equal(dec.observed, [0, 2, 4])
    eff = gc.effective(dec)
    free_eff = gc.effective(gc.decorated([0.2, 0.3]))
    assert eff.wall and eff.size == 4
    np.testing.assert_array_equal(eff.masses[:-1], free_eff.masses)
    np.testing.assert_array_equal(eff.stiffness[:-1], free_eff.stiffness)
    assert eff.stiffness[-1] == dec.stiffness[-1] == math.sqrt(2.0)  # large granule N touches the wall


# -- 2. one granule and a wall ---------------------------------------------------------------------
@pytest.mark.parametrize("m, c, n, v", [(1.0, math.sqrt(2.0), 2.5, 1.0), (0.3, 0.7, 2.0, 1.4), (2.0, 1.1, 3.2, 0.6)])
@pytest.mark.parametrize("integrator", [gc.DP5(), gc.DOP853()], ids=["dp5", "dop853"])
def test_one_granule_bounces_off_the_wall(m, c, n, v, integrator):
    """Reduced mass m (the wall is infinitely heavy): (1/2) m v^2 = (c/n) delta^n, F = c delta^(n-1);
    the granule comes back with -v and the wall took the impulse 2 m v."""
    res = gc.simulate(gc.Chain([m, np.inf], [c], n, v), integrator)
    assert res.ok
    delta = (n * m * v * v / (2 * c)) ** (1 / n)
    assert res.peak_wall_force == pytest.approx(c * delta ** (n - 1), rel=1e-8)
    assert res.peak_wall_force == res.peak_force[-1]
    assert res.peak_wall_force_time == pytest.approx(float(bca.time_to_max_compression(m, c, v, n)), abs=1e-7)
    # The end state carries the error of the steps across the contact's opening (a kink of the
    # force): ~1e-7 for DP5 at its defaults, within the accuracy contract (1e-6).
    assert res.velocities[0] == pytest.approx(-v, rel=1e-6)
    assert res.wall_impulse == pytest.approx(2 * m * v, rel=1e-6)
    assert abs(res.energy_error) < 1e-6
    assert math.isnan(res.momentum_error)  # not conserved with a wall: see wall_impulse


# -- 3. chains against the wall --------------------------------------------------------------------
@pytest.fixture(scope="module")
def monodisperse_runs():
    chain = gc.monodisperse(12, wall=True)
    grid = np.linspace(0.0, 60.0, 30001)
    return chain, gc.simulate(chain, t_grid=grid), gc.simulate(chain, "dop853", t_grid=grid), gc.simulate(gc.monodisperse(12))


def test_monodisperse_wall_force_agrees_with_dop853(monodisperse_runs):
    chain, res, ref, free = monodisperse_runs
    assert res.ok and ref.ok
    assert res.peak_wall_force == pytest.approx(ref.peak_wall_force, rel=1e-6)
    assert res.peak_wall_force_time == pytest.approx(ref.peak_wall_force_time, abs=1e-6)
    np.testing.assert_allclose(res.peak_force, ref.peak_force, rtol=1e-6)
    np.testing.assert_allclose(res.wall_force, ref.wall_force, rtol=1e-6, atol=1e-8)
    # The wall pushes back: its peak force clearly exceeds the solitary wave's contact force.
    assert res.peak_wall_force > 1.3 * free.peak_force[5]


def test_monodisperse_wall_conserves_energy_and_reflects_the_pulse(monodisperse_runs):
    chain, res, ref, _ = monodisperse_runs
    assert abs(res.energy_error) < 1e-7 and abs(ref.energy_error) < 1e-7
    # the granule next to the wall ends moving away from it, the wall contact open
    assert res.velocities[-2] < 0 and res.positions[-2] - res.positions[-1] <= 0
    # the pulse came back: the struck granule ends moving backwards, most of the momentum reversed
    assert res.velocities[0] < 0
    assert res.wall_impulse > 1.5 * chain.momentum
    # the run stopped by the wall rule (not at t_max) exit_margin after the release
    assert res.t_end < 100 and res.exit_time > res.peak_wall_force_time


def test_wall_impulse_is_the_integral_of_the_wall_force(monodisperse_runs):
    _, res, _, _ = monodisperse_runs
    assert res.wall_force[-1] == 0.0  # the contact is over before the grid ends
    assert np.trapezoid(res.wall_force, res.t_grid) == pytest.approx(res.wall_impulse, rel=1e-6)


def test_decorated_chain_against_a_wall_agrees_with_dop853():
    chain = gc.random_decorated(6, seed=2, realization=1).with_wall()
    res, ref = gc.simulate(chain), gc.simulate(chain, "dop853")
    assert res.ok and ref.ok
    assert res.peak_wall_force == pytest.approx(ref.peak_wall_force, rel=1e-6)
    assert res.peak_wall_force_time == pytest.approx(ref.peak_wall_force_time, abs=1e-5)
    assert abs(res.energy_error) < 1e-7
    assert res.velocities[-2] < 0


def test_verlet_runs_chains_with_a_wall():
    chain = gc.monodisperse(8, wall=True)
    ref = gc.simulate(chain, "dop853")
    res = gc.simulate(chain, gc.Verlet(1e-3))
    assert res.ok
    assert res.peak_wall_force == pytest.approx(ref.peak_wall_force, rel=1e-5)
    assert abs(res.energy_error) < 1e-5


# -- 4. families ------------------------------------------------------------------------------------
def test_family_wall_option_is_recorded_and_rebuilt():
    fam = gc.RandomRadii(6, gc.Uniform(0.6, 1.0), wall=True)
    record = fam.describe()
    assert record["wall"] is True
    assert gc.family_from_record(record) == fam
    assert "wall" not in gc.RandomRadii(6, gc.Uniform(0.6, 1.0)).describe()  # free-end records as before
    assert "wall" in fam.label()
    chain = fam.chain(3, 2)
    assert chain.wall and chain.size == 7
    with pytest.raises(ValueError, match="wall"):
        gc.RandomDecorated(5, wall="yes")


def test_wall_family_ensemble_rows_are_simulate():
    fam = gc.RandomDecorated(5, wall=True)
    ds = gc.run_ensemble(fam, realizations=4, seed=9, chunk_size=3, progress=False)
    assert (ds["status"] == 0).all()
    assert ds.attrs["granchain_family"].count('"wall": true') == 1
    from granchain.ensembles.run import ensemble_integrator

    for name in fam.chains:
        res = gc.simulate(fam.chain(9, 3, name), ensemble_integrator(name), t_grid=ds["time"].values)
        row = ds.sel(chain=name).isel(realization=3)
        np.testing.assert_array_equal(row["peak_velocity"].values, res.peak_velocity)
        assert float(row["peak_wall_force"]) == res.peak_wall_force
        assert float(row["energy_error"]) == res.energy_error


# -- 5. the command line -----------------------------------------------------------------------------
def test_cli_pulse_wall_json_is_simulate(capsys):
    import json

    from granchain.cli import main

    assert main(["pulse", "--radii", "1,1,1,1", "--wall", "--forces", "--json", "--material", "steel",
                 "--radius", "5mm", "--impact-speed", "1m/s"]) == 0
    data = json.loads(capsys.readouterr().out)
    res = gc.simulate(gc.monodisperse(4, wall=True))
    assert data["wall"]["peak_force"] == res.peak_wall_force and data["wall"]["impulse"] == res.wall_impulse
    np.testing.assert_array_equal(data["peak_force"], res.peak_force)
    s = gc.units.scale(gc.units.STEEL, 5e-3, 1.0)
    assert data["physical"]["peak_wall_force_N"] == pytest.approx(res.peak_wall_force * s.force, rel=1e-14)
    np.testing.assert_allclose(data["physical"]["peak_force_N"], res.peak_force * s.force, rtol=1e-14)


def test_cli_ensemble_wall_and_units(tmp_path, capsys):
    import xarray as xr

    from granchain.cli import main

    store = tmp_path / "w.zarr"
    assert main(["ensemble", "--family", "polydisperse", "--size", "5", "--wall", "--realizations", "3", "--chunk-size", "2",
                 "--out", str(store), "--material", "steel", "--radius", "5mm", "--impact-speed", "1m/s"]) == 0
    out = capsys.readouterr().out
    assert "peak wall force" in out and " N" in out
    ds = xr.open_dataset(store, engine="zarr")
    api = gc.run_ensemble(gc.RandomRadii(5, gc.Uniform(0.5, 1.0), wall=True), realizations=3, chunk_size=2, progress=False)
    np.testing.assert_array_equal(ds["peak_wall_force"].values, api["peak_wall_force"].values)
    s = gc.units.scale(gc.units.STEEL, 5e-3, 1.0)
    assert ds.attrs["physical_force_unit_N"] == pytest.approx(s.force, rel=1e-15)


@pytest.mark.parametrize("make", [gc.RKN4.relaxed, gc.DP5.windowed])
def test_a_wall_that_switches_goal_control_off_says_so(make):
    """A fixed wall sends the pulse back through the granules behind the front, so the relaxed zone and
    the trailing window are switched off there (the results are the exact method's, bitwise). The
    result must then say so: its integrator record has no goal-oriented zones and names why, in the
    Dataset and the table; the free chain's record (negative control) keeps its zones and says nothing."""
    import json

    integ = make()
    chain = gc.random_decorated(5, gc.Uniform(0.01, 0.4), seed=2)
    walled = gc.simulate(chain.with_wall(), integ)
    exact = gc.simulate(chain.with_wall(), type(integ)(integ.rtol, integ.atol))
    np.testing.assert_array_equal(walled.peak_velocity, exact.peak_velocity)
    record = walled.integrator_record
    assert record["name"] == integ.name and "fixed wall" in record["goal_control"]
    assert record.get("relaxed_lag") is None and record.get("window_lag") is None
    assert json.loads(walled.to_dataset().attrs["integrator_record"]) == record
    assert "goal-oriented error control off: the chain ends in a fixed wall" in walled.table()
    free = gc.simulate(chain, integ)
    assert "goal_control" not in free.integrator_record and free.integrator_record == integ.describe()
    assert "goal-oriented" not in free.table()


def test_a_walled_store_records_the_integrators_as_they_ran(tmp_path):
    """An ensemble of chains against a wall stores, next to the integrators asked for, the ones that
    ran (goal control off, and why); a free family's store records them unchanged."""
    import json

    fam = gc.RandomDecorated(4, gc.Uniform(0.01, 0.4), wall=True)
    ds = gc.run_ensemble(fam, realizations=2, chunk_size=2, seed=1, progress=False, out=tmp_path / "w.zarr")
    asked = json.loads(ds.attrs["granchain_integrator"])
    ran = json.loads(ds.attrs["granchain_integrator_as_run"])
    assert set(ran) == {"decorated", "effective"}
    assert asked.get("relaxed_lag") is not None  # the ensemble default asks for a relaxed zone ...
    for record in ran.values():  # ... which the wall switched off
        assert record.get("relaxed_lag") is None and "fixed wall" in record["goal_control"]
    free = gc.run_ensemble(gc.RandomDecorated(4, gc.Uniform(0.01, 0.4)), realizations=2, chunk_size=2, seed=1,
                           progress=False, out=tmp_path / "f.zarr")
    assert all("goal_control" not in r for r in json.loads(free.attrs["granchain_integrator_as_run"]).values())


def test_the_old_name_of_the_fixed_wall_still_works_and_warns():
    """"Rigid" means only an infinitely stiff wall material; the boundary, an immovable wall of any
    material, is FixedWall, and its old name RigidWall warns."""
    import granchain.model as model
    from granchain.model import contacts

    with pytest.warns(DeprecationWarning, match="FixedWall"):
        assert contacts.RigidWall is contacts.FixedWall
    with pytest.warns(DeprecationWarning, match="FixedWall"):
        assert model.RigidWall is contacts.FixedWall
    assert isinstance(gc.monodisperse(4, wall=True).boundary, contacts.FixedWall)
    assert "fixed wall" in contacts.FixedWall.why_no_goal_control and "rigid" not in contacts.FixedWall.why_no_goal_control
