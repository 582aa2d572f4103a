"""Dense output of the Runge-Kutta step loop, and the roots found on it.

Peaks of the observed granules are located between steps: a local maximum of v_k lies where its
acceleration changes sign from + to -, and the root of the acceleration computed from the
dense-output positions is found by the Illinois method, so peak times are not tied to the step
grid. Peak contact forces the same way: contact j's compression peaks where the dense-output
relative velocity v_j - v_{j+1} changes sign from + to -; the force there is c_j delta^(n-1) of the
dense-output positions (Eq. motion_rescaled).

Every scheme (``schemes``) evaluates its dense output as y + h sum_s K[s] Q[s] with its own weights Q:
DP5's continuous extension (``dp5.weights``, one set for positions and velocities) or RKN4's quintic
Hermite pair (``rkn4.weights``). The root searches take the scheme's kind as a run-time value and ask
``schemes.dense_weights`` for them.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .forces import contact_force, contact_law_force, force_rate
from .jit import JIT_INLINE, JIT_INTERNAL, named
from .schemes import dense_weights

#: What :func:`first_root` follows across a step: the acceleration of a granule (its velocity
#: maximum) or the relative velocity of a contact (its compression, i.e. force, maximum).
ROOT_ACCELERATION = 0
ROOT_APPROACH = 1
#: ... or the rate of a viscoelastic contact's force, which peaks before its compression does.
ROOT_FORCE_RATE = 2
#: ... or the acceleration of a granule of the paper's chain (elastic, unloaded): the search the paper's
#: step loop compiles, without the real contacts' laws (:func:`elastic_acceleration`).
ROOT_ELASTIC_ACCELERATION = 3


@njit(**JIT_INTERNAL)
def dense_value(y0, K, k, h, Q):
    """y_k(t + theta h) = y0 + h sum_s K[s, k] Q[s], Q the weights at theta (``schemes.dense_weights``)."""
    acc = 0.0
    for s in range(7):
        acc += K[s, k] * Q[s]
    return y0 + h * acc


@njit(**JIT_INTERNAL)
def dense_compression(j, x, Kx, h, Q):
    """Compression x_j - x_{j+1} of contact j from the dense-output positions at the time whose
    weights ``Q`` holds (``schemes.dense_weights`` already called)."""
    return dense_value(x[j], Kx, j, h, Q) - dense_value(x[j + 1], Kx, j + 1, h, Q)


@njit(**JIT_INTERNAL)
def elastic_dense_force(j, step, fm, Q, Qv):
    """:func:`dense_force` of the paper's chain (elastic, unloaded): c_j delta^(n-1) (Eq. motion_rescaled), the
    same arithmetic as the general law's for that chain."""
    x, v, Kx, Kv, h = step
    d = fm.overlap[j] + dense_compression(j, x, Kx, h, Q)
    return contact_force(d, fm.stiffness[j], fm.params)


@njit(**JIT_INLINE)
def law_dense_force(general, j, step, fm, Q, Qv):
    """The force of contact j on the dense output: :func:`dense_force`, or :func:`elastic_dense_force` for the
    paper's chain (``general`` False, a constant where this is inlined: the paper's step loop compiles no
    other law)."""
    if general:
        return dense_force(j, step, fm, Q, Qv)
    return elastic_dense_force(j, step, fm, Q, Qv)


@njit(**JIT_INTERNAL)
def dense_force(j, step, fm, Q, Qv):
    """The force of contact j by the chain's law (``forces.law_force``: its static overlap included, and
    its rate of compression for a viscoelastic law) from the dense output of ``step``
    (``records.Dense``) at the time whose weights ``Q``, ``Qv`` hold (``schemes.dense_weights`` already called)."""
    x, v, Kx, Kv, h = step
    p, o = fm.params, fm.overlap
    d = o[j] + dense_compression(j, x, Kx, h, Q)
    w = 0.0
    if p.gamma > 0.0:
        w = dense_value(v[j], Kv, j, h, Qv) - dense_value(v[j + 1], Kv, j + 1, h, Qv)
    return contact_law_force(j, d, w, fm)


