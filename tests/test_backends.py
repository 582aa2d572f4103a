"""The backend layer: every registered integrator on every backend over one set of cases, and the
two promises of the grouped kernel records.

1. Conformance. A short list of chains (monodisperse, a fixed and a random decorated chain, the
   random one's effective chain, a general exponent n = 3, decorated and monodisperse chains ending
   in a fixed wall) runs through every integrator in ``granchain.solve.integrators.INTEGRATORS`` (so a
   new one is picked up, and fails until it is given a case with its tolerances) and is compared
   with SciPy's DOP853 at rtol 1e-11: status, peak velocities and times, velocities on a time grid,
   energy, momentum (or, with a wall, the wall's impulse) and the stop event. Tolerances are scaled
   to each method (tight for DP5 and RKN4 at their defaults, O(dt^2) for Verlet). Also: every
   backend's ``check`` refuses a method for x'' = f(x) on a contact law that is not conservative,
   and ``effective_integrator`` switches the goal-oriented zones off for a chain ending in a wall
   (bitwise the exact method there) and leaves them on otherwise.
2. Grouped records. No compiled entry point of ``granchain.backends.kernels`` takes more than 8
   positional parameters (a long positional call is where a swapped argument hides), with a
   negative control showing that the counter flags one that does.
3. One seam for the model. A field added to ``records.Params`` (the model's scalars) and filled in
   ``numba_backend.model_params`` reaches the kernels' step loops, for one chain and through the
   batch kernel, with no other change, and changes nothing else in the results.

Why: the renovation moved every kernel behind ``granchain.backends``; these tests pin what that
layer promises, so that the next method, backend or model parameter cannot quietly break it.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib
import inspect
import json
import os
import pkgutil
import shutil
import subprocess
import sys
import textwrap
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest
from conftest import in_order

import granchain as gc
from granchain.backends import BACKENDS, OPTIONAL_BACKENDS, effective_integrator, get_backend
from granchain.model.contacts import PowerLaw
from granchain.solve.integrators import INTEGRATORS

# -- 1. conformance ---------------------------------------------------------------------------------
#: The chains every integrator runs (built lazily, once).
CHAINS = {
    "monodisperse": lambda: gc.monodisperse(8),
    "decorated": lambda: gc.decorated([0.3, 0.05, 0.4, 0.15]),
    "random decorated": lambda: gc.random_decorated(6, gc.Uniform(0.01, 0.4), seed=11),
    "effective": lambda: gc.effective(gc.random_decorated(6, gc.Uniform(0.01, 0.4), seed=11)),
    "n = 3": lambda: gc.from_radii([1.0, 0.8, 1.2, 0.6, 1.0, 0.9], n=3.0),
    "decorated + wall": lambda: gc.decorated([0.3, 0.05, 0.4, 0.15]).with_wall(),
    "monodisperse + wall": lambda: gc.monodisperse(6).with_wall(),
}
#: Grid of the recorded velocities: up to about the pulse's exit from the shortest chains, so that
#: most runs stop at exit + margin, not at the grid's end.
T_GRID = np.linspace(0.0, 10.0, 201)
EXIT_MARGIN = 3.0  # simulate's default
REFERENCE = gc.DOP853(rtol=1e-11, atol=1e-13)
#: The exit is detected at the end of the first step after the pulse has left; steps in the free
#: flight that follows are up to a few 1e-2 long (measured: all methods 0.017-0.021 before the
#: reference's on the n = 3 chain). 0.1 is < 10 % of the time the pulse needs to cross one granule
#: (~1.2): the same event, not the next granule's.
EXIT_ATOL = 0.1
#: Momentum is a linear invariant, which every Runge-Kutta method and Verlet conserve up to round-off
#: (measured <= 7e-15 on these chains).
MOMENTUM_ATOL = 1e-12
VERLET_DT = 1e-3  # dt omega_max <= 0.14 on these chains (Gershgorin bound 140 on the decorated ones)


@dataclass(frozen=True)
class Case:
    """An integrator as the conformance suite runs it, with its tolerances against the reference.

    peak_rtol : relative error of peak velocities, and of the wall's impulse.
    time_atol, time_rtol : peak times, |t - t_ref| <= time_atol + time_rtol |t_ref|.
    grid_atol : absolute error of the velocities on ``T_GRID``.
    energy_atol : |E_end - E_0| / E_0.
    """

    integrator: gc.Integrator
    peak_rtol: float
    time_atol: float
    time_rtol: float
    grid_atol: float
    energy_atol: float


#: One case per registered integrator (measured worst case over CHAINS in the comments; margins ~3-10x).
CASES = {
    # rtol 1e-8: peaks 4e-8, times 1.2e-9, grid 4e-8, energy 7e-8 (the class contract: ~1e-7).
    "dp5": Case(gc.DP5(), peak_rtol=5e-7, time_atol=2e-8, time_rtol=2e-8, grid_atol=5e-7, energy_atol=1e-6),
    # rtol 1e-8 (more, cheaper steps than DP5 at equal rtol): peaks 5e-10, times 5e-10, grid 3e-9, energy 2e-10.
    "rkn4": Case(gc.RKN4(), peak_rtol=1e-8, time_atol=5e-9, time_rtol=5e-9, grid_atol=2e-8, energy_atol=2e-9),
    # Order 2, dt = 1e-3: peaks 3e-7 (~0.3 dt^2), grid 2e-6 (~2 dt^2), energy 9e-8; peak times 5e-7
    # in the chain, but the last granule of a free end peaks where its contact opens, where Verlet's
    # linearly interpolated acceleration is exactly 0 at the step's end: that time is located only to
    # within one step (measured 3.5e-4, 8.7e-4 at dt = 1e-3; first order), hence time_atol = 1.5 dt.
    "verlet": Case(gc.Verlet(dt=VERLET_DT), peak_rtol=3e-6, time_atol=1.5 * VERLET_DT, time_rtol=1e-6, grid_atol=2e-5,
                   energy_atol=1e-6),
    # rtol 1e-10 (RMS norm): peaks 5e-10, times 1.5e-10, grid 2.1e-8, energy 3.9e-8.
    "dop853": Case(gc.DOP853(), peak_rtol=5e-9, time_atol=1e-9, time_rtol=1e-9, grid_atol=2e-7, energy_atol=2e-7),
}


@functools.lru_cache(maxsize=None)
def chain_named(name: str) -> gc.Chain:
    return CHAINS[name]()


@functools.lru_cache(maxsize=None)
def reference_result(name: str) -> gc.PulseResult:
    result = gc.simulate(chain_named(name), REFERENCE, t_grid=T_GRID, exit_margin=EXIT_MARGIN)
    assert result.ok, f"the reference failed on the {name} chain: {result.message}"
    return result


def case_for(name: str) -> Case:
    if name not in CASES:
        pytest.fail(f"the registered integrator {name!r} has no conformance case: add its instance and tolerances "
                    "to CASES in tests/test_backends.py")
    return CASES[name]


def test_every_backend_is_exercised():
    """Every backend in ``BACKENDS`` runs at least one registered integrator (so the conformance suite
    runs every backend), resolves by its name, and every integrator names a known backend."""
    used = {cls.backend for cls in INTEGRATORS.values()}
    # (the GPU backend runs RKN4 on hardware CI lacks: tests/test_cuda.py runs it under Numba's simulator)
    own = set(BACKENDS) - set(OPTIONAL_BACKENDS)
    assert used == own, f"backends without an integrator: {own - used}; unknown: {used - own}"
    for name in own:
        assert get_backend(name).name == name
    with pytest.raises(ValueError, match="unknown backend"):
        get_backend("no such backend")


@pytest.mark.parametrize("chain_name", list(CHAINS))
@pytest.mark.parametrize("integ_name", sorted(INTEGRATORS))
def test_conformance_with_dop853(integ_name, chain_name):
    """Every registered integrator against DOP853 at rtol 1e-11 on the same chain and grid.

    Checks, with the case's tolerances (``CASES``): success; peak velocities (relative) and peak
    times (absolute + relative) at the granules whose peaks come in order (``conftest.in_order``:
    out-of-order late humps are chaotic, not resolved by the reference either); the velocities on
    the time grid (absolute); energy conservation |dE/E_0|; momentum conserved to round-off (free
    end) or, with a wall, the wall's impulse P_0 - P_end (relative, as the peaks); and the same stop
    event: the pulse's exit within ``EXIT_ATOL`` of the reference's and the run ending exactly
    ``exit_margin`` after it (or at the grid's end, whichever is later).
    """
    case = case_for(integ_name)
    assert case.integrator.name == integ_name and type(case.integrator) is INTEGRATORS[integ_name]
    chain = chain_named(chain_name)
    ref = reference_result(chain_name)
    res = gc.simulate(chain, case.integrator, t_grid=T_GRID, exit_margin=EXIT_MARGIN)
    what = f"{integ_name} on the {chain_name} chain"

    assert res.status == gc.Status.SUCCESS, f"{what}: {res.status.name} ({res.message})"
    assert res.integrator == integ_name

    # peaks, at the granules whose peaks the reference resolves
    np.testing.assert_array_equal(res.granule, ref.granule)
    ok = in_order(ref)
    assert ok[:2].all() and ok.sum() >= 0.5 * ok.size, f"too many out-of-order peaks in the reference: {ref.peak_time}"
    np.testing.assert_allclose(res.peak_velocity[ok], ref.peak_velocity[ok], rtol=case.peak_rtol, atol=0,
                               err_msg=f"{what}: peak velocities")
    late = np.abs(res.peak_time - ref.peak_time)
    bad = ok & (late > case.time_atol + case.time_rtol * np.abs(ref.peak_time))
    assert not bad.any(), (f"{what}: peak times differ at granules {res.granule[bad]}: "
                           f"{res.peak_time[bad]} vs {ref.peak_time[bad]}")

    # velocities on the grid (at t = 0 exactly the initial state)
    assert res.velocity.shape == (chain.observed.size, T_GRID.size)
    np.testing.assert_allclose(res.velocity, ref.velocity, rtol=0, atol=case.grid_atol,
                               err_msg=f"{what}: grid velocities")
    np.testing.assert_array_equal(res.velocity[:, 0], np.r_[chain.initial_velocity, np.zeros(chain.observed.size - 1)])

    # conservation
    assert abs(res.energy_error) <= case.energy_atol, f"{what}: energy error {res.energy_error:.2e}"
    if chain.wall:
        assert np.isnan(res.momentum_error)
        assert res.wall_impulse == pytest.approx(ref.wall_impulse, rel=case.peak_rtol), what
        assert res.wall_impulse > chain.momentum  # the pulse came back: the granules end moving away from the wall
    else:
        assert abs(res.momentum_error) <= MOMENTUM_ATOL, f"{what}: momentum error {res.momentum_error:.2e}"

    # the same stop event
    assert ref.exit_time > 0 and abs(res.exit_time - ref.exit_time) <= EXIT_ATOL, (
        f"{what}: exit at {res.exit_time:.6g}, reference {ref.exit_time:.6g}")
    assert res.t_end == pytest.approx(max(res.exit_time + EXIT_MARGIN, T_GRID[-1]), rel=0, abs=1e-12), (
        f"{what}: t_end {res.t_end!r}, exit {res.exit_time!r}")


# -- 1b. capabilities: conservative forces, goal-oriented zones --------------------------------------
@dataclass(frozen=True)
class VelocityDependentLaw(PowerLaw):
    """Stand-in for a contact law whose force depends on velocities (a damped Hertz law, say): only
    its declaration differs from the power law."""

    conservative: ClassVar[bool] = False


def nonconservative(chain: gc.Chain) -> gc.Chain:
    """A copy of ``chain`` whose contact law declares velocity-dependent forces."""
    other = dataclasses.replace(chain)
    object.__setattr__(other, "contact", VelocityDependentLaw(chain.n))
    assert not other.contact.conservative and chain.contact.conservative
    return other


@pytest.mark.parametrize("backend_name", [b for b in BACKENDS if b not in OPTIONAL_BACKENDS])  # (GPU: test_cuda.py)
@pytest.mark.parametrize("integ_name", sorted(INTEGRATORS))
def test_check_refuses_methods_for_conservative_forces(backend_name, integ_name):
    """Every backend's ``check``: a method for x'' = f(x) (``needs_conservative_forces``: RKN4,
    Verlet) is refused on a contact law that is not conservative, with a message naming what to use
    instead; every method is accepted on the (conservative) power law. A method without that need
    gets past the capability check on the stand-in law; a compiled backend then refuses it because it
    has no code for its force (the stand-in does not declare a ``form`` of its own: it would otherwise
    run as the plain power law), while the SciPy backend, whose code is the law's own NumPy force, runs it."""
    backend = get_backend(backend_name)
    integ = case_for(integ_name).integrator
    chain = gc.decorated([0.2, 0.3])
    backend.check(integ, chain)  # the power law: never refused
    if integ.needs_conservative_forces:
        with pytest.raises(ValueError, match=f"{integ.name} integrates x'' = f\\(x\\).*positions only.*use DP5"):
            backend.check(integ, nonconservative(chain))
    elif backend.law_forms is None:
        backend.check(integ, nonconservative(chain))
    else:
        with pytest.raises(ValueError, match=f"the {backend_name} backend has no code for the contact law "
                                             "VelocityDependentLaw.*it runs the laws of forms power-law"):
            backend.check(integ, nonconservative(chain))


