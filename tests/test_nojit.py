"""The package works with NUMBA_DISABLE_JIT=1 (STYLE.md habit 3), giving the compiled results.

A subprocess imports granchain with the JIT disabled (so coverage tools can see the kernels),
checks that the kernels really are plain Python functions, simulates a few small chains with
each compiled integrator and prints the observables as JSON; the in-process (compiled) results
must agree to 1e-9.
"""

from __future__ import annotations

import textwrap

import numpy as np
import pytest

import granchain as gc

CHAINS = {
    "decorated": "gc.decorated([0.2, 0.3])",
    "monodisperse": "gc.monodisperse(5)",
    "general exponent": "gc.from_radii([1.0, 0.7, 1.2], n=3.0)",
}
INTEGRATORS = ("dp5", "verlet")

SCRIPT = textwrap.dedent(
    """
    import inspect, json
    import numba
    import numpy as np
    import granchain as gc
    from granchain.backends.kernels import dispatch, forces, rkloop, schemes, verlet

    assert numba.config.DISABLE_JIT
    for f in (dispatch.dp5_chain, rkloop.rk_kernel(schemes.DP5, False), verlet.verlet_integrate, forces.accelerations):
        assert inspect.isfunction(f), type(f)

    chains = {chains}
    out = {{}}
    for name, make in chains.items():
        chain = eval(make)
        for integrator in {integrators!r}:
            r = gc.simulate(chain, integrator, t_grid=np.linspace(0.0, 6.0, 13))
            out[name + "/" + integrator] = dict(
                status=int(r.status), peak_velocity=r.peak_velocity.tolist(), peak_time=r.peak_time.tolist(),
                velocity=r.velocity.tolist(), velocities=r.velocities.tolist(), energy_error=r.energy_error,
            )
    print(json.dumps(out))
    """
)


@pytest.fixture(scope="module")
def nojit_results(run_without_jit):
    return run_without_jit(SCRIPT.format(chains=repr(CHAINS), integrators=INTEGRATORS))


def test_compiled_in_this_process():
    from granchain.backends.kernels import dispatch

    assert hasattr(dispatch.dp5_chain, "py_func")  # a Numba dispatcher here


@pytest.mark.parametrize("integrator", INTEGRATORS)
@pytest.mark.parametrize("name", list(CHAINS))
def test_nojit_matches_jit(nojit_results, name, integrator):
    got = nojit_results[f"{name}/{integrator}"]
    chain = eval(CHAINS[name])
    r = gc.simulate(chain, integrator, t_grid=np.linspace(0.0, 6.0, 13))
    assert got["status"] == int(r.status) == 0
    np.testing.assert_allclose(got["peak_velocity"], r.peak_velocity, rtol=0, atol=1e-9)
    np.testing.assert_allclose(got["peak_time"], r.peak_time, rtol=0, atol=1e-9)
    np.testing.assert_allclose(got["velocity"], r.velocity, rtol=0, atol=1e-9)
    np.testing.assert_allclose(got["velocities"], r.velocities, rtol=0, atol=1e-9)
    assert got["energy_error"] == pytest.approx(r.energy_error, abs=1e-9)