@njit(**JIT_INTERNAL)
def elastic_acceleration(kind, theta, k, step, fm, Q, Qv):
    """:func:`dense_acceleration` of the paper's chain (elastic, unloaded; Eq. motion_rescaled): what the
    paper's step loop follows to its granules' velocity maxima, and the general search on such a chain."""
    x, v, Kx, Kv, h = step
    c, inv_m, p = fm.stiffness, fm.inv_mass, fm.params
    M = x.shape[0]
    dense_weights(kind, theta, Q, Qv)
    xk = dense_value(x[k], Kx, k, h, Q)
    left = 0.0
    right = 0.0
    if k > 0:
        left = contact_force(dense_value(x[k - 1], Kx, k - 1, h, Q) - xk, c[k - 1], p)
    if k < M - 1:
        right = contact_force(xk - dense_value(x[k + 1], Kx, k + 1, h, Q), c[k], p)
    return (left - right) * inv_m[k]


@njit(**JIT_INTERNAL)
def dense_acceleration(kind, theta, k, step, fm, Q, Qv):
    """Acceleration of granule k at t + theta h from the dense output of ``step`` (``records.Dense``),
    forces from ``fm`` (``records.Forces``; the dynamic forces of ``forces.accelerations``: each
    contact's force by its law, static overlap included, less its static force)."""
    x, v, Kx, Kv, h = step
    c, inv_m, p, o, f0, _, _ = fm
    M = x.shape[0]
    if p.gamma == 0.0 and p.static_force == 0.0 and p.yield_overlap == 0.0:
        # Elastic and unloaded at run time (the general loop's chain with a striker, say): the paper's arithmetic,
        # without the general path's extra call and loads per evaluation (tens per peak).
        return elastic_acceleration(kind, theta, k, step, fm, Q, Qv)
    dense_weights(kind, theta, Q, Qv)
    xk = dense_value(x[k], Kx, k, h, Q)
    left = 0.0
    right = 0.0
    vk = dense_value(v[k], Kv, k, h, Qv) if p.gamma > 0.0 else 0.0  # rates only for a viscoelastic law
    if k > 0:
        w = dense_value(v[k - 1], Kv, k - 1, h, Qv) - vk if p.gamma > 0.0 else 0.0
        left = contact_law_force(k - 1, o[k - 1] + (dense_value(x[k - 1], Kx, k - 1, h, Q) - xk), w, fm) - f0[k - 1]
    if k < M - 1:
        w = vk - dense_value(v[k + 1], Kv, k + 1, h, Qv) if p.gamma > 0.0 else 0.0
        right = contact_law_force(k, o[k] + (xk - dense_value(x[k + 1], Kx, k + 1, h, Q)), w, fm) - f0[k]
    return (left - right) * inv_m[k]


@njit(**JIT_INTERNAL)
def relative_velocity(kind, theta, i, step, Q, Qv):
    """v_i - v_{i+1} of contact i at t + theta h on the dense output of ``step`` (its compression
    rate: the compression peaks where it falls through 0)."""
    x, v, Kx, Kv, h = step
    dense_weights(kind, theta, Q, Qv)
    return dense_value(v[i], Kv, i, h, Qv) - dense_value(v[i + 1], Kv, i + 1, h, Qv)


@njit(**JIT_INTERNAL)
def dense_force_rate(kind, theta, i, step, fm, Q, Qv):
    """The rate of contact i's force (``forces.force_rate``) at t + theta h on the dense output of
    ``step``: a viscoelastic force peaks where it falls through 0."""
    x, v, Kx, Kv, h = step
    dw = (dense_acceleration(kind, theta, i, step, fm, Q, Qv)
          - dense_acceleration(kind, theta, i + 1, step, fm, Q, Qv))
    c, _, p, o, _, _, _ = fm
    d = o[i] + dense_compression(i, x, Kx, h, Q)
    w = dense_value(v[i], Kv, i, h, Qv) - dense_value(v[i + 1], Kv, i + 1, h, Qv)
    return force_rate(d, w, dw, c[i], p)


