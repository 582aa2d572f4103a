"""The Runge-Kutta(-Nystrom) methods of the step loop, as values: one :class:`Scheme` per method.

A scheme is a module of the method's own code and constants (``dp5``, ``rkn4``) read into a record.
The generic step loop (``rkloop.rk_kernel``) is specialised on it: every constant becomes a
constant of the compiled loop's code (Numba prunes the branches it decides: the DP5 loop holds no
code of a lazy dense output, the RKN4 loop none of the dissipated energy), and every function is
called by name from the loop's code and inlined there. What a scheme's module provides:

- constants: ``ORDER`` (of the method), ``ERROR_ORDER`` (the embedded error estimate is O(h^ERROR_ORDER):
  the PI controller's exponent), ``EVALUATIONS`` (force evaluations per step), ``LAZY_DENSE`` (the dense
  output must be laid out by ``dense_data`` before it is read), ``SEPARATE_VELOCITY_WEIGHTS`` (positions
  and velocities have their own dense-output weights), ``END_IN_STAGE`` (the step's end velocities are in
  the last stage, ``Kx[6]``, rather than only in ``vs``), ``VELOCITY_FORCES`` (the stages pass their
  velocities to the forces and report the dissipated power ``Pd``: the damping laws);
- ``stages(x, v, Kx, Kv, xs, vs, h, hi, fm, F, Pd, general)``: one step's stages into the seven stage
  slots ``Kx``, ``Kv`` (``Kv[0]`` and, with ``END_IN_STAGE``, ``Kx[0]`` hold the derivative at the step's
  start; on return ``xs``, ``vs`` hold the new solution and ``Kv[6]`` its acceleration);
- ``error_ratios(x, v, xs, vs, Kx, Kv, h, hi, relaxed, factor, rtol, atol, ratio)``: the embedded error
  over its tolerance, positions in ``ratio[:hi]``, velocities in ``ratio[hi:2 hi]``;
- ``dense_data(x, v, xs, vs, Kx, Kv, h, hi)`` and ``weights(theta, Qx, Qv)``: the dense output
  y(t + theta h) = y + h sum_s K[s] Q[s] (positions with ``Kx``, ``Qx``; velocities with ``Kv``, ``Qv``);
- with ``VELOCITY_FORCES``: ``dissipated(Pd, h)`` and ``dissipated_error_ratio(Pd, h, e, rtol, atol)``,
  the quadrature of the dissipated power over a step and its embedded error.

A new method is a module with these, a :func:`scheme` line in :data:`SCHEMES`, its branch in
:func:`dense_weights` (and its kind in :data:`WEIGHTED_KINDS`) and its integrator class (``granchain.solve.integrators``); the Numba backend and
the entry points (``dispatch``) read :data:`SCHEMES`.
"""

from __future__ import annotations

from collections import namedtuple

from numba import njit

from . import dp5, rkn4
from .jit import JIT_INTERNAL
from .records import KIND_DP5, KIND_RKN4

#: A method of the step loop: its ``name`` (the integrator's), ``kind`` (``records.Method.kind``), its
#: ``module`` and the module's constants (see the module docstring).
Scheme = namedtuple("Scheme", ["name", "kind", "module", "order", "error_order", "evaluations", "lazy_dense",
                               "separate_velocity_weights", "end_in_stage", "velocity_forces"])

_FUNCTIONS = ("stages", "error_ratios", "dense_data", "weights")
#: The kinds :func:`dense_weights` has a branch for.
WEIGHTED_KINDS = (KIND_DP5, KIND_RKN4)


def scheme(name: str, kind: int, module) -> Scheme:
    """The scheme of ``module`` (checked: every constant and function of the module docstring, and a branch
    of :func:`dense_weights` for its kind, without which its peaks would be located on another method's
    dense output)."""
    if kind not in WEIGHTED_KINDS:
        raise TypeError(f"the Runge-Kutta scheme {name!r} has kind {kind}, which schemes.dense_weights has no branch "
                        f"for (it has {WEIGHTED_KINDS}): add one, and the kind to WEIGHTED_KINDS")
    missing = [f for f in _FUNCTIONS + (("dissipated", "dissipated_error_ratio") if module.VELOCITY_FORCES else ())
               if not hasattr(module, f)]
    if missing:
        raise TypeError(f"the Runge-Kutta scheme {name!r} ({module.__name__}) lacks {missing}")
    return Scheme(name, kind, module, int(module.ORDER), int(module.ERROR_ORDER), int(module.EVALUATIONS),
                  bool(module.LAZY_DENSE), bool(module.SEPARATE_VELOCITY_WEIGHTS), bool(module.END_IN_STAGE),
                  bool(module.VELOCITY_FORCES))


#: Every Runge-Kutta scheme, by kind.
SCHEMES = {s.kind: s for s in (scheme("dp5", KIND_DP5, dp5), scheme("rkn4", KIND_RKN4, rkn4))}
DP5 = SCHEMES[KIND_DP5]
RKN4 = SCHEMES[KIND_RKN4]


@njit(**JIT_INTERNAL)
def dense_weights(kind, theta, Qx, Qv):
    """The dense-output weights of the scheme ``kind`` at t + theta h, the method a run-time value: for
    the root searches (``dense.first_root``), compiled once for every method. The step loop calls its
    scheme's ``weights`` directly."""
    if kind == KIND_RKN4:
        rkn4.weights(theta, Qx, Qv)
    else:
        dp5.weights(theta, Qx, Qv)
