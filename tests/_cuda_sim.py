"""Checks of the CUDA backend run under Numba's CUDA simulator, one per process.

The simulator must be switched on (``NUMBA_ENABLE_CUDASIM=1``) before Numba's CUDA target is first
imported, so ``tests/test_cuda.py`` runs each check here in a subprocess and reads the JSON it prints:
``python tests/_cuda_sim.py CHECK [ARGS]``. The simulator runs a block's threads as Python threads, so
the chains are tiny.
"""

from __future__ import annotations

import json
import os
import sys
import warnings

import numpy as np
from numba import cuda

from granchain.backends.cuda.device import warp_any, warp_last


def batch(n_large: int, realizations: int, kind: str = "decorated", seed: int = 0):
    """The arrays ``integrate_batch`` takes, for the first realisations of ``RandomDecorated(n_large)``."""
    from granchain.families import RandomDecorated

    family = RandomDecorated(n_large)
    b = family.build(family.draw_batch(seed, np.arange(realizations)), kind)
    return (np.ascontiguousarray(b.masses, dtype=float), np.ascontiguousarray(b.stiffness, dtype=float), b.n,
            np.ascontiguousarray(b.initial_velocity, dtype=float), np.ascontiguousarray(b.observed, dtype=np.int64),
            np.ascontiguousarray(b.recorded_contacts()))


def outputs(R: int, K: int, C: int, T: int) -> dict:
    return {"peak_velocity": np.zeros((R, K)), "peak_time": np.zeros((R, K)), "peak_force": np.zeros((R, C)),
            "peak_force_time": np.zeros((R, C)), "peak_wall_force": np.zeros(R), "peak_wall_force_time": np.zeros(R), "status": np.zeros(R, np.int64),
            "n_steps": np.zeros(R, np.int64), "t_end": np.zeros(R), "energy_error": np.zeros(R),
            "sum_v": np.zeros((T, K), np.int64), "sum_v2": np.zeros((T, K), np.int64),
            "sum_wall": np.zeros(T, np.int64), "n_valid": np.zeros(1, np.int64), "dissipated_energy": np.zeros(R), "lags": None}


def integrator_of(spec: str):
    """The integrator named by ``spec``: a chain kind, for the ensembles' default ("decorated": windowed RKN4,
    "effective": windowed DP5), "damped" (the default for contacts that dissipate: DP5, relaxed zone, every granule
    to the end), "verlet:DT", or "rkn4:DT" / "dp5:DT" for a fixed step DT."""
    import granchain as gc
    from granchain.ensembles.run import ensemble_integrator

    name, _, dt = spec.partition(":")
    if name == "damped":
        return ensemble_integrator("decorated", conservative=False)
    if not dt:
        return ensemble_integrator(name)
    if name == "verlet":
        return gc.Verlet(float(dt))
    return {"rkn4": gc.RKN4, "dp5": gc.DP5}[name](fixed_step=float(dt))


def contact_of(spec: str | None):
    """The contact law named by ``spec``: None (the paper's elastic one), "kuwabara-kono:GAMMA" (clamped),
    "kuwabara-kono-unclamped:GAMMA", "viscous:GAMMA" (unclamped, the authors' form) or "plastic:YIELD_SPEED"
    (Thornton's elastic-plastic contacts)."""
    import granchain as gc

    if spec is None:
        return None
    name, _, value = spec.partition(":")
    return {"kuwabara-kono": lambda g: gc.Viscoelastic(g), "kuwabara-kono-unclamped": lambda g: gc.Viscoelastic(g, clamp=False),
            "viscous": lambda g: gc.Viscous(g), "plastic": lambda v: gc.ElasticPlastic(v)}[name](float(value))


