"""``np.median`` of a 1-D array without importing :mod:`numpy.ma`.

``np.median`` checks its result for NaN through ``np.ma.isMaskedArray``,
which imports ``numpy.ma`` (~10 ms) the first time; the command line's run
path needs a handful of medians and nothing else from it."""
from __future__ import annotations

import numpy as np

__all__ = ["median"]


def median(x) -> float:
    """The median of the values of ``x`` as ``np.median`` computes it (the
    mean of the two middle values for an even count; NaN when a value is NaN
    or there is none)."""
    a = np.asarray(x, dtype=float).reshape(-1)
    n = a.size
    if n == 0:
        return float("nan")
    k = n // 2
    p = np.partition(a, k if n % 2 else (k - 1, k))
    if np.isnan(p[-1]):  # NaNs sort last
        return float("nan")
    return float(p[k]) if n % 2 else float((p[k - 1] + p[k]) / 2.0)
