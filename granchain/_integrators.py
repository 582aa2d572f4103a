"""Integrators as small frozen dataclasses plus a registry (like scipy's METHODS).

Each declares its ``name`` and convergence ``order``; the test-suite loops over
:data:`INTEGRATORS` and measures every order. All share one contract: integrate
a :class:`~granchain.Chain` from its initial state, record the peaks of the
observed granules between steps and, on request, their velocities on a grid.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ._kernels._common import power_code
from ._kernels._dp5 import dp5_integrate
from ._kernels._verlet import verlet_integrate
from ._reference import dop853_integrate
from ._validate import finite_scalar

__all__ = ["DP5", "Verlet", "DOP853", "INTEGRATORS", "get_integrator"]


def _tolerances(rtol, atol):
    rtol = finite_scalar("rtol", rtol, positive=True)
    atol = finite_scalar("atol", atol, positive=True)
    if rtol < 1e-14:
        raise ValueError(f"rtol = {rtol:g} is below what double precision can deliver; use rtol >= 1e-14")
    return rtol, atol


@dataclass(frozen=True)
class DP5:
    """Compiled adaptive Dormand-Prince 5(4), PI step control, max-norm error (the default).

    ``fixed_step`` switches step control off (used to measure the order).
    The defaults keep peak velocities and times within ~1e-7 (relative) of
    DOP853 at rtol 1e-10 on random decorated chains and their effective chains.
    """

    rtol: float = 1e-8
    atol: float = 1e-10
    first_step: float = 1e-3
    fixed_step: float | None = None

    name: ClassVar[str] = "dp5"
    order: ClassVar[int] = 5

    def __post_init__(self):
        rtol, atol = _tolerances(self.rtol, self.atol)
        object.__setattr__(self, "rtol", rtol)
        object.__setattr__(self, "atol", atol)
        finite_scalar("first_step", self.first_step, positive=True)
        if self.fixed_step is not None:
            finite_scalar("fixed_step", self.fixed_step, positive=True)

    def integrate(self, chain, x, v, *, t_grid, t_max, stop_at_exit, exit_margin, max_steps, peak_rtol):
        peak_v, peak_t, grid_v, info = _outputs(chain, t_grid)
        status = dp5_integrate(
            chain.masses, chain.stiffness, chain.n, power_code(chain.n), chain.observed,
            self.rtol, self.atol, self.first_step, self.fixed_step or 0.0, t_max, stop_at_exit,
            exit_margin, max_steps, peak_rtol, t_grid, x, v, peak_v, peak_t, grid_v, info,
        )
        return int(status), info, peak_v, peak_t, grid_v


@dataclass(frozen=True)
class Verlet:
    """Compiled fixed-step velocity Verlet (symplectic, order 2)."""

    dt: float = 1e-3

    name: ClassVar[str] = "verlet"
    order: ClassVar[int] = 2

    def __post_init__(self):
        object.__setattr__(self, "dt", finite_scalar("dt", self.dt, positive=True))

    def integrate(self, chain, x, v, *, t_grid, t_max, stop_at_exit, exit_margin, max_steps, peak_rtol):
        peak_v, peak_t, grid_v, info = _outputs(chain, t_grid)
        status = verlet_integrate(
            chain.masses, chain.stiffness, chain.n, power_code(chain.n), chain.observed,
            self.dt, t_max, stop_at_exit, exit_margin, max_steps, peak_rtol, t_grid, x, v, peak_v, peak_t, grid_v, info,
        )
        return int(status), info, peak_v, peak_t, grid_v


@dataclass(frozen=True)
class DOP853:
    """SciPy's DOP853 (order 8), the independent high-accuracy reference. Slow."""

    rtol: float = 1e-10
    atol: float = 1e-12

    name: ClassVar[str] = "dop853"
    order: ClassVar[int] = 8

    def __post_init__(self):
        rtol, atol = _tolerances(self.rtol, self.atol)
        object.__setattr__(self, "rtol", rtol)
        object.__setattr__(self, "atol", atol)

    def integrate(self, chain, x, v, *, t_grid, t_max, stop_at_exit, exit_margin, max_steps, peak_rtol):
        status, info, peak_v, peak_t, grid_v, xf, vf = dop853_integrate(
            chain.masses, chain.stiffness, chain.n, chain.observed, x.copy(), v.copy(),
            rtol=self.rtol, atol=self.atol, t_max=t_max, stop_at_exit=stop_at_exit,
            exit_margin=exit_margin, max_steps=max_steps, peak_rtol=peak_rtol, t_grid=t_grid,
        )
        x[:] = xf
        v[:] = vf
        return int(status), info, peak_v, peak_t, grid_v


def _outputs(chain, t_grid):
    k = chain.observed.size
    return np.zeros(k), np.zeros(k), np.zeros((t_grid.size, k)), np.zeros(5)  # velocities time-major


#: Registered integrators by name (the CLI's ``--integrator`` choices).
INTEGRATORS = {cls.name: cls for cls in (DP5, Verlet, DOP853)}


def get_integrator(spec=None):
    """An integrator instance from an instance, a registered name, or None (DP5 defaults)."""
    if spec is None:
        return DP5()
    if isinstance(spec, str):
        try:
            return INTEGRATORS[spec.lower()]()
        except KeyError:
            raise ValueError(f"unknown integrator {spec!r}; choose one of {sorted(INTEGRATORS)}") from None
    if hasattr(spec, "integrate") and hasattr(spec, "order"):
        return spec
    raise ValueError(f"integrator must be a name in {sorted(INTEGRATORS)} or an instance such as granchain.DP5(), got {spec!r}")
