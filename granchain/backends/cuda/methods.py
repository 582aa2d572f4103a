"""The GPU step's methods: each one's stages and error estimate as device functions of the step loop
(``kernel.make_kernel``), chosen when a kernel is compiled, as the CPU's step loop is specialised on a
scheme (``kernels.schemes``).

- ``rkn4``: the Runge-Kutta-Nystrom pair RKN4(3) of Dormand, El-Mikkawy & Prince (``kernels.rkn4``);
- ``dp5``: Dormand-Prince 5(4) (``kernels.dp5``; J. R. Dormand and P. J. Prince, J. Comput. Appl. Math. 6,
  19 (1980));
- ``verlet``: velocity Verlet (``kernels.verlet``), a fixed step and no error estimate.

Each is the CPU's arithmetic in the CPU's order, so that in Numba's simulator (which computes as the CPU
does) the GPU gives the CPU's numbers; the tables are imported from the CPU modules, never repeated.
"""

from __future__ import annotations

import math

from numba import cuda

from ..kernels import dp5 as _dp5
from ..kernels.rkn4 import A10, A20, A21, B0, B1, B2, C1, C2, EB0, EB1, EB2, EB3, EP0, EP1, EP2, EP3, P0, P1, P2, P3
from ..kernels.rkloop import pi_exponent
from ..kernels.schemes import DP5, RKN4
from .device import cpu_source

#: The methods (``Integrator.name``).
METHODS = ("rkn4", "dp5", "verlet")
#: The PI controller's exponent of each adaptive method's error estimate (the CPU step loop's,
#: ``rkloop.pi_exponent``).
ALPHA = {"rkn4": pi_exponent(RKN4), "dp5": pi_exponent(DP5)}
#: Rows of the stage array DP5 keeps besides k1, k2: the stage velocities u1..u5, the accelerations k3..k5.
DP5_ROWS = 8

# Dormand-Prince 5(4)'s tableau (``kernels.dp5``, whose names RKN4's share: renamed D* here).
D21 = _dp5.A21
D31, D32 = _dp5.A31, _dp5.A32
D41, D42, D43 = _dp5.A41, _dp5.A42, _dp5.A43
D51, D52, D53, D54 = _dp5.A51, _dp5.A52, _dp5.A53, _dp5.A54
D61, D62, D63, D64, D65 = _dp5.A61, _dp5.A62, _dp5.A63, _dp5.A64, _dp5.A65
DB1, DB3, DB4, DB5, DB6 = _dp5.B1, _dp5.B3, _dp5.B4, _dp5.B5, _dp5.B6
DE1, DE3, DE4, DE5, DE6, DE7 = _dp5.E1, _dp5.E3, _dp5.E4, _dp5.E5, _dp5.E6, _dp5.E7


