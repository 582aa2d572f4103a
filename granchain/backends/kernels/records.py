"""The grouped records the kernels take, instead of long lists of positional arguments.

A kernel entry point takes a handful of these (Numba compiles a named tuple into a struct whose
fields it reads directly, at no cost over separate arguments): a new model parameter is one more
field here and in the Python code that fills it (``granchain.backends.numba_backend``), not one more
argument in every signature between them. ``tests/test_backends.py`` counts the positional
arguments of every compiled entry point and checks that a field added to :data:`Params` reaches the
kernels (interpreted and compiled) with no other change.

Arrays are float64 and C-contiguous unless said otherwise; indices 0-based.
"""

from __future__ import annotations

from collections import namedtuple

#: The model's scalar parameters, passed whole through every kernel that reads any of them: ``n`` the
#: exponent of the power-law contact (granchain.model.contacts.PowerLaw); ``power`` its fast-path code
#: (``forces.power_code``); ``wall`` whether the far end is a fixed wall (the boundary value of the
#: chain, ``granchain.model.contacts.FixedWall``: asked here once, not re-derived from the infinite mass).
#: ``gamma`` the damping time of the viscoelastic contact (``granchain.model.contacts.Viscoelastic``;
#: 0: elastic), ``static_force`` the precompression F0 (``granchain.model.contacts.Precompression``; 0:
#: none). A new physics parameter is one more field here, filled in one place
#: (``granchain.backends.numba_backend.model_params``), and the kernels that need it read it by name:
#: no signature between them changes (``tests/test_backends.py`` checks this).
#: ``clamp``: whether the viscoelastic force is clamped at 0 (never pulls; the default) or may pull, as in
#: the published law (``Viscoelastic(clamp=False)``; read only where ``gamma`` > 0). ``damping``: the
#: form of the damping term (``forces.LAW_FORMS``, from the law's ``form``; read only where ``gamma`` > 0).
#: ``yield_overlap``: Thornton's elastic-plastic contact (``granchain.model.contacts.ElasticPlastic``), the yield
#: overlap of the reference pair (contact j yields at c_j^2 times it; 0: no yield, every other law).
Params = namedtuple("Params", ["n", "power", "wall", "gamma", "static_force", "clamp", "damping", "yield_overlap"],
                    defaults=(True, 0, 0.0))

#: One chain as the kernels see it (Eq. motion_rescaled). ``masses`` (M,), the last ``inf`` for a
#: fixed wall; ``stiffness`` (M-1,), the prefactors c_k; ``params`` its :data:`Params`.
Model = namedtuple("Model", ["masses", "stiffness", "params"])

#: A batch of chains of one size for the ensemble kernel: ``masses`` (R, M), ``stiffness`` (R, M-1),
#: ``initial_velocity`` (R,) (the impulse on granule 1 of each row), the :data:`Params` the rows share,
#: and each row's time limit ``t_max`` (R,; a row's own, so that its result does not depend on the rows
#: it is batched with: a precompressed chain runs to it); ``order`` (R,), the rows in the order they are
#: started (a permutation of 0..R-1, ``backends.longest_first``; no result depends on it), and ``taken``
#: (1,), how many of them the threads have taken (``queue.take``: from 0).
Batch = namedtuple("Batch", ["masses", "stiffness", "initial_velocity", "params", "t_max", "order", "taken"])

#: The integration method: ``kind`` (``KIND_*`` below) and its settings ``params`` (float64,
#: laid out by the kind: see ``dispatch``).
Method = namedtuple("Method", ["kind", "params"])

#: The step control of the Runge-Kutta loop (``rkloop``), unpacked from a :data:`Method`'s params.
#: ``fixed_step`` > 0 turns the control off; the goal-oriented zones are off when their lags are 0.
Steps = namedtuple("Steps", ["rtol", "atol", "first_step", "fixed_step", "relaxed_lag", "relaxed_factor", "window_lag"])

#: What to record and when to stop: the ``observed`` granules (int64, (K,)), the ``t_grid`` (T,)
#: on which their velocities are sampled, the hard limit ``t_max``, whether to stop
#: ``exit_margin`` after the pulse has left (``stop_at_exit``), the step budget ``max_steps``, the
#: tie rule of peaks ``peak_rtol`` (``peaks.is_new_peak``) and the ``contacts`` (int64, (S,), 0-based)
#: whose force is recorded on the grid (a sensor granule's two contacts; empty: none), and per observed
#: granule the end of its averaged-pulse window ``pulse_end`` (K,): the trailing window keeps the granule
#: integrated until that time (inf: to the end), and its grid velocities after it are not recorded (written
#: as 0; the ensembles' readers show them as not computed). Empty (simulate, and ensembles without
#: windows): no window, the trailing window drops granules as the front alone decides.
Run = namedtuple("Run", ["observed", "t_grid", "t_max", "stop_at_exit", "exit_margin", "max_steps", "peak_rtol",
                         "contacts", "pulse_end"])

