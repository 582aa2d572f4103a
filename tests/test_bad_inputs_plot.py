"""Bad inputs to the figures of a pulse: PulseResult.plot, the averaged pulse of a store, `granchain pulse
--plot` and `granchain plot`. Each is refused before anything is integrated or drawn, with words that say
what to change."""

from __future__ import annotations

import functools
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from _bad_inputs import Api, Cli, check  # noqa: E402

SMALL = "0.05,0.3,0.012"  # a decorated chain of N = 4 large granules


@functools.cache
def _result(sensors: bool = True, grid: bool = True):
    import granchain as gc
    from granchain.solve.plot import force_sensors

    chain = gc.decorated([0.05, 0.3, 0.012])
    return gc.simulate(chain, t_grid=np.linspace(0, 20, 201) if grid else None,
                       sensors=force_sensors(chain) if sensors and grid else None)


@functools.cache
def _store() -> Path:
    """One small store for the cases that need a real one (8 realisations of N = 6, seconds)."""
    import granchain as gc

    path = Path(tempfile.mkdtemp(prefix="granchain-bad-plot-")) / "N6.zarr"
    gc.run_ensemble(6, realizations=8, out=path, progress=False)
    return path


def _plot(**kw):
    return lambda tmp: _result().plot(**kw)


def _averaged(pulse=None, **kw):
    def call(tmp):
        from granchain.analysis import plot_averaged_pulse

        return plot_averaged_pulse(pulse or _store(), **kw)

    return call


def _directory_named_png(tmp):
    from granchain.solve.plot import check_figure_path

    (tmp / "figure.png").mkdir()
    check_figure_path(tmp / "figure.png", "--out")


def _averaged_pulse_object_with_chain(tmp):
    from granchain.analysis import averaged_pulse, plot_averaged_pulse

    plot_averaged_pulse(averaged_pulse(_store()), chain="effective")


def _empty_dataset(tmp):
    import xarray as xr

    from granchain.analysis import plot_averaged_pulse

    plot_averaged_pulse(xr.Dataset())


