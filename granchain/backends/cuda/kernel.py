"""The CUDA kernels: RKN4(3), DP5(4) or velocity Verlet over a batch of chains, a group of ``L`` threads per
chain.

Layout (why it is not one thread per chain). An adaptive method takes as many steps as its chain
needs, and the paper's decorated chains differ in that by up to 50x (the tiniest decorating granules
ring fastest): laid out one thread per chain, a warp runs as long as its slowest chain and each
thread's stage arrays live in local memory (measured: 937 s for the paper's 30,000 N = 26 chains on an
H200, against 3.6 s here). Here a chain is a block of ``L`` threads (``L`` = 32: one warp) and its
granules are spread across them, ``G`` consecutive granules a thread (``L * G >= M``); the group shares
one step size, so its threads never diverge in step count, and a block that finishes frees its slot
for the next chain at once (the host launches the chains longest first). Per step the threads exchange
only what crosses their boundaries: the neighbours' stage positions (for the contact forces,
Eq. (motion_rescaled)), the error norm's maximum, the candidates of peaks and of the trailing window's
cut, by warp shuffles (``shuffle``, the default at ``L`` = 32) or through shared memory and barriers;
and, on the few steps that hold a peak or a grid time, the dense output of every granule, through
shared memory. ``L = 1`` compiles the same code as one thread per chain (its exchange arrays in local
memory, no barriers), the layout it is measured against (``benchmarks/bench_gpu.py``).

The methods, step control and records are those of the CPU kernels (``granchain.backends.kernels``:
``rkn4`` for the Runge-Kutta-Nystrom pair of Dormand, El-Mikkawy & Prince, ``dp5`` for Dormand-Prince,
``verlet`` for velocity Verlet with its own peak rules (see :func:`make_kernel`), ``rkloop`` for the PI
controller, the max-norm error with its relaxed zone and the stop rule, ``dense`` for the peaks
located as roots on the quintic Hermite dense output), written once more for the GPU because a GPU
kernel cannot call the CPU's: compiled by NVVM, whose fused multiply-adds round differently, the
results agree with the CPU's within the accuracy contract, not bit for bit (in Numba's simulator,
which computes as the CPU does, they are the CPU's to rounding: ``tests/test_cuda.py``). The granules
ahead of the pulse are integrated too (the CPU's active window skips them: they are exactly at rest, so
this changes nothing, and the threads that hold them would idle anyway); the trailing window behind the
pulse is the CPU's (``kernels.window``). Elastic power-law contacts (Hertz, n = 5/2, or any n), or with DP5 damped ones
(Kuwabara-Kono, viscous: ``make_kernel``'s ``damped``), free end or fixed wall, precompressed or not
(``make_kernel``'s ``precompressed``): what else a chain declares is refused by ``CudaBackend.check``.

The step loop calls device functions of four modules: ``granchain.backends.cuda.methods`` (each method's
stages and error estimate), ``granchain.backends.cuda.exchange`` (the group's reductions and the
neighbours' positions for the forces), ``granchain.backends.cuda.observe`` (what a step records: the peaks,
the grid samples, a yielding contact's turn, the last instant's candidates) and
``granchain.backends.cuda.device`` (the force, the dense output, the root search); the averaged pulse is
reduced by ``granchain.backends.cuda.sums``.
"""

from __future__ import annotations

import math

from numba import cuda, float64, int64

from ..._status import MAX_STEPS, NONFINITE, STEP_UNDERFLOW, SUCCESS, T_MAX

# The step control's constants and the stop and window rules: the CPU kernels' own numbers (one source;
# the GPU code below is the CPU's written for CUDA).
from ..kernels.rkloop import BETA, MAX_FACTOR, MIN_FACTOR, SAFETY, TURN_SLACK
from ..kernels.stop import RATTLER_MASS_RATIO
from .device import FULL_MASK, compression, cut_target, falls, force_rate, unloading_curve
from .exchange import make_exchange
from .observe import make_observers
from .methods import ALPHA, DP5_ROWS, dissipated, dissipated_error, make_error, make_stages, make_velocity, over_tolerance


