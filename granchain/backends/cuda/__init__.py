"""The CUDA backend: the ensembles' RKN4, DP5 and Verlet on an NVIDIA GPU (Numba's CUDA target).

``CudaBackend`` runs batches of chains (``run_ensemble(..., backend="cuda")``, the design evaluator,
validity maps) and single chains (``simulate(..., backend="cuda")``) with the kernels of
``granchain.backends.cuda.kernel`` (its docstring says why a chain is a block of threads, not one
thread). It runs what the CPU kernels run for elastic chains: RKN4 and DP5 with the same step control
(or a fixed step), velocity Verlet, the same peaks, grid samples and stop rule, and DP5 for chains whose
contacts dissipate (Kuwabara & Kono's viscoelastic law, the viscous law of Rosas et al.), with the energy
they dissipate integrated and its error controlled as the CPU does, so its per-realisation
results agree with the CPU backend's within the accuracy contract (not bit for bit: the GPU's fused
multiply-adds round differently, and DP5's peaks are read on another interpolant, ``kernel.make_kernel``),
and its sums of the averaged pulse are fixed-point integers added in a fixed order, so a run repeated
gives the same bits. Precompressed chains run as the CPU runs them (in displacements from the static state,
to their time limit), and so do contacts that yield (Thornton's elastic-plastic law, with DP5: each contact's
history kept on the GPU, a step retaken where a contact turns from loading to unloading). It samples force
sensors on the grid as the CPU does, and sums the aligned pulse (each realisation's velocities about its own
peak times) from the grid velocities it holds. What it has no kernel for (another contact law or integrator, a
chain not at rest ahead of the pulse) is refused with an error that names the CPU backend.

Needs an NVIDIA GPU and Numba's CUDA target (``pip install granchain[cuda]``, which installs
``numba-cuda``). Under ``NUMBA_ENABLE_CUDASIM=1`` the same kernels run in Numba's simulator on a CPU
(slowly: the tests use it on tiny chains).
"""

from __future__ import annotations

import functools
import time

import numpy as np

from .. import Backend, BackendUnavailable, effective_integrator, longest_first

__all__ = ["CudaBackend", "available"]

#: The layouts: threads per chain. 32 (a warp) is the default, measured fastest for the paper's chains
#: (benchmarks/bench_gpu.py); 1 is one thread per chain; the small groups exercise the exchange between
#: threads cheaply in the simulator.
LAYOUTS = (1, 2, 4, 8, 16, 32, 64)
#: Chains of one launch at most, so that the grid velocities (R x T x K doubles) stay near 8 GB: the
#: paper's 30,000 N = 26 chains in one launch (4.8 GB). Each launch waits for its slowest chain, so fewer,
#: larger launches waste less.
GRID_BYTES = 8_000_000_000
#: Threads per block for one thread per chain.
BLOCK_THREADS = 64


def available() -> tuple[bool, str]:
    """(True, "") when the CUDA backend can run here; else (False, why)."""
    try:
        from numba import cuda
    except ImportError as exc:  # pragma: no cover - numba without its CUDA target
        return False, f"Numba's CUDA target is not installed ({exc}): pip install granchain[cuda]"
    except Exception as exc:  # noqa: BLE001 - an installed numba-cuda that breaks on import
        # (as a numba-cuda release that calls np.row_stack does under NumPy 2.5, which removed it: AttributeError)
        return False, (f"Numba's CUDA target is installed but fails to import ({type(exc).__name__}: {exc}); "
                       f"it may not support NumPy {np.__version__}: upgrade numba-cuda, or install a NumPy it supports")
    try:
        if cuda.is_available():
            return True, ""
    except Exception as exc:  # noqa: BLE001 - a broken driver raises anything
        return False, f"the CUDA driver could not be loaded ({exc})"
    return False, "no NVIDIA GPU found (numba.cuda.is_available() is False)"


