"""Validity maps (issue 13): physics of the map, bitwise reproducibility, resuming, netCDF, figure, CLI;
the Mixture distribution; the aligned pulse the ensembles can accumulate."""

from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest
import xarray as xr
from scipy import stats

import granchain as gc
from granchain.model.distributions import distribution_from_record
from granchain.paper import validity

SMALL = dict(alphas=(0.01,), betas=(0.2, 0.4, 0.9), n_large=(6,), realizations=60, blocks=5, seed=11, progress=False)


def _data(ds):
    """The map without its creation time (everything else must be bitwise equal)."""
    out = ds.copy()
    out.attrs = {k: v for k, v in ds.attrs.items() if k != "created"}
    return out


@pytest.fixture(scope="module")
def small_map(tmp_path_factory):
    out = tmp_path_factory.mktemp("map")
    return out, validity.validity_map(out, **SMALL)


# -- physics of the map ------------------------------------------------------------------------------
def test_effective_error_grows_with_beta_and_is_below_1_percent_at_the_papers_range(small_map):
    _, ds = small_map
    for name in ("arrival_time_error_effective", "averaged_pulse_peak_error_effective"):
        v = ds[name].sel(alpha=0.01, n_large=6).values
        e = ds[name + "_stderr"].sel(alpha=0.01, n_large=6).values
        assert np.all(np.isfinite(v)) and np.all(e > 0), name
        # monotone within its errors (2 sigma), and the growth from 0.2 to 0.9 is significant
        for j in range(v.size - 1):
            assert v[j + 1] > v[j] - 2 * math.hypot(e[j], e[j + 1]), (name, v, e)
        assert v[-1] - v[0] > 3 * math.hypot(e[0], e[-1]), (name, v, e)
    p = ds.sel(alpha=0.01, beta=0.4, n_large=6)
    assert abs(float(p["arrival_time_error_effective"])) + 2 * float(p["arrival_time_error_effective_stderr"]) < 0.01
    # beyond 0.4 the EffectiveValidityWarning is recorded, not raised
    assert list(ds["beyond_effective_validity"].sel(alpha=0.01, n_large=6).values) == [0, 0, 1]
    assert int(ds["valid_realizations"].sel(alpha=0.01, beta=0.4, n_large=6)) == 60


def test_map_measures_match_a_direct_computation(small_map):
    """The map's numbers are the paired ensemble's: recompute two of them from the point's store."""
    out, ds = small_map
    point = xr.open_zarr(out / "points" / "N6_alpha0.01_beta0.4.zarr").load()
    t = point["peak_time"].sel(granule=5)
    td, te = t.sel(chain="decorated").values, t.sel(chain="effective").values
    p = ds.sel(alpha=0.01, beta=0.4, n_large=6)
    assert float(p["arrival_time_error_effective"]) == pytest.approx(te.mean() / td.mean() - 1.0, rel=1e-12)
    assert float(p["arrival_time_ks_effective"]) == pytest.approx(stats.ks_2samp(te, td).statistic, rel=1e-12)
    assert float(p["arrival_time_iqr_error_effective"]) == pytest.approx(stats.iqr(te) / stats.iqr(td) - 1.0, rel=1e-9)
    from granchain import analysis

    pk_d = analysis.averaged_pulse_peak(point, "decorated").velocity
    pk_e = analysis.averaged_pulse_peak(point, "effective").velocity
    rel = pk_e[1:5] / pk_d[1:5] - 1.0
    assert float(p["averaged_pulse_peak_error_effective"]) == pytest.approx(rel[np.argmax(np.abs(rel))], rel=1e-9)
    # BCA: Eq. (total-time) on the point's radii
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gc.EffectiveValidityWarning)
        tb = gc.bca.arrival_times(point["small_radius"].values)[:, 4]
    assert float(p["arrival_time_error_bca"]) == pytest.approx(tb.mean() / td.mean() - 1.0, rel=1e-12)


# -- reproducible, resumable ---------------------------------------------------------------------------
def test_map_is_bitwise_reproducible_and_resumable(small_map, tmp_path):
    out, ds = small_map
    again = validity.validity_map(tmp_path / "fresh", **SMALL)
    xr.testing.assert_identical(_data(again), _data(ds))
    # a partial map (one beta) completed later gives the same map
    part = tmp_path / "partial"
    validity.validity_map(part, **{**SMALL, "betas": (0.4,)})
    # and an interrupted point: undo chunk 2 of one store, as if the run had stopped there
    store = part / "points" / "N6_alpha0.01_beta0.4.zarr"
    xr.Dataset({"done": (("chunk",), np.zeros(1, dtype=np.int8))}).to_zarr(
        store, group="progress", region={"chunk": slice(2, 3)}, mode="r+", consolidated=False, zarr_format=2)
    done = xr.open_zarr(store, group="progress", consolidated=False)["done"].values
    assert list(done) == [1, 1, 0, 1, 1]
    completed = validity.validity_map(part, **SMALL)
    xr.testing.assert_identical(_data(completed), _data(ds))
    # negative control: another seed gives other numbers
    other = validity.validity_map(tmp_path / "other", **{**SMALL, "betas": (0.4,), "seed": 12})
    assert float(other["arrival_time_error_effective"].sel(beta=0.4, alpha=0.01, n_large=6)) != \
        float(ds["arrival_time_error_effective"].sel(beta=0.4, alpha=0.01, n_large=6))


