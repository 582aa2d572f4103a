"""Integrators as data: small frozen dataclasses of settings with declared capabilities, plus a
registry (like scipy's METHODS).

Each declares its ``name``, its convergence ``order``, the ``backend`` that runs it
(``granchain.backends``: "numba" for the compiled DP5, RKN4 and Verlet, "scipy" for DOP853) and
what it needs of the model and supports: ``needs_conservative_forces`` (a method for x'' = f(x):
RKN4, Verlet), ``supports_goal_control`` (the relaxed zone and trailing window of DP5 and RKN4).
The adaptive Runge-Kutta methods are siblings (:class:`AdaptiveRK`): each is a scheme of the compiled
step loop (``granchain.backends.kernels.schemes``, by its ``name``) run under a :class:`StepControl`.
None of them calls compiled code: :meth:`Integrator.integrate` and :meth:`Integrator.integrate_batch`
hand the integrator and the chain to its backend, which binds them to its code. That is the one seam
through which ``simulate`` and ``run_ensemble`` reach any integrator; the test-suite loops over
:data:`INTEGRATORS`, measures every order and runs every backend over the same cases.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from .._validate import count, finite_scalar

__all__ = ["Integrator", "StepControl", "AdaptiveRK", "DP5", "RKN4", "Verlet", "VerletStabilityWarning", "verlet_omega_max", "DOP853", "INTEGRATORS", "RunControls", "get_integrator"]


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
                         "defaults are 1e-6 for DP5 and 3e-6 for RKN4)")
    if atol >= 1.0:
        raise ValueError(f"atol = {atol:g} must lie in (0, 1): it is an absolute error in rescaled units, in which "
                         "the struck granule's velocity is 1 (the ensembles' defaults are 1e-9 and 3e-9)")
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


class Integrator:
    """Base of every integrator: a frozen dataclass of settings with a ``name``, an ``order``, the
    ``backend`` that runs it and its capabilities (see the module doc)."""

    name: ClassVar[str]
    order: ClassVar[int]
    backend: ClassVar[str] = "numba"
    #: A method for x'' = f(x): needs forces that depend on positions only.
    needs_conservative_forces: ClassVar[bool] = False
    #: Has the goal-oriented error control (relaxed zone, trailing window) of :class:`DP5`.
    supports_goal_control: ClassVar[bool] = False

    @property
    def goal_oriented(self) -> bool:
        """True when the goal-oriented error control is on (never for integrators without it)."""
        return False

    def describe(self) -> dict:
        """JSON-able record of the integrator and all its settings (stored with ensembles)."""
        return {"name": self.name, **{f.name: getattr(self, f.name) for f in dataclasses.fields(self)}}

    def check_law(self, law, whose: str = "the contact law", hint: str = "") -> None:
        """Refuse a contact law whose force is not a function of the positions alone (it reads velocities, or
        each contact's history) where this is a method for x'' = f(x), saying which methods integrate it
        (``hint``: added after DP5, e.g. " (the default for it)"; ``whose``: how the message names the law)."""
        if self.needs_conservative_forces and not law.conservative:
            why = ("remembers each contact's largest overlap (its force depends on that history)"
                   if getattr(law, "history", False) else "depends on velocities")
            raise ValueError(f"{self.name} integrates x'' = f(x) and needs forces that depend on positions only; "
                             f"{whose} {law!r} {why}: use DP5{hint} or DOP853")

    def check_chains(self, masses, stiffness, n, initial_velocity) -> None:
        """Called with the chains (rows) before every integration: warn or refuse where the method
        cannot work (e.g. a fixed step beyond its stability limit). Nothing by default."""

    def integrate(self, chain, x, v, *, t_grid, t_max, stop_at_exit, controls: RunControls, sensed=None):
        """Integrate ``chain`` from (x, v) at t = 0 (both updated in place to the final state), on this
        integrator's backend.

        Returns (status, info, peak_v, peak_t, grid_v, peak_f, peak_ft, grid_f, grid_c): the status code,
        the run's ``info`` (slots ``INFO_*`` of ``granchain.backends.kernels.records``), per observed
        granule its peak velocity and time and its velocities on ``t_grid`` (time-major), per contact
        (M - 1) its peak force and time, the wall force on the grid (zeros without a wall), and the forces
        of the contacts ``sensed`` (0-based) on the grid (T, S).
        """
        from ..backends import get_backend

        return get_backend(self.backend).integrate(self, chain, x, v, t_grid=t_grid, t_max=t_max,
                                                   stop_at_exit=stop_at_exit, controls=controls, sensed=sensed)

    def integrate_batch(self, masses, stiffness, n, initial_velocity, observed, contacts, *, t_grid, t_max,
                        controls: RunControls, scale: float, out: dict, model=None,
                        pulse_end=None) -> None:
        """Integrate a batch of chains (rows of ``masses`` (R, M), ``stiffness`` (R, M-1),
        ``initial_velocity`` (R,), shared ``observed`` and recorded ``contacts``, 0-based),
        stopping at the pulse's exit (or its return from a wall), on this integrator's backend.

        Writes ``out["peak_velocity"]``/``["peak_time"]`` (R, K), ``["peak_force"]``/
        ``["peak_force_time"]`` (R, C) of the contacts ``contacts``, ``["peak_wall_force"]``,
        ``["peak_wall_force_time"]`` (R,; only for chains ending in a wall), ``["status"]``,
        ``["energy_error"]``, ``["n_steps"]``, ``["t_end"]`` (R,) (and ``["dissipated_energy"]`` (R,)
        when ``out`` has it), adds the fixed-point
        sums of successful rows' grid velocities to ``["sum_v"]``/``["sum_v2"]`` (T, K) (and of
        the wall force to ``["sum_wall"]`` (T,)) and counts them in ``["n_valid"]`` (1,). With
        ``out["lags"]`` (L,), also adds the aligned pulse's sums to ``["sum_a"]``/``["sum_a2"]``
        (L, K) (``granchain.backends.kernels.aligned``). ``model``: what the rows share besides their
        arrays, a :class:`granchain.ChainModel` (or a dict of the :class:`granchain.Chain` keywords ``contact``,
        ``static_force``, ``striker``; None: the paper's elastic, unloaded chain struck on granule 1). ``t_max``: one time limit for all
        rows, or one per row (R,). A precompressed batch runs to it (its contacts never open), the others
        stop at the pulse's exit. ``pulse_end`` (K,; None: never): per observed granule the end of its
        averaged-pulse window (``granchain.ensembles.pulse_window``): a trailing window does not drop the
        granule before that time, and its grid velocities after it are not recorded (they enter the sums
        as 0, and the store shows them as not computed).
        """
        from ..backends import get_backend

        get_backend(self.backend).integrate_batch(self, masses, stiffness, n, initial_velocity, observed, contacts,
                                                  t_grid=t_grid, t_max=t_max, controls=controls, scale=scale, out=out,
                                                  model=model, pulse_end=pulse_end)


@dataclass(frozen=True)
class StepControl:
    """The step control of the adaptive Runge-Kutta methods (:class:`DP5`, :class:`RKN4`), a value of its
    own: the tolerances, the first step, a fixed step (control off), and the goal-oriented zones (the
    relaxed zone and the trailing window; see :class:`DP5` for what they do and their accuracy contract).
    The method (the scheme: its stages, error estimate and dense output) is the integrator's; this is
    what a run asks of it. ``integrator.step_control`` gives it, validated.
    """

    rtol: float = 1e-8
    atol: float = 1e-10
    first_step: float = 1e-3
    fixed_step: float | None = None
    relaxed_lag: int | None = None
    relaxed_factor: float = 1000.0
    window_lag: int | None = None

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


@dataclass(frozen=True)
class AdaptiveRK(StepControl, Integrator):
    """Base of the compiled adaptive Runge-Kutta methods (:class:`DP5`, :class:`RKN4`): a method (a scheme of
    the compiled step loop, ``granchain.backends.kernels.schemes``, by the integrator's ``name``) under a
    step control, whose fields and checks are :class:`StepControl`'s (``step_control`` gives the value).
    Siblings share the step control, the goal-oriented constructors (:meth:`granchain.DP5.relaxed`,
    :meth:`granchain.DP5.windowed`) and the records, nothing of each other's method."""

    supports_goal_control: ClassVar[bool] = True
    #: The tolerances of :meth:`relaxed` and :meth:`windowed` (each method's own, validated).
    goal_tolerances: ClassVar[tuple]

    @functools.cached_property
    def step_control(self) -> StepControl:
        """The integrator's :class:`~granchain.solve.integrators.StepControl` (its step-control fields, as one
        value; made once per integrator, which is frozen: every run asks for it)."""
        return StepControl(*(getattr(self, f.name) for f in dataclasses.fields(StepControl)))

    @property
    def goal_oriented(self) -> bool:
        """True with a relaxed zone or a trailing window (switched off for chains whose boundary does
        not license them: ``granchain.backends.effective_integrator``)."""
        return not self.is_exact

    @classmethod
    def relaxed(cls, rtol: float | None = None, atol: float | None = None) -> "AdaptiveRK":
        """The method with the validated relaxed zone: granules more than 4 observed granules behind
        the front at 1000 times looser tolerances; every granule integrated to the end
        (``RELAXED_LAG``, ``RELAXED_FACTOR`` in ``granchain.solve.integrators``). ``rtol``, ``atol`` default
        to the method's validated ``goal_tolerances`` (DP5: 1e-6, 1e-9; RKN4: 3e-6, 3e-9)."""
        return cls(*cls._goal_tolerances(rtol, atol), relaxed_lag=RELAXED_LAG, relaxed_factor=RELAXED_FACTOR)

    @classmethod
    def windowed(cls, rtol: float | None = None, atol: float | None = None) -> "AdaptiveRK":
        """:meth:`relaxed` plus the trailing window 7 observed granules behind the front
        (``WINDOW_LAG``): cost linear in N, peaks as accurate, the averaged pulse's tail not (see
        the class notes)."""
        return cls(*cls._goal_tolerances(rtol, atol), relaxed_lag=RELAXED_LAG, relaxed_factor=RELAXED_FACTOR,
                   window_lag=WINDOW_LAG)

    @classmethod
    def _goal_tolerances(cls, rtol, atol) -> tuple:
        default_rtol, default_atol = cls.goal_tolerances
        return (default_rtol if rtol is None else rtol, default_atol if atol is None else atol)


@dataclass(frozen=True)
class DP5(AdaptiveRK):
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
    Accuracy contract (tests/test_window.py, ``benchmarks/validate_tolerances.py``), at DP5 rtol 1e-6
    (or :class:`RKN4` rtol 3e-6: the ensembles' default) for decorated chains; 1e-8 for chains without
    light granules, whose errors add up along the chain: at rtol 1e-6 their peaks are off by up to
    ~5e-6, with or without these settings; pass ``DP5.windowed(1e-8, 1e-11)`` (or ``relaxed``) for
    such chains (the ensembles' default for the effective chains):

    - :meth:`relaxed` (with RKN4 or DP5, :func:`granchain.ensemble_integrator`): peak
      velocities within 1e-6 (relative), peak times within 1e-5 and peak contact forces within 1e-6 of
      the chain's largest of DOP853 at rtol 1e-10 on random decorated chains (N = 26, DP5 rtol 1e-6,
      RKN4 rtol 3e-6) and their effective chains (rtol 1e-8), and the averaged pulse <v_k(t)> of a
      500-realisation ensemble within 1e-4 (absolute, about 0.01 of its standard error) of the
      untruncated DP5 run's.
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
    (``granchain.backends.kernels.forces.final_energy``). Their final positions are continued ballistically
    and may overlap (contacts behind the window are not resolved): compute no energy from the
    returned positions of a windowed run. The relaxed zone's looser tolerance shows in
    the energy report as a drift typically ~1e-4 instead of ~1e-5 (worst in the paper's set: 2.6e-3,
    peaks unaffected: the drift is the rattling granules' behind the pulse). The exit rule reads the granules
    still integrated (those behind the window are behind the pulse by construction).
    """

    name: ClassVar[str] = "dp5"
    order: ClassVar[int] = 5
    #: The tolerances of :meth:`relaxed` and :meth:`windowed` (validated, tests/test_window.py).
    goal_tolerances: ClassVar[tuple] = (1e-6, 1e-9)

    def describe(self) -> dict:
        record = super().describe()
        if self.is_exact and self.relaxed_factor == RELAXED_FACTOR:  # the record of stores written by granchain < 0.3
            for key in ("relaxed_lag", "relaxed_factor", "window_lag"):
                record.pop(key)
        return record


@dataclass(frozen=True)
class RKN4(AdaptiveRK):
    """Compiled adaptive Runge-Kutta-Nystrom 4(3) (Dormand, El-Mikkawy & Prince 1987, "RKN4(3)4FM"):
    DP5's sibling (the same :class:`~granchain.solve.integrators.StepControl`, goal-oriented zones and
    records), with a method made for x'' = f(x).

    Three force evaluations per step (DP5: six), order 4 with a 3rd-order error estimate, dense
    output by the quintic Hermite interpolant of the positions (``granchain.backends.kernels.rkn4``). A
    decorated chain's step is set by its light granules' oscillations; there this pair neither
    grows nor damps an oscillation up to h omega = 3.77 (DP5 grows beyond h omega ~ 1), and on
    random N = 26 decorated chains it takes ~0.9x DP5's steps at half the force evaluations each.
    Its tolerances are not DP5's: at rtol 1e-5 its peak velocities are as accurate as DP5's at 1e-6
    (and more so at the free end of short chains), but its peak contact forces are not: they set its
    tolerance (``goal_tolerances``), so ``RKN4.relaxed()`` and ``RKN4.windowed()`` (shared with DP5:
    :meth:`DP5.relaxed`, :meth:`DP5.windowed`) take rtol 3e-6
    (the decorated ensembles' :func:`granchain.ensemble_integrator`; tests/test_window.py). For
    smooth chains (no light granules) it saves nothing over DP5 at equal accuracy.
    """

    name: ClassVar[str] = "rkn4"
    order: ClassVar[int] = 4
    needs_conservative_forces: ClassVar[bool] = True

    #: The tolerances of ``RKN4.relaxed()`` and ``RKN4.windowed()`` (those of the decorated ensembles,
    #: ``granchain.ENSEMBLE_RTOL``, ``ENSEMBLE_ATOL``): the loosest rtol tried whose worst error stays within
    #: half the accuracy contract (``benchmarks/validate_tolerances.py``, 2026-11-27; decorated N = 26
    #: chains, ``RKN4.windowed`` as ``simulate`` runs it). The peak contact forces at the pulse front
    #: decide it (velocities and times stay below 0.3 of the contract at every rtol that meets it): worst
    #: force error against DOP853 (rtol 1e-12) on 102 chains / against exact DP5 (rtol 1e-10) on 2,000
    #: more, as fractions of the contract: rtol 1e-5 (the default until then) 1.11 / 1.30, missed on 3 /
    #: 21 chains (relaxed: 1.02 / 1.19, missed on 1 / 15; exact RKN4 the same: not the relaxed zone);
    #: 5e-6 0.60 / 0.70; 4e-6 0.46 / 0.55; 3e-6 **0.36 / 0.42**; 2e-6 0.24 / 0.30. The error grows about
    #: linearly with rtol and scatters by ~2x from chain to chain, and the worst of 2,000 chains was up
    #: to 1.2x the worst of 100: the margin of 2 stands for the realisations never checked (the paper's
    #: set has 120,000). Cost: 1.34x the steps of rtol 1e-5 (10,655 against 7,942 per N = 26 chain; the
    #: paper's run: 1.25x its CPU).
    goal_tolerances: ClassVar[tuple] = (3e-6, 3e-9)

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
class Verlet(Integrator):
    """Compiled fixed-step velocity Verlet (symplectic, order 2).

    Stability: velocity Verlet is stable only for dt * omega_max <= 2, omega_max the chain's highest
    linearised angular frequency. Before integrating, ``dt`` is checked against the safe upper bound
    of ``granchain.solve.integrators.verlet_omega_max`` (every contact at most as compressed as if it held all the pulse's
    energy; Gershgorin bound of M^-1 K); a :class:`granchain.VerletStabilityWarning` is issued when
    dt * omega_max > 2 (the bound is conservative: near it, compare with a smaller dt or DP5).
    Not checked for n < 2, where the contact stiffness has no bound.
    """

    dt: float = 1e-3

    name: ClassVar[str] = "verlet"
    order: ClassVar[int] = 2
    needs_conservative_forces: ClassVar[bool] = True

    def __post_init__(self):
        object.__setattr__(self, "dt", finite_scalar("dt", self.dt, positive=True))

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
    backend: ClassVar[str] = "scipy"

    def __post_init__(self):
        rtol, atol = _tolerances(self.rtol, self.atol)
        object.__setattr__(self, "rtol", rtol)
        object.__setattr__(self, "atol", atol)


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
