"""Ensembles of random chains: a family (:mod:`granchain.families`) and an integrator run over
realisations in chunks, each realisation's seed fixed by (seed, index) so that a result never depends
on how the work was split (:mod:`~granchain.ensembles.run`), written to a resumable store whose one
schema table drives the compute buffers, the writer, the resume check and the readers, which open
stores with :func:`~granchain.ensembles.store.open_store` (:mod:`~granchain.ensembles.store`), guarded
against two writers (:mod:`~granchain.ensembles.lock`).
"""

from .run import EnsembleSpec, default_time_grid, ensemble_integrator, run_ensemble
from .store import open_store

__all__ = ["EnsembleSpec", "default_time_grid", "ensemble_integrator", "open_store", "run_ensemble"]
