"""The first pictures of a pulse: PulseResult.plot, the ensemble's averaged space-time diagram, and the
commands that write them (granchain pulse --plot, granchain plot). Each figure is checked as a referee
would: it draws, every axis and colour bar says what it shows and in which units, no two texts overlap,
and the numbers drawn are the result's numbers (in SI when a scale is given)."""

from __future__ import annotations

import subprocess
import sys

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import granchain as gc  # noqa: E402
from granchain.analysis import AveragedPulse, averaged_pulse, plot_averaged_pulse  # noqa: E402
from granchain.cli import main  # noqa: E402
from granchain.paper.figures._style import text_overlaps  # noqa: E402
from granchain.solve.plot import force_sensors, granule_labels, plot_pulse  # noqa: E402

SMALL = [0.05, 0.3, 0.012, 0.2, 0.1]  # a decorated chain of N = 6 large granules (M = 11)
SCALE = gc.units.scale("steel", "5 mm", "0.5 m/s")


@pytest.fixture(scope="module")
def chain():
    return gc.decorated(SMALL)


@pytest.fixture(scope="module")
def result(chain):
    """Velocities and every granule force on one grid."""
    return gc.simulate(chain, t_grid=np.linspace(0.0, 25.0, 501), sensors=force_sensors(chain))


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    path = tmp_path_factory.mktemp("plot-store") / "N6.zarr"
    gc.run_ensemble(6, realizations=8, out=path, progress=False)
    return path


def _colorbars(fig):
    return [a for a in fig.axes if a.get_label() == "<colorbar>"]


def _cut_off(fig) -> list[str]:
    """Visible texts that reach beyond the figure's edge (a title too long for the figure, say)."""
    from matplotlib.text import Text

    renderer = fig.canvas.get_renderer()
    edge = fig.bbox
    ticks, drawn = set(), set()  # tick labels exist beyond the view limits too; only the drawn ones count
    for ax in fig.axes:
        for axis in ax._axis_map.values():
            ticks |= {id(t) for tick in axis.majorTicks + axis.minorTicks for t in (tick.label1, tick.label2)}
            drawn |= {id(t) for tick in axis._update_ticks() for t in (tick.label1, tick.label2)}
    out = []
    for t in fig.findobj(Text):
        if id(t) in ticks and id(t) not in drawn:
            continue
        if t.get_visible() and t.get_text().strip():
            bb = t.get_window_extent(renderer)
            if bb.x0 < edge.x0 - 0.5 or bb.x1 > edge.x1 + 0.5 or bb.y0 < edge.y0 - 0.5 or bb.y1 > edge.y1 + 0.5:
                out.append(t.get_text())
    return out


def test_cut_off_detector_detects_a_title_too_long():
    fig, ax = plt.subplots(figsize=(3, 2))
    ax.set_title("a title much too long for a figure three inches wide, cut at both ends")
    fig.canvas.draw()
    assert _cut_off(fig)
    plt.close(fig)


def _check(ax, *, units: str):
    """Labels with units on every axis and colour bar, nothing overlapping; returns the labels."""
    fig = ax.figure
    assert text_overlaps(fig) == []
    assert _cut_off(fig) == []
    labels = [ax.get_xlabel(), ax.get_ylabel()] + [c.get_ylabel() for c in _colorbars(fig)]
    assert all(label.strip() for label in labels), labels
    if units == "rescaled":
        assert "rescaled" in ax.get_xlabel()
        assert not any("m/s" in x or "(N)" in x or "s)" in x for x in labels), labels
    else:
        assert ax.get_xlabel().endswith("s)"), ax.get_xlabel()
    return labels


# ------------------------------------------------------------------ one pulse


@pytest.mark.parametrize("kind", ["traces", "spacetime"])
@pytest.mark.parametrize("quantity", ["velocity", "force"])
def test_every_kind_and_quantity_draws_with_labelled_axes(result, kind, quantity):
    ax = result.plot(kind, quantity)
    labels = _check(ax, units="rescaled")
    word = "velocity" if quantity == "velocity" else "force"
    if kind == "spacetime":
        (bar,) = _colorbars(ax.figure)
        assert word in bar.get_ylabel() and "rescaled" in bar.get_ylabel()
        assert ax.get_ylabel() == r"large granule $k$"
    else:
        assert word in ax.get_ylabel() and "rescaled" in ax.get_ylabel()
        assert ax.get_legend().get_title().get_text() == r"large granule $k$"
    assert ax.get_title()
    plt.close(ax.figure)
    assert labels


