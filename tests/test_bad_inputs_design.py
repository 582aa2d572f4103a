"""Bad inputs of ``granchain design`` and ``granchain.design``: each is refused clearly, before any chain is
integrated (so every case is fast), naming what to change (tests/_bad_inputs.py judges them)."""

import math

import numpy as np
import pytest
from _bad_inputs import Api, Cli, check

from granchain import design
from granchain.design import (
    BinarySpace,
    Constraints,
    DecoratedSpace,
    FunctionSpace,
    ImpulseDuration,
    RandomDecoratedSpace,
    SensorForce,
    TaperedSpace,
    WallForce,
)


def _run(space, objective="wall-force", **kw):
    return lambda tmp: design.optimize(space() if callable(space) else space, objective, **{"budget": 60, **kw})


def _taper(**kw):
    return lambda: TaperedSpace(20, (0.0, 0.15), **kw)


def _raises_above(p):
    if p["a"] > 0.6:
        raise RuntimeError("the part cannot be machined")
    return np.ones(5)


def _always_raises(p):
    raise RuntimeError("no drawing for this part")


def _length_changes(p):
    return np.ones(5 if p["a"] < 0.6 else 6)


def _file(tmp, name="taken"):
    path = tmp / name
    path.write_text("not a directory")
    return path


CASES = [
    # -- spaces -----------------------------------------------------------------------------------------
    Api("taper-size-1", lambda tmp: TaperedSpace(1), r"size must be >= 2"),
    Api("taper-size-float", lambda tmp: TaperedSpace(20.5), r"size must be a whole number"),
    Api("taper-q-inverted", lambda tmp: TaperedSpace(20, (0.2, 0.1)), r"inverted.*\(0\.1, 0\.2\)"),
    Api("taper-q-empty", lambda tmp: TaperedSpace(20, (0.1, 0.1)), r"empty.*low < high"),
    Api("taper-q-nan", lambda tmp: TaperedSpace(20, (0.0, math.nan)), r"bounds of q must be finite"),
    Api("taper-q-text", lambda tmp: TaperedSpace(20, "abc"), r"bounds of q must be a pair"),
    Api("taper-q-above-1", lambda tmp: TaperedSpace(20, (0.0, 1.2)), r"q < 1.*lower the upper bound"),
    Api("taper-linear-too-steep", lambda tmp: TaperedSpace(20, (0.0, 0.1), profile="linear"), r"q < 1/\(size - 1\)"),
    Api("taper-profile", lambda tmp: TaperedSpace(20, profile="cubic"), r"profile must be 'geometric' or 'linear'"),
    Api("taper-wall-text", lambda tmp: TaperedSpace(20, wall="yes"), r"wall must be True or False"),
    Api("taper-n-negative", lambda tmp: TaperedSpace(20, n=-1), r"n must be > 0"),
    Api("taper-constraints-dict", lambda tmp: TaperedSpace(20, constraints={"max_mass": 1}),
        r"constraints must be a granchain.design.Constraints"),
    Api("constraints-negative-mass", lambda tmp: Constraints(max_mass=-1), r"max_mass must be > 0"),
    Api("constraints-infinite-length", lambda tmp: Constraints(max_length=math.inf), r"max_length must be finite"),
    Api("constraints-min-above-max", lambda tmp: Constraints(min_radius=0.5, max_radius=0.4), r"min_radius.*below max_radius"),
    Api("decorated-radius-zero", lambda tmp: DecoratedSpace(10, (0.0, 0.5)), r"small radii must lie in \(0, 1\]"),
    Api("decorated-radius-above-1", lambda tmp: DecoratedSpace(10, (0.1, 1.5)), r"small radii must lie in \(0, 1\]"),
    Api("decorated-one-large", lambda tmp: DecoratedSpace(1), r"n_large must be >= 2"),
    Api("decorated-motif-too-long", lambda tmp: DecoratedSpace(10, motif=20), r"motif <= 9"),
    Api("decorated-motif-zero", lambda tmp: DecoratedSpace(10, motif=0), r"motif must be >= 1"),
    Api("binary-species-a-not-1", lambda tmp: BinarySpace(20, (2.0, 0.5)), r"radii = \(1, R_b\)"),
    Api("binary-negative-radius", lambda tmp: BinarySpace(20, (1.0, -0.5)), r"two positive radii"),
    Api("binary-one-material", lambda tmp: BinarySpace(20, materials=("steel",)), r"two materials"),
    Api("binary-unknown-material", lambda tmp: BinarySpace(20, materials=("steel", "unobtainium")),
        r"unobtainium|material"),
    Api("random-alpha-zero", lambda tmp: RandomDecoratedSpace(10, (0.0, 0.3)), r"0 < alpha"),
    Api("random-no-width", lambda tmp: RandomDecoratedSpace(10, (0.3, 0.35), (0.05, 0.2)), r"raise the upper bound of beta"),
    Api("random-one-realisation", lambda tmp: RandomDecoratedSpace(10, realizations=1), r"realizations must be >= 2"),
    Api("random-width-zero", lambda tmp: RandomDecoratedSpace(10, min_width=0), r"min_width must be > 0"),
    Api("function-not-callable", lambda tmp: FunctionSpace("radii", {"a": (0, 1)}), r"needs a function build"),
    Api("function-no-bounds", lambda tmp: FunctionSpace(lambda p: np.ones(5), {}), r"bounds must be a non-empty dict"),
    Api("function-raises-at-centre", lambda tmp: FunctionSpace(_always_raises, {"a": (0, 1)}),
        r"design function failed for \{'a': 0\.5\}.*no drawing"),
    Api("function-negative-radii", lambda tmp: FunctionSpace(lambda p: -np.ones(5), {"a": (0, 1)}),
        r"returned an invalid chain.*positive radii"),
    # -- failures inside a run: the design and the cause, not SciPy's words --------------------------------
    Api("function-raises-for-some", _run(lambda: FunctionSpace(_raises_above, {"a": (0.0, 1.0)})),
        r"design \{'a': 0\.[6-9]\d*\}.*cannot be machined.*narrow the bounds"),
    Api("function-length-changes", _run(lambda: FunctionSpace(_length_changes, {"a": (0.0, 1.0)})),
        r"chain of 7 granules.*\{'a': 0\.[6-9]\d*\}.*same size"),
    # -- objectives -----------------------------------------------------------------------------------------
    Api("objective-unknown", _run(_taper(), "force"), r"unknown objective 'force'; choose one of"),
    Api("sensor-granule-0", lambda tmp: SensorForce(granule=0), r"granule must be >= 1"),
    Api("sensor-granule-float", lambda tmp: SensorForce(granule=1.5), r"granule must be a whole number"),
    Api("sensor-beyond-chain", _run(_taper(), SensorForce(granule=25)), r"choose granule in 1\.\.19"),
    Api("impulse-fraction", lambda tmp: ImpulseDuration(fraction=1.5), r"0 < fraction < 1"),
    Api("impulse-fraction-text", lambda tmp: ImpulseDuration(fraction="most"), r"0 < fraction < 1"),
    Api("objective-sense", lambda tmp: WallForce(sense=2), r"sense must be \+1.*or -1"),
    Api("energy-against-wall", _run(_taper(), "transmitted-energy"), r"needs a free far end.*wall=False"),
    Api("wall-force-free-end", _run(_taper(wall=False), "wall-force"), r"ends in a fixed wall.*wall=True"),
    # -- constraints no design meets: refused before any evaluation -----------------------------------------
    Api("max-radius-below-1", _run(_taper(constraints=Constraints(max_radius=0.5))), r"max_radius.*at least 1"),
    Api("max-length-tiny", _run(_taper(constraints=Constraints(max_length=0.1))), r"max_length.*at least 1\d\.\d"),
    Api("max-mass-below-granule-1", _run(_taper(constraints=Constraints(max_mass=0.5))), r"max_mass.*lightest design weighs 2\.59.*at least 2\.59"),
    Api("min-radius-unreachable", _run(lambda: TaperedSpace(20, (0.05, 0.15), constraints=Constraints(min_radius=0.9))),
        r"min_radius.*at most 0\.37"),
    Api("decorated-max-length", _run(lambda: DecoratedSpace(10, motif=2, constraints=Constraints(max_length=5))),
        r"max_length.*at least"),
    Api("random-max-radius", _run(lambda: RandomDecoratedSpace(10, realizations=4, constraints=Constraints(max_radius=0.9))),
        r"max_radius.*at least 1"),
    # -- budgets, seeds, sizes, options ---------------------------------------------------------------------
    Api("budget-zero", _run(_taper(), budget=0), r"budget must be >= 1"),
    Api("budget-below-minimum", _run(_taper(), budget=5), r"below this run's minimum 23"),
    Api("budget-float", _run(_taper(), budget=60.5), r"budget must be a whole number"),
    Api("popsize-one", _run(_taper(), popsize=1), r"popsize must be >= 2"),
    Api("seed-negative", _run(_taper(), seed=-1), r"seed must be >= 0"),
    Api("local-unknown", _run(_taper(), local="bfgs"), r"local must be one of"),
    Api("statistic-median", _run(lambda: RandomDecoratedSpace(10, realizations=4), statistic="median"),
        r"statistic must be 'mean' or a quantile in \(0, 1\)"),
    Api("statistic-above-1", _run(lambda: RandomDecoratedSpace(10, realizations=4), statistic=1.5),
        r"statistic must be 'mean' or a quantile"),
    Api("size-too-large", _run(lambda: TaperedSpace(100_000, (0.0, 1e-6))), r"at most 2000"),
    Api("decorated-too-large", _run(lambda: DecoratedSpace(5000, motif=1)), r"9999 granules.*at most 2000"),
    Api("space-as-text", lambda tmp: design.optimize("tapered", "wall-force"), r"space must be a granchain.design space"),
    Api("workers-not-callable", _run(_taper(), workers="pool"), r"workers must be a function workers\(func, iterable\)"),
    # -- output directories ---------------------------------------------------------------------------------
    Api("out-empty", _run(_taper(), out=""), r"out must be a directory path.*empty string"),
    Api("out-is-file", lambda tmp: design.optimize(TaperedSpace(20), "wall-force", out=_file(tmp)),
        r"existing file, not a directory"),
    Api("out-under-file", lambda tmp: design.optimize(TaperedSpace(20), "wall-force", out=_file(tmp) / "run"),
        r"cannot create its folder"),
    Api("backend-unknown", _run(_taper(), backend="gpu"), r"backend must be one of \['cpu', .*'cuda'\]"),
    Api("backend-number", _run(_taper(), backend=2), r"backend must be one of"),
    Api("switch-backend-string", _run(_taper(), switch_backend="yes"), r"switch_backend must be True or False"),
    Api("evaluator-backend-unknown", lambda tmp: design.BatchEvaluator(TaperedSpace(20), "wall-force", backend="gpu"),
        r"backend must be one of"),
    # -- the command line -----------------------------------------------------------------------------------
    Cli("cli-backend-unknown", ["design", "--out", "{tmp}/d", "--backend", "gpu"], r"--backend: invalid choice: 'gpu'"),
    Cli("cli-max-radius", ["design", "--out", "{tmp}/d", "--max-radius", "0.5"], r"--max-radius\) at least 1"),
    Cli("cli-max-length", ["design", "--out", "{tmp}/d", "--max-length", "0.1"], r"--max-length\) at least"),
    Cli("cli-size-huge", ["design", "--out", "{tmp}/d", "--size", "100000"], r"--size\) to at most 2000"),
    Cli("cli-size-1", ["design", "--out", "{tmp}/d", "--size", "1"], r"size must be >= 2"),
    Cli("cli-out-empty", ["design", "--out", ""], r"--out must be a directory path"),
    Cli("cli-out-file", ["design", "--out", "{tmp}/taken"], r"--out = .*existing file", files={"taken": "x"}),
    Cli("cli-out-under-file", ["design", "--out", "{tmp}/taken/run"], r"--out = .*cannot create its folder",
        files={"taken": "x"}),
    Cli("cli-q-inverted", ["design", "--out", "{tmp}/d", "--q", "0.2,0.1"], r"inverted"),
    Cli("cli-q-text", ["design", "--out", "{tmp}/d", "--q", "abc"], r"--q expects two comma-separated numbers"),
    Cli("cli-q-above-1", ["design", "--out", "{tmp}/d", "--q", "0,1.5"], r"q < 1"),
    Cli("cli-budget-zero", ["design", "--out", "{tmp}/d", "--budget", "0"], r"budget must be >= 1"),
    Cli("cli-budget-small", ["design", "--out", "{tmp}/d", "--budget", "3"], r"raise --budget to at least"),
    Cli("cli-popsize-1", ["design", "--out", "{tmp}/d", "--popsize", "1"], r"popsize must be >= 2"),
    Cli("cli-seed-negative", ["design", "--out", "{tmp}/d", "--seed", "-1"], r"seed must be >= 0"),
    Cli("cli-statistic", ["design", "--out", "{tmp}/d", "--space", "random-decorated", "--statistic", "median"],
        r"--statistic must be 'mean' or a quantile"),
    Cli("cli-free-end-wall-force", ["design", "--out", "{tmp}/d", "--free-end"], r"judged at a wall: drop --free-end"),
    Cli("cli-materials-tapered", ["design", "--out", "{tmp}/d", "--materials", "steel,ptfe"], r"--materials is for --space binary"),
    Cli("cli-motif-long", ["design", "--out", "{tmp}/d", "--space", "decorated", "--motif", "50"], r"motif <= 19"),
    Cli("cli-small-radii-zero", ["design", "--out", "{tmp}/d", "--space", "decorated", "--small-radii", "0,0.5"],
        r"small radii must lie in \(0, 1\]"),
    Cli("cli-species-radius", ["design", "--out", "{tmp}/d", "--space", "binary", "--species-radius", "-1"],
        r"two positive radii"),
    Cli("cli-realizations-1", ["design", "--out", "{tmp}/d", "--space", "random-decorated", "--realizations", "1"],
        r"realizations must be >= 2"),
    Cli("cli-alpha-beta", ["design", "--out", "{tmp}/d", "--space", "random-decorated", "--alpha", "0.3,0.35", "--beta",
                           "0.05,0.2"], r"raise the upper bound of beta"),
    Cli("cli-max-mass-negative", ["design", "--out", "{tmp}/d", "--max-mass", "-1"], r"max_mass must be > 0"),
    Cli("cli-min-above-max-radius", ["design", "--out", "{tmp}/d", "--min-radius", "0.5", "--max-radius", "0.4"],
        r"min_radius .* must be below max_radius"),
    Cli("cli-energy-max-mass", ["design", "--out", "{tmp}/d", "--objective", "transmitted-energy", "--max-mass", "0.5"],
        r"--max-mass\) at least"),
]


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input_is_refused_clearly(case, tmp_path):
    check(case, tmp_path)
