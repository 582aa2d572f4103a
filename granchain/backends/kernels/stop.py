"""When a run ends: the pulse has left the chain through its free end, or come back from a wall.

The boundary (``granchain.model.contacts.FreeEnd`` or ``FixedWall``) decides which rule applies; the
kernels get it as ``Params.wall``, asked once.
"""

from __future__ import annotations

from numba import njit

from ..._status import SUCCESS, T_MAX
from .jit import JIT_INLINE

#: Granules lighter than this fraction of the last granule's mass are "rattlers":
#: they do not hold the exit of the pulse (see pulse_has_left).
RATTLER_MASS_RATIO = 0.1


@njit(**JIT_INLINE)
def pulse_has_left(x, v, m, gap=0.0):
    """The pulse has left the chain through its last granule.

    Conditions: the last contact is open, the last granule moves away from its
    neighbour (v_M > v_{M-1}) and outruns every granule at least
    RATTLER_MASS_RATIO as heavy as itself (all granules of a plain chain, the
    large ones of a decorated chain). A light granule flung ahead of the pulse
    can open the last contact early, but then the last granule is slow and the
    pulse behind it is faster, so the integration goes on. Light granules
    rattling between heavy ones behind the pulse are not the pulse and do not
    hold the run.

    ``gap``: the compression at or below which the last contact is open, 0 but for a contact that has
    yielded (Thornton's law: its plastic overlap, the dent it keeps; ``forces.unloading_curve``).
    """
    M = x.shape[0]
    if x[M - 2] - x[M - 1] > gap:
        return False
    vl = v[M - 1]
    if vl <= 0.0 or v[M - 2] >= vl:
        return False
    m_min = RATTLER_MASS_RATIO * m[M - 1]
    for k in range(M - 1):
        if v[k] >= vl and m[k] >= m_min:
            return False
    return True


@njit(**JIT_INLINE)
def wall_released(x, v, gap=0.0):
    """The pulse has come back from the wall: the wall contact is open and the granule
    next to the wall moves away from it (v < 0). The run ends ``exit_margin`` after this
    has held without a break (it resets if the granule is pushed back), so "for good"
    means: for at least exit_margin."""
    M = x.shape[0]
    return x[M - 2] - x[M - 1] <= gap and v[M - 2] < 0.0


@njit(**JIT_INLINE)
def pulse_is_out(x, v, m, wall, gap=0.0):
    """The stop condition: :func:`wall_released` with a wall, else :func:`pulse_has_left`."""
    if wall:
        return wall_released(x, v, gap)
    return pulse_has_left(x, v, m, gap)


@njit(**JIT_INLINE)
def end_of_step(x, v, m, wall, hi, t, run, exit_since, t_needed, gap=0.0):
    """Bookkeeping after an accepted step: (status, or -1 to go on; updated exit_since).

    ``exit_since`` is the time since which the pulse has been out of the chain, or
    back from the wall (-1 while it is not); the run succeeds ``run.exit_margin`` later
    (not before t_needed). ``gap``: see :func:`pulse_has_left`.
    """
    if run.stop_at_exit:
        if hi == x.shape[0] and pulse_is_out(x, v, m, wall, gap):
            if exit_since < 0.0:
                exit_since = t
            if t >= max(exit_since + run.exit_margin, t_needed):
                return SUCCESS, exit_since
        else:
            exit_since = -1.0
    if t == run.t_max:
        return (T_MAX if run.stop_at_exit else SUCCESS), exit_since
    return -1, exit_since


@njit(**JIT_INLINE)
def stop_time(run, exit_since, t_needed):
    """Where the run must end: exit_margin after the exit (not before t_needed), at most t_max."""
    if exit_since < 0.0:
        return run.t_max
    return min(run.t_max, max(exit_since + run.exit_margin, t_needed))
