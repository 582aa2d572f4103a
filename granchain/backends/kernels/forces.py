"""Contact forces and energies of the power-law chain.

Equation of motion, paper Eq. (motion_rescaled):
    m_k x_k'' = c_{k-1} (x_{k-1} - x_k)^(n-1) theta(x_{k-1} - x_k)
              - c_k     (x_k - x_{k+1})^(n-1) theta(x_k - x_{k+1}).

A rigid wall at the far end is a last granule of infinite mass (inverse mass 0, contact
stiffness sqrt(2 R_M), the limit of Eq. r-prime): it never moves, and the same force routines
serve it; the stop rule (``stop``) and the energy and momentum sums (which skip it) know about it.

The forces depend on positions only (``granchain.model.contacts.PowerLaw.conservative``): that is what
licenses the Nystrom method (``rkn4``) and Verlet, and the potential energy below.
"""

from __future__ import annotations

import math

from numba import njit

from .jit import JIT, JIT_INLINE
from .records import INFO_FROZEN_POTENTIAL, INFO_WINDOW_START

# Fast paths for the contact power delta^(n-1).
POW_GENERAL = 0
POW_HERTZ = 1  # n = 5/2: delta * sqrt(delta)
POW_LINEAR = 2  # n = 2: delta


def power_code(n: float) -> int:
    """The fast-path code of the contact power delta^(n-1) for exponent ``n``."""
    if n == 2.5:
        return POW_HERTZ
    if n == 2.0:
        return POW_LINEAR
    return POW_GENERAL


@njit(**JIT)
def contact_force(d, c, p):
    """c * d^(n-1) for d > 0, else 0 (Eq. motion_rescaled); n and its fast path from ``p``
    (``records.Params``)."""
    if d <= 0.0:
        return 0.0
    pw = p.power
    if pw == POW_HERTZ:
        return c * d * math.sqrt(d)
    if pw == POW_LINEAR:
        return c * d
    return c * d ** (p.n - 1.0)


@njit(**JIT_INLINE)
def accelerations(x, fm, hi, F, a):
    """a_k for k < hi (Eq. motion_rescaled), the forces' parameters in ``fm`` (``records.Forces``).

    ``F`` is scratch of length >= hi + 1: F[j + 1] receives the force of contact j, and F[0] (the free
    end) and F[hi] past the last granule (when hi = M) are set to 0, so that a_k = (F[k] - F[k + 1]) / m_k
    for every k, the chain's ends included, in one loop that vectorises."""
    c, inv_m, p = fm
    M = x.shape[0]
    nc = min(hi, M - 1)  # contacts 0..nc-1; contact hi-1 touches the resting granule hi
    F[0] = 0.0
    F[hi] = 0.0  # overwritten below by contact hi - 1 unless hi = M
    if p.power == POW_HERTZ:  # branch-free so that the loop vectorises (SIMD sqrt)
        for j in range(nc):
            d = max(x[j] - x[j + 1], 0.0)
            F[j + 1] = c[j] * d * math.sqrt(d)
    else:
        for j in range(nc):
            F[j + 1] = contact_force(x[j] - x[j + 1], c[j], p)
    for k in range(hi):
        a[k] = (F[k] - F[k + 1]) * inv_m[k]


@njit(**JIT)
def acceleration_of(x, k, fm):
    """The acceleration of granule k alone (``fm``: ``records.Forces``)."""
    c, inv_m, p = fm
    M = x.shape[0]
    left = contact_force(x[k - 1] - x[k], c[k - 1], p) if k > 0 else 0.0
    right = contact_force(x[k] - x[k + 1], c[k], p) if k < M - 1 else 0.0
    return (left - right) * inv_m[k]


@njit(**JIT)
def impulse_energy(m0, v0):
    """The energy of the initial state, all kinetic: granule 1 struck with v0, the rest at rest
    (``granchain.model.contacts.Impulse``)."""
    return 0.5 * m0 * v0 * v0


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
