"""Contact forces and energies of the power-law chain.

Equation of motion, paper Eq. (motion_rescaled):
    m_k x_k'' = c_{k-1} (x_{k-1} - x_k)^(n-1) theta(x_{k-1} - x_k)
              - c_k     (x_k - x_{k+1})^(n-1) theta(x_k - x_{k+1}).

A fixed wall at the far end is a last granule of infinite mass (inverse mass 0, contact
stiffness sqrt(2 R_M), the limit of Eq. r-prime): it never moves, and the same force routines
serve it; the stop rule (``stop``) and the energy and momentum sums (which skip it) know about it.

The elastic forces depend on positions only (``granchain.model.contacts.PowerLaw.conservative``): that
is what licenses the Nystrom method (``rkn4``) and Verlet, and the potential energy below. The
viscoelastic law (``law_force``) depends on the rate of compression too: only DP5 (and SciPy's DOP853)
integrate it, and the power it takes from the motion is returned by ``accelerations`` so that the
integrator accumulates the dissipated energy with its own quadrature weights.

A precompressed chain (``static_force`` > 0) is integrated in displacements from its static state: each
contact has a static overlap delta0_k and force f0_k (``static_state``), and the kernels use the dynamic
force F_k - f0_k, which is exactly 0 in the static state.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .jit import JIT, JIT_INLINE, JIT_INTERNAL, named
from .records import INFO_DISSIPATED, INFO_FROZEN_POTENTIAL, INFO_SIZE, INFO_WINDOW_START

# Fast paths for the contact power delta^(n-1).
POW_GENERAL = 0
POW_HERTZ = 1  # n = 5/2: delta * sqrt(delta)
POW_LINEAR = 2  # n = 2: delta


# The damping term of a dissipative law (``records.Params.damping``; read only where gamma > 0).
DAMPING_KUWABARA_KONO = 0  # gamma c delta^(n-2) d(delta)/dt
DAMPING_VISCOUS = 1  # gamma d(delta)/dt (Rosas et al., Phys. Rev. Lett. 98, 164301 (2007))

#: The force forms of the contact laws these kernels compute (``granchain.model.contacts.ContactLaw.form``)
#: and the damping code each lowers to: what the compiled backend declares it runs. Thornton's
#: elastic-plastic contact has no damping (its ``Params.yield_overlap`` > 0 selects it: :func:`plastic_force`).
LAW_FORMS = {"power-law": DAMPING_KUWABARA_KONO, "kuwabara-kono": DAMPING_KUWABARA_KONO, "viscous": DAMPING_VISCOUS,
             "thornton": DAMPING_KUWABARA_KONO}


def power_code(n: float) -> int:
    """The fast-path code of the contact power delta^(n-1) for exponent ``n``."""
    if n == 2.5:
        return POW_HERTZ
    if n == 2.0:
        return POW_LINEAR
    return POW_GENERAL


@njit(**JIT_INTERNAL)
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


@njit(**JIT_INTERNAL)
def law_force(d, w, c, p):
    """The force of a contact of compression ``d`` (the static overlap included) closing at the rate
    ``w`` = d(delta)/dt, by the chain's contact law: the elastic :func:`contact_force` when
    ``p.gamma`` = 0, else the viscoelastic Hertz force of Kuwabara & Kono (J. Appl. Phys. Jpn. 26,
    1230 (1987)) and Brilliantov et al. (Phys. Rev. E 53, 5382 (1996)),
    c [d^(n-1) + gamma d^(n-2) w], clamped at 0 when ``p.clamp`` (the default: never attractive, 0 while
    the contact is closed but the damping would pull, the spheres separate freely), else as published
    (it pulls at the end of a collision: the law the restitution tables of Schwager & Poschel, Phys. Rev.
    E 57, 650 (1998) and Ramirez et al., Phys. Rev. E 60, 4465 (1999) are for), and 0 for d <= 0
    (``granchain.model.contacts.Viscoelastic``); or the viscous force c d^(n-1) + gamma w of Rosas et al.
    (``p.damping`` = ``DAMPING_VISCOUS``, ``granchain.model.contacts.Viscous``), clamped the same way."""
    if p.gamma == 0.0:
        return contact_force(d, c, p)
    if d <= 0.0:
        return 0.0
    if p.damping == DAMPING_VISCOUS:  # c d^(n-1) + gamma w (granchain.model.contacts.Viscous)
        if c == 0.0:  # the padding after the last granule (rkloop.padded_arrays): no contact, no damping
            return 0.0
        f = contact_force(d, c, p) + p.gamma * w
    elif p.power == POW_HERTZ:
        f = c * math.sqrt(d) * (d + p.gamma * w)
    elif p.power == POW_LINEAR:
        f = c * (d + p.gamma * w)
    else:
        f = c * d ** (p.n - 2.0) * (d + p.gamma * w)
    if p.clamp:
        return max(f, 0.0)
    return f


@njit(**JIT_INTERNAL)
def unloading_curve(m, dy):
    """(c_p / c, delta_p) of Thornton's unloading curve from the largest overlap ``m`` >= ``dy`` (the yield
    overlap): f = F* / F_y = (3 m / dy - 1) / 2, c_p / c = ((2 f + 1) / 3)^(3/4) f^(-1/2) (the enlarged radius of
    curvature R_p, C. Thornton, J. Appl. Mech. 64, 383 (1997)), delta_p = m - f dy (3 / (2 f + 1))^(1/2).
    (1, 0), Hertz's curve, for m = dy."""
    f = 1.5 * m / dy - 0.5
    q = (2.0 * f + 1.0) / 3.0
    return q**0.75 / math.sqrt(f), m - f * dy / math.sqrt(q)


