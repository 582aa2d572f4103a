"""Solving one chain: the integrators (values with capabilities, :mod:`~granchain.solve.integrators`)
and :func:`~granchain.simulate` (:mod:`~granchain.solve.simulation`), which validates, hands the chain
and the integrator to the integrator's backend (:mod:`granchain.backends`) and returns a
:class:`~granchain.PulseResult`.
"""

from .integrators import (
           DOP853,
           DP5,
           INTEGRATORS,
           RKN4,
           Integrator,
           RunControls,
           Verlet,
           get_integrator,
)
from .simulation import PulseResult, simulate

__all__ = ["DP5", "RKN4", "Verlet", "DOP853", "INTEGRATORS", "Integrator", "RunControls", "get_integrator", "PulseResult",
           "simulate"]
