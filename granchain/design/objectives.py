"""Objectives: what a design is judged by, computed from one run of its chain.

Each objective computes its value two ways that agree: from the per-row outputs of the compiled
batch kernel (``Integrator.integrate_batch``: peak velocities and times of the observed granules,
peak forces of the recorded contacts, the wall's peak force and its time) and from a
:class:`granchain.PulseResult` of :func:`granchain.simulate` (the check of a reported optimum).

Two objectives need the *history* of the wall force of each design (:class:`ImpulseDuration`, and
:class:`TransmittedMomentum` against a wall): the batch kernel sums the wall force over its rows
(the ensemble-averaged wall force), it does not keep one row's. Those are evaluated design by
design with :func:`granchain.simulate` (``route == "history"``), a documented slower path.

Units are the paper's rescaled ones (Sec. II); ``kind`` names the quantity for
:meth:`granchain.units.Scale.to_si` ("1" for a ratio).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

__all__ = [
    "OBJECTIVES",
    "ArrivalTime",
    "ImpulseDuration",
    "Objective",
    "SensorForce",
    "TransmittedEnergy",
    "TransmittedMomentum",
    "WallForce",
    "get_objective",
]


class Objective:
    """Base of the objectives. ``sense`` is +1 when smaller is better, -1 when larger is better;
    ``boundary`` is "wall" (needs a chain ending in a fixed wall: immovable, of the granules' material, contact
    stiffness sqrt(2 R_M); not the infinitely stiff ``wall_material="rigid"`` of :meth:`granchain.Chain.with_wall`), "free" (needs a free end) or "any"."""

    name: ClassVar[str]
    long_name: ClassVar[str]
    kind: ClassVar[str] = "1"
    boundary: ClassVar[str] = "any"
    sense: int = 1

    def __post_init__(self):
        if self.sense not in (1, -1) or isinstance(self.sense, bool):
            raise ValueError(f"sense must be +1 (smaller is better) or -1 (larger is better), got {self.sense!r}")

    def bind(self, size: int) -> None:
        """Refuse a chain of ``size`` granules (the wall excluded) this objective cannot read, before any
        integration."""
        self.contacts(size)

    def check(self, wall: bool) -> None:
        """Refuse a chain whose end this objective cannot judge, saying what to change."""
        if self.boundary == "wall" and not wall:
            raise ValueError(f"the objective {self.name!r} ({self.long_name}) needs a chain that ends in a fixed wall: "
                             "build the space with wall=True (CLI: the design sub-command adds the wall for this objective)")
        if self.boundary == "free" and wall:
            raise ValueError(f"the objective {self.name!r} ({self.long_name}) needs a free far end (a fixed wall does no work, "
                             "so it takes no energy): build the space with wall=False, or judge the wall by 'wall-force' "
                             "or 'impulse-duration'")

    def route(self, wall: bool) -> str:
        """"rows" (from the batch kernel's per-row outputs) or "history" (design by design, simulate)."""
        return "rows"

    def contacts(self, size: int) -> np.ndarray:
        """The 0-based contacts whose peak forces the batch must record."""
        return np.zeros(1, dtype=np.int64)

    def from_rows(self, rows: dict, batch) -> np.ndarray:
        raise NotImplementedError

    def from_result(self, result) -> float:
        raise NotImplementedError

    def describe(self) -> dict:
        return {"objective": self.name, "sense": "minimise" if self.sense > 0 else "maximise"}

    def __str__(self) -> str:
        return self.long_name


@dataclass(frozen=True)
class WallForce(Objective):
    """The peak force on the fixed wall (immovable, of the granules' material), max_t c_M delta_M(t)^(n-1) (the wall contact of Eq.
    motion_rescaled, stiffness sqrt(2 R_M), the limit of Eq. r-prime): what a protector transmits
    to what it protects. Minimised."""

    name: ClassVar[str] = "wall-force"
    long_name: ClassVar[str] = "peak force on the wall"
    kind: ClassVar[str] = "force"
    boundary: ClassVar[str] = "wall"
    sense: int = 1

    def from_rows(self, rows, batch):
        return rows["peak_wall_force"].copy()

    def from_result(self, result):
        return float(result.peak_wall_force)


@dataclass(frozen=True)
class SensorForce(Objective):
    """The peak force of the contact between granules ``granule`` and ``granule`` + 1 (1-based), as a
    force sensor there would read it. Minimised."""

    granule: int = 1
    sense: int = 1
    name: ClassVar[str] = "sensor-force"
    long_name: ClassVar[str] = "peak force of a contact"
    kind: ClassVar[str] = "force"

    def __post_init__(self):
        super().__post_init__()
        from .._validate import count

        object.__setattr__(self, "granule", count("granule", self.granule, minimum=1))

    def contacts(self, size):
        if not 1 <= self.granule < size:
            raise ValueError(f"the sensor contact lies between granules {self.granule} and {self.granule + 1}: "
                             f"choose granule in 1..{size - 1}")
        return np.array([self.granule - 1], dtype=np.int64)

    def from_rows(self, rows, batch):
        return rows["peak_force"][:, 0].copy()

    def from_result(self, result):
        return float(result.peak_force[self.granule - 1])

    def describe(self):
        return {**super().describe(), "granule": self.granule}


def _last_observed(batch) -> int:
    last = int(batch.observed[-1])
    M = batch.masses.shape[1] - int(np.isinf(batch.masses[0, -1]))
    if last != M - 1:
        raise ValueError("the transmitted energy and momentum are those of the last granule: it must be observed")
    return last


@dataclass(frozen=True)
class TransmittedEnergy(Objective):
    """The energy the pulse carries out of a chain with a free end: the kinetic energy of the last
    granule at its peak velocity, m_M v_M^2 / 2, as a fraction of the input m_1 v_1^2 / 2 (the
    quantity by which tapered chains are called shock absorbers: Sen et al.; Doney & Sen, PRL 97,
    155502 (2006)). Once its contact opens the last granule flies off at that speed, unless a
    granule behind catches it up later. Minimised."""

    name: ClassVar[str] = "transmitted-energy"
    long_name: ClassVar[str] = "energy of the last granule / input energy"
    boundary: ClassVar[str] = "free"
    sense: int = 1

    def from_rows(self, rows, batch):
        last = _last_observed(batch)
        m, v = batch.masses[:, last], rows["peak_velocity"][:, -1]
        return (m * v * v) / (batch.masses[:, 0] * batch.initial_velocity**2)

    def from_result(self, result):
        ch = result.chain
        return float(ch.masses[-1] * result.peak_velocity[-1] ** 2 / (ch.masses[0] * ch.initial_velocity**2))


@dataclass(frozen=True)
class TransmittedMomentum(Objective):
    """The momentum transmitted, as a fraction of the input m_1 v_1: with a free end, the last
    granule's at its peak velocity, m_M v_M; against a fixed wall, the impulse the wall takes,
    P_0 - P_end (:attr:`granchain.PulseResult.wall_impulse`; 2 for one granule bouncing back, more
    when the chain comes back in pieces). Minimised."""

    name: ClassVar[str] = "transmitted-momentum"
    long_name: ClassVar[str] = "transmitted momentum / input momentum"
    sense: int = 1

    def route(self, wall):
        return "history" if wall else "rows"

    def from_rows(self, rows, batch):
        last = _last_observed(batch)
        return batch.masses[:, last] * rows["peak_velocity"][:, -1] / (batch.masses[:, 0] * batch.initial_velocity)

    def from_result(self, result):
        ch = result.chain
        p0 = ch.masses[0] * ch.initial_velocity
        if ch.wall:
            return float(result.wall_impulse / p0)
        return float(ch.masses[-1] * result.peak_velocity[-1] / p0)


@dataclass(frozen=True)
class ImpulseDuration(Objective):
    """The time over which the wall receives the central ``fraction`` of its impulse: t_hi - t_lo
    where the accumulated impulse int_0^t F_wall dt' reaches (1 - fraction)/2 and (1 + fraction)/2 of
    its total (trapezoids on the force's time grid, linear between samples). A protector that
    spreads the same impulse over a longer time lowers the force. Maximised."""

    fraction: float = 0.9
    sense: int = -1
    name: ClassVar[str] = "impulse-duration"
    long_name: ClassVar[str] = "duration of the wall's impulse"
    kind: ClassVar[str] = "time"
    boundary: ClassVar[str] = "wall"

    def __post_init__(self):
        super().__post_init__()
        try:
            fraction = float(self.fraction)
        except (TypeError, ValueError):
            fraction = float("nan")
        if not 0.0 < fraction < 1.0:
            raise ValueError(f"fraction = {self.fraction!r} is the share of the impulse whose duration is measured: give 0 < fraction < 1")

    def route(self, wall):
        return "history"

    def from_result(self, result):
        return impulse_duration(result.t_grid, result.wall_force, self.fraction)

    def describe(self):
        return {**super().describe(), "fraction": float(self.fraction)}


def impulse_duration(t: np.ndarray, force: np.ndarray, fraction: float) -> float:
    """t_hi - t_lo of the accumulated impulse (see :class:`ImpulseDuration`)."""
    t, f = np.asarray(t, dtype=float), np.asarray(force, dtype=float)
    acc = np.concatenate(([0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(t))))
    total = acc[-1]
    if not total > 0:
        return float("nan")
    lo, hi = np.interp([(1 - fraction) / 2 * total, (1 + fraction) / 2 * total], acc, t)
    return float(hi - lo)


@dataclass(frozen=True)
class ArrivalTime(Objective):
    """When the pulse arrives: the time of the wall's peak force (against a wall) or of the last
    granule's peak velocity (free end). ``sense=-1`` (the default) maximises it: a delay line."""

    sense: int = -1
    name: ClassVar[str] = "arrival-time"
    long_name: ClassVar[str] = "arrival time of the pulse"
    kind: ClassVar[str] = "time"

    def from_rows(self, rows, batch):
        if np.isinf(batch.masses[0, -1]):
            return rows["peak_wall_force_time"].copy()
        return rows["peak_time"][:, -1].copy()

    def from_result(self, result):
        return float(result.peak_wall_force_time if result.chain.wall else result.peak_time[-1])


#: Objectives by CLI name.
OBJECTIVES = {cls.name: cls for cls in (WallForce, SensorForce, TransmittedEnergy, TransmittedMomentum, ImpulseDuration,
                                         ArrivalTime)}


def get_objective(objective) -> Objective:
    """An objective instance, or one by name (:data:`OBJECTIVES`)."""
    if isinstance(objective, Objective):
        return objective
    if isinstance(objective, str) and objective in OBJECTIVES:
        return OBJECTIVES[objective]()
    raise ValueError(f"unknown objective {objective!r}; choose one of {sorted(OBJECTIVES)} or pass an Objective")
