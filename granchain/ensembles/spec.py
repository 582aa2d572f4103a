"""What determines an ensemble's result: :class:`EnsembleSpec` (validated, recorded with the store and
compared on resume) and the defaults it fills in (each chain kind's integrator, the time grid).

A spec is a value: two runs with equal specs compute bitwise equal results, whatever the number of
threads, the chunks' order or the machine (:mod:`granchain.ensembles.run` runs one;
:mod:`granchain.ensembles.chunks` computes one chunk of it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .._validate import count
from .._version import RESULTS_VERSION
from ..families import ChainFamily, RandomDecorated
from ..solve.defaults import LIGHT_GRANULES, REFLECTING, SMOOTH, default_integrator
from ..solve.integrators import Integrator, RunControls, get_integrator
from . import backend as _backend
from . import pulse_window as _window
from .pulse_window import AUTO, FULL

__all__ = ["EnsembleSpec", "default_time_grid", "ensemble_integrator", "family_integrator"]

def ensemble_integrator(chain: str = "decorated", *, conservative: bool = True, windowed: bool = True) -> Integrator:
    """The default integrator of :class:`RandomDecorated`'s chain kinds by name: "decorated" chains are
    :data:`~granchain.solve.defaults.LIGHT_GRANULES`, "effective" ones
    :data:`~granchain.solve.defaults.SMOOTH`, and any other name
    :data:`~granchain.solve.defaults.REFLECTING` (:func:`granchain.solve.defaults.default_integrator`:
    ``RKN4.windowed()`` at :data:`ENSEMBLE_RTOL`, :meth:`DP5.windowed` at :data:`SMOOTH_RTOL`, ``DP5`` at
    :data:`RANDOM_RTOL`; ``DP5.relaxed`` at :data:`DAMPED_RTOL` for decorated chains whose contacts are not
    ``conservative``). An ensemble asks its family instead (:meth:`ChainFamily.character`), which
    knows what its chains are like whatever their names. ``windowed``: the trailing window (False:
    ``relaxed``, every granule integrated to the end of the time grid)."""
    character = {"decorated": LIGHT_GRANULES, "effective": SMOOTH}.get(chain, REFLECTING)
    return default_integrator(character, conservative=conservative, windowed=windowed)


def family_integrator(family: ChainFamily, chain: str, *, windowed: bool = True, method: type | None = None) -> Integrator:
    """The integrator the family's ``chain`` kind is integrated with unless one is given: that of its
    character (:meth:`ChainFamily.character`, :func:`granchain.solve.defaults.default_integrator`), for the
    family's contacts; ``method``: another adaptive Runge-Kutta class at the character's settings."""
    return default_integrator(family.character(chain), conservative=family.model.conservative, windowed=windowed,
                              method=method)


def default_time_grid(family=26, dt: float = 0.1) -> np.ndarray:
    """Grid for <v_k(t)> of a family (or of ``RandomDecorated(family)`` for a number N of large
    granules: to 1.1 x the BCA arrival time at granule N, slope 2.35 per granule, + 10)."""
    if not isinstance(family, ChainFamily):
        family = RandomDecorated(family)
    return family.default_time_grid(dt)


def _fixed_point_bits(realizations: int, vmax: float = 2.0) -> int:
    """Bits after the binary point so that sums of v^2 over all realisations fit in int64."""
    return int(min(40, math.floor(math.log2(2.0**62 / (realizations * vmax * vmax)))))


@dataclass(frozen=True)
class EnsembleSpec:
    """Every parameter that determines an ensemble's result (validated)."""

    family: ChainFamily
    realizations: int = 1000
    seed: int = 0
    chains: tuple = ("both",)
    integrator: Integrator | None = None
    t_grid: np.ndarray = field(default=None, repr=False)
    #: Realisations per chunk; None: the backend's ``default_chunk_size`` (500 on the CPU).
    chunk_size: int | None = None
    controls: RunControls = field(default_factory=RunControls)
    lags: np.ndarray = field(default=None, repr=False)
    #: {chain kind: Integrator}; filled from ``integrator`` (one for all kinds) or, without one, from
    #: each kind's :func:`family_integrator` (the default of its character). Given explicitly, it wins over ``integrator``.
    chain_integrators: dict | None = None
    #: "auto": each observed granule's averaged pulse in a window of its own, for the chain kinds whose
    #: integrator runs a trailing window (the defaults; :mod:`granchain.ensembles.pulse_window`); "full":
    #: the whole time grid (default integrators without the trailing window: the wake included).
    pulse_window: str = "auto"
    #: {chain kind: window ends (K,)} once set (``pulse_window.window_ends``, or a store's record); None before.
    pulse_ends: dict | None = field(default=None, repr=False)
    #: What computes the chunks: None (or "cpu"): each integrator's own backend; a backend's name ("cuda",
    #: "numba") or a ``granchain.backends.Backend``: its ``integrate_batch`` (``granchain.ensembles.backend``).
    backend: object = None
    #: Every backend that computed the store's chunks, in the order first used (``run_ensemble(
    #: switch_backend=True)``; the record's ``"backend"`` is the first); None: ``backend`` alone.
    backends_used: tuple | None = None

    def __post_init__(self):
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731
        if not isinstance(self.family, ChainFamily):
            raise ValueError(f"family must be a granchain chain family (e.g. granchain.RandomDecorated(26)), got {self.family!r}")
        set_("realizations", count("realizations", self.realizations, minimum=1))
        set_("seed", count("seed", self.seed, minimum=0))
        known = self.family.chains
        chains = (self.chains,) if isinstance(self.chains, str) else tuple(self.chains)
        if chains in (("both",), ("all",)):
            chains = known
        if not chains or any(c not in known for c in chains) or len(set(chains)) != len(chains):
            raise ValueError(f"chains must be one or more of {list(known)} (or 'both'), got {self.chains!r}")
        set_("chains", tuple(c for c in known if c in chains))
        if self.pulse_window not in (AUTO, FULL):
            raise ValueError(f"pulse_window must be {AUTO!r} (each granule's averaged pulse in a window of its own, the "
                             f"trailing window on: cost linear in N) or {FULL!r} (the whole time grid, the wake behind "
                             f"the pulse included), got {self.pulse_window!r}")
        # One integrator for every chain kind when one is given; else each kind's default.
        if self.chain_integrators is not None:
            # A dict may name kinds the family has but this run does not compute (one dict for runs of
            # "decorated", "effective" or both); a kind the family does not have is a typo, and a kind
            # the run computes needs its integrator.
            if not isinstance(self.chain_integrators, dict):
                raise ValueError(f"chain_integrators must be a dict {{chain kind: integrator}}, got {self.chain_integrators!r}")
            unknown = sorted(set(self.chain_integrators) - set(known))
            if unknown:
                raise ValueError(f"the integrator dict names chain kinds {unknown} that the family {type(self.family).__name__} does not "
                                 f"have; its kinds are {list(known)}")
            missing = [c for c in self.chains if c not in self.chain_integrators]
            if missing:
                raise ValueError(f"the integrator dict has no integrator for the chain kinds {missing} this run computes "
                                 f"(it names {sorted(self.chain_integrators)}); add them, or pass one integrator for all")
            per_chain = {c: get_integrator(self.chain_integrators[c]) for c in self.chains}
        else:
            given = self.integrator
            windowed = self.pulse_window == AUTO
            per_chain = {c: (get_integrator(given) if given is not None else family_integrator(self.family, c, windowed=windowed))
                         for c in self.chains}
            # A backend that defaults to fewer methods (the GPU: RKN4, the one measured there) gets the
            # light-granule chains' default, RKN4, for the kinds whose default it does not: valid for every
            # elastic chain. Contacts that dissipate keep each kind's own default (DP5 at its tolerances: RKN4
            # cannot integrate them, and the light-granule chains' DP5 is looser than the smooth chains').
            methods = _backend.default_methods(_backend.resolve(_backend.checked(self.backend)))
            if given is None and methods is not None:
                fallback = default_integrator(LIGHT_GRANULES, conservative=self.family.model.conservative, windowed=windowed)
                if fallback.name in methods:
                    per_chain = {c: (i if i.name in methods else fallback) for c, i in per_chain.items()}
        law = self.family.contact_law
        for c, integ in per_chain.items():  # refused here, before a store exists
            integ.check_law(law, "the family's contact law", " (the default for it)")
        set_("integrator", per_chain[self.chains[0]])
        set_("chain_integrators", per_chain)
        grid = self.family.default_time_grid() if self.t_grid is None else np.asarray(self.t_grid, dtype=float).reshape(-1)
        if grid.size == 0 or not np.all(np.isfinite(grid)) or grid[0] < 0 or np.any(np.diff(grid) <= 0):
            raise ValueError("t_grid must be a non-empty, finite, increasing array of times >= 0")
        grid = np.array(grid)
        grid.setflags(write=False)
        set_("t_grid", grid)
        set_("pulse_ends", self._checked_pulse_ends())
        set_("backend", _backend.checked(self.backend))
        if self.backends_used is not None:
            used = tuple(self.backends_used) if isinstance(self.backends_used, (tuple, list)) else ()
            if not used or not all(isinstance(u, str) and u for u in used):
                raise ValueError(f"backends_used must list the names of the backends that computed the store, in the "
                                 f"order first used (e.g. ('cpu', 'cuda')), got {self.backends_used!r}")
            set_("backends_used", used)
        if self.chunk_size is None:
            set_("chunk_size", _backend.default_chunk_size(self.backend))
        set_("chunk_size", count("chunk_size", self.chunk_size, minimum=1))
        if not isinstance(self.controls, RunControls):
            raise ValueError(f"controls must be a granchain.RunControls, got {self.controls!r}")
        if self.lags is not None:  # the aligned pulse (granchain.backends.kernels.aligned); None: not accumulated
            lags = np.array(np.asarray(self.lags, dtype=float).reshape(-1))
            if lags.size == 0 or not np.all(np.isfinite(lags)) or np.any(np.diff(lags) <= 0):
                raise ValueError("lags must be a non-empty, finite, increasing array of times relative to each "
                                 "realisation's peak (e.g. numpy.arange(-10, 10.05, 0.1)), or None")
            lags.setflags(write=False)
            set_("lags", lags)

    def _checked_pulse_ends(self) -> dict | None:
        """The averaged-pulse windows as given (a dict per chain kind that gets one), or None where the run has
        none (``pulse_window="full"``, or no integrator with a trailing window)."""
        kinds = _window.applies(self) if self.pulse_window == AUTO else {}
        if not kinds or self.pulse_ends is None:
            return None
        if set(self.pulse_ends) != set(kinds):
            raise ValueError(f"pulse_ends must give the windows of the chain kinds {sorted(kinds)}, got {sorted(self.pulse_ends)}")
        K = self.family.n_observed
        ends = {}
        for kind, e in self.pulse_ends.items():
            e = np.array([np.inf if x is None else x for x in np.ravel(np.asarray(e, dtype=object))], dtype=float)
            if np.any(np.isnan(e)) or e.size != K:
                raise ValueError(f"the averaged-pulse window ends of the {kind} chains must be {K} times (inf: none), got {e!r}")
            e.setflags(write=False)
            ends[kind] = e
        return ends

    @property
    def has_pulse_windows(self) -> bool:
        """True when some chain kind of this run gets averaged-pulse windows (set or still to set)."""
        return self.pulse_window == AUTO and bool(_window.applies(self))

    def _other_integrators(self) -> dict:
        """``{"chain_integrators": {kind: record}}`` when the chain kinds are not all integrated by
        ``integrator`` (the default since granchain 0.3), else nothing (the record of earlier stores)."""
        records = {c: integ.describe() for c, integ in self.chain_integrators.items()}
        if all(r == self.integrator.describe() for r in records.values()):
            return {}
        return {"chain_integrators": records}

    @property
    def n_chunks(self) -> int:
        return -(-self.realizations // self.chunk_size)

    def chunk_slice(self, j: int) -> slice:
        return slice(j * self.chunk_size, min((j + 1) * self.chunk_size, self.realizations))

    @property
    def fixed_point_bits(self) -> int:
        return _fixed_point_bits(self.realizations)

    def describe(self) -> dict:
        """JSON-able record of the parameters (stored with the results, compared on resume)."""
        record = {
            "family": self.family.describe(),
            "realizations": self.realizations,
            "seed": self.seed,
            "chains": list(self.chains),
            "integrator": self.integrator.describe(),
            **self._other_integrators(),
            "t_grid": {"start": float(self.t_grid[0]), "stop": float(self.t_grid[-1]), "size": int(self.t_grid.size),
                       "checksum": float(np.sum(self.t_grid * np.arange(1, self.t_grid.size + 1)))},
            "chunk_size": self.chunk_size,
            "exit_margin": self.controls.exit_margin,
            "peak_rtol": self.controls.peak_rtol,
            "max_steps": self.controls.max_steps,
            "results_version": RESULTS_VERSION,  # not the package version: an upgrade that computes the same numbers resumes
        }
        used = list(self.backends_used or (_backend.name_of(self.backend),))
        if used[0] != _backend.CPU:  # only then: a store of the CPU default keeps the record of earlier versions
            record["backend"] = used[0]
        if len(used) > 1:  # the run's history (not compared on resume, not in the checksums' key)
            record["backends_used"] = used
        if self.has_pulse_windows:  # only then: a run without windows keeps the record of earlier versions
            record["pulse_window"] = _window.record(self)
        if self.lags is not None:  # only then: stores without the aligned pulse keep their 0.1/0.2 record
            record["lags"] = {"start": float(self.lags[0]), "stop": float(self.lags[-1]), "size": int(self.lags.size),
                              "checksum": float(np.sum(self.lags * np.arange(1, self.lags.size + 1)))}
        return record