def test_run_path_refuses_methods_for_conservative_forces():
    """The check is on the run path of every backend, not only callable: ``simulate`` refuses each
    registered method that needs conservative forces on a non-conservative chain before integrating,
    and the SciPy backend refuses a (hypothetical) SciPy method that declares that need."""
    chain = nonconservative(gc.decorated([0.2, 0.3]))
    needing = [name for name, cls in INTEGRATORS.items() if cls.needs_conservative_forces]
    assert needing, "no registered integrator needs conservative forces: this test checks nothing"
    for name in needing:
        with pytest.raises(ValueError, match="positions only"):
            gc.simulate(chain, case_for(name).integrator)

    @dataclass(frozen=True)
    class NystromOnScipy(gc.DOP853):
        needs_conservative_forces: ClassVar[bool] = True

    assert NystromOnScipy.backend == "scipy"
    with pytest.raises(ValueError, match="positions only"):
        gc.simulate(chain, NystromOnScipy())


def goal_variants():
    """(id, integrator) for the goal-oriented settings of every registered integrator that supports
    them (``DP5.relaxed()``, ``DP5.windowed()``, ``RKN4.relaxed()``, ...)."""
    out = []
    for name, cls in sorted(INTEGRATORS.items()):
        if cls.supports_goal_control:
            out += [(f"{name}.relaxed", cls.relaxed()), (f"{name}.windowed", cls.windowed())]
    assert {"dp5.relaxed", "rkn4.relaxed", "rkn4.windowed"} <= {i for i, _ in out}
    return out


