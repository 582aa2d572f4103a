"""A chain's physics as one value (granchain.ChainModel): families carry it as their ``model`` field, the
keywords stay as sugar with the same chains, records and results, a record gives it back, and a single
chain built with it is the family's chain bitwise."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as hs

import granchain as gc
from granchain.backends import batch_chain
from granchain.families import family_from_record

LAWS = {"paper": None, "viscous": gc.Viscous(0.1), "viscoelastic": gc.Viscoelastic(0.05),
        "plastic": gc.ElasticPlastic(0.5)}


def _families(**keywords):
    """One family of each registered kind with the real contacts ``keywords`` (model= or its parts)."""
    return {"decorated": gc.RandomDecorated(4, **keywords),
            "tapered": gc.TaperedDecorated(4, q=0.1, **keywords),
            "polydisperse": gc.RandomRadii(5, gc.Uniform(0.8, 1.2), **keywords),
            "binary": gc.BinaryRandom(5, (1.0, 0.6), 0.5, **keywords)}


def _keywords(model: gc.ChainModel) -> dict:
    return {"contact": model.contact, "static_force": model.static_force, "striker_mass": model.striker_mass,
            "wall": model.wall}


MODELS = [gc.ChainModel(), gc.ChainModel(gc.Viscous(0.1), wall=True), gc.ChainModel(static_force=0.01, striker_mass=2.0),
          gc.ChainModel(gc.ElasticPlastic(0.5), striker_mass=0.5, wall=True)]


@pytest.mark.parametrize("model", MODELS, ids=["paper", "viscous-wall", "loaded-striker", "plastic-striker-wall"])
def test_model_and_keywords_make_the_same_family(model):
    """family(model=m) and family(its parts as keywords) are one family: the same model, record, label,
    batch arrays and single chains (bitwise)."""
    by_model, by_keywords = _families(model=model), _families(**_keywords(model))
    for kind, fam in by_model.items():
        other = by_keywords[kind]
        assert fam == other and fam.model == other.model == model.for_exponent(fam.n)
        assert fam.describe() == other.describe() and fam.label() == other.label()
        assert (fam.wall, fam.contact, fam.static_force, fam.striker_mass) == (model.wall, model.contact, model.static_force,
                                                                                model.striker_mass)
        params = fam.draw_batch(3, range(4))
        for chain in fam.chains:
            a, b = fam.build(params, chain), other.build(params, chain)
            assert np.array_equal(a.masses, b.masses) and np.array_equal(a.stiffness, b.stiffness)
        assert np.array_equal(fam.chain(3, 2).masses, other.chain(3, 2).masses)
        assert fam.chain(3, 2).model == fam.model  # the family's chain carries the family's model


@pytest.mark.parametrize("model", MODELS[1:], ids=["viscous-wall", "loaded-striker", "plastic-striker-wall"])
def test_a_store_record_gives_the_model_back(model):
    """The family rebuilt from its record has the same model; the paper's chain writes no model keys (its
    stores resume unchanged), every other model only the parts that differ from the paper's."""
    for fam in _families(model=model).values():
        back = family_from_record(fam.describe())
        assert back == fam and back.model == fam.model
        assert gc.ChainModel.from_record(fam.describe()) == fam.model
    paper = gc.RandomDecorated(4)
    assert paper.model == gc.ChainModel() and paper.model.record() == {}
    assert set(paper.describe()) == {"family", "n_large", "distribution", "n", "momentum_conserving"}


@settings(max_examples=40, deadline=None)
@given(law=hs.sampled_from(sorted(LAWS)), load=hs.sampled_from([0.0, 1e-3, 0.05]),
       striker=hs.sampled_from([None, 0.3, 4.0]), wall=hs.booleans())
def test_any_model_round_trips(law, load, striker, wall):
    """Whatever its parts, a model given to a family comes back from the family's record, and its label
    names every part that differs from the paper's chain."""
    if LAWS[law] is not None and LAWS[law].history and load > 0:
        load = 0.0  # a static load that yields a contact is refused (tested with the law)
    model = gc.ChainModel(LAWS[law], load, striker, wall)
    fam = gc.RandomDecorated(4, model=model)
    assert gc.ChainModel.from_record(fam.describe()) == fam.model == model
    label = fam.model.label()
    assert ("against a fixed wall" in label) == wall and ("striker" in label) == (striker is not None)
    assert ("precompressed" in label) == (load > 0)
    assert (label == "") == (model.elastic and not wall) == (fam.describe() == gc.RandomDecorated(4).describe())


@settings(max_examples=24, deadline=None)
@given(load=hs.sampled_from([0.0, 1e-3, 0.05]), striker=hs.sampled_from([None, 2.0]), wall=hs.booleans(),
       seed=hs.integers(0, 50))