@njit(**JIT_INTERNAL)
def plastic_force(d, m, c, dy):
    """The force of Thornton's elastic-plastic contact (``granchain.model.contacts.ElasticPlastic``) at
    compression ``d`` whose largest overlap so far is ``m`` (>= its yield overlap ``dy``):
    the loading line c dy^(1/2) (3 d - dy) / 2 where d >= m (Thornton's limiting contact pressure,
    the Hertz slope at dy), else the Hertzian unloading curve c_p (d - delta_p)^(3/2) from m
    (:func:`unloading_curve`: Hertz's c d^(3/2) for a contact that never yielded); 0 for d <= delta_p, and for
    the zero-stiffness padding."""
    if d <= 0.0 or c == 0.0:
        return 0.0
    if d >= m:
        if d <= dy:
            return c * d * math.sqrt(d)
        return c * math.sqrt(dy) * (1.5 * d - 0.5 * dy)
    if m <= dy:
        return c * d * math.sqrt(d)
    cp, dp = unloading_curve(m, dy)
    e = d - dp
    return c * cp * e * math.sqrt(e) if e > 0.0 else 0.0


@njit(**JIT_INTERNAL)
def plastic_work(m, c, dy):
    """The energy a contact of Thornton's law with largest overlap ``m`` has dissipated plastically: the work
    along its loading curve to m less the elastic energy (2/5) F* (m - delta_p) its unloading gives back; 0
    below yield (``ElasticPlastic.plastic_work``)."""
    if c == 0.0 or m <= dy:
        return 0.0
    u = m / dy - 1.0
    fy_dy = c * dy * dy * math.sqrt(dy)
    f = 1.0 + 1.5 * u
    return fy_dy * (0.4 + u + 0.75 * u * u) - 0.4 * fy_dy * f * f * math.sqrt(3.0 / (2.0 * f + 1.0))


@njit(**JIT)
def plastic_energy(x, v, m, c, p, history):
    """Kinetic energy plus the elastic energy the contacts of Thornton's law give back, (2/5) c_p (delta -
    delta_p)^(5/2) on the unloading curve through the final compression (the largest overlaps ``history``),
    measured from the static state as :func:`add_potential` does: the energy check of a yielding chain, with
    :func:`plastic_work` summed apart as its dissipated energy. (The ensembles' rows: granules of one material,
    yield overlaps c^2 ``p.yield_overlap``.)"""
    M = x.shape[0]
    e = 0.0
    for k in range(M):
        if m[k] < math.inf:
            e += 0.5 * m[k] * v[k] * v[k]
    for j in range(M - 1):
        d0, f0 = static_state(c[j], p)
        D = x[j] - x[j + 1]
        d = d0 + D
        if d > 0.0:
            dy = c[j] * c[j] * p.yield_overlap
            mm = max(history[j], d, dy)
            cp, dp = unloading_curve(mm, dy)
            g = d - dp
            if g > 0.0:
                e += 0.4 * c[j] * cp * g * g * math.sqrt(g)
        e -= 0.4 * c[j] * d0 * d0 * math.sqrt(d0) + f0 * D
    return e