GOAL = goal_variants()


@pytest.mark.parametrize("integ", [i for _, i in GOAL], ids=[n for n, _ in GOAL])
def test_effective_integrator_switches_goal_zones_off_at_a_wall(integ):
    """A wall sends the pulse back through the granules behind the front, so the relaxed zone and
    the trailing window are switched off there (``FixedWall.licenses_goal_control``): the effective
    integrator is the exact method with the same tolerances. A free end leaves them on (the
    integrator itself)."""
    assert integ.goal_oriented and integ.relaxed_lag is not None
    free = gc.decorated([0.2, 0.3, 0.1])
    walled = free.with_wall()
    assert effective_integrator(integ, free) is integ
    eff = effective_integrator(integ, walled)
    assert type(eff) is type(integ)
    assert eff.relaxed_lag is None and eff.window_lag is None and eff.is_exact and not eff.goal_oriented
    assert eff == dataclasses.replace(integ, relaxed_lag=None, window_lag=None)  # nothing else changed
    assert (eff.rtol, eff.atol) == type(integ).goal_tolerances


@pytest.mark.parametrize("integ_name", sorted(INTEGRATORS))
def test_effective_integrator_leaves_exact_methods_alone(integ_name):
    """An integrator without goal-oriented zones on (every registered default) is run as it is,
    with or without a wall."""
    integ = case_for(integ_name).integrator
    assert not integ.goal_oriented
    for chain in (gc.monodisperse(4), gc.monodisperse(4, wall=True)):
        assert effective_integrator(integ, chain) is integ


