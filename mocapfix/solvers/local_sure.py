"""Locally adaptive smoothing strength for the DCT smoother: the strength chosen per sample
by Stein's unbiased risk estimate (SURE; Stein 1981), summed over a window of the signal —
the local bandwidth choice of e.g. Donoho & Johnstone 1995 — instead of one GCV strength for
the whole channel.

A motion is slow in some parts and fast in others (a dancer holding a pose, then stepping):
one smoothing strength per channel (:func:`mocapfix.solvers.dct.gcv_smooth`) blurs the fast
parts or leaves noise on the slow ones. :func:`local_sure_smooth` smooths every channel
with the GCV strength μ times each of a few ``multipliers`` g (one inverse DCT each),
estimates for every sample the risk of each output by SURE with the white-noise level σ²
of the channel,

    r_g(t) = (y_t − ẑ_g,t)² + σ² (2 h̄_g − 1),   h̄_g = mean_k 1 / (1 + g μ λ_k²)

(h̄_g is the diagonal of the smoother matrix, constant along time for this shift-invariant
smoother up to the padded ends; λ_k the eigenvalues of Garcia 2010 eq. 7), sums it over a
triangular window in time and over the channels of one ``group`` (x, y, z of a joint share
their dynamics), and keeps per sample the output of least risk — its log multiplier
smoothed in time and the outputs interpolated between neighbouring multipliers, so the
result is a smooth blend of linear smoothers. Cost: ``len(multipliers)`` + 1 transforms
per call against GCV's 2.
"""
from __future__ import annotations

import numpy as np

from mocapfix.solvers.dct import dct, eigenvalues, gcv_mu, idct, pad_reflect, unpad

#: strength multipliers around the GCV choice (× e^-1.5, 1, e^1.5)
MULTIPLIERS = np.exp(np.array([-1.5, 0.0, 1.5]))


def local_sure_smooth(y: np.ndarray, sigma2: np.ndarray, *, width: float, n_pad: int = 0,
                      group: int = 1, multipliers: np.ndarray = MULTIPLIERS) -> tuple[np.ndarray, np.ndarray]:
    """Smooth the complete columns of ``y`` (T, C) with a strength chosen per sample (see the
    module docstring). ``sigma2`` (C,) is the white-noise variance of each column,
    ``width`` the length in samples of the (triangular) window the risk is summed over,
    ``group`` the number of consecutive columns that share one choice (C must be a
    multiple of it). Returns ``(smoothed, mu)``, μ the GCV strength per column."""
    from scipy.ndimage import uniform_filter1d   # imported here: not loaded unless used

    yp, p = pad_reflect(y, n_pad)
    n, C = yp.shape
    T, G, Cg = y.shape[0], len(multipliers), C // group
    mu, _ = gcv_mu(yp)
    lam2 = eigenvalues(n)[:, None] ** 2
    Y = dct(yp, 0)
    s2 = np.asarray(sigma2, dtype=float)
    box = max(1, int(round(width / 2)))     # two boxes of width/2: a triangle of ``width``
    outs = np.empty((G, T, C))
    risk = np.empty((G, T, Cg))
    for i, g in enumerate(multipliers):
        h = 1.0 / (1.0 + (g * mu)[None, :] * lam2)
        outs[i] = unpad(idct(Y * h, 0), p)
        r = y - outs[i]
        r *= r
        r += s2 * (2.0 * h.mean(axis=0) - 1.0)
        r = r.reshape(T, Cg, group).sum(axis=2)
        risk[i] = uniform_filter1d(uniform_filter1d(r, box, axis=0, mode="nearest"), box, axis=0, mode="nearest")
    logs = np.log(multipliers)
    pick = uniform_filter1d(logs[np.argmin(risk, axis=0)], max(1, int(round(width / 4))), axis=0,
                            mode="nearest")
    at = np.interp(pick, logs, np.arange(G))
    out = np.zeros((T, Cg, group))
    for i in range(G):
        wi = np.maximum(1.0 - np.abs(at - i), 0.0)
        if wi.any():
            out += wi[..., None] * outs[i].reshape(T, Cg, group)
    out = out.reshape(T, C)
    return out, mu
