"""Backends: what binds an integrator (a value: its settings and capabilities) and a chain (a value:
masses, stiffnesses, contact law, boundaries, initial state) to code that runs them.

Three backends today:

- ``"numba"`` (:class:`~granchain.backends.numba_backend.NumbaBackend`): the compiled kernels of
  :mod:`granchain.backends.kernels` for DP5, RKN4 and Verlet, one chain or a parallel batch;
- ``"scipy"`` (:class:`~granchain.backends.scipy_backend.ScipyBackend`): SciPy's DOP853, the
  independent reference;
- ``"cuda"`` (``granchain.backends.cuda.CudaBackend``): RKN4, DP5 and Verlet for elastic chains, DP5 for
  damped ones, precompressed or not, on an NVIDIA GPU (Numba's CUDA target), batches of thousands of chains
  at once.

Every integrator names its backend (``Integrator.backend``); :func:`get_backend` returns it. Before a
run the backend checks that the integrator's capabilities fit the chain's declared assumptions
(:meth:`Backend.check`): a method that needs conservative forces x'' = f(x) refuses a contact law
that depends on velocities, and goal-oriented error control (relaxed zone, trailing window) is
turned off for a chain whose pulse comes back (a fixed wall) and the effective integrator says so
(:func:`effective_integrator`). The test-suite runs every backend over the same cases
(``tests/test_backends.py``).
"""

from __future__ import annotations

import dataclasses

import numpy as np


__all__ = ["Backend", "BackendUnavailable", "RunRecord", "BACKENDS", "get_backend", "effective_integrator", "integrator_as_run", "final_energy_momentum"]

#: The slots of the ``info`` record every backend fills (defined with the kernels, in
#: :mod:`granchain.backends.kernels.records`): offered here so that callers read a run's record through
#: this package, and loaded on first access, so that ``import granchain`` loads neither Numba nor the kernels.
INFO_SLOTS = ("INFO_T_END", "INFO_STEPS", "INFO_REJECTED", "INFO_EXIT", "INFO_EVALUATIONS", "INFO_WINDOW_START",
              "INFO_FROZEN_POTENTIAL", "INFO_DISSIPATED", "INFO_SIZE")