#: Long enough that the zones act on a free end: the front passes 7 observed granules (window lag).
GOAL_CHAIN = dict(size=10, dist=gc.Uniform(0.01, 0.4), seed=5)


@pytest.mark.parametrize("integ", [i for _, i in GOAL], ids=[n for n, _ in GOAL])
def test_goal_zones_switched_off_means_bitwise_exact(integ):
    """On a chain ending in a wall, ``RKN4.relaxed()`` (and every goal-oriented variant) gives bitwise
    the result of the exact method at the same tolerances: peaks, grid velocities, forces, final
    state, step counts, stop. Negative control: on the same chain without the wall the zones act,
    and the results differ (so the bitwise comparison can fail)."""
    exact = type(integ)(integ.rtol, integ.atol)
    assert exact.is_exact
    free = gc.random_decorated(GOAL_CHAIN["size"], GOAL_CHAIN["dist"], seed=GOAL_CHAIN["seed"])
    grid = np.linspace(0.0, 30.0, 61)

    def same(a, b) -> bool:
        arrays = ("peak_velocity", "peak_time", "velocity", "positions", "velocities", "peak_force", "peak_force_time")
        scalars = ("n_steps", "n_rejected", "n_evaluations", "t_end", "exit_time", "energy_error", "status")
        return (all(np.array_equal(getattr(a, k), getattr(b, k)) for k in arrays)
                and all(getattr(a, k) == getattr(b, k) for k in scalars))

    walled = free.with_wall()
    a, b = gc.simulate(walled, integ, t_grid=grid), gc.simulate(walled, exact, t_grid=grid)
    assert a.ok and b.ok
    assert same(a, b), f"{integ} on a walled chain is not bitwise {exact}: peaks {a.peak_velocity - b.peak_velocity}"
    assert np.array_equal(a.wall_force, b.wall_force) and a.wall_impulse == b.wall_impulse
    a, b = gc.simulate(free, integ, t_grid=grid), gc.simulate(free, exact, t_grid=grid)
    assert a.ok and b.ok and not same(a, b), "the goal-oriented zones did not act on the free chain: no control"


