"""granchain: pulse propagation in one-dimensional granular chains.

The founding reference is U. Harbola, A. Rosas, A. H. Romero and K. Lindenberg,
"Pulse propagation in decorated random chains". Rescaled units as in its Sec. II.
"""

from ._version import __version__
from .model.chain import Chain, decorated, from_radii, monodisperse, regular_decorated, sphere_stiffness, tapered, wall_stiffness
from .model.chainmodel import ChainModel
from .model.contacts import ElasticPlastic, PowerLaw, Precompression, Striker, Viscoelastic, Viscous
from .model.distributions import Mixture, Truncated, Uniform, as_distribution, small_radius_distribution
from .model.effective import effective, effective_parameters
from .model.random import draw_small_radii, random_decorated, realization_rng
from ._status import Status
from ._validate import EFFECTIVE_VALIDITY_LIMIT, EffectiveValidityWarning
from .solve.integrators import DOP853, DP5, INTEGRATORS, RKN4, Integrator, RunControls, Verlet, VerletStabilityWarning, get_integrator
from .solve.simulation import PulseResult, default_t_max, simulate
from .families import (
    FAMILIES,
    BinaryRandom,
    ChainFamily,
    CustomFamily,
    RandomDecorated,
    RandomRadii,
    TaperedDecorated,
    family_from_dataset,
    family_from_record,
)
from .ensembles.run import (
    DAMPED_ATOL,
    DAMPED_RTOL,
    ENSEMBLE_ATOL,
    ENSEMBLE_RTOL,
    RANDOM_ATOL,
    RANDOM_RTOL,
    SMOOTH_ATOL,
    SMOOTH_RTOL,
    EnsembleSpec,
    default_time_grid,
    ensemble_integrator,
    family_integrator,
    run_ensemble,
)
from .ensembles.read import open_store
from .units import Material, Scale, scale, to_physical  # physical units; the rest in granchain.units

__all__ = [
    "BinaryRandom",
    "Chain",
    "ChainModel",
    "ChainFamily",
    "CustomFamily",
    "DOP853",
    "DP5",
    "RKN4",
    "EFFECTIVE_VALIDITY_LIMIT",
    "DAMPED_ATOL",
    "DAMPED_RTOL",
    "ENSEMBLE_ATOL",
    "ENSEMBLE_RTOL",
    "SMOOTH_ATOL",
    "SMOOTH_RTOL",
    "RANDOM_RTOL",
    "RANDOM_ATOL",
    "EffectiveValidityWarning",
    "EnsembleSpec",
    "FAMILIES",
    "INTEGRATORS",
    "Integrator",
    "Material",
    "Mixture",
    "PowerLaw",
    "Precompression",
    "PulseResult",
    "RandomDecorated",
    "RandomRadii",
    "RunControls",
    "Scale",
    "Status",
    "Striker",
    "TaperedDecorated",
    "Truncated",
    "Uniform",
    "Verlet",
    "Viscoelastic",
    "Viscous",
    "ElasticPlastic",
    "VerletStabilityWarning",
    "__version__",
    "as_distribution",
    "decorated",
    "default_t_max",
    "default_time_grid",
    "draw_small_radii",
    "effective",
    "effective_parameters",
    "ensemble_integrator",
    "family_from_dataset",
    "family_integrator",
    "family_from_record",
    "from_radii",
    "get_integrator",
    "monodisperse",
    "open_store",
    "random_decorated",
    "realization_rng",
    "regular_decorated",
    "run_ensemble",
    "scale",
    "simulate",
    "small_radius_distribution",
    "sphere_stiffness",
    "wall_stiffness",
    "tapered",
    "to_physical",
]
#: The statistics, the paper's research and the theories load on first use (``from granchain import
#: analysis``, ``granchain.paper.validity``, ...): a run of the dynamics does not pay for SciPy's
#: fitting and statistics imports.
_LAZY_MODULES = ("analysis", "bca", "paper", "theory")
#: Moved in 0.5 (granchain.paper): still reachable as attributes, with a DeprecationWarning.
_MOVED_MODULES = ("dephasing", "figures", "validity")


def __getattr__(name):
    import importlib

    if name in _LAZY_MODULES:
        return importlib.import_module(f"{__name__}.{name}")
    if name in _MOVED_MODULES:
        import warnings

        from ._moved import MOVED

        warnings.warn(f"granchain.{name} moved to {MOVED[f'granchain.{name}']} in granchain 0.5; import it from there "
                      "(the old path will be removed)", DeprecationWarning, stacklevel=2)
        with warnings.catch_warnings():  # warned here, where the caller is
            warnings.simplefilter("ignore", DeprecationWarning)
            return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY_MODULES))
