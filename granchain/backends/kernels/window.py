"""The active window: which granules are integrated.

``hi``: granules hi..M-1 are exactly at rest in the static state (uncompressed, or at their static
overlaps in a precompressed chain, where the dynamic forces are exactly 0: the initial state's promise,
``granchain.model.contacts.Impulse.rest_ahead``), so only granules 0..hi-1 are integrated. A Runge-Kutta
step spreads motion by at most a few granules per step, so the window is kept :func:`margin` granules
ahead of the last moving one; with that margin the windowed integration is identical, bit for bit, to
integrating all granules. With forces of positions only, motion spreads one granule per two stages
(DP5's six new stages per step reach 4 granules past the last moving one: WINDOW_MARGIN = 5). A
viscoelastic force reads the neighbours' velocities too, and motion spreads one granule per stage
(7 past it: DAMPED_WINDOW_MARGIN = 9).

``lo``: the trailing window (``granchain.DP5(window_lag=...)``) drops granules behind the pulse
across a contact that is open at that moment, or, where every contact behind the pulse stays closed,
across one whose force has fallen below :data:`CUT_FORCE` (:func:`open_contact_behind`).
"""

from __future__ import annotations

import math

from numba import njit

from .forces import contact_force
from .jit import JIT_INLINE, JIT_INTERNAL

#: The force (rescaled units: the struck granule's pulse carries forces of order 1) below which a
#: closed contact behind the pulse may be cut as if it were open. Behind the solitary wave of a
#: monodisperse chain the granules come to rest with their contacts still closed at compressions of
#: rounding size, so no contact ever opens there: the window could not be cut, every step integrated
#: the whole chain behind the pulse and a long chain cost the square of its length. Cutting such a
#: contact drops a force of at most 1e-12 (and its potential energy, ~1e-20) from the granules left
#: behind, whose motion the trailing window stops following anyway.
CUT_FORCE = 1e-12

WINDOW_MARGIN = 5
DAMPED_WINDOW_MARGIN = 9


@njit(**JIT_INLINE)
def margin(p):
    """How far ahead of the last moving granule the window ends, for the model ``p``
    (``records.Params``): farther for a viscoelastic law, whose forces read velocities."""
    return DAMPED_WINDOW_MARGIN if p.gamma > 0.0 else WINDOW_MARGIN


@njit(**JIT_INTERNAL)
def initial_window(x, v, ahead):
    """Window end for a state given at t = 0: ``ahead`` (:func:`margin`) past the last granule that moves."""
    M = x.shape[0]
    last = M - 1
    while last > 0 and x[last] == 0.0 and v[last] == 0.0:
        last -= 1
    return min(M, last + 1 + ahead)


@njit(**JIT_INLINE)
def advance_window(x, v, hi, ahead):
    """New window end: ``ahead`` (:func:`margin`) past the last granule that moved (never shrinks)."""
    M = x.shape[0]
    last = hi - 1
    while last > 0 and x[last] == 0.0 and v[last] == 0.0:
        last -= 1
    return max(hi, min(M, last + 1 + ahead))


@njit(**JIT_INTERNAL)
def open_contact_behind(x, c, p, lo, target):
    """The window start for a cut just behind granule ``target`` (0-based, in the chain): j + 1 for
    the last contact j < target that is open now (x_j <= x_{j+1}; ``x`` and the stiffness ``c`` hold
    the granules and contacts lo..; ``p`` the model's ``records.Params``); if every contact between lo
    and target is closed, the last one whose force is below :data:`CUT_FORCE`; else ``lo`` (no cut)."""
    for j in range(target - 1, lo - 1, -1):
        if x[j - lo] - x[j + 1 - lo] <= 0.0:
            return j + 1
    for j in range(target - 1, lo - 1, -1):
        if contact_force(x[j - lo] - x[j + 1 - lo], c[j - lo], p) <= CUT_FORCE:
            return j + 1
    return lo


@njit(**JIT_INLINE)
def is_finite_window(x, v, hi):
    """Every integrated position and velocity (granules 0..hi-1 of the views) is finite.

    Without a branch per granule (|y| < inf is False for inf and NaN), so that the test vectorises: it
    runs after every step, and a loop that returns at the first bad value cost Verlet ~15 % per step."""
    ok = True
    for k in range(hi):
        ok &= (abs(x[k]) < math.inf) & (abs(v[k]) < math.inf)
    return ok
