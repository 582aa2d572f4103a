"""Building blocks shared by the integrators: forces, energy, pulse bookkeeping.

Equation of motion, paper Eq. (motion_rescaled):
    m_k x_k'' = c_{k-1} (x_{k-1} - x_k)^(n-1) theta(x_{k-1} - x_k)
              - c_k     (x_k - x_{k+1})^(n-1) theta(x_k - x_{k+1}).

A rigid wall at the far end is a last granule of infinite mass (inverse mass 0,
contact stiffness sqrt(2 R_M), the limit of Eq. r-prime): it never moves, and the
same force routines serve it; only the stop rule (:func:`pulse_is_out`) and the
energy and momentum sums (which skip it) know about it.

Contact forces: the force c_k delta^(n-1) of contact k peaks where its
compression delta = x_k - x_{k+1} does, i.e. where the relative velocity
v_k - v_{k+1} changes sign from + to - (the integrators locate that root between
steps, as they locate the velocity peaks).

The "window" ``hi``: granules hi..M-1 are exactly at rest and uncompressed, so
only granules 0..hi-1 are integrated. A Runge-Kutta step spreads motion by at
most a few granules per step (one per two stages), so the window is kept
``WINDOW_MARGIN`` granules ahead of the last moving one; with that margin the
windowed integration is identical, bit for bit, to integrating all granules.
"""

from __future__ import annotations

import math

import numba
from numba import njit, types
from numba.core import errors
from numba.extending import intrinsic, overload

from ._jit import JIT, JIT_INLINE

# Status codes of one integration: defined with their messages in plain Python (granchain._status).
from .._status import MAX_STEPS, NONFINITE, STEP_UNDERFLOW, SUCCESS, T_MAX  # noqa: E402,F401

# Slots of the ``info`` array every single-chain kernel fills.
INFO_T_END = 0  # time the run stopped
INFO_STEPS = 1  # accepted steps
INFO_REJECTED = 2  # rejected steps
INFO_EXIT = 3  # time the pulse left the last granule (-1: it did not)
INFO_EVALUATIONS = 4  # force evaluations (whole-window sweeps)
INFO_WINDOW_START = 5  # first granule still integrated at the end (0-based; > 0 only with a trailing window)
INFO_FROZEN_POTENTIAL = 6  # potential energy of the contacts behind the window when they left it
INFO_SIZE = 7


@intrinsic
def _data_pointer(typingctx, arr):
    """The data pointer of an array (for :func:`borrowed`)."""
    sig = types.CPointer(arr.dtype)(arr)

    def codegen(context, builder, signature, args):
        return context.make_array(signature.args[0])(context, builder, args[0]).data

    return sig, codegen


def borrowed(a):
    """A view of ``a`` that does not own its memory (compiled: ``numba.carray`` on its data pointer), so
    that passing it to a function costs no reference counting. Numba passes every owning array with an
    atomic increment and decrement of its reference count (NRT); in DP5's step loop, whose helpers see a
    dozen arrays every step, that was half of the run time (profiled with perf).

    The caller must keep ``a`` alive for as long as the view is used (:func:`keep_alive`); the
    arguments of a function are kept alive by its caller. Plain Python (``NUMBA_DISABLE_JIT``): ``a``."""
    return a


@overload(borrowed, jit_options=JIT)
def _borrowed_compiled(a):
    if not (isinstance(a, types.Array) and a.layout == "C"):  # carray assumes C order
        raise errors.TypingError(f"borrowed() takes a C-contiguous array, got {a}")

    def impl(a):
        return numba.carray(_data_pointer(a), a.shape)

    return impl


@njit(**JIT)
def keep_alive(*arrays):
    """Does nothing: a use of ``arrays`` after the last use of their :func:`borrowed` views, so that
    Numba releases them only after that."""
    return None


# Fast paths for the contact power delta^(n-1).
POW_GENERAL = 0
POW_HERTZ = 1  # n = 5/2: delta * sqrt(delta)
POW_LINEAR = 2  # n = 2: delta

