"""``simulate``: the exact dynamics of one chain struck at one end."""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from .._status import Status
from .._validate import finite_scalar
from ..backends import integrator_as_run
from ..backends.kernels.forces import final_energy, total_momentum
from ..backends.kernels.records import (
    INFO_EVALUATIONS,
    INFO_EXIT,
    INFO_REJECTED,
    INFO_STEPS,
    INFO_T_END,
)
from ..model.chain import Chain
from ..units import rescaled_attrs
from .integrators import RunControls, get_integrator

__all__ = ["Status", "PulseResult", "simulate", "default_t_max"]


@dataclass(frozen=True, eq=False)
class PulseResult:
    """What one integration gives, per observed granule and for the run.

    ``granule`` holds 1-based indices of the observed granules (for a decorated
    chain: 1, 3, 5, ... in the full chain); ``peak_velocity``/``peak_time`` the
    maximum of v_k(t) and its time, located between steps. ``energy_error`` is
    (E_end - E_0)/E_0, ``momentum_error`` (P_end - P_0)/P_0. ``velocity`` is
    (observed granule, time) on ``t_grid`` when a grid was requested.

    ``peak_force``/``peak_force_time``: per contact j = 1..M-1 (between granules j and
    j+1, 1-based), the maximum contact force c_j delta^(n-1) (Eq. motion_rescaled) and its
    time, located between steps at the compression maximum (0 at t = 0 for a contact that
    never closed). With a wall (``chain.wall``) the last contact is the wall's:
    ``peak_wall_force``/``peak_wall_force_time`` repeat it, ``wall_force`` is the wall force
    on ``t_grid`` (when a grid was requested), and ``wall_impulse`` = P_0 - P_end is the
    momentum the wall took (= the time integral of the wall force); momentum is then not
    conserved and ``momentum_error`` is NaN. Without a wall these are None.

    ``positions``/``velocities`` are the final state. With a trailing window (``DP5(window_lag=...)``)
    the granules that left it keep the velocity they left with and their positions are continued
    ballistically (they may overlap: ``energy_error`` is computed from the energies they had when
    they left, see ``granchain.DP5``).
    """

    chain: Chain
    integrator: str
    granule: np.ndarray
    peak_velocity: np.ndarray
    peak_time: np.ndarray
    status: Status
    t_end: float
    exit_time: float
    energy_error: float
    momentum_error: float
    n_steps: int
    n_rejected: int
    n_evaluations: int
    t_grid: np.ndarray | None
    velocity: np.ndarray | None
    positions: np.ndarray
    velocities: np.ndarray
    peak_force: np.ndarray | None = None
    peak_force_time: np.ndarray | None = None
    wall_force: np.ndarray | None = None
    peak_wall_force: float | None = None
    peak_wall_force_time: float | None = None
    wall_impulse: float | None = None
    #: The integrator as it ran on this chain (``describe()``), with ``"goal_control"`` saying why
    #: when the chain's boundary switched its relaxed zone and trailing window off (a rigid wall).
    integrator_record: dict | None = None

    @property
    def ok(self) -> bool:
        return self.status == Status.SUCCESS

    @property
    def message(self) -> str:
        return self.status.message

    def table(self, labels=None) -> str:
        """A readable table of peak velocity and peak time per observed granule.

        ``labels`` replaces the 1-based chain indices in the first column (e.g. the
        large-granule index k = 1..N of a decorated chain).
        """
        labels = self.granule if labels is None else labels
        lines = [f"{'granule':>8} {'peak_velocity':>15} {'peak_time':>12}"]
        for k, vp, tp in zip(labels, self.peak_velocity, self.peak_time):
            lines.append(f"{k:8d} {vp:15.9f} {tp:12.6f}")
        lines.append(
            f"# {self.chain.kind} chain, M = {self.chain.size}, n = {self.chain.n:g}, integrator {self.integrator}: "
            f"{self.status.name} ({self.message}); t_end = {self.t_end:.4g}, steps = {self.n_steps} "
            f"(+{self.n_rejected} rejected), energy error {self.energy_error:.2e}, "
            + (f"momentum error {self.momentum_error:.2e}" if not self.chain.wall else
               f"wall: peak force {self.peak_wall_force:.9g} at t = {self.peak_wall_force_time:.6f}, impulse {self.wall_impulse:.9g}")
        )
        if self.integrator_record and "goal_control" in self.integrator_record:
            lines.append(f"# goal-oriented error control {self.integrator_record['goal_control']}")
        return "\n".join(lines)

    def to_dataset(self):
        """The result as an ``xarray.Dataset`` (granule dimension, 1-based)."""
        import xarray as xr

        ds = xr.Dataset(
            {
                "peak_velocity": ("granule", self.peak_velocity, {**rescaled_attrs("velocity"), "long_name": "maximum velocity of the granule"}),
                "peak_time": ("granule", self.peak_time, {**rescaled_attrs("time"), "long_name": "time of the maximum velocity"}),
            },
            coords={"granule": ("granule", self.granule, {"long_name": "granule index (1-based)", "units": "1"})},
            attrs={
                "status": int(self.status), "status_message": self.message, "integrator": self.integrator,
                "energy_error": self.energy_error, "momentum_error": self.momentum_error,
                "n_steps": self.n_steps, "t_end": self.t_end, "chain_kind": self.chain.kind, "n": self.chain.n,
            },
        )
        if self.integrator_record is not None:
            ds.attrs["integrator_record"] = json.dumps(self.integrator_record, sort_keys=True)
        if self.velocity is not None:
            ds["velocity"] = (("granule", "time"), self.velocity, {**rescaled_attrs("velocity"), "long_name": "velocity"})
            ds = ds.assign_coords(time=("time", self.t_grid, {**rescaled_attrs("time"), "long_name": "time"}))
        if self.peak_force is not None:
            ds["peak_force"] = ("contact", self.peak_force, {**rescaled_attrs("force"), "long_name": "maximum contact force c delta^(n-1)"})
            ds["peak_force_time"] = ("contact", self.peak_force_time, {**rescaled_attrs("time"),
                                                                       "long_name": "time of the maximum contact force"})
            last = "; the last is the wall contact" if self.chain.wall else ""
            ds = ds.assign_coords(contact=("contact", np.arange(1, self.peak_force.size + 1),
                                           {"long_name": f"contact j between granules j and j+1 (1-based){last}", "units": "1"}))
        if self.chain.wall:
            ds.attrs.update(peak_wall_force=self.peak_wall_force, peak_wall_force_time=self.peak_wall_force_time,
                            wall_impulse=self.wall_impulse)
            if self.wall_force is not None:
                ds["wall_force"] = ("time", self.wall_force, {**rescaled_attrs("force"), "long_name": "force on the wall"})
        return ds