def test_point_seed_depends_only_on_its_parameters():
    d = gc.Uniform(0.01, 0.4).describe()
    assert validity.point_seed(0, 6, d) == validity.point_seed(0, 6, d)
    assert len({validity.point_seed(0, 6, d), validity.point_seed(1, 6, d), validity.point_seed(0, 26, d),
                validity.point_seed(0, 6, gc.Uniform(0.01, 0.5).describe())}) == 4


def test_netcdf_holds_the_map(small_map):
    out, ds = small_map
    back = xr.open_dataset(out / "validity.nc")
    assert set(back.dims) == {"alpha", "beta", "n_large"}
    for name in validity.MEASURES:
        np.testing.assert_array_equal(back[name].values, ds[name].values)
        assert back[name].attrs["long_name"] and back[name + "_stderr"].attrs["units"]


def test_invalid_parameters_say_what_to_change(tmp_path):
    with pytest.raises(ValueError, match="betas <= 1"):
        validity.validity_map(tmp_path, alphas=(0.01,), betas=(1.2,), n_large=(6,), realizations=10, blocks=2, progress=False)
    with pytest.raises(ValueError, match="blocks"):
        validity.validity_map(tmp_path, alphas=(0.01,), betas=(0.3,), n_large=(6,), realizations=10, blocks=6, progress=False)
    with pytest.raises(ValueError, match="n_large"):
        validity.validity_map(tmp_path, alphas=(0.01,), betas=(0.3,), n_large=(2,), realizations=10, blocks=2, progress=False)


# -- figure, report, CLI ----------------------------------------------------------------------------------
def _overlap(fig, texts):
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    boxes = [t.get_window_extent(r) for t in texts if t.get_visible() and t.get_text()]
    return any(boxes[i].overlaps(boxes[j]) for i in range(len(boxes)) for j in range(i + 1, len(boxes)))


def test_figure_has_labels_colour_bars_and_contours(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from granchain.paper.figures import validity as figure

    ds = figure.compute(tmp_path, alphas=(0.01, 0.2), betas=(0.3, 0.6, 0.9), n_large=(5,), realizations=20, blocks=2,
                        progress=False, netcdf=False)
    fig = figure.plot(ds)
    heat = [ax for ax in fig.axes if ax.get_label() != "<colorbar>"]
    assert len(heat) == len(figure.PANELS)
    for ax in heat:
        assert ax.get_xlabel() and ax.get_ylabel()
    bars = [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]
    assert len(bars) == len(figure.PANELS) and all(b.get_ylabel() for b in bars)
    for ax in heat:
        assert not _overlap(fig, [ax.xaxis.label, ax.yaxis.label, ax.title])
    plt.close(fig)


def test_report_section_names_the_contour(small_map):
    _, ds = small_map
    text = validity.report_section(ds)
    assert text.startswith("## Where the theory holds")
    assert "|error| < 1 %" in text and "| 6 | 0.01 | 0.4 |" in text
    c = validity.contour_beta(ds, "arrival_time_error_effective", 0.01)
    assert c[(6, 0.01)] >= 0.4


def test_cli_validity_quick(tmp_path, capsys):
    from granchain.cli import main

    rc = main(["validity", "--out", str(tmp_path), "--quick", "--alphas", "0.01", "--betas", "0.2,0.4", "--large", "5",
               "--realizations", "20", "--blocks", "2", "--no-progress"])
    assert rc == 0
    for name in ("validity.nc", "validity.png", "validity.pdf", "validity.md"):
        assert (tmp_path / name).exists(), name
    assert "Where the theory holds" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["validity", "--out", str(tmp_path), "--large", "6,x"])


