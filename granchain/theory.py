"""A predictive theory of the pulse in a random decorated chain, from the small-radius law alone.

The averaged pulse max_t <v_k(t)> decays mostly by dephasing of realisations, and the mean
single-realisation peak <max_t v_k> by a solitary wave crossing random contact stiffnesses
(:mod:`granchain.paper.dephasing`). Both need the joint law of each realisation's peaks P_k and peak
times t_k. This module predicts that law without integrating the chain:

1. **Effective chain** (paper Eqs. renorm-mass, effec-int, zetak): small radius R_j gives the
   contact stiffness c_j = r(R_j) / 2^(n-1), r(R) = sqrt(2R / (1 + R)), and the masses
   mu_k = 1 + (R_{k-1}^3 + R_k^3) / 2. Contacts are i.i.d.

2. **Windowed transfer map.** The step from granule j to j + 1 changes the peak by the gain
   G_j = P_{j+1} / P_j and takes the time dt_j = t_{j+1} - t_j. Both are taken from a short chain
   holding only the contacts j - a .. j + b (a = ``memory`` behind, b = ``lookahead`` ahead), fed
   by a uniform lead-in (``LEAD_IN`` contacts of stiffness c_{j-a}: a formed solitary wave
   arrives) and closed by a uniform tail of c_{j+b}. The Hertz chain's scaling symmetry (a
   solitary wave of amplitude v keeps its width in granules and has the time scale
   v^(-(n-2)/n) c^(-1/n); Nesterenko 1983) makes G_j independent of the incoming amplitude and
   dt_j P_j^((n-2)/n) a function of the window alone. Near the struck end (j < a) the window
   starts at the struck granule itself (pulse formation treated explicitly); the last step
   (j = N - 1) has the real free end. The slow end of the formation (the solitary wave's
   amplitude still settles for ~10 granules, 0.690 -> 0.682 in a monodisperse chain) is a
   factor from one monodisperse chain (:func:`formation_factors`).

3. **Quadrature of the disorder.** Each contact's x = log r(R) is replaced by a Q-point Gauss
   quadrature of its law (nodes x_q, weights w_q; Golub & Welsch 1969, by the Stieltjes
   procedure on a fine quantile grid, :func:`stiffness_quadrature`), so the map is a finite
   table over Q^(a+b+1) windows, tabulated once per law by short-chain simulations
   (:func:`transfer_table`, cached in memory and on disk).

4. **Markov composition.** Drawing node sequences (q_1, ..., q_{N-1}) with weights w and composing
   log P_{j+1} = log P_j + log G_j, t_{j+1} = t_j + dt_j is a Markov chain over (amplitude, window)
   — the window of recent contacts is the pulse's "shape" state — whose samples carry the
   correlations of P_k and t_k. No chain is integrated.

5. **Averaged pulse** by the dephasing convolution (:mod:`granchain.paper.dephasing`, Eq. 1):
   <v_k(t)> = <P_k S((t - t_k) / s_k)>, S the monodisperse solitary wave's time profile and s_k
   each sample's local time scale (its steps into and out of k against the monodisperse step).

Derivations, validation against ensembles and the model's limits:
docs/explanation/pulse-decay-theory.md.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import time
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ._cache import user_cache_dir
from ._validate import count, exponent
from ._version import __version__
from .model.chain import HERTZ
from .model.distributions import small_radius_distribution
from .model.effective import effective_parameters
from .units import rescaled_attrs

__all__ = ["TheorySettings", "TransferTable", "stiffness_quadrature", "transfer_table", "formation_factors",
           "aligned_profiles", "sample_pulses", "averaged_pulse", "predict", "clear_cache", "cache_dir"]

#: Contacts of the uniform lead-in that forms the incoming solitary wave (its amplitude is then
#: within 1e-4 of the monodisperse solitary wave's) and of the uniform tail ahead of a window.
LEAD_IN = 12
TAIL = 6
#: Integration tolerances of the short chains (DP5): log gains and steps within ~2e-6 of rtol 1e-8
#: (measured on 2233 windows of U[0.01, 0.4]), 25 steps then ~5e-5, far below the model's own error;
#: 1e-8 costs 1.8x the time.
RTOL, ATOL = 1e-6, 1e-9
#: Table format; bump when the tabulation changes so stale disk caches are not read.
TABLE_VERSION = 1


@dataclass(frozen=True)
class TheorySettings:
    """The model's numerical settings (recorded in every prediction's attributes).

    ``memory`` a: contacts behind the step kept in a window; ``lookahead`` b: contacts ahead;
    ``nodes`` Q: quadrature nodes per contact (tables hold Q^(a+b+1) windows);
    ``stiffness_disorder``: False replaces every contact's stiffness by the law's median one
    while the masses stay random (the negative control: the model then cannot decay).
    """

    memory: int = 4
    lookahead: int = 1
    nodes: int = 5
    n: float = HERTZ
    stiffness_disorder: bool = True

    def __post_init__(self):
        object.__setattr__(self, "memory", count("memory", self.memory, minimum=1))
        object.__setattr__(self, "lookahead", count("lookahead", self.lookahead, minimum=1))
        object.__setattr__(self, "nodes", count("nodes", self.nodes, minimum=1))
        object.__setattr__(self, "n", exponent(self.n, minimum=2.0, why="a solitary pulse exists only for n > 2 "
                                               "(Nesterenko); the theory's scaling v^(-(n-2)/n) needs it"))
        if self.nodes ** (self.memory + self.lookahead + 1) > 400_000:
            raise ValueError(f"nodes^(memory + lookahead + 1) = {self.nodes}^{self.memory + self.lookahead + 1} short chains "
                             "per table is too many: lower nodes or memory (defaults 5 and 4)")


# --------------------------------------------------------------------------- effective chain
def stiffness_of_radius(R, n: float = HERTZ):
    """Effective contact stiffness r(R) / 2^(n-1), r = sqrt(2R / (1 + R)) (paper Eqs. effec-int, zetak)."""
    R = np.asarray(R, dtype=float)
    return np.sqrt(2.0 * R / (1.0 + R)) * 2.0 ** -(n - 1.0)


def radius_of_log_r(x):
    """Inverse of x = log r(R): r^2 (1 + R) = 2R, so R = r^2 / (2 - r^2)."""
    r2 = np.exp(2.0 * np.asarray(x, dtype=float))
    return r2 / (2.0 - r2)


def stiffness_quadrature(distribution, nodes: int, fine: int = 20_000) -> tuple[np.ndarray, np.ndarray]:
    """(radii R_q, weights w_q) of a ``nodes``-point Gauss quadrature of x = log r(R).

    Nodes and weights of the Gauss rule of the law of x (exact for polynomials in x of degree
    < 2 ``nodes``; Golub & Welsch, Math. Comp. 23, 221 (1969)), from the Jacobi matrix that the
    Stieltjes procedure builds on ``fine`` equiprobable quantiles of R. log r is the variable
    the scaling symmetry singles out (a uniform stiffness factor only rescales time), and the
    rule reaches into the weak-contact tail that dominates the scattering.
    """
    u = (np.arange(fine) + 0.5) / fine
    x = np.log(np.sqrt(2.0 * distribution.ppf(u) / (1.0 + distribution.ppf(u))))
    w = np.full(fine, 1.0 / fine)
    if nodes == 1 or np.ptp(x) == 0.0:
        return radius_of_log_r(np.array([np.sum(w * x)])), np.array([1.0])
    shift, scale = np.sum(w * x), max(np.ptp(x), 1e-300)
    z = (x - shift) / scale  # well scaled for the recurrence
    alpha, beta = np.zeros(nodes), np.zeros(nodes)
    p_prev, p = np.zeros(fine), np.ones(fine)
    norm_prev = 1.0
    for k in range(nodes):  # Stieltjes: three-term recurrence of the orthogonal polynomials
        norm = np.sum(w * p * p)
        alpha[k] = np.sum(w * z * p * p) / norm
        beta[k] = norm / norm_prev if k > 0 else norm
        p_prev, p = p, (z - alpha[k]) * p - (beta[k] * p_prev if k > 0 else 0.0)
        norm_prev = norm
    J = np.diag(alpha) + np.diag(np.sqrt(beta[1:]), 1) + np.diag(np.sqrt(beta[1:]), -1)
    ev, vec = np.linalg.eigh(J)  # Golub-Welsch: nodes = eigenvalues, weights = first components^2
    weights = vec[0] ** 2
    return radius_of_log_r(shift + scale * ev), weights / weights.sum()


def _median_radius(distribution) -> float:
    return float(distribution.ppf(0.5))


# --------------------------------------------------------------------------- short chains
def _simulate_batch(masses: np.ndarray, stiffness: np.ndarray, n: float, observed=None, lags=None,
                    dt: float = 0.05) -> dict:
    """Peak velocity and time of the ``observed`` granules (default all) of a batch of chains struck
    at granule 1 with v = 1, by the compiled DP5 batch kernel that ensembles use. With ``lags``,
    also the batch's aligned pulse <v(t_peak + tau)> per observed granule (on a grid of step
    ``dt``, cubic interpolation: ``granchain.backends.kernels.aligned``)."""
    from .solve.integrators import DP5, RunControls
    from .solve.simulation import time_limit

    R, M = masses.shape
    obs = np.arange(M, dtype=np.int64) if observed is None else np.asarray(observed, dtype=np.int64)
    K = obs.size
    t_max = time_limit(M, 1.0, n) * float(np.max(stiffness.min(axis=1) ** (-1.0 / n)))
    grid = np.zeros(1) if lags is None else np.arange(0.0, t_max, dt)
    L = 0 if lags is None else len(lags)
    scale = 2.0**40  # fixed-point sums of |v| <= 1 over < 2^20 chains fit in int64
    out = {
        "peak_velocity": np.zeros((R, K)), "peak_time": np.zeros((R, K)), "peak_force": np.zeros((R, 0)),
        "peak_force_time": np.zeros((R, 0)), "peak_wall_force": np.full(R, np.nan),
        "peak_wall_force_time": np.full(R, np.nan), "status": np.zeros(R, dtype=np.int64),
        "energy_error": np.zeros(R), "n_steps": np.zeros(R, dtype=np.int64), "t_end": np.zeros(R),
        "sum_v": np.zeros((grid.size, K), dtype=np.int64), "sum_v2": np.zeros((grid.size, K), dtype=np.int64),
        "sum_wall": np.zeros(grid.size, dtype=np.int64), "n_valid": np.zeros(1, dtype=np.int64),
        "lags": None if lags is None else np.asarray(lags, dtype=float),
        "sum_a": np.zeros((L, K), dtype=np.int64), "sum_a2": np.zeros((L, K), dtype=np.int64),
    }
    DP5(rtol=RTOL, atol=ATOL).integrate_batch(
        np.ascontiguousarray(masses), np.ascontiguousarray(stiffness), float(n), np.ones(R), obs,
        np.zeros(0, dtype=np.int64), t_grid=grid, t_max=t_max, controls=RunControls(), scale=scale, out=out)
    bad = out["status"] != 0
    if bad.any():
        raise RuntimeError(f"{int(bad.sum())} of {R} short chains of the transfer table did not finish "
                           f"(status {sorted(set(out['status'][bad].tolist()))}): the stiffness contrast is too large "
                           "for the time limit; narrow the distribution")
    if lags is not None:
        out["aligned"] = out["sum_a"].T / scale / R  # (K, L)
    return out


def _window_chains(radii: np.ndarray, start: str, end: str, settings: TheorySettings, median: float):
    """Masses and stiffnesses of the short chains for windows of radii (B, w), one radius per contact.

    ``start``: "struck" (granule 1 of the window is the chain's struck granule) or "lead" (a
    uniform lead-in of LEAD_IN contacts with the first window radius). ``end``: "tail" (a uniform
    tail of TAIL contacts with the last window radius) or "free" (the chain's real free end).
    Returns (masses, stiffness, offset): offset = chain index of the window's first granule.
    """
    B, w = radii.shape
    lead = LEAD_IN if start == "lead" else 0
    tail = TAIL if end == "tail" else 0
    full = np.concatenate([np.repeat(radii[:, :1], lead, axis=1), radii, np.repeat(radii[:, -1:], tail, axis=1)], axis=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mu, c = effective_parameters(np.ones((B, full.shape[1] + 1)), full, settings.n)  # Eqs. renorm-mass, effec-int
    if not settings.stiffness_disorder:
        c = np.full_like(c, float(stiffness_of_radius(median, settings.n)))
    return mu, c, lead


@dataclass(frozen=True, eq=False)
class TransferTable:
    """The transfer map of one window type over all Q^w node combinations.

    ``log_gain[i]`` = log(P_{g+1} / P_g) and ``scaled_step[i]`` = (t_{g+1} - t_g) P_g^((n-2)/n) at
    the window's step granule g, for the combination i = sum_p q_p Q^p (q_p the node of window
    contact p, p = 0 the oldest).
    """

    start: str
    end: str
    width: int
    step: int
    log_gain: np.ndarray
    scaled_step: np.ndarray
    seconds: float


def _combinations(Q: int, w: int) -> np.ndarray:
    """(Q^w, w) node indices, combination i = sum_p q_p Q^p."""
    i = np.arange(Q**w)
    return np.stack([(i // Q**p) % Q for p in range(w)], axis=1)


def _tabulate(radii_nodes, start, end, width, step, settings, median) -> TransferTable:
    t0 = time.perf_counter()
    combos = _combinations(radii_nodes.size, width)
    mu, c, off = _window_chains(radii_nodes[combos], start, end, settings, median)
    g = off + step
    lg, st = np.empty(len(combos)), np.empty(len(combos))
    for lo in range(0, len(combos), 4096):  # bounded memory; the kernel itself is the cost
        sl = slice(lo, lo + 4096)
        res = _simulate_batch(mu[sl], c[sl], settings.n, observed=[g, g + 1])
        pv, pt = res["peak_velocity"], res["peak_time"]  # columns: granules g, g + 1
        lg[sl] = np.log(pv[:, 1] / pv[:, 0])
        st[sl] = (pt[:, 1] - pt[:, 0]) * pv[:, 0] ** ((settings.n - 2.0) / settings.n)
    return TransferTable(start, end, width, step, lg, st, time.perf_counter() - t0)


# --------------------------------------------------------------------------- caching
_MEMORY: dict = {}


def cache_dir() -> Path:
    """Where tables are kept between sessions: ``theory`` under granchain's per-user cache directory
    ($GRANCHAIN_CACHE, else $XDG_CACHE_HOME or ~/.cache, then ``granchain``: ``granchain._cache``)."""
    return user_cache_dir() / "theory"


def clear_cache(disk: bool = False) -> None:
    """Forget the in-memory tables (and with ``disk=True`` the files under :func:`cache_dir`)."""
    _MEMORY.clear()
    if disk and cache_dir().exists():
        for f in cache_dir().glob("*.npz"):
            f.unlink()


def _key(distribution, settings: TheorySettings, kind: tuple) -> str:
    rec = {"dist": distribution.describe(), "settings": asdict(settings), "kind": list(kind), "lead": LEAD_IN,
           "tail": TAIL, "rtol": RTOL, "atol": ATOL, "version": TABLE_VERSION}
    return hashlib.sha256(json.dumps(rec, sort_keys=True).encode()).hexdigest()[:24]


def _cached(key: str, cache: bool, compute) -> dict:
    """compute() -> dict of arrays, kept in memory and as ``key``.npz under :func:`cache_dir`."""
    if cache and key in _MEMORY:
        return _MEMORY[key]
    path = cache_dir() / f"{key}.npz"
    value = None
    if cache and path.exists():
        try:
            with np.load(path) as f:
                value = {name: f[name] for name in f.files}
        except (OSError, KeyError, ValueError):
            value = None  # a damaged cache file is recomputed, never trusted
    if value is None:
        value = compute()
        if cache:
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
                tmp = path.with_suffix(f".{os.getpid()}.tmp.npz")
                np.savez(tmp, **value)
                os.replace(tmp, path)
            except OSError:
                pass  # a read-only cache directory only costs recomputation
    if cache:
        _MEMORY[key] = value
    return value


def transfer_table(distribution, start: str, end: str, width: int, step: int, settings: TheorySettings,
                   *, cache: bool = True) -> TransferTable:
    """The table of one window type (computed, or read from the memory / disk cache)."""
    key = _key(distribution, settings, (start, end, int(width), int(step)))

    def compute():
        R, _ = stiffness_quadrature(distribution, settings.nodes)
        t = _tabulate(R, start, end, width, step, settings, _median_radius(distribution))
        return {"log_gain": t.log_gain, "scaled_step": t.scaled_step, "seconds": np.array(t.seconds)}

    v = _cached(key, cache, compute)
    return TransferTable(start, end, int(width), int(step), v["log_gain"], v["scaled_step"], float(v["seconds"]))


# --------------------------------------------------------------------------- monodisperse references
def _monodisperse(size: int, n: float, t_grid=None):
    from .model.chain import monodisperse
    from .solve.simulation import simulate

    return simulate(monodisperse(size, n=n), t_grid=t_grid)


def formation_factors(size: int, settings: TheorySettings) -> tuple[np.ndarray, np.ndarray]:
    """(gain, step) factors per step j = 0..size-2 that carry a lead-in window to step j.

    A lead-in window delivers a fully formed solitary wave; at step j the real pulse is still
    forming (its amplitude settles over ~10 granules). With P^0, t^0 the monodisperse chain's
    peaks, gain_j = (P^0_{j+1}/P^0_j) / (P^0_{g+1}/P^0_g) and step_j likewise for
    dt P^((n-2)/n), g = LEAD_IN + memory the window's step granule: exact for a uniform chain,
    and a product ansatz (formation x disorder) otherwise. Both -> 1 for large j.
    """
    g = LEAD_IN + settings.memory
    res = _monodisperse(max(size, g + 2) + 20, settings.n)
    p, t = res.peak_velocity, res.peak_time
    e = (settings.n - 2.0) / settings.n
    ratio = p[1:] / p[:-1]
    scaled = np.diff(t) * p[:-1] ** e
    j = np.arange(size - 1)
    return ratio[j] / ratio[g], scaled[j] / scaled[g]


# --------------------------------------------------------------------------- composition
def _window_types(N: int, a: int, b: int) -> list:
    """Per step j = 0..N-2: (start, end, lo, width, step) of its window."""
    types = []
    for j in range(N - 1):
        lo = max(j - a, 0)
        last = j == N - 2
        hi = j if last else min(j + b, N - 2)
        types.append(("struck" if lo == 0 else "lead", "free" if last else "tail", lo, hi - lo + 1, j - lo))
    return types


def sample_pulses(distribution, n_large: int, settings: TheorySettings, samples: int = 20_000, seed: int = 0,
                  *, cache: bool = True) -> dict:
    """Monte Carlo of the Markov composition: per sample (realisation of the contact nodes) the
    peaks P (samples, N), peak times t (samples, N) and local time scales s (samples, N).

    Node sequences are drawn with the quadrature weights; every step looks its window up in the
    transfer tables. No chain is integrated here (the tables are built from short chains once).
    """
    N = count("n_large", n_large, minimum=2)
    a, b, Q = settings.memory, settings.lookahead, settings.nodes
    _, weights = stiffness_quadrature(distribution, Q)
    rng = np.random.default_rng(seed)
    q = rng.choice(Q, size=(samples, N - 1), p=weights)
    gain_f, step_f = formation_factors(N, settings)
    e = (settings.n - 2.0) / settings.n
    logP = np.zeros((samples, N))
    t = np.zeros((samples, N))
    dts = np.zeros((samples, N - 1))
    tables = {}
    for j, (start, end, lo, width, step) in enumerate(_window_types(N, a, b)):
        kind = (start, end, width, step)
        if kind not in tables:
            tables[kind] = transfer_table(distribution, start, end, width, step, settings, cache=cache)
        tab = tables[kind]
        idx = np.zeros(samples, dtype=np.int64)
        for p in range(width):
            idx += q[:, lo + p] * Q**p
        fg, fs = (gain_f[j], step_f[j]) if start == "lead" else (1.0, 1.0)
        P_j = np.exp(logP[:, j])
        dts[:, j] = fs * tab.scaled_step[idx] * P_j ** (-e)
        logP[:, j + 1] = logP[:, j] + tab.log_gain[idx] + math.log(fg)
        t[:, j + 1] = t[:, j] + dts[:, j]
    return {"peak": np.exp(logP), "time": t, "steps": dts, "nodes": q, "tables": tables}


#: Lags (rescaled time) of the tabulated aligned pulse, and the window chains drawn per profile.
PROFILE_LAGS = np.arange(-10.0, 14.0001, 0.05)
PROFILE_WINDOWS = 2000


def aligned_profiles(distribution, n_large: int, settings: TheorySettings, *, windows: int = PROFILE_WINDOWS,
                     seed: int = 0, cache: bool = True) -> dict:
    """The aligned pulse <v_k(t_k + tau)> / <P_k> of the window chains, per large granule k = 2..N.

    Granule k is the step granule of the window of step k - 1 (k = N: the flying granule of the
    last window). ``windows`` window chains per window type are drawn with the quadrature
    weights and integrated with the aligned pulse accumulated (``granchain.backends.kernels.aligned``).
    Returns {k: (tau, S, p)}, p the windows' mean peak at that granule (the amplitude at which
    tau is measured: the pulse duration scales as amplitude^(-(n-2)/n)). The window keeps the
    pulse's dressing by its ``memory`` contacts: in a random chain the pulse is broader than
    the monodisperse solitary wave and has a wake, which a rescaled monodisperse profile misses
    by 10 % in max_t <v_k(t)> at N = 26.
    """
    N = count("n_large", n_large, minimum=2)
    R_nodes, weights = stiffness_quadrature(distribution, settings.nodes)
    median = _median_radius(distribution)
    types = _window_types(N, settings.memory, settings.lookahead)
    out, done = {}, {}
    for k in range(2, N + 1):
        start, end, lo, width, step = types[min(k - 1, N - 2)]
        offset = 1 if k == N else 0
        group = (start, end, width, step, offset)
        if group not in done:
            key = _key(distribution, settings, ("profile",) + group + (windows, seed))
            done[group] = _cached(key, cache, lambda: _profile(R_nodes, weights, median, group, settings, windows, seed))
        prof = done[group]
        out[k] = (PROFILE_LAGS, prof["shape"], float(prof["peak"]))
    return out


def _profile(R_nodes, weights, median, group, settings, windows, seed) -> dict:
    start, end, width, step, offset = group
    rng = np.random.default_rng([seed, width, step, offset, start == "lead", end == "free"])
    q = rng.choice(R_nodes.size, size=(windows, width), p=weights)
    mu, c, off = _window_chains(R_nodes[q], start, end, settings, median)
    g = off + step + offset
    res = _simulate_batch(mu, c, settings.n, observed=[g], lags=PROFILE_LAGS)
    peak = float(res["peak_velocity"][:, 0].mean())
    return {"shape": res["aligned"][0] / peak, "peak": np.array(peak)}


def _parabola_peak(t, y) -> tuple[float, float]:
    """(max, argmax) of samples y on the uniform grid t, refined by the parabola through the best three."""
    i = int(np.clip(np.argmax(y), 1, y.size - 2))
    y0, y1, y2 = y[i - 1 : i + 2]
    curv = y0 - 2 * y1 + y2
    off = 0.5 * (y0 - y2) / curv if curv < 0 else 0.0
    return float(y1 - 0.25 * (y0 - y2) * off), float(t[i] + off * (t[1] - t[0]))


def averaged_pulse(peak, times, profiles, n: float = HERTZ, *, points: int = 201) -> tuple[np.ndarray, np.ndarray]:
    """max_t and argmax_t of <P_k S_k((t - t_k) / f_k)> per granule: the dephasing convolution
    (:mod:`granchain.paper.dephasing`, Eq. 1) of the Monte Carlo's (P_k, t_k) with the window chains'
    aligned pulse S_k, its time axis stretched by f_k = (<P_k> / p_k)^(-(n-2)/n) from the windows'
    amplitude p_k to the chain's (Nesterenko's scaling of the pulse duration)."""
    S_, N = peak.shape
    vmax, tmax = np.empty(N), np.empty(N)
    vmax[0], tmax[0] = float(np.mean(peak[:, 0])), 0.0  # struck granule: v = 1 at t = 0 in every realisation
    e = (n - 2.0) / n
    for k in range(1, N):
        tau, S, p_ref = profiles[k + 1]
        f = (float(np.mean(peak[:, k])) / p_ref) ** (-e)
        tk, pk = times[:, k], peak[:, k]
        lo = np.percentile(tk, 0.5) + f * tau[0] / 4
        hi = np.percentile(tk, 99.5) + f * (tau[-1] if k == N - 1 else -tau[0] / 4)
        grid = np.linspace(lo, hi, points)
        right = S[-1] if k == N - 1 else 0.0  # the free end keeps its final velocity
        avg = np.array([np.mean(pk * np.interp((g - tk) / f, tau, S, left=0.0, right=right)) for g in grid])
        if k == N - 1:
            vmax[k], tmax[k] = float(avg.max()), float(grid[int(np.argmax(avg))])
        else:
            vmax[k], tmax[k] = _parabola_peak(grid, avg)
    return vmax, tmax


# --------------------------------------------------------------------------- the public prediction
#: Largest samples x N of one prediction. The Monte Carlo keeps :data:`MC_ARRAYS` arrays of samples x N
#: numbers of 8 bytes (nodes, log-peaks, peaks, times, steps), and the averaged pulse interpolates every
#: sample at 201 times per granule: 5e7 is ~2 GB and a few minutes on one core (the default, 20000 x 26,
#: is 5.2e5: a few seconds once the tables are cached).
MAX_WORK = 50_000_000
MC_ARRAYS = 5


def check_work(n_large: int, samples: int) -> None:
    """Refuse a prediction whose Monte Carlo would not fit in memory or would run for hours, before any
    table is built: samples x N at most :data:`MAX_WORK` and its arrays within half this machine's memory."""
    need = MC_ARRAYS * 8 * samples * n_large
    try:
        half = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") // 2
    except (AttributeError, ValueError, OSError):  # pragma: no cover -- no sysconf (Windows)
        half = None
    too_much = samples * n_large > MAX_WORK or (half is not None and need > half)
    if too_much:
        room = f" (half this machine's memory is {half / 2**30:.3g} GiB)" if half is not None else ""
        raise ValueError(
            f"N = {n_large} large granules x samples = {samples} Monte Carlo samples is too large a prediction: its arrays "
            f"need ~{need / 2**30:.3g} GiB{room} and its averaged pulse ~N x samples x 201 interpolations; keep N x samples "
            f"<= {MAX_WORK:.0e} ("
            + (f"with samples = {samples}: N <= {MAX_WORK // samples}): lower n_large (CLI: --large) or samples (CLI: --samples)"
               if MAX_WORK // samples >= 2 else f"samples <= {MAX_WORK // 2} even for N = 2): lower samples (CLI: --samples)"))


def _check_distribution(distribution):
    if distribution is None:
        raise ValueError("distribution is required: a granchain.Uniform(alpha, beta), Truncated, Mixture or a frozen "
                         "scipy.stats distribution of the small radii (in units of the large radius)")
    return small_radius_distribution(distribution, what="the theory's small-radius distribution", stacklevel=3)


def predict(distribution, n_large: int, n: float = HERTZ, *, samples: int = 20_000, seed: int = 0, memory: int = 4,
            lookahead: int = 1, nodes: int = 5, stiffness_disorder: bool = True, profile_windows: int = PROFILE_WINDOWS,
            cache: bool = True):
    """Predict the pulse along a random decorated chain of ``n_large`` large granules from the
    small-radius law alone (see the module docstring; no ensemble of the chain is run or read).

    Parameters
    ----------
    distribution : Uniform | Truncated | Mixture | scipy.stats frozen distribution
        Law of the small radii (units of the large radius). Beyond 0.4 the effective description
        the theory rests on fails: :class:`granchain.EffectiveValidityWarning`.
    n_large : int
        Number N >= 2 of large granules.
    n : float
        Contact exponent, n > 2 (Hertz 2.5).
    samples, seed : int
        Monte Carlo samples of the Markov composition (its statistical error on <max_t v_k> is
        ~ std / sqrt(samples), 0.04 % at the default) and their seed.
    memory, lookahead, nodes : int
        The transfer map's window (a contacts behind, b ahead) and the quadrature nodes Q per
        contact; tables hold Q^(a+b+1) short chains, built once per law and cached.
    stiffness_disorder : bool
        False: every contact gets the median stiffness (the masses stay random). The negative
        control: without the stiffness disorder nothing makes the pulse decay.
    profile_windows : int
        Window chains drawn per window type for the aligned pulse shape (:func:`aligned_profiles`).
    cache : bool
        Keep and reuse tables in memory and under :func:`cache_dir`.

    Returns
    -------
    xarray.Dataset over ``granule`` (large granules 1..N): ``mean_peak_velocity`` <max_t v_k>,
    ``peak_velocity_std``, ``arrival_time_mean``, ``arrival_time_std`` (per-realisation peak
    times), ``averaged_peak_velocity`` max_t <v_k(t)> and ``averaged_peak_time``, each with
    its Monte Carlo standard error where it has one (``*_mc_stderr``).
    """
    import xarray as xr

    t0 = time.perf_counter()
    N = count("n_large", n_large, minimum=2)
    settings = TheorySettings(memory, lookahead, nodes, n, bool(stiffness_disorder))
    dist = _check_distribution(distribution)
    samples = count("samples", samples, minimum=100)
    seed = count("seed", seed, minimum=0)
    profile_windows = count("profile_windows", profile_windows, minimum=10)  # all checked before any table is built
    check_work(N, samples)
    mc = sample_pulses(dist, N, settings, samples, seed, cache=cache)
    P, T = mc["peak"], mc["time"]
    profiles = aligned_profiles(dist, N, settings, windows=profile_windows, seed=seed, cache=cache)
    vavg, tavg = averaged_pulse(P, T, profiles, settings.n)
    tabulation = sum(tab.seconds for tab in mc["tables"].values())
    R, w = stiffness_quadrature(dist, settings.nodes)
    one = "1"
    granule = np.arange(1, N + 1)
    sq = math.sqrt(samples)

    def var(values, long_name):  # rescaled velocities and times: units "1", the kind recorded (granchain.units)
        kind = "time" if "time" in long_name else "velocity"
        return ("granule", np.asarray(values, dtype=float), {**rescaled_attrs(kind), "long_name": long_name})

    ds = xr.Dataset(
        {
            "mean_peak_velocity": var(P.mean(0), "mean of per-realisation peak velocities <max_t v_k> (units of V_1)"),
            "mean_peak_velocity_mc_stderr": var(P.std(0, ddof=1) / sq, "Monte Carlo standard error of mean_peak_velocity"),
            "peak_velocity_std": var(P.std(0, ddof=1), "standard deviation over realisations of max_t v_k (units of V_1)"),
            "arrival_time_mean": var(T.mean(0), "mean per-realisation peak time of granule k (rescaled time, paper Sec. II)"),
            "arrival_time_mean_mc_stderr": var(T.std(0, ddof=1) / sq, "Monte Carlo standard error of arrival_time_mean"),
            "arrival_time_std": var(T.std(0, ddof=1), "standard deviation over realisations of the peak time of granule k "
                                    "(rescaled time)"),
            "averaged_peak_velocity": var(vavg, "peak of the ensemble-averaged pulse max_t <v_k(t)> (units of V_1; "
                                          "k = N: the free end's final velocity)"),
            "averaged_peak_time": var(tavg, "argmax_t <v_k(t)> (rescaled time, paper Sec. II)"),
        },
        coords={"granule": ("granule", granule, {"long_name": "large granule index k (1-based)", "units": one})},
        attrs={
            "model": "windowed transfer map on the effective chain, composed as a Markov chain (granchain.theory)",
            "distribution": json.dumps(dist.describe(), sort_keys=True),
            "distribution_label": dist.label(),
            "n_large": N,
            "n": settings.n,
            "samples": samples,
            "seed": int(seed),
            "memory": settings.memory,
            "lookahead": settings.lookahead,
            "nodes": settings.nodes,
            "stiffness_disorder": int(settings.stiffness_disorder),
            "quadrature_radii": R.tolist(),
            "quadrature_weights": w.tolist(),
            "profile_windows": int(profile_windows),
            "lead_in_contacts": LEAD_IN,
            "tail_contacts": TAIL,
            "short_chain_rtol": RTOL,
            "short_chain_atol": ATOL,
            "short_chains_tabulated": int(sum(tab.log_gain.size for tab in mc["tables"].values())),
            "tabulation_seconds": float(tabulation),
            "seconds": float(time.perf_counter() - t0),
            "units_note": "units '1': rescaled, dimensionless quantities of the paper's Sec. II (velocities in V_1)",
            "granchain_version": __version__,
        },
    )
    return ds