#: The state (x, v) of the M granules and the per-contact ``history`` (M-1,) of a law with memory (each
#: contact's largest overlap for Thornton's law, unread for every other law): the initial state on entry,
#: the final one on return. A run starts from virgin contacts, whose largest overlap is by convention their
#: yield overlap: on entry ``history`` holds the contacts' yield overlaps (0: c_j^2 ``Params.yield_overlap``,
#: granules of one material), which the kernel keeps as such.
State = namedtuple("State", ["x", "v", "history"])

#: What one integration records: per observed granule its peak velocity and time (K,), its
#: velocities on the grid ``grid_v`` (T, K, time-major); per contact its peak force and time (M-1,);
#: the wall force on the grid ``grid_f`` (T,; with a wall); the run's ``info`` (INFO_SIZE,); the
#: forces of ``Run.contacts`` on the grid ``grid_c`` (T, S; NaN behind a trailing window).
Outputs = namedtuple("Outputs", ["peak_v", "peak_t", "grid_v", "peak_f", "peak_ft", "grid_f", "info", "grid_c"])

#: What the ensemble kernel records per realisation r (rows), each field named as the results' schema names
#: it (so that a backend fills it from the schema-built buffers by name): peak velocity and time (R, K), the
#: recorded contacts' peak force and time (R, C), the wall's peak force and its time (R,), the status, the
#: relative energy error, the accepted steps, the end time and the dissipated energy (R,).
Rows = namedtuple("Rows", ["peak_velocity", "peak_time", "peak_force", "peak_force_time", "peak_wall_force",
                           "peak_wall_force_time", "status", "energy_error", "n_steps", "t_end", "dissipated_energy"])

#: The ensemble kernel's fixed-point sums (int64): of the grid velocities and their squares (T, K), of
#: the wall force (T,), the count of successful realisations (1,), and of the aligned pulse (L, K).
Sums = namedtuple("Sums", ["sum_v", "sum_v2", "sum_wall", "n_valid", "sum_a", "sum_a2"])

#: What the ensemble kernel needs besides the chains: the recorded ``contacts`` (int64, (C,)), the
#: fixed-point ``scale`` (2^bits) and the aligned pulse's ``lags`` (L,; empty: none).
Tally = namedtuple("Tally", ["contacts", "scale", "lags"])

#: The per-thread partial sums of :data:`Sums` (first axis: thread), allocated by the caller
#: (``batch.thread_sums``).
Partials = namedtuple("Partials", ["sum_v", "sum_v2", "sum_wall", "n_valid", "sum_a", "sum_a2"])

#: What a force evaluation reads, as views from the window's first granule on: the contact
#: prefactors, the inverse masses (0 for a wall and for padding), the model's :data:`Params`, and for
#: a precompressed chain each contact's static overlap delta0_k and static force f0_k
#: (``forces.static_state``; zeros without precompression), and for Thornton's law (read only where
#: ``params.yield_overlap`` > 0) each contact's ``history`` (its largest overlap) and ``yield_overlap``.
Forces = namedtuple("Forces", ["stiffness", "inv_mass", "params", "overlap", "preload", "history", "yield_overlap"])

# Slots of the ``info`` array every single-chain kernel fills.
INFO_T_END = 0  # time the run stopped
INFO_STEPS = 1  # accepted steps
INFO_REJECTED = 2  # rejected steps
INFO_EXIT = 3  # time the pulse left the last granule (-1: it did not)
INFO_EVALUATIONS = 4  # force evaluations (whole-window sweeps)
INFO_WINDOW_START = 5  # first granule still integrated at the end (0-based; > 0 only with a trailing window)
INFO_FROZEN_POTENTIAL = 6  # potential energy of the contacts behind the window when they left it
INFO_DISSIPATED = 7  # energy dissipated by viscoelastic contacts (0 for elastic ones)
INFO_SIZE = 8

# Method kinds (``Method.kind``): one id per compiled method, the only place it is numbered.
KIND_DP5 = 0
KIND_VERLET = 1
KIND_RKN4 = 2

#: An accepted Runge-Kutta step's dense output, as views from the window's first granule on: the
#: state at the step's start (x, v), the stage slots Kx, Kv (7, Mp) that ``dp5``/``rkn4`` fill,
#: and the step h. Its values at t + theta h are y + h sum_s K[s] Q[s] (``dense.dense_value``).
Dense = namedtuple("Dense", ["x", "v", "Kx", "Kv", "h"])