class CudaBackend(Backend):
    """RKN4, DP5 and Verlet for elastic chains, DP5 for damped and yielding ones, on an NVIDIA GPU.

    Parameters
    ----------
    threads_per_chain : int
        The layout: threads that integrate one chain, one of ``LAYOUTS`` (1, 2, 4, 8, 16, 32, 64). 32, one warp
        a chain, is the default and measured fastest for the paper's chains; 1 is one thread a chain.
    max_registers : int, optional
        A cap on the registers per thread: more chains resident on a multiprocessor, against spills to local
        memory (``benchmarks/gpu_registers.py`` says what ptxas allots; ``benchmarks/bench_gpu.py`` times it).
    exchange : {"shuffle", "shared"}, optional
        How a chain's threads share values: warp shuffles (the default at 32 threads, and only there) or shared
        memory and barriers (the default otherwise).
    votes : bool
        With the shuffle exchange, whether its integer reductions are warp votes (the default) or shuffle trees
        (``kernel.make_kernel``): the same results.
    compiled_exponent : bool
        Compile each chain's exponent n into its kernel (one kernel per n, ``make_kernel``'s ``exponent``), with
        the same results. For Hertz's n = 5/2 the general power's code (libdevice's ``pow``) leaves the kernel,
        which frees registers on the decorated chains' kernel (ptxas, sm_90: 255 registers and spills without,
        232 and none with) and takes a few from the default one (196 to 203). Which is faster is for a GPU to
        say (``benchmarks/bench_gpu.py``, layouts ``32/n`` and ``32/n/200``); off by default until then.

    Raises
    ------
    BackendUnavailable
        Without an NVIDIA GPU or Numba's CUDA target; the message says what to install or to use the CPU backend.
    ValueError
        A layout or exchange it has no kernel for.

    Notes
    -----
    ``timings`` receives ``{"kernel_s", "realizations", "launches"}`` for every batch: the device time of the
    integration and the reduction, synchronised, transfers excluded.
    """

    name = "cuda"
    #: The elastic power law, the damped laws DP5 integrates (``kernel.make_kernel``'s ``damped``) and Thornton's
    #: yielding contacts (its ``plastic``).
    law_forms = ("power-law", "kuwabara-kono", "viscous", "thornton")
    #: Yielding contacts' histories live on the GPU and come back with the final state (``integrate``'s ``history``).
    carries_history = True
    #: The integrators it has kernels for (``Integrator.name``).
    methods = ("rkn4", "dp5", "verlet")
    #: The methods a caller's default may pick on it: RKN4 alone, the one measured on a GPU
    #: (benchmarks/bench_gpu.py). The ensembles and the design evaluator give every elastic chain kind RKN4
    #: here (the decorated chains' CPU default; the others' is DP5, which runs when it is asked for).
    default_methods = ("rkn4",)
    #: Realisations per store chunk (one launch each): a launch needs thousands of chains to fill the GPU
    #: (one block per chain, up to 32 blocks on each of an H100's 132 multiprocessors) and lasts until its
    #: slowest chain ends, so the paper's 30,000 go in one.
    default_chunk_size = 30_000

    def __init__(self, threads_per_chain: int = 32, max_registers: int | None = None, exchange: str | None = None,
                 votes: bool = True, compiled_exponent: bool = False):
        ok, why = available()
        if not ok:
            raise BackendUnavailable(f"the cuda backend cannot run here: {why}. Use the CPU backend "
                                     "(backend='cpu', or --backend cpu), or a machine with an NVIDIA GPU and "
                                     "`pip install granchain[cuda]`")
        if threads_per_chain not in LAYOUTS:
            raise ValueError(f"threads_per_chain must be one of {LAYOUTS}, got {threads_per_chain!r}")
        if exchange is None:
            exchange = "shuffle" if threads_per_chain == 32 else "shared"
        if exchange not in ("shuffle", "shared") or (exchange == "shuffle" and threads_per_chain != 32):
            raise ValueError(f"exchange must be 'shuffle' (32 threads per chain: one warp) or 'shared', got {exchange!r} "
                             f"with {threads_per_chain} threads per chain")
        from . import simulator

        simulator.install()  # warp shuffles for Numba's simulator (a no-op on a GPU)
        self.threads_per_chain = int(threads_per_chain)
        self.max_registers = max_registers
        self.exchange = exchange
        self.votes = bool(votes) and exchange == "shuffle"
        self.compiled_exponent = bool(compiled_exponent)
        self.timings: list = []
        self._kernels: dict = {}

    # ------------------------------------------------------------------ what it runs
    def check(self, integrator, chain) -> None:
        """RKN4, DP5 or Verlet on an elastic (power-law) chain, or DP5 on a damped one (Kuwabara-Kono or
        viscous contacts) or a yielding one (Thornton's), precompressed or not, at rest ahead of the pulse; then
        :meth:`Backend.check` (which refuses RKN4 and Verlet for damped and yielding contacts). Each refusal names
        the CPU backend, which runs all of these."""
        cpu = "; use the CPU backend (backend='cpu')"
        if type(chain.contact).__dict__.get("form") not in self.law_forms:
            raise ValueError(f"the cuda backend has no kernel for the contact law {chain.contact!r} (elastic power-law, "
                             f"Kuwabara-Kono viscoelastic, viscous and Thornton's elastic-plastic contacts only){cpu}")
        if integrator.name not in self.methods:
            raise ValueError(f"the cuda backend runs RKN4, DP5 and Verlet (granchain.RKN4, granchain.DP5, "
                             f"granchain.Verlet), not {integrator.name}{cpu}")
        if not chain.initial.rest_ahead:
            raise ValueError(f"the cuda backend starts every granule but the first at rest; the initial state "
                             f"{chain.initial!r} does not{cpu}")
        super().check(integrator, chain)

    def _kernel(self, M: int, n: float, method: str, fixed: bool, damped: bool, precompressed: bool,
                plastic: bool = False, sensed: bool = False):
        from .kernel import make_kernel

        L = self.threads_per_chain
        G = max(1, -(-M // L))
        G = 1 << (G - 1).bit_length() if L > 1 else -(-G // 16) * 16  # few compiled variants
        exponent = float(n) if self.compiled_exponent else None  # (n in the key only when it is in the code)
        key = (L, G, method, fixed, damped, precompressed, plastic, sensed, exponent)
        if key not in self._kernels:
            self._kernels[key] = make_kernel(L, G, self.max_registers, self.exchange == "shuffle", self.votes, method, fixed,
                                             damped, precompressed, plastic, sensed, exponent)
        return L, G, self._kernels[key]

    # ------------------------------------------------------------------ runs
    def integrate(self, integrator, chain, x, v, *, t_grid, t_max, stop_at_exit, controls, sensed=None, history=None):
        """:meth:`Backend.integrate` of one chain: a batch of one row on the GPU. ``history`` (yielding contacts):
        the contacts' yield overlaps on entry (``history_state``: several materials give each contact its own), their
        largest overlaps on return, as the CPU's."""
        from ..kernels.records import (
            INFO_DISSIPATED,
            INFO_EXIT,
            INFO_FROZEN_POTENTIAL,
            INFO_REJECTED,
            INFO_SIZE,
            INFO_STEPS,
            INFO_T_END,
            INFO_WINDOW_START,
        )

        self.check(integrator, chain)
        if np.any(x != 0.0) or np.count_nonzero(v[1:]):
            raise ValueError("the cuda backend starts from rest with granule 1 struck; use the CPU backend (backend='cpu')")
        res = self._run(integrator, chain, chain.masses[None], chain.stiffness[None], np.array([v[0]]),
                        chain.observed, t_grid, np.array([float(t_max)]), stop_at_exit, controls, None,
                        history=None if history is None else np.asarray(history, dtype=float)[None], sensed=sensed)
        info = np.zeros(INFO_SIZE)
        info[INFO_T_END], info[INFO_STEPS] = res["t_end"][0], res["n_steps"][0]
        info[INFO_REJECTED] = res["n_rejected"][0]
        info[INFO_EXIT] = res["exit_time"][0]
        info[INFO_WINDOW_START], info[INFO_FROZEN_POTENTIAL] = res["window_start"][0], res["frozen_potential"][0]
        info[INFO_DISSIPATED] = res["dissipated_energy"][0]
        x[:], v[:] = res["positions"][0], res["velocities"][0]
        if history is not None and res["history"] is not None:
            history[:] = res["history"][0]
        grid_f = res["wall_force"][0] if res["wall_force"] is not None else np.zeros(t_grid.size)
        grid_c = res["sensor_force"][0] if res["sensor_force"] is not None else np.zeros((t_grid.size, 0))
        return (int(res["status"][0]), info, res["peak_velocity"][0], res["peak_time"][0], res["velocity"][0],
                res["peak_force"][0], res["peak_force_time"][0], grid_f, grid_c)

    def integrate_batch(self, integrator, masses, stiffness, n, initial_velocity, observed, contacts, *, t_grid, t_max,
                        controls, scale: float, out: dict, model=None, pulse_end=None) -> None:
        from .. import aligned_outputs, batch_chain

        lags = aligned_outputs(out, observed.shape[0])[0]
        integrator.check_chains(masses, stiffness, n, initial_velocity)
        first = batch_chain(masses[0], stiffness[0], n, initial_velocity[0], observed, model)
        self.check(integrator, first)
        R = masses.shape[0]
        limits = np.ascontiguousarray(np.broadcast_to(np.asarray(t_max, dtype=float), (R,)))
        res = self._run(integrator, first, masses, stiffness, initial_velocity, observed, t_grid, limits,
                        first.ends_at_exit, controls, pulse_end, scale=scale, sums=out, lags=lags)
        wall = first.boundary.wall
        out["peak_velocity"][:], out["peak_time"][:] = res["peak_velocity"], res["peak_time"]
        contacts = np.asarray(contacts, dtype=np.int64)
        out["peak_force"][:] = res["peak_force"][:, contacts]
        out["peak_force_time"][:] = res["peak_force_time"][:, contacts]
        if wall:
            out["peak_wall_force"][:] = res["peak_force"][:, -1]
            out["peak_wall_force_time"][:] = res["peak_force_time"][:, -1]
        out["status"][:], out["n_steps"][:], out["t_end"][:] = res["status"], res["n_steps"], res["t_end"]
        out["energy_error"][:] = _energy_errors(first, masses, stiffness, initial_velocity, res)
        if "dissipated_energy" in out:
            out["dissipated_energy"][:] = res["dissipated_energy"]
        out["n_valid"][0] += int(np.count_nonzero(res["status"] == 0))

    def _run(self, integrator, chain, masses, stiffness, v0, observed, t_grid, t_max, stop_at_exit, controls,
             pulse_end, *, scale=None, sums=None, history=None, lags=None, sensed=None) -> dict:
        """Integrate the rows on the GPU in launches of at most :data:`GRID_BYTES` of grid velocities. Returns
        the per-row arrays (and, with ``sums``, adds the averaged pulse's fixed-point sums into it, and with ``lags``
        the aligned pulse's, ``sum_a`` and ``sum_a2``: ``kernels.aligned``). Yielding
        contacts: ``history`` (rows x contacts) their yield overlaps (None: c^2 times the law's reference yield
        overlap, spheres of one material, as the CPU's ensembles), and each row's final histories returned.
        ``sensed``: contacts (0-based) whose total forces are sampled on the grid (``"sensor_force"``, rows x grid
        times x contacts)."""
        from numba import cuda

        from ..kernels.forces import DAMPING_VISCOUS
        from ..numba_backend import model_params
        from .kernel import P_SIZE

        ran = effective_integrator(integrator, chain)
        R, M = masses.shape
        observed = np.asarray(observed, dtype=np.int64)
        K, T = observed.size, t_grid.size
        obs_of = np.full(M, -1, dtype=np.int64)
        obs_of[observed] = np.arange(K)
        ends = np.full(K, np.inf) if pulse_end is None else np.asarray(pulse_end, dtype=float)
        prm = np.zeros(P_SIZE)
        if ran.name == "verlet":  # a fixed step, no tolerances, no goal-oriented zones, no averaged-pulse windows
            fixed, steps, pulse_end = True, (0.0, 0.0, ran.dt, 0, 1.0, 0), None  # (as the CPU's Verlet: kernels.verlet)
        else:
            fixed = ran.fixed_step is not None
            steps = (ran.rtol, ran.atol, ran.fixed_step if fixed else ran.first_step, ran.relaxed_lag or 0,
                     ran.relaxed_factor, ran.window_lag or 0)
        # The model's values as the CPU kernels take them (``numba_backend.model_params``, the one place they are filled).
        model = model_params(chain)
        damped = model.gamma > 0.0  # (a damped law with gamma = 0 is the elastic one)
        plastic = model.yield_overlap > 0.0  # Thornton's contacts (check: the only law with memory it runs)
        prm[:] = (*steps, controls.exit_margin, controls.peak_rtol, controls.max_steps, model.n,
                  float(bool(stop_at_exit)), float(model.wall), float(t_grid[-1]) if T else 0.0,
                  float(pulse_end is not None), model.gamma, float(model.damping == DAMPING_VISCOUS),
                  float(model.clamp), model.static_force, model.yield_overlap)
        # A precompressed chain runs without a trailing window (effective_integrator: its loaded far end licenses
        # none), which the kernel's static state relies on (its contacts never leave the integration).
        loaded = chain.precompression.applied
        assert not (loaded and steps[5]), "a precompressed chain runs without a trailing window"
        # Yielding contacts likewise (effective_integrator): the granules left behind would take their histories.
        assert not (plastic and (steps[3] or steps[5])), "yielding contacts run without goal-oriented zones"
        sensing = sensed is not None and len(sensed) > 0 and T > 0
        L, G, kernel = self._kernel(M, model.n, ran.name, fixed, damped, loaded, plastic, sensing)
        wall = chain.boundary.wall
        # Longest first: blocks start in index order, and a launch lasts until its slowest chain ends, so the
        # chains with the fastest oscillators (the most steps) go first. Rows are put back in order after.
        order = longest_first(masses, stiffness)
        masses, stiffness, v0, t_max = masses[order], stiffness[order], np.asarray(v0)[order], np.asarray(t_max)[order]
        if plastic:
            history = np.zeros((R, M - 1)) if history is None else np.asarray(history, dtype=float)[order]
        per = max(1, min(R, int(GRID_BYTES // max(1, T * K * 8))))
        const = [cuda.to_device(np.ascontiguousarray(a)) for a in (obs_of, observed, np.asarray(t_grid, float), ends, prm)]
        aligned = sums is not None and lags is not None and lags.size > 0 and T > 0 and K > 0
        d_lags = cuda.to_device(np.ascontiguousarray(lags, dtype=float)) if aligned else None
        # (each named as the results name it: ``RunRecord``, the ensembles' schema; the compressions stay on the device)
        res = {k: [] for k in KERNEL_OUTPUTS + ("history", "sensor_force") if k != "peak_compression"}
        d_sensed = cuda.to_device(np.ascontiguousarray(sensed, dtype=np.int64)) if sensing else ()
        elapsed = 0.0
        launches = 0
        for start in range(0, R, per):
            sl = slice(start, min(R, start + per))
            r = sl.stop - sl.start
            d_in = [cuda.to_device(np.ascontiguousarray(a[sl], dtype=float)) for a in (masses, stiffness, v0, t_max)]
            shapes = {"peak_velocity": (r, K), "peak_time": (r, K), "peak_force": (r, M - 1), "peak_force_time": (r, M - 1),
                      "peak_compression": (r, M - 1), "velocity": (r, T, K), "wall_force": (r, T if wall else 1)}
            d_out = {k: cuda.device_array(s, dtype=np.float64) for k, s in shapes.items()}
            for k in ("status", "n_steps", "n_rejected", "window_start"):
                d_out[k] = cuda.device_array(r, dtype=np.int64)
            for k in ("t_end", "exit_time", "frozen_potential", "dissipated_energy"):
                d_out[k] = cuda.device_array(r, dtype=np.float64)
            d_out["positions"] = cuda.device_array((r, M), dtype=np.float64)
            d_out["velocities"] = cuda.device_array((r, M), dtype=np.float64)
            # (in: the yield overlaps; out: the final histories. Other kernels: an empty tuple, no parameter)
            d_hist = cuda.to_device(np.ascontiguousarray(history[sl])) if plastic else ()
            d_grid_c = cuda.device_array((r, T, len(sensed)), dtype=np.float64) if sensing else ()
            extra = {"history": d_hist if plastic else None, "sensor_force": d_grid_c if sensing else None}
            blocks, threads = (r, L) if L > 1 else (-(-r // BLOCK_THREADS), BLOCK_THREADS)
            cuda.synchronize()
            t0 = time.perf_counter()
            kernel[blocks, threads](*d_in[:2], d_in[2], d_in[3], *const, *(d_out[k] for k in KERNEL_OUTPUTS), d_hist,
                                    d_sensed, d_grid_c)
            if sums is not None and T and K:
                d_sv = cuda.to_device(np.zeros((T, K), dtype=np.int64))
                d_sv2 = cuda.to_device(np.zeros((T, K), dtype=np.int64))
                sum_kernel("make_sum_kernel")[-(-(T * K) // 128), 128](d_out["velocity"], d_out["status"], float(scale),
                                                                        d_sv, d_sv2)
                if wall:
                    d_sf = cuda.to_device(np.zeros(T, dtype=np.int64))
                    sum_kernel("make_wall_sum_kernel")[-(-T // 128), 128](d_out["wall_force"], d_out["status"], float(scale),
                                                                          d_sf)
                if aligned:
                    d_sa = cuda.to_device(np.zeros((lags.size, K), dtype=np.int64))
                    d_sa2 = cuda.to_device(np.zeros((lags.size, K), dtype=np.int64))
                    sum_kernel("make_aligned_sum_kernel")[-(-(lags.size * K) // 128), 128](
                        d_out["velocity"], d_out["peak_time"], d_out["status"], const[2], d_lags, float(scale), d_sa, d_sa2)
            cuda.synchronize()
            elapsed += time.perf_counter() - t0
            launches += 1
            if sums is not None and T and K:
                sums["sum_v"] += d_sv.copy_to_host()
                sums["sum_v2"] += d_sv2.copy_to_host()
                if wall:
                    sums["sum_wall"] += d_sf.copy_to_host()
                if aligned:
                    sums["sum_a"] += d_sa.copy_to_host()
                    sums["sum_a2"] += d_sa2.copy_to_host()
            for k in res:
                if k == "velocity" and sums is not None:
                    continue  # reduced on the device
                if k == "wall_force" and (not wall or sums is not None):
                    continue
                if k in extra:  # (outputs of some kernels only)
                    if extra[k] is not None:
                        res[k].append(extra[k].copy_to_host())
                    continue
                res[k].append(d_out[k].copy_to_host())
        self.timings.append({"kernel_s": elapsed, "realizations": R, "launches": launches})
        back = np.empty_like(order)
        back[order] = np.arange(R)
        joined = {k: (np.concatenate(a)[back] if a else None) for k, a in res.items()}
        joined["status"] = joined["status"].astype(np.int64)
        return joined


#: The kernel's output arrays, in the order of its parameters (``kernel.make_kernel``), by the names the results
#: give them (``peak_compression``: each contact's compression at its recorded peak, for the root screen).
KERNEL_OUTPUTS = ("peak_velocity", "peak_time", "peak_force", "peak_force_time", "peak_compression", "velocity",
                  "wall_force", "status", "n_steps", "n_rejected", "t_end", "exit_time", "window_start",
                  "frozen_potential", "dissipated_energy", "positions", "velocities")


@functools.cache
def sum_kernel(name: str):
    """The reduction kernel ``name`` of ``sums`` (``"make_sum_kernel"``: the averaged pulse, ``"make_wall_sum_kernel"``:
    the wall force, ``"make_aligned_sum_kernel"``: the aligned pulse), made once per process."""
    from . import sums

    return getattr(sums, name)()


def _energy_errors(chain, masses, stiffness, v0, res) -> np.ndarray:
    """(E_end + E_dissipated - E_0) / E_0 per row, by the CPU kernels' own function
    (``kernels.forces.energy_errors``: one definition of each realisation's energy balance for both backends),
    from the final states, trailing windows, frozen potentials, dissipated energies and (yielding contacts)
    histories the GPU returned."""
    from ..kernels.forces import energy_errors
    from ..numba_backend import model_params

    def rows(a, dtype=float):
        return np.ascontiguousarray(a, dtype=dtype)

    R = masses.shape[0]
    history = res["history"] if chain.contact.history else np.zeros((R, 0))
    out = np.empty(R)
    energy_errors(rows(res["positions"]), rows(res["velocities"]), rows(masses), rows(stiffness), model_params(chain),
                  rows(res["window_start"], np.int64), rows(res["frozen_potential"]), rows(res["dissipated_energy"]),
                  rows(history), rows(v0), out)
    return out