WINDOW_MARGIN = 5


def power_code(n: float) -> int:
    if n == 2.5:
        return POW_HERTZ
    if n == 2.0:
        return POW_LINEAR
    return POW_GENERAL


@njit(**JIT)
def contact_force(d, c, n, pw):
    """c * d^(n-1) for d > 0, else 0 (Eq. motion_rescaled)."""
    if d <= 0.0:
        return 0.0
    if pw == POW_HERTZ:
        return c * d * math.sqrt(d)
    if pw == POW_LINEAR:
        return c * d
    return c * d ** (n - 1.0)


@njit(**JIT_INLINE)
def accelerations(x, c, inv_m, n, pw, hi, F, a):
    """a_k for k < hi (Eq. motion_rescaled).

    ``F`` is scratch of length >= hi + 1: F[j + 1] receives the force of contact j, and F[0] (the free
    end) and F[hi] past the last granule (when hi = M) are set to 0, so that a_k = (F[k] - F[k + 1]) / m_k
    for every k, the chain's ends included, in one loop that vectorises."""
    M = x.shape[0]
    nc = min(hi, M - 1)  # contacts 0..nc-1; contact hi-1 touches the resting granule hi
    F[0] = 0.0
    F[hi] = 0.0  # overwritten below by contact hi - 1 unless hi = M
    if pw == POW_HERTZ:  # branch-free so that the loop vectorises (SIMD sqrt)
        for j in range(nc):
            d = max(x[j] - x[j + 1], 0.0)
            F[j + 1] = c[j] * d * math.sqrt(d)
    else:
        for j in range(nc):
            F[j + 1] = contact_force(x[j] - x[j + 1], c[j], n, pw)
    for k in range(hi):
        a[k] = (F[k] - F[k + 1]) * inv_m[k]


@njit(**JIT)
def acceleration_of(x, k, c, inv_m, n, pw):
    """The acceleration of granule k alone."""
    M = x.shape[0]
    left = contact_force(x[k - 1] - x[k], c[k - 1], n, pw) if k > 0 else 0.0
    right = contact_force(x[k] - x[k + 1], c[k], n, pw) if k < M - 1 else 0.0
    return (left - right) * inv_m[k]


@njit(**JIT)
def total_energy(x, v, m, c, n):
    """Kinetic plus potential energy, sum m v^2/2 + sum (c/n) delta^n (Eq. hertz-1).

    A wall (infinite mass, at rest) has no kinetic energy; its contact's potential counts."""
    M = x.shape[0]
    e = 0.0
    for k in range(M):
        if m[k] < math.inf:
            e += 0.5 * m[k] * v[k] * v[k]
    return add_potential(e, x, c, n, 0, M - 1)


@njit(**JIT)
def add_potential(e, x, c, n, first, last):
    """e + the potential energy (c_j / n) delta_j^n of contacts first..last-1 (Eq. hertz-1), added
    one contact at a time (the order :func:`total_energy` has always summed in)."""
    for j in range(first, last):
        d = x[j] - x[j + 1]
        if d > 0.0:
            e += c[j] / n * d**n
    return e


@njit(**JIT)
def final_energy(x, v, m, c, n, info):
    """The energy a finished run reports: kinetic energy of every granule (granules behind a
    trailing window keep the velocity they left it with), the potential of the contacts still
    integrated (from granule ``info[INFO_WINDOW_START]`` on) at the end, and the potential the
    contacts behind the window held when they left it (``info[INFO_FROZEN_POTENTIAL]``). The
    contact across the window's edge was open when it was cut, so no energy is lost there; the
    drift E_end - E_0 is then the integration error, granule by granule up to its exit from the
    window. Without a window (start 0, nothing frozen) this is :func:`total_energy`, bit for bit."""
    lo = int(info[INFO_WINDOW_START])
    if lo == 0:
        return total_energy(x, v, m, c, n)
    e = info[INFO_FROZEN_POTENTIAL]
    for k in range(lo):
        e += 0.5 * m[k] * v[k] * v[k]
    return e + total_energy(x[lo:], v[lo:], m[lo:], c[lo:], n)