#: Layout of the float settings array ``prm`` the kernel reads.
#: ``P_GAMMA``, ``P_VISCOUS``, ``P_CLAMP``: a damped law's constant, 1 for the viscous law (else Kuwabara-Kono's), 1
#: where its force is clamped at 0 (``records.Params``; read by the damped kernels alone). ``P_STATIC``: the
#: precompression F0 (``records.Params.static_force``; read by the precompressed kernels alone). ``P_YIELD``: the
#: yield overlap of two reference granules (``records.Params.yield_overlap``; read by the yielding kernels alone).
(P_RTOL, P_ATOL, P_FIRST, P_RELAX_LAG, P_RELAX_FACTOR, P_WINDOW_LAG, P_EXIT_MARGIN, P_PEAK_RTOL, P_MAX_STEPS, P_N,
 P_STOP_AT_EXIT, P_WALL, P_T_NEEDED, P_WINDOWS, P_GAMMA, P_VISCOUS, P_CLAMP, P_STATIC, P_YIELD, P_SIZE) = range(20)


def make_kernel(L: int, G: int, max_registers: int | None = None, shuffle: bool = False, votes: bool = True,
                method: str = "rkn4", fixed: bool = False, damped: bool = False, precompressed: bool = False,
                plastic: bool = False, sensed: bool = False, exponent: float | None = None):
    """The batch kernel of ``method`` ("rkn4", "dp5" or "verlet") for ``L`` threads per chain and ``G``
    granules per thread (chains of up to ``L * G`` granules). ``L``, ``G``, the method and ``fixed`` are
    constants of its code: Numba prunes the barriers of ``L = 1`` and the other methods' code, and sizes
    the per-thread arrays by ``G``. ``max_registers`` caps the registers per thread (more resident chains
    per multiprocessor, against spills: measured in benchmarks/bench_gpu.py; what ptxas allots each
    kernel, in benchmarks/gpu_registers.py).

    ``fixed``: RKN4 or DP5 with a fixed step (the first step, ``P_FIRST``): no error estimate, every step
    accepted, as the CPU's ``fixed_step`` (``rkloop``); a state that is not finite ends the run (NONFINITE).

    ``method`` "dp5": Dormand-Prince 5(4) (``kernels.dp5``: six force evaluations a step, the seventh
    stage the next step's first) in the same step loop, with its own PI exponent; its error norm is the
    CPU's. Its peaks and grid samples are read on the quintic Hermite interpolant through (x, v, a) at the
    step's ends, as RKN4's are, not on Shampine's continuous extension the CPU uses: Hermite needs only
    the step's end states of a granule's neighbours (three shared arrays, not fourteen stage arrays) and is
    of higher order in the positions (O(h^6) against the extension's O(h^5); velocities O(h^5) in both); the
    two locate a peak within the step's error, so GPU and CPU agree within the accuracy contract, with the
    same steps (the step control reads no dense output).

    ``method`` "verlet": velocity Verlet with the fixed step ``P_FIRST`` (``kernels.verlet``): one force
    evaluation a step, its peaks at the zero of the linearly interpolated acceleration (or relative
    velocity) and its grid samples on the cubic Hermite interpolant of the step's ends, as the CPU reads
    them, to rounding; no goal-oriented zones (the host passes no lags and no averaged-pulse windows).

    ``damped`` (DP5 only): contacts whose force reads the rate of compression (Kuwabara & Kono's viscoelastic
    law, or the viscous law of Rosas et al.: ``device.law_force``, by ``P_GAMMA``, ``P_VISCOUS``, ``P_CLAMP``), as
    the CPU's DP5 integrates them (``kernels.dp5``, ``kernels.rkloop``): the stages pass their velocities to the
    forces (the neighbours' through the exchange too), the energy the contacts dissipate is integrated with the
    motion by the stages' quadrature and its embedded error steers the step; a granule's velocity maximum is
    the root of its damped acceleration, a contact's force maximum the root of the force's rate (it peaks
    while the contact still closes); after a cut of the trailing window the first stage is evaluated again
    (the contact at its edge dropped). The kernel writes each chain's dissipated energy.

    ``precompressed`` (every method): a chain held by the static force F0 = ``P_STATIC``
    (``granchain.model.contacts.Precompression``), integrated as the CPU integrates it (``kernels.forces``): in
    displacements from the static state, each contact with its static overlap delta0_j and force f0_j
    (``device.static_state``, computed once per chain into a shared array) and the dynamic force F_j - f0_j,
    exactly 0 in the static state, so the granules ahead of the pulse stay exactly at rest; the recorded forces
    (peaks, the wall's on the grid) are the total ones, the static load included, which is also each contact's
    first peak candidate at t = 0 (``kernels.peaks.initial_force_records``). Such a chain has no trailing window
    or relaxed zone (its contacts never open: ``CudaBackend`` runs it with neither) and runs to its time limit.

    ``plastic`` (DP5, not damped): Thornton's elastic-perfectly plastic contacts (C. Thornton, J. Appl. Mech. 64,
    383 (1997); ``granchain.model.contacts.ElasticPlastic``), contacts with memory, as the CPU's DP5 integrates them
    (``kernels.rkloop``): each contact's yield overlap delta_y,j and history, its largest overlap so far, are kept
    in a shared array (``device.elastic_force`` reads them: the loading line beyond the history, the unloading
    curve from it below); the history moves after each accepted step, never within one, so an accepted step in
    which a contact on its loading line turns back (its compression peaks beyond its history) is retaken to end
    at the turn (``kernels.observe.yield_turn``: the turn located on the dense output, where the stages past it
    followed the loading line while the contact unloads). The last argument ``history`` holds each chain's yield
    overlaps on entry (0: c_j^2 ``P_YIELD``, spheres of one material) and its final histories on return; the
    dissipated energy written is the plastic work of the final histories (``kernels.forces.plastic_work``). The
    pulse leaves through a yielded last contact when it opens at its plastic overlap (the dent it keeps:
    ``kernels.stop.pulse_has_left``). Such a chain runs without a trailing window or relaxed zone (the granules
    left behind would take their contacts' histories with them: ``effective_integrator``). Other kernels take
    ``history`` as an empty tuple, which adds no parameter to their code.

    ``sensed`` (every method and law): the total forces of the contacts ``sensors`` (0-based, the last two
    arguments: ``sensors`` and ``grid_c``, rows x grid times x sensors) on the grid, as the wall's force is
    sampled (``kernels.observe.sample_grid``): each by the thread that holds the contact's left granule; at the
    grid times <= 0 its force at t = 0, behind the trailing window NaN (as the CPU's). Other kernels take both
    as empty tuples.

    ``exponent`` (every method and law): the contact law's exponent n as a constant of the code, for chains of that n
    only (the host's ``P_N`` is not read). Constant, the branches of ``device.contact_force`` and the damped forces
    on n fold away: for n = 5/2, Hertz's ``c d sqrt(d)`` is all that is left of the power, and libdevice's general
    ``pow`` (a call the compiler keeps registers for, though a Hertz chain never takes it) leaves the kernel. The
    same arithmetic, so the same results bit for bit. None (the default): n read from ``P_N``, one kernel for
    every n.

    Barriers: a group exchanges the stage positions through two alternating shared arrays, so that one
    barrier per force evaluation suffices (a thread can only overwrite an array after every thread has
    passed the next barrier, i.e. finished reading it); per step, one for each force evaluation (RKN4
    three, DP5 six, Verlet one), one for the error norm (damped: two more, for the sums of the dissipated
    energy and its error) and two for the candidates of peaks and of the trailing window's cut.

    ``shuffle`` (``L`` = 32, one warp per chain): the neighbours' positions and every reduction of a step
    go through warp shuffles instead, with no barrier at all in a step without a peak or grid time (Numba's
    simulator has no shuffles: ``simulator.install`` emulates them, so the tests run both exchanges).

    ``votes`` (with ``shuffle``): the step's integer reductions (is there a peak candidate, which contact
    the trailing window cuts, how far the front has come, is the exit blocked) by warp votes instead of
    shuffle trees. Each is a flag, or an index that is -1 or grows with the granules a thread owns (lane l
    holds granules l G .. l G + G - 1, and the observed granules are strictly increasing), so the group's
    maximum is the value of the last lane that has one: one ballot and one 32-bit shuffle, where a
    butterfly of 64-bit maxima takes five shuffle rounds of two instructions each. Same results bit for
    bit (integers); ``votes=False`` keeps the butterflies for the benchmark's comparison."""
    VERLET = method == "verlet"
    FIXED = bool(fixed) or VERLET
    N_FIXED = -1.0 if exponent is None else float(exponent)  # > 0: the exponent compiled in (``exponent``)
    if exponent is not None and not 1.0 < N_FIXED < math.inf:
        raise ValueError(f"exponent must be a contact law's finite n > 1 (Hertz: 2.5), got {exponent!r}")
    SG = G if method == "dp5" else 1  # DP5's stage arrays (one element, unused, in the others' kernels)
    MMAX = L * G
    GROUP = L > 1
    SHUFFLE = bool(shuffle)
    VOTES = SHUFFLE and bool(votes)
    if SHUFFLE and L != 32:
        raise ValueError("the shuffle exchange needs one warp (32 threads) per chain")
    options = {} if max_registers is None else {"max_registers": max_registers}

    DAMPED = bool(damped)
    LOADED = bool(precompressed)
    PLASTIC = bool(plastic)
    SENSED = bool(sensed)
    if PLASTIC and (method != "dp5" or DAMPED):
        raise ValueError("yielding contacts are integrated by DP5 alone, without damping (as the CPU's kernels)")
    (sync, group_max, group_any, group_last, group_sum, right_neighbour, forces,
     cut_candidates) = make_exchange(L, G, SHUFFLE, VOTES, DAMPED)
    stages = make_stages(method, forces, G, DAMPED)  # (refuses a method it has no stages for, and damping but DP5)
    BX = MMAX * (2 if DAMPED else 1)  # the stage exchange: positions, and a damped law's velocities after them
    LD = L if DAMPED or PLASTIC else 1  # the reductions of the dissipated energy (damped, yielding)
    PW = 7 if DAMPED else 1
    new_velocity = make_velocity(method)
    step_error = make_error(method, fixed)
    EXPONENT = 0.0 if FIXED else ALPHA[method]
    initial_records, yield_turn, step_peaks, sample_grid, final_records = make_observers(method, G, DAMPED, LOADED,
                                                                                         PLASTIC, SENSED)

    @cuda.jit(**options)
    def kernel(masses, stiffness, v_init, t_limit, obs_of, obs, t_grid, pulse_end, prm,
               peak_v, peak_t, peak_f, peak_ft, peak_d, grid_v, grid_f, status_out, steps_out, rejected_out,
               t_end_out, exit_out, lo_out, frozen_out, diss_out, x_out, v_out, history, sensors, grid_c):
        if GROUP:
            r = cuda.blockIdx.x
            lane = cuda.threadIdx.x
        else:
            r = cuda.blockIdx.x * cuda.blockDim.x + cuda.threadIdx.x
            lane = 0
        R = masses.shape[0]
        if r >= R:
            return
        M = masses.shape[1]
        T = t_grid.shape[0]
        K = obs.shape[0]
        own = lane * G  # first granule of this thread
        # Exchange arrays: shared by the group's threads (one chain per block), or the thread's own.
        if GROUP:
            bxa = cuda.shared.array(BX, float64)
            bxb = cuda.shared.array(BX, float64)
            hx0 = cuda.shared.array(MMAX, float64)
            hv0 = cuda.shared.array(MMAX, float64)
            ha0 = cuda.shared.array(MMAX, float64)
            hx1 = cuda.shared.array(MMAX, float64)
            hv1 = cuda.shared.array(MMAX, float64)
            ha1 = cuda.shared.array(MMAX, float64)
            red_e = cuda.shared.array(L, float64)
            red_c = cuda.shared.array(L, int64)
            red_o = cuda.shared.array(L, int64)
            red_f = cuda.shared.array(L, int64)
            red_q = cuda.shared.array(L, int64)
            red_b = cuda.shared.array(L, int64)
            red_w = cuda.shared.array(LD, float64)
            red_z = cuda.shared.array(LD, float64)
            tail = cuda.shared.array(4, float64)
            if LOADED:  # each contact's static overlap and force
                pre = cuda.shared.array((2, MMAX), float64)
            else:
                pre = None
            if PLASTIC:  # each contact's yield overlap and history (its largest overlap)
                yld = cuda.shared.array((2, MMAX), float64)
            else:
                yld = None
        else:
            bxa = cuda.local.array(BX, float64)
            bxb = cuda.local.array(BX, float64)
            hx0 = cuda.local.array(MMAX, float64)
            hv0 = cuda.local.array(MMAX, float64)
            ha0 = cuda.local.array(MMAX, float64)
            hx1 = cuda.local.array(MMAX, float64)
            hv1 = cuda.local.array(MMAX, float64)
            ha1 = cuda.local.array(MMAX, float64)
            red_e = cuda.local.array(1, float64)
            red_c = cuda.local.array(1, int64)
            red_o = cuda.local.array(1, int64)
            red_f = cuda.local.array(1, int64)
            red_q = cuda.local.array(1, int64)
            red_b = cuda.local.array(1, int64)
            red_w = cuda.local.array(1, float64)
            red_z = cuda.local.array(1, float64)
            tail = cuda.local.array(4, float64)
            if LOADED:
                pre = cuda.local.array((2, MMAX), float64)
            else:
                pre = None
            if PLASTIC:
                yld = cuda.local.array((2, MMAX), float64)
            else:
                yld = None
        x = cuda.local.array(G, float64)
        v = cuda.local.array(G, float64)
        a0 = cuda.local.array(G, float64)
        k1 = cuda.local.array(G, float64)
        k2 = cuda.local.array(G, float64)
        a3 = cuda.local.array(G, float64)
        xs = cuda.local.array(G, float64)
        vs = cuda.local.array(G, float64)
        inv_m = cuda.local.array(G, float64)
        mass = cuda.local.array(G, float64)
        c_left = cuda.local.array(G, float64)
        c_right = cuda.local.array(G, float64)
        q_of = cuda.local.array(G, int64)
        stage = cuda.local.array((DP5_ROWS, SG), float64)  # DP5's stages besides k1, k2 (``methods``)
        pw = cuda.local.array(PW, float64)  # a damped law: this thread's contacts' power at each stage

        rtol = prm[P_RTOL]
        atol = prm[P_ATOL]
        relax_lag = int64(prm[P_RELAX_LAG])
        relax_factor = prm[P_RELAX_FACTOR]
        window_lag = int64(prm[P_WINDOW_LAG])
        exit_margin = prm[P_EXIT_MARGIN]
        peak_rtol = prm[P_PEAK_RTOL]
        max_steps = int64(prm[P_MAX_STEPS])
        n = N_FIXED if N_FIXED > 0.0 else prm[P_N]
        stop_at_exit = prm[P_STOP_AT_EXIT] > 0.0
        wall = prm[P_WALL] > 0.0
        t_needed = prm[P_T_NEEDED]
        windows = prm[P_WINDOWS] > 0.0
        t_max = t_limit[r]
        m_last = masses[r, M - 1]
        law = (n, prm[P_GAMMA], prm[P_VISCOUS], prm[P_CLAMP])

        for s in range(G):
            i = own + s
            x[s] = 0.0
            v[s] = 0.0
            xs[s] = 0.0
            inv_m[s] = 0.0
            mass[s] = 0.0
            c_left[s] = 0.0
            c_right[s] = 0.0
            q_of[s] = -1
            if i < M:
                mass[s] = masses[r, i]
                inv_m[s] = 1.0 / masses[r, i]  # 0 for a wall (infinite mass)
                if i > 0:
                    c_left[s] = stiffness[r, i - 1]
                if i < M - 1:
                    c_right[s] = stiffness[r, i]
                q_of[s] = obs_of[i]
                if i == 0:
                    v[s] = v_init[r]
                if i < M - 1:  # the contact's first records (a static state, a yielding contact's history)
                    initial_records(r, i, v[s], c_right[s], law, prm[P_STATIC], pre, yld, history, prm[P_YIELD], peak_f,
                                    peak_ft, peak_d)
        if LOADED or PLASTIC:
            sync()
        # The initial state: the first peak candidates, and the grid times <= 0.
        for s in range(G):
            q = q_of[s]
            if q >= 0:
                peak_v[r, q] = v[s]
                peak_t[r, q] = 0.0
        g = 0
        while g < T and t_grid[g] <= 0.0:
            for s in range(G):
                q = q_of[s]
                if q >= 0:
                    grid_v[r, g, q] = v[s]
            if wall and lane == 0:
                if LOADED:  # the static load on the wall (the wall contact's force at t = 0, written above)
                    grid_f[r, g] = peak_f[r, M - 2]
                else:
                    grid_f[r, g] = 0.0
            if SENSED:  # each sensed contact's force at t = 0 (written above by this thread, which holds it)
                for k in range(sensors.shape[0]):
                    j = sensors[k]
                    if j >= own and j < own + G:
                        grid_c[r, g, k] = peak_f[r, j]
            g += 1
        lo = int64(0)  # the trailing window: granules 0..lo-1 have left the integration
        p0 = forces(x, v, own, M, lo, bxa, c_left, c_right, inv_m, law, a0, pre, yld)
        if DAMPED:
            pw[0] = p0

        t = 0.0
        h = prm[P_FIRST]
        h_fixed = h
        err_old = 1e-4
        exit_since = -1.0
        n_acc = int64(0)
        n_rej = int64(0)
        front = int64(-1)
        relaxed = int64(0)
        q_open = int64(0)
        frozen = 0.0
        spent = 0.0  # the energy the contacts have dissipated
        step_spent = 0.0
        status = int64(-1)
        while status < 0:
            if n_acc + n_rej >= max_steps:
                status = MAX_STEPS
                break
            t_stop = t_max
            if exit_since >= 0.0:
                t_stop = min(t_max, max(exit_since + exit_margin, t_needed))
            last = False
            if t + h >= t_stop:
                h = t_stop - t
                last = True
            h2 = h * h
            stages(x, v, a0, xs, vs, a3, k1, k2, stage, h, h2, own, M, lo, bxa, bxb, c_left, c_right, inv_m, law, pw, pre,
                   yld)
            # The new velocities (RKN4) and this thread's share of the error norm.
            e = 0.0
            for s in range(G):
                i = own + s
                new_velocity(s, v, vs, a0, k1, k2, a3, h)
                if i < M:
                    w = relax_factor if i < relaxed else 1.0
                    e = max(e, step_error(s, x, v, xs, vs, a0, k1, k2, a3, stage, h, h2, w, rtol, atol))
                    if not SHUFFLE:
                        if i == M - 2:
                            tail[0] = xs[s]
                            tail[1] = vs[s]
                        if i == M - 1:
                            tail[2] = xs[s]
                            tail[3] = vs[s]
            err = group_max(e, red_e, lane)
            if DAMPED:  # the dissipated energy, a component of the state (``kernels.dp5.dissipated_error_ratio``)
                step_spent = group_sum(dissipated(pw, h), red_w, lane)
                if not FIXED:
                    spent_error = group_sum(dissipated_error(pw, h), red_z, lane)
                    err = max(err, over_tolerance(spent_error, spent, rtol, atol))
            if SHUFFLE:  # the last two granules' new state, from the threads that hold them
                x_m2 = 0.0
                v_m2 = 0.0
                x_m1 = 0.0
                v_m1 = 0.0
                for s in range(G):
                    if own + s == M - 2:
                        x_m2 = xs[s]
                        v_m2 = vs[s]
                    if own + s == M - 1:
                        x_m1 = xs[s]
                        v_m1 = vs[s]
                x_m2 = cuda.shfl_sync(FULL_MASK, x_m2, (M - 2) // G)
                v_m2 = cuda.shfl_sync(FULL_MASK, v_m2, (M - 2) // G)
                x_m1 = cuda.shfl_sync(FULL_MASK, x_m1, (M - 1) // G)
                v_m1 = cuda.shfl_sync(FULL_MASK, v_m1, (M - 1) // G)
            else:
                x_m2 = tail[0]
                v_m2 = tail[1]
                x_m1 = tail[2]
                v_m1 = tail[3]
            if not (err <= 1e300):
                status = NONFINITE
                break
            if err > 1.0:
                n_rej += 1
                h *= max(MIN_FACTOR, SAFETY * err ** -EXPONENT)
                if h < 1e-14 * max(1.0, t):
                    status = STEP_UNDERFLOW
                continue

            # Accepted. The candidates: a velocity maximum of an observed granule or a compression maximum
            # (their roots need the dense output of every granule), and, behind the front, the contact
            # the trailing window may cut (``kernels.window.open_contact_behind``). The right neighbour's
            # state crosses thread boundaries: start velocities in bxa, new velocities in hv1, new positions
            # in hx1.
            t_new = t + h if not last else t_stop
            if windows:
                while q_open < K and pulse_end[q_open] < t_new:
                    q_open += 1
            target = cut_target(front, window_lag, windows, q_open, obs)
            if not SHUFFLE:
                for s in range(G):
                    i = own + s
                    if i < M:
                        bxa[i] = v[s]
                        hv1[i] = vs[s]
                        hx1[i] = xs[s]
                        if DAMPED:  # (the dense output's arrays, as they are written below)
                            hx0[i] = x[s]
                            ha0[i] = a0[s]
                            ha1[i] = a3[s]
                sync()
            vr0 = right_neighbour(v, own, M, bxa)
            vr1 = right_neighbour(vs, own, M, hv1)
            xr1 = right_neighbour(xs, own, M, hx1)
            xr0 = 0.0
            ar0 = 0.0
            ar1 = 0.0
            if DAMPED:
                xr0 = right_neighbour(x, own, M, hx0)
                ar0 = right_neighbour(a0, own, M, ha0)
                ar1 = right_neighbour(a3, own, M, ha1)
            cand = 0
            for s in range(G):
                i = own + s
                if i >= lo and i < M:
                    if q_of[s] >= 0 and falls(a0[s], a3[s]):
                        cand = 1
                    if i < M - 1:
                        w0 = v[s] - (v[s + 1] if s < G - 1 else vr0)
                        w1 = vs[s] - (vs[s + 1] if s < G - 1 else vr1)
                        if DAMPED:  # a damped contact's force peaks where its rate falls (``kernels.observe.force_peaks``)
                            w0 = force_rate(compression(x[s] - (x[s + 1] if s < G - 1 else xr0), i, pre), w0,
                                            a0[s] - (a0[s + 1] if s < G - 1 else ar0), c_right[s], law)
                            w1 = force_rate(compression(xs[s] - (xs[s + 1] if s < G - 1 else xr1), i, pre), w1,
                                            a3[s] - (a3[s + 1] if s < G - 1 else ar1), c_right[s], law)
                        if falls(w0, w1):
                            cand = 1
            j_open, j_weak = cut_candidates(target, own, lo, M, xs, xr1, c_right, n)
            need = group_any(cand, red_c, lane)
            j_open = group_last(j_open, red_o, lane)
            j_weak = group_last(j_weak, red_f, lane)
            if g < T and t_grid[g] <= t + h:
                need = 1
            if need > 0:
                # The dense output of every granule, for the roots and the grid samples.
                for s in range(G):
                    i = own + s
                    if i < M:
                        hx0[i] = x[s]
                        hv0[i] = v[s]
                        ha0[i] = a0[s]
                        hx1[i] = xs[s]
                        hv1[i] = vs[s]
                        ha1[i] = a3[s]
                sync()
                if PLASTIC:  # retaken to end where a contact turns from loading to unloading (``kernels.observe.yield_turn``)
                    turn = -group_max(-yield_turn(own, lo, M, hx0, hv0, ha0, hx1, hv1, ha1, h, law, pre, yld), red_e, lane)
                    if turn < 1.0 - TURN_SLACK:
                        n_rej += 1
                        h *= turn
                        continue
                found = step_peaks(r, t, h, own, lo, M, q_of, v, vs, a0, a3, c_left, c_right, inv_m, masses, stiffness,
                                   hx0, hv0, ha0, hx1, hv1, ha1, n, law, pre, yld, peak_rtol, peak_v, peak_t, peak_f,
                                   peak_ft, peak_d)
                g = sample_grid(g, r, t, h, own, lo, M, q_of, v, c_right, hx0, hv0, ha0, hx1, hv1, ha1, n, law, pre, yld,
                                t_grid, pulse_end, windows, wall, grid_v, grid_f, sensors, grid_c)
                before = front
                front = max(front, group_last(found, red_q, lane))
                if relax_lag > 0 and front >= relax_lag:
                    relaxed = obs[front - relax_lag]
                if front != before and window_lag > 0:
                    # The front moved in this step: the cut is decided behind the new one (as the CPU does).
                    target = cut_target(front, window_lag, windows, q_open, obs)
                    j_open, j_weak = cut_candidates(target, own, lo, M, xs, xr1, c_right, n)
                    j_open = group_last(j_open, red_o, lane)
                    j_weak = group_last(j_weak, red_f, lane)

            # The trailing window's cut: granules lo..new_lo-1 leave it with the potential of the contacts
            # among them (the contact at the new edge is open, or holds less than CUT_FORCE). (Never in a
            # precompressed chain, which runs without a trailing window: its contacts do not open.)
            new_lo = lo
            cut = False
            if j_open >= 0:
                new_lo = j_open + 1
            elif j_weak >= 0:
                new_lo = j_weak + 1
            if new_lo > lo:
                u = 0.0
                for s in range(G):
                    i = own + s
                    if i >= lo and i < new_lo - 1:
                        d = xs[s] - (xs[s + 1] if s < G - 1 else xr1)
                        if d > 0.0:
                            u += c_right[s] * d ** n / n  # Eq. (hertz-1)
                frozen += group_sum(u, red_e, lane)
                lo = new_lo
                cut = True

            for s in range(G):
                x[s] = xs[s]
                v[s] = vs[s]
                a0[s] = a3[s] if own + s >= lo else 0.0
            if DAMPED:
                spent += step_spent
                pw[0] = pw[6]
                if cut:  # the first stage without the contact at the window's new edge (as the CPU's)
                    pw[0] = forces(x, v, own, M, lo, bxa, c_left, c_right, inv_m, law, a0, pre, yld)
            if PLASTIC:  # the loading line moves each contact's history, between two barriers: every thread has
                sync()  # read this step's histories before it moves, and reads the moved ones after
                for s in range(G):
                    i = own + s
                    if i < M - 1:
                        yld[1, i] = max(yld[1, i], compression(x[s] - (x[s + 1] if s < G - 1 else xr1), i, pre))
                sync()
            t = t_new
            n_acc += 1

            # The stop rule (``kernels.stop.end_of_step``), from the tail granules every thread read.
            if stop_at_exit:
                out_now = False
                gap = 0.0  # the compression at which the last contact opens (``kernels.stop.pulse_has_left``)
                if PLASTIC:
                    if yld[1, M - 2] > yld[0, M - 2]:  # a yielded last contact opens at its plastic overlap (its dent)
                        gap = unloading_curve(yld[1, M - 2], yld[0, M - 2])[1] - compression(0.0, M - 2, pre)
                if wall:
                    out_now = x_m2 - x_m1 <= gap and v_m2 < 0.0
                elif x_m2 - x_m1 <= gap and v_m1 > 0.0 and v_m2 < v_m1:
                    # ``pulse_has_left``: no granule at least RATTLER_MASS_RATIO as heavy as the last outruns it.
                    blocked = 0
                    m_min = RATTLER_MASS_RATIO * m_last
                    for s in range(G):
                        i = own + s
                        if i >= lo and i < M - 1 and v[s] >= v_m1 and mass[s] >= m_min:
                            blocked = 1
                    out_now = group_any(blocked, red_b, lane) == 0
                if out_now:
                    if exit_since < 0.0:
                        exit_since = t
                    if t >= max(exit_since + exit_margin, t_needed):
                        status = SUCCESS
                else:
                    exit_since = -1.0
            if status < 0 and t == t_max:
                status = T_MAX if stop_at_exit else SUCCESS
            if status >= 0:
                break
            if VERLET:
                h = h_fixed  # (a step shortened to land on the end is not kept: ``kernels.verlet``)
            elif not FIXED:
                fac = SAFETY * max(err, 1e-10) ** -EXPONENT * err_old ** BETA
                fac = min(MAX_FACTOR, max(MIN_FACTOR, fac))
                h *= fac
                err_old = max(err, 1e-4)

        # The end of the run: the last instant is a peak candidate where a granule still speeds up, or a
        # contact still compresses (``kernels.peaks.final_peaks``, ``final_force_peaks``).
        for s in range(G):
            i = own + s
            if i < M:
                hx0[i] = x[s]
                hv0[i] = v[s]
        sync()
        spent = final_records(r, t, own, lo, M, q_of, x, v, a0, c_right, hx0, hv0, n, law, pre, yld, peak_rtol, peak_v,
                              peak_t, peak_f, peak_ft, x_out, v_out, history, spent)
        if PLASTIC:
            spent = group_sum(spent, red_w, lane)
        if lane == 0:
            status_out[r] = status
            steps_out[r] = n_acc
            rejected_out[r] = n_rej
            t_end_out[r] = t
            exit_out[r] = exit_since
            lo_out[r] = lo
            frozen_out[r] = frozen
            diss_out[r] = spent

    return kernel