def make_stages(method: str, forces, G: int, damped: bool = False):
    """The device function ``stages(x, v, a0, xs, vs, a3, k1, k2, S, h, h2, own, M, lo, bxa, bxb, c_left,
    c_right, inv_m, law, pw, pre, yld)`` of ``method``: one step of size ``h`` (``h2`` = h^2) from the thread's granules'
    state ``x``, ``v`` and acceleration ``a0`` to the new state ``xs``, ``vs`` (RKN4's velocities after the
    stages: :func:`make_velocity`) and its acceleration ``a3`` (the next step's first stage), the
    intermediate stages in ``k1``, ``k2`` and, for DP5, the rows of
    ``S`` (:data:`DP5_ROWS`). ``forces`` is the layout's force evaluation (``exchange.make_exchange``),
    which every thread of the group calls at the same stages; its two shared arrays ``bxa``, ``bxb``
    alternate, so that one barrier per evaluation suffices. ``law``: the contacts' (n, gamma, viscous, clamp)
    (``device.law_force``); ``pre``: a precompressed chain's static state (``device.compression``), or None;
    ``yld``: yielding contacts' yield overlaps and histories (``device.elastic_force``), or None.

    ``damped`` (DP5 only; ``forces`` made for it): the forces read the stage velocities, as the CPU's DP5's
    do, and each stage's share of the power the thread's contacts dissipate goes to ``pw[1..6]`` (``pw[0]``,
    the first stage's, is the last step's seventh: FSAL), for :data:`dissipated` and :data:`dissipated_error`."""
    if method not in METHODS:
        raise ValueError(f"the cuda kernels integrate with {METHODS}, not {method!r}")
    DAMPED = bool(damped)
    if DAMPED and method != "dp5":
        raise ValueError(f"forces that read velocities (damping) are integrated by DP5 alone, not {method!r}")

    if method == "verlet":

        @cuda.jit(device=True)
        def stages(x, v, a0, xs, vs, a3, k1, k2, S, h, h2, own, M, lo, bxa, bxb, c_left, c_right, inv_m, law, pw, pre, yld):
            """``kernels.verlet``: x' = x + h v + h^2 a / 2, v' = v + h (a + a') / 2."""
            for s in range(G):
                xs[s] = x[s] + (h * v[s] + 0.5 * h * h * a0[s])
            forces(xs, v, own, M, lo, bxb, c_left, c_right, inv_m, law, a3, pre, yld)
            for s in range(G):
                vs[s] = v[s] + 0.5 * h * (a0[s] + a3[s])

    elif method == "dp5":

        @cuda.jit(device=True)
        def stages(x, v, a0, xs, vs, a3, k1, k2, S, h, h2, own, M, lo, bxa, bxb, c_left, c_right, inv_m, law, pw, pre, yld):
            """Stages 2..7 of ``kernels.dp5.stages``: the 7th is the new state (FSAL)."""
            u1, u2, u3, u4, u5, k3, k4, k5 = S[0], S[1], S[2], S[3], S[4], S[5], S[6], S[7]
            for s in range(G):
                xs[s] = x[s] + h * (D21 * v[s])
                u1[s] = v[s] + h * (D21 * a0[s])
            p = forces(xs, u1, own, M, lo, bxb, c_left, c_right, inv_m, law, k1, pre, yld)
            if DAMPED:
                pw[1] = p
            for s in range(G):
                xs[s] = x[s] + h * (D31 * v[s] + D32 * u1[s])
                u2[s] = v[s] + h * (D31 * a0[s] + D32 * k1[s])
            p = forces(xs, u2, own, M, lo, bxa, c_left, c_right, inv_m, law, k2, pre, yld)
            if DAMPED:
                pw[2] = p
            for s in range(G):
                xs[s] = x[s] + h * (D41 * v[s] + D42 * u1[s] + D43 * u2[s])
                u3[s] = v[s] + h * (D41 * a0[s] + D42 * k1[s] + D43 * k2[s])
            p = forces(xs, u3, own, M, lo, bxb, c_left, c_right, inv_m, law, k3, pre, yld)
            if DAMPED:
                pw[3] = p
            for s in range(G):
                xs[s] = x[s] + h * (D51 * v[s] + D52 * u1[s] + D53 * u2[s] + D54 * u3[s])
                u4[s] = v[s] + h * (D51 * a0[s] + D52 * k1[s] + D53 * k2[s] + D54 * k3[s])
            p = forces(xs, u4, own, M, lo, bxa, c_left, c_right, inv_m, law, k4, pre, yld)
            if DAMPED:
                pw[4] = p
            for s in range(G):
                xs[s] = x[s] + h * (D61 * v[s] + D62 * u1[s] + D63 * u2[s] + D64 * u3[s] + D65 * u4[s])
                u5[s] = v[s] + h * (D61 * a0[s] + D62 * k1[s] + D63 * k2[s] + D64 * k3[s] + D65 * k4[s])
            p = forces(xs, u5, own, M, lo, bxb, c_left, c_right, inv_m, law, k5, pre, yld)
            if DAMPED:
                pw[5] = p
            for s in range(G):
                xs[s] = x[s] + h * (DB1 * v[s] + DB3 * u2[s] + DB4 * u3[s] + DB5 * u4[s] + DB6 * u5[s])
                vs[s] = v[s] + h * (DB1 * a0[s] + DB3 * k2[s] + DB4 * k3[s] + DB5 * k4[s] + DB6 * k5[s])
            p = forces(xs, vs, own, M, lo, bxa, c_left, c_right, inv_m, law, a3, pre, yld)
            if DAMPED:
                pw[6] = p

    else:

        @cuda.jit(device=True)
        def stages(x, v, a0, xs, vs, a3, k1, k2, S, h, h2, own, M, lo, bxa, bxb, c_left, c_right, inv_m, law, pw, pre, yld):
            """Stages 1..3 of ``kernels.rkn4.stages`` (a3 the force per mass at the new position); the new
            velocities come after (:func:`make_velocity`)."""
            for s in range(G):
                xs[s] = x[s] + h * (C1 * v[s]) + h2 * (A10 * a0[s])
            forces(xs, v, own, M, lo, bxb, c_left, c_right, inv_m, law, k1, pre, yld)
            for s in range(G):
                xs[s] = x[s] + h * (C2 * v[s]) + h2 * (A20 * a0[s] + A21 * k1[s])
            forces(xs, v, own, M, lo, bxa, c_left, c_right, inv_m, law, k2, pre, yld)
            for s in range(G):
                xs[s] = x[s] + h * v[s] + h2 * (B0 * a0[s] + B1 * k1[s] + B2 * k2[s])
            forces(xs, v, own, M, lo, bxb, c_left, c_right, inv_m, law, a3, pre, yld)

    return stages


