"""Design chains that protect: which chain, within a designer's constraints, does best.

The first paragraph of the founding paper (Harbola, Rosas, Romero, Lindenberg, "Pulse propagation in
decorated random chains") is why such chains are studied: "designer chains" that steer a pulse,
optimising its propagation or its attenuation (shock absorbers, protectors). This package asks the
inverse question of :func:`granchain.simulate`: not what a chain does to a pulse, but which chain
of a *design space* (:class:`TaperedSpace`, :class:`DecoratedSpace`, :class:`BinarySpace`,
:class:`RandomDecoratedSpace`, :class:`FunctionSpace`, with :class:`Constraints`) minimises or
maximises an *objective* (:class:`WallForce`, :class:`TransmittedEnergy`, :class:`TransmittedMomentum`,
:class:`ImpulseDuration`, :class:`ArrivalTime`, :class:`SensorForce`), found by SciPy's optimisers
(:func:`optimize`) over generations evaluated as batches of the compiled ensemble kernel
(:class:`~granchain.design.evaluate.BatchEvaluator`). The result (:class:`DesignResult`) holds the best chain, its value (with
its error bar over common random realisations for a random space), the monodisperse reference and
the history of every evaluation, resumable on disk.

    >>> from granchain import design
    >>> res = design.optimize(design.TaperedSpace(20, q=(0.0, 0.15)), "wall-force", budget=60)  # doctest: +SKIP
    >>> res.params, res.value, res.reference_value                                               # doctest: +SKIP
"""

from .evaluate import BatchEvaluator, Evaluation, default_integrator
from .function_space import FunctionSpace
from .objectives import (OBJECTIVES, ArrivalTime, ImpulseDuration, Objective, SensorForce, TransmittedEnergy,
                         TransmittedMomentum, WallForce, get_objective)
from .optimize import LOCAL_METHODS, minimum_budget, optimize
from .result import DesignResult
from .robust import RandomDecoratedSpace
from .space import BinarySpace, Constraints, DecoratedSpace, DesignSpace, TaperedSpace

__all__ = ["ArrivalTime", "BatchEvaluator", "BinarySpace", "Constraints", "DecoratedSpace", "DesignResult", "DesignSpace",
           "Evaluation", "FunctionSpace", "ImpulseDuration", "LOCAL_METHODS", "OBJECTIVES", "Objective",
           "RandomDecoratedSpace", "SensorForce", "TaperedSpace", "TransmittedEnergy", "TransmittedMomentum", "WallForce",
           "default_integrator", "get_objective", "minimum_budget", "optimize"]
