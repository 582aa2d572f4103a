"""Random decorated chains with seeds that depend only on (seed, realisation).

Realisation i uses ``SeedSequence(seed, spawn_key=(i,))``, the same stream
``SeedSequence(seed).spawn(i + 1)[i]`` gives: its radii never depend on how
the work was chunked, threaded or distributed.
"""

from __future__ import annotations

import numpy as np

from .._validate import count
from .chain import HERTZ, Chain, decorated
from .distributions import as_distribution, small_radius_distribution

__all__ = ["realization_rng", "draw_small_radii", "random_decorated"]


def realization_rng(seed: int, realization: int) -> np.random.Generator:
    """The generator of realisation ``realization`` under ``seed``."""
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(int(realization),)))


def draw_small_radii(dist, n_gaps: int, seed: int, realizations) -> np.ndarray:
    """Small radii (len(realizations), n_gaps): row i depends only on (seed, realizations[i])."""
    dist = as_distribution(dist)
    idx = np.atleast_1d(np.asarray(realizations, dtype=np.int64))
    out = np.empty((idx.size, n_gaps))
    for row, i in enumerate(idx):
        out[row] = dist.sample(realization_rng(seed, i), n_gaps)
    return out


def random_decorated(size: int, dist=None, *, seed: int = 0, realization: int = 0, n: float = HERTZ, initial_velocity: float = 1.0) -> Chain:
    """A decorated chain of ``size`` large granules with random small radii.

    Radii are i.i.d. from ``dist`` (default: the paper's U[0.01, 0.4]; any
    :class:`granchain.Uniform`, :class:`granchain.Truncated` or frozen
    scipy.stats distribution, which is truncated to (0, 1)), drawn from the
    stream of (seed, realization).
    """
    size = count("size", size, minimum=2)
    seed = count("seed", seed, minimum=0)  # a SeedSequence's entropy: a whole number >= 0
    realization = count("realization", realization, minimum=0)
    dist = small_radius_distribution(dist, stacklevel=2)
    radii = draw_small_radii(dist, size - 1, seed, [realization])[0]
    return decorated(radii, n=n, initial_velocity=initial_velocity)
