"""The Numba backend: binds DP5, RKN4 and Verlet and a chain to the compiled kernels (``kernels``).

This is the only place that knows both sides: it turns an integrator's settings into a
``records.Method`` (kind and float64 params), a chain into a ``records.Model``, the run controls into
a ``records.Run``, allocates the outputs and calls the entry point ``kernels.dispatch.chain_kernel``
picks (one chain) or ``kernels.batch.integrate_batch`` with it (a parallel batch of chains of one size).

Every array the kernels read is passed writable and C-contiguous (:func:`kernel_array`; a chain's own
arrays are read-only): Numba compiles a function once per combination of argument types, read-only
being one, so ``simulate`` and the ensembles share one compiled entry point per method and model class.
"""

from __future__ import annotations

import numpy as np

from . import Backend, aligned_outputs, batch_chain, effective_integrator, longest_first, warm
from .kernels.batch import integrate_batch, row_records, thread_sums
from .kernels.dispatch import chain_kernel, integrate_chain, kernel_function
from .kernels.forces import DAMPING_KUWABARA_KONO, LAW_FORMS, power_code
from .kernels.records import (
    INFO_SIZE,
    KIND_VERLET,
    Batch,
    Method,
    Model,
    Outputs,
    Params,
    Rows,
    Run,
    State,
    Sums,
    Tally,
)
from .kernels.schemes import SCHEMES


def kernel_array(a, dtype=float) -> np.ndarray:
    """``a`` as the kernels take their arrays: ``dtype``, C-contiguous and writable (a copy only if it is
    not already), so that every call has the argument types of the one compiled signature."""
    return np.require(a, dtype, "CAW")


def _rk_params(integ) -> np.ndarray:
    """The step control of a Runge-Kutta integrator (DP5, RKN4: ``integ.step_control``) in the layout of
    ``rkloop.unpack_steps``."""
    c = integ.step_control
    return np.array([c.rtol, c.atol, c.first_step, c.fixed_step or 0.0, c.relaxed_lag or 0, c.relaxed_factor,
                     c.window_lag or 0])


#: Integrator name -> (kernel kind, settings packer): the one table that maps an integrator to a kernel
#: (every Runge-Kutta scheme of ``kernels.schemes`` by its name, and Verlet).
METHODS = {
    **{s.name: (s.kind, _rk_params) for s in SCHEMES.values()},
    "verlet": (KIND_VERLET, lambda integ: np.array([integ.dt])),
}


def method_record(integrator) -> Method:
    """The kernel's ``Method`` for ``integrator`` (already made effective for the chain)."""
    try:
        kind, pack = METHODS[integrator.name]
    except KeyError:
        raise ValueError(f"the numba backend has no kernel for integrator {integrator.name!r}; "
                         f"it runs {sorted(METHODS)}") from None
    return Method(kind, pack(integrator))


def model_params(chain) -> Params:
    """The kernels' ``Params`` of ``chain``: the scalars its model declares (contact law, boundary,
    static load). The one place a new physics parameter is filled in."""
    law = chain.contact
    # a law of no compiled form (run by the SciPy backend) gets the default code: the energies read none
    damping = LAW_FORMS.get(type(law).__dict__.get("form"), DAMPING_KUWABARA_KONO)
    yield_overlap = float(law.reference_yield_overlap) if law.history else 0.0  # Thornton's contact (forces.plastic_force)
    return Params(float(chain.n), power_code(chain.n), chain.boundary.wall, float(law.gamma), float(chain.static_force),
                  bool(law.clamp), damping, yield_overlap)


def model_record(chain) -> Model:
    """The kernel's ``Model`` for ``chain``: its arrays and :func:`model_params`."""
    return Model(kernel_array(chain.masses), kernel_array(chain.stiffness), model_params(chain))


def run_record(chain, t_grid, t_max, stop_at_exit, controls, sensed=None) -> Run:
    """The kernel's ``Run``: what to record (``chain``'s observed granules, velocities on ``t_grid``, the
    forces of the contacts ``sensed`` on it) and when to stop (``t_max``, or the pulse's exit with
    ``stop_at_exit``; ``controls``: :class:`granchain.RunControls`)."""
    return Run(kernel_array(chain.observed, np.int64), kernel_array(t_grid), float(t_max), bool(stop_at_exit),
               controls.exit_margin, controls.max_steps, controls.peak_rtol,
               no_contacts() if sensed is None else kernel_array(sensed, np.int64), no_windows())


def no_contacts() -> np.ndarray:
    """An empty list of contacts (nothing recorded on the grid but velocities and the wall force)."""
    return np.zeros(0, dtype=np.int64)


def no_windows() -> np.ndarray:
    """No averaged-pulse windows (an empty ``records.Run.pulse_end``): the trailing window alone decides."""
    return np.zeros(0)


def outputs(n_observed: int, n_grid: int, n_granules: int, n_sensed: int = 0) -> Outputs:
    """Zeroed outputs of one integration (velocities time-major: one contiguous row per grid time)."""
    return Outputs(np.zeros(n_observed), np.zeros(n_observed), np.zeros((n_grid, n_observed)), np.zeros(n_granules - 1),
                   np.zeros(n_granules - 1), np.zeros(n_grid), np.zeros(INFO_SIZE), np.zeros((n_grid, n_sensed)))