def default_t_max(chain: Chain) -> float:
    """A generous time limit: a pulse in any sensible chain crosses a granule in a few time units.

    (Monodisperse: ~1.2 time units per granule; decorated random chains: ~2.4 per large granule.)
    """
    return time_limit(chain.size, chain.initial_velocity, chain.n)


def time_limit(size: int, initial_velocity: float, n: float) -> float:
    """:func:`default_t_max` from the numbers it depends on (for batches of chains)."""
    return 100.0 + 20.0 * size / max(initial_velocity, 1e-3) ** (1.0 - 2.0 / max(n, 2.0))


def simulate(chain: Chain, integrator=None, *, t_grid=None, t_max: float | None = None, stop: str = "exit", exit_margin: float = 3.0, max_steps: int = 20_000_000, peak_rtol: float = 1e-6) -> PulseResult:
    """Integrate Eq. (motion_rescaled) for one chain struck at granule 1.

    Parameters
    ----------
    chain : Chain
        Any chain (``granchain.from_radii``, ``decorated``, ``effective``, ...).
    integrator : DP5 | Verlet | DOP853 | str, optional
        Default: ``DP5()`` (compiled adaptive Dormand-Prince 5(4)). "dop853" is
        SciPy's reference integrator.
    t_grid : array, optional
        Ascending times >= 0 at which to record the observed granules' velocities.
    t_max : float, optional
        Hard time limit (default :func:`default_t_max`).
    stop : "exit" or "t_max"
        "exit" (default) stops ``exit_margin`` time units after the pulse has
        left the last granule (last contact open and the last granule faster
        than every other one) or, for a chain ending in a wall, after the pulse
        has come back from the wall (wall contact open and the granule next to it
        moving away, without a break for ``exit_margin``), and not before
        ``t_grid[-1]``; "t_max" integrates to exactly ``t_max``.
    peak_rtol : float
        Tie rule for the peak: a later local maximum replaces the recorded one
        only if higher by more than this relative amount (keep it above the
        integration error, below any physical difference of interest).
    """
    if not isinstance(chain, Chain):
        raise ValueError(f"simulate() needs a granchain.Chain, got {type(chain).__name__}")
    integ = get_integrator(integrator)
    if stop not in ("exit", "t_max"):
        raise ValueError(f"stop must be 'exit' or 't_max', got {stop!r}")
    t_max = default_t_max(chain) if t_max is None else finite_scalar("t_max", t_max, positive=True)
    controls = RunControls(exit_margin, max_steps, peak_rtol)
    # a C-contiguous copy of a strided grid: the kernels take C-contiguous arrays
    grid = np.zeros(0) if t_grid is None else np.ascontiguousarray(t_grid, dtype=float).reshape(-1)
    if grid.size:
        if not np.all(np.isfinite(grid)) or grid[0] < 0 or np.any(np.diff(grid) <= 0):
            raise ValueError("t_grid must be finite, >= 0 and strictly increasing")
        if stop == "t_max" and grid[-1] > t_max:
            raise ValueError(f"t_grid ends at {grid[-1]:g}, beyond t_max = {t_max:g}")
        t_max = max(t_max, float(grid[-1]))
    x = np.zeros(chain.size)
    v = np.zeros(chain.size)
    v[0] = chain.initial_velocity
    status, info, peak_v, peak_t, grid_v, peak_f, peak_ft, grid_f = integ.integrate(
        chain, x, v, t_grid=grid, t_max=t_max, stop_at_exit=(stop == "exit"), controls=controls
    )
    if status != Status.SUCCESS:
        import warnings

        warnings.warn(f"simulate: the integration did not succeed: {Status(status).name} ({Status(status).message}); "
                      "check result.status before using the peaks", RuntimeWarning, stacklevel=2)
    e0, p0 = chain.energy, chain.momentum
    e1 = final_energy(x, v, chain.masses, chain.stiffness, chain.n, info)
    p1 = total_momentum(v, chain.masses)
    wall = chain.wall
    return PulseResult(
        chain=chain,
        integrator=integ.name,
        granule=chain.observed + 1,
        peak_velocity=peak_v,
        peak_time=peak_t,
        status=Status(status),
        t_end=float(info[INFO_T_END]),
        exit_time=float(info[INFO_EXIT]),
        energy_error=float((e1 - e0) / e0),
        momentum_error=float("nan") if wall else float((p1 - p0) / p0),
        n_steps=int(info[INFO_STEPS]),
        n_rejected=int(info[INFO_REJECTED]),
        n_evaluations=int(info[INFO_EVALUATIONS]),
        t_grid=grid if grid.size else None,
        velocity=np.ascontiguousarray(grid_v.T) if grid.size else None,
        positions=x,
        velocities=v,
        peak_force=peak_f,
        peak_force_time=peak_ft,
        wall_force=grid_f if wall and grid.size else None,
        peak_wall_force=float(peak_f[-1]) if wall else None,
        peak_wall_force_time=float(peak_ft[-1]) if wall else None,
        wall_impulse=float(p0 - p1) if wall else None,
        integrator_record=integrator_as_run(integ, chain),
    )