def test_the_models_far_end_and_exit_rule_are_its_chains(load, striker, wall, seed):
    """The family's model says which far end its chains have and whether their runs can end at the
    pulse's exit, as each chain built from it does (one rule for both: ``conditions.far_end``): a wall;
    else a loaded end under a static load, else a free one; no exit under a static load, wall or not."""
    model = gc.ChainModel(None, load, striker, wall)
    for fam in _families(model=model).values():
        chain = fam.chain(seed, 0, fam.chains[0])
        assert type(chain.boundary) is model.boundary
        assert chain.ends_at_exit == model.ends_at_exit == (load == 0.0)
        assert chain.precompression.applied == model.precompression.applied == (load > 0.0)
    expected = gc.model.FixedWall if wall else (gc.model.LoadedEnd if load > 0 else gc.model.FreeEnd)
    assert model.boundary is expected
    assert model.boundary.licenses_goal_control == (not wall and load == 0.0)


def test_a_keyword_that_contradicts_the_model_is_refused():
    model = gc.ChainModel(gc.Viscous(0.1), static_force=0.01)
    with pytest.raises(ValueError, match="contact both in model= and as keywords"):
        gc.RandomDecorated(4, model=model, contact=gc.Viscous(0.2))
    with pytest.raises(ValueError, match="static_force"):
        gc.RandomRadii(5, gc.Uniform(0.8, 1.2), model=model, static_force=0.02)
    # the same value twice is one value
    assert gc.RandomDecorated(4, model=model, contact=gc.Viscous(0.1)) == gc.RandomDecorated(4, model=model)
    with pytest.raises(ValueError, match="must be a granchain.ChainModel"):
        gc.RandomDecorated(4, model={"contact": gc.Viscous(0.1)})
    with pytest.raises(ValueError, match="exponent"):
        gc.RandomDecorated(4, n=3.0, model=gc.ChainModel(gc.Viscous(0.1)))  # the law's n is 2.5
    with pytest.raises(ValueError, match="striker_mass"):
        gc.ChainModel(striker_mass=-1.0)
    with pytest.raises(ValueError, match="wall must be True or False"):
        gc.ChainModel(wall="yes")


def test_a_chain_with_the_model_is_the_family_chain():
    """decorated(radii).with_model(m) is the family's realisation with that model: the same arrays,
    contacts and, integrated, the same peaks to the bit."""
    model = gc.ChainModel(gc.Viscous(0.1), striker_mass=2.0, wall=True)
    fam = gc.RandomDecorated(4, model=model)
    ref = fam.chain(7, 1)
    plain = gc.RandomDecorated(4).chain(7, 1)
    built = plain.with_model(model)
    assert np.array_equal(built.masses, ref.masses) and np.array_equal(built.stiffness, ref.stiffness)
    assert built.model == ref.model == model and built.contact == ref.contact
    a, b = gc.simulate(built), gc.simulate(ref)
    assert np.array_equal(a.peak_velocity, b.peak_velocity) and np.array_equal(a.peak_time, b.peak_time)
    assert plain.with_model(gc.ChainModel()).model == gc.ChainModel()
    with pytest.raises(ValueError, match="starts from the paper's chain"):
        built.with_model(model)
    with pytest.raises(ValueError, match="ends in a wall and the model has none"):
        plain.with_wall().with_model(gc.ChainModel(gc.Viscous(0.1)))


def test_backends_take_the_model_as_a_value_or_the_old_dict():
    """A row's chain from the model value and from the dict of Chain keywords that backends took before."""
    fam = gc.RandomDecorated(4, model=gc.ChainModel(gc.Viscous(0.1), static_force=0.01, striker_mass=2.0))
    batch = fam.build(fam.draw_batch(0, range(2)), "decorated")
    rows = [batch_chain(batch.masses[0], batch.stiffness[0], batch.n, batch.initial_velocity[0], batch.observed, m)
            for m in (fam.model, fam.model.chain_keywords(fam.n))]
    assert rows[0].model == rows[1].model == fam.model
    assert np.array_equal(rows[0].masses, fam.chain(0, 0).masses)


def test_an_ensemble_runs_the_model_it_is_given():
    """An ensemble of a family given model= integrates each realisation with the model's law: its peaks and
    dissipated energies are those of simulate on the family's chain (bitwise), and its peaks differ from the
    elastic family's (negative control)."""
    model = gc.ChainModel(gc.Viscous(0.2))
    fam = gc.RandomDecorated(4, model=model)
    integ = gc.DP5(1e-8, 1e-10)
    ds = gc.run_ensemble(fam, realizations=3, seed=5, chains="decorated", integrator=integ, progress=False)
    ds = ds.sel(chain="decorated")
    for i in range(3):
        ref = gc.simulate(fam.chain(5, i), integ, t_grid=ds["time"].values)  # (the run lasts to the grid's end)
        assert np.array_equal(ds["peak_velocity"].values[i], ref.peak_velocity)
        assert ds["dissipated_energy"].values[i] == ref.dissipated_energy > 0
    elastic = gc.run_ensemble(gc.RandomDecorated(4), realizations=3, seed=5, chains="decorated", integrator=integ,
                              progress=False)
    assert np.all(elastic["peak_velocity"].sel(chain="decorated").values[:, -1] > ds["peak_velocity"].values[:, -1])
