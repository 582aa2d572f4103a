"""``simulate``: the exact dynamics of one chain struck at one end."""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from .._status import Status, final_status, peak_at_end
from .._validate import finite_scalar
from ..backends import integrator_as_run
from ..model.chain import Chain
from ..model.contacts import Precompression
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

    Real contacts (``granchain.model.contacts``): ``dissipated_energy`` is the energy a viscoelastic
    law took (integrated with the motion), and ``energy_error`` is then (E_end + E_dissipated - E_0)/E_0.
    For a precompressed chain (``static_force`` F0 > 0) positions are displacements from the static
    state, forces (``peak_force``, ``wall_force``, ``sensor_force``) are total forces, static load
    included (what a gauge measures), and :attr:`peak_dynamic_force` is the peak less F0.
    ``sensor_granule``/``sensor_force`` (sensor, time): the force inside each sensor granule on
    ``t_grid``, the mean of its two contact forces (the embedded-gauge experiments' measure, e.g.
    C. Daraio et al., Phys. Rev. E 73, 026610 (2006)); :meth:`sensor_peak` its maximum.
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
    #: when the chain's boundary switched its relaxed zone and trailing window off (a fixed wall).
    integrator_record: dict | None = None
    dissipated_energy: float = 0.0
    sensor_granule: np.ndarray | None = None
    sensor_force: np.ndarray | None = None

    @property
    def static_force(self) -> float:
        """The chain's precompression F0 (0 without)."""
        return self.chain.static_force

    @property
    def peak_dynamic_force(self) -> np.ndarray | None:
        """Per contact, the peak force less the static load F0 (``peak_force`` without precompression)."""
        return None if self.peak_force is None else self.peak_force - self.chain.static_force

    def sensor_peak(self, until: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(peak force, its time) of each sensor granule's force (:attr:`sensor_force`), the grid sample
        of the maximum refined by the parabola through it and its two neighbours (exact for a smooth
        peak to O(dt^3)): the quantity the embedded-gauge experiments report. ``until``: only grid times
        up to it (the first passage of the pulse, before a wall or a loaded end sends it back through
        the sensor; by default the whole run)."""
        if self.sensor_force is None:
            raise ValueError("no sensor was recorded: simulate(..., t_grid=..., sensors=[k, ...])")
        t = self.t_grid
        end = t.size if until is None else int(np.searchsorted(t, until, side="right"))
        if end < 3:
            raise ValueError(f"until = {until!r} leaves fewer than 3 grid times: the peak needs the pulse's passage")
        t = t[:end]
        peaks, times = [], []
        for f in self.sensor_force[:, :end]:
            i = int(np.nanargmax(f))
            if 0 < i < f.size - 1 and np.isfinite(f[i - 1:i + 2]).all():
                den = f[i - 1] - 2.0 * f[i] + f[i + 1]
                u = 0.5 * (f[i - 1] - f[i + 1]) / den if den < 0 else 0.0
                dt = t[i + 1] - t[i] if u >= 0 else t[i] - t[i - 1]
                peaks.append(f[i] - 0.25 * (f[i - 1] - f[i + 1]) * u)
                times.append(t[i] + u * dt)
            else:
                peaks.append(f[i])
                times.append(t[i])
        return np.array(peaks), np.array(times)

    def wave_speed(self, first: int | None = None, last: int | None = None) -> float:
        """The pulse's speed in granules per unit time: the inverse slope of the least-squares line
        through the observed granules' peak times against their labels, over the labels first..last
        (default: the middle half of the observed granules, away from the struck end where the pulse
        forms and from the far end where it is reflected). Multiply by the granule spacing in metres
        over the time unit (``granchain.units.Scale``) for m/s."""
        labels = np.asarray(self.granule, dtype=float)
        if first is None and last is None:
            k = labels.size
            sel = np.arange(k // 4, max(k // 4 + 2, 3 * k // 4))
        else:
            lo = labels[0] if first is None else first
            hi = labels[-1] if last is None else last
            sel = np.flatnonzero((labels >= lo) & (labels <= hi))
        if sel.size < 2:
            raise ValueError("the wave speed needs at least two observed granules in the range")
        slope = np.polyfit(labels[sel], self.peak_time[sel], 1)[0]
        return float(1.0 / slope)

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
            + (f"dissipated {self.dissipated_energy:.6g}, " if self.chain.contact.dissipates else "")
            + (f"static force {self.chain.static_force:.6g}, " if self.chain.precompression.applied else "")
            + (f"momentum error {self.momentum_error:.2e}" if not self.chain.wall else
               f"wall: peak force {self.peak_wall_force:.9g} at t = {self.peak_wall_force_time:.6f}, impulse {self.wall_impulse:.9g}")
        )
        if not self.chain.ends_at_exit:
            lines.append("# precompressed: the loaded contacts do not open, so the run ends at t_max, not at the pulse's exit")
        if self.integrator_record and "goal_control" in self.integrator_record:
            lines.append(f"# goal-oriented error control {self.integrator_record['goal_control']}")
        return "\n".join(lines)

    def plot(self, kind="traces", quantity="velocity", granules=None, ax=None, **kwargs):
        """Draw the pulse: traces v_k(t) or the space-time diagram; returns the Axes (:func:`granchain.solve.plot.plot_pulse`)."""
        from .plot import plot_pulse  # (matplotlib loads only when a figure is drawn)

        return plot_pulse(self, kind, quantity, granules, ax, **kwargs)

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
                "contact_model": json.dumps(self.chain.describe_model(), sort_keys=True),
                "dissipated_energy": self.dissipated_energy, "static_force": self.chain.static_force,
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
        if self.sensor_force is not None:
            ds["sensor_force"] = (("sensor", "time"), self.sensor_force,
                                  {**rescaled_attrs("force"), "long_name": "force inside the sensor granule (mean of its two contact forces)"})
            ds = ds.assign_coords(sensor=("sensor", self.sensor_granule, {"long_name": "sensor granule (1-based label)", "units": "1"}))
        if self.chain.wall:
            ds.attrs.update(peak_wall_force=self.peak_wall_force, peak_wall_force_time=self.peak_wall_force_time,
                            wall_impulse=self.wall_impulse)
            if self.wall_force is not None:
                ds["wall_force"] = ("time", self.wall_force, {**rescaled_attrs("force"), "long_name": "force on the wall"})
        return ds


def default_t_max(chain: Chain) -> float:
    """A generous time limit: a pulse in any sensible chain crosses a granule in a few time units.

    (Monodisperse: ~1.2 time units per granule; decorated random chains: ~2.4 per large granule.)
    A precompressed chain runs to this time (its contacts never open, so there is no exit to stop
    at): the pulse is faster than linear waves (its solitary wave's speed exceeds the sound speed,
    Nesterenko 2001, Sec. 1.3), so twice the time a linear wave takes to cross the chain
    (:func:`linear_crossing_time`), plus 20, bounds its crossing; the run ends at the smaller of
    the two limits.
    """
    limit = time_limit(chain.size, chain.initial_velocity, chain.n)
    if not chain.ends_at_exit:
        limit = min(limit, 2.0 * float(linear_crossing_time(chain.masses, chain.stiffness, chain.n, chain.static_force)) + 20.0)
    return limit


def linear_crossing_time(masses, stiffness, n: float, static_force: float):
    """The time a linear wave takes to cross a chain precompressed by ``static_force``: the sum over its
    contacts of sqrt(m / k0), k0 = (n-1) c delta0^(n-2) the contact's linear stiffness and m the heavier
    of its two granules (the slower local speed; monodisperse: N / c0, c0 the sound speed). Works on
    batches (rows of ``masses``, ``stiffness``); a wall (infinite mass) is not crossed."""
    m = np.asarray(masses, dtype=float)
    c = np.asarray(stiffness, dtype=float)
    k0 = Precompression(static_force).linear_stiffness(c, n)
    heavier = np.maximum(m[..., :-1], m[..., 1:])
    return np.sum(np.where(np.isfinite(heavier), np.sqrt(heavier / k0), 0.0), axis=-1)


def time_limit(size: int, initial_velocity: float, n: float) -> float:
    """:func:`default_t_max` from the numbers it depends on (for batches of chains)."""
    return 100.0 + 20.0 * size / max(initial_velocity, 1e-3) ** (1.0 - 2.0 / max(n, 2.0))


def simulate(chain: Chain, integrator=None, *, t_grid=None, t_max: float | None = None, stop: str = "exit", exit_margin: float = 3.0, max_steps: int = 20_000_000, peak_rtol: float = 1e-6, sensors=None, backend=None) -> PulseResult:
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
        ``t_grid[-1]``; "t_max" integrates to exactly ``t_max`` (the peaks are then the maxima up to
        it, by request). With "exit" (and ``exit_margin`` > 0, the time the run gives the granules
        behind the front to finish their peaks), a run whose observed granule is still pushed forward
        at its last instant (its "peak" is the end of the run) reports status PEAK_AT_END, not SUCCESS;
        ``exit_margin=0`` asks for the state at the instant the pulse left, peaks so far. A
        precompressed chain has no exit
        (its loaded contacts do not open): it always runs to ``t_max`` (default: twice the linear
        crossing time, :func:`default_t_max`).
    sensors : sequence of int, optional
        1-based labels of sensor granules (granule 1 is the first after a striker): the force inside
        each, the mean of its two contact forces, is recorded on ``t_grid`` (``sensor_force``).
        A sensor needs a contact on each side (not granule 1 of a chain struck on it, not a free last
        granule).
    peak_rtol : float
        Tie rule for the peak: a later local maximum replaces the recorded one
        only if higher by more than this relative amount (keep it above the
        integration error, below any physical difference of interest).
    backend : str or granchain.backends.Backend, optional
        What runs the integrator: None or "cpu" (default), the integrator's own backend (the Numba kernels,
        SciPy for DOP853); "cuda", an NVIDIA GPU (RKN4 on elastic chains; one chain fills a GPU poorly: the
        GPU is for ensembles, and this is for checking a chain against them).
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
    sensor_labels, sensed = _sensor_contacts(chain, sensors, grid)
    from ..backends import Backend, get_backend

    # the integrator's own backend by default (the Numba kernels; SciPy for DOP853), else the one chosen
    chosen = backend if isinstance(backend, Backend) else get_backend(
        integ.backend if backend is None or backend == "cpu" else backend)
    run = chosen.run(integ, chain, t_grid=grid, t_max=t_max, stop_at_exit=(stop == "exit" and chain.ends_at_exit),
                     controls=controls, sensed=sensed)
    status, x, v = run.status, run.positions, run.velocities
    # a granule still speeding up when a run meant to outlast the pulse stopped (its exit rule or time limit)
    # has no peak yet (e.g. behind a heavy striker); stop="t_max" asks for maxima up to a chosen time
    # instead, and exit_margin = 0 for the state at the very instant the pulse left
    # (the final forces only when a peak lies at the end: what decides it, asked of every run)
    if stop == "exit" and controls.exit_margin > 0 and peak_at_end(run.peak_time, run.t_end).any():
        status = final_status(status, run.peak_time, run.t_end, _accelerated(chain, x, v))
    if status != Status.SUCCESS:
        import warnings

        warnings.warn(f"simulate: the integration did not succeed: {Status(status).name} ({Status(status).message}); "
                      "check result.status before using the peaks", RuntimeWarning, stacklevel=2)
    e0, p0 = chain.energy, chain.momentum
    e1, p1 = run.energy, run.momentum
    wall = chain.wall
    return PulseResult(
        chain=chain,
        integrator=integ.name,
        granule=chain.labels,
        peak_velocity=run.peak_velocity,
        peak_time=run.peak_time,
        status=Status(status),
        t_end=run.t_end,
        exit_time=run.exit_time,
        energy_error=float((e1 - e0) / e0),
        momentum_error=float("nan") if wall else float((p1 - p0) / p0),
        n_steps=run.n_steps,
        n_rejected=run.n_rejected,
        n_evaluations=run.n_evaluations,
        t_grid=grid if grid.size else None,
        velocity=np.ascontiguousarray(run.velocity.T) if grid.size else None,
        positions=x,
        velocities=v,
        peak_force=run.peak_force,
        peak_force_time=run.peak_force_time,
        wall_force=run.wall_force if wall and grid.size else None,
        peak_wall_force=float(run.peak_force[-1]) if wall else None,
        peak_wall_force_time=float(run.peak_force_time[-1]) if wall else None,
        wall_impulse=float(p0 - p1) if wall else None,
        integrator_record=integrator_as_run(integ, chain),
        dissipated_energy=run.dissipated_energy,
        sensor_granule=sensor_labels,
        sensor_force=None if sensor_labels is None else 0.5 * (run.contact_force[:, 0::2] + run.contact_force[:, 1::2]).T.copy(),
    )


def _accelerated(chain: Chain, x, v) -> np.ndarray:
    """Per observed granule, whether the final state pushes it forward (its acceleration > 0: its
    velocity still rising), from the chain's own law in NumPy (``contact.force``; for a precompressed
    chain the dynamic forces about the static state, as the kernels integrate them)."""
    law, d0 = chain.contact, chain.overlaps
    f0 = law.force(d0, chain.stiffness, 0.0)
    F = law.force(d0 + (x[:-1] - x[1:]), chain.stiffness, v[:-1] - v[1:]) - f0
    net = np.zeros(chain.size)
    net[1:] += F
    net[:-1] -= F
    obs = chain.observed
    return net[obs] / chain.masses[obs] > 0.0


def _sensor_contacts(chain: Chain, sensors, grid):
    """(labels, contacts): the sensor granules' 1-based labels and their two contacts each (0-based,
    left then right), checked."""
    if sensors is None:
        return None, None
    labels = np.atleast_1d(np.asarray(sensors))
    if labels.ndim != 1 or labels.size == 0 or not np.issubdtype(labels.dtype, np.integer):
        raise ValueError(f"sensors must be a non-empty list of 1-based granule labels, got {sensors!r}")
    if grid.size == 0:
        raise ValueError("a sensor's force is recorded on a time grid: pass t_grid=... with sensors=...")
    idx = labels.astype(np.int64) - 1 + int(chain.striker)  # array index of each sensor granule
    last = chain.size - 1 - int(chain.wall)  # the last granule that moves
    bad = (idx < 1) | (idx > last) | ((idx == last) & (not chain.wall))
    if bad.any():
        k = int(labels[np.flatnonzero(bad)[0]])
        raise ValueError(f"sensor granule {k} has no contact on one side (or is not in the chain): a sensor measures "
                         f"the mean of its two contact forces; choose labels in 2..{last - int(chain.striker) + (1 if chain.wall else 0)}")
    contacts = np.empty(2 * idx.size, dtype=np.int64)
    contacts[0::2] = idx - 1
    contacts[1::2] = idx
    return labels.astype(np.int64), contacts
