"""How a chain's threads share a step on the GPU: the reductions over a group of ``L`` threads, the
neighbours' positions for the contact forces and the trailing window's cut candidates, by warp shuffles
(one warp per chain) or through shared memory and barriers. Device functions compiled for a layout
(:func:`make_exchange`), which the step loop (``kernel.make_kernel``) calls; its docstring says which
barriers they need and why a chain is a group of threads.
"""

from __future__ import annotations

from collections import namedtuple

from numba import cuda, int64

from ..kernels.window import CUT_FORCE
from .device import FULL_MASK, compression, contact_force, dynamic, elastic_force, law_force, law_power, warp_any, warp_last

#: The device functions of a layout, by name.
Exchange = namedtuple("Exchange", ["sync", "group_max", "group_any", "group_last", "group_sum", "right_neighbour",
                                   "forces", "cut_candidates"])


def make_exchange(L: int, G: int, shuffle: bool, votes: bool, damped: bool = False) -> Exchange:
    """The exchange device functions for ``L`` threads per chain and ``G`` granules per thread (constants of
    their code: ``L = 1`` has no barriers), by warp shuffles (``shuffle``, ``L`` = 32) or shared memory, with
    the integer reductions by warp votes (``votes``, with ``shuffle``) or by maxima; ``damped``: forces that
    read the velocities too (the stage exchange's shared arrays then hold 2 L G values: positions, then
    velocities)."""
    GROUP = L > 1
    DAMPED = bool(damped)
    MMAX = L * G
    SHUFFLE = bool(shuffle)
    VOTES = SHUFFLE and bool(votes)

    @cuda.jit(device=True)
    def sync():
        if GROUP:
            cuda.syncthreads()

    @cuda.jit(device=True)
    def group_max(value, red, lane):
        """The maximum of ``value`` over the group's threads (every thread gets it)."""
        if SHUFFLE:
            off = 16
            while off > 0:
                value = max(value, cuda.shfl_xor_sync(FULL_MASK, value, off))
                off //= 2
            return value
        red[lane] = value
        sync()
        m = red[0]
        for l in range(1, L):
            m = max(m, red[l])
        return m

    @cuda.jit(device=True)
    def group_any(flag, red, lane):
        """1 where ``flag`` (0 or 1) is 1 on any thread of the group, else 0 (every thread gets it)."""
        if VOTES:
            return warp_any(flag)
        return group_max(flag, red, lane)

    @cuda.jit(device=True)
    def group_last(value, red, lane):
        """The maximum over the group of ``value``, which is -1 or grows with the lane (an index of one of the
        thread's own granules or observed granules): with votes, the value of the last lane that has one."""
        if VOTES:
            return warp_last(value)
        return group_max(value, red, lane)

    @cuda.jit(device=True)
    def group_sum(value, red, lane):
        """The sum of ``value`` over the group's threads, in an order fixed by the layout (deterministic)."""
        if SHUFFLE:
            off = 16
            while off > 0:
                value += cuda.shfl_xor_sync(FULL_MASK, value, off)
                off //= 2
            return value
        red[lane] = value
        sync()
        total = 0.0
        for l in range(L):
            total += red[l]
        return total

    @cuda.jit(device=True)
    def right_neighbour(values, own, M, shared):
        """The value of granule own + G (the right neighbour of this thread's last granule; 0 past the chain):
        from the next thread by a shuffle, or from ``shared`` (written, and a barrier passed, before)."""
        if SHUFFLE:
            return cuda.shfl_down_sync(FULL_MASK, values[0], 1)
        j = own + G
        return shared[j] if j < M else 0.0

    @cuda.jit(device=True)
    def forces(xs, us, own, M, lo, bx, c_left, c_right, inv_m, law, acc, pre, yld):
        """acc[s] = the acceleration of owned granule s at the positions ``xs``: every thread of the group
        calls it (the positions cross thread boundaries through ``bx``, or by shuffles). Granules behind the
        trailing window (i < lo) are not integrated (acceleration 0: they continue ballistically) and the
        contact at its edge is dropped (``kernels.window``). ``law``: the contacts' (n, gamma, viscous, clamp);
        ``pre``: the static state of a precompressed chain (``device.compression``; None: unloaded), whose contacts
        exert their dynamic force, 0 in the static state (``kernels.forces.accelerations``); ``yld``: yielding
        contacts' yield overlaps and histories (``device.elastic_force``: Thornton's force), or None.

        ``damped`` (a constant of the code): the forces of a damped law (``device.law_force``) read the stage
        velocities ``us`` too (through ``bx[MMAX:]``, or by shuffles), and the function returns this thread's
        share of the power the contacts take from the motion (its granules' right contacts from the window's
        start on: ``kernels.forces.accelerations``); elastic, it reads no velocities and returns 0."""
        n = law[0]
        ul = 0.0
        ur = 0.0
        if SHUFFLE:
            xl = cuda.shfl_up_sync(FULL_MASK, xs[G - 1], 1)
            xr = cuda.shfl_down_sync(FULL_MASK, xs[0], 1)
            if DAMPED:
                ul = cuda.shfl_up_sync(FULL_MASK, us[G - 1], 1)
                ur = cuda.shfl_down_sync(FULL_MASK, us[0], 1)
        else:
            for s in range(G):
                i = own + s
                if i < M:
                    bx[i] = xs[s]
                    if DAMPED:
                        bx[MMAX + i] = us[s]
            sync()
        power = 0.0
        for s in range(G):
            i = own + s
            if i < M:
                left = 0.0
                right = 0.0
                if DAMPED:
                    if SHUFFLE:
                        x_left = xs[s - 1] if s > 0 else xl
                        u_left = us[s - 1] if s > 0 else ul
                        x_right = xs[s + 1] if s < G - 1 else xr
                        u_right = us[s + 1] if s < G - 1 else ur
                    else:
                        x_left = bx[i - 1] if i > 0 else 0.0
                        u_left = bx[MMAX + i - 1] if i > 0 else 0.0
                        x_right = bx[i + 1] if i < M - 1 else 0.0
                        u_right = bx[MMAX + i + 1] if i < M - 1 else 0.0
                    if i > lo:
                        d = compression(x_left - xs[s], i - 1, pre)
                        left = dynamic(law_force(d, u_left - us[s], c_left[s], law), i - 1, pre)
                    if i < M - 1:
                        d = compression(xs[s] - x_right, i, pre)
                        w = us[s] - u_right
                        right = law_force(d, w, c_right[s], law)
                        if i >= lo:
                            power += law_power(d, w, right, c_right[s], law)
                        right = dynamic(right, i, pre)
                elif SHUFFLE:
                    if i > lo:
                        left = dynamic(elastic_force(compression((xs[s - 1] if s > 0 else xl) - xs[s], i - 1, pre), i - 1,
                                                     c_left[s], n, yld), i - 1, pre)
                    if i < M - 1:
                        right = dynamic(elastic_force(compression(xs[s] - (xs[s + 1] if s < G - 1 else xr), i, pre), i,
                                                      c_right[s], n, yld), i, pre)
                else:
                    if i > lo:
                        left = dynamic(elastic_force(compression(bx[i - 1] - xs[s], i - 1, pre), i - 1, c_left[s], n, yld),
                                       i - 1, pre)
                    if i < M - 1:
                        right = dynamic(elastic_force(compression(xs[s] - bx[i + 1], i, pre), i, c_right[s], n, yld), i, pre)
                acc[s] = (left - right) * inv_m[s] if i >= lo else 0.0
        return power

    @cuda.jit(device=True)
    def cut_candidates(target, own, lo, M, xs, xr, c_right, n):
        """This thread's share of ``kernels.window.open_contact_behind``: the last open contact j in
        lo..target-1 among its own (the new positions ``xs``; ``xr`` the right neighbour of its last granule),
        and the last one holding less than CUT_FORCE (-1: none)."""
        j_open = int64(-1)
        j_weak = int64(-1)
        for s in range(G):
            i = own + s
            if i >= lo and i < target and i < M - 1:
                d = xs[s] - (xs[s + 1] if s < G - 1 else xr)
                if d <= 0.0:
                    j_open = max(j_open, i)
                elif contact_force(d, c_right[s], n) <= CUT_FORCE:
                    j_weak = max(j_weak, i)
        return j_open, j_weak

    return Exchange(sync, group_max, group_any, group_last, group_sum, right_neighbour, forces, cut_candidates)
