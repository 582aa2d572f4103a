"""Peak contact forces (issue 12, item 2).

1. two-body collisions: the peak force and its time equal their closed forms
   (energy (1/2) M_red v^2 = (c/n) delta_max^n, F_max = c delta_max^(n-1));
2. agreement with SciPy's DOP853 at rtol 1e-10 to 1e-6 (relative force, absolute time) on
   random decorated chains and their effective chains;
3. Verlet's peak forces converge at order 2;
4. ensembles record forces bitwise equal to ``simulate`` of the same chain, on the family's
   ``contact`` dimension, and the store describes them;
5. the velocity peaks did not change (forces are extra).
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

import granchain as gc
from granchain import bca
from granchain.ensembles import run as ens

SEED = 5


def _two_body_closed_form(m1, m2, c, n, v):
    """delta_max from (1/2) M_red v^2 = (c/n) delta_max^n; F_max = c delta_max^(n-1)."""
    m_red = m1 * m2 / (m1 + m2)
    delta = (n * m_red * v * v / (2.0 * c)) ** (1.0 / n)
    return c * delta ** (n - 1.0), float(bca.time_to_max_compression(m_red, c, v, n))


# -- 1. two bodies --------------------------------------------------------------------------------
@pytest.mark.parametrize("m1, m2, c, n, v", [
    (1.0, 1.0, 1.0, 2.5, 1.0),      # Hertz fast path
    (1.0, 0.001, 0.2, 2.5, 1.0),    # a light granule (decorated-chain mass ratio)
    (2.0, 0.5, 3.0, 2.0, 0.7),      # linear contact (fast path)
    (1.0, 3.0, 0.8, 3.1, 1.3),      # general exponent
])
@pytest.mark.parametrize("integrator", [gc.DP5(), gc.DOP853()], ids=["dp5", "dop853"])
def test_two_body_peak_force_is_the_closed_form(m1, m2, c, n, v, integrator):
    chain = gc.Chain([m1, m2], [c], n, v)
    res = gc.simulate(chain, integrator)
    assert res.ok
    f_max, t_max = _two_body_closed_form(m1, m2, c, n, v)
    assert res.peak_force.shape == (1,)
    assert res.peak_force[0] == pytest.approx(f_max, rel=1e-8)
    assert res.peak_force_time[0] == pytest.approx(t_max, abs=1e-7)


def test_two_body_negative_control():
    """The closed form with the mass of one body instead of the reduced mass is far off: the test can fail."""
    res = gc.simulate(gc.Chain([1.0, 1.0], [1.0], 2.5, 1.0))
    wrong = 1.0 * (2.5 * 1.0 / 2.0) ** (1.5 / 2.5)
    assert abs(res.peak_force[0] / wrong - 1) > 0.1


# -- 2. against DOP853 ------------------------------------------------------------------------------
def _chains():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gc.EffectiveValidityWarning)
        for i in range(3):
            ch = gc.random_decorated(10, seed=SEED, realization=i)
            yield f"decorated-{i}", ch
            yield f"effective-{i}", gc.effective(ch)


@pytest.fixture(scope="module")
def dop853_runs():
    return {key: (ch, gc.simulate(ch, "dop853")) for key, ch in _chains()}


def test_peak_forces_agree_with_dop853(dop853_runs):
    """Forces within 1e-6 (relative) with simulate's default DP5. Peak times: within 1e-5 with the
    default (measured worst 2.6e-6, a contact of a light granule, whose relative velocity
    carries the light granule's error) and within 1e-6 at DP5 rtol 1e-10."""
    worst_f = worst_t = worst_t_tight = 0.0
    for key, (ch, ref) in dop853_runs.items():
        res = gc.simulate(ch)
        tight = gc.simulate(ch, gc.DP5(rtol=1e-10, atol=1e-12))
        assert res.ok and ref.ok, key
        assert res.peak_force.shape == (ch.size - 1,) == ref.peak_force.shape
        assert np.all(ref.peak_force > 0), key  # every contact closed as the pulse passed
        worst_f = max(worst_f, np.max(np.abs(res.peak_force / ref.peak_force - 1)))
        worst_t = max(worst_t, np.max(np.abs(res.peak_force_time - ref.peak_force_time)))
        worst_t_tight = max(worst_t_tight, np.max(np.abs(tight.peak_force_time - ref.peak_force_time)))
    assert worst_f < 1e-6, worst_f
    assert worst_t < 1e-5, worst_t
    assert worst_t_tight < 1e-6, worst_t_tight


def test_located_peak_is_the_maximum_of_the_sampled_force():
    """The wall force is sampled on t_grid: the located peak bounds every sample and equals the
    grid maximum to second order in the grid spacing (a negative control for the root search)."""
    grid = np.linspace(0.0, 6.0, 6001)
    res = gc.simulate(gc.from_radii([1.0, 0.3, 1.0], wall=True), t_grid=grid, stop="t_max", t_max=6.0)
    assert res.ok
    assert res.peak_wall_force >= res.wall_force.max() * (1 - 1e-12)
    assert res.peak_wall_force == pytest.approx(res.wall_force.max(), rel=1e-5)
    assert res.peak_wall_force_time == pytest.approx(grid[int(np.argmax(res.wall_force))], abs=1e-3)


# -- 3. Verlet converges at order 2 -------------------------------------------------------------------
def test_verlet_peak_forces_converge_at_order_two():
    chain = gc.from_radii([1.0, 0.5, 1.0, 0.7, 1.0, 0.4, 1.0])
    ref = gc.simulate(chain, gc.DOP853())
    errors = []
    steps = (4e-3, 2e-3, 1e-3)
    for dt in steps:
        res = gc.simulate(chain, gc.Verlet(dt))
        errors.append(np.max(np.abs(res.peak_force / ref.peak_force - 1)))
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all((orders > 1.7) & (orders < 2.4)), (errors, orders)


# -- 4. ensembles --------------------------------------------------------------------------------
FAMILIES = {
    "decorated": lambda: gc.RandomDecorated(5),
    "tapered": lambda: gc.TaperedDecorated(5, q=0.1, distribution=gc.Uniform(0.05, 0.35)),
    "polydisperse": lambda: gc.RandomRadii(6, gc.Uniform(0.5, 1.0)),
    "binary-wall": lambda: gc.BinaryRandom(6, (1.0, 0.6), 0.4, wall=True),
    "decorated-wall": lambda: gc.RandomDecorated(5, wall=True),
    "custom-chain": lambda: gc.CustomFamily(lambda rng: gc.Chain(np.ones(5), rng.uniform(0.5, 1.5, 4), observed=[0, 2, 4]),
                                            name="springs"),
}


@pytest.mark.parametrize("key", FAMILIES)
def test_ensemble_forces_are_simulate_bitwise(key):
    family = FAMILIES[key]()
    ds = gc.run_ensemble(family, realizations=6, seed=SEED, chunk_size=4, progress=False)
    assert ds["peak_force"].dims == ("chain", "realization", "contact")
    assert ds.sizes["contact"] == family.n_contacts
    np.testing.assert_array_equal(ds["contact"].values, family.contact_coordinate()[0])
    assert ("peak_wall_force" in ds) == family.wall
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gc.EffectiveValidityWarning)
        for name in family.chains:
            for i in (0, 5):
                chain = family.chain(SEED, i, name)
                res = gc.simulate(chain, ens.ensemble_integrator(name), t_grid=ds["time"].values)
                row = ds.sel(chain=name).isel(realization=i)
                contacts = family.build(family.draw_batch(SEED, [i]), name).recorded_contacts()
                assert contacts.size == family.n_contacts
                np.testing.assert_array_equal(row["peak_force"].values, res.peak_force[contacts])
                np.testing.assert_array_equal(row["peak_force_time"].values, res.peak_force_time[contacts])
                if family.wall:
                    assert float(row["peak_wall_force"]) == res.peak_wall_force
                    assert float(row["peak_wall_force_time"]) == res.peak_wall_force_time
                    assert contacts.max() < chain.size - 2  # the wall's contact is stored apart