# -- 2. grouped records: no long positional signatures ------------------------------------------------
MAX_POSITIONAL = 8


def positional_parameters(dispatcher) -> int:
    """The number of named positional parameters of a Numba dispatcher's Python function. A
    ``*args`` catch-all (``memory.keep_alive``, a no-op that only extends lifetimes) is not a list
    of values the callee reads by position, and is not counted."""
    kinds = (inspect.Parameter.POSITIONAL_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)
    return sum(p.kind in kinds for p in inspect.signature(dispatcher.py_func).parameters.values())


def compiled_functions(package) -> dict:
    """Every Numba dispatcher (an object with ``py_func``) defined in the modules of ``package``, by
    qualified name (each once, wherever it is imported)."""
    found = {}
    for info in pkgutil.iter_modules(package.__path__):
        module = importlib.import_module(f"{package.__name__}.{info.name}")
        for obj in vars(module).values():
            if hasattr(obj, "py_func") and callable(obj):
                found[f"{obj.py_func.__module__}.{obj.py_func.__qualname__}"] = obj
    return found


def long_signatures(functions: dict, limit: int = MAX_POSITIONAL) -> dict:
    """{name: count} of the functions taking more than ``limit`` positional parameters."""
    return {name: n for name, f in sorted(functions.items()) if (n := positional_parameters(f)) > limit}


#: The compiled entry points: what the Numba backend calls (one chain, a batch) and the per-method
#: kernels ``dispatch.chain_kernel`` picks for a chain (one per method and model class; the
#: Runge-Kutta ones made by ``rkloop.rk_kernel``, which hold their step loop). These are the
#: signatures a new physics parameter used to be threaded through. (The small inlined helpers
#: below them, e.g. the Runge-Kutta stages and error ratios over a window's arrays, take their
#: arrays one by one: they are the loops' bodies, not seams.)
CHAIN_KERNELS = ("dp5_chain", "dp5_chain_general", "rkn4_chain", "rkn4_chain_general", "verlet_chain",
                 "verlet_chain_general")
ENTRY_POINTS = ("batch.integrate_batch", "verlet.verlet_integrate")


