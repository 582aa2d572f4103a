"""Delete-one-group jackknife over blocks of realisations (re-exported by :mod:`granchain.analysis`).

Two kinds of groups:

* **blocks of realisations** (:func:`block_jackknife`): per-realisation data (peak times,
  peak velocities) cut into ``n_blocks`` contiguous blocks along ``realization``; the
  statistic is recomputed with each block left out.
* **chunks of a store** (:func:`chunk_jackknife`): the averaged pulse <v_k(t)> is not stored
  per realisation, only as per-chunk fixed-point sums in the store's ``progress`` group
  (:class:`ChunkSums`); the leave-one-chunk-out mean is (total - chunk) / (n - n_chunk),
  exact in integers.

Both give the jackknife standard error (Efron & Stein; Efron & Tibshirani, *An Introduction
to the Bootstrap*, Eq. 11.5)

    se = sqrt((g - 1) / g * sum_i (theta_(i) - theta_(.))^2),

with g groups and theta_(.) the mean of the leave-one-out replicates theta_(i). Because every
replicate recomputes the whole statistic (a fit over all granules, say), correlations between
granules and between the two chains of the same realisations are included.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Jackknife", "ChunkSums", "block_labels", "jackknife_stderr", "block_jackknife", "chunk_jackknife"]


def block_labels(n: int, n_blocks: int) -> np.ndarray:
    """Block index 0..n_blocks-1 of each of n items in contiguous, nearly equal blocks."""
    n, g = int(n), int(n_blocks)
    if g < 2 or n < g:
        raise ValueError(f"need 2 <= n_blocks <= n, got n_blocks = {n_blocks!r} for n = {n}")
    return (np.arange(n) * g) // n


def jackknife_stderr(replicates) -> np.ndarray:
    """sqrt((g-1)/g sum_i (theta_(i) - mean)^2) over axis 0 of the (g, ...) leave-one-out replicates."""
    r = np.asarray(replicates, dtype=float)
    g = r.shape[0]
    if g < 2:
        raise ValueError("the jackknife needs at least 2 replicates")
    return np.sqrt((g - 1) / g * np.sum((r - r.mean(axis=0)) ** 2, axis=0))


@dataclass(frozen=True, eq=False)
class Jackknife:
    """A statistic, its jackknife standard error and how it was obtained.

    ``value`` is the statistic on the whole sample (not bias-corrected); ``replicates`` the
    leave-one-group-out values, shape (groups, ...). ``method`` names the groups.
    """

    value: np.ndarray
    stderr: np.ndarray
    replicates: np.ndarray
    groups: int
    method: str


def block_jackknife(statistic, *samples, n_blocks: int = 20) -> Jackknife:
    """Jackknife of ``statistic(*samples)`` over ``n_blocks`` contiguous blocks of axis 0.

    ``samples`` are arrays sharing their first axis (realisations, e.g. the arrival times of
    the numerics and of the BCA for the same chains, so that a ratio of the two keeps their
    correlation); ``statistic`` returns a number or an array.
    """
    arrays = [np.asarray(s) for s in samples]
    n = arrays[0].shape[0]
    if any(a.shape[0] != n for a in arrays):
        raise ValueError("all samples must have the same length along axis 0 (one entry per realisation)")
    lab = block_labels(n, n_blocks)
    value = np.asarray(statistic(*arrays), dtype=float)
    reps = np.stack([np.asarray(statistic(*(a[lab != b] for a in arrays)), dtype=float) for b in range(int(n_blocks))])
    return Jackknife(value, jackknife_stderr(reps), reps, int(n_blocks),
                     f"jackknife over {int(n_blocks)} blocks of realisations")


@dataclass(frozen=True, eq=False)
class ChunkSums:
    """Per-chunk sums of v_k(t) and v_k(t)^2 over the valid realisations of each chunk.

    ``sum_v``, ``sum_v2``: int64 fixed point (chunk, chain, granule, time), value =
    integer / 2**``fixed_point_bits``; ``n_valid``: (chunk, chain). Only finished chunks
    belong here (see :meth:`from_store`). ``window_end`` (chain, granule), optional: the averaged
    pulse's windows of a run with them (the store's ``pulse_window_end``); means past them are NaN, as
    the store's ``mean_velocity`` (the sums there are not those of every realisation).
    """

    sum_v: np.ndarray
    sum_v2: np.ndarray
    n_valid: np.ndarray
    fixed_point_bits: int
    chains: tuple
    time: np.ndarray
    window_end: np.ndarray | None = None

    def __post_init__(self):
        sv, sv2, nv = (np.asarray(a) for a in (self.sum_v, self.sum_v2, self.n_valid))
        if sv.ndim != 4 or sv2.shape != sv.shape or nv.shape != sv.shape[:2]:
            raise ValueError(f"sum_v, sum_v2 must be (chunk, chain, granule, time) and n_valid (chunk, chain); "
                             f"got {sv.shape}, {sv2.shape}, {nv.shape}")
        if sv.shape[1] != len(self.chains) or sv.shape[3] != len(self.time):
            raise ValueError("chains and time must match the chain and time axes of sum_v")
        if sv.shape[0] < 2:
            raise ValueError("a jackknife over chunks needs at least 2 finished chunks")
        # mean(leave_out) by leave_out: every jackknife over these chunks asks for the same chunks + 1 means
        object.__setattr__(self, "_means", {})
        object.__setattr__(self, "_totals", None)

    @classmethod
    def from_store(cls, path) -> "ChunkSums":
        """Read the ``progress`` group of a ``run_ensemble`` Zarr store (finished chunks only;
        :func:`granchain.open_store`)."""
        from ..ensembles.read import open_store

        root = open_store(path)
        prog = open_store(path, group="progress", load=True)
        done = prog["done"].values.astype(bool)
        return cls(prog["sum_v"].values[done], prog["sum_v2"].values[done], prog["n_valid"].values[done],
                   int(root.attrs["fixed_point_bits"]), tuple(str(c) for c in root["chain"].values),
                   np.asarray(root["time"].values, dtype=float),
                   root["pulse_window_end"].values if "pulse_window_end" in root else None)

    @property
    def chunks(self) -> int:
        return int(np.asarray(self.sum_v).shape[0])

    def mean(self, leave_out: int | None = None) -> np.ndarray:
        """<v_k(t)> (chain, granule, time) over all chunks, or without chunk ``leave_out`` (read-only: computed
        once per ``leave_out`` and shared by every statistic that asks for it); NaN past the averaged
        pulse's windows (``window_end``), as the store's ``mean_velocity``."""
        key = None if leave_out is None else int(leave_out)
        if key not in self._means:
            sv, nv = np.asarray(self.sum_v), np.asarray(self.n_valid)
            if self._totals is None:  # the sums over all chunks, computed once
                object.__setattr__(self, "_totals", (sv.sum(axis=0), nv.sum(axis=0)))
            s, n = self._totals
            if key is not None:
                s, n = s - sv[key], n - nv[key]  # exact: integer arithmetic
            with np.errstate(invalid="ignore", divide="ignore"):
                m = (s.astype(float) / 2.0**self.fixed_point_bits) / n.astype(float)[:, None, None]
            m = np.where(n[:, None, None] > 0, m, np.nan)
            if self.window_end is not None:
                m[np.asarray(self.time)[None, None, :] > np.asarray(self.window_end)[:, :, None]] = np.nan
            m.setflags(write=False)
            self._means[key] = m
        return self._means[key]


def chunk_jackknife(statistic, sums: ChunkSums) -> Jackknife:
    """Jackknife of ``statistic(mean)`` over the chunks of a store.

    ``statistic`` maps a mean pulse, a dict chain -> (granule, time) array of <v_k(t)> on
    ``sums.time``, to a number or an array.
    """
    def stat(m):
        return np.asarray(statistic({c: m[i] for i, c in enumerate(sums.chains)}), dtype=float)

    value = stat(sums.mean())
    reps = np.stack([stat(sums.mean(j)) for j in range(sums.chunks)])
    return Jackknife(value, jackknife_stderr(reps), reps, sums.chunks,
                     f"jackknife over the store's {sums.chunks} chunks of realisations")
