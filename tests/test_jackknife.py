"""Jackknife, quantile skewness and p-value formatting (granchain.analysis)."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from granchain import analysis as A


def test_block_jackknife_of_the_mean_matches_the_known_standard_error():
    rng = np.random.default_rng(1)
    x = rng.normal(3.0, 2.0, size=20_000)
    jk = A.block_jackknife(np.mean, x, n_blocks=20)
    assert jk.value == pytest.approx(x.mean())
    assert jk.stderr == pytest.approx(2.0 / np.sqrt(x.size), rel=0.35)  # 19 dof: ~16 % scatter
    # delete-one jackknife of the mean is exactly s / sqrt(n)
    y = x[:200]
    assert A.block_jackknife(np.mean, y, n_blocks=200).stderr == pytest.approx(y.std(ddof=1) / np.sqrt(y.size), rel=1e-10)


def test_block_jackknife_sees_correlated_blocks():
    """Realisations correlated within blocks: the jackknife error exceeds the naive s / sqrt(n)."""
    rng = np.random.default_rng(2)
    x = np.repeat(rng.normal(size=100), 50) + 0.1 * rng.normal(size=5000)
    jk = A.block_jackknife(np.mean, x, n_blocks=100)
    assert jk.stderr > 5 * x.std(ddof=1) / np.sqrt(x.size)


def test_chunk_sums_leave_one_out_and_jackknife():
    rng = np.random.default_rng(3)
    bits = 30
    v = rng.uniform(0, 1, size=(6, 10, 2, 3, 5))  # chunk, realisation, chain, granule, time
    q = np.round(v * 2.0**bits).astype(np.int64)
    sums = A.ChunkSums(q.sum(1), (q * q // 2**bits).sum(1), np.full((6, 2), 10), bits, ("decorated", "effective"), np.arange(5.0))
    exact = q / 2.0**bits
    assert sums.mean() == pytest.approx(exact.mean(axis=(0, 1)), rel=1e-12)
    assert sums.mean(2) == pytest.approx(np.delete(exact, 2, axis=0).mean(axis=(0, 1)), rel=1e-12)
    jk = A.chunk_jackknife(lambda m: m["effective"][1, 2], sums)
    chunk_means = exact.mean(axis=1)[:, 1, 1, 2]
    # with equal chunks the jackknife of a mean is the standard error of the chunk means
    assert jk.stderr == pytest.approx(chunk_means.std(ddof=1) / np.sqrt(6), rel=1e-9)
    with pytest.raises(ValueError, match="at least 2"):
        A.ChunkSums(q.sum(1)[:1], q.sum(1)[:1], np.full((1, 2), 10), bits, ("decorated", "effective"), np.arange(5.0))


def test_chunk_sums_from_a_stored_ensemble_reproduce_its_mean():
    path = "tests/data/v0.1.0-decorated-N6.zarr"
    sums = A.ChunkSums.from_store(path)
    ds = xr.open_zarr(path).load()
    assert sums.chunks == 3
    assert sums.mean() == pytest.approx(ds["mean_velocity"].transpose("chain", "granule", "time").values, rel=1e-14, nan_ok=True)


def test_chunk_sums_means_are_computed_once_and_read_only():
    sums = A.ChunkSums.from_store("tests/data/v0.1.0-decorated-N6.zarr")
    assert sums.mean(1) is sums.mean(1) and sums.mean() is sums.mean()
    with pytest.raises(ValueError, match="read-only"):
        sums.mean(0)[0, 0, 0] = 1.0


def test_quantile_skewness():
    rng = np.random.default_rng(4)
    assert A.quantile_skewness(rng.normal(size=200_000)) == pytest.approx(0, abs=0.01)
    e = rng.exponential(size=400_000)
    assert A.quantile_skewness(e) == pytest.approx(np.log(4 / 3) / np.log(3), abs=0.006)
    assert A.quantile_skewness(-e) == pytest.approx(-A.quantile_skewness(e))
    # an outlier moves the moment skewness, not the quantile one
    x = rng.normal(size=2000)
    y = np.r_[x, 40.0]
    assert abs(A.skewness(y) - A.skewness(x)) > 1
    assert abs(A.quantile_skewness(y) - A.quantile_skewness(x)) < 0.01
    with pytest.raises(ValueError):
        A.quantile_skewness(x, p=0.6)


def test_pvalue_bound_at_the_monte_carlo_floor():
    assert A.format_pvalue(1 / 1001, 1000).startswith("< 1/(B+1)")
    assert A.format_pvalue(0.2, 1000).startswith("0.2")
    assert A.format_pvalue(float("nan"), 0) == "not computed"
    rng = np.random.default_rng(5)
    ks = A.ks_normal(rng.exponential(size=3000), n_mc_samples=99)
    assert ks.at_floor and ks.pvalue_text.startswith("< 1/(B+1) = 0.01")
    ks = A.ks_normal(rng.normal(size=3000), n_mc_samples=99, rng=1)
    assert not ks.at_floor


def test_rounding_envelope_bounds_the_printed_digits():
    k = np.arange(4, 26.0)
    env = A.rounding_envelope(k, A.PAPER_FIG2, (5e-4,) * 3)
    assert np.all(np.diff(env) > 0) and 0.004 < env[-1] < 0.008
    p = np.array(A.PAPER_FIG2) + [5e-4, -5e-4, 5e-4]
    assert np.all(np.abs(A.stretched_exp(k, *p) / A.stretched_exp(k, *A.PAPER_FIG2) - 1) <= env + 1e-15)