def test_no_compiled_entry_point_takes_more_than_8_positional_parameters():
    """Kernels take grouped records (``records``), not long positional lists: every compiled entry
    point (:data:`CHAIN_KERNELS`, :data:`ENTRY_POINTS`) takes at most 8 positional parameters (they
    took 21-37 before the records). Also checks that every kernel ``dispatch.chain_kernel`` can pick
    is listed."""
    from granchain.backends import kernels
    from granchain.backends.kernels import dispatch
    from granchain.backends.kernels.records import KIND_DP5, KIND_RKN4, KIND_VERLET, Params

    functions = compiled_functions(kernels)
    assert len(functions) >= 40
    entry = {f"granchain.backends.kernels.{name}": functions[f"granchain.backends.kernels.{name}"] for name in ENTRY_POINTS}
    entry.update({f"granchain.backends.kernels.dispatch.{name}": getattr(dispatch, name) for name in CHAIN_KERNELS})
    picked = {dispatch.chain_kernel(kind, Params(2.5, 1, False, gamma, load))
              for kind in (KIND_DP5, KIND_RKN4, KIND_VERLET) for gamma, load in ((0.0, 0.0), (0.1, 0.0), (0.0, 0.1))}
    assert picked == {getattr(dispatch, name) for name in CHAIN_KERNELS}
    offenders = long_signatures(entry)
    assert not offenders, (f"{len(offenders)} compiled functions take more than {MAX_POSITIONAL} positional parameters "
                           "(group them into records of granchain.backends.kernels.records): "
                           + ", ".join(f"{name} ({n})" for name, n in offenders.items()))


def test_the_signature_counter_flags_a_long_signature():
    """Negative control: the same helpers flag a compiled function of 9 positional parameters and
    pass one of 8 (neither is compiled: the count reads the Python signature)."""
    import numba

    @numba.njit
    def nine(a, b, c, d, e, f, g, h, i):
        return a

    @numba.njit
    def eight(a, b, c, d, e, f, g, h, *rest, key=0):
        return a

    assert positional_parameters(nine) == 9 and positional_parameters(eight) == 8
    assert long_signatures({"nine": nine, "eight": eight}) == {"nine": 9}


# -- 3. a new model parameter reaches the kernels through one place ------------------------------------
MODEL_FIELD_SCRIPT = textwrap.dedent(
    """
    import collections, inspect, json, sys, traceback
    import numba
    import numpy as np
    import granchain as gc
    from granchain.backends import numba_backend
    from granchain.backends.kernels import dispatch, peaks, records, rkloop, verlet
    from granchain.backends.kernels.forces import power_code

    assert numba.config.DISABLE_JIT and inspect.isfunction(dispatch.dp5_chain)
    PROBE = 0.125
    seen = []

    # Observe the model's parameters where the step loops hand them on (the kernels of rkloop.rk_kernel
    # and verlet.verlet_integrate call peaks.initial_force_records(x, v, model, g, out, contacts)).
    def observed(original):
        def initial_force_records(x, v, model, g, out, contacts):
            seen.append(getattr(model.params, "probe", "absent"))
            return original(x, v, model, g, out, contacts)
        return initial_force_records

    rkloop.initial_force_records = observed(peaks.initial_force_records)
    verlet.initial_force_records = observed(peaks.initial_force_records)

    chain = gc.decorated([0.2, 0.3])
    grid = np.linspace(0.0, 6.0, 13)
    INTEGRATORS = {"dp5": gc.DP5(), "rkn4": gc.RKN4(), "verlet": gc.Verlet(dt=2e-3), "ensemble": "ensemble"}

    def run(integrator):
        seen.clear()
        try:
            if integrator == "ensemble":  # the batch kernel: Batch -> Model per realisation
                ds = gc.run_ensemble(3, realizations=2, chunk_size=2, seed=4, chains="decorated", progress=False,
                                     integrator=gc.DP5())
                return dict(error=None, seen=list(seen), status=int(ds["status"].values.max()),
                            peak_velocity=ds["peak_velocity"].values.tolist(), peak_time=ds["peak_time"].values.tolist(),
                            velocity=ds["mean_velocity"].values.tolist(), n_steps=ds["n_steps"].values.tolist())
            r = gc.simulate(chain, integrator, t_grid=grid)
        except Exception as e:
            where = traceback.extract_tb(e.__traceback__)[-1]
            return dict(error=f"{type(e).__name__}: {e} (at {where.filename.split('granchain')[-1]}:{where.lineno}: "
                              f"{where.line})", seen=list(seen))
        return dict(error=None, seen=list(seen), status=int(r.status), peak_velocity=r.peak_velocity.tolist(),
                    peak_time=r.peak_time.tolist(), velocity=r.velocity.tolist(), positions=r.positions.tolist(),
                    velocities=r.velocities.tolist(), n_steps=r.n_steps, t_end=r.t_end, energy_error=r.energy_error)

    plain = {name: run(i) for name, i in INTEGRATORS.items()}

    # The change under test: one more field in records.Params, the model's scalars (every module
    # that imported the name sees the new record, as after editing records.py) ...
    Old = records.Params
    New = collections.namedtuple("Params", Old._fields + ("probe",), defaults=tuple(Old._field_defaults.values()) + (0.0,))
    patched = []
    for module in list(sys.modules.values()):
        if getattr(module, "__name__", "").startswith("granchain") and getattr(module, "Params", None) is Old:
            module.Params = New
            patched.append(module.__name__)
    # ... and the one place that fills it.
    original_model_params = numba_backend.model_params

    def model_params(chain):
        return original_model_params(chain)._replace(probe=PROBE)  # (the original fills today's fields)
    numba_backend.model_params = model_params

    extended = {name: run(i) for name, i in INTEGRATORS.items()}
    print(json.dumps(dict(probe=PROBE, patched=patched, plain=plain, extended=extended)))
    """
)


