"""DCT-diagonalised smoothness operators for the TSMC family (Feng et al. 2014; Garcia 2010).

Layout: ``x`` is (T, C) — time along axis 0, one column per channel — unless an ``axis``
argument says otherwise. Nothing here builds a T×T matrix.

The operator ``O`` of Feng et al. 2014, eq. (6), is the second difference with repeated
borders (rows ``[-1 1 0 …]``, ``[1 -2 1 …]``, …, ``[… 1 -1]``). It is symmetric and is
diagonalised by the orthonormal DCT-II (Strang 1999, "The discrete cosine transform";
Garcia 2010, "Robust smoothing of gridded data in one and higher dimensions with missing
values", CSDA 54:1167): ``O = Cᵀ diag(λ) C`` with

    λ_k = −2 + 2 cos(π k / n),   k = 0 … n−1,

so ``OᵀO = OOᵀ = Cᵀ diag(λ²) C`` and

    (I + μ OᵀO)⁻¹ y   = idct( dct(y) / (1 + μ λ²) )          (Feng 2014 eq. 14)
    z (β OOᵀ + λ2 I)⁻¹ = idct( dct(z) / (β λ² + λ2) )          (Feng 2014 Alg. 2 step 7)

— one DCT, a division and one inverse DCT, O(n log n) per channel, all channels at once.

The repeated-border condition makes the smoother's solution flat at the ends (zero first
difference in the last row of ``O``). :func:`pad` therefore extends each channel before a
DCT step — by point reflection of a complete channel (value and slope continuous), or with
samples marked missing for the weighted solvers — and :func:`unpad` removes it.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from mocapfix.solvers.segments import extend, linear_bridge


def eigenvalues(n: int) -> np.ndarray:
    """Eigenvalues ``λ_k = −2 + 2 cos(π k / n)`` of the n×n repeated-border second-difference
    matrix ``O`` (Feng 2014 eq. 6), in DCT-II order (k = 0 … n−1)."""
    return -2.0 + 2.0 * np.cos(np.pi * np.arange(n) / n)


def _shape(lam: np.ndarray, ndim: int, axis: int) -> np.ndarray:
    shape = [1] * ndim
    shape[axis] = lam.size
    return lam.reshape(shape)


@lru_cache(maxsize=8)
def _twiddle(n: int) -> np.ndarray:
    """``exp(−iπk / 2n)`` times the orthonormal scale ``√(2/n)`` (``√(1/n)`` at k = 0),
    k = 0 … n//2."""
    w = np.exp(-0.5j * np.pi * np.arange(n // 2 + 1) / n) * np.sqrt(2.0 / n)
    w[0] *= np.sqrt(0.5)
    w.setflags(write=False)
    return w


def _dct_rows(x: np.ndarray) -> np.ndarray:
    """Orthonormal DCT-II along the last axis by one real FFT of length n (Makhoul 1980,
    "A fast cosine transform in one and two dimensions", IEEE TASSP 28(1): the even
    samples in order, then the odd ones reversed; ``X_k = Re(e^{−iπk/2n} V_k)``, and
    ``X_{n−k} = −Im(e^{−iπk/2n} V_k)``). numpy's FFT: no scipy import on the default path."""
    n = x.shape[-1]
    h, m = n // 2 + 1, (n + 1) // 2
    v = np.empty(x.shape)
    v[..., :m] = x[..., ::2]
    v[..., m:] = x[..., 1::2][..., ::-1]
    spec = np.fft.rfft(v, axis=-1)
    spec *= _twiddle(n)
    out = v                                         # reused: v is not needed any more
    out[..., :h] = spec.real
    out[..., h:] = spec.imag[..., n - h:0:-1]
    out[..., h:] *= -1.0
    return out


def _idct_rows(y: np.ndarray) -> np.ndarray:
    """Inverse of :func:`_dct_rows` (orthonormal DCT-III): ``V_k = e^{iπk/2n} (X_k − i
    X_{n−k})`` (X_n = 0) unscaled, one inverse real FFT, samples put back in order."""
    n = y.shape[-1]
    h, m = n // 2 + 1, (n + 1) // 2
    spec = np.empty(y.shape[:-1] + (h,), dtype=np.complex128)
    spec.real = y[..., :h]
    spec.imag[..., 0] = 0.0
    spec.imag[..., 1:] = y[..., n - 1:n - h:-1]
    spec.imag[..., 1:] *= -1.0
    tw = _twiddle(n)
    spec *= np.conj(tw) / (tw.real ** 2 + tw.imag ** 2)
    v = np.fft.irfft(spec, n=n, axis=-1)
    out = np.empty(y.shape)
    out[..., ::2] = v[..., :m]
    out[..., 1::2] = v[..., m:][..., ::-1]
    return out


def _along_rows(transform, x, axis):
    """``transform`` (along the last axis) along ``axis`` of ``x``; a (T, C) array
    transformed along axis 0 is transformed as its transpose along contiguous rows and
    returned as a (T, C) view of the result."""
    x = np.asarray(x, dtype=np.float64)
    axis = axis % max(x.ndim, 1)
    if x.ndim == 2 and axis == 0 and x.shape[1] > 1:
        return transform(np.ascontiguousarray(x.T)).T
    if axis == x.ndim - 1:
        return transform(x)
    return np.moveaxis(transform(np.moveaxis(x, axis, -1)), -1, axis)


def dct(x: np.ndarray, axis: int = 0) -> np.ndarray:
    """Orthonormal DCT-II along ``axis``."""
    return _along_rows(_dct_rows, x, axis)


def idct(x: np.ndarray, axis: int = 0) -> np.ndarray:
    """Inverse of :func:`dct`."""
    return _along_rows(_idct_rows, x, axis)


def smoother(y: np.ndarray, mu, axis: int = 0) -> np.ndarray:
    """``(I + μ OᵀO)⁻¹ y`` along ``axis`` (Feng 2014 eq. 14; Garcia 2010 eq. 7).

    Parameters
    ----------
    y : array, any shape; the operator acts along ``axis``.
    mu : scalar, or an array broadcastable against ``y`` with ``axis`` removed (one μ per
        channel), μ ≥ 0.

    Returns
    -------
    Array of ``y``'s shape.
    """
    y = np.asarray(y, dtype=np.float64)
    axis = axis % y.ndim
    lam2 = _shape(eigenvalues(y.shape[axis]) ** 2, y.ndim, axis)
    mu = np.expand_dims(np.asarray(mu, dtype=np.float64), axis) if np.ndim(mu) else mu
    return idct(dct(y, axis) / (1.0 + mu * lam2), axis)


def penalty_solve(z: np.ndarray, beta: float, lam: float, axis: int = 0) -> np.ndarray:
    """``(β OOᵀ + λ I)⁻¹`` applied along ``axis`` of ``z`` (Feng 2014 eq. A.13: with the
    channels as rows, ``M = Z (β OOᵀ + λ I)⁻¹`` is this operator on every row, O being
    symmetric). Parameters: β ≥ 0, λ > 0."""
    z = np.asarray(z, dtype=np.float64)
    axis = axis % z.ndim
    lam2 = _shape(eigenvalues(z.shape[axis]) ** 2, z.ndim, axis)
    return idct(dct(z, axis) / (beta * lam2 + lam), axis)


# -- generalised cross-validation ------------------------------------------------------

LOG_MU_GRID = np.arange(-3.0, 10.01, 0.25)


def gcv_mu(y: np.ndarray | None, n_eff: np.ndarray | None = None,
           log_mu: np.ndarray = LOG_MU_GRID,
           spectrum: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per-channel smoothing parameter by generalised cross-validation (Craven & Wahba
    1979; Feng 2014 eqs. 16–18; Garcia 2010 eq. 9) for the smoother :func:`smoother` on the
    complete (T, C) data ``y``.

    With ``Γ_k(μ) = 1 / (1 + μ λ_k²)`` and ``ŷ = dct(y)``, the residual sum of squares is
    ``Σ_k (1 − Γ_k)² ŷ_k²`` and ``tr H = Σ_k Γ_k``, so

        GCV(μ) = RSS / n_eff  /  (1 − tr H / n)²

    is evaluated on a grid of log10 μ for all channels with one matrix product, then
    refined per channel by a parabola through the best grid point and its neighbours.
    ``n_eff`` (C,) is the number of observed samples (eq. 17's n − n_s; default n) — it
    scales GCV per channel and does not move its minimum, kept for the reported score.

    ``spectrum`` = ``dct(y)`` when the caller has it already (``y`` may then be None).

    Returns ``(mu, score)``, both (C,).
    """
    if spectrum is None:
        spectrum = dct(np.asarray(y, dtype=np.float64))
    n = spectrum.shape[0]
    mu = 10.0 ** np.asarray(log_mu)
    damp2, denom = _gcv_tables(n, tuple(np.asarray(log_mu, dtype=np.float64).tolist()))
    power = spectrum ** 2                                       # (n, C)
    rss = power.T @ damp2                                       # (C, m)
    with np.errstate(divide="ignore", invalid="ignore"):
        score = rss / np.where(denom > 0, denom, np.nan)[None, :]
    score = np.where(np.isfinite(score), score, np.inf)
    best = np.argmin(score, axis=1)
    # parabolic refinement in log μ (grid is uniform)
    i = np.clip(best, 1, len(mu) - 2)
    s0, s1, s2 = (score[np.arange(len(i)), i + d] for d in (-1, 0, 1))
    step = log_mu[1] - log_mu[0]
    curv = s0 - 2 * s1 + s2
    with np.errstate(divide="ignore", invalid="ignore"):
        offset = np.where((curv > 0) & np.isfinite(curv), 0.5 * (s0 - s2) / curv, 0.0)
    offset = np.clip(offset, -1.0, 1.0)
    refined = np.where((best == i), log_mu[i] + offset * step, log_mu[best])
    n_eff = np.full(spectrum.shape[1], n) if n_eff is None else np.asarray(n_eff)
    return 10.0 ** refined, score[np.arange(len(best)), best] / np.maximum(n_eff, 1)


@lru_cache(maxsize=8)
def _gcv_tables(n: int, log_mu: tuple) -> tuple[np.ndarray, np.ndarray]:
    """For :func:`gcv_mu`: ``(1 − Γ)²`` (n, m) and ``(1 − tr H / n)²`` (m,) on the grid
    (they depend on n and the grid only; the robust smoother asks for them every step)."""
    lam2 = eigenvalues(n) ** 2
    mu = 10.0 ** np.asarray(log_mu)
    gamma = 1.0 / (1.0 + lam2[:, None] * mu[None, :])            # (n, m)
    damp2 = (1.0 - gamma) ** 2
    denom = (1.0 - gamma.sum(axis=0) / n) ** 2
    damp2.setflags(write=False)
    denom.setflags(write=False)
    return damp2, denom


def gcv_smooth(y: np.ndarray, n_pad: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Smooth every complete column of ``y`` (T, C) by :func:`smoother` with its own
    GCV-chosen μ, after point-reflection padding of ``n_pad`` samples at each end (so the
    repeated-border condition does not flatten the ends). Returns ``(smoothed, mu)``."""
    yp, p = pad_reflect(y, n_pad)
    mu, _ = gcv_mu(yp)
    return unpad(smoother(yp, mu), p), mu


# -- weighted robust smoothing (Algorithm 1 of Feng 2014) --------------------------------

def robust_smooth(x: np.ndarray, weights: np.ndarray, scale: np.ndarray,
                  iterations: int = 8, mu: np.ndarray | None = None,
                  init: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Robust penalised least squares per channel (Feng 2014 Algorithm 1, eqs. 12–18;
    Garcia 2010 §3–4):

        x̂ ← (I + μ OᵀO)⁻¹ ( G (x − x̂) + x̂ ),   G = w · exp(−r² / p²)

    Parameters
    ----------
    x : (n, C) data; NaN = missing (weight 0).
    weights : (n, C) prior weights in [0, 1] (0 = missing / not to be used; the reader's
        confidence goes here).
    scale : (C,) Welsch scale ``p`` per channel (Feng uses 5 cm).
    iterations : robust re-weighting steps; μ is re-chosen by GCV at each step on the
        pseudo-data ``G (x − x̂) + x̂`` (Garcia's device: with the weights folded into the
        pseudo-data the complete-data GCV of :func:`gcv_mu` applies).
    mu : fixed (C,) μ instead of GCV.
    init : (n, C) complete initial guess (default: linear interpolation, ends held).

    Returns
    -------
    (x̂, mu, G): the smooth (n, C), the last μ per channel and the last weights.
    """
    x = np.asarray(x, dtype=np.float64)
    w = np.where(np.isnan(x), 0.0, np.asarray(weights, dtype=np.float64))
    x0 = np.where(w > 0, x, 0.0)
    xhat = linear_bridge(np.where(w > 0, x, np.nan)) if init is None else np.array(init, dtype=np.float64)
    n_obs = (w > 0).sum(axis=0)
    p2 = np.maximum(np.asarray(scale, dtype=np.float64), 1e-300)[:, None] ** 2
    fixed = mu is not None
    # the iteration runs on the transposes (C, n): every channel a contiguous row, where
    # the DCT is ~2x faster and no array changes memory order
    wT, x0T, xhat = (np.ascontiguousarray(a.T) for a in (w, x0, xhat))
    g = wT.copy()
    r = np.empty_like(g)
    lam2 = eigenvalues(x.shape[0])[None, :] ** 2
    for _ in range(max(1, iterations)):
        # in place (the same operations as g = w·exp(−r²/p²), pseudo = g·r + x̂): large
        # temporaries cost page faults
        np.subtract(x0T, xhat, out=r)
        np.multiply(r, r, out=g)
        np.negative(g, out=g)
        np.divide(g, p2, out=g)
        np.exp(g, out=g)
        g *= wT
        r *= g
        r += xhat                           # the pseudo-data
        spectrum = dct(r, axis=1)           # shared by GCV and the smoother
        if not fixed:
            mu, _ = gcv_mu(None, n_obs, spectrum=spectrum.T)
        denom = np.multiply(np.asarray(mu)[..., None], lam2)
        denom += 1.0
        spectrum /= denom
        xhat = idct(spectrum, axis=1)
    return (np.ascontiguousarray(xhat.T), np.asarray(mu, dtype=np.float64) * np.ones(x.shape[1]),
            np.ascontiguousarray(g.T))


# -- padding and initial fills -------------------------------------------------------------

def pad_reflect(x: np.ndarray, n_pad: int) -> tuple[np.ndarray, int]:
    """Point-reflect a complete (T, C) array by up to ``n_pad`` samples at each end
    (``2 x[0] − x[i]``: value and slope continuous; :func:`segments.extend`)."""
    if n_pad <= 0 or x.shape[0] < 2:
        return np.asarray(x, dtype=np.float64), 0
    return extend(np.asarray(x, dtype=np.float64), n_pad)


def fast_pad(n: int, n_pad: int, search: int | None = None) -> int:
    """The smallest padding ``p >= n_pad`` (at most ``n_pad + search``, default
    max(64, n/20): at most ~10 % more samples) for which the padded length ``n + 2p`` has
    no prime factor above 5, where the DCT is fastest (4,600 → 4,608 frames: 2.9 → 2.2 ms
    for 123 channels); ``n_pad`` itself when none is in reach."""
    search = max(64, n // 20) if search is None else search
    for p in range(n_pad, n_pad + search + 1):
        m = n + 2 * p
        for f in (2, 3, 5):
            while m % f == 0:
                m //= f
        if m == 1:
            return p
    return n_pad


def pad_missing(x: np.ndarray, n_pad: int) -> tuple[np.ndarray, int]:
    """Add ``n_pad`` missing (NaN) samples at each end of (T, C) ``x``: for the weighted
    solvers, which then extrapolate by their own model instead of a flat border."""
    if n_pad <= 0:
        return np.asarray(x, dtype=np.float64), 0
    nan = np.full((n_pad,) + x.shape[1:], np.nan)
    return np.concatenate([nan, x, nan], axis=0), n_pad


def unpad(x: np.ndarray, p: int) -> np.ndarray:
    """Remove ``p`` samples added at each end by :func:`pad_reflect` / :func:`pad_missing`."""
    return x[p:x.shape[0] - p] if p else x
