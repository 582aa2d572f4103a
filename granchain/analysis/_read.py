"""Reading the observables of an ensemble: a Dataset as given or the store at a path, one chain of
it, and per-realisation values with failed realisations set aside.

Every Dataset function of :mod:`granchain.analysis` (and :mod:`~granchain.analysis.spacetime`) reads
through these, so a store path is opened by :func:`granchain.open_store` (which verifies it) wherever
a Dataset is accepted.
"""

from __future__ import annotations

import numpy as np


_NEEDED = ("status", "peak_velocity", "peak_time", "mean_velocity", "mean_velocity_stderr")


def _dataset(ds):
    """An ensemble Dataset as given, or the store at a path (str or os.PathLike) read with
    :func:`granchain.open_store` (records and metadata of earlier versions in today's form)."""
    import os

    if isinstance(ds, (str, os.PathLike)):
        from ..ensembles.read import open_store
        from ..ensembles.verify import StoreDamagedError

        try:
            return open_store(ds)
        except StoreDamagedError:  # a store, damaged: its own message names the chunk and the remedy
            raise
        except ValueError as exc:
            raise ValueError(f"ds = {os.fspath(ds)!r} is neither an ensemble Dataset nor a store it can read: {exc}") from None
    return ds


def _chain(ds, chain: str, need: tuple[str, ...]):
    ds = _dataset(ds)
    missing = [v for v in need if v not in ds.variables]
    if missing:
        raise ValueError(f"the Dataset lacks {missing}; expected the run_ensemble schema ({', '.join(_NEEDED)})")
    names = [str(c) for c in ds["chain"].values]
    if chain not in names:
        raise ValueError(f"chain = {chain!r} is not in the Dataset; choose one of {names}")
    return ds.sel(chain=chain)


def _valid(sub, name: str) -> np.ndarray:
    """(realization, granule) values of ``name`` with failed realisations (status != 0) as NaN."""
    values = sub[name].transpose("realization", "granule").values.astype(float)
    ok = sub["status"].transpose("realization").values == 0
    return np.where(ok[:, None], values, np.nan)
