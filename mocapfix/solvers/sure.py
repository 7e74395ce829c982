"""Per-channel smoothing chosen by Stein's unbiased risk estimate (SURE; Stein 1981).

For a linear smoother z = S y of a channel y = x + e with white noise e ~ N(0, σ²),
``SURE = ||y − S y||² − T σ² + 2 σ² tr(S)`` is an unbiased estimate of ||z − x||². For a
Gaussian kernel of width s (samples), tr(S) ≈ T · g_s(0) (the kernel's centre weight), so
the risk of every width in a family costs one filtering pass; each channel takes the width
of least risk. σ is estimated from the data (:func:`mocapfix.solvers.ssa.noise_level`:
median absolute second difference), so the choice adapts to each channel's motion and
to the noise, without a cut-off to tune.
"""
from __future__ import annotations

import numpy as np

#: Gaussian widths tried, in samples (0.7 … 48)
WIDTHS = (0.7, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0, 16.0, 24.0, 32.0, 48.0)


def centre_weight(sigma: float) -> float:
    """g_σ(0) of the discrete Gaussian filter ``ndimage.gaussian_filter1d`` applies."""
    n = int(4 * sigma + 2)
    impulse = np.zeros(2 * n + 1)
    impulse[n] = 1.0
    from scipy import ndimage  # imported here: not loaded unless needed
    return float(ndimage.gaussian_filter1d(impulse, sigma)[n])


def sure_gaussian(X: np.ndarray, noise: float, *, widths=WIDTHS, max_width: float | None = None,
                  span: float | None = None):
    """Each column of X (T, C, no NaN) Gaussian-smoothed with the width of least SURE
    (σ = ``noise``). ``max_width`` caps the widths (samples). ``span`` (samples): choose
    per sample instead, by the risk summed over a Gaussian neighbourhood of that width
    (the width then varies along the motion: short in a fast turn, long in a hold).
    Returns (Z, widths (C,) — with ``span``, the median width per column)."""
    X = np.asarray(X, dtype=np.float64)
    T = X.shape[0]
    best = X.copy()
    s2 = noise ** 2
    shape = X.shape if span else X.shape[1:]
    chosen = np.zeros(shape)
    risk = np.full(shape, (1 if span else T) * s2)     # the identity: SURE = −σ² + 2σ² per sample
    for w in widths:
        if max_width is not None and w > max_width:
            break
        from scipy import ndimage  # imported here: not loaded unless needed
        Z = ndimage.gaussian_filter1d(X, w, axis=0, mode="nearest")
        if span:
            r = ndimage.gaussian_filter1d((X - Z) ** 2 - s2 + 2 * s2 * centre_weight(w), span, axis=0,
                                          mode="nearest")
        else:
            r = np.sum((X - Z) ** 2, axis=0) - T * s2 + 2 * s2 * T * centre_weight(w)
        better = r < risk
        if span:
            best[better] = Z[better]
        else:
            best[:, better] = Z[:, better]
        chosen[better] = w
        risk[better] = r[better]
    return best, (np.median(chosen, axis=0) if span else chosen)
