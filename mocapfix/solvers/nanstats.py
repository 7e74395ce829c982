"""Column statistics of arrays with NaN for missing values, without numpy's per-column
Python loops."""
from __future__ import annotations

import numpy as np


def nanmedian_columns(x: np.ndarray) -> np.ndarray:
    """``np.nanmedian(x, axis=0)`` (NaN where a column has no number) from one sort with
    NaN last: the middle value, or the mean of the two middle values. numpy's nanmedian
    loops in Python over the columns that hold a NaN (the swaps test's J² columns: ~0.3 s
    a file; a short take's cut detection: most of its cost)."""
    s = np.sort(x, axis=0)
    n = (~np.isnan(x)).sum(axis=0)
    lo = np.take_along_axis(s, np.maximum((n - 1) // 2, 0)[None], axis=0)[0]
    hi = np.take_along_axis(s, np.minimum(n // 2, len(x) - 1)[None], axis=0)[0]
    with np.errstate(invalid="ignore"):
        return np.where(n > 0, (lo + hi) / 2, np.nan)
