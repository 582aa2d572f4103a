"""Bad inputs of ``granchain theory`` and ``granchain.theory.predict``: each is refused clearly, before any
table is built or sample drawn (so every case is fast), naming what to change (tests/_bad_inputs.py)."""

import math

import pytest
from _bad_inputs import Api, Cli, check

from granchain import Uniform
from granchain.theory import predict

LAW = Uniform(0.01, 0.4)


def _predict(*args, **kw):
    return lambda tmp: predict(*args, **kw)


CASES = [
    Api("no-distribution", _predict(None, 26), r"distribution is required"),
    Api("large-1", _predict(LAW, 1), r"n_large must be >= 2"),
    Api("large-float", _predict(LAW, 2.5), r"n_large must be a whole number"),
    Api("large-text", _predict(LAW, "26"), r"n_large must be a whole number"),
    Api("large-huge", _predict(LAW, 100_000_000), r"too large a prediction.*GiB.*lower n_large"),
    Api("samples-huge", _predict(LAW, 26, samples=10**8), r"keep N x samples <= 5e\+07.*samples"),
    Api("n-2", _predict(LAW, 26, 2.0), r"need n > 2"),
    Api("n-nan", _predict(LAW, 26, math.nan), r"n must be finite"),
    Api("samples-few", _predict(LAW, 26, samples=10), r"samples must be >= 100"),
    Api("samples-negative", _predict(LAW, 26, samples=-5), r"samples must be >= 100"),
    Api("seed-negative", _predict(LAW, 26, seed=-1), r"seed must be >= 0"),
    Api("memory-0", _predict(LAW, 26, memory=0), r"memory must be >= 1"),
    Api("lookahead-0", _predict(LAW, 26, lookahead=0), r"lookahead must be >= 1"),
    Api("nodes-0", _predict(LAW, 26, nodes=0), r"nodes must be >= 1"),
    Api("nodes-too-many", _predict(LAW, 26, nodes=20), r"too many: lower nodes or memory"),
    Api("profile-windows-1", _predict(LAW, 26, profile_windows=1), r"profile_windows must be >= 10"),
    Api("alpha-above-beta", lambda tmp: predict(Uniform(0.4, 0.01), 26), r"alpha|beta"),
    Cli("cli-large-huge", ["theory", "--large", "100000000"], r"too large a prediction.*--large"),
    Cli("cli-samples-huge", ["theory", "--samples", "100000000"], r"--samples"),
    Cli("cli-large-1", ["theory", "--large", "1"], r"--large must be >= 2"),
    Cli("cli-alpha-above-beta", ["theory", "--alpha", "0.5", "--beta", "0.1"], r"alpha|beta"),
    Cli("cli-alpha-negative", ["theory", "--alpha", "-0.1"], r"alpha"),
    Cli("cli-n-2", ["theory", "--n", "2"], r"need n > 2"),
    Cli("cli-samples-few", ["theory", "--samples", "10"], r"samples must be >= 100"),
    Cli("cli-nodes-0", ["theory", "--nodes", "0"], r"nodes must be >= 1"),
    Cli("cli-nodes-many", ["theory", "--nodes", "30"], r"lower nodes or memory"),
    Cli("cli-memory-0", ["theory", "--memory", "0"], r"memory must be >= 1"),
    Cli("cli-seed-negative", ["theory", "--seed", "-1"], r"seed must be >= 0"),
    Cli("cli-out-empty", ["theory", "--out", ""], r"--out must be a directory path"),
    Cli("cli-out-file", ["theory", "--out", "{tmp}/taken"], r"--out = .*existing file", files={"taken": "x"}),
    Cli("cli-out-under-file", ["theory", "--out", "{tmp}/taken/sub"], r"--out = .*cannot create its folder",
        files={"taken": "x"}),
    Cli("cli-compare-missing", ["theory", "--compare", "{tmp}/none.zarr"], r"--compare: no store at"),
    Cli("cli-compare-empty", ["theory", "--compare", ""], r"--compare must be the path"),
]


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input_is_refused_clearly(case, tmp_path):
    check(case, tmp_path)