def run_batch(backend, n_large: int, realizations: int, t_end: float, kind: str = "decorated", pulse_end=None,
              integrator: str = "decorated", contact: str | None = None, load: float = 0.0, lags=None) -> dict:
    """``integrator``: see :func:`integrator_of`; ``contact``: :func:`contact_of`; ``load``: a precompression F0 (such
    a chain runs to its time limit, here ``t_end``); ``lags``: the aligned pulse's (its sums ``sum_a``, ``sum_a2``)."""
    from granchain.solve.integrators import RunControls

    masses, stiffness, n, v0, observed, contacts = batch(n_large, realizations, kind)
    t_grid = np.arange(0.0, t_end, 0.5)
    out = outputs(realizations, observed.size, contacts.size, t_grid.size)
    if lags is not None:
        out["lags"] = np.asarray(lags, dtype=float)
        out["sum_a"] = np.zeros((out["lags"].size, observed.size), np.int64)
        out["sum_a2"] = np.zeros((out["lags"].size, observed.size), np.int64)
    law = contact_of(contact)
    model = {**({} if law is None else {"contact": law}), **({"static_force": load} if load else {})}
    backend.integrate_batch(integrator_of(integrator), masses, stiffness, n, v0, observed, contacts, t_grid=t_grid,
                            t_max=t_end if load else 200.0, controls=RunControls(), scale=2.0**30, out=out,
                            pulse_end=pulse_end, model=model or None)
    return {k: a.tolist() for k, a in out.items() if k != "lags"}


def compare(threads: int, exchange: str, n_large: int, realizations: int, t_end: float, windows: bool,
            repeat: bool = False, votes: bool = True, kind: str = "decorated", integrator: str = "decorated",
            contact: str | None = None, load: float = 0.0, lags=None) -> dict:
    """The CUDA backend and the CPU's Numba backend on the same batch: every per-realisation result and sum
    (``repeat``: the GPU run twice, ``"again"`` the second, with ``votes`` negated where the exchange is by
    shuffles (the shuffle trees against the warp votes: the same results); else ``"again"`` is None).
    ``kind``: the chains; ``integrator``: whose default method, ``contact``: their law, ``load``: their precompression,
    ``lags``: the aligned pulse's (``run_batch``)."""
    from granchain.backends import get_backend
    from granchain.backends.cuda import CudaBackend

    ends = np.linspace(6.0, t_end, n_large) if windows else None  # averaged-pulse windows closing one by one
    gpu = CudaBackend(threads, exchange=exchange, votes=votes)
    kw = {"pulse_end": ends, "kind": kind, "integrator": integrator, "contact": contact, "load": load, "lags": lags}
    first = run_batch(gpu, n_large, realizations, t_end, **kw)
    other = CudaBackend(threads, exchange=exchange, votes=not votes) if exchange == "shuffle" else gpu
    again = run_batch(other, n_large, realizations, t_end, **kw) if repeat else None
    cpu = run_batch(get_backend("numba"), n_large, realizations, t_end, **kw)
    return {"cuda": first, "again": again, "cpu": cpu}


def small_chain(radii, contact: str | None, load: float, wall: bool):
    """``gc.decorated(radii)`` with the law ``contact`` (:func:`contact_of`), a precompression ``load`` and a wall."""
    import granchain as gc

    chain = gc.decorated(radii)
    if contact is not None:
        chain = chain.replace(contact=contact_of(contact))
    if load:
        chain = chain.with_precompression(load)
    return chain.with_wall() if wall else chain