# -- any distribution at equal support ----------------------------------------------------------------------
def test_mixture_distribution():
    comps = (gc.Truncated(stats.norm(0.05, 0.02), 0.01, 0.4), gc.Truncated(stats.norm(0.35, 0.02), 0.01, 0.4))
    m = gc.Mixture(comps, (1, 3))
    assert m.weights == (0.25, 0.75)
    assert m.support == (0.01, 0.4)
    assert m.expect(lambda r: 1.0) == pytest.approx(1.0, rel=1e-8)
    u = np.linspace(0.001, 0.999, 57)
    np.testing.assert_allclose(m.cdf(m.ppf(u)), u, atol=1e-12)
    x = m.sample(np.random.default_rng(1), 20000)
    assert stats.kstest(x, m.cdf).pvalue > 1e-3
    assert abs(np.mean(x < 0.2) - 0.25) < 0.02
    assert distribution_from_record(json.loads(m.key())) == m
    fam = gc.RandomDecorated(5, m)
    assert gc.family_from_record(fam.describe()) == fam
    with pytest.raises(ValueError, match="weights"):
        gc.Mixture(comps, (1, -1))


def test_compare_distributions_runs_paired_points(tmp_path):
    dists = {"uniform": gc.Uniform(0.01, 0.4), "beta(5,2)": validity.default_distributions()["beta(5,2)"]}
    ds = validity.compare_distributions(tmp_path, dists, n_large=(5,), realizations=20, blocks=2, progress=False)
    assert list(ds["distribution"].values) == ["uniform", "beta(5,2)"]
    assert ds["radius_mean"].sel(distribution="beta(5,2)") > ds["radius_mean"].sel(distribution="uniform")
    assert np.all(np.isfinite(ds["arrival_time_error_effective"].values))
    assert (tmp_path / "distributions.nc").exists()
    for d in validity.default_distributions().values():
        assert d.support[0] >= 0.01 - 1e-12 and d.support[1] <= 0.4 + 1e-12


# -- the aligned pulse in ensembles ---------------------------------------------------------------------------
LAGS = np.arange(-4.0, 4.001, 0.25)


def test_without_lags_the_store_is_unchanged():
    spec = gc.EnsembleSpec(gc.RandomDecorated(5), realizations=4)
    assert "lags" not in spec.describe()
    ds = gc.run_ensemble(gc.RandomDecorated(5), realizations=4, progress=False)
    assert "lag" not in ds.dims and "aligned_velocity" not in ds


def test_aligned_pulse_is_the_velocity_at_peak_time_plus_lag(tmp_path):
    fam = gc.RandomDecorated(6)
    ds = gc.run_ensemble(fam, realizations=6, seed=2, chunk_size=4, lags=LAGS, progress=False, out=tmp_path / "a.zarr")
    # by hand: each realisation simulated with velocities sampled exactly at t_peak + lag (dense output)
    for chain in ("decorated", "effective"):
        expect = np.zeros((6, LAGS.size))
        for i in range(6):
            c = fam.chain(2, i, chain)
            peaks = ds["peak_time"].sel(chain=chain).values[i]
            for q in range(1, 6):
                t = peaks[q] + LAGS
                inside = t >= 0
                res = gc.simulate(c, gc.DP5(rtol=1e-10, atol=1e-12), t_grid=t[inside])
                expect[q, inside] += res.velocity[q]
        got = ds["aligned_velocity"].sel(chain=chain).values
        np.testing.assert_allclose(got[1:], expect[1:] / 6, atol=2e-4)  # cubic interpolation of the dt = 0.1 grid
        lag0 = np.argmin(np.abs(LAGS))
        # at lag 0: the mean peak, up to the cubic interpolation of the grid at each peak (measured 1.0e-4 at
        # k = 2 of the decorated chain, whose rattling small granules roughen the top of the pulse)
        np.testing.assert_allclose(got[:, lag0], ds["peak_velocity"].sel(chain=chain).mean("realization").values, rtol=3e-4)
    # the same numbers in memory and with another chunking (fixed-point sums: bitwise)
    mem = gc.run_ensemble(fam, realizations=6, seed=2, chunk_size=5, lags=LAGS, progress=False)
    np.testing.assert_array_equal(mem["aligned_velocity"].values, ds["aligned_velocity"].values)
    # resuming a store asks the same lags
    with pytest.raises(ValueError, match="lags"):
        gc.run_ensemble(fam, realizations=6, seed=2, chunk_size=4, lags=LAGS[1:], progress=False, out=tmp_path / "a.zarr")


def test_aligned_pulse_of_the_python_integrator_matches_the_compiled_one():
    fam = gc.RandomDecorated(5)
    a = gc.run_ensemble(fam, realizations=2, seed=1, chains="effective", lags=LAGS, progress=False)
    b = gc.run_ensemble(fam, realizations=2, seed=1, chains="effective", lags=LAGS, progress=False, integrator=gc.DOP853())
    np.testing.assert_allclose(a["aligned_velocity"].values, b["aligned_velocity"].values, atol=1e-5)


def test_bad_lags_say_what_to_change():
    with pytest.raises(ValueError, match="lags must be"):
        gc.EnsembleSpec(gc.RandomDecorated(5), lags=[1.0, 0.0])