def _root_search(what):
    """The root search of :func:`first_root` for the function followed ``what`` (``ROOT_*``): the
    acceleration of granule i (:func:`dense_acceleration`), the relative velocity of contact i
    (:func:`relative_velocity`) or the rate of its force (:func:`dense_force_rate`), on the dense
    output (weights ``Q`` for positions, ``Qv`` for velocities, see ``schemes.dense_weights``).

    ``what`` is a constant of the search's code (this closure's variable, whose branches Numba
    prunes): each search compiles the one function it follows. With ``what`` a literal argument, each
    specialisation compiled the three; with ``what`` a run-time value the decorated ensembles ran ~3 %
    slower (every peak is located by this loop; same-process timings at N = 26)."""

    @njit(**JIT_INTERNAL)
    @named(("acceleration", "approach", "force_rate", "elastic_acceleration")[what])
    def search(kind, i, f01, step, fm, Q, Qv):
        lo, hi = 0.0, 1.0
        f_lo, f_hi = f01
        theta = 0.0
        side = 0
        for _ in range(200):
            if f_hi < 0.0:
                theta = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
                if not (lo < theta < hi):
                    theta = 0.5 * (lo + hi)
            else:
                theta = 0.5 * (lo + hi)
            if what == ROOT_ACCELERATION:
                f = dense_acceleration(kind, theta, i, step, fm, Q, Qv)
            elif what == ROOT_ELASTIC_ACCELERATION:
                f = elastic_acceleration(kind, theta, i, step, fm, Q, Qv)
            elif what == ROOT_APPROACH:
                f = relative_velocity(kind, theta, i, step, Q, Qv)
            else:
                f = dense_force_rate(kind, theta, i, step, fm, Q, Qv)
            if f > 0.0:
                lo, f_lo = theta, f
                if side == -1:
                    f_hi *= 0.5
                side = -1
            else:
                hi, f_hi = theta, f
                if side == 1:
                    f_lo *= 0.5
                side = 1
            if hi - lo < 1e-14:
                break
        return hi

    return search


_acceleration_root = _root_search(ROOT_ACCELERATION)
_approach_root = _root_search(ROOT_APPROACH)
_force_rate_root = _root_search(ROOT_FORCE_RATE)
_elastic_acceleration_root = _root_search(ROOT_ELASTIC_ACCELERATION)


@njit(**JIT_INLINE)
def first_root(kind, what, i, f01, step, fm, Q, Qv):
    """First theta in [0, 1] where the followed function (f01 = its values (+ at 0, <= 0 at 1)) stops
    being positive: a granule's velocity maximum (``ROOT_ACCELERATION``; ``ROOT_ELASTIC_ACCELERATION`` on the
    paper's chain), a contact's compression maximum (``ROOT_APPROACH``) or its force maximum
    (``ROOT_FORCE_RATE``).

    Illinois (modified regula falsi) while the bracket has a strictly negative end; bisection
    while it ends on an exact zero (a contact that opened: the acceleration is then zero on a
    whole interval and the first zero is wanted).

    Inlined into the step loop, where ``what`` is a constant: a call of the search compiled for it
    (:func:`_root_search`). The scheme's ``kind`` reaches it as a run-time value (it is a constant in the
    step loop, which Numba would pass on as a literal): one search serves every scheme, compiled once
    for a run that uses several (the paper's ensembles: DP5 and RKN4), and its dense output tests the
    kind at each evaluation (``schemes.dense_weights``), a branch always taken the same way.
    """
    kind = np.int64(kind)
    if what == ROOT_ACCELERATION:
        return _acceleration_root(kind, i, f01, step, fm, Q, Qv)
    if what == ROOT_ELASTIC_ACCELERATION:
        return _elastic_acceleration_root(kind, i, f01, step, fm, Q, Qv)
    if what == ROOT_APPROACH:
        return _approach_root(kind, i, f01, step, fm, Q, Qv)
    return _force_rate_root(kind, i, f01, step, fm, Q, Qv)


@njit(**JIT_INLINE)
def falls(f0, f1):
    """A function followed over a step is + at its start and <= 0 at its end: a maximum of what it
    is the derivative of lies inside (:func:`first_root`). Branch-free, so that the candidate
    counts of the step loop vectorise; the same test in the counts and in the loops they guard."""
    return (f0 > 0.0) & (f1 <= 0.0)


@njit(**JIT_INTERNAL)
def hermite_max_estimate(d0, w0, d1, w1, h):
    """The cubic Hermite interpolant of the compression through (d0, w0) and (d1, w1) over a step h,
    at the zero of the linearly interpolated relative velocity w (w0 > 0 >= w1): an estimate of the
    compression maximum, used only to skip hopeless root searches (``observe.SCREEN``)."""
    theta = w0 / (w0 - w1)
    t2 = theta * theta
    t3 = t2 * theta
    return (2 * t3 - 3 * t2 + 1) * d0 + (t3 - 2 * t2 + theta) * h * w0 + (-2 * t3 + 3 * t2) * d1 + (t3 - t2) * h * w1
