"""Ensembles of random chains: a family (:mod:`granchain.families`) and an integrator run over
realisations in chunks, each realisation's seed fixed by (seed, index) so that a result never depends
on how the work was split (:mod:`~granchain.ensembles.run`), written to a resumable store. One schema
table (:mod:`~granchain.ensembles.schema`) drives the compute buffers, the writer and the resume check
(:mod:`~granchain.ensembles.store`) and the reader every granchain reader uses
(:func:`~granchain.ensembles.read.open_store`), which verifies a store's checksums as ``granchain info``
does (:mod:`~granchain.ensembles.verify`); :mod:`~granchain.ensembles.lock` guards a store against two
writers.
"""

from .read import open_store
from .run import EnsembleSpec, default_time_grid, ensemble_integrator, family_integrator, run_ensemble
from .verify import StoreDamagedError, StoreVerificationWarning

__all__ = ["EnsembleSpec", "StoreDamagedError", "StoreVerificationWarning", "default_time_grid", "ensemble_integrator",
           "family_integrator", "open_store", "run_ensemble"]
