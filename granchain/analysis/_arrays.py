"""Read-only arrays for the results of :mod:`granchain.analysis`.

Every result record (a fit, a histogram, a per-granule statistic) holds its arrays frozen, so that a
result handed out cannot be edited afterwards and silently disagree with its own summary.
"""

from __future__ import annotations

import numpy as np


def _frozen(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a