@njit(**JIT_INTERNAL)
def contact_law_force(j, d, w, fm):
    """The force of contact j (compression ``d``, rate ``w``) by the chain's law, reading the contact's
    history from ``fm`` (``records.Forces``) for Thornton's law: :func:`plastic_force`, else :func:`law_force`."""
    p = fm.params
    if p.yield_overlap > 0.0:
        return plastic_force(d, fm.history[j], fm.stiffness[j], fm.yield_overlap[j])
    return law_force(d, w, fm.stiffness[j], p)


@njit(**JIT_INTERNAL)
def force_rate(d, w, dw, c, p):
    """d/dt of :func:`law_force` for compression ``d``, rate ``w`` and its derivative ``dw`` (the
    relative acceleration): where it falls from + to - the contact force peaks. For the elastic law
    the compression peaks there (w = 0); for the viscoelastic one the force peaks earlier, while the
    contact still closes. 0 where the force is <= 0 (open, clamped, or pulling: no peak there)."""
    if d <= 0.0 or law_force(d, w, c, p) <= 0.0:
        return 0.0
    n, g = p.n, p.gamma
    if p.damping == DAMPING_VISCOUS:  # d/dt (c d^(n-1) + gamma w)
        if p.power == POW_HERTZ:
            return c * 1.5 * math.sqrt(d) * w + g * dw
        return c * (n - 1.0) * d ** (n - 2.0) * w + g * dw
    if p.power == POW_HERTZ:
        r = math.sqrt(d)
        return c * (1.5 * r * w + g * (0.5 * w * w / r + r * dw))
    return c * ((n - 1.0) * d ** (n - 2.0) * w + g * ((n - 2.0) * d ** (n - 3.0) * w * w + d ** (n - 2.0) * dw))


@njit(**JIT_INTERNAL)
def static_state(c, p):
    """(delta0, f0) of a contact of prefactor ``c`` in the static state of a chain precompressed by
    F0 = ``p.static_force`` (``granchain.model.contacts.Precompression``): the overlap
    delta0 = (F0 / c)^(1/(n-1)) at which the contact carries F0 (V. F. Nesterenko, *Dynamics of
    Heterogeneous Materials*, Springer 2001, Sec. 1.1), and f0 its force by the very law and
    arithmetic the kernels use (:func:`law_force`), F0 to rounding. The kernels subtract f0 from each
    contact force, so the static state is an exact equilibrium in floating point: granules ahead of
    the pulse are exactly at rest. (0, 0) without precompression, and for the zero-stiffness padding."""
    if p.static_force <= 0.0 or c <= 0.0:
        return 0.0, 0.0
    d0 = (p.static_force / c) ** (1.0 / (p.n - 1.0))
    return d0, law_force(d0, 0.0, c, p)