class NumbaBackend(Backend):
    """Compiled kernels (Numba) for DP5, RKN4 and Verlet; batches run in parallel threads."""

    name = "numba"
    law_forms = tuple(LAW_FORMS)
    #: Thornton's contacts: each one's largest overlap is state the DP5 step loop carries (``kernels.rkloop``).
    carries_history = True

    def check(self, integrator, chain) -> None:
        """Besides :meth:`Backend.check`: the kernels integrate only the granules the pulse has reached
        (``kernels.window``), which is exact only when the initial state declares every granule ahead of
        the pulse at rest (``rest_ahead``): an initial state that does not is refused, not run wrong."""
        super().check(integrator, chain)
        if not chain.initial.rest_ahead:
            raise ValueError(f"the {self.name} backend integrates only the granules the pulse has reached and needs "
                             f"every other granule at rest; the initial state {chain.initial!r} does not say so: "
                             "use DOP853 (integrator='dop853'), which integrates every granule")

    def prepare(self, integrators):
        """A helper process compiling DP5's entry point (``granchain.backends.warm``) when a run integrates
        the paper's chains with another method first and DP5 later (the ensembles' defaults: RKN4 for the
        decorated chains, then DP5 for the effective ones), so that a first run compiles the two on two
        cores; None otherwise."""
        first, *later = (integ.name for integ in integrators)
        if first == "dp5" or "dp5" not in later:
            return None
        return warm.compile_elsewhere("dp5")

    def release(self, handle) -> None:
        warm.stop(handle)

    def integrate(self, integrator, chain, x, v, *, t_grid, t_max, stop_at_exit, controls, sensed=None, history=None):
        self.check(integrator, chain)
        integrator.check_chains(chain.masses[None], chain.stiffness[None], chain.n, chain.initial_velocity)
        method = method_record(effective_integrator(integrator, chain))
        run = run_record(chain, t_grid, t_max, stop_at_exit, controls, sensed)
        out = outputs(chain.observed.size, t_grid.size, chain.size, run.contacts.size)
        model = model_record(chain)
        status = integrate_chain(method, model, run, State(x, v, np.zeros(chain.size - 1) if history is None else history),
                                 out)
        return int(status), out.info, out.peak_v, out.peak_t, out.grid_v, out.peak_f, out.peak_ft, out.grid_f, out.grid_c

    def integrate_batch(self, integrator, masses, stiffness, n, initial_velocity, observed, contacts, *, t_grid, t_max,
                        controls, scale: float, out: dict, model=None, pulse_end=None) -> None:
        import numba

        integrator.check_chains(masses, stiffness, n, initial_velocity)
        first = batch_chain(masses[0], stiffness[0], n, initial_velocity[0], observed, model)  # the model the rows share
        self.check(integrator, first)
        method = method_record(effective_integrator(integrator, first))
        lags, sum_a, sum_a2 = aligned_outputs(out, observed.shape[0])
        limits = np.ascontiguousarray(np.broadcast_to(np.asarray(t_max, dtype=float), masses.shape[:1]))
        ends = no_windows() if pulse_end is None else kernel_array(pulse_end)
        run = Run(kernel_array(observed, np.int64), kernel_array(t_grid), float(limits.max()), first.ends_at_exit,
                  controls.exit_margin, controls.max_steps, controls.peak_rtol, no_contacts(), ends)
        # The threads take the realisations one at a time, longest first (``kernels.queue``: Numba's prange
        # gives each thread a fixed block, whatever its chunk size). Realisations differ in cost by up to 19x
        # (the paper's decorated N = 26 chains: 4,187 to 78,279 steps in 4,000 realisations), and on 16
        # threads the last ones taken decide when a chunk ends: computed from those step counts, 16 threads
        # are busy 81.3 % of a 500-realisation chunk split in fixed blocks, 95.2 % taking them one at a time
        # in index order, 99.3 % longest first (on 2 threads: 97.9 %, 99.9 %, 99.97 %). Results do not
        # change: realisations are independent and the sums are integers (test_ensemble). The per-thread
        # sums are allocated here, not in the kernel (see thread_sums).
        params = model_params(first)
        batch = Batch(kernel_array(masses), kernel_array(stiffness), initial_velocity, params, limits,
                      longest_first(masses, stiffness).astype(np.int64), np.zeros(1, dtype=np.int64))
        # (buffers the schema holds only for some chains, a wall or a dissipative law: the kernel writes them
        # for those alone, and gets scratch otherwise)
        R = masses.shape[0]
        scratch = {"peak_wall_force": np.nan, "peak_wall_force_time": np.nan, "dissipated_energy": 0.0}
        rows = Rows(*(out[name] if name in out else np.full(R, scratch[name]) for name in Rows._fields))
        entry = chain_kernel(method.kind, params)
        warm.wait_for(entry)  # a helper process compiling it into the cache (a first run of both chains)
        kernel = kernel_function(entry, *row_records(batch, method, run, rows))
        integrate_batch(
            kernel, batch, method, run, Tally(contacts, float(scale), lags), rows,
            Sums(out["sum_v"], out["sum_v2"], out["sum_wall"], out["n_valid"], sum_a, sum_a2),
            thread_sums(numba.get_num_threads(), t_grid.size, observed.shape[0], lags.size),
        )
