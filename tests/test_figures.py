"""Each paper figure at low resolution: compute, plot, no overlapping text, every axis labelled."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
import xarray as xr  # noqa: E402

import granchain as gc  # noqa: E402
from granchain import analysis  # noqa: E402
from granchain.ensembles.run import default_time_grid  # noqa: E402
from granchain.paper.figures import fig1, fig2, fig3, fig4  # noqa: E402
from granchain.paper.figures._style import text_overlaps  # noqa: E402


@pytest.fixture(scope="module")
def stores(tmp_path_factory):
    """Tiny ensembles (both chains) written as stores with 8 chunks each: N -> (Dataset, ChunkSums)."""
    root = tmp_path_factory.mktemp("fig-stores")
    out = {}
    for N, R in ((6, 40), (11, 40), (16, 24), (26, 32)):
        path = root / f"N{N:02d}.zarr"
        gc.run_ensemble(N, gc.Uniform(0.01, 0.4), R, 100 + N, "both", t_grid=default_time_grid(N),
                        chunk_size=R // 8, out=path, progress=False)
        out[N] = (xr.open_zarr(path).load(), analysis.ChunkSums.from_store(path))
    return out


def _check(fig):
    fig.canvas.draw()
    assert text_overlaps(fig) == []
    for ax in fig.axes:
        if ax.get_label() == "<colorbar>":
            assert ax.get_ylabel()
            continue
        assert ax.get_xlabel().strip(), f"axes {ax.get_title()!r} has no x label"
        assert ax.get_ylabel().strip(), f"axes {ax.get_title()!r} has no y label"
        for child in ax.child_axes:  # insets
            assert child.get_xlabel().strip() and child.get_ylabel().strip()
    plt.close(fig)


def test_overlap_detector_detects_overlap():
    fig, ax = plt.subplots()
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.text(0.5, 0.5, "some text", transform=ax.transAxes)
    ax.text(0.52, 0.5, "other text", transform=ax.transAxes)
    assert text_overlaps(fig)
    plt.close(fig)


def test_fig1(stores):
    data = fig1.compute(stores[11][0])
    assert data.decorated.shape == data.effective.shape == (11, stores[11][0].sizes["time"])
    _check(fig1.plot(data))
    data.to_dataset()


def test_save_lays_out_once_and_keeps_the_engine(stores, tmp_path):
    """save() draws the PDF with the PNG's layout (constrained layout runs once) and gives the figure its
    layout engine back: a later draw still lays it out, with nothing overlapping."""
    from granchain.paper.figures import save

    fig = fig1.plot(fig1.compute(stores[11][0]))
    engine = fig.get_layout_engine()
    paths = save(fig, tmp_path / "fig1")
    assert [p.suffix for p in paths] == [".png", ".pdf"] and all(p.stat().st_size > 0 for p in paths)
    assert fig.get_layout_engine() is engine
    _check(fig)


def test_fig2_jackknife_and_fallback(stores):
    ds, sums = stores[26]
    data = fig2.compute(ds, sums=sums)
    assert data.fit_range == (4, 25) and data.main == "effective"
    f = data.fit_k["effective"]
    assert "jackknife" in f.method and f.fit.sigma is None  # unweighted, as the paper
    assert np.all(np.isfinite(f.stderr))
    _check(fig2.plot(data))
    mem = fig2.compute(ds)  # no chunk sums: residual errors, labelled
    assert "residuals" in mem.fit_k["effective"].method
    assert mem.fit_k["effective"].params == pytest.approx(f.params, rel=1e-12)
    data.to_dataset()


def test_fig3_default_range_and_slope_function(stores):
    ds, sums = stores[26]
    data = fig3.compute(ds, sums=sums)
    assert data.fit_range == (2, 25)
    assert data.S == pytest.approx(fig3._bca_slope(ds)) and data.S == pytest.approx(2.3482, abs=1e-4)
    assert np.all(np.isfinite(data.pulse_time_stderr["effective"][1:]))
    _check(fig3.plot(data))
    data.to_dataset()


def test_fig4_clockwise_order_common_range_and_sign(stores):
    data = fig4.compute({N: s[0] for N, s in stores.items()}, n_mc_samples=20, n_blocks=4)
    assert [p.N for p in data.panels] == [6, 11, 16, 26]
    for p in data.panels:
        assert np.array_equal(p.hist_numerics.edges, p.hist_theory.edges)
        assert p.numerics.size == p.theory.size
        assert p.stats["shift"].value == pytest.approx(p.shifted.shift)
        # each panel's Lilliefors test (computed in threads) is the one its own sample gets alone
        assert p.ks == analysis.ks_normal(p.numerics, n_mc_samples=20)
    fig = fig4.plot(data)
    fig.canvas.draw()
    centre = {p.N: ax.get_position() for p, ax in zip(data.panels, fig.axes)}
    assert centre[6].y0 > centre[26].y0 and centre[6].x0 < centre[11].x0      # 6 upper left, 11 upper right
    assert centre[16].x0 > centre[26].x0 and centre[16].y0 < centre[11].y0    # 16 lower right, 26 lower left
    _check(fig)
    data.to_dataset()


@pytest.mark.usefixtures("private_theory_cache")
def test_theory_figure_says_what_it_compares():
    """The theory figure: labelled axes, no overlapping text; without numerics its title says so; the
    paper's fit is drawn for the paper's law only, and no stretched exponential is fitted through
    fewer than six granules (three parameters would fit anything)."""
    from granchain import theory
    from granchain.paper.figures import theory as figure

    small = dict(memory=2, nodes=3, samples=1000, profile_windows=100)
    law = gc.Uniform(0.05, 0.3)
    data = figure.compute(law, 12, prediction=theory.predict(law, 12, **small))
    assert data.measured is None and data.fit is not None
    fig = figure.plot(data)
    labels = [t.get_text() for ax in fig.axes for t in ax.get_legend().get_texts()]
    assert not any("paper's fit" in s for s in labels) and any("fit to the theory" in s for s in labels)
    assert fig.axes[0].get_title().startswith("Theory (no numerics given), U[0.05, 0.3], N = 12")
    _check_stacked(fig)
    short = figure.compute(law, 8, prediction=theory.predict(law, 8, **small))
    assert short.fit is None
    fig = figure.plot(short)
    assert not any("fit to the theory" in t.get_text() for ax in fig.axes for t in ax.get_legend().get_texts())
    _check_stacked(fig)


def _check_stacked(fig):
    """Panels stacked on a shared x axis: the bottom one carries the x label, every one a y label."""
    fig.canvas.draw()
    assert text_overlaps(fig) == []
    assert fig.axes[-1].get_xlabel().strip()
    assert all(ax.get_ylabel().strip() for ax in fig.axes)
    plt.close(fig)