@pytest.fixture(scope="module")
def model_field_run():
    """The script's JSON, run with NUMBA_DISABLE_JIT=1 from the repository's root. (Not
    ``conftest.run_without_jit``: that asserts the script exits 0, and a traceback inside the
    kernels is reported in the JSON instead, so that the failing test can say where it stopped.)"""
    env = dict(os.environ, NUMBA_DISABLE_JIT="1")
    proc = subprocess.run([sys.executable, "-c", MODEL_FIELD_SCRIPT], env=env, cwd=Path(__file__).parents[1],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_model_field_harness_control(model_field_run):
    """Control for the test below: with the records as they are, the observation hook is reached in
    every compiled method and in the batch kernel (it sees Params without the new field) and the runs
    succeed; and the patch replaced the record in ``records`` and ``numba_backend`` (the one place
    that fills it)."""
    for name, run in model_field_run["plain"].items():
        assert run["error"] is None and run["status"] == 0, (name, run["error"])
        assert run["seen"] and set(run["seen"]) == {"absent"}, (name, run["seen"])
    assert {"granchain.backends.kernels.records", "granchain.backends.numba_backend"} <= set(model_field_run["patched"])


@pytest.mark.parametrize("integ_name", ["dp5", "rkn4", "verlet", "ensemble"])
def test_a_new_model_field_reaches_the_step_loop_untouched(model_field_run, integ_name):
    """A new model parameter needs one change: a field in ``records.Params`` (the model's scalars)
    and the line of ``numba_backend.model_params`` that fills it. No kernel signature, no call, no
    other record.

    Why this proves it: in a fresh interpreter with the JIT off (the kernels are then the very
    Python functions Numba compiles, looked up at call time, so the record can be swapped in as if
    ``records.py`` had been edited), ``records.Params`` gets a field ``probe`` (every module that
    imported the name sees the new record) and ``model_params`` fills it; nothing else changes. The
    run goes through the real paths (``simulate`` -> backend -> ``dispatch.chain_kernel``'s kernel -> the
    method's step loop; ``run_ensemble`` -> backend -> ``batch.integrate_batch`` -> a Model per
    realisation -> the same) and a hook on ``peaks.initial_force_records``, which the step loops of
    DP5, RKN4 (``rkloop.rk_kernel``) and Verlet call with the Model record they hold, must see the
    probe's value: the field travelled through every signature on the way. The results must be bitwise those
    of the unchanged record (nothing read a field by position that the new one shifted). Tuple
    unpacking and named-tuple construction have a fixed arity in the source whether compiled or not
    (Numba raises a TypingError where Python raises ValueError/TypeError), so what passes here passes
    compiled. The JIT-off run of a 5-granule chain takes about a second.
    """
    plain = model_field_run["plain"][integ_name]
    run = model_field_run["extended"][integ_name]
    assert run["error"] is None, f"{integ_name}: a Params with one more field does not reach the kernel: {run['error']}"
    assert run["seen"] and all(s == model_field_run["probe"] for s in run["seen"]), (
        f"{integ_name}: the step loop saw {run['seen']} instead of the new field's value {model_field_run['probe']}")
    for key in set(plain) - {"error", "seen"}:
        assert run[key] == plain[key], f"{integ_name}: {key} changed with the new field"


COMPILED_FIELD_SCRIPT = """
import json, sys
sys.path.insert(0, {root!r})
import numpy as np
import granchain as gc
assert gc.__file__.startswith({root!r}), gc.__file__
chain = gc.random_decorated(6, gc.Uniform(0.01, 0.4), seed=3)
r = gc.simulate(chain, gc.DP5(), t_grid=np.linspace(0.0, 20.0, 41))
ds = gc.run_ensemble(4, realizations=3, chunk_size=3, seed=2, chains="decorated", progress=False)
print(json.dumps(dict(peak_velocity=r.peak_velocity.tolist(), peak_time=r.peak_time.tolist(),
                      ensemble=ds["peak_time"].values.tolist())))
"""


@pytest.mark.slow
def test_a_new_params_field_compiles_and_reaches_the_forces(tmp_path):
    """The compiled counterpart of the test above, on a copy of the package: ``records.Params`` gets a
    field ``stiffening``, ``numba_backend.model_params`` fills it with 2, and the two Hertz force
    expressions of ``forces`` multiply by it; no other line changes. The kernels must compile
    (simulate and the parallel batch kernel) and the field must reach the forces: every contact
    twice as stiff. Physics check of that: with m x'' = c delta^(n-1) and v_1(0) = 1, x = a X and
    t = a T (velocities unchanged) leave the equation invariant when a^n = m / c, so doubling every
    c scales every time by 2^(-1/n) and leaves every velocity unchanged (Hertz: times x 0.758). Compared
    with the unchanged package's runs, to the integrators' accuracy."""
    root = tmp_path / "pkg"
    shutil.copytree(Path(gc.__file__).parent, root / "granchain", ignore=shutil.ignore_patterns("__pycache__"))
    kernels = root / "granchain" / "backends"
    edits = {
        kernels / "kernels" / "records.py": [('"damping", "yield_overlap"],\n                    defaults=(True, 0, 0.0))',
                                              '"damping", "yield_overlap", "stiffening"],\n                    defaults=(True, 0, 0.0, 1.0))')],
        kernels / "numba_backend.py": [("bool(law.clamp), damping, yield_overlap)", "bool(law.clamp), damping, yield_overlap, 2.0)")],
        kernels / "kernels" / "forces.py": [("if pw == POW_HERTZ:\n        return c * d * math.sqrt(d)",
                                             "if pw == POW_HERTZ:\n        return p.stiffening * c * d * math.sqrt(d)"),
                                            ("F[j + 1] = c[j] * d * math.sqrt(d)",
                                             "F[j + 1] = p.stiffening * c[j] * d * math.sqrt(d)")],
    }
    for path, pairs in edits.items():
        text = path.read_text()
        for old, new in pairs:
            assert text.count(old) == 1, f"the test edits {old!r} in {path.name}: update the test"
            text = text.replace(old, new)
        path.write_text(text)
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}

    def run(script_root):
        proc = subprocess.run([sys.executable, "-c", COMPILED_FIELD_SCRIPT.format(root=str(script_root))],
                              capture_output=True, text=True, cwd=tmp_path, env=env, timeout=900)
        assert proc.returncode == 0, proc.stderr[-3000:]
        return json.loads(proc.stdout.strip().splitlines()[-1])

    stiff = run(root)
    plain = run(Path(gc.__file__).parents[1])
    scale = 2.0 ** (-1.0 / 2.5)
    np.testing.assert_allclose(stiff["peak_velocity"], plain["peak_velocity"], rtol=2e-6)
    np.testing.assert_allclose(stiff["peak_time"], scale * np.asarray(plain["peak_time"]), rtol=0, atol=2e-5)
    np.testing.assert_allclose(stiff["ensemble"], scale * np.asarray(plain["ensemble"]), rtol=0, atol=2e-4)


def test_the_numba_backend_asks_the_initial_state_for_rest_ahead():
    """The kernels integrate only the granules the pulse has reached, exact only when the initial state
    declares the others at rest (``rest_ahead``): the Numba backend refuses one that does not, and the
    SciPy backend, which integrates every granule, runs it."""
    from granchain.model.contacts import Impulse

    class Moving(Impulse):  # a hypothetical initial state with granules ahead of the pulse in motion
        rest_ahead = False

    chain = gc.monodisperse(3)
    object.__setattr__(chain, "initial", Moving(1.0))
    with pytest.raises(ValueError, match="needs every other granule at rest"):
        get_backend("numba").check(gc.DP5(), chain)
    get_backend("scipy").check(gc.DOP853(), chain)
    get_backend("numba").check(gc.DP5(), gc.monodisperse(3))  # the paper's impulse declares it