def __getattr__(name):
    if name in INFO_SLOTS:
        from .kernels import records

        return getattr(records, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def final_energy_momentum(chain, x, v, info, history=None) -> tuple[float, float]:
    """(E_end, P_end) of ``chain`` in the final state (x, v) of a run whose record is ``info``: the
    energy with what a viscoelastic law dissipated added (``info``'s dissipated slot) and the energies
    that granules leaving a trailing window had then, summed by the kernels' own routines
    (``kernels.forces.final_energy``, ``total_momentum``) whichever backend ran: ``simulate``'s
    ``energy_error`` and ``momentum_error`` come from here. For a law with memory (``ContactLaw.history``)
    the contacts' elastic energy depends on ``history``, their final per-contact state: the law's own
    ``stored_energy`` (measured from the static state, as ``kernels.forces.add_potential`` does)."""
    from .kernels.forces import final_energy, total_momentum
    from .kernels.records import INFO_DISSIPATED
    from .numba_backend import kernel_array, model_params

    dissipated = float(info[INFO_DISSIPATED])
    # (the chain's arrays as the kernels take them, writable: the types the ensemble kernel compiles these for)
    masses, stiffness = kernel_array(chain.masses), kernel_array(chain.stiffness)
    if chain.contact.history:
        from ..model.contacts import Precompression

        law, moving, dy = chain.contact, np.isfinite(masses), chain.yield_overlaps()
        d0 = Precompression(chain.static_force).overlaps(stiffness, chain.n)
        D = x[:-1] - x[1:]
        stored = (law.stored_energy(d0 + D, stiffness, history, dy) - law.stored_energy(d0, stiffness, None, dy)
                  - law.elastic_force(d0, stiffness) * D)
        e1 = 0.5 * float(np.sum(masses[moving] * v[moving] ** 2)) + float(np.sum(stored)) + dissipated
    else:
        e1 = final_energy(x, v, masses, stiffness, model_params(chain), info) + dissipated
    return e1, total_momentum(v, masses)


def effective_integrator(integrator, chain, contact=None):
    """The integrator as it actually runs on ``chain`` (a :class:`granchain.Chain`, or its boundary
    value and its contact law ``contact``): its goal-oriented zones (relaxed zone, trailing window)
    switched off when the boundary does not license them (a fixed wall sends the pulse back through the
    granules behind the front) or the contacts have a history, else ``integrator`` itself."""
    boundary = getattr(chain, "boundary", chain)
    if integrator.goal_oriented and not boundary.licenses_goal_control:
        return dataclasses.replace(integrator, relaxed_lag=None, window_lag=None)
    law = getattr(chain, "contact", None) if contact is None else contact
    if integrator.goal_oriented and getattr(law, "history", False):
        # granules left behind a trailing window would take their contacts' histories with them
        return dataclasses.replace(integrator, relaxed_lag=None, window_lag=None)
    return integrator


def integrator_as_run(integrator, chain, contact=None) -> dict:
    """The record (``describe()``) of the integrator as it runs on ``chain`` (or at its boundary),
    with ``"goal_control"`` saying why when the boundary switched its goal-oriented zones off: the
    record a result carries next to the integrator that was asked for, so that it never claims a
    control that did not run."""
    ran = effective_integrator(integrator, chain, contact)
    record = ran.describe()
    if ran is not integrator:
        boundary = getattr(chain, "boundary", chain)
        why = (boundary.why_no_goal_control if not boundary.licenses_goal_control else
               "the contacts have a history (their largest overlaps), which granules left behind a trailing window "
               "would take with them")
        record["goal_control"] = f"off: {why}"
    return record


@dataclasses.dataclass(frozen=True)
class RunRecord:
    """What one run of one chain gives its caller (:meth:`Backend.run`), each field named as the
    results name it (``granchain.PulseResult``, the ensembles' schema), so that no caller reads a
    backend's tuple or its ``info`` slots.

    Per observed granule (K): ``peak_velocity``, ``peak_time``; on the time grid (T): ``velocity``
    (T, K, time-major), ``wall_force`` (T; zeros without a wall), ``contact_force`` (T, S: the contacts
    asked for, 0-based); per contact (M - 1, the wall's last): ``peak_force``, ``peak_force_time``; the
    run: ``status`` (a ``granchain.Status`` code), ``t_end``, ``exit_time`` (-1: the pulse did not
    leave), ``n_steps``, ``n_rejected``, ``n_evaluations``, ``dissipated_energy``; the final state
    ``positions``, ``velocities`` (M) and its ``energy`` (kinetic + potential + dissipated, the energy
    of granules a trailing window left behind included) and ``momentum``."""

    status: int
    peak_velocity: np.ndarray
    peak_time: np.ndarray
    velocity: np.ndarray
    peak_force: np.ndarray
    peak_force_time: np.ndarray
    wall_force: np.ndarray
    contact_force: np.ndarray
    t_end: float
    exit_time: float
    n_steps: int
    n_rejected: int
    n_evaluations: int
    dissipated_energy: float
    positions: np.ndarray
    velocities: np.ndarray
    energy: float
    momentum: float


class BackendUnavailable(RuntimeError):
    """A backend that cannot run on this machine (no GPU, or its compiler not installed); the message says
    what to install or which backend to use instead."""


class Backend:
    """Runs integrators of one kind of code. Subclasses implement :meth:`integrate`; the batch loop
    here calls it realisation by realisation with the ensemble's fixed-point sums (compiled backends
    override it with a parallel kernel)."""

    name: str = ""
    #: The force forms of the contact laws this backend has code for (``ContactLaw.form``, read from the
    #: law's own class: a subclass that does not declare its form again may have changed the force, and
    #: is refused); None: any law (code that calls the law's own NumPy methods).
    law_forms: tuple | None = ("power-law",)
    #: Whether :meth:`integrate` carries a per-contact state (its ``history`` argument) for the laws with
    #: memory (``ContactLaw.history``).
    carries_history: bool = False

    def check(self, integrator, chain) -> None:
        """Refuse an integrator whose requirements the chain's model does not meet, and a contact law
        this backend has no code for (rather than run it as another law), saying what to change."""
        integrator.check_law(chain.contact)
        if self.law_forms is not None and type(chain.contact).__dict__.get("form") not in self.law_forms:
            raise ValueError(f"the {self.name} backend has no code for the contact law {chain.contact!r}; it runs "
                             f"the laws of forms {', '.join(self.law_forms)} (the SciPy reference, "
                             f"integrator=granchain.DOP853(), runs any law)")
        if chain.contact.history and not self.carries_history:
            raise ValueError(f"the {self.name} backend carries no per-contact history, which the contact law "
                             f"{chain.contact!r} needs: run it with integrator=granchain.DOP853() (the SciPy reference)")

    def prepare(self, integrators):
        """Start what makes the later of ``integrators`` (in the order a run uses them) ready sooner, e.g. a
        compilation in another process; returns a handle for :meth:`release` (None: nothing started)."""
        return None

    def release(self, handle) -> None:
        """Stop what :meth:`prepare` started, if it still runs."""

    def run(self, integrator, chain, *, t_grid, t_max, stop_at_exit, controls, sensed=None) -> RunRecord:
        """Run ``integrator`` on ``chain`` from its initial state (granule 1, or the striker, moving at
        ``chain.initial_velocity``, every granule at rest in the static state) to the stop rule; the
        :class:`RunRecord` of the run. ``t_grid`` (T,) the times of the recorded velocities and forces,
        ``t_max`` the time limit, ``stop_at_exit`` whether the pulse's exit ends the run, ``controls`` a
        ``granchain.RunControls``, ``sensed`` the contacts (0-based) whose forces are recorded on the grid.
        A backend implements :meth:`integrate`, the low-level contract this wraps (the batch loop of
        :meth:`integrate_batch` calls it too)."""
        from .kernels.records import INFO_DISSIPATED, INFO_EVALUATIONS, INFO_EXIT, INFO_REJECTED, INFO_STEPS, INFO_T_END

        x = np.zeros(chain.size)
        v = np.zeros(chain.size)
        v[0] = chain.initial_velocity
        state = history_state(chain)
        status, info, peak_v, peak_t, grid_v, peak_f, peak_ft, grid_f, grid_c = self.integrate(
            integrator, chain, x, v, t_grid=t_grid, t_max=t_max, stop_at_exit=stop_at_exit, controls=controls,
            sensed=sensed, **state)
        energy, momentum = final_energy_momentum(chain, x, v, info, **state)
        return RunRecord(int(status), peak_v, peak_t, grid_v, peak_f, peak_ft, grid_f, grid_c, float(info[INFO_T_END]),
                         float(info[INFO_EXIT]), int(info[INFO_STEPS]), int(info[INFO_REJECTED]), int(info[INFO_EVALUATIONS]),
                         float(info[INFO_DISSIPATED]), x, v, float(energy), float(momentum))

    def integrate(self, integrator, chain, x, v, *, t_grid, t_max, stop_at_exit, controls, sensed=None):
        """Integrate ``chain`` from (x, v) at t = 0 (both updated in place to the final state); returns
        (status, info, peak_v, peak_t, grid_v, peak_f, peak_ft, grid_f, grid_c) (see ``Integrator.integrate``):
        the low-level contract ``Backend.run`` wraps. A backend that :attr:`carries_history` takes the keyword
        ``history`` too, the per-contact state of a law with memory (in and out, like x and v)."""
        raise NotImplementedError

    def run_batch(self, integrator, batch, buffers: dict, *, t_grid, t_max, controls, scale: float = 1.0,
                  model=None, pulse_end=None) -> None:
        """Run ``integrator`` on every row of ``batch`` (a ``granchain.families.ChainBatch``: the rows'
        masses, stiffnesses and initial velocities, the observed granules and the contacts whose peak forces
        are recorded) into ``buffers``, arrays named as the results' schema names them (per row
        ``peak_velocity``, ``peak_time``, ``peak_force``, ``peak_force_time``, ``status``, ``energy_error``,
        ``n_steps``, ``t_end``, and ``peak_wall_force``, ``peak_wall_force_time``, ``dissipated_energy``
        where the chains have them; the fixed-point sums ``sum_v``, ``sum_v2``, ``sum_wall``, ``n_valid``,
        and ``lags``, ``sum_a``, ``sum_a2`` for the aligned pulse: ``granchain.ensembles.chunks.chunk_buffers``
        builds them from the schema). ``model``: what the rows share besides their arrays (a
        :class:`granchain.ChainModel`; None: the paper's chain). The batch seam of the ensembles and the design evaluator; a
        backend implements :meth:`integrate_batch`, which this calls with the batch's arrays (C-contiguous
        and writable: read-only arrays would make Numba compile its kernels again for them)."""

        def array(a, dtype=float):
            return np.require(a, dtype=dtype, requirements=("C", "W"))

        self.integrate_batch(integrator, array(batch.masses), array(batch.stiffness), batch.n,
                             array(batch.initial_velocity), array(batch.observed, np.int64),
                             array(batch.recorded_contacts(), np.int64), t_grid=t_grid, t_max=t_max, controls=controls,
                             scale=scale, out=buffers, model=model, pulse_end=pulse_end)

    def integrate_batch(self, integrator, masses, stiffness, n, initial_velocity, observed, contacts, *, t_grid, t_max,
                        controls, scale: float, out: dict, model=None, pulse_end=None) -> None:
        """A batch of chains (``Integrator.integrate_batch``), one :meth:`integrate` at a time.
        ``pulse_end`` is not read: it bounds the trailing window, and the integrators run here have none."""
        from .kernels.aligned import accumulate_aligned
        from .kernels.batch import (
            accumulate_fixed_point,
            accumulate_fixed_point_1d,
            gather_forces,
        )
        from .kernels.forces import impulse_energy
        from .kernels.records import INFO_DISSIPATED, INFO_STEPS, INFO_T_END

        R, M = masses.shape
        wall = bool(np.isinf(masses[0, -1]))
        limits = np.broadcast_to(np.asarray(t_max, dtype=float), (R,))
        for r in range(R):
            chain = batch_chain(masses[r], stiffness[r], n, initial_velocity[r], observed, model)
            x, v = np.zeros(M), np.zeros(M)
            v[0] = initial_velocity[r]
            state = history_state(chain)
            st, info, peak_v, peak_t, grid_v, peak_f, peak_ft, grid_f, _ = self.integrate(
                integrator, chain, x, v, t_grid=t_grid, t_max=float(limits[r]), stop_at_exit=chain.ends_at_exit,
                controls=controls, **state)
            out["peak_velocity"][r], out["peak_time"][r] = peak_v, peak_t
            gather_forces(peak_f, peak_ft, contacts, out["peak_force"][r], out["peak_force_time"][r])
            if wall:
                out["peak_wall_force"][r], out["peak_wall_force_time"][r] = peak_f[-1], peak_ft[-1]
            out["status"][r], out["n_steps"][r], out["t_end"][r] = st, int(info[INFO_STEPS]), info[INFO_T_END]
            e0 = impulse_energy(masses[r, 0], initial_velocity[r])
            out["energy_error"][r] = (final_energy_momentum(chain, x, v, info, **state)[0] - e0) / e0
            if "dissipated_energy" in out:
                out["dissipated_energy"][r] = info[INFO_DISSIPATED]
            if st == 0:
                out["n_valid"][0] += 1
                accumulate_fixed_point(np.ascontiguousarray(grid_v), scale, out["sum_v"], out["sum_v2"])
                if wall:
                    accumulate_fixed_point_1d(grid_f, scale, out["sum_wall"])
                lags, sum_a, sum_a2 = aligned_outputs(out, len(observed))
                accumulate_aligned(t_grid, np.ascontiguousarray(grid_v), np.asarray(peak_t, dtype=float), lags, scale,
                                   sum_a, sum_a2)

    def __repr__(self) -> str:
        return f"<granchain backend {self.name!r}>"


def longest_first(masses, stiffness) -> np.ndarray:
    """The rows of a batch in decreasing order of their fastest contact oscillation,
    max_j sqrt(c_j / min(m_j, m_j+1)) (stable: equal rows keep their order). An adaptive step follows the
    lightest granule squeezed by its stiffest contact, so this orders the rows by their expected number of
    steps: the order a batch's chains are started in, so that the longest do not start last and leave
    every other core, or the GPU's other multiprocessors, waiting at the end (longest processing time
    first). It changes no result: the rows are independent and the sums are integers."""
    c = np.asarray(stiffness, dtype=float)[:, : masses.shape[1] - 1]
    lightest = np.minimum(masses[:, :-1], masses[:, 1:])
    rate = np.max(np.sqrt(c / lightest), axis=1) if c.shape[1] else np.zeros(masses.shape[0])
    return np.argsort(-rate, kind="stable")


def history_state(chain) -> dict:
    """The per-contact state a run of ``chain`` carries besides (x, v), as ``Backend.integrate``'s keywords:
    ``{"history": the contacts' largest overlaps}`` for a law with memory, on entry those of virgin contacts
    (their yield overlaps, :meth:`granchain.Chain.yield_overlaps`), else nothing."""
    if not chain.contact.history:
        return {}
    return {"history": np.array(chain.yield_overlaps(), dtype=float)}


def batch_chain(masses, stiffness, n, initial_velocity, observed, model=None):
    """The :class:`granchain.Chain` of one row of a batch: its arrays, and the model the rows share
    (``model``: a :class:`granchain.ChainModel`, or a dict of the ``Chain`` keywords ``contact``,
    ``static_force``, ``striker``; None: the paper's)."""
    from ..model.chain import Chain

    keywords = model if model is None or isinstance(model, dict) else model.chain_keywords(n)
    return Chain(masses, stiffness, n, initial_velocity, observed, **(keywords or {}))


def aligned_outputs(out: dict, n_observed: int):
    """(lags, sum_a, sum_a2) of ``out`` for the aligned pulse (``kernels.aligned``); an empty
    lag grid (no aligned pulse asked) when ``out`` has no ``"lags"``."""
    if out.get("lags") is None:
        empty = np.zeros((0, n_observed), dtype=np.int64)
        return np.zeros(0), empty, empty.copy()
    return np.asarray(out["lags"], dtype=float), out["sum_a"], out["sum_a2"]


_BACKENDS: dict = {}


def get_backend(name: str) -> Backend:
    """The backend registered as ``name`` ("numba", "scipy" or "cuda"), imported on first use; "cuda" raises
    :class:`BackendUnavailable` on a machine without a GPU or Numba's CUDA target."""
    if name not in _BACKENDS:
        if name == "numba":
            from .numba_backend import NumbaBackend as cls
        elif name == "scipy":
            from .scipy_backend import ScipyBackend as cls
        elif name == "cuda":
            from .cuda import CudaBackend as cls
        else:
            raise ValueError(f"unknown backend {name!r}; choose one of {sorted(BACKENDS)}")
        _BACKENDS[name] = cls()
    return _BACKENDS[name]


#: The backends by name.
BACKENDS = ("numba", "scipy", "cuda")
#: The backends that need hardware a machine may lack (an NVIDIA GPU): no integrator names them as its own;
#: they run another backend's integrators when chosen (``backend="cuda"``).
OPTIONAL_BACKENDS = ("cuda",)