CASES = [
    # PulseResult.plot / plot_pulse
    Api("plot-kind-unknown", _plot(kind="heatmap"), r"kind must be one of 'traces', 'spacetime'"),
    Api("plot-kind-none", _plot(kind=None), r"kind must be one of"),
    Api("plot-quantity-unknown", _plot(quantity="energy"), r"quantity must be one of 'velocity', 'force'"),
    Api("plot-granule-out-of-range", _plot(granules=[9]), r"granule 9 has no recorded velocity; choose among 1\.\.4"),
    Api("plot-granule-zero", _plot(granules=[0]), r"granule 0 .*choose among 1\.\.4"),
    Api("plot-granules-empty", _plot(granules=[]), r"non-empty list of integer granule labels"),
    Api("plot-granule-fraction", _plot(granules=[1.5]), r"integer granule labels"),
    Api("plot-granules-text", _plot(granules="1,2"), r"integer granule labels"),
    Api("plot-granule-bool", _plot(granules=[True]), r"integer granule labels"),
    Api("plot-granule-twice", _plot(granules=[2, 2]), r"lists a granule twice"),
    Api("plot-force-struck-granule", _plot(kind="traces", quantity="force", granules=[1]),
        r"granule 1 has no recorded force; choose among 2\.\.3"),
    Api("plot-no-time-grid", lambda tmp: _result(False, False).plot(), r"pass t_grid=\.\.\. to simulate\(\)"),
    Api("plot-force-without-sensors", lambda tmp: _result(False, True).plot("spacetime", "force"),
        r"pass sensors=granchain\.solve\.plot\.force_sensors\(chain\)"),
    Api("plot-scale-a-name", _plot(scale="steel"), r"scale must be a granchain\.units\.Scale"),
    Api("plot-ax-not-axes", _plot(ax="left"), r"ax must be a matplotlib Axes"),
    Api("plot-time-range-reversed", _plot(time_range=(10, 5)), r"start < end"),
    Api("plot-time-range-outside", _plot(time_range=(100, 200)), r"fewer than 2 grid times; the grid spans 0\.\.20"),
    Api("plot-time-range-one-number", _plot(time_range=5), r"time_range must be \(start, end\)"),
    Api("plot-title-text", _plot(title="yes"), r"title must be True or False"),
    Api("plot-cmap-unknown", _plot(kind="spacetime", cmap="rainbowish"), r"not a matplotlib colour map; give a name such as"),
    Api("plot-cmap-number", _plot(kind="spacetime", cmap=3), r"cmap must be a colour map's name or a matplotlib Colormap"),
    # the averaged pulse of a store
    Api("averaged-missing-store", lambda tmp: _averaged(pulse=tmp / "missing.zarr")(tmp), r"does not exist"),
    Api("averaged-not-a-dataset", _empty_dataset, r"mean_velocity"),
    Api("averaged-chain-unknown", lambda tmp: _averaged(chain="tapered")(tmp), r"choose one of \['decorated', 'effective'\]"),
    Api("averaged-kind-unknown", lambda tmp: _averaged(kind="surface")(tmp), r"kind must be one of"),
    Api("averaged-granule-out-of-range", lambda tmp: _averaged(kind="traces", granules=[7])(tmp),
        r"granule 7 .*choose among 1\.\.6"),
    Api("averaged-chain-given-twice", _averaged_pulse_object_with_chain, r"pass them to averaged_pulse"),
    Api("averaged-stderr-flag", lambda tmp: _averaged(kind="traces", stderr="no")(tmp), r"stderr must be True or False"),
    Api("figure-path-is-a-directory", _directory_named_png, r"is a directory; give a file name"),
    # granchain pulse --plot
    Cli("pulse-plot-unknown-extension", ["pulse", "--small-radii", SMALL, "--plot", "{tmp}/pulse.jpg"],
        r"--plot = .*end the name in \.png, \.pdf, \.svg"),
    Cli("pulse-plot-no-extension", ["pulse", "--small-radii", SMALL, "--plot", "{tmp}/pulse"], r"extension picks the format"),
    Cli("pulse-plot-missing-directory", ["pulse", "--small-radii", SMALL, "--plot", "{tmp}/no/such/dir/pulse.png"],
        r"directory .* does not exist; create it"),
    Cli("pulse-plot-kind-without-plot", ["pulse", "--small-radii", SMALL, "--plot-kind", "traces"],
        r"--plot-kind applies to a figure: add --plot"),
    Cli("pulse-plot-quantity-without-plot", ["pulse", "--small-radii", SMALL, "--plot-quantity", "force"],
        r"--plot-quantity applies to a figure"),
    Cli("pulse-plot-kind-unknown", ["pulse", "--small-radii", SMALL, "--plot", "{tmp}/p.png", "--plot-kind", "surface"],
        r"--plot-kind: invalid choice"),
    Cli("pulse-plot-quantity-unknown", ["pulse", "--small-radii", SMALL, "--plot", "{tmp}/p.png", "--plot-quantity", "energy"],
        r"--plot-quantity: invalid choice"),
    Cli("pulse-plot-granule-out-of-range", ["pulse", "--small-radii", SMALL, "--plot", "{tmp}/p.png", "--plot-granules", "9"],
        r"--plot-granules: granule 9 has no recorded velocity; choose among 1\.\.4"),
    Cli("pulse-plot-granule-no-force", ["pulse", "--small-radii", SMALL, "--plot", "{tmp}/p.png", "--plot-quantity", "force",
                                        "--plot-granules", "1,4"], r"granule 1 has no recorded force; choose among 2\.\.3"),
    Cli("pulse-plot-granules-words", ["pulse", "--small-radii", SMALL, "--plot", "{tmp}/p.png", "--plot-granules", "a,b"],
        r"--plot-granules expects comma-separated whole granule numbers"),
    Cli("pulse-plot-granules-empty-field", ["pulse", "--small-radii", SMALL, "--plot", "{tmp}/p.png", "--plot-granules", "1,,2"],
        r"--plot-granules has an empty field"),
    # granchain plot STORE --out FILE
    Cli("plot-missing-store", ["plot", "{tmp}/missing.zarr", "--out", "{tmp}/a.png"], r"missing\.zarr does not exist"),
    Cli("plot-not-a-store", ["plot", "{tmp}/notes.txt", "--out", "{tmp}/a.png"], r"give the path of an ensemble store",
        files={"notes.txt": "not a store"}),
    Cli("plot-out-missing", ["plot", "{tmp}/missing.zarr"], r"the following arguments are required: --out"),
    Cli("plot-out-unknown-extension", ["plot", "{tmp}/missing.zarr", "--out", "{tmp}/a.gif"], r"--out = .*end the name in"),
    Cli("plot-out-missing-directory", ["plot", "{tmp}/missing.zarr", "--out", "{tmp}/nope/a.png"], r"does not exist; create it"),
    Cli("plot-kind-unknown", ["plot", "{tmp}/missing.zarr", "--out", "{tmp}/a.png", "--kind", "surface"],
        r"--kind: invalid choice"),
    Cli("plot-t-max-negative", ["plot", "{tmp}/missing.zarr", "--out", "{tmp}/a.png", "--t-max", "-1"], r"--t-max must be a time > 0"),
    Cli("plot-granules-words", ["plot", "{tmp}/missing.zarr", "--out", "{tmp}/a.png", "--granules", "one"],
        r"--granules expects comma-separated whole granule numbers"),
]


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input_is_refused_clearly(case, tmp_path):
    check(case, tmp_path)
