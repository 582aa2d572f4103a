"""Bad inputs of ``granchain bca``, ``validity``, ``reproduce`` and ``export``, and of the Python API of
``granchain.bca`` (and the paper's validity map and experiment behind the two commands). Every case
must be refused before anything is integrated or written, with a message that names what to change
(``tests/_bad_inputs.py`` judges them)."""

from __future__ import annotations

import numpy as np
import pytest
from _bad_inputs import Api, Cli, check

import granchain as gc
from granchain import bca
from granchain.paper import reproduce as paper_reproduce
from granchain.paper import validity as paper_validity

NAN, INF = float("nan"), float("inf")
#: A path no one can create (``/proc`` accepts no new entries, also for root).
UNWRITABLE = "/proc/granchain-cannot-be-here"
SAMPLE = [1.0, 2.0, 3.0, 4.0]

CASES = [
    # -- granchain bca -----------------------------------------------------------------------------
    Cli("bca-alpha-nan", ["bca", "--alpha", "nan"], r"alpha"),
    Cli("bca-alpha-negative", ["bca", "--alpha", "-0.1"], r"alpha"),
    Cli("bca-alpha-zero", ["bca", "--alpha", "0"], r"0 < alpha"),
    Cli("bca-alpha-above-beta", ["bca", "--alpha", "0.5", "--beta", "0.4"], r"alpha.*beta"),
    Cli("bca-alpha-equals-beta", ["bca", "--alpha", "0.3", "--beta", "0.3"], r"alpha.*beta"),
    Cli("bca-alpha-text", ["bca", "--alpha", "small"], r"--alpha"),
    Cli("bca-beta-above-1", ["bca", "--beta", "1.5"], r"beta.*1"),
    Cli("bca-beta-inf", ["bca", "--beta", "inf"], r"beta"),
    Cli("bca-large-1", ["bca", "--large", "1"], r"--large"),
    Cli("bca-large-0", ["bca", "--large", "0"], r"--large"),
    Cli("bca-large-negative", ["bca", "--large", "-3"], r"--large"),
    Cli("bca-large-text", ["bca", "--large", "many"], r"--large"),
    Cli("bca-granule-0", ["bca", "--granule", "0"], r"--granule"),
    Cli("bca-granule-beyond-N", ["bca", "--large", "6", "--granule", "7"], r"--granule"),
    Cli("bca-n-2", ["bca", "--n", "2"], r"--n.*> 2"),
    Cli("bca-n-below-2", ["bca", "--n", "1.5"], r"--n.*> 2"),
    Cli("bca-n-nan", ["bca", "--n", "nan"], r"--n"),
    Cli("bca-n-inf", ["bca", "--n", "inf"], r"--n"),
    Cli("bca-realizations-negative", ["bca", "--realizations", "-5"], r"--realizations"),
    Cli("bca-seed-negative", ["bca", "--realizations", "10", "--seed", "-1"], r"--seed"),
    # -- granchain validity ------------------------------------------------------------------------
    Cli("validity-out-empty", ["validity", "--quick", "--out", ""], r"--out"),
    Cli("validity-out-file", ["validity", "--quick", "--out", "{tmp}/a-file"], r"--out.*file", files={"a-file": "x"}),
    Cli("validity-out-unwritable", ["validity", "--quick", "--out", UNWRITABLE], r"--out"),
    Cli("validity-alpha-above-every-beta", ["validity", "--out", "{tmp}/v", "--alphas", "0.5", "--betas", "0.4"],
        r"alpha.*beta"),
    Cli("validity-beta-above-1", ["validity", "--out", "{tmp}/v", "--betas", "1.5"], r"beta.*1"),
    Cli("validity-alpha-negative", ["validity", "--out", "{tmp}/v", "--alphas", "-0.1"], r"alpha"),
    Cli("validity-alpha-nan", ["validity", "--out", "{tmp}/v", "--alphas", "nan"], r"alpha"),
    Cli("validity-alphas-text", ["validity", "--out", "{tmp}/v", "--alphas", "a,b"], r"--alphas"),
    Cli("validity-alphas-empty", ["validity", "--out", "{tmp}/v", "--alphas", ","], r"alpha"),
    Cli("validity-large-2", ["validity", "--out", "{tmp}/v", "--large", "2"], r"N >= 3|n_large|--large"),
    Cli("validity-large-text", ["validity", "--out", "{tmp}/v", "--large", "6,x"], r"--large"),
    Cli("validity-realizations-2", ["validity", "--out", "{tmp}/v", "--realizations", "2"], r"realizations"),
    Cli("validity-blocks-1", ["validity", "--out", "{tmp}/v", "--blocks", "1"], r"blocks"),
    Cli("validity-blocks-too-many", ["validity", "--out", "{tmp}/v", "--realizations", "10", "--blocks", "8"], r"blocks"),
    Cli("validity-seed-negative", ["validity", "--out", "{tmp}/v", "--seed", "-1"], r"seed"),
    # -- granchain reproduce -----------------------------------------------------------------------
    Cli("reproduce-realizations-few", ["reproduce", "--realizations", "5", "--out", "{tmp}/r"], r"--realizations"),
    Cli("reproduce-realizations-negative", ["reproduce", "--realizations", "-1", "--out", "{tmp}/r"], r"--realizations"),
    Cli("reproduce-seed-negative", ["reproduce", "--quick", "--seed", "-1", "--out", "{tmp}/r"], r"--seed"),
    Cli("reproduce-backend-unknown", ["reproduce", "--quick", "--out", "{tmp}/r", "--backend", "gpu"],
        r"--backend: invalid choice: 'gpu'"),
    Cli("validity-backend-unknown", ["validity", "--quick", "--out", "{tmp}/v", "--backend", "gpu"],
        r"--backend: invalid choice: 'gpu'"),
    Cli("reproduce-out-empty", ["reproduce", "--quick", "--out", " "], r"--out"),
    Cli("reproduce-out-file", ["reproduce", "--quick", "--out", "{tmp}/a-file"], r"--out.*file", files={"a-file": "x"}),
    Cli("reproduce-out-unwritable", ["reproduce", "--quick", "--out", UNWRITABLE], r"--out"),
    # -- granchain export (the command belongs to another module; listed here for the sweep) --------
    Cli("export-store-missing", ["export", "{tmp}/none.zarr", "{tmp}/x.nc"], r"store"),
    Cli("export-store-empty", ["export", "", "{tmp}/x.nc"], r"store"),
    Cli("export-store-a-file", ["export", "{tmp}/a-file", "{tmp}/x.nc"], r"store", files={"a-file": "x"}),
    Cli("export-store-not-a-store", ["export", "{tmp}", "{tmp}/x.nc"], r"store"),
    Cli("export-file-empty", ["export", "{tmp}", ""], r"FILE"),
    Cli("export-file-folder-missing", ["export", "{tmp}", "{tmp}/no/such/x.nc"], r"folder.*missing"),
    Cli("export-file-exists", ["export", "{tmp}", "{tmp}/a.nc"], r"--force", files={"a.nc": "x"}),
    # -- granchain.bca -----------------------------------------------------------------------------
    Api("A-n-2", lambda t: bca.A(2.0), r"n.*> 2"),
    Api("A-n-nan", lambda t: bca.A(NAN), r"\bn\b"),
    Api("A-n-text", lambda t: bca.A("hertz"), r"\bn\b"),
    Api("A_plain-n-below-2", lambda t: bca.A_plain(1.5), r"n.*> 2"),
    Api("prefactor-mass-negative", lambda t: bca.prefactor(2.5, m=-1.0), r"\bm\b"),
    Api("slope_uniform-alpha-above-beta", lambda t: bca.slope_uniform(0.5, 0.4), r"alpha.*beta"),
    Api("slope_uniform-alpha-zero", lambda t: bca.slope_uniform(0.0, 0.4), r"alpha"),
    Api("slope_uniform-beta-above-1", lambda t: bca.slope_uniform(0.01, 1.5), r"beta"),
    Api("slope_uniform-alpha-nan", lambda t: bca.slope_uniform(NAN, 0.4), r"alpha"),
    Api("slope_uniform-n-2", lambda t: bca.slope_uniform(0.01, 0.4, n=2.0), r"n.*> 2"),
    Api("slope-distribution-text", lambda t: bca.slope("wide"), r"distribution"),
    Api("XDistribution-alpha-above-beta", lambda t: bca.XDistribution(0.5, 0.4), r"alpha.*beta"),
    Api("gaussian_limit-granule-0", lambda t: bca.gaussian_limit(gc.Uniform(0.01, 0.4), 0), r"granule"),
    Api("gaussian_limit-granule-float", lambda t: bca.gaussian_limit(gc.Uniform(0.01, 0.4), 2.5), r"granule"),
    Api("gaussian_limit-n-2", lambda t: bca.gaussian_limit(gc.Uniform(0.01, 0.4), 25, n=2.0), r"n.*> 2"),
    Api("monte_carlo-size-1", lambda t: bca.monte_carlo_arrival_times(1, gc.Uniform(0.01, 0.4), 10), r"size"),
    Api("monte_carlo-realizations-0", lambda t: bca.monte_carlo_arrival_times(6, gc.Uniform(0.01, 0.4), 0),
        r"realizations"),
    Api("monte_carlo-seed-negative", lambda t: bca.monte_carlo_arrival_times(6, gc.Uniform(0.01, 0.4), 10, seed=-1),
        r"seed"),
    Api("monte_carlo-n-2", lambda t: bca.monte_carlo_arrival_times(6, gc.Uniform(0.01, 0.4), 10, n=2.0), r"n.*> 2"),
    Api("monte_carlo-at-0", lambda t: bca.monte_carlo_arrival_times(6, gc.Uniform(0.01, 0.4), 10).at(0), r"granule"),
    Api("monte_carlo-at-beyond", lambda t: bca.monte_carlo_arrival_times(6, gc.Uniform(0.01, 0.4), 10).at(7),
        r"granule"),
    Api("arrival_times-no-gap", lambda t: bca.arrival_times(np.zeros((2, 0))), r"small_radii"),
    Api("arrival_times-radius-negative", lambda t: bca.arrival_times([0.1, -0.2]), r"small_radii"),
    Api("arrival_times-radius-nan", lambda t: bca.arrival_times([0.1, NAN]), r"small_radii"),
    Api("arrival_times-radius-above-large", lambda t: bca.arrival_times([0.1, 1.5]), r"small_radii"),
    Api("arrival_times-approximation", lambda t: bca.arrival_times([0.1, 0.2], approximation="rough"),
        r"approximation"),
    Api("arrival_times-n-2", lambda t: bca.arrival_times([0.1, 0.2], n=2.0), r"n.*> 2"),
    Api("arrival_times-velocity-zero", lambda t: bca.arrival_times([0.1, 0.2], initial_velocity=0.0),
        r"initial_velocity"),
    Api("travel_times-not-a-chain", lambda t: bca.travel_times([1.0, 1.0]), r"chain"),
    Api("time_to_max_compression-mass-negative", lambda t: bca.time_to_max_compression(-1.0, 1.0, 1.0),
        r"reduced_mass"),
    Api("time_to_max_compression-speed-zero", lambda t: bca.time_to_max_compression(0.5, 1.0, 0.0), r"speed"),
    Api("shift_peak-one-value", lambda t: bca.shift_peak([1.0], SAMPLE), r"at least 2"),
    Api("shift_peak-nan", lambda t: bca.shift_peak([NAN, NAN, NAN], SAMPLE), r"finite"),
    Api("shift_peak-method", lambda t: bca.shift_peak(SAMPLE, SAMPLE, method="median"), r"method"),
    Api("shift_peak-bins", lambda t: bca.shift_peak(SAMPLE, SAMPLE, bins=3), r"bins"),
    Api("shift_peak-smoothing-negative", lambda t: bca.shift_peak(SAMPLE, SAMPLE, smoothing=-1.0), r"smoothing"),
    # -- granchain.paper: the validity map and the paper's experiment -------------------------------
    Api("validity_map-realizations-2", lambda t: paper_validity.validity_map(t / "v", realizations=2), r"realizations"),
    Api("validity_map-alpha-above-beta",
        lambda t: paper_validity.validity_map(t / "v", alphas=[0.5], betas=[0.4], realizations=10, blocks=2),
        r"alpha.*beta"),
    Api("validity_map-out-file", lambda t: (t / "f").write_text("x") and paper_validity.validity_map(
        t / "f", alphas=[0.01], betas=[0.4], realizations=10, blocks=2, n_large=6), r"out.*file"),
    Api("compare_distributions-n-large-2", lambda t: paper_validity.compare_distributions(t / "d", n_large=2),
        r"n_large"),
    Api("reproduce-realizations-few", lambda t: paper_reproduce.reproduce(t / "r", realizations=5), r"realizations"),
    Api("reproduce-out-file", lambda t: (t / "f").write_text("x") and paper_reproduce.reproduce(
        t / "f", realizations=20, quick=True), r"out.*file"),
    Api("reproduce-seed-negative", lambda t: paper_reproduce.reproduce(t / "r", realizations=20, seed=-1), r"seed"),
    Api("reproduce-backend-unknown", lambda t: paper_reproduce.reproduce(t / "r", quick=True, backend="gpu"),
        r"backend must be one of \['cpu', .*'cuda'\]"),
    Api("validity_map-backend-unknown", lambda t: paper_validity.validity_map(t / "v", backend="gpu"),
        r"backend must be one of"),
    Api("compare_distributions-backend-unknown", lambda t: paper_validity.compare_distributions(t / "d", backend="gpu"),
        r"backend must be one of"),
]


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input_is_refused_clearly(case, tmp_path):
    check(case, tmp_path)