def versus_dop853(threads: int, wall: bool, method: str = "rkn4", contact: str | None = None, load: float = 0.0) -> dict:
    """``simulate(..., backend="cuda")`` with ``method`` ("rkn4" or "dp5" at rtol 1e-10, "verlet" at dt = 2.5e-4)
    and DOP853 on a small decorated chain (with a wall or a free end; ``contact``: its law, :func:`contact_of`;
    ``load``: a precompression F0). Also each contact's static force (``"static_force"``: F0 to rounding)."""
    import granchain as gc

    chain = small_chain([0.3, 0.05, 0.2], contact, load, wall)
    grid = np.linspace(0.0, 12.0, 25)
    from granchain.backends.cuda import CudaBackend

    res = {}
    method = gc.Verlet(2.5e-4) if method == "verlet" else {"rkn4": gc.RKN4, "dp5": gc.DP5}[method](1e-10, 1e-13)
    # A damped chain to a fixed end, so that the dissipated energies are of the same interval (the two
    # integrators see the pulse leave at instants that differ within their tolerances, and the granules
    # behind it keep dissipating).
    # A precompressed chain runs to its time limit (its contacts do not open): the same, shorter.
    end = {"stop": "t_max", "t_max": 15.0} if contact is not None or load else {}
    for name, kw in (("cuda", {"integrator": method, "backend": CudaBackend(threads)}),
                     ("dop853", {"integrator": "dop853"})):
        r = gc.simulate(chain, t_grid=grid, **kw, **end)
        res[name] = {"status": int(r.status), "peak_velocity": r.peak_velocity.tolist(), "peak_time": r.peak_time.tolist(),
                     "grid": r.velocity.tolist(), "energy_error": float(r.energy_error),
                     "peak_force": np.asarray(r.peak_force).tolist(), "dissipated_energy": float(r.dissipated_energy),
                     "peak_force_time": np.asarray(r.peak_force_time).tolist(),
                     "wall_force": None if r.wall_force is None else np.asarray(r.wall_force).tolist(),
                     "positions": np.asarray(r.positions).tolist(), "t_end": float(r.t_end)}
    c, n = chain.stiffness, chain.n
    res["static_force"] = (c * chain.overlaps ** (n - 1.0)).tolist()
    return res


def _votes_kernel(values, last, any_):
    """Each lane's ``warp_last`` and ``warp_any`` of ``values`` (a module-level function: the simulator swaps the
    ``cuda`` of a kernel's module globals for its fake one)."""
    lane = cuda.threadIdx.x
    last[lane] = warp_last(values[lane])
    any_[lane] = warp_any(1 if values[lane] >= 0 else 0)


def votes(patterns: list) -> dict:
    """The warp votes of ``backends.cuda.device`` over one warp, for each pattern of 32 lane values: what
    ``warp_last`` and ``warp_any`` give every lane."""
    from granchain.backends.cuda import simulator

    simulator.install()
    kernel = cuda.jit(_votes_kernel)
    got = {"last": [], "any": []}
    for pattern in patterns:
        values = np.asarray(pattern, dtype=np.int64)
        last = np.zeros(32, dtype=np.int64)
        any_ = np.zeros(32, dtype=np.int64)
        kernel[1, 32](values, last, any_)
        got["last"].append(last.tolist())
        got["any"].append(any_.tolist())
    return got


def refusals() -> dict:
    """What the CUDA backend refuses, each with the message it gives (fast: refused before any kernel)."""
    import granchain as gc
    from granchain.backends.cuda import CudaBackend

    backend = CudaBackend(1)
    chain = gc.decorated([0.3, 0.05])
    cases = {
        "dop853": lambda: gc.simulate(chain, "dop853", backend=backend),
        "yielding contacts with RKN4": lambda: gc.simulate(chain.replace(contact=gc.ElasticPlastic(0.5)), "rkn4",
                                                          backend=backend),
        "damping with RKN4": lambda: gc.simulate(chain.with_dissipation(0.1), "rkn4", backend=backend),
    }
    got = {}
    for name, call in cases.items():
        try:
            call()
            got[name] = "accepted"
        except ValueError as exc:
            got[name] = str(exc)
    return got


def rest_ahead(threads: int) -> dict:
    """A precompressed decorated chain (F0 = 1e-3, 8 large granules) on the GPU backend to t = 2, before the pulse
    has crossed two large granules: the final positions and velocities, which ahead of the pulse must be exactly 0
    (each contact's dynamic force is its force less its static force by the same arithmetic, exactly 0 in the static
    state); and, as a negative control, each contact's static force c delta0^(n-1) less F0 (rounding, not 0: an
    integration that subtracted F0 itself would set the granules ahead moving)."""
    import granchain as gc
    from granchain.backends.cuda import CudaBackend

    chain = gc.decorated([0.3, 0.05, 0.2, 0.37, 0.11, 0.02, 0.25, 0.4]).with_precompression(1e-3)
    with warnings.catch_warnings():  # (the pulse is still rising at t = 2: PEAK_AT_END, as it should be)
        warnings.simplefilter("ignore", RuntimeWarning)
        r = gc.simulate(chain, gc.RKN4(), t_max=2.0, backend=CudaBackend(threads))
    residual = chain.stiffness * chain.overlaps ** (chain.n - 1.0) - chain.static_force
    return {"status": int(r.status), "t_end": float(r.t_end), "positions": np.asarray(r.positions).tolist(),
            "velocities": np.asarray(r.velocities).tolist(), "residual": residual.tolist()}