#: ``kernels.dp5.dissipated`` and ``dissipated_error``: the energy a step dissipates by the 5th-order quadrature of
#: its stages' powers ``pw[0..6]`` and that quadrature's embedded error, the CPU's own functions compiled for the
#: GPU. The quadratures are linear in the powers, so each thread applies them to its own contacts' share and
#: the group sums the results (``exchange.group_sum``, in a fixed order), where the CPU sums the contacts first.
dissipated = cpu_source(_dp5.dissipated)
dissipated_error = cpu_source(_dp5.dissipated_error)
#: ``kernels.dp5.over_tolerance``: the dissipated energy's summed error over its tolerance, the CPU's own function.
over_tolerance = cpu_source(_dp5.over_tolerance)


def make_velocity(method: str):
    """The device function ``velocity(s, v, vs, a0, k1, k2, a3, h)``: RKN4's new velocity of granule s, which
    its stages leave to the pass over the thread's granules that estimates the error from the same stages
    (one pass: with 32 granules a thread, two passes spilled about twice as many bytes, by ptxas for sm_90);
    nothing for the others, whose stages end with it."""
    if method == "rkn4":

        @cuda.jit(device=True)
        def velocity(s, v, vs, a0, k1, k2, a3, h):
            vs[s] = v[s] + h * (P0 * a0[s] + P1 * k1[s] + P2 * k2[s] + P3 * a3[s])

    else:

        @cuda.jit(device=True)
        def velocity(s, v, vs, a0, k1, k2, a3, h):
            pass

    return velocity


def make_error(method: str, fixed: bool):
    """The device function ``error(s, x, v, xs, vs, a0, k1, k2, a3, S, h, h2, w, rtol, atol)``: owned granule
    s's share of the step's error norm, the larger of its position's and its velocity's embedded error over
    its tolerance (atol + rtol max(|y|, |y'|)) w, ``w`` the relaxed zone's factor (``error_ratios`` of
    ``kernels.rkn4`` and ``kernels.dp5``; inf where one is not finite, so that a NaN is not lost in a
    maximum). With a fixed step (``fixed``, and Verlet always) there is no estimate: 0, or inf where the new
    state is not finite (the run ends NONFINITE, as the CPU's ``rkloop`` and ``verlet`` end it)."""
    if fixed or method == "verlet":

        @cuda.jit(device=True)
        def error(s, x, v, xs, vs, a0, k1, k2, a3, S, h, h2, w, rtol, atol):
            return 0.0 if abs(xs[s]) < math.inf and abs(vs[s]) < math.inf else math.inf

        return error
    DP = method == "dp5"

    @cuda.jit(device=True)
    def error(s, x, v, xs, vs, a0, k1, k2, a3, S, h, h2, w, rtol, atol):
        if DP:
            ex = h * (DE1 * v[s] + DE3 * S[1, s] + DE4 * S[2, s] + DE5 * S[3, s] + DE6 * S[4, s] + DE7 * vs[s])
            ev = h * (DE1 * a0[s] + DE3 * k2[s] + DE4 * S[5, s] + DE5 * S[6, s] + DE6 * S[7, s] + DE7 * a3[s])
        else:
            ex = h2 * (EB0 * a0[s] + EB1 * k1[s] + EB2 * k2[s] + EB3 * a3[s])
            ev = h * (EP0 * a0[s] + EP1 * k1[s] + EP2 * k2[s] + EP3 * a3[s])
        rx = abs(ex) / ((atol + rtol * max(abs(x[s]), abs(xs[s]))) * w)
        rv = abs(ev) / ((atol + rtol * max(abs(v[s]), abs(vs[s]))) * w)
        if not (rx <= 1e300):  # inf or NaN wins (a max would drop a NaN)
            rx = math.inf
        if not (rv <= 1e300):
            rv = math.inf
        return max(rx, rv)

    return error
