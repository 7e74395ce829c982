"""Weighted local polynomial regression by convolution (Savitzky & Golay 1964 with
weights; the robust, iteratively reweighted form is LOESS, Cleveland 1979).

For every sample ``t`` a polynomial of degree ``d`` in the offset ``u = i / half``
(``|i| <= half``) is fitted by weighted least squares to the samples around ``t`` and
evaluated at ``u = 0``. All the normal-equation moments ``Σ_i K_i w_{t+i} u^k`` and
``Σ_i K_i w_{t+i} x_{t+i} u^k`` are correlations along time, so a whole (T, J, D) array
is fitted with ``2d + 1 + (d + 1)`` calls of :func:`scipy.ndimage.correlate1d` and one
batched (d+1)×(d+1) solve per sample — no loop over frames or channels.
"""
from __future__ import annotations

import numpy as np


def local_polyfit(x: np.ndarray, w: np.ndarray, half: int, degree: int = 2,
                  leave_out: bool = True,
                  ridge: float = 1e-10) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Local weighted polynomial prediction of every sample.

    Parameters
    ----------
    x : (T, J, D) values; NaN entries must have weight 0 (they are ignored).
    w : (T, J) weights in [0, 1] shared by the D coordinates of a point (0 = ignore).
    half : half-width of the window in samples (window ``2 half + 1``).
    degree : polynomial degree (2 = local quadratic: unbiased for constant acceleration).
    leave_out : exclude the sample itself from its own fit (a prediction; a spike then
        shows its full size in ``x − fit`` whatever its weight).
    ridge : Tikhonov term on the non-constant coefficients, relative to the window's total
        weight, so that windows with fewer than ``degree + 1`` usable samples still give a
        (lower-order) fit.

    Returns
    -------
    fit : (T, J, D) fitted values (NaN where the window holds no usable sample).
    leverage : (T, J) ``e₀ᵀ M⁻¹ e₀`` — the variance of the fit in units of the noise
        variance (exact for 0/1 weights); a residual ``x − fit`` of a leave-one-out fit has
        variance ``σ² (1 + leverage)``.
    support : (T, J) total weight in the window.
    """
    x = np.asarray(x, dtype=np.float64)
    T, J, D = x.shape
    w = np.where(np.isnan(x).any(axis=2), 0.0, np.asarray(w, dtype=np.float64))
    xw = np.where(w[..., None] > 0, x, 0.0) * w[..., None]
    # the window is cut at T - 1 samples each side (farther taps only meet the zero
    # padding), so the kernels and their cost stay O(T) whatever ``half`` is
    reach = max(0, min(int(half), T - 1))
    offsets = np.arange(-reach, reach + 1)
    u = offsets / float(max(reach, 1))
    kernel = np.ones(2 * reach + 1)
    if leave_out:
        kernel[reach] = 0.0
    n = degree + 1
    from scipy import ndimage  # imported here: not loaded unless needed
    S = np.stack([ndimage.correlate1d(w, kernel * u ** k, axis=0, mode="constant")
                  for k in range(2 * degree + 1)], axis=-1)                    # (T, J, 2d+1)
    R = np.stack([ndimage.correlate1d(xw, kernel * u ** k, axis=0, mode="constant")
                  for k in range(n)], axis=2)                                    # (T, J, n, D)
    support = S[..., 0]
    reg = ridge * np.maximum(support, 1e-12)
    idx = np.add.outer(np.arange(n), np.arange(n))
    M = S[..., idx]                                                              # (T, J, n, n)
    M[..., np.arange(1, n), np.arange(1, n)] += reg[..., None]
    empty = support <= 1e-9                      # no usable sample (weights are in [0, 1])
    M[..., 0, 0] += np.where(empty, 1.0, 0.0)
    e0 = np.zeros((T, J, n, 1))
    e0[..., 0, 0] = 1.0
    z = np.linalg.solve(M, e0)[..., 0]                                           # (T, J, n)
    fit = np.einsum("tjk,tjkd->tjd", z, R)
    fit[empty] = np.nan
    return fit, z[..., 0], np.where(empty, 0.0, support)


_MEDIAN_BLOCK = 1 << 22  # values sorted at once by moving_median (32 MiB of float64)


def moving_median(x: np.ndarray, half: int) -> np.ndarray:
    """Median over the ``2 half + 1`` samples centred on each sample, along axis 0,
    ignoring NaN (windows are truncated at the ends; a window with no value gives NaN).

    Sorting a strided (T, ..., 2 half + 1) view puts NaN last; the median is then read at
    the middle of each window's valid count — no Python loop, no ``nanmedian`` overhead.
    """
    from numpy.lib.stride_tricks import sliding_window_view

    x = np.asarray(x, dtype=np.float64)
    T = x.shape[0]
    if half < 1 or T == 0:
        return x.copy()
    half = min(int(half), T - 1) if T > 1 else 0  # farther samples are NaN padding
    if half < 1:
        return x.copy()
    pad = [(half, half)] + [(0, 0)] * (x.ndim - 1)
    view = sliding_window_view(np.pad(x, pad, constant_values=np.nan), 2 * half + 1, axis=0)
    # sorted windows are (rows, ..., 2 half + 1): done in blocks of rows so that memory
    # stays bounded (about _MEDIAN_BLOCK values) however wide the window is
    per_row = max(1, view[:1].size)
    step = max(1, _MEDIAN_BLOCK // per_row)
    out = np.empty(x.shape)
    for start in range(0, T, step):
        block = view[start:start + step]
        srt = np.sort(block, axis=-1)
        n = np.sum(~np.isnan(block), axis=-1)
        lo = np.take_along_axis(srt, np.maximum((n - 1) // 2, 0)[..., None], axis=-1)[..., 0]
        hi = np.take_along_axis(srt, np.maximum(n // 2, 0)[..., None], axis=-1)[..., 0]
        out[start:start + step] = np.where(n > 0, 0.5 * (lo + hi), np.nan)
    return out
