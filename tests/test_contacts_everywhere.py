"""Real contacts everywhere a chain goes: families, ensembles, stores, the command line, units.

The physics of the contact laws is validated in ``test_real_contacts.py``; here, that the settings
travel: a family's rows are bitwise the single chains ``simulate`` integrates, the store records the
contact model and refuses to resume with other settings (naming them), bad input is refused before
anything is written, and the CLI's physical quantities convert to the rescaled ones.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import xarray as xr

import granchain as gc
from granchain.cli import main
from granchain.model.collision import restitution

GAMMA = 0.05
VARIANTS = {
    "dissipative": {"contact": gc.Viscoelastic(GAMMA)},
    "precompressed": {"static_force": 0.1},
    "striker": {"striker_mass": 3.0},
    "combined": {"contact": gc.Viscoelastic(GAMMA), "static_force": 0.1, "striker_mass": 3.0, "wall": True},
}
FAMILIES = {
    "decorated": lambda **kw: gc.RandomDecorated(5, **kw),
    "tapered": lambda **kw: gc.TaperedDecorated(5, q=0.1, **kw),
    "polydisperse": lambda **kw: gc.RandomRadii(6, gc.Uniform(0.6, 1.2), **kw),
    "binary": lambda **kw: gc.BinaryRandom(6, (1.0, 0.5), 0.5, **kw),
}


@pytest.mark.parametrize("variant", sorted(VARIANTS))
@pytest.mark.parametrize("family_name", sorted(FAMILIES))
def test_family_rows_are_the_single_chains(family_name, variant):
    """Row r of an ensemble is bitwise ``simulate(family.chain(seed, r))`` with the same integrator: the
    batch builders (striker column, static load, law) and the single-chain builders (``with_striker``,
    ``replace``) make the same arrays, and the batch kernel passes the model to the same step loop.
    Fails if either side drops or reorders a setting (a striker's stiffness from another radius, the
    static force missing in the batch, the law's damping not reaching the kernels)."""
    family = FAMILIES[family_name](**VARIANTS[variant])
    ds = gc.run_ensemble(family, realizations=4, chunk_size=2, seed=3, progress=False)
    for chain_name in family.chains:
        integ = gc.ensemble_integrator(chain_name, conservative=family.contact_law.conservative)
        for r in (0, 3):
            chain = family.chain(3, r, chain_name)
            row = ds.sel(chain=chain_name).isel(realization=r)
            # on the ensemble's grid: a run ends no earlier than the grid's end (a precompressed one at the
            # later of its grid's end and the time that bounds the pulse's crossing)
            res = gc.simulate(chain, integ, t_grid=ds["time"].values)
            np.testing.assert_array_equal(row["t_end"].values, res.t_end)
            np.testing.assert_array_equal(row["peak_velocity"].values, res.peak_velocity)
            np.testing.assert_array_equal(row["peak_time"].values, res.peak_time)
            assert int(row["status"]) == 0
            assert float(row["energy_error"]) == res.energy_error


def test_family_records_round_trip_and_default_records_unchanged():
    """The store's family record carries the real contacts (so that a resumed store is rebuilt with
    them) and a family of the paper's chains keeps the record it had (so its stores resume)."""
    for kw in VARIANTS.values():
        fam = gc.RandomDecorated(5, **kw)
        assert gc.family_from_record(fam.describe()) == fam
    plain = gc.RandomDecorated(5)
    assert set(plain.describe()) == {"family", "n_large", "distribution", "n", "momentum_conserving"}
    # the paper's law given explicitly is the default, recorded as such
    assert gc.RandomDecorated(5, contact=gc.PowerLaw(2.5)).describe() == plain.describe()


def test_dissipative_family_defaults_to_dp5_and_refuses_rkn4_before_writing(tmp_path):
    """A viscoelastic law depends on velocities: RKN4 (x'' = f(x)) cannot integrate it. The ensemble's
    default is then DP5, and RKN4 asked for explicitly is refused before a store exists."""
    fam = gc.RandomDecorated(5, contact=gc.Viscoelastic(GAMMA))
    spec = gc.EnsembleSpec(fam, realizations=2)
    assert {i.name for i in spec.chain_integrators.values()} == {"dp5"}
    assert gc.EnsembleSpec(gc.RandomDecorated(5)).chain_integrators["decorated"].name == "rkn4"
    out = tmp_path / "refused.zarr"
    with pytest.raises(ValueError, match="depends on velocities: use DP5"):
        gc.run_ensemble(fam, realizations=2, integrator=gc.RKN4(), out=str(out), progress=False)
    assert not out.exists()


def test_store_records_the_contact_model_and_refuses_other_settings(tmp_path):
    """The store says which contacts it holds (``granchain_contact_model``) and a resume with other
    contact settings is refused, naming the settings that differ; a store of the paper's chains has no
    such attribute (its metadata are those of earlier versions)."""
    out = str(tmp_path / "store.zarr")
    fam = gc.RandomDecorated(5, contact=gc.Viscoelastic(GAMMA), static_force=0.1)
    gc.run_ensemble(fam, realizations=4, chunk_size=2, out=out, progress=False)
    with xr.open_dataset(out, engine="zarr") as ds:
        model = json.loads(ds.attrs["granchain_contact_model"])
        assert model == {"law": "viscoelastic", "n": 2.5, "gamma": GAMMA, "static_force": 0.1, "striker_mass": None}
        assert "precompressed" in json.loads(ds.attrs["granchain_integrator_as_run"])["decorated"]["goal_control"]
    other = gc.RandomDecorated(5, contact=gc.Viscoelastic(2 * GAMMA), static_force=0.1)
    with pytest.raises(ValueError, match=r"family\.contact\.gamma: stored 0\.05, asked 0\.1"):
        gc.run_ensemble(other, realizations=4, chunk_size=2, out=out, progress=False)
    with pytest.raises(ValueError, match=r"family\.static_force: stored 0\.1, asked None"):
        gc.run_ensemble(gc.RandomDecorated(5, contact=gc.Viscoelastic(GAMMA)), realizations=4, chunk_size=2, out=out,
                        progress=False)
    ds = gc.run_ensemble(fam, realizations=4, chunk_size=2, out=out, progress=False)  # the same settings resume
    assert int((ds["status"] == 0).sum()) == 8
    plain = str(tmp_path / "plain.zarr")
    gc.run_ensemble(gc.RandomDecorated(5), realizations=2, out=plain, progress=False)
    with xr.open_dataset(plain, engine="zarr") as ds:
        assert "granchain_contact_model" not in ds.attrs


@pytest.mark.parametrize("kw, words", [
    ({"static_force": -1.0}, "static force F0 must be finite and >= 0"),
    ({"static_force": float("nan")}, "static force F0 must be finite"),
    ({"striker_mass": 0.0}, "striker_mass must be > 0"),
    ({"contact": gc.Viscoelastic(0.1, n=3.0)}, "differs from the family's n"),
    ({"contact": "viscous"}, r"must be a contact law \(granchain.PowerLaw, granchain.Viscoelastic"),
])
def test_family_bad_contact_settings_say_what_to_change(kw, words):
    with pytest.raises(ValueError, match=words):
        gc.RandomDecorated(5, **kw)


def test_precompressed_ensembles_run_to_a_time_and_succeed():
    """A precompressed chain has no exit (its contacts stay closed): the batch runs to the time that
    bounds the pulse's crossing, and succeeds there (status 0), instead of reporting T_MAX."""
    fam = gc.RandomDecorated(5, static_force=0.2)
    ds = gc.run_ensemble(fam, realizations=3, chunk_size=3, progress=False)
    assert (ds["status"].values == 0).all()
    t_end = ds["t_end"].values
    assert np.all(t_end >= float(ds["time"][-1]))  # not before the grid's end


# -- the command line ---------------------------------------------------------------------------------
def test_cli_pulse_real_contacts_json_is_simulate(capsys):
    """``granchain pulse`` with every real-contact option gives what the Python API gives for the same
    chain (the options are read into the same values), and reports the contact model."""
    argv = ["pulse", "--radii", "1,1,1,1,1,1", "--wall", "--restitution", "0.9@1", "--precompression", "0.05",
            "--striker-mass", "2", "--json"]
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    chain = (gc.from_radii(np.ones(6), wall=True).with_striker(mass=2.0)
             .with_dissipation(restitution=0.9, speed=1.0).with_precompression(0.05))
    res = gc.simulate(chain)
    np.testing.assert_array_equal(out["peak_velocity"], res.peak_velocity)
    assert out["wall"]["peak_force"] == res.peak_wall_force
    assert out["contact_model"]["initial"] == "striker" and out["contact_model"]["static_force"] == 0.05
    assert out["dissipated_energy"] == res.dissipated_energy > 0
    assert restitution(out["contact_model"]["gamma"], 1.0) == pytest.approx(0.9, abs=1e-10)


def test_cli_pulse_physical_quantities_convert_to_rescaled(capsys):
    """'2N', '1g', '0.9@0.5m/s' are converted with the scale of --material/--radius/--impact-speed: the same
    chain as the rescaled values scale.to_rescaled gives."""
    units = ["--material", "stainless-steel", "--radius", "2.38mm", "--impact-speed", "0.5m/s"]
    argv = ["pulse", "--radii", "1,1,1,1,1", *units, "--static-force", "2N", "--restitution", "0.9@0.5m/s",
            "--striker-mass", "1g", "--json"]
    assert main(argv) == 0
    model = json.loads(capsys.readouterr().out)["contact_model"]
    s = gc.units.scale("stainless-steel", "2.38mm", "0.5m/s")
    assert model["static_force"] == pytest.approx(s.to_rescaled("2 N", "force"), rel=1e-14)
    assert model["striker_mass"] == pytest.approx(s.to_rescaled("1 g", "mass"), rel=1e-14)
    assert model["gamma"] == pytest.approx(gc.Viscoelastic.from_restitution(0.9, 1.0).gamma, rel=1e-12)


@pytest.mark.parametrize("args, words", [
    (["--dissipation", "0.1", "--integrator", "rkn4"], "depends on velocities: use DP5"),
    (["--dissipation", "0.1", "--integrator", "verlet", "--dt", "0.001"], "depends on velocities"),
    (["--restitution", "1.2@1"], r"must lie in \(0, 1\]"),
    (["--restitution", "0.9"], "E@V"),
    (["--precompression", "-1"], "must be finite and >= 0"),
    (["--precompression", "2N"], "has a unit: give the physical-unit options"),
    (["--striker-mass", "0"], "must be > 0"),
    (["--dissipation", "-0.1"], "must be finite and >= 0"),
    (["--wall-material", "steel"], "needs --wall"),
    (["--precompression", "0.1", "--n", "1.0"], "n > 1"),
])
def test_cli_pulse_bad_contact_options(args, words, capsys):
    assert main(["pulse", "--radii", "1,1,1,1", *args]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert __import__("re").search(words, err), err


def test_cli_ensemble_refuses_before_writing_and_info_names_the_contacts(tmp_path, capsys):
    """A refused option writes nothing; a store made with real contacts is described by ``granchain info``."""
    bad = tmp_path / "bad.zarr"
    assert main(["ensemble", "--large", "5", "--realizations", "2", "--dissipation", "0.1", "--integrator", "rkn4",
                 "--out", str(bad), "--quiet"]) == 2
    assert not bad.exists()
    assert main(["ensemble", "--large", "5", "--realizations", "2", "--restitution", "1.5@1", "--out", str(bad), "--quiet"]) == 2
    assert not bad.exists()
    capsys.readouterr()
    good = tmp_path / "good.zarr"
    assert main(["ensemble", "--large", "5", "--realizations", "4", "--chunk-size", "2", "--dissipation", "0.05",
                 "--precompression", "0.1", "--striker-mass", "2", "--out", str(good), "--quiet"]) == 0
    assert main(["info", str(good)]) == 0
    text = capsys.readouterr().out
    assert "contacts     viscoelastic gamma = 0.05, precompressed by F0 = 0.1, struck by a striker of mass 2" in text


def test_materials_and_elastic_walls_reduce_to_one_material():
    """One material given per granule (and a wall of it) is the one-material chain bitwise (the ratio of
    effective moduli is exactly 1); a second material changes the masses by the density ratio and the
    contacts by Hertz's effective modulus of the pair (K. L. Johnson, Contact Mechanics, Sec. 4.2)."""
    r = np.array([1.0, 0.7, 1.2, 0.9])
    steel = gc.units.STEEL
    one = gc.from_radii(r, materials=[steel] * 4, wall=True)
    plain = gc.from_radii(r, wall=True)
    np.testing.assert_array_equal(one.masses, plain.masses)
    np.testing.assert_array_equal(one.stiffness, plain.stiffness)
    ptfe = gc.units.PTFE
    mixed = gc.from_radii(r, materials=[steel, ptfe, steel, ptfe], wall_material="rigid")
    assert mixed.masses[1] == pytest.approx(ptfe.rho / steel.rho * 0.7**3, rel=1e-14)
    e_ref = steel.E / (2 * (1 - steel.nu**2))
    e_pair = 1.0 / ((1 - steel.nu**2) / steel.E + (1 - ptfe.nu**2) / ptfe.E)
    assert mixed.stiffness[0] == pytest.approx(e_pair / e_ref * gc.sphere_stiffness(r[:2])[0], rel=1e-14)
    # an infinitely stiff ("rigid") wall against the last (PTFE) granule: E* = E / (1 - nu^2)
    e_wall = ptfe.E / (1 - ptfe.nu**2)
    assert mixed.stiffness[-1] == pytest.approx(e_wall / e_ref * np.sqrt(2 * 0.9), rel=1e-14)
    with pytest.raises(ValueError, match="one material per granule"):
        gc.from_radii(r, materials=[steel, ptfe])


def test_dissipative_store_holds_the_dissipated_energy(tmp_path):
    """A viscoelastic family's store holds each realisation's dissipated energy, equal to ``simulate``'s
    (bitwise: the same kernel and bookkeeping), and positive; every granule is integrated to the end
    (no trailing window: a dropped granule would stop dissipating), so the run has no averaged-pulse
    windows; an elastic family's store has no such variable (its schema is unchanged)."""
    fam = gc.RandomDecorated(5, contact=gc.Viscoelastic(GAMMA))
    out = str(tmp_path / "d.zarr")
    ds = gc.run_ensemble(fam, realizations=3, chunk_size=2, chains="decorated", out=out, progress=False)
    res = gc.simulate(fam.chain(0, 2), gc.ensemble_integrator("decorated", conservative=False), t_grid=ds["time"].values)
    with xr.open_dataset(out, engine="zarr") as stored:
        d = stored["dissipated_energy"].sel(chain="decorated").values
        assert stored["dissipated_energy"].attrs["units"] == "1"
    assert d[2] == res.dissipated_energy and np.all(d > 0)
    assert gc.ensemble_integrator("decorated", conservative=False).window_lag is None
    assert "pulse_window" not in json.loads(ds.attrs["granchain_parameters"])
    plain = gc.run_ensemble(gc.RandomDecorated(5), realizations=2, progress=False)
    assert "dissipated_energy" not in plain
