"""Where the cheap descriptions hold: validity maps of the effective chain and the BCA.

The paper (Sec. III A, V) claims that the effective chain (Eqs. renorm-mass, effec-int, zetak)
and the binary collision approximation (BCA, Sec. III B) describe the random decorated chain
while the small radii stay below ~0.4 of the large ones, "for arbitrary distributions". This
module measures it. Each point is a *paired* ensemble: the same random radii integrated as the
exact decorated chain and as its effective chain
(``run_ensemble(RandomDecorated(N, dist), chains="both")``), written to its own Zarr store, so a
map is resumable point by point and chunk by chunk, and bitwise reproducible from its seed and
parameters (a point's seed is derived from (seed, N, the distribution) by :func:`point_seed`).

Per point (:data:`MEASURES`; arrival times at large granule N-1 as in the paper's Fig. 4;
"max over k" runs over k = 2..N-1: k = 1 is struck, k = N flies off):

* effective vs decorated: relative error of the mean arrival time, of its standard deviation
  (and of its interquartile range, robust to rare late double peaks),
  the two-sample KS distance of the arrival times (``scipy.stats.ks_2samp``; the statistic,
  whatever p-value method), the relative
  error of the averaged-pulse peaks max_t <v_k(t)> and of the mean single-realisation peaks
  <max_t v_k> (signed, the k of largest magnitude);
* the BCA (Eq. total-time on each realisation's radii) vs the decorated numerics: relative
  error of the mean arrival time, width ratio std_BCA / std_numerics, the peak shift
  (mean numerics - mean BCA: the paper's Fig. 4 shift, mean to mean) and the KS distance after
  that shift.

Every measure has ``*_stderr``: a delete-one jackknife over the ensemble's chunks (blocks of
realisations, ``blocks`` of them), sqrt((B-1)/B sum_i (theta_(i) - theta_(.))^2). The pairing
(same radii in both chains) is kept inside each block, so correlated errors cancel as in the
estimate itself. For KS distances the jackknife is only indicative (a non-smooth statistic).
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import math
import warnings
from pathlib import Path

import numpy as np

from .. import analysis, bca
from .._validate import EFFECTIVE_VALIDITY_LIMIT, EffectiveValidityWarning, output_directory  # noqa: F401 (public here too)
from .._version import __version__
from ..model.distributions import Uniform, as_distribution
from ..units import rescaled_attrs

__all__ = ["MEASURES", "DEFAULT_ALPHAS", "DEFAULT_BETAS", "QUICK", "validity_map", "compare_distributions",
           "point_seed", "compare_paired", "contour_beta", "default_distributions", "report_section"]

#: The default map: 4 x 8 (alpha, beta) points (31 with alpha < beta) at N = 6 and 26.
DEFAULT_ALPHAS = (0.01, 0.05, 0.1, 0.2)
DEFAULT_BETAS = (0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9)
DEFAULT_REALIZATIONS = 400
#: ``granchain validity --quick``: a coarse map (52 s on 2 shared cores; the default map took 12 min).
QUICK = {"alphas": (0.01, 0.2), "betas": (0.3, 0.4, 0.6, 0.9), "n_large": (6, 26), "realizations": 100}

_REL = "1 (relative)"
#: name -> (units, long_name) of every measure (each also has ``<name>_stderr``).
MEASURES = {
    "arrival_time_error_effective": (_REL, "mean arrival time at granule N-1, effective / decorated - 1"),
    "arrival_time_std_error_effective": (_REL, "std of the arrival time at granule N-1, effective / decorated - 1"),
    "arrival_time_iqr_error_effective": (_REL, "interquartile range of the arrival time at N-1, effective / decorated - 1 "
                                         "(robust to the rare late double peaks that dominate the std beyond beta ~ 0.6)"),
    "arrival_time_ks_effective": ("1", "two-sample KS distance of the arrival times at N-1, effective vs decorated"),
    "averaged_pulse_peak_error_effective": (_REL, "max_t <v_k(t)>, effective / decorated - 1, largest |.| over k = 2..N-1"),
    "mean_peak_error_effective": (_REL, "<max_t v_k>, effective / decorated - 1, largest |.| over k = 2..N-1"),
    "arrival_time_error_bca": (_REL, "mean arrival time at N-1, BCA Eq. (total-time) / decorated numerics - 1"),
    "arrival_time_width_ratio_bca": ("1", "std of the arrival time at N-1, BCA / decorated numerics"),
    "bca_peak_shift": ("rescaled time", "mean numerics - mean BCA arrival time at N-1 (the paper's Fig. 4 shift, mean to mean)"),
    "arrival_time_ks_bca_shifted": ("1", "two-sample KS distance at N-1, BCA shifted by bca_peak_shift vs decorated numerics"),
}
#: Measures that are relative errors (their |value| is compared with the 1 % and 5 % contours).
RELATIVE = tuple(k for k, (u, _) in MEASURES.items() if u == _REL)


def point_seed(seed: int, *parts) -> int:
    """Seed of one map point: ``SeedSequence`` entropy from (seed, parts), parts JSON-able (e.g. N and
    the distribution's record). Depends on nothing else, so any subset of a map reproduces its points."""
    digest = hashlib.sha256(json.dumps([int(seed), *parts], sort_keys=True).encode()).digest()
    entropy = [int(seed), int.from_bytes(digest[:16], "little")]
    return int(np.random.SeedSequence(entropy).generate_state(1, np.uint32)[0])


# --------------------------------------------------------------------------- one paired ensemble
def _jackknife(fn, B: int):
    """(estimate on all blocks, jackknife standard error) of ``fn(mask)`` -> dict of floats."""
    full = fn(np.ones(B, dtype=bool))
    if B < 2:
        return full, {k: math.nan for k in full}
    reps = []
    for i in range(B):
        m = np.ones(B, dtype=bool)
        m[i] = False
        reps.append(fn(m))
    err = {}
    for k in full:
        x = np.array([r[k] for r in reps], dtype=float)
        err[k] = float(math.sqrt((B - 1) / B * np.sum((x - x.mean()) ** 2))) if np.all(np.isfinite(x)) else math.nan
    return full, err


def _signed_max(rel: np.ndarray) -> float:
    """The entry of largest magnitude (sign kept); NaN if none is finite."""
    rel = np.asarray(rel, dtype=float)
    if not np.any(np.isfinite(rel)):
        return math.nan
    return float(rel[np.nanargmax(np.abs(rel))])


def _iqr(x) -> float:
    q1, q3 = np.percentile(x, [25, 75])
    return float(q3 - q1)


def _averaged_peaks(ds, sum_v, n_valid, bits: int, chain_index: int, mask) -> np.ndarray:
    """max_t <v_k(t)> over the chunks in ``mask`` (via :func:`granchain.analysis.averaged_pulse_peak`)."""
    import xarray as xr

    from ..ensembles.store import mean_from_sums

    s1 = sum_v[mask, chain_index].sum(0)[None]
    s2 = np.zeros_like(s1)
    nv = n_valid[mask, chain_index].sum(0).reshape(1)
    mean, _ = mean_from_sums(s1, s2, nv, bits)
    sub = xr.Dataset({"mean_velocity": (("chain", "granule", "time"), mean),
                      "mean_velocity_stderr": (("chain", "granule", "time"), np.zeros_like(mean))},
                     coords={"chain": ["x"], "granule": ds["granule"].values, "time": ds["time"].values})
    return np.asarray(analysis.averaged_pulse_peak(sub, "x").velocity)


def compare_paired(ds, progress) -> dict:
    """All :data:`MEASURES` (and ``*_stderr``) of one paired ensemble ``ds`` (chains decorated and
    effective, as run_ensemble returns it) with its ``progress`` group (the per-chunk sums)."""
    from scipy.stats import ks_2samp

    chains = [str(c) for c in ds["chain"].values]
    if chains != ["decorated", "effective"]:
        raise ValueError(f"a validity point needs the paired chains ['decorated', 'effective'], got {chains}")
    N = ds.sizes["granule"]
    if N < 3:
        raise ValueError(f"validity maps need N >= 3 large granules (arrival at N-1 > 1), got N = {N}")
    chunk = int(ds.attrs["chunk_size"])
    R = ds.sizes["realization"]
    B = -(-R // chunk)
    block = np.arange(R) // chunk
    ok = np.all(ds["status"].values == 0, axis=0)  # valid in both chains (paired)
    t = ds["peak_time"].values[:, :, N - 2]  # (chain, realization) at granule N-1
    peaks = ds["peak_velocity"].values  # (chain, realization, granule)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", EffectiveValidityWarning)
        t_bca = bca.arrival_times(ds["small_radius"].values, float(ds.attrs["n"]))[:, N - 2]  # Eq. (total-time)
    sum_v = progress["sum_v"].values
    n_valid = progress["n_valid"].values
    bits = int(ds.attrs["fixed_point_bits"])
    inner = slice(1, N - 1)  # k = 2..N-1

    def stats(mask):
        use = ok & mask[block]
        td, te, tb = t[0, use], t[1, use], t_bca[use]
        out = {
            "arrival_time_error_effective": te.mean() / td.mean() - 1.0,
            "arrival_time_std_error_effective": te.std(ddof=1) / td.std(ddof=1) - 1.0,
            "arrival_time_iqr_error_effective": _iqr(te) / _iqr(td) - 1.0,
            "arrival_time_ks_effective": ks_2samp(te, td, method="asymp").statistic,
            "mean_peak_error_effective": _signed_max(peaks[1, use][:, inner].mean(0) / peaks[0, use][:, inner].mean(0) - 1.0),
            "arrival_time_error_bca": tb.mean() / td.mean() - 1.0,
            "arrival_time_width_ratio_bca": tb.std(ddof=1) / td.std(ddof=1),
        }
        shift = td.mean() - tb.mean()
        out["bca_peak_shift"] = shift
        out["arrival_time_ks_bca_shifted"] = ks_2samp(tb + shift, td, method="asymp").statistic
        pd_, pe = (_averaged_peaks(ds, sum_v, n_valid, bits, ci, mask) for ci in (0, 1))
        out["averaged_pulse_peak_error_effective"] = _signed_max(pe[inner] / pd_[inner] - 1.0)
        return {k: float(v) for k, v in out.items()}

    value, err = _jackknife(stats, B)
    res = {}
    for name in MEASURES:
        res[name], res[name + "_stderr"] = value[name], err[name]
    res["valid_realizations"] = int(ok.sum())
    res["mean_arrival_time_decorated"] = float(t[0, ok].mean())
    res["std_arrival_time_decorated"] = float(t[0, ok].std(ddof=1))
    return res


def _run_point(dist, N: int, realizations: int, seed: int, blocks: int, path, integrator, progress: bool, backend=None,
               switch_backend: bool = False) -> dict:
    """Run (or resume) one paired ensemble into ``path`` (on ``backend``: :func:`granchain.run_ensemble`'s) and
    measure it."""
    from ..ensembles.run import run_ensemble
    from ..ensembles.read import open_store
    from ..families import RandomDecorated

    chunk = -(-realizations // blocks)
    with warnings.catch_warnings(record=True) as caught:  # beyond 0.4 is the point of a validity map
        warnings.simplefilter("always", EffectiveValidityWarning)
        family = RandomDecorated(N, dist)
        ds = run_ensemble(family, realizations=realizations, seed=seed, chains="both", integrator=integrator,
                          chunk_size=chunk, out=path, resume=True, progress=progress, backend=backend,
                          switch_backend=switch_backend)
    warned = any(issubclass(w.category, EffectiveValidityWarning) for w in caught)
    for w in caught:  # anything else is re-issued
        if not issubclass(w.category, EffectiveValidityWarning):
            warnings.warn(w.message, w.category, stacklevel=3)
    prog = open_store(path, group="progress", load=True)
    res = compare_paired(ds, prog)
    res["beyond_effective_validity"] = int(warned)
    res["failed_realizations"] = int(np.sum(np.any(ds["status"].values != 0, axis=0)))
    return res


_EXTRA = {
    "valid_realizations": ("1", "realisations successful in both chains"),
    "failed_realizations": ("1", "realisations failed in either chain"),
    "mean_arrival_time_decorated": ("rescaled time", "mean arrival time at N-1, decorated numerics"),
    "std_arrival_time_decorated": ("rescaled time", "std of the arrival time at N-1, decorated numerics"),
    "beyond_effective_validity": ("1", "1 where the radii reach beyond 0.4 (EffectiveValidityWarning caught and recorded)"),
}


def _unit_attrs(units: str) -> dict:
    """A ``units`` string pint and UDUNITS parse ("1"); what the number means in ``units_description``."""
    if units == _REL:
        return {"units": "1", "units_description": "relative error, a fraction (0.01 = 1 %)"}
    if units == "rescaled time":
        return rescaled_attrs("time")
    return {"units": units}


def _variables(dims, shape):
    data = {}
    for name, (units, long) in MEASURES.items():
        data[name] = (dims, np.full(shape, np.nan), {**_unit_attrs(units), "long_name": long})
        data[name + "_stderr"] = (dims, np.full(shape, np.nan), {**_unit_attrs(units), "long_name": "jackknife standard error of " + name})
    for name, (units, long) in _EXTRA.items():
        data[name] = (dims, np.full(shape, np.nan), {**_unit_attrs(units), "long_name": long})
    return data


def _attrs(kind: str, realizations: int, seed: int, blocks: int, integrator, backend=None) -> dict:
    from ..ensembles.run import ensemble_integrator
    from ..solve.integrators import get_integrator

    integ = ensemble_integrator() if integrator is None else get_integrator(integrator)
    return {
        "title": f"granchain {kind}: effective chain and BCA vs the decorated chain",
        "source": f"granchain {__version__} granchain.paper.validity (paired run_ensemble, chains decorated + effective)",
        "references": "U. Harbola, A. Rosas, A. H. Romero and K. Lindenberg, Pulse propagation in decorated random chains",
        "realizations": int(realizations),
        "seed": int(seed),
        "blocks": int(blocks),
        "integrator": json.dumps(integ.describe(), sort_keys=True),
        "granchain_version": __version__,
        "arrival_granule": "N-1",
        "stderr": "delete-one jackknife over blocks of realisations (the ensemble chunks)",
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        # only for another backend than the CPU default: the maps of earlier versions keep their attributes
        **({} if backend is None else {"backend": _backend_name(backend)}),
    }


def _backend_name(backend) -> str:
    from ..ensembles import backend as _backend

    return _backend.name_of(_backend.checked(backend))


def _usable_backend(backend):
    """``backend`` checked (a name :func:`granchain.run_ensemble` knows, usable here) before a map starts."""
    from ..ensembles import backend as _backend

    _backend.resolve(_backend.checked(backend))
    return backend


def _check_common(realizations, blocks, n_large, seed=0):
    from .._validate import count

    count("seed", seed, minimum=0)
    realizations = count("realizations", realizations, minimum=4)
    blocks = count("blocks", blocks, minimum=2)
    if blocks > realizations // 2:
        raise ValueError(f"blocks = {blocks} needs realizations >= 2 * blocks (got {realizations}); lower blocks")
    Ns = tuple(count("n_large", N, minimum=3) for N in np.atleast_1d(n_large))
    return realizations, blocks, Ns


def write_netcdf(ds, path) -> Path:
    """``ds.to_netcdf(path)`` with the first installed engine (netCDF4, h5netcdf, else SciPy's netCDF3)."""
    import importlib.util

    engine = next((e for e, mod in (("netcdf4", "netCDF4"), ("h5netcdf", "h5netcdf")) if importlib.util.find_spec(mod)), "scipy")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ds.to_netcdf(path, engine=engine)
    return path


def validity_map(out, *, alphas=DEFAULT_ALPHAS, betas=DEFAULT_BETAS, n_large=(6, 26), realizations: int = DEFAULT_REALIZATIONS,
                 seed: int = 0, blocks: int = 10, integrator=None, progress: bool = True, netcdf: bool = True,
                 backend=None, switch_backend: bool = False):
    """Validity map of the effective chain and the BCA over small radii uniform on [alpha, beta].

    Parameters
    ----------
    out : path
        Directory: one Zarr store per point (``points/N{N}_alpha{a}_beta{b}.zarr``, resumed if present)
        and the map as netCDF (``validity.nc``, if ``netcdf``).
    alphas, betas : sequences of float
        The grid; points with alpha >= beta are left NaN. beta up to 1.
    n_large : int or sequence of int
        Numbers N of large granules (>= 3).
    realizations, seed, blocks
        Realisations per point; the map's seed (each point's from :func:`point_seed`); jackknife blocks
        (= ensemble chunks of ceil(realizations / blocks)).
    integrator
        Any registered integrator (default: the ensembles' DP5).
    backend, switch_backend
        What computes the points' ensembles ("cpu", the default, or "cuda"), and whether points computed
        on another backend are continued (:func:`granchain.run_ensemble`).

    Returns
    -------
    xarray.Dataset with dims ``alpha``, ``beta``, ``n_large`` and the :data:`MEASURES` with ``*_stderr``.
    """
    import xarray as xr
    from tqdm.auto import tqdm

    realizations, blocks, Ns = _check_common(realizations, blocks, n_large, seed)
    backend = _usable_backend(backend)
    try:
        a = np.array(sorted(float(x) for x in np.atleast_1d(alphas)))
        b = np.array(sorted(float(x) for x in np.atleast_1d(betas)))
    except (TypeError, ValueError):
        raise ValueError(f"alphas and betas must be sequences of numbers, got alphas={alphas!r}, betas={betas!r}") from None
    if a.size == 0 or b.size == 0 or not (np.isfinite(a).all() and np.isfinite(b).all()) or a[0] <= 0 or b[-1] > 1:
        raise ValueError(f"need finite 0 < alphas and betas <= 1 (small radii in units of the large), got "
                         f"alphas={[float(x) for x in a]}, betas={[float(x) for x in b]}")
    shape = (a.size, b.size, len(Ns))
    ds = xr.Dataset(_variables(("alpha", "beta", "n_large"), shape),
                    coords={"alpha": ("alpha", a, {**rescaled_attrs("radius"), "long_name": "smallest small radius (units of the large radius)"}),
                            "beta": ("beta", b, {**rescaled_attrs("radius"), "long_name": "largest small radius (units of the large radius)"}),
                            "n_large": ("n_large", np.array(Ns), {"long_name": "number N of large granules", "units": "1"})},
                    attrs={**_attrs("validity map", realizations, seed, blocks, integrator, backend),
                           "distribution": "uniform on [alpha, beta]"})
    points = [(i, j, k) for k in range(len(Ns)) for i in range(a.size) for j in range(b.size) if a[i] < b[j]]
    if not points:  # refused before anything is written: an empty map would look like a finished one
        raise ValueError(f"no grid point has alpha < beta (alphas={[float(x) for x in a]}, betas={[float(x) for x in b]}): "
                         "the small radii are uniform on [alpha, beta], so give at least one alpha below a beta")
    root = output_directory(out)
    for i, j, k in tqdm(points, desc="validity map", unit=" points", disable=not progress, dynamic_ncols=True):
        dist = Uniform(a[i], b[j])
        N = Ns[k]
        path = root / "points" / f"N{N}_alpha{a[i]:g}_beta{b[j]:g}.zarr"
        res = _run_point(dist, N, realizations, point_seed(seed, N, dist.describe()), blocks, path, integrator, False,
                         backend, switch_backend)
        for name, value in res.items():
            ds[name].values[i, j, k] = value
    if netcdf:
        write_netcdf(ds, root / "validity.nc")
    return ds


# --------------------------------------------------------------------------- any distribution
def default_distributions(lower: float = 0.01, upper: float = 0.4) -> dict:
    """Small-radius distributions on the same support [lower, upper]:
    uniform (the paper), a truncated normal, two betas (mass low, mass high), a bimodal mixture."""
    from scipy import stats

    from ..model.distributions import Mixture, Truncated

    w = upper - lower
    mid = lower + 0.5 * w
    return {
        "uniform": Uniform(lower, upper),
        "truncated normal": Truncated(stats.norm(mid, 0.2 * w), lower, upper),
        "beta(2,5)": Truncated(stats.beta(2, 5, loc=lower, scale=w), lower, upper),
        "beta(5,2)": Truncated(stats.beta(5, 2, loc=lower, scale=w), lower, upper),
        "bimodal": Mixture((Truncated(stats.norm(lower + 0.1 * w, 0.06 * w), lower, upper),
                            Truncated(stats.norm(upper - 0.1 * w, 0.06 * w), lower, upper)), (0.5, 0.5)),
    }


def compare_distributions(out, distributions=None, *, n_large=(6, 26), realizations: int = DEFAULT_REALIZATIONS, seed: int = 0,
                          blocks: int = 10, integrator=None, progress: bool = True, netcdf: bool = True, backend=None,
                          switch_backend: bool = False):
    """The map's measures for several small-radius distributions (default: :func:`default_distributions`),
    their ensembles computed on ``backend`` (as :func:`validity_map`'s).

    Returns an xarray.Dataset with dims ``distribution`` (labels), ``n_large``; also the mean and
    std of the radius and the fraction of radii above 0.4 per distribution.
    """
    import xarray as xr
    from tqdm.auto import tqdm

    realizations, blocks, Ns = _check_common(realizations, blocks, n_large, seed)
    backend = _usable_backend(backend)
    dists = default_distributions() if distributions is None else {str(k): as_distribution(v) for k, v in dict(distributions).items()}
    names = list(dists)
    ds = xr.Dataset(_variables(("distribution", "n_large"), (len(names), len(Ns))),
                    coords={"distribution": ("distribution", np.array(names, dtype=object).astype(str)),
                            "n_large": ("n_large", np.array(Ns), {"long_name": "number N of large granules", "units": "1"})},
                    attrs=_attrs("distribution comparison", realizations, seed, blocks, integrator, backend))
    ds["label"] = ("distribution", np.array([d.label() for d in dists.values()], dtype=object).astype(str))
    ds["radius_mean"] = ("distribution", [d.expect(lambda r: r) for d in dists.values()], {**rescaled_attrs("radius"), "long_name": "mean small radius"})
    ds["radius_std"] = ("distribution", [math.sqrt(max(d.expect(lambda r: r * r) - d.expect(lambda r: r) ** 2, 0.0))
                                         for d in dists.values()], {**rescaled_attrs("radius"), "long_name": "std of the small radius"})
    ds["fraction_above_limit"] = ("distribution", [1.0 - float(d.cdf(EFFECTIVE_VALIDITY_LIMIT)) for d in dists.values()],
                                  {"long_name": f"probability of a small radius above {EFFECTIVE_VALIDITY_LIMIT}", "units": "1"})
    root = output_directory(out)
    jobs = [(i, k) for k in range(len(Ns)) for i in range(len(names))]
    for i, k in tqdm(jobs, desc="distributions", unit=" points", disable=not progress, dynamic_ncols=True):
        d, N = dists[names[i]], Ns[k]
        slug = "".join(ch if ch.isalnum() else "_" for ch in names[i])
        res = _run_point(d, N, realizations, point_seed(seed, N, d.describe()), blocks,
                         root / "distributions" / f"N{N}_{slug}.zarr", integrator, False, backend, switch_backend)
        for name, value in res.items():
            ds[name].values[i, k] = value
    if netcdf:
        write_netcdf(ds, root / "distributions.nc")
    return ds


# --------------------------------------------------------------------------- summaries
def contour_beta(ds, name: str = "arrival_time_error_effective", level: float = 0.01) -> dict:
    """Per (N, alpha): the largest beta up to which |name| stays below ``level`` at every grid beta
    (NaN if already above at the smallest beta). The map's grid resolution bounds its accuracy."""
    out = {}
    for N in ds["n_large"].values:
        for a in ds["alpha"].values:
            col = ds[name].sel(n_large=N, alpha=a)
            betas = [float(b) for b, v in zip(col["beta"].values, col.values) if np.isfinite(v)]
            vals = [abs(float(v)) for v in col.values if np.isfinite(v)]
            last = math.nan
            for b, v in zip(betas, vals):
                if v >= level:
                    break
                last = b
            out[(int(N), float(a))] = last
    return out


def _fmt(v, e, pct=True):
    if not np.isfinite(v):
        return "-"
    return f"{100 * v:+.2f} ± {100 * e:.2f} %" if pct else f"{v:.3f} ± {e:.3f}"


def report_section(validity=None, distributions=None, dephasing=None) -> str:
    """Markdown section "Where the theory holds" from a :func:`validity_map` Dataset, a
    :func:`compare_distributions` Dataset and a dephasing summary (``granchain.paper.dephasing.summary``);
    any may be None."""
    lines = ["## Where the theory holds", ""]
    if validity is not None:
        v = validity
        lines += [f"Paired decorated/effective ensembles, {v.attrs['realizations']} realisations per point, small radii "
                  f"uniform on [alpha, beta]; errors at granule N-1 (jackknife errors over {v.attrs['blocks']} blocks).", ""]
        for name, label in (("arrival_time_error_effective", "effective chain, mean arrival time"),
                            ("averaged_pulse_peak_error_effective", "effective chain, averaged-pulse peak"),
                            ("arrival_time_error_bca", "BCA, mean arrival time")):
            for level in (0.01, 0.05):
                parts = []
                for (N, a), b in contour_beta(v, name, level).items():
                    valid = np.isfinite(v[name].sel(n_large=N, alpha=a).values)
                    if not valid.any():  # no beta above this alpha in the grid: nothing to say
                        continue
                    where = f"N = {N}, alpha = {a:g}"
                    parts.append(f"up to beta = {b:g} ({where})" if np.isfinite(b) else
                                 f"not even at beta = {float(v['beta'].values[valid][0]):g} ({where})")
                lines.append(f"- {label}, |error| < {100 * level:g} %: {'; '.join(parts) or 'no point computed'}")
        lines.append("")
        lines.append("| N | alpha | beta | arrival (eff.) | std (eff.) | KS (eff.) | <v>-peak (eff.) | <max v> (eff.) | arrival (BCA) | width ratio (BCA) | shift (BCA) |")
        lines.append("|---|---|---|---|---|---|---|---|---|---|---|")
        for N in v["n_large"].values:
            for a in v["alpha"].values:
                for b in v["beta"].values:
                    p = v.sel(n_large=N, alpha=a, beta=b)
                    if not np.isfinite(float(p["arrival_time_error_effective"])):
                        continue
                    g = lambda n, pct=True: _fmt(float(p[n]), float(p[n + "_stderr"]), pct)  # noqa: E731
                    lines.append(f"| {int(N)} | {a:g} | {b:g} | {g('arrival_time_error_effective')} | "
                                 f"{g('arrival_time_std_error_effective')} | {g('arrival_time_ks_effective', False)} | "
                                 f"{g('averaged_pulse_peak_error_effective')} | {g('mean_peak_error_effective')} | "
                                 f"{g('arrival_time_error_bca')} | {g('arrival_time_width_ratio_bca', False)} | "
                                 f"{g('bca_peak_shift', False)} |")
        lines.append("")
    if distributions is not None:
        d = distributions
        lines += ["### Any distribution at equal support", "",
                  "| distribution | N | mean R | arrival (eff.) | std (eff.) | <v>-peak (eff.) | <max v> (eff.) | arrival (BCA) | width ratio (BCA) |",
                  "|---|---|---|---|---|---|---|---|---|"]
        for name in d["distribution"].values:
            for N in d["n_large"].values:
                p = d.sel(distribution=name, n_large=N)
                g = lambda n, pct=True: _fmt(float(p[n]), float(p[n + "_stderr"]), pct)  # noqa: E731
                lines.append(f"| {name} | {int(N)} | {float(p['radius_mean']):.3f} | {g('arrival_time_error_effective')} | "
                             f"{g('arrival_time_std_error_effective')} | {g('averaged_pulse_peak_error_effective')} | "
                             f"{g('mean_peak_error_effective')} | {g('arrival_time_error_bca')} | "
                             f"{g('arrival_time_width_ratio_bca', False)} |")
        lines.append("")
        for name, label in (("arrival_time_error_effective", "effective chain, mean arrival time"),
                            ("averaged_pulse_peak_error_effective", "effective chain, averaged-pulse peak"),
                            ("arrival_time_error_bca", "BCA, mean arrival time")):
            ok = [f"{n} (N={int(N)})" for n in d["distribution"].values for N in d["n_large"].values
                  if abs(float(d[name].sel(distribution=n, n_large=N))) < 0.01]
            bad = [f"{n} (N={int(N)}: {100 * float(d[name].sel(distribution=n, n_large=N)):+.2f} %)"
                   for n in d["distribution"].values for N in d["n_large"].values
                   if not abs(float(d[name].sel(distribution=n, n_large=N))) < 0.01]
            lines.append(f"- {label} within 1 %: {', '.join(ok) or 'none'}; not: {', '.join(bad) or 'none'}")
        lines.append("")
    if dephasing is not None:
        lines += ["### The averaged-pulse decay", "", str(dephasing), ""]
    return "\n".join(lines)