@njit(**JIT_INLINE)
def accelerations(x, v, fm, hi, F, a, general):
    """a_k for k < hi (Eq. motion_rescaled), the forces' parameters in ``fm`` (``records.Forces``);
    returns the power the contacts dissipate (0 for elastic contacts).

    ``general`` is a compile-time constant of the step loop that inlines this (``rkloop``): False
    compiles the paper's chain alone (elastic, unloaded: the loop as it was before real contacts, with
    nothing else in the compiled code), True the real contacts (static load, damping; the paper's chain
    too, by the run-time values of ``fm.params``). One routine with a runtime test cost the paper's
    ensembles 10-20 % (same-run timings against granchain 0.4.0).

    ``x`` are displacements from the static state (positions from contact for an unloaded chain),
    ``v`` the velocities (read only by a viscoelastic law). ``F`` is scratch of length >= hi + 1:
    F[j + 1] receives the dynamic force of contact j (its force minus its static force f0_j), and
    F[0] and F[hi] past the last granule (when hi = M) are set to 0, so that a_k = (F[k] - F[k + 1]) / m_k
    for every k, the chain's ends included, in one loop that vectorises. The dynamic force 0 at an end
    is a free end, or an end held by the constant static force F0 of a precompressed chain (the
    external load balances f0 there; ``granchain.model.contacts.Precompression``)."""
    c, inv_m, p, o, f0, hm, dy = fm
    M = x.shape[0]
    nc = min(hi, M - 1)  # contacts 0..nc-1; contact hi-1 touches the resting granule hi
    F[0] = 0.0
    F[hi] = 0.0  # overwritten below by contact hi - 1 unless hi = M
    dissipated = 0.0
    if not general or (p.gamma == 0.0 and p.static_force == 0.0 and p.yield_overlap == 0.0):  # the paper's chain
        if p.power == POW_HERTZ:  # branch-free so that the loop vectorises (SIMD sqrt)
            for j in range(nc):
                d = max(x[j] - x[j + 1], 0.0)
                F[j + 1] = c[j] * d * math.sqrt(d)
        else:
            for j in range(nc):
                F[j + 1] = contact_force(x[j] - x[j + 1], c[j], p)
    elif p.yield_overlap > 0.0:  # Thornton's elastic-plastic contacts, each with its largest overlap hm[j]
        for j in range(nc):
            F[j + 1] = plastic_force(o[j] + (x[j] - x[j + 1]), hm[j], c[j], dy[j]) - f0[j]
    elif p.gamma == 0.0:  # precompressed, elastic
        for j in range(nc):
            F[j + 1] = contact_force(o[j] + (x[j] - x[j + 1]), c[j], p) - f0[j]
    else:  # viscoelastic (and precompressed, if o, f0 are not 0)
        for j in range(nc):
            d = o[j] + (x[j] - x[j + 1])
            w = v[j] - v[j + 1]
            f = law_force(d, w, c[j], p)
            if d > 0.0:
                # Power taken from the motion: (F - F_elastic) w >= 0 (also where F is clamped at 0, and
                # where the unclamped law pulls: there it is gamma c d^(n-2) w^2).
                dissipated += (f - contact_force(d, c[j], p)) * w
            F[j + 1] = f - f0[j]
    for k in range(hi):
        a[k] = (F[k] - F[k + 1]) * inv_m[k]
    return dissipated


def _accelerations_call(general):
    """:func:`accelerations` compiled as a function of its own for the model class ``general``, a
    constant of its code (this closure's variable: Numba prunes the other class's branches)."""

    @njit(**JIT_INTERNAL)
    @named("general" if general else "paper")
    def call(x, v, fm, hi, F, a):
        return accelerations(x, v, fm, hi, F, a, general)

    return call


_accelerations_paper = _accelerations_call(False)
_accelerations_general = _accelerations_call(True)


@njit(**JIT_INLINE)
def accelerations_once(x, v, fm, hi, F, a, general):
    """:func:`accelerations` as a call, not inlined: for the step loops' calls outside the stages
    (the first stage, a window that grows or is cut), which are rare; the stages inline their one call.
    Every copy inlined is compiled again (the first run of a kernel pays for it). Itself inlined where
    ``general`` is a constant: a call of the function compiled for it."""
    if general:
        return _accelerations_general(x, v, fm, hi, F, a)
    return _accelerations_paper(x, v, fm, hi, F, a)


@njit(**JIT)
def impulse_energy(m0, v0):
    """The energy of the initial state, all kinetic: granule 1 (or a striker) struck with v0, the rest
    at rest in the static state (``granchain.model.contacts.Impulse``, ``Striker``)."""
    return 0.5 * m0 * v0 * v0


@njit(**JIT_INTERNAL)
def total_energy(x, v, m, c, p):
    """Kinetic plus potential energy, sum m v^2/2 + sum (c/n) delta^n (Eq. hertz-1).

    A wall (infinite mass, at rest) has no kinetic energy; its contact's potential counts. For a
    precompressed chain the potential is measured from the static state (:func:`add_potential`)."""
    M = x.shape[0]
    e = 0.0
    for k in range(M):
        if m[k] < math.inf:
            e += 0.5 * m[k] * v[k] * v[k]
    return add_potential(e, x, c, p, 0, M - 1)


