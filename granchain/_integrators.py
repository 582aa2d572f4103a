"""Integrators as small frozen dataclasses plus a registry (like scipy's METHODS).

Each declares its ``name`` and convergence ``order``; the test-suite loops over
:data:`INTEGRATORS` and measures every order. All share one contract: integrate
a :class:`~granchain.Chain` from its initial state, record the peaks of the
observed granules between steps and, on request, their velocities on a grid
(:meth:`Integrator.integrate`), and do the same for a batch of chains of one size
with the ensemble's fixed-point sums (:meth:`Integrator.integrate_batch`). That is
the one seam through which ``simulate`` and ``run_ensemble`` reach any integrator.

Compiled integrators (DP5, Verlet) name a Numba kernel by id and pack their settings
into a float64 array; both paths then run the same compiled code
(``granchain._kernels._dispatch``). A pure-Python integrator (DOP853) gets a batch
loop for free, with the same fixed-point accumulation.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ._kernels._common import INFO_SIZE, INFO_STEPS, INFO_T_END, final_energy, power_code
from ._kernels._aligned import accumulate_aligned
from ._kernels._dispatch import KERNEL_DP5, KERNEL_RKN4, KERNEL_VERLET, integrate_chain
from ._kernels._ensemble import accumulate_fixed_point, accumulate_fixed_point_1d, gather_forces, integrate_batch, thread_sums
from ._reference import dop853_integrate
from ._validate import count, finite_scalar

__all__ = ["Integrator", "DP5", "RKN4", "Verlet", "VerletStabilityWarning", "verlet_omega_max", "DOP853", "INTEGRATORS", "RunControls", "get_integrator"]


#: Validated goal-oriented settings of :meth:`DP5.relaxed` and :meth:`DP5.windowed` (lags counted in
#: observed granules behind the front; tests/test_window.py). A relaxed lag of 3 broke the contract
#: at the last granule, where the pulse piles up against the free end, in 2 of 120,000 decorated
#: realisations of the paper's set (2.3e-6 and 1.3e-6 from DOP853); 4 keeps them within 1.2e-7.
RELAXED_LAG = 4
RELAXED_FACTOR = 1000.0
WINDOW_LAG = 7


def _tolerances(rtol, atol):
    """Tolerances of an adaptive method: rtol in [1e-14, 1), atol in (0, 1). An error of 100 % (or of
    one rescaled velocity unit, the struck granule's) is no error control at all: every step would be
    accepted and the run would fail or return noise."""
    rtol = finite_scalar("rtol", rtol, positive=True)
    atol = finite_scalar("atol", atol, positive=True)
    if rtol < 1e-14:
        raise ValueError(f"rtol = {rtol:g} is below what double precision can deliver; use rtol >= 1e-14")
    if rtol >= 1.0:
        raise ValueError(f"rtol = {rtol:g} must lie in (0, 1): it is a relative error per step (the ensembles' "
                         "defaults are 1e-6 for DP5 and 1e-5 for RKN4)")
    if atol >= 1.0:
        raise ValueError(f"atol = {atol:g} must lie in (0, 1): it is an absolute error in rescaled units, in which "
                         "the struck granule's velocity is 1 (the ensembles' defaults are 1e-9 and 1e-8)")
    return rtol, atol


@dataclass(frozen=True)
class RunControls:
    """When a run stops and how peaks are recorded; the same checks for ``simulate`` and ensembles.

    exit_margin : float >= 0
        Time units the run goes on after the pulse has left the last granule.
    max_steps : int >= 1
        Step budget (accepted + rejected) of one integration; status MAX_STEPS when exhausted.
    peak_rtol : float >= 0
        Tie rule for peaks: a later local maximum replaces the recorded one only if higher
        by more than this relative amount (keep it above the integration error).
    """

    exit_margin: float = 3.0
    max_steps: int = 20_000_000
    peak_rtol: float = 1e-6

    def __post_init__(self):
        for name in ("exit_margin", "peak_rtol"):
            value = finite_scalar(name, getattr(self, name))
            if value < 0:
                raise ValueError(f"{name} must be >= 0, got {value!r}")
            object.__setattr__(self, name, value)
        object.__setattr__(self, "max_steps", count("max_steps", self.max_steps, minimum=1))


def _outputs(n_observed: int, n_grid: int, n_granules: int):
    # velocities time-major: one contiguous row per grid time; forces per contact (M - 1)
    return (np.zeros(n_observed), np.zeros(n_observed), np.zeros((n_grid, n_observed)), np.zeros(n_granules - 1),
            np.zeros(n_granules - 1), np.zeros(n_grid), np.zeros(INFO_SIZE))


def _aligned_outputs(out: dict, n_observed: int):
    """(lags, sum_a, sum_a2) of ``out`` for the aligned pulse (``_kernels._aligned``); an empty
    lag grid (no aligned pulse asked) when ``out`` has no ``"lags"``."""
    if out.get("lags") is None:
        empty = np.zeros((0, n_observed), dtype=np.int64)
        return np.zeros(0), empty, empty.copy()
    return np.asarray(out["lags"], dtype=float), out["sum_a"], out["sum_a2"]


class Integrator:
    """Base of every integrator: a frozen dataclass of settings with a ``name`` and an ``order``."""

    name: ClassVar[str]
    order: ClassVar[int]

    def describe(self) -> dict:
        """JSON-able record of the integrator and all its settings (stored with ensembles)."""
        return {"name": self.name, **{f.name: getattr(self, f.name) for f in dataclasses.fields(self)}}

    def integrate(self, chain, x, v, *, t_grid, t_max, stop_at_exit, controls: RunControls):
        """Integrate ``chain`` from (x, v) at t = 0 (both updated in place to the final state).

        Returns (status, info, peak_v, peak_t, grid_v, peak_f, peak_ft, grid_f), see
        ``granchain._kernels._dispatch``: peak_f, peak_ft per contact (M - 1), grid_f the wall force
        on the grid (zeros without a wall).
        """
        raise NotImplementedError

    def integrate_batch(self, masses, stiffness, n, initial_velocity, observed, contacts, *, t_grid, t_max,
                        controls: RunControls, scale: float, out: dict) -> None:
        """Integrate a batch of chains (rows of ``masses`` (R, M), ``stiffness`` (R, M-1),
        ``initial_velocity`` (R,), shared ``observed`` and recorded ``contacts``, 0-based),
        stopping at the pulse's exit (or its return from a wall).

        Writes ``out["peak_velocity"]``/``["peak_time"]`` (R, K), ``["peak_force"]``/
        ``["peak_force_time"]`` (R, C) of the contacts ``contacts``, ``["peak_wall"]`` (R, 2: the
        wall's peak force and its time; only for chains ending in a wall), ``["status"]``,
        ``["energy_error"]``, ``["n_steps"]``, ``["t_end"]`` (R,), adds the fixed-point
        sums of successful rows' grid velocities to ``["sum_v"]``/``["sum_v2"]`` (T, K) (and of
        the wall force to ``["sum_wall"]`` (T,)) and counts them in ``["n_valid"]`` (1,). With
        ``out["lags"]`` (L,), also adds the aligned pulse's sums to ``["sum_a"]``/``["sum_a2"]``
        (L, K) (``_kernels._aligned``). This generic version loops in Python over
        :meth:`integrate`; compiled integrators override it with a parallel kernel.
        """
        from ._chain import Chain

        R, M = masses.shape
        wall = bool(np.isinf(masses[0, -1]))
        for r in range(R):
            chain = Chain(masses[r], stiffness[r], n, initial_velocity[r], observed)
            x, v = np.zeros(M), np.zeros(M)
            v[0] = initial_velocity[r]
            st, info, peak_v, peak_t, grid_v, peak_f, peak_ft, grid_f = self.integrate(
                chain, x, v, t_grid=t_grid, t_max=t_max, stop_at_exit=True, controls=controls)
            out["peak_velocity"][r], out["peak_time"][r] = peak_v, peak_t
            gather_forces(peak_f, peak_ft, contacts, wall, out["peak_force"][r], out["peak_force_time"][r], out["peak_wall"][r])
            out["status"][r], out["n_steps"][r], out["t_end"][r] = st, int(info[INFO_STEPS]), info[INFO_T_END]
            e0 = 0.5 * masses[r, 0] * initial_velocity[r] * initial_velocity[r]  # the expression of the compiled batch
            out["energy_error"][r] = (final_energy(x, v, masses[r], stiffness[r], n, info) - e0) / e0
            if st == 0:
                out["n_valid"][0] += 1
                accumulate_fixed_point(np.ascontiguousarray(grid_v), scale, out["sum_v"], out["sum_v2"])
                if wall:
                    accumulate_fixed_point_1d(grid_f, scale, out["sum_wall"])
                lags, sum_a, sum_a2 = _aligned_outputs(out, len(observed))
                accumulate_aligned(t_grid, np.ascontiguousarray(grid_v), np.asarray(peak_t, dtype=float), lags, scale,
                                   sum_a, sum_a2)


class _Compiled(Integrator):
    """An integrator with a Numba kernel (``kernel_id``) and settings packed by ``kernel_params``."""

    kernel_id: ClassVar[int]

    def kernel_params(self) -> np.ndarray:
        raise NotImplementedError

    def check_chains(self, masses, stiffness, n, initial_velocity) -> None:
        """Called with the chains (rows) before every integration: warn or refuse where the method
        cannot work (e.g. a fixed step beyond its stability limit). Nothing by default."""

    def integrate(self, chain, x, v, *, t_grid, t_max, stop_at_exit, controls: RunControls):
        self.check_chains(chain.masses[None], chain.stiffness[None], chain.n, chain.initial_velocity)
        peak_v, peak_t, grid_v, peak_f, peak_ft, grid_f, info = _outputs(chain.observed.size, t_grid.size, chain.size)
        status = integrate_chain(
            self.kernel_id, self.kernel_params(), chain.masses, chain.stiffness, chain.n, power_code(chain.n), chain.observed,
            t_max, stop_at_exit, controls.exit_margin, controls.max_steps, controls.peak_rtol, t_grid, x, v,
            peak_v, peak_t, grid_v, peak_f, peak_ft, grid_f, info,
        )
        return int(status), info, peak_v, peak_t, grid_v, peak_f, peak_ft, grid_f

    def integrate_batch(self, masses, stiffness, n, initial_velocity, observed, contacts, *, t_grid, t_max,
                        controls: RunControls, scale: float, out: dict) -> None:
        import numba

        self.check_chains(masses, stiffness, n, initial_velocity)
        lags, sum_a, sum_a2 = _aligned_outputs(out, observed.shape[0])
        # Dynamic scheduling, one realisation at a time. Realisations differ in cost by up to 16x
        # (N = 6 decorated chains), and Numba's default static split (each thread a contiguous
        # half of the batch) left a thread idle for 1.2-3.6 % of a 1000-realisation chunk of the
        # paper's set (computed from its per-realisation step counts; 0.1 % dynamic). Results do not
        # change: realisations are independent and the sums are integers (test_ensemble). The
        # per-thread sums are allocated here, not in the kernel (see thread_sums).
        with numba.parallel_chunksize(1):
            integrate_batch(
                self.kernel_id, self.kernel_params(), masses, stiffness, n, power_code(n), initial_velocity, observed,
                contacts, t_max, controls.exit_margin, controls.max_steps, controls.peak_rtol, t_grid, scale,
                out["peak_velocity"], out["peak_time"], out["peak_force"], out["peak_force_time"], out["peak_wall"],
                out["status"], out["energy_error"], out["n_steps"], out["t_end"], out["sum_v"], out["sum_v2"], out["sum_wall"],
                out["n_valid"], lags, sum_a, sum_a2,
                *thread_sums(numba.get_num_threads(), t_grid.size, observed.shape[0], lags.size),
            )


@dataclass(frozen=True)
class DP5(_Compiled):
    """Compiled adaptive Dormand-Prince 5(4), PI step control, max-norm error (simulate's default).

    The defaults keep peak velocities and times within ~1e-7 (relative) of DOP853 at rtol 1e-10
    on random decorated chains and their effective chains. Goal-oriented error control
    is off by default: ``DP5()`` integrates every granule to the end at the full tolerance.

    Parameters
    ----------
    rtol, atol : float
        Tolerances of the max-norm error (of the granules near the pulse, with the settings below).
    first_step : float
        First trial step.
    fixed_step : float, optional
        Switches step control off (fixed steps; used to measure the order).
    relaxed_lag : int, optional
        The *front* is the most advanced observed granule (the large granules of a decorated
        chain) whose velocity maximum has been located; it never moves backwards. Granules behind
        observed granule front - ``relaxed_lag`` (their peaks are past) enter the step-size error
        norm with ``relaxed_factor`` times looser tolerances (the relaxed zone).
    relaxed_factor : float
        How much looser the relaxed zone's tolerances are (>= 1).
    window_lag : int, optional
        Granules behind observed granule front - ``window_lag``, cut across the last contact
        behind it that is open at that moment, leave the integration (the trailing window): they
        keep the velocity they had (their positions continue ballistically), their peaks are
        final, and the contact at the window's edge is dropped. The work per step then no longer
        grows with the chain (cost linear in N). Must be larger than ``relaxed_lag``.

    Notes
    -----
    Accuracy contract (tests/test_window.py), at DP5 rtol 1e-6 (or :class:`RKN4` rtol 1e-5: the
    ensembles' default for decorated chains) for decorated chains; 5e-8 for chains without light
    granules, whose errors add up along the chain: at rtol 1e-6 their peaks are off by up to ~5e-6,
    with or without these settings; pass ``DP5.relaxed(5e-8, 5e-11)`` or ``DP5.windowed(5e-8, 5e-11)``
    for such chains (the ensembles' default for them):

    - :meth:`relaxed` (with RKN4 or DP5, :func:`granchain.ensemble_integrator`): peak
      velocities within 1e-6 (relative) and peak times within 1e-5 of DOP853 at rtol 1e-10 on
      random decorated chains (N = 26, DP5 rtol 1e-6, RKN4 rtol 1e-5) and their effective chains
      (rtol 5e-8), and the averaged pulse <v_k(t)> of a 500-realisation ensemble within 1e-4
      (absolute, about 0.01 of its standard error) of the untruncated DP5 run's.
    - :meth:`windowed` (relaxed zone and trailing window): the same peak contract, and the
      averaged-pulse maxima max_t <v_k(t)> unchanged within 1e-6 (relative); but not the averaged
      pulse's *tail* long after the pulse has passed granule k: granules behind the window report
      the velocity they left it with, while in the full dynamics the rattling granules behind the
      pulse keep exchanging momentum with them (measured: up to 0.08 at the end of the default
      grid of N = 26, ~15 standard errors of 500 realisations). Use it for peaks, arrival times,
      forces and long chains, not for <v_k(t)> tails.

    Both are off for chains ending in a wall (the pulse comes back through the granules behind
    it). Granules behind the window are no longer integrated: their velocity on the time grid is
    the one they left with, their contact forces stop, and the energy report counts their kinetic
    energy and the potential of their contacts at the time they left
    (``granchain._kernels._common.final_energy``). Their final positions are continued ballistically
    and may overlap (contacts behind the window are not resolved): compute no energy from the
    returned positions of a windowed run. The relaxed zone's looser tolerance shows in
    the energy report as a drift typically ~1e-4 instead of ~1e-5 (worst in the paper's set: 2.6e-3,
    peaks unaffected: the drift is the rattling granules' behind the pulse). The exit rule reads the granules
    still integrated (those behind the window are behind the pulse by construction).
    """

    rtol: float = 1e-8
    atol: float = 1e-10
    first_step: float = 1e-3
    fixed_step: float | None = None
    relaxed_lag: int | None = None
    relaxed_factor: float = 1000.0
    window_lag: int | None = None

    name: ClassVar[str] = "dp5"
    order: ClassVar[int] = 5
    kernel_id: ClassVar[int] = KERNEL_DP5
    #: The tolerances of :meth:`relaxed` and :meth:`windowed` (validated, tests/test_window.py).
    goal_tolerances: ClassVar[tuple] = (1e-6, 1e-9)

    def __post_init__(self):
        rtol, atol = _tolerances(self.rtol, self.atol)
        object.__setattr__(self, "rtol", rtol)
        object.__setattr__(self, "atol", atol)
        object.__setattr__(self, "first_step", finite_scalar("first_step", self.first_step, positive=True))
        if self.fixed_step is not None:
            object.__setattr__(self, "fixed_step", finite_scalar("fixed_step", self.fixed_step, positive=True))
        for name in ("relaxed_lag", "window_lag"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, count(name, getattr(self, name), minimum=1))
        factor = finite_scalar("relaxed_factor", self.relaxed_factor, positive=True)
        if factor < 1.0:
            raise ValueError(f"relaxed_factor = {factor:g} would tighten the tolerance behind the pulse; use a factor >= 1")
        object.__setattr__(self, "relaxed_factor", factor)
        if self.relaxed_lag is not None and self.rtol * factor >= 1.0:
            raise ValueError(f"the relaxed zone's tolerance rtol * relaxed_factor = {self.rtol * factor:g} must stay below 1 "
                             "(it would control nothing there): lower rtol or relaxed_factor")
        if self.relaxed_lag is not None and self.window_lag is not None and self.relaxed_lag >= self.window_lag:
            raise ValueError(f"relaxed_lag = {self.relaxed_lag} must be smaller than window_lag = {self.window_lag}: "
                             "the relaxed zone lies between the front and the trailing window")

    @property
    def is_exact(self) -> bool:
        """True when every granule is integrated to the end with the full tolerance."""
        return self.relaxed_lag is None and self.window_lag is None

    @classmethod
    def relaxed(cls, rtol: float | None = None, atol: float | None = None) -> "DP5":
        """The method with the validated relaxed zone: granules more than 4 observed granules behind
        the front at 1000 times looser tolerances; every granule integrated to the end
        (``RELAXED_LAG``, ``RELAXED_FACTOR`` in ``granchain._integrators``). ``rtol``, ``atol`` default
        to the method's validated ``goal_tolerances`` (DP5: 1e-6, 1e-9; RKN4: 1e-5, 1e-8)."""
        return cls(*cls._goal_tolerances(rtol, atol), relaxed_lag=RELAXED_LAG, relaxed_factor=RELAXED_FACTOR)

    @classmethod
    def windowed(cls, rtol: float | None = None, atol: float | None = None) -> "DP5":
        """:meth:`relaxed` plus the trailing window 7 observed granules behind the front
        (``WINDOW_LAG``): cost linear in N, peaks as accurate, the averaged pulse's tail not (see
        the class notes)."""
        return cls(*cls._goal_tolerances(rtol, atol), relaxed_lag=RELAXED_LAG, relaxed_factor=RELAXED_FACTOR,
                   window_lag=WINDOW_LAG)

    @classmethod
    def _goal_tolerances(cls, rtol, atol) -> tuple:
        default_rtol, default_atol = cls.goal_tolerances
        return (default_rtol if rtol is None else rtol, default_atol if atol is None else atol)

    def describe(self) -> dict:
        record = super().describe()
        if self.is_exact and self.relaxed_factor == RELAXED_FACTOR:  # the record of stores written by granchain < 0.3
            for key in ("relaxed_lag", "relaxed_factor", "window_lag"):
                record.pop(key)
        return record

    def kernel_params(self) -> np.ndarray:
        return np.array([self.rtol, self.atol, self.first_step, self.fixed_step or 0.0, self.relaxed_lag or 0,
                         self.relaxed_factor, self.window_lag or 0])


@dataclass(frozen=True)
class RKN4(DP5):
    """Compiled adaptive Runge-Kutta-Nystrom 4(3) (Dormand, El-Mikkawy & Prince 1987, "RKN4(3)4FM"):
    DP5's settings, step control, goal-oriented zones and records, with a method made for x'' = f(x).

    Three force evaluations per step (DP5: six), order 4 with a 3rd-order error estimate, dense
    output by the quintic Hermite interpolant of the positions (``granchain._kernels._rkn``). A
    decorated chain's step is set by its light granules' oscillations; there this pair neither
    grows nor damps an oscillation up to h omega = 3.77 (DP5 grows beyond h omega ~ 1), and on
    random N = 26 decorated chains it takes ~0.9x DP5's steps at half the force evaluations each.
    Its tolerances are not DP5's: at rtol 1e-5 its peaks are as accurate as DP5's at 1e-6 (and more
    so at the free end of short chains), so ``RKN4.relaxed()`` and ``RKN4.windowed()`` (inherited:
    :meth:`DP5.relaxed`, :meth:`DP5.windowed`) take that default
    (the decorated ensembles' :func:`granchain.ensemble_integrator`; tests/test_window.py). For
    smooth chains (no light granules) it saves nothing over DP5 at equal accuracy.
    """

    name: ClassVar[str] = "rkn4"
    order: ClassVar[int] = 4
    kernel_id: ClassVar[int] = KERNEL_RKN4

    #: The tolerances of ``RKN4.relaxed()`` and ``RKN4.windowed()`` (those of the decorated ensembles,
    #: ``granchain.ENSEMBLE_RTOL``, ``ENSEMBLE_ATOL``): peaks as accurate as ``DP5.relaxed()``'s.
    goal_tolerances: ClassVar[tuple] = (1e-5, 1e-8)

    def describe(self) -> dict:
        return Integrator.describe(self)  # every setting (DP5 drops the goal ones for its old records)


class VerletStabilityWarning(UserWarning):
    """Verlet's time step is beyond its stability limit for the chain: results are meaningless."""


def verlet_omega_max(masses, stiffness, n, initial_velocity) -> np.ndarray:
    """Upper bound of the highest linearised angular frequency of chains (rows of ``masses``, ``stiffness``).

    No contact can be compressed beyond the compression that holds all the energy E_0 = m_1 v_1^2 / 2
    (Eq. motion_rescaled's potential (c/n) delta^n): delta_i <= (n E_0 / c_i)^(1/n), where the contact's
    linear stiffness is k_i = c_i (n-1) delta_i^(n-2). Gershgorin's theorem on M^-1 K then bounds
    omega^2 <= max_i 2 (k_{i-1} + k_i) / m_i. For n < 2 the stiffness diverges at zero compression and
    there is no bound (returns NaN).
    """
    m = np.atleast_2d(np.asarray(masses, dtype=float))
    c = np.atleast_2d(np.asarray(stiffness, dtype=float))
    v0 = np.atleast_1d(np.asarray(initial_velocity, dtype=float)).reshape(-1, 1)
    if n < 2.0:
        return np.full(m.shape[0], np.nan)
    e0 = 0.5 * m[:, :1] * v0 * v0
    k = c * (n - 1.0) * (n * e0 / c) ** ((n - 2.0) / n)
    zero = np.zeros((m.shape[0], 1))
    both = np.concatenate([zero, k], axis=1) + np.concatenate([k, zero], axis=1)
    return np.sqrt(np.max(2.0 * both / m, axis=1))


@dataclass(frozen=True)
class Verlet(_Compiled):
    """Compiled fixed-step velocity Verlet (symplectic, order 2).

    Stability: velocity Verlet is stable only for dt * omega_max <= 2, omega_max the chain's highest
    linearised angular frequency. Before integrating, ``dt`` is checked against the safe upper bound
    of ``granchain._integrators.verlet_omega_max`` (every contact at most as compressed as if it held all the pulse's
    energy; Gershgorin bound of M^-1 K); a :class:`granchain.VerletStabilityWarning` is issued when
    dt * omega_max > 2 (the bound is conservative: near it, compare with a smaller dt or DP5).
    Not checked for n < 2, where the contact stiffness has no bound.
    """

    dt: float = 1e-3

    name: ClassVar[str] = "verlet"
    order: ClassVar[int] = 2
    kernel_id: ClassVar[int] = KERNEL_VERLET

    def __post_init__(self):
        object.__setattr__(self, "dt", finite_scalar("dt", self.dt, positive=True))

    def kernel_params(self) -> np.ndarray:
        return np.array([self.dt])

    def check_chains(self, masses, stiffness, n, initial_velocity) -> None:
        """Warn (:class:`granchain.VerletStabilityWarning`) where dt * omega_max > 2 (see the class docstring)."""
        import warnings

        omega = verlet_omega_max(masses, stiffness, n, initial_velocity)
        bad = self.dt * omega > 2.0
        if np.any(bad):
            worst = float(np.nanmax(omega))
            warnings.warn(
                f"Verlet dt = {self.dt:g} is beyond its stability limit for {int(bad.sum())} of {bad.size} chain(s): "
                f"dt * omega_max = {self.dt * worst:.3g} > 2 (omega_max <= {worst:.4g}); the results are not trustworthy. "
                f"Use dt <= {2.0 / worst:.3g} or the adaptive DP5", VerletStabilityWarning, stacklevel=4)


@dataclass(frozen=True)
class DOP853(Integrator):
    """SciPy's DOP853 (order 8), the independent high-accuracy reference. Slow (pure Python);
    in ensembles it runs realisation by realisation, for validation."""

    rtol: float = 1e-10
    atol: float = 1e-12

    name: ClassVar[str] = "dop853"
    order: ClassVar[int] = 8

    def __post_init__(self):
        rtol, atol = _tolerances(self.rtol, self.atol)
        object.__setattr__(self, "rtol", rtol)
        object.__setattr__(self, "atol", atol)

    def integrate(self, chain, x, v, *, t_grid, t_max, stop_at_exit, controls: RunControls):
        status, info, peak_v, peak_t, grid_v, xf, vf, peak_f, peak_ft, grid_f = dop853_integrate(
            chain.masses, chain.stiffness, chain.n, chain.observed, x.copy(), v.copy(),
            rtol=self.rtol, atol=self.atol, t_max=t_max, stop_at_exit=stop_at_exit,
            exit_margin=controls.exit_margin, max_steps=controls.max_steps, peak_rtol=controls.peak_rtol, t_grid=t_grid,
        )
        x[:] = xf
        v[:] = vf
        return int(status), info, peak_v, peak_t, grid_v, peak_f, peak_ft, grid_f


#: Registered integrators by name (the CLI's ``--integrator`` choices).
INTEGRATORS = {cls.name: cls for cls in (DP5, RKN4, Verlet, DOP853)}


def get_integrator(spec=None) -> Integrator:
    """An integrator instance from an instance, a registered name, or None (DP5 defaults)."""
    if spec is None:
        return DP5()
    if isinstance(spec, str):
        try:
            return INTEGRATORS[spec.lower()]()
        except KeyError:
            raise ValueError(f"unknown integrator {spec!r}; choose one of {sorted(INTEGRATORS)}") from None
    if isinstance(spec, Integrator):
        return spec
    raise ValueError(f"integrator must be a name in {sorted(INTEGRATORS)} or an instance such as granchain.DP5(), got {spec!r}")


def integrator_from_record(record: dict) -> Integrator:
    """The integrator a stored :meth:`Integrator.describe` record names (for stores read back)."""
    record = dict(record)
    name = record.pop("name", None)
    if name not in INTEGRATORS:
        raise ValueError(f"the stored integrator {name!r} is not registered here; known: {sorted(INTEGRATORS)}")
    return INTEGRATORS[name](**record)