def test_spacetime_draws_the_results_numbers_row_by_granule(result):
    ax = result.plot("spacetime", "velocity")
    mesh = ax.collections[0]
    image = np.asarray(mesh.get_array()).reshape(result.granule.size, -1)
    np.testing.assert_array_equal(image, result.velocity)  # row k-1 is large granule k
    norm = mesh.norm
    assert norm.vmin == -norm.vmax and norm.vmax == pytest.approx(np.max(np.abs(result.velocity)))  # centred on 0
    assert np.min(result.velocity) < 0  # (so centring matters: granules behind the pulse move back)
    plt.close(ax.figure)
    ax = result.plot("spacetime", "force")
    image = np.asarray(ax.collections[0].get_array())
    rows = granule_labels(result.chain, result.sensor_granule)[0]
    assert list(rows) == [2, 3, 4, 5]  # large granules with two contacts: not 1 (struck), not 6 (free end)
    np.testing.assert_array_equal(image.reshape(rows.size, -1), result.sensor_force)
    assert ax.collections[0].norm.vmin == 0.0  # sequential from 0: contacts only push
    plt.close(ax.figure)


def test_physical_units_convert_the_numbers_and_say_so(result):
    ax = result.plot("traces", "velocity", granules=[1, 3], scale=SCALE)
    labels = _check(ax, units="SI")
    assert ax.get_ylabel() == r"velocity $v_k$ (m/s)" and ax.get_xlabel() == r"time $t$ (µs)"
    line = ax.get_lines()[1]
    np.testing.assert_allclose(line.get_ydata(), result.velocity[2] * 0.5)  # V_1 = 0.5 m/s
    np.testing.assert_allclose(line.get_xdata(), result.t_grid * SCALE.time * 1e6)
    plt.close(ax.figure)
    ax = result.plot("spacetime", "force", scale=SCALE)
    (bar,) = _colorbars(ax.figure)
    assert bar.get_ylabel() == r"granule force $F_k$ (N)"
    np.testing.assert_allclose(np.asarray(ax.collections[0].get_array()).reshape(4, -1), result.sensor_force * SCALE.force)
    plt.close(ax.figure)
    assert labels


def test_default_traces_are_a_readable_spread_and_many_get_a_colour_bar():
    chain = gc.monodisperse(20)
    res = gc.simulate(chain, t_grid=np.linspace(0, 40, 401))
    ax = res.plot()
    shown = [t.get_text() for t in ax.get_legend().get_texts()]
    assert shown[0] == "1" and shown[-1] == "20" and 4 <= len(shown) <= 8
    assert ax.get_legend().get_title().get_text() == "granule"  # not a decorated chain: its own labels
    plt.close(ax.figure)
    ax = res.plot("traces", granules=list(range(1, 21)))
    assert ax.get_legend() is None
    (bar,) = _colorbars(ax.figure)
    assert bar.get_ylabel() == "granule"
    assert len([line for line in ax.get_lines() if not line.get_label().startswith("_")]) == 20  # (not the v = 0 line)
    _check(ax, units="rescaled")
    plt.close(ax.figure)


def test_chosen_granules_and_the_given_axes_are_used(result):
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4), layout="constrained")
    out = result.plot("spacetime", granules=[2, 5], ax=b, title=False)
    assert out is b and not b.get_title()
    image = np.ma.getdata(b.collections[0].get_array()).reshape(4, -1)  # rows 2..5, 3 and 4 not chosen
    np.testing.assert_array_equal(image[0], result.velocity[1])
    assert np.isnan(image[1]).all() and np.isnan(image[2]).all()
    assert any("not among the chosen" in t.get_text() for t in b.texts)
    plt.close(fig)


def test_time_range_cuts_the_drawn_times(result):
    ax = plot_pulse(result, "traces", granules=[2], time_range=(5, 10))  # (what result.plot calls)
    x = ax.get_lines()[0].get_xdata()
    assert x.min() >= 5 and x.max() <= 10 and x.size == 101
    np.testing.assert_array_equal(ax.get_lines()[0].get_ydata(), result.velocity[1][(result.t_grid >= 5) & (result.t_grid <= 10)])
    plt.close(ax.figure)


def test_missing_data_says_which_simulate_argument_to_pass(chain):
    bare = gc.simulate(chain)
    with pytest.raises(ValueError, match=r"t_grid=\.\.\. to simulate\(\)"):
        bare.plot()
    gridded = gc.simulate(chain, t_grid=np.linspace(0, 20, 101))
    with pytest.raises(ValueError, match=r"sensors=granchain\.solve\.plot\.force_sensors\(chain\)"):
        gridded.plot("spacetime", "force")
    gridded.plot("spacetime", "velocity")  # (the velocity needs only the grid)
    plt.close("all")


def test_force_sensors_are_the_granules_with_two_contacts(chain):
    assert force_sensors(chain) == [3, 5, 7, 9]  # chain labels of large granules 2..5
    assert force_sensors(gc.monodisperse(5)) == [2, 3, 4]
    assert force_sensors(gc.monodisperse(5).with_wall()) == [2, 3, 4, 5]  # the last one presses on the wall
    assert force_sensors(gc.monodisperse(5).with_striker(radius=1.0)) == [1, 2, 3, 4]  # the striker hits granule 1


