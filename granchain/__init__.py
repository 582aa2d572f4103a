"""granchain: pulse propagation in one-dimensional granular chains.

The founding reference is U. Harbola, A. Rosas, A. H. Romero and K. Lindenberg,
"Pulse propagation in decorated random chains". Rescaled units as in its Sec. II.
"""

from ._chain import Chain, decorated, from_radii, monodisperse, regular_decorated, sphere_stiffness, tapered
from ._distributions import Truncated, Uniform, as_distribution
from ._effective import effective, effective_parameters
from ._random import draw_small_radii, random_decorated, realization_rng
from ._validate import EFFECTIVE_VALIDITY_LIMIT, EffectiveValidityWarning

__version__ = "0.1.0"

__all__ = [
    "Chain",
    "EFFECTIVE_VALIDITY_LIMIT",
    "EffectiveValidityWarning",
    "Truncated",
    "Uniform",
    "as_distribution",
    "decorated",
    "draw_small_radii",
    "effective",
    "effective_parameters",
    "from_radii",
    "monodisperse",
    "random_decorated",
    "realization_rng",
    "regular_decorated",
    "sphere_stiffness",
    "tapered",
]

from ._integrators import DOP853, DP5, INTEGRATORS, Verlet, get_integrator  # noqa: E402
from ._simulate import PulseResult, Status, default_t_max, simulate  # noqa: E402

__all__ += ["DOP853", "DP5", "INTEGRATORS", "PulseResult", "Status", "Verlet", "default_t_max", "get_integrator", "simulate"]
from ._ensemble import ENSEMBLE_ATOL, ENSEMBLE_RTOL, EnsembleSpec, default_time_grid, run_ensemble  # noqa: E402

__all__ += ["ENSEMBLE_ATOL", "ENSEMBLE_RTOL", "EnsembleSpec", "default_time_grid", "run_ensemble"]
from .units import Material, Scale, scale, to_physical  # noqa: E402  (physical units; the rest in granchain.units)
__all__ += ["Material", "Scale", "scale", "to_physical"]
