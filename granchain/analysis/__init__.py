"""Statistics of the paper's Sec. IV: decay fits, arrival times, histograms, KS distance.

Everything is re-exported here from the module of its concept:

* ``granchain.analysis.fits`` - :func:`fit_stretched_exp` (v = a exp(-b x^c), paper Fig. 2
  with x = granule k, and its inset with x = time t, parameters a', b', c'); :func:`fit_linear`
  (arrival time versus k, paper Fig. 3: t = 2.402 k - 1.181); :func:`compare_curves` (fitted
  curves, not their strongly correlated parameters); the paper's values :data:`PAPER_FIG2`,
  :data:`PAPER_FIG2_INSET`, :data:`PAPER_FIG3`;
* ``granchain.analysis.distribution`` - :func:`histogram` (arrival-time densities with
  Poisson error bars, paper Fig. 4); :func:`ks_normal` (the KS distance d of the standardised
  sample to N(0, 1), paper Eq. (AD), with a Monte Carlo (Lilliefors) p-value) and
  :func:`ks_distance`; robust statistics: :func:`quantile_skewness`; :func:`format_pvalue`
  (bounds at the Monte Carlo floor);
* observables of an ensemble Dataset (the ``run_ensemble`` store schema) or of the store at a path
  (read with :func:`granchain.open_store`, ``granchain.analysis._read``): the two different
  amplitudes :func:`mean_peak_amplitude` (<max_t v_k>) and :func:`averaged_pulse_peak`
  (max_t <v_k(t)>, the paper's Fig. 2) in ``granchain.analysis.amplitude``, and
  :func:`mean_arrival_time`, :func:`arrival_times`, :func:`out_of_order_peaks` in
  ``granchain.analysis.arrival``;
* ``granchain.analysis.jackknife`` - jackknife errors over blocks of realisations or chunks
  of a store (:func:`block_jackknife`, :class:`ChunkSums`, :func:`chunk_jackknife`);
* ``granchain.analysis.pulsefits`` - the paper's unweighted averaged-pulse fits with them
  (:func:`fit_averaged_decay`, :func:`fit_averaged_arrival`, :func:`paper_curve_agreement`,
  :func:`averaged_peak_gap`);
* :mod:`~granchain.analysis.spacetime` - the averaged pulse as a space-time diagram
  (:func:`averaged_pulse`, :func:`plot_averaged_pulse`).
"""

from __future__ import annotations

# The private names other modules of granchain and its tests use, from before the split.
from ._read import _chain, _dataset, _valid  # noqa: F401
from .amplitude import PerGranule, PulsePeak, averaged_pulse_peak, mean_peak_amplitude, pulse_peak
from .arrival import arrival_times, mean_arrival_time, out_of_order_peaks
from .distribution import (  # noqa: F401
    Histogram,
    KSResult,
    _ks_statistic,
    _ks_upper_bound,
    _null_count,
    format_pvalue,
    histogram,
    ks_distance,
    ks_normal,
    quantile_skewness,
    skewness,
)
from . import fits as _fits
from .fits import (  # noqa: F401
    CurveComparison,
    LinearFit,
    StretchedExpFit,
    _Fit,
    compare_curves,
    fit_linear,
    fit_stretched_exp,
    stretched_exp,
)
from .jackknife import ChunkSums, Jackknife, block_jackknife, block_labels, chunk_jackknife, jackknife_stderr
from .pulsefits import (
    CurveAgreement,
    PulseFit,
    averaged_peak_gap,
    fit_averaged_arrival,
    fit_averaged_decay,
    paper_curve_agreement,
    pulse_jackknife,
    pulse_means,
    rounding_envelope,
)
from .spacetime import AveragedPulse, averaged_pulse, plot_averaged_pulse
from .spacetime import __all__ as _SPACETIME

# The paper's values, defined in granchain.analysis.fits, are described again here: the API reference takes a
# constant's description from the `#:` comment at its assignment in the module it documents (this one).
#: Paper Fig. 2: averaged-pulse peak v_k = a exp(-b k^c), N = 26, fit range about k = 4..25.
PAPER_FIG2 = _fits.PAPER_FIG2
#: Paper Fig. 2 inset: v(t) = a' exp(-b' t^c').
PAPER_FIG2_INSET = _fits.PAPER_FIG2_INSET
#: Paper Fig. 3: (slope, intercept) of t = 2.402 k - 1.181 (arrival of the averaged pulse).
PAPER_FIG3 = _fits.PAPER_FIG3

__all__ = [
    "PAPER_FIG2", "PAPER_FIG2_INSET", "PAPER_FIG3",
    "StretchedExpFit", "LinearFit", "Histogram", "KSResult", "PerGranule", "PulsePeak",
    "CurveComparison", "stretched_exp", "fit_stretched_exp", "fit_linear", "histogram",
    "ks_distance", "ks_normal", "skewness", "quantile_skewness", "format_pvalue", "pulse_peak", "mean_peak_amplitude", "averaged_pulse_peak",
    "mean_arrival_time", "arrival_times", "out_of_order_peaks", "compare_curves",
    # jackknife (granchain.analysis.jackknife) and averaged-pulse fits (granchain.analysis.pulsefits)
    "Jackknife", "ChunkSums", "block_labels", "jackknife_stderr", "block_jackknife", "chunk_jackknife",
    "PulseFit", "CurveAgreement", "pulse_means", "pulse_jackknife", "fit_averaged_decay", "fit_averaged_arrival",
    "paper_curve_agreement", "rounding_envelope", "averaged_peak_gap",
]
__all__ += _SPACETIME  # the averaged pulse as a space-time diagram (granchain.analysis.spacetime)
