"""granchain reproduce at low resolution: the report's numbers are the analysis functions' numbers."""

from __future__ import annotations

import json

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from granchain import analysis  # noqa: E402
from granchain.paper import reproduce as _reproduce  # noqa: E402


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("reproduce")
    res = _reproduce.reproduce(out, realizations=32, Ns=(6, 26), progress=False, log=lambda *a: None, chunk_size=4)
    return out, res


def _records(out):
    return {(r["section"], r["quantity"], r["range"]): r for r in json.loads((out / "summary.json").read_text())["records"]}


def test_summary_json_is_machine_readable(run):
    out, _ = run
    recs = json.loads((out / "summary.json").read_text())["records"]
    assert recs
    for r in recs:
        assert set(r) >= {"quantity", "value", "stderr", "paper", "unit", "range", "method", "agrees"}
        for key in ("value", "stderr", "paper"):
            v = r[key]
            assert v is None or isinstance(v, (int, float)) or (isinstance(v, list) and all(isinstance(x, (int, float)) or x is None for x in v))
        assert r["agrees"] in (True, False, None)
        assert r["range"] and r["method"]
    assert recs[0]["section"].startswith("headline")


def test_report_numbers_equal_analysis_functions(run):
    out, res = run
    recs = _records(out)
    ds = res["datasets"][26]
    sums = analysis.ChunkSums.from_store(_reproduce.ensemble_path(out, 26))
    g = analysis.paper_curve_agreement(ds, "effective", (4, 25), sums)
    r = recs[("headline: Fig. 2", "fitted amplitude curve vs the paper's curve (effective chain)", "k = 4..25")]
    assert r["value"] == pytest.approx(g.max_relative, rel=1e-12) and r["agrees"] == g.agrees
    f = analysis.fit_averaged_arrival(ds, "effective", (2, 25), sums)
    r = recs[("headline: Fig. 3", "slope of the arrival line (effective chain)", "k = 2..25")]
    assert (r["value"], r["stderr"]) == pytest.approx(f.params[0:1] + f.stderr[0:1], rel=1e-12)
    assert "jackknife" in r["method"]
    f = analysis.fit_averaged_decay(ds, "effective", (4, 25), sums)
    for i, key in enumerate("abc"):
        r = recs[("Fig. 2", f"{key} (effective chain)", "k = 4..25")]
        assert (r["value"], r["stderr"]) == pytest.approx((f.params[i], f.stderr[i]), rel=1e-12)
    gap = analysis.averaged_peak_gap(ds, 25, sums)
    r = recs[("decorated vs effective", "averaged-pulse peak at k = 25, N = 26: decorated / effective - 1", "k = 25")]
    assert (r["value"], r["stderr"]) == pytest.approx((float(gap.value), float(gap.stderr)), rel=1e-12)
    for N in (6, 26):
        t = analysis.arrival_times(res["datasets"][N], "decorated", N - 1)
        rng = f"N = {N}, k = {N - 1}"
        assert recs[("Fig. 4", f"KS distance d of the standardised arrival times, N = {N}", rng)]["value"] == pytest.approx(analysis.ks_distance(t))
        q = recs[("Fig. 4", f"quantile (Bowley) skewness of the arrival times, N = {N}", rng)]["value"]
        assert q == pytest.approx(analysis.quantile_skewness(t))
    # the range is stated next to every fitted number
    assert all(r["range"] != "-" for r in recs.values() if r["section"].startswith(("Fig. 2", "Fig. 3", "headline")))


def test_curve_agreement_from_a_fit_at_hand_is_the_refitted_one(run):
    """paper_curve_agreement(fit=...) takes the curves of fit_averaged_decay's replicates instead of fitting
    them again: the same numbers, bitwise; a fit of another range or chain is refused."""
    out, res = run
    ds = res["datasets"][26]
    sums = analysis.ChunkSums.from_store(_reproduce.ensemble_path(out, 26))
    for s in (sums, None):
        fit = analysis.fit_averaged_decay(ds, "effective", (4, 25), s)
        a = analysis.paper_curve_agreement(ds, "effective", (4, 25), s)
        b = analysis.paper_curve_agreement(ds, "effective", (4, 25), s, fit=fit)
        for name in ("granule", "deviation", "stderr", "envelope"):
            assert np.array_equal(getattr(a, name), getattr(b, name))
        assert a.method == b.method
    with pytest.raises(ValueError, match="fit must be"):
        analysis.paper_curve_agreement(ds, "effective", (5, 25), sums, fit=fit)
    with pytest.raises(ValueError, match="fit must be"):
        analysis.paper_curve_agreement(ds, "effective", (4, 25), sums,
                                       fit=analysis.fit_averaged_decay(ds, "effective", (4, 25), sums, variable="t"))


def test_report_html_has_unbroken_paragraphs_and_bounds(run):
    out, _ = run
    html = (out / "report.html").read_text()
    md = (out / "report.md").read_text()
    assert "Fits are done as the paper does them" in html
    para = next(p for p in md.split("\n\n") if p.startswith("Fits are done"))
    assert "\n" not in para  # one line per paragraph: no hard wraps to break apart
    for name in ("fig1", "fig2", "fig3", "fig4"):
        assert (out / f"{name}.png").exists() and (out / f"{name}.nc").exists()


def test_rerun_reuses_stores(run, monkeypatch):
    out, res = run
    from granchain.ensembles import run as _ensemble

    def boom(*a, **k):
        raise AssertionError("a finished store was recomputed")

    monkeypatch.setattr(_ensemble, "compute_chunk", boom)
    again = _reproduce.reproduce(out, realizations=32, Ns=(6, 26), progress=False, log=lambda *a: None, chunk_size=4)
    assert np.array_equal(again["datasets"][26]["peak_time"].values, res["datasets"][26]["peak_time"].values)