@njit(**JIT_INTERNAL)
def add_potential(e, x, c, p, first, last):
    """e + the potential energy of contacts first..last-1, added one contact at a time (the order
    :func:`total_energy` has always summed in): (c_j / n) delta_j^n (Eq. hertz-1). For a
    precompressed chain, of the dynamic force (:func:`accelerations`) from the static state:
    V(delta0 + D) - V(delta0) - f0 D with D = x_j - x_{j+1}, the elastic energy stored beyond the
    static state less the work of the constant load that holds the chain (Nesterenko 2001, Sec. 1.1)."""
    n = p.n
    if p.static_force == 0.0:
        for j in range(first, last):
            d = x[j] - x[j + 1]
            if d > 0.0:
                e += c[j] / n * d**n
        return e
    for j in range(first, last):
        d0, f0 = static_state(c[j], p)
        D = x[j] - x[j + 1]
        d = d0 + D
        u = c[j] / n * d**n if d > 0.0 else 0.0
        e += (u - c[j] / n * d0**n) - f0 * D
    return e


@njit(**JIT)
def final_energy(x, v, m, c, p, info):
    """The energy a finished run reports: kinetic energy of every granule (granules behind a
    trailing window keep the velocity they left it with), the potential of the contacts still
    integrated (from granule ``info[INFO_WINDOW_START]`` on) at the end, and the potential the
    contacts behind the window held when they left it (``info[INFO_FROZEN_POTENTIAL]``). The
    contact across the window's edge was open when it was cut, so no energy is lost there; the
    drift E_end + E_dissipated - E_0 is then the integration error, granule by granule up to its exit
    from the window. Without a window (start 0, nothing frozen) this is :func:`total_energy`, bit for
    bit. The energy dissipated by viscoelastic contacts is ``info[INFO_DISSIPATED]``, apart."""
    lo = int(info[INFO_WINDOW_START])
    if lo == 0:
        return total_energy(x, v, m, c, p)
    e = info[INFO_FROZEN_POTENTIAL]
    for k in range(lo):
        e += 0.5 * m[k] * v[k] * v[k]
    return e + total_energy(x[lo:], v[lo:], m[lo:], c[lo:], p)


@njit(**JIT)
def energy_error(x, v, m, c, p, info, history, v0):
    """(E_end + E_dissipated - E_0) / E_0 of a finished run struck with ``v0``, the energy balance's drift each
    realisation reports: E_0 by :func:`impulse_energy`; E_end by :func:`final_energy`, or for Thornton's
    yielding contacts by :func:`plastic_energy` (the elastic energy a yielded contact gives back depends on its
    history, ``history``), and E_dissipated = ``info[INFO_DISSIPATED]`` (damped contacts: integrated with the
    motion; yielding ones: the plastic work)."""
    e0 = impulse_energy(m[0], v0)
    if p.yield_overlap > 0.0:
        e1 = plastic_energy(x, v, m, c, p, history) + info[INFO_DISSIPATED]
    else:
        e1 = final_energy(x, v, m, c, p, info) + info[INFO_DISSIPATED]
    return (e1 - e0) / e0


@njit(**JIT)
def energy_errors(x, v, m, c, p, window_start, frozen, dissipated, history, v0, out):
    """:func:`energy_error` of each row of runs integrated elsewhere (the GPU's: final positions ``x`` and
    velocities ``v``, masses ``m``, stiffnesses ``c``, rows x granules; each row's first integrated granule
    ``window_start``, frozen potential ``frozen``, dissipated energy ``dissipated``, contacts' ``history`` (rows
    x 0 for laws without one) and initial velocity ``v0``) into ``out``."""
    info = np.zeros(INFO_SIZE)
    for r in range(x.shape[0]):
        info[INFO_WINDOW_START] = window_start[r]
        info[INFO_FROZEN_POTENTIAL] = frozen[r]
        info[INFO_DISSIPATED] = dissipated[r]
        out[r] = energy_error(x[r], v[r], m[r], c[r], p, info, history[r], v0[r])


@njit(**JIT)
def total_momentum(v, m):
    """sum m v over the granules (a wall, of infinite mass, is left out: it takes the impulse)."""
    p = 0.0
    for k in range(v.shape[0]):
        if m[k] < math.inf:
            p += m[k] * v[k]
    return p
