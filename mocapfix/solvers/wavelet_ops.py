"""Orthonormal discrete wavelet transform along time, as a linear operator ``W`` with
``Wᵀ W = I``, for the wavelet-sparsity prior ``μ ||W A||₁`` of Yang et al. 2019 (IEEE TIP,
"Spatio-temporal reconstruction for 3D motion recovery", eq. 6 and the A-subproblem,
eqs. 13–14, which needs an orthonormal ``W``).

An orthogonal Daubechies filter bank with periodic extension (``pywt`` mode
``'periodization'``) is an orthonormal transform of R^n when n is divisible by 2^L
(L = number of levels): the coefficient vector has exactly n entries and the inverse is the
transpose (Mallat, *A Wavelet Tour of Signal Processing*, §7.5.1). Other lengths are handled
by **pad and mask**: the time axis is padded to ``padded_length(T, L)`` frames and the solver
treats the padded frames as unobserved samples (see :func:`pad_time` and
:func:`mocapfix.solvers.isometry` users). On the padded length ``W`` is square and
orthonormal (``WᵀW = WWᵀ = I``); seen as an operator on the unpadded signal,
``crop ∘ Wᵀ ∘ W ∘ zero-pad`` is the identity too (:func:`forward_padded`/
:func:`adjoint_padded`), which is what tests check numerically.

Layout: arrays are (T, ...) with time on ``axis`` (default 0); every other index is an
independent channel. Coefficients are returned as one array of the same shape, the levels
concatenated along the time axis as ``[cA_L, cD_L, cD_{L-1}, …, cD_1]`` (``pywt.wavedec``
order), so shrinkage and the ALM multipliers act on plain arrays.
"""
from __future__ import annotations

import warnings

import numpy as np

MODE = "periodization"


def padded_length(n: int, level: int) -> int:
    """The smallest multiple of ``2**level`` that is ``>= n`` (and ``>= 2**level``)."""
    step = 1 << int(level)
    return max(step, -(-int(n) // step) * step)


def check_wavelet(wavelet: str):
    """The ``pywt.Wavelet`` named ``wavelet``; raises ValueError unless it is orthogonal
    (only orthogonal filter banks give ``WᵀW = I``)."""
    import pywt  # imported here: listing the cleaners must not load PyWavelets

    if wavelet not in pywt.wavelist(kind="discrete"):
        raise ValueError(f"unknown wavelet {wavelet!r}")
    w = pywt.Wavelet(wavelet)
    if not w.orthogonal:
        raise ValueError(f"wavelet {wavelet!r} is not orthogonal (WᵀW = I needs an orthogonal one)")
    return w


def forward(x: np.ndarray, wavelet: str = "db10", level: int = 2, axis: int = 0) -> np.ndarray:
    """``W x``: the L-level orthonormal DWT along ``axis`` (length divisible by 2^L).

    Parameters
    ----------
    x : array, time along ``axis``; its length must be a multiple of ``2**level``.
    wavelet : an orthogonal ``pywt`` wavelet name (Yang 2019: a Daubechies wavelet).
    level : number of levels L (Yang 2019: J = 2).

    Returns
    -------
    Array of ``x``'s shape: the coefficients ``[cA_L, cD_L, …, cD_1]`` along ``axis``.
    """
    import pywt

    x = np.asarray(x, dtype=np.float64)
    n = x.shape[axis]
    if n % (1 << level):
        raise ValueError(f"length {n} is not a multiple of 2^{level}; pad it (pad_time)")
    with warnings.catch_warnings():
        # pywt warns when the filter is longer than a level's signal; with periodization
        # the transform is still exact and orthonormal (the filter wraps around)
        warnings.simplefilter("ignore", UserWarning)
        coeffs = pywt.wavedec(x, wavelet, mode=MODE, level=level, axis=axis)
    return np.concatenate(coeffs, axis=axis)


def _split_sizes(n: int, level: int) -> list[int]:
    """Lengths of ``[cA_L, cD_L, …, cD_1]`` for a length-n periodized transform."""
    sizes = [n >> k for k in range(level, 0, -1)]
    return [sizes[0]] + sizes


def inverse(c: np.ndarray, wavelet: str = "db10", level: int = 2, axis: int = 0) -> np.ndarray:
    """``Wᵀ c`` (= ``W⁻¹ c``): the inverse of :func:`forward`, same layout."""
    import pywt

    c = np.asarray(c, dtype=np.float64)
    n = c.shape[axis]
    if n % (1 << level):
        raise ValueError(f"length {n} is not a multiple of 2^{level}")
    bounds = np.cumsum(_split_sizes(n, level))[:-1]
    coeffs = np.split(c, bounds, axis=axis)
    out = pywt.waverec(coeffs, wavelet, mode=MODE, axis=axis)
    return out


def pad_time(x: np.ndarray, level: int, axis: int = 0, fill: float = np.nan, margin: int = 0):
    """Pad ``x`` along ``axis`` with ``fill`` (NaN: "unobserved") to
    ``padded_length(n + margin, level)`` frames.

    Returns (padded array, mask) where ``mask`` (length of the padded axis) is True on
    the original frames. The pad goes at the end; a solver treats those frames as missing
    samples, so the transform stays square and orthonormal. A ``margin`` of about the
    filter length lets the periodic wrap (last frame → first frame) fall in frames the
    solver is free to fill smoothly, instead of a jump that the sparsity prior would
    smear into both ends of the capture."""
    x = np.asarray(x, dtype=np.float64)
    n = x.shape[axis]
    m = padded_length(n + int(margin), level)
    mask = np.zeros(m, dtype=bool)
    mask[:n] = True
    if m == n:
        return x.copy(), mask
    widths = [(0, 0)] * x.ndim
    widths[axis] = (0, m - n)
    return np.pad(x, widths, mode="constant", constant_values=fill), mask


def forward_padded(x: np.ndarray, wavelet: str = "db10", level: int = 2, axis: int = 0) -> np.ndarray:
    """``W x`` for any length: zero-pad to a multiple of 2^L, then :func:`forward`.
    The result has ``padded_length`` entries along ``axis``; :func:`adjoint_padded` is its
    transpose and ``adjoint_padded(forward_padded(x)) == x``."""
    xp, _ = pad_time(x, level, axis=axis, fill=0.0)
    return forward(xp, wavelet, level, axis)


def adjoint_padded(c: np.ndarray, n: int, wavelet: str = "db10", level: int = 2, axis: int = 0) -> np.ndarray:
    """``Wᵀ c`` for :func:`forward_padded`: inverse transform, then keep the first ``n``
    frames (the transpose of zero-padding is cropping)."""
    full = inverse(c, wavelet, level, axis)
    return np.take(full, np.arange(n), axis=axis)