@njit(**JIT)
def total_momentum(v, m):
    """sum m v over the granules (a wall, of infinite mass, is left out: it takes the impulse)."""
    p = 0.0
    for k in range(v.shape[0]):
        if m[k] < math.inf:
            p += m[k] * v[k]
    return p


@njit(**JIT)
def initial_window(x, v):
    """Window end for a state given at t = 0: WINDOW_MARGIN past the last granule that moves."""
    M = x.shape[0]
    last = M - 1
    while last > 0 and x[last] == 0.0 and v[last] == 0.0:
        last -= 1
    return min(M, last + 1 + WINDOW_MARGIN)


@njit(**JIT_INLINE)
def advance_window(x, v, hi):
    """New window end: WINDOW_MARGIN past the last granule that moved (never shrinks)."""
    M = x.shape[0]
    last = hi - 1
    while last > 0 and x[last] == 0.0 and v[last] == 0.0:
        last -= 1
    return max(hi, min(M, last + 1 + WINDOW_MARGIN))


#: Granules lighter than this fraction of the last granule's mass are "rattlers":
#: they do not hold the exit of the pulse (see pulse_has_left).
RATTLER_MASS_RATIO = 0.1


@njit(**JIT_INLINE)
def pulse_has_left(x, v, m):
    """The pulse has left the chain through its last granule.

    Conditions: the last contact is open, the last granule moves away from its
    neighbour (v_M > v_{M-1}) and outruns every granule at least
    RATTLER_MASS_RATIO as heavy as itself (all granules of a plain chain, the
    large ones of a decorated chain). A light granule flung ahead of the pulse
    can open the last contact early, but then the last granule is slow and the
    pulse behind it is faster, so the integration goes on. Light granules
    rattling between heavy ones behind the pulse are not the pulse and do not
    hold the run.
    """
    M = x.shape[0]
    if x[M - 2] - x[M - 1] > 0.0:
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
def has_wall(m):
    """The last granule is a rigid wall (infinite mass)."""
    return m[m.shape[0] - 1] == math.inf


@njit(**JIT_INLINE)
def wall_released(x, v):
    """The pulse has come back from the wall: the wall contact is open and the granule
    next to the wall moves away from it (v < 0). The run ends ``exit_margin`` after this
    has held without a break (it resets if the granule is pushed back), so "for good"
    means: for at least exit_margin."""
    M = x.shape[0]
    return x[M - 2] - x[M - 1] <= 0.0 and v[M - 2] < 0.0


@njit(**JIT_INLINE)
def pulse_is_out(x, v, m):
    """The stop condition: :func:`wall_released` with a wall, else :func:`pulse_has_left`."""
    if has_wall(m):
        return wall_released(x, v)
    return pulse_has_left(x, v, m)


@njit(**JIT_INLINE)
def end_of_step(x, v, m, hi, t, t_max, stop_at_exit, exit_since, exit_margin, t_needed):
    """Bookkeeping after an accepted step: (status, or -1 to go on; updated exit_since).

    ``exit_since`` is the time since which the pulse has been out of the chain, or
    back from the wall (-1 while it is not); the run succeeds ``exit_margin`` later
    (not before t_needed).
    """
    if stop_at_exit:
        if hi == x.shape[0] and pulse_is_out(x, v, m):
            if exit_since < 0.0:
                exit_since = t
            if t >= max(exit_since + exit_margin, t_needed):
                return SUCCESS, exit_since
        else:
            exit_since = -1.0
    if t == t_max:
        return (T_MAX if stop_at_exit else SUCCESS), exit_since
    return -1, exit_since


@njit(**JIT_INLINE)
def stop_time(t_max, exit_since, exit_margin, t_needed):
    """Where the run must end: exit_margin after the exit (not before t_needed), at most t_max."""
    if exit_since < 0.0:
        return t_max
    return min(t_max, max(exit_since + exit_margin, t_needed))


