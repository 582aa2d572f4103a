"""Outcome codes of one integration, with their messages (plain Python, like scipy's MESSAGES).

The compiled kernels return these integers; they import the module-level constants (Numba
freezes them as compile-time constants). Python code uses :class:`Status`.
"""

from __future__ import annotations

import enum

__all__ = ["Status", "SUCCESS", "T_MAX", "MAX_STEPS", "STEP_UNDERFLOW", "NONFINITE", "PEAK_AT_END", "NOT_COMPUTED",
           "peak_at_end", "final_status"]

SUCCESS = 0
T_MAX = 1
MAX_STEPS = 2
STEP_UNDERFLOW = 3
NONFINITE = 4
#: The run ended (at its exit rule or its time limit) while an observed granule was still speeding up:
#: its recorded "peak" is the last instant of the run, not a maximum (decided after the run, in Python).
PEAK_AT_END = 5
#: Fill value of ``status`` in a store for realisations not computed (yet).
NOT_COMPUTED = -1


class Status(enum.IntEnum):
    """Outcome of one integration (also stored per realisation in ensembles)."""

    SUCCESS = SUCCESS
    T_MAX = T_MAX
    MAX_STEPS = MAX_STEPS
    STEP_UNDERFLOW = STEP_UNDERFLOW
    NONFINITE = NONFINITE
    PEAK_AT_END = PEAK_AT_END

    @property
    def message(self) -> str:
        return _MESSAGES[self]


_MESSAGES = {
    Status.SUCCESS: "finished: the pulse left the last granule, or came back from the wall (stop='exit'), "
                    "or t_max was reached (stop='t_max')",
    Status.T_MAX: "t_max was reached before the pulse left the last granule: raise t_max",
    Status.MAX_STEPS: "the step budget (max_steps) ran out: raise max_steps or loosen rtol",
    Status.STEP_UNDERFLOW: "the step size underflowed: the chain is too stiff for these tolerances",
    Status.NONFINITE: "the state became non-finite (NaN/inf)",
    Status.PEAK_AT_END: "the run ended while an observed granule was still speeding up, so its 'peak' is the end of "
                        "the run, not a maximum (a late hump from rattling light granules, or a heavy striker still "
                        "pushing): give the granules more time with a larger exit_margin, or run to a fixed time "
                        "(stop='t_max', t_max=...)",
}


def peak_at_end(peak_time, t_end, *, rtol: float = 1e-12):
    """Whether each observed granule's located peak lies at the last instant of the run (its velocity
    still rising when the run stopped): boolean array like ``peak_time`` (works on rows of an ensemble:
    ``t_end`` then broadcasts per row). A peak at t = 0 (the struck granule) is a real one; the test is
    relative to the run's length, so that rounding of the located time does not hide it."""
    import numpy as np

    t = np.asarray(peak_time, dtype=float)
    end = np.asarray(t_end, dtype=float)
    if t.ndim > end.ndim:
        end = end.reshape(end.shape + (1,) * (t.ndim - end.ndim))
    return (end > 0.0) & (t >= end * (1.0 - rtol))


def final_status(status: int, peak_time, t_end, rising=None) -> int:
    """The status a run reports: the kernel's ``status``, or :data:`PEAK_AT_END` when the kernel
    finished (SUCCESS) but an observed granule's peak lies at the run's last instant (:func:`peak_at_end`)
    while it is still accelerated forward (``rising``, a boolean per observed granule; None: assume so).
    A granule whose peak is at the end but whose force has just vanished (the last granule of a run
    stopped with no margin the instant its contact opened) has a genuine maximum there. A failure the
    kernel reported (T_MAX, MAX_STEPS, ...) says more and is kept."""
    if int(status) != SUCCESS:
        return int(status)
    at_end = peak_at_end(peak_time, t_end)
    if rising is not None:
        import numpy as np

        at_end = at_end & np.asarray(rising, dtype=bool)
    return PEAK_AT_END if bool(at_end.any()) else SUCCESS


def describe_codes() -> str:
    """'0 = SUCCESS: ...; 1 = T_MAX: ...' for file attributes."""
    return "; ".join(f"{int(s)} = {s.name}: {s.message}" for s in Status)
