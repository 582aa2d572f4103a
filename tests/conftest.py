"""Shared test configuration for the granchain test-suite.

Hypothesis profiles
-------------------
* ``dev`` (default): random exploration, no per-example deadline (the first
  example of a test may include Numba compilation, seconds long).
* ``ci``: the same, derandomised, so that a CI run is reproducible.

Select one with ``HYPOTHESIS_PROFILE=ci python -m pytest ...``. Each expensive
property test sets its own (small) ``max_examples``; the profiles only fix the
deadline and the randomness.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, settings

settings.register_profile("dev", deadline=None, print_blob=True)
settings.register_profile(
    "ci", deadline=None, print_blob=True, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "dev"))


@pytest.fixture
def private_theory_cache(tmp_path, monkeypatch):
    """granchain.theory's tables in a directory of the test's own: a test neither uses nor fills the
    user's cache (and starts with an empty memory cache)."""
    from granchain import theory

    monkeypatch.setenv("GRANCHAIN_CACHE", str(tmp_path / "cache"))
    theory.clear_cache()
    yield
    theory.clear_cache()


@pytest.fixture(scope="session")
def reference():
    """The accuracy contract's reference integrator: SciPy DOP853 at rtol 1e-10, atol 1e-12."""
    import granchain

    return granchain.DOP853(rtol=1e-10, atol=1e-12)


def chain_energy(chain, x, v) -> float:
    """Total energy sum m v^2/2 + sum (c/n) delta^n (paper Eq. hertz-1), in plain NumPy."""
    d = np.asarray(x[:-1]) - np.asarray(x[1:])
    pot = np.where(d > 0, chain.stiffness / chain.n * np.clip(d, 0, None) ** chain.n, 0.0)
    return float(0.5 * np.sum(chain.masses * np.asarray(v) ** 2) + pot.sum())


@pytest.fixture(scope="session")
def energy_of():
    """``energy_of(chain, x, v)``: the total energy, independent of the package's kernels."""
    return chain_energy


def _run_without_jit(script: str, timeout: float = 300):
    """Run ``script`` in a fresh Python with NUMBA_DISABLE_JIT=1 (every kernel as plain Python) from
    the repository's root; it must succeed. Returns the JSON it printed on its last line."""
    env = dict(os.environ, NUMBA_DISABLE_JIT="1")
    proc = subprocess.run([sys.executable, "-c", script], env=env, cwd=Path(__file__).parents[1], capture_output=True,
                          text=True, timeout=timeout)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="session")
def run_without_jit():
    """``run_without_jit(script, timeout=300)``: the JSON of the script's last line, run with the JIT off."""
    return _run_without_jit


def in_order(b):
    """Granules whose peak comes no later than the next observed granule's (the last one always).

    A peak after the next granule's is a late hump of a granule the pulse has passed, raised above
    the pulse's own by the rattling of light granules. On decorated chains of radii [0.01, 0.4, 0.01,
    0.4] and [0.015625, 0.4, 0.015625, 0.4] (found by the slow sweep), granule 4 peaks after granule 5,
    in a hump still rising when the exit rule ends the run: its recorded "peak" is the run's end, which
    moves with the integrator's last steps (DOP853 at rtol 1e-10 and 1e-12: 3.7e-5 and 2.8e-5 apart,
    relative), and ``simulate`` reports PEAK_AT_END; a larger ``exit_margin`` resolves it
    (tests/test_simulate.py). (The ensembles' report counts these out-of-order peaks.)"""
    return np.r_[b.peak_time[:-1] <= b.peak_time[1:], True]


def completed(r) -> bool:
    """The integration of ``r`` (a ``PulseResult``) ran to its end: SUCCESS, or PEAK_AT_END, where a late hump
    (:func:`in_order`) was still rising when the exit rule ended the run and the run says so instead of calling
    the run's end a maximum (its other peaks and its conservation stand)."""
    from granchain._status import Status

    return r.status in (Status.SUCCESS, Status.PEAK_AT_END)


def _v040_decorated():
    import granchain as gc

    return gc.RandomDecorated(6, gc.Uniform(0.01, 0.4))


def _v040_tapered_wall():
    import granchain as gc

    return gc.TaperedDecorated(5, q=0.1, distribution=gc.Uniform(0.05, 0.35), wall=True)  # 0.4's ratio 0.9


def _v040_integrators():
    """The ensembles' default integrators of granchain 0.4.0 (today's are tighter: a store names them to resume)."""
    import granchain as gc

    return {"decorated": gc.RKN4.relaxed(1e-5, 1e-8), "effective": gc.DP5.relaxed(5e-8, 5e-11)}


#: The stores granchain 0.4.0 wrote (tests/data/make_v0.4.0_fixtures.py) and how today's API makes the
#: same runs: {store name: (family factory, run_ensemble keywords)}.
FIXTURE_GRID = np.round(np.arange(0.0, 30.05, 0.5), 12)
FIXTURES_040 = {
    # pulse_window="full": stores of 0.4 hold the averaged pulse on the whole grid (run_ensemble resuming
    # one finds that in its record by itself: tests/test_store_upgrade.py)
    "v0.4.0-decorated-N6.zarr": (_v040_decorated, dict(realizations=24, seed=7, chunk_size=8, t_grid=FIXTURE_GRID,
                                                       pulse_window="full", integrator=_v040_integrators())),
    "v0.4.0-tapered-wall-N5.zarr": (_v040_tapered_wall, dict(realizations=12, seed=3, chunk_size=4, t_grid=FIXTURE_GRID,
                                                             lags=np.round(np.arange(-4.0, 4.05, 0.5), 12),
                                                             pulse_window="full", integrator=_v040_integrators())),
}