def striker(threads: int) -> dict:
    """A decorated chain precompressed by F0 = 1e-3, struck by a striker of mass 2 and ending in a wall, simulated to
    t = 15 with RKN4(1e-10) on the GPU backend and on the CPU's: each one's steps, peaks and energy error."""
    import granchain as gc
    from granchain.backends.cuda import CudaBackend

    chain = gc.decorated([0.3, 0.05, 0.2]).with_precompression(1e-3).with_striker(mass=2.0).with_wall()
    res = {}
    for name, kw in (("cuda", {"backend": CudaBackend(threads)}), ("cpu", {})):
        r = gc.simulate(chain, gc.RKN4(1e-10, 1e-13), t_grid=np.linspace(0.0, 12.0, 25), t_max=15.0, **kw)
        res[name] = {"status": int(r.status), "n_steps": int(r.n_steps), "peak_velocity": r.peak_velocity.tolist(),
                     "peak_force": np.asarray(r.peak_force).tolist(), "energy_error": float(r.energy_error),
                     "wall_force": np.asarray(r.wall_force).tolist()}
    return res


def sensors(threads: int, integrator: str, contact: str | None = None, wall: bool = False, load: float = 0.0,
            repeats: int = 1, t_end: float = 14.0) -> dict:
    """Force sensors (granules 2 and 5, and with a wall the last) of a decorated chain of 6 ``repeats`` large granules
    (on a grid to ``t_end``) on the
    GPU backend and on the CPU's: each one's status, steps, sensor forces and wall force on the grid. ``integrator``:
    :func:`integrator_of` (e.g. "decorated" for the ensembles' RKN4, "verlet:0.01"); ``contact``: :func:`contact_of`;
    ``load``: a precompression (to t = 15)."""
    import granchain as gc
    from granchain.backends.cuda import CudaBackend

    chain = small_chain([0.3, 0.05, 0.2, 0.37, 0.11, 0.25] * repeats, contact, load, wall)
    labels = [2, 5] + ([chain.size - 1] if wall else [])  # (the wall is the last "granule" of the chain)
    integ = integrator_of(integrator)
    end = {"t_max": 15.0, "stop": "t_max"} if load else {}
    res = {}
    for name, kw in (("cuda", {"backend": CudaBackend(threads)}), ("cpu", {})):
        r = gc.simulate(chain, integ, t_grid=np.linspace(0.0, t_end, int(4 * t_end) + 1), sensors=labels, **end, **kw)
        res[name] = {"status": int(r.status), "n_steps": int(r.n_steps),
                     "sensor_force": r.sensor_force.tolist(),  # (NaN behind a trailing window: JSON's NaN)
                     "wall_force": None if r.wall_force is None else np.asarray(r.wall_force).tolist(),
                     "peak_velocity": r.peak_velocity.tolist()}
    return res


def unavailable() -> dict:
    """Without the simulator and without a GPU: the error a user gets."""
    from granchain.backends import BackendUnavailable, get_backend

    try:
        get_backend("cuda")
    except BackendUnavailable as exc:
        return {"error": str(exc)}
    return {"error": None}