@njit(**JIT_INLINE)
def is_finite_window(x, v, hi):
    for k in range(hi):
        if not (math.isfinite(x[k]) and math.isfinite(v[k])):
            return False
    return True


@njit(**JIT)
def initial_records(obs, v, t_grid, peak_v, peak_t, grid_v):
    """The state at t = 0 is the first peak candidate and fills grid times <= 0; returns the next grid index."""
    n_obs = obs.shape[0]
    for q in range(n_obs):
        peak_v[q] = v[obs[q]]
        peak_t[q] = 0.0
    g = 0
    while g < t_grid.shape[0] and t_grid[g] <= 0.0:
        for q in range(n_obs):
            grid_v[g, q] = v[obs[q]]
        g += 1
    return g


@njit(**JIT)
def initial_force_records(x, m, c, n, pw, g, peak_f, peak_ft, grid_f):
    """No contact has a force peak yet (0 at t = 0); with a wall, its force at the ``g`` grid times
    <= 0 (the state at t = 0). Returns whether the chain ends in a wall."""
    M = x.shape[0]
    wall = has_wall(m)
    for j in range(M - 1):
        peak_f[j] = 0.0
        peak_ft[j] = 0.0
    if wall:
        for gg in range(g):
            grid_f[gg] = contact_force(x[M - 2] - x[M - 1], c[M - 2], n, pw)
    return wall


@njit(**JIT)
def is_new_peak(candidate, current, peak_rtol):
    """Does a local maximum ``candidate`` replace the recorded peak ``current``?

    Candidates are the local maxima of v_k(t) (acceleration + to -), the
    velocity at t = 0 and at the end. A later maximum wins only if it is higher
    by more than ``peak_rtol`` (relative): maxima equal within the integration
    error are a tie, and the earliest is kept, so that the peak time does not
    jump between two humps (or to the plateau of a free end) on round-off.
    """
    return candidate > current + peak_rtol * abs(current)


@njit(**JIT)
def final_peaks(obs, lo, v, a, t, peak_rtol, peak_v, peak_t):
    """The velocity at the end of the run is a candidate if the granule is still speeding up
    (a > 0). A granule in free flight (a = 0) had its maximum located where its contact
    opened; its end velocity carries the error of the step across that kink of the force,
    so it must not displace the located maximum.

    ``v``, ``a`` hold the integrated granules lo.. (index k - lo for granule k); granules
    behind a trailing window (k < lo) left it with their peaks final."""
    for q in range(obs.shape[0]):
        k = obs[q] - lo
        if k >= 0 and a[k] > 0.0 and is_new_peak(v[k], peak_v[q], peak_rtol):
            peak_v[q] = v[k]
            peak_t[q] = t


@njit(**JIT)
def final_force_peaks(x, v, c, n, pw, lo, t, peak_rtol, peak_f, peak_ft):
    """The force at the end of the run is a candidate for contacts still compressing
    (delta > 0 and v_k - v_{k+1} > 0): their maximum lies beyond the run.

    ``x``, ``v``, ``c`` hold the integrated granules lo.. and their contacts (contact j of the
    chain is entry j - lo); the contacts behind a trailing window have final peaks."""
    for j in range(x.shape[0] - 1):
        if v[j] - v[j + 1] > 0.0:
            f = contact_force(x[j] - x[j + 1], c[j], n, pw)
            if f > 0.0 and is_new_peak(f, peak_f[lo + j], peak_rtol):
                peak_f[lo + j] = f
                peak_ft[lo + j] = t


@njit(**JIT)
def write_info(info, t, n_acc, n_rej, exit_since, n_eval, lo, frozen_potential):
    """Fill the ``info`` record of a finished run (slots INFO_*)."""
    info[INFO_T_END] = t
    info[INFO_STEPS] = n_acc
    info[INFO_REJECTED] = n_rej
    info[INFO_EXIT] = exit_since
    info[INFO_EVALUATIONS] = n_eval
    info[INFO_WINDOW_START] = lo
    info[INFO_FROZEN_POTENTIAL] = frozen_potential
