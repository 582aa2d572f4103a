"""The history of a design run: every evaluation, on disk as an xarray Dataset, resumable.

The optimisers are deterministic for a seed: run again, they ask for the same designs in the same
order. So the history is also a cache: a design already evaluated is looked up (by the exact bytes
of its parameter vector) instead of integrated, and an interrupted run started again with the same
arguments replays its finished evaluations in no time and continues where it stopped; its result
is the uninterrupted run's. The store is a Zarr group (``DIR/history.zarr``) appended after a batch
(at most every :data:`FLUSH_SECONDS`, and at the end); its ``evaluations_done`` attribute is written after the arrays, so a batch cut off while
being written is simply done again. A store written with other arguments is refused, naming the
difference.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
from typing import ClassVar

import numpy as np

from .._version import __version__

__all__ = ["History"]

_RECORD = "granchain_design"

#: Seconds between appends to the store: an append costs ~0.1 s, a local refinement's evaluation
#: a few milliseconds, so appending after each would spend the run writing.
FLUSH_SECONDS = 5.0


class History:
    """Evaluations so far (in memory, and in ``path`` if given); ``record`` names the run."""

    def __init__(self, names: tuple, record: dict, path=None, resume: bool = True):
        self.names, self.record, self.path = tuple(names), record, None if path is None else os.fspath(path)
        self.x = np.zeros((0, len(self.names)))
        self.value = np.zeros(0)
        self.stderr = np.zeros(0)
        self.failed = np.zeros(0, dtype=np.int64)
        self.stage = np.zeros(0, dtype=np.int8)
        self.cache: dict = {}
        self.replayed = 0
        self.written = 0
        self._last = 0.0
        if self.path is not None and os.path.exists(self.path):
            if not resume:
                raise ValueError(f"{self.path} already holds a design run; pass resume=True to continue it, or choose another directory")
            self._load()

    # -- disk ---------------------------------------------------------------------------
    def _load(self) -> None:
        import zarr  # the history is no ensemble store (granchain.open_store reads those): its arrays directly

        group = zarr.open_group(self.path, mode="r")
        # (the backends used are the run's history, checked by optimize: a run continued on another one adds its own)
        stored = json.loads(group.attrs.get(_RECORD, "{}"))
        old = {k: v for k, v in stored.items() if k != "backends_used"}
        new = {k: v for k, v in json.loads(json.dumps(self.record)).items() if k != "backends_used"}
        if old != new:
            diff = sorted(k for k in set(old) | set(new) if old.get(k) != new.get(k))
            raise ValueError(f"{self.path} holds a design run with other arguments (they differ in {diff}); start it with the "
                             "same arguments to continue it, or choose another directory")
        if stored.get("backends_used") != self.record.get("backends_used"):  # recorded now, new evaluations or not
            zarr.open_group(self.path, mode="r+").attrs[_RECORD] = json.dumps(self.record)
        done = int(group.attrs.get("evaluations_done", 0))
        x = np.asarray(group["params"][:done], dtype=float)
        for row, v, s, f in zip(x, group["value"][:done], group["stderr"][:done], group["failed"][:done]):
            self.cache[row.tobytes()] = (float(v), float(s), int(f))
        self.written = done

    def _dataset(self, sl: slice):
        import xarray as xr

        ds = xr.Dataset(
            {"params": (("evaluation", "parameter"), self.x[sl], {"long_name": "design parameters", "units": "1"}),
             "value": ("evaluation", self.value[sl], {"long_name": "objective (NaN: infeasible or failed)", "units": "1"}),
             "stderr": ("evaluation", self.stderr[sl], {"long_name": "standard error over the realisations (NaN: deterministic)",
                                                       "units": "1"}),
             "failed": ("evaluation", self.failed[sl], {"long_name": "failed integrations of the design", "units": "1"}),
             "stage": ("evaluation", self.stage[sl], {"long_name": "stage of the search", "units": "1",
                                                     "flag_values": [0, 1], "flag_meanings": "global local"})},
            coords={"parameter": np.array(self.names, dtype=object)})
        return ds

    def dataset(self):
        """Every evaluation of this run as an xarray Dataset (dims ``evaluation``, ``parameter``)."""
        ds = self._dataset(slice(None))
        ds = ds.assign_coords(evaluation=np.arange(1, ds.sizes["evaluation"] + 1))
        ds.attrs.update({_RECORD: json.dumps(self.record), "granchain_version": __version__})
        return ds

    def flush(self, force: bool = True) -> None:
        """Append the evaluations not yet on disk (then mark them done); unless ``force``, only when
        :data:`FLUSH_SECONDS` have passed since the last append."""
        import time

        if self.path is None or self.x.shape[0] <= self.written:
            return
        if not force and time.monotonic() - self._last < FLUSH_SECONDS:
            return
        self._last = time.monotonic()
        import zarr

        new = self._dataset(slice(self.written, None))
        new.attrs.update({_RECORD: json.dumps(self.record), "granchain_version": __version__, "evaluations_done": self.written})
        if self.written == 0:
            new.attrs["created"] = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
            new.to_zarr(self.path, mode="w", consolidated=False)
        else:
            group = zarr.open_group(self.path, mode="r+")
            stored = group["value"].shape[0]
            if stored != self.written:  # an append cut off before it was marked done: drop its rows
                for name in ("params", "value", "stderr", "failed", "stage"):
                    arr = group[name]
                    arr.resize((self.written,) + arr.shape[1:])
            new.to_zarr(self.path, append_dim="evaluation", consolidated=False)
        self.written = self.x.shape[0]
        zarr.open_group(self.path, mode="r+").attrs.update({"evaluations_done": self.written, _RECORD: json.dumps(self.record)})

    # -- evaluations ----------------------------------------------------------------------
    def lookup(self, X: np.ndarray):
        """(found (P,) bool, value, stderr, failed) of designs already evaluated by this run (or the interrupted one)."""
        P = X.shape[0]
        found = np.zeros(P, dtype=bool)
        value, stderr, failed = np.full(P, np.nan), np.full(P, np.nan), np.zeros(P, dtype=np.int64)
        for i, row in enumerate(X):
            hit = self.cache.get(np.ascontiguousarray(row, dtype=float).tobytes())
            if hit is not None:
                found[i] = True
                value[i], stderr[i], failed[i] = hit
        return found, value, stderr, failed

    #: Stage codes of the ``stage`` variable.
    STAGES: ClassVar[dict] = {"global": 0, "local": 1}

    def add(self, X, value, stderr, failed, stage: str) -> None:
        X = np.asarray(X, dtype=float)
        self.x = np.concatenate((self.x, X))
        self.value = np.concatenate((self.value, value))
        self.stderr = np.concatenate((self.stderr, stderr))
        self.failed = np.concatenate((self.failed, failed))
        self.stage = np.concatenate((self.stage, np.full(X.shape[0], self.STAGES[stage], dtype=np.int8)))
        for row, v, s, f in zip(X, value, stderr, failed):
            self.cache[np.ascontiguousarray(row).tobytes()] = (float(v), float(s), int(f))

    @property
    def count(self) -> int:
        return int(self.x.shape[0])