def model_ensemble(threads: int, store: str, model: str = "damped") -> dict:
    """``run_ensemble`` of a family of real contacts (``RandomDecorated(3)``, both chain kinds, 3 realisations;
    ``model`` "damped": Kuwabara-Kono contacts, "precompressed": a static load F0 = 1e-3 and a wall, "plastic":
    Thornton's yielding contacts, yield speed 0.3) with the GPU
    backend, written to ``store`` and read back, and the same on the CPU in memory: each one's integrators,
    dissipated energies, energy errors, peak velocities and end times (and, with a wall, its peak force)."""
    import xarray as xr

    import granchain as gc
    from granchain.backends.cuda import CudaBackend

    if model == "damped":
        family = gc.RandomDecorated(3, contact=gc.Viscoelastic(0.05))
    elif model == "plastic":
        family = gc.RandomDecorated(3, contact=gc.ElasticPlastic(0.3))
    else:
        family = gc.RandomDecorated(3, static_force=1e-3, wall=True)
    kw = {"realizations": 3, "chains": "both", "progress": False, "pulse_window": "full"}
    gc.run_ensemble(family, out=store, backend=CudaBackend(threads), **kw)
    res = {}
    for name, ds in (("cuda", xr.open_dataset(store, engine="zarr")), ("cpu", gc.run_ensemble(family, out=None, **kw))):
        res[name] = {"integrator": str(ds.attrs.get("integrator")), "backend": ds.attrs.get("backend"),
                     **{k: ds[k].transpose("chain", "realization", ...).values.tolist()
                        for k in ("dissipated_energy", "energy_error", "peak_velocity", "status", "t_end",
                                  "peak_wall_force") if k in ds}}
    return res


def compiled_exponent(threads: int) -> dict:
    """Three chains of radii [0.3, 0.05, 0.2] run to t = 5 (rtol 1e-6) on the GPU backend with the exponent read at
    run time and with it compiled in (``CudaBackend(compiled_exponent=True)``, one backend for all three, in this
    order): Hertz's with RKN4, the same with viscoelastic damping (DP5; the damped force's own powers of n), and
    n = 3 with RKN4 (after the Hertz kernel is compiled: a kernel cache keyed without n would run it with 5/2).
    Each one's steps, peaks and final state; the kernels each backend compiled; and what ``make_kernel`` says to
    an exponent of 1."""
    import granchain as gc
    from granchain.backends.cuda import CudaBackend

    hertz = gc.decorated([0.3, 0.05, 0.2])
    cases = {"hertz": (hertz, gc.RKN4(1e-6, 1e-9)), "damped": (hertz.with_dissipation(0.1), gc.DP5(1e-6, 1e-9)),
             "n=3": (gc.decorated([0.3, 0.05, 0.2], n=3.0), gc.RKN4(1e-6, 1e-9))}
    res = {}
    for name, backend in (("read", CudaBackend(threads)), ("compiled", CudaBackend(threads, compiled_exponent=True))):
        res[name] = {}
        for case, (chain, integrator) in cases.items():
            with warnings.catch_warnings():  # (a pulse still rising at t = 5: PEAK_AT_END)
                warnings.simplefilter("ignore", RuntimeWarning)
                r = gc.simulate(chain, integrator, t_max=5.0, backend=backend)
            res[name][case] = {"status": int(r.status), "n_steps": int(r.n_steps),
                               "peak_velocity": r.peak_velocity.tolist(), "peak_force": np.asarray(r.peak_force).tolist(),
                               "positions": np.asarray(r.positions).tolist(), "velocities": np.asarray(r.velocities).tolist()}
        res[name]["kernels"] = len(backend._kernels)
    from granchain.backends.cuda.kernel import make_kernel

    try:
        make_kernel(1, 16, exponent=1.0)
        res["exponent 1"] = "accepted"
    except ValueError as exc:
        res["exponent 1"] = str(exc)
    return res


CHECKS = {"compare": compare, "versus_dop853": versus_dop853, "votes": votes, "refusals": refusals,
          "unavailable": unavailable, "model_ensemble": model_ensemble, "rest_ahead": rest_ahead,
          "striker": striker, "sensors": sensors, "compiled_exponent": compiled_exponent}

if __name__ == "__main__":
    name, args = sys.argv[1], [json.loads(a) for a in sys.argv[2:]]
    if name != "unavailable" and os.environ.get("NUMBA_ENABLE_CUDASIM") != "1":
        sys.exit("run with NUMBA_ENABLE_CUDASIM=1")
    print("RESULT " + json.dumps(CHECKS[name](*args)))