def test_import_granchain_and_simulating_do_not_import_matplotlib():
    code = ("import sys, numpy, granchain as gc; gc.simulate(gc.monodisperse(4), t_grid=numpy.linspace(0, 5, 11)); "
            "print('matplotlib' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"


# ------------------------------------------------------------------ an ensemble's averaged pulse


def test_averaged_pulse_is_the_stores_mean_velocity(store):
    ds = gc.open_store(store)
    for chain in ("decorated", "effective"):
        p = averaged_pulse(store, chain)
        assert isinstance(p, AveragedPulse)
        np.testing.assert_array_equal(p.velocity, ds["mean_velocity"].sel(chain=chain).transpose("granule", "time").values)
        assert p.chain == chain and p.n_valid == 8 and list(p.granule) == [1, 2, 3, 4, 5, 6]
    assert averaged_pulse(ds).chain == "decorated"  # default: the store's first chain


@pytest.mark.parametrize("kind", ["spacetime", "traces"])
def test_averaged_pulse_draws_in_either_kind(store, kind):
    ax = plot_averaged_pulse(store, kind)
    _check(ax, units="rescaled")
    label = _colorbars(ax.figure)[0].get_ylabel() if kind == "spacetime" else ax.get_ylabel()
    assert r"averaged velocity $\langle v_k \rangle$" in label and "rescaled" in label
    assert "8 realisations" in ax.get_title()
    if kind == "traces":  # one standard-error band per trace
        from matplotlib.collections import FillBetweenPolyCollection, PolyCollection

        bands = [c for c in ax.collections if isinstance(c, (PolyCollection, FillBetweenPolyCollection))]
        assert len(bands) == len(ax.get_legend().get_texts()) == 6
    plt.close(ax.figure)


def test_a_stores_physical_scale_is_used_unless_rescaled_is_asked(store):
    ds = gc.open_store(store)
    ds.attrs.update({f"physical_{k}": v for k, v in SCALE.as_dict().items()})
    p = averaged_pulse(ds)
    assert p.units.time == SCALE.time and p.units.velocity == 0.5
    ax = plot_averaged_pulse(p, "traces", granules=[2])
    np.testing.assert_allclose(ax.get_lines()[0].get_ydata(), p.velocity[1] * 0.5, equal_nan=True)
    assert ax.get_ylabel().endswith("(m/s)")
    _check(ax, units="SI")
    plt.close(ax.figure)
    assert averaged_pulse(ds, scale=False).units.time is None
    assert averaged_pulse(gc.open_store(store)).units.time is None  # (negative control: no scale recorded)


# ------------------------------------------------------------------ the commands


def _png(path):
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_pulse_plot_writes_each_format(tmp_path, capsys):
    radii = ",".join(map(str, SMALL))
    assert main(["pulse", "--small-radii", radii, "--plot", str(tmp_path / "a.png")]) == 0
    assert "# figure written to" in capsys.readouterr().out
    _png(tmp_path / "a.png")
    assert main(["pulse", "--small-radii", radii, "--plot", str(tmp_path / "b.pdf"), "--plot-kind", "traces",
                 "--plot-quantity", "force", "--material", "steel", "--radius", "5mm", "--impact-speed", "1m/s"]) == 0
    assert (tmp_path / "b.pdf").read_bytes()[:5] == b"%PDF-"
    capsys.readouterr()
    assert main(["pulse", "--radii", "1,1,1,1", "--plot", str(tmp_path / "c.svg"), "--plot-granules", "2,3",
                 "--json"]) == 0
    assert "<svg" in (tmp_path / "c.svg").read_text()[:1000]
    out = capsys.readouterr().out
    assert out.startswith("{") and "figure" not in out  # --json stays JSON


def test_pulse_without_plot_writes_nothing_and_prints_the_same(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["pulse", "--small-radii", "0.1,0.2"]) == 0
    plain = capsys.readouterr().out
    assert main(["pulse", "--small-radii", "0.1,0.2", "--plot", "p.png"]) == 0
    with_plot = capsys.readouterr().out
    assert list(tmp_path.iterdir()) == [tmp_path / "p.png"]
    assert with_plot.splitlines()[-1] == "# figure written to p.png"
    assert with_plot.splitlines()[:4] == plain.splitlines()[:4]  # the same peaks (header and granules 1..3)


def test_granchain_plot_writes_the_averaged_pulse(store, tmp_path, capsys):
    assert main(["plot", str(store), "--out", str(tmp_path / "st.png")]) == 0
    _png(tmp_path / "st.png")
    assert "decorated chains (8 realisations)" in capsys.readouterr().out
    assert main(["plot", str(store), "--out", str(tmp_path / "tr.svg"), "--kind", "traces", "--chain", "effective",
                 "--granules", "1,3,6", "--t-max", "15"]) == 0
    text = (tmp_path / "tr.svg").read_text()
    assert "<svg" in text[:1000]