def test_decorated_contact_dimension_is_the_contact_right_of_each_large_granule():
    family = gc.RandomDecorated(4)
    params = family.draw_batch(0, [0])
    np.testing.assert_array_equal(family.build(params, "decorated").recorded_contacts(), [0, 2, 4])  # large k - small k
    np.testing.assert_array_equal(family.build(params, "effective").recorded_contacts(), [0, 1, 2])  # k - k+1
    assert "right of large granule q" in family.contact_coordinate()[1]


def test_store_describes_the_forces(tmp_path):
    import xarray as xr

    ds = gc.run_ensemble(gc.RandomDecorated(4, wall=True), realizations=3, seed=1, chunk_size=2, progress=False,
                         out=tmp_path / "w.zarr")
    disk = xr.open_dataset(tmp_path / "w.zarr", engine="zarr")
    for name in ("peak_force", "peak_force_time", "peak_wall_force", "peak_wall_force_time"):
        assert disk[name].attrs["units"] and disk[name].attrs["long_name"], name
        np.testing.assert_array_equal(disk[name].values, ds[name].values)
    assert "right of large granule" in disk["contact"].attrs["long_name"]
    s = gc.units.scale(gc.units.STEEL, 5e-3, 1.0)
    phys = gc.units.dataset_to_physical(disk, s)
    np.testing.assert_allclose(phys["peak_force_si"].values, disk["peak_force"].values * s.force, rtol=1e-15)
    np.testing.assert_allclose(phys["peak_wall_force_time_si"].values, disk["peak_wall_force_time"].values * s.time, rtol=1e-15)
    assert phys["peak_wall_force_si"].attrs["units"] == "N"


# -- 5. the pulse itself is unchanged ---------------------------------------------------------------
def test_simulate_result_carries_forces_per_contact():
    chain = gc.decorated([0.2, 0.3, 0.1])
    res = gc.simulate(chain, t_grid=np.linspace(0, 10, 11))
    ds = res.to_dataset()
    assert ds["peak_force"].dims == ("contact",) and ds.sizes["contact"] == chain.size - 1
    np.testing.assert_array_equal(ds["peak_force"].values, res.peak_force)
    assert res.peak_wall_force is None and res.wall_force is None and math.isfinite(res.momentum_error)
    # forces increase where the pulse is strong: the struck contact closes first
    assert res.peak_force_time[0] == res.peak_force_time.min()
