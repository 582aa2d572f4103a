"""Every ``units`` attribute granchain writes parses with pint and with UDUNITS (cf_units), so
pint-xarray's ``quantify()`` and CF readers take granchain's data as they are.

The paper's rescaled quantities are dimensionless numbers (units "1"); what they count is in
``rescaled_quantity`` and ``units_description``, and ``granchain.units.dataset_to_physical``
converts by that attribute (and, for stores written before it existed, by variable name).
"""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

import granchain as gc
from granchain import units
from granchain.ensembles.run import default_time_grid

pint = pytest.importorskip("pint")
pint_xarray = pytest.importorskip("pint_xarray")
cf_units = pytest.importorskip("cf_units")

UREG = pint.UnitRegistry()


def assert_units_parse(ds: xr.Dataset, where: str) -> None:
    """Every numeric variable has a units string; pint and UDUNITS parse each one; quantify() works."""
    for name, var in ds.variables.items():
        if var.dtype.kind not in "iufb":
            assert "units" not in var.attrs, f"{where}: {name} holds strings but has units"
            continue
        if "flag_values" in var.attrs and where == "export":  # CF flag variables carry no units (CF-1.8 Sec. 3.5)
            continue
        assert "units" in var.attrs, f"{where}: {name} has no units attribute"
        text = var.attrs["units"]
        UREG.parse_units(text)  # raises on prose such as "rescaled time (paper Sec. II)"
        cf_units.Unit(text)
        if "rescaled_quantity" in var.attrs:
            assert var.attrs["rescaled_quantity"] in units.RESCALED and var.attrs["units"] == "1"
            assert var.attrs["units_description"] == units.RESCALED[var.attrs["rescaled_quantity"]]
    quantified = ds.pint.quantify()
    for name in ds.data_vars:
        if ds[name].dtype.kind in "iuf" and "units" in ds[name].attrs:
            assert str(quantified[name].pint.units) == "dimensionless", f"{where}: {name}"


@pytest.fixture(scope="module")
def wall_store(tmp_path_factory):
    path = tmp_path_factory.mktemp("units") / "wall.zarr"
    family = gc.RandomRadii(6, gc.Uniform(0.5, 1.0), wall=True)
    gc.run_ensemble(family, realizations=6, seed=1, out=path, progress=False, lags=np.linspace(-2, 2, 9))
    return path


@pytest.fixture(scope="module")
def decorated_store(tmp_path_factory):
    path = tmp_path_factory.mktemp("units") / "decorated.zarr"
    gc.run_ensemble(16, gc.Uniform(0.01, 0.4), 24, 116, "both", t_grid=default_time_grid(16), chunk_size=3, out=path,
                    progress=False)
    return path


def test_the_pattern_rejects_prose():
    """Negative control: the old prose units fail the check this file relies on."""
    with pytest.raises(Exception):
        UREG.parse_units("rescaled time (paper Sec. II)")
    with pytest.raises(Exception):
        cf_units.Unit("V_1 (velocity of the struck granule; rescaled, paper Sec. II)")
    bad = xr.Dataset({"peak_time": ("k", [1.0], {"units": "rescaled time (paper Sec. II)"})})
    with pytest.raises(Exception):
        assert_units_parse(bad, "prose")


@pytest.mark.parametrize("which", ["decorated_store", "wall_store"])
def test_store_groups_parse(request, which):
    path = request.getfixturevalue(which)
    with xr.open_zarr(path, consolidated=False) as ds:
        assert_units_parse(ds, which)
    with xr.open_zarr(path, group="progress", consolidated=False) as prog:
        assert_units_parse(prog, which + "/progress")


def test_netcdf_export_parses(decorated_store, tmp_path):
    pytest.importorskip("netCDF4")
    from granchain.cli.export import export

    nc = tmp_path / "e.nc"
    export(decorated_store, nc)
    with xr.open_dataset(nc) as ds:
        assert_units_parse(ds, "export")


def test_single_run_datasets_parse():
    chain = gc.decorated([0.2, 0.05, 0.3])
    result = gc.simulate(chain, t_grid=np.linspace(0, 10, 21))  # peak forces are always recorded
    assert_units_parse(result.to_dataset(), "simulate")
    wall = gc.simulate(gc.monodisperse(4, wall=True), t_grid=np.linspace(0, 8, 9))
    assert_units_parse(wall.to_dataset(), "simulate with a wall")


def test_figure_datasets_parse(decorated_store):
    from granchain.paper.figures import fig1, fig2, fig3

    with xr.open_zarr(decorated_store, consolidated=False) as ds:
        ds = ds.load()
    assert_units_parse(fig1.compute(ds).to_dataset(), "fig1")
    assert_units_parse(fig2.compute(ds).to_dataset(), "fig2")
    assert_units_parse(fig3.compute(ds).to_dataset(), "fig3")


def test_quantified_store_converts_to_si_by_its_attributes(wall_store):
    """dataset_to_physical converts what the store says it holds: the random radii of RandomRadii
    (kind "radius") become metres, the wall force newtons, times seconds."""
    s = units.scale("steel", "5 mm", "1 m/s")
    with xr.open_zarr(wall_store, consolidated=False) as ds:
        phys = units.dataset_to_physical(ds, s)
        np.testing.assert_allclose(phys["radius_si"].values, ds["radius"].values * 5e-3, rtol=1e-15)
        np.testing.assert_allclose(phys["peak_wall_force_si"].values, ds["peak_wall_force"].values * s.force, rtol=1e-15)
        assert phys["peak_time_si"].attrs["units"] == "s" and phys["peak_wall_force_si"].attrs["units"] == "N"
        q = phys["peak_time_si"].pint.quantify()
        assert q.pint.to("us").values[0, 0, 0] == pytest.approx(ds["peak_time"].values[0, 0, 0] * s.time * 1e6)


def test_stores_from_before_the_attribute_still_convert():
    """A 0.1.0 store (prose units, no rescaled_quantity) converts by the variable names."""
    from pathlib import Path

    old = Path(__file__).parent / "data" / "v0.1.0-decorated-N6.zarr"
    s = units.scale("steel", 5e-3, 1.0)
    with xr.open_dataset(old, engine="zarr") as ds:
        assert "rescaled_quantity" not in ds["peak_time"].attrs
        phys = units.dataset_to_physical(ds, s)
        np.testing.assert_allclose(phys["peak_time_si"].values, ds["peak_time"].values * s.time)
        np.testing.assert_allclose(phys["small_radius_si"].values, ds["small_radius"].values * s.radius)


def test_theory_and_validity_datasets_parse(tmp_path, private_theory_cache):
    from granchain import theory
    from granchain.paper import validity

    pred = theory.predict(gc.Uniform(0.01, 0.4), 6, memory=2, nodes=3, samples=500, profile_windows=50)
    assert_units_parse(pred, "theory")
    assert pred["arrival_time_mean"].attrs["rescaled_quantity"] == "time"
    assert pred["mean_peak_velocity"].attrs["rescaled_quantity"] == "velocity"
    vmap = validity.validity_map(tmp_path / "v", alphas=[0.1], betas=[0.3], n_large=4, realizations=20, blocks=4,
                                 progress=False)
    assert_units_parse(vmap, "validity map")
    with xr.open_dataset(tmp_path / "v" / "validity.nc") as ds:
        assert_units_parse(ds, "validity.nc")
