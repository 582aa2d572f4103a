"""Outcome codes of one integration, with their messages (plain Python, like scipy's MESSAGES).

The compiled kernels return these integers; they import the module-level constants (Numba
freezes them as compile-time constants). Python code uses :class:`Status`.
"""

from __future__ import annotations

import enum

__all__ = ["Status", "SUCCESS", "T_MAX", "MAX_STEPS", "STEP_UNDERFLOW", "NONFINITE", "NOT_COMPUTED"]

SUCCESS = 0
T_MAX = 1
MAX_STEPS = 2
STEP_UNDERFLOW = 3
NONFINITE = 4
#: Fill value of ``status`` in a store for realisations not computed (yet).
NOT_COMPUTED = -1


class Status(enum.IntEnum):
    """Outcome of one integration (also stored per realisation in ensembles)."""

    SUCCESS = SUCCESS
    T_MAX = T_MAX
    MAX_STEPS = MAX_STEPS
    STEP_UNDERFLOW = STEP_UNDERFLOW
    NONFINITE = NONFINITE

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
}


def describe_codes() -> str:
    """'0 = SUCCESS: ...; 1 = T_MAX: ...' for file attributes."""
    return "; ".join(f"{int(s)} = {s.name}: {s.message}" for s in Status)
