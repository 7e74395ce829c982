"""Multichannel singular spectrum analysis (M-SSA) filter bases and their robust use for
denoising and gap filling (Lou 2012, PhD thesis, ch. 2).

Layout: a motion is a (T, L) array of channels (time along axis 0), NaN where a sample is
missing. A *window* of ``m`` frames starting at frame s is the frame-major vector
``X[s:s+m].ravel()`` of length d = m·L (the thesis' ``x_{s,1:M}``).

- :func:`windows` — every window start as rows of one (S, d) matrix, taken from a
  strided view of X (no Python loop over frames).
- :class:`LagCovariance` — the grand lag-covariance C_D = Σ_w x_w x_wᵀ / S (thesis
  eq. 2.3–2.5), accumulated over several training sequences, centred with the training
  mean; :meth:`LagCovariance.bases` keeps the K leading eigenvectors holding a fraction of
  the energy (99 % in the thesis, §2.3) or K given.
- :func:`robust_reconstruct` — eq. 2.16: minimise
  Σ α ρ(z − y) + λ Σ_s ||z_s − E c_s||² with Welsch ρ(r) = p²/2 (1 − exp(−r²/p²))
  (eq. 2.9) and α = 0 on missing samples, by the thesis' alternation (§2.2.4): all
  windows' coefficients c_s = Eᵀ z_s in one matrix product (eq. 2.13), then the motion
  update of eq. 2.15 per sample — z = (λ Σ_s (E c_s)_t + w y) / (λ·count + w) with the
  IRLS weights w = α exp(−r²/p²) — where the sum over the windows covering a frame is an
  overlap-add.
- :func:`robust_bases` — bases learned from the sequence to be cleaned itself, robustly:
  samples that a running median flags as spikes are replaced by the median before the
  covariance, and the windows the first bases explain worst (the trimmed fraction) are
  dropped before the final fit.
"""
from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import as_strided

from mocapfix.solvers.glitches import despike
from mocapfix.solvers.noise import difference_noise
from mocapfix.solvers.segments import linear_bridge


def windows(X: np.ndarray, m: int, *, step: int = 1) -> np.ndarray:
    """(S, m·L) matrix of the windows of X (T, L) starting every ``step`` frames: row j is
    ``X[j·step : j·step + m].ravel()``. A copy, made from one strided view."""
    X = np.ascontiguousarray(X)
    T, L = X.shape
    S = T - m + 1
    if S <= 0:
        return np.zeros((0, m * L), dtype=X.dtype)
    view = as_strided(X, shape=(S, m * L), strides=(X.strides[0], X.strides[1]), writeable=False)
    return np.array(view[::step])


def overlap_add(R: np.ndarray, T: int, m: int, L: int) -> np.ndarray:
    """Sum of the window reconstructions R (S, m·L), S = T − m + 1 windows starting at
    every frame, into a (T, L) sequence: frame t receives Σ_s R[s, t − s] (inverse of
    :func:`windows`, without the division by the count)."""
    R = R.reshape(-1, m, L)
    S = R.shape[0]
    out = np.zeros((T, L), dtype=R.dtype)
    for k in range(m):
        out[k:k + S] += R[:, k]
    return out


def window_counts(T: int, m: int) -> np.ndarray:
    """Number of windows (starting at every frame) that cover each frame, (T,)."""
    S = max(T - m + 1, 0)
    t = np.arange(T)
    return (np.minimum(t, S - 1) - np.maximum(t - m + 1, 0) + 1).clip(min=0).astype(np.float64)


class LagCovariance:
    """Accumulator of the grand lag-covariance (thesis eq. 2.3) over training sequences.

    ``add`` takes a sequence (T, L) already centred with the training mean; windows with a
    missing sample are left out. ``step`` > 1 takes every step-th window (consecutive
    windows of a densely sampled capture are nearly identical)."""

    def __init__(self, m: int, L: int):
        self.m, self.L = int(m), int(L)
        d = self.m * self.L
        self.sum = np.zeros((d, d))
        self.count = 0

    def add(self, X: np.ndarray, *, step: int = 1, weights: np.ndarray | None = None) -> int:
        """Add the complete windows of X; ``weights`` (S,) per window (0 drops it).
        Returns the number of windows added."""
        W = windows(X, self.m, step=step)
        ok = ~np.isnan(W).any(axis=1)
        if weights is not None:
            ok &= np.asarray(weights)[: len(ok)] > 0
        W = W[ok]
        if weights is not None:
            w = np.sqrt(np.asarray(weights)[: len(ok)][ok])
            W = W * w[:, None]
        if len(W):
            self.sum += W.T @ W
            self.count += len(W)
        return int(len(W))

    def bases(self, *, energy: float = 0.99, k: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(E (d, K), eigenvalues (d,) in decreasing order): the K leading eigenvectors of
        C_D, K given or the smallest holding ``energy`` of the trace (thesis §2.2.1)."""
        if self.count == 0:
            raise ValueError("no complete window to learn filter bases from")
        C = self.sum / self.count
        vals, vecs = np.linalg.eigh(C)
        vals, vecs = np.clip(vals[::-1], 0.0, None), vecs[:, ::-1]
        if k is None:
            total = vals.sum()
            k = 1 if total <= 0 else int(np.searchsorted(np.cumsum(vals) / total, energy) + 1)
        k = int(min(max(k, 1), len(vals)))
        return np.ascontiguousarray(vecs[:, :k]), vals


def unexplained_fraction(eigenvalues: np.ndarray, k: int) -> float:
    """Fraction of the training energy the first k bases leave out."""
    total = float(np.sum(eigenvalues))
    return float(np.sum(eigenvalues[k:]) / total) if total > 0 else 0.0


def projector(E: np.ndarray, m: int, *, dtype=np.float32):
    """The overlap-added projection of every window onto the bases, as a function of Z
    (T, L): ``Z ↦ Σ_s (E Eᵀ z_s)`` placed back at the window's frames (the sum over windows
    of eq. 2.14, before dividing by the count).

    Computed as a multichannel FIR filter: frame t receives Σ_τ H_τ z(t + τ) with
    H_τ = Σ_k E_k E_{k+τ}ᵀ (E_k: the L rows of frame k of a window; |τ| < m), one matrix
    product per lag on a shifted slice of Z for short motions; for long ones by overlap-save
    FFT blocks (one L × L product per frequency) — instead of 2·m·L·K per frame for
    coefficients and reconstructions. The first and last
    m − 1 frames, covered by fewer windows, are computed from their windows directly.
    """
    E = np.asarray(E, dtype=np.float64)
    L = E.shape[0] // m
    G = (E @ E.T).reshape(m, L, m, L)              # G[k, :, k', :] = E_k E_k'ᵀ
    H = np.zeros((2 * m - 1, L, L))
    for k in range(m):
        # H[τ + m − 1] += E_k E_{k+τ}ᵀ for every k' = k + τ in the window
        H[m - 1 - k: 2 * m - 1 - k] += G[k].transpose(1, 0, 2)
    Ht = np.ascontiguousarray(np.transpose(H, (0, 2, 1)), dtype=dtype)     # H_τᵀ, τ = −(m−1) …
    Ed = np.asarray(E, dtype=dtype)
    lags = 2 * m - 1
    # long motions: overlap-save FFT blocks, one L × L product per frequency and block
    n_fft = 1 << int(np.ceil(np.log2(8 * lags)))
    ctype = np.complex64 if np.dtype(dtype) == np.float32 else np.complex128
    Gf = np.fft.rfft(Ht[::-1], n=n_fft, axis=0).astype(ctype)              # (F, L, L)

    def fir(Zp: np.ndarray, T: int) -> np.ndarray:
        """out(t) = Σ_j Zp[t + j] H_jᵀ, t < T (Zp holds T + lags − 1 frames)."""
        if T < 4 * lags:
            out = np.zeros((T, L), dtype=dtype)
            for k in range(lags):
                out += Zp[k:k + T] @ Ht[k]
            return out
        step = n_fft - (lags - 1)
        nb = -(-T // step)
        padded = np.zeros((nb * step + lags - 1, L), dtype=dtype)
        padded[:len(Zp)] = Zp
        blocks = as_strided(padded, shape=(nb, n_fft, L),
                            strides=(step * padded.strides[0],) + padded.strides, writeable=False)
        Xf = np.fft.rfft(blocks, axis=1).astype(ctype).transpose(1, 0, 2)   # (F, nb, L)
        Y = np.fft.irfft(np.matmul(Xf, Gf).transpose(1, 0, 2), n=n_fft, axis=1)
        return Y[:, lags - 1:].reshape(nb * step, L)[:T]

    def project(Z: np.ndarray) -> np.ndarray:
        T = Z.shape[0]
        Zp = np.zeros((T + 2 * (m - 1), L), dtype=dtype)
        Zp[m - 1:m - 1 + T] = Z
        out = np.array(fir(Zp, T), dtype=np.float64)
        edge = min(m - 1, T)
        if edge:
            head = windows(np.asarray(Z[:2 * m - 2], dtype=dtype), m)       # windows 0 … m − 2
            tail = windows(np.asarray(Z[-(2 * m - 2):], dtype=dtype), m)
            out[:edge] = overlap_add((head @ Ed) @ Ed.T, len(head) + m - 1, m, L)[:edge]
            out[T - edge:] = overlap_add((tail @ Ed) @ Ed.T, len(tail) + m - 1, m, L)[-edge:]
        return out

    return project


def robust_reconstruct(Y: np.ndarray, E: np.ndarray, m: int, *, lam: float = 0.1, p: float = 3.0,
                       iterations: int = 15, tol: float = 1e-4, relax: float = 1.8,
                       dtype=np.float32):
    """Robust M-SSA reconstruction (Lou 2012 eq. 2.16, §2.2.4–2.2.5).

    Parameters
    ----------
    Y : (T, L) centred channels, NaN = missing (α = 0 there).
    E : (m·L, K) orthonormal filter bases (frame-major windows).
    lam : λ, the weight of the filter term (thesis: 0.1).
    p : Welsch scale in the units of Y (thesis: 3, degrees).
    iterations : at most this many alternations (thesis: 10–20); stops earlier when the
        largest change of z falls below ``tol`` · p.
    relax : over-relaxation of the update of missing samples (1 = the thesis' update).

    Returns (Z (T, L) filled and filtered, w (T, L) final Welsch weights — 0 on missing
    samples, ≈ 0 on outliers —, iterations run).

    The two steps run on all windows at once: coefficients ``C = W E`` for the (S, d)
    window matrix W, reconstructions ``C Eᵀ``, overlap-added into the frames. Frames near
    the ends are covered by fewer windows (``count``), as in eq. 2.14's min/max bounds.
    """
    Y = np.asarray(Y, dtype=np.float64)
    T, L = Y.shape
    if T < m:
        raise ValueError(f"{T} frames is shorter than the window of {m}")
    alpha = ~np.isnan(Y)
    y0 = np.where(alpha, Y, 0.0)
    Z = linear_bridge(Y)
    count = window_counts(T, m)[:, None]
    w = alpha.astype(np.float64)
    it = 0
    project = projector(E, m, dtype=dtype)
    for it in range(1, iterations + 1):
        acc = project(Z)
        r = Z - y0
        w = np.where(alpha, np.exp(-(r * r) / (p * p)), 0.0)
        Znew = (lam * acc + w * y0) / (lam * count + w)
        # missing samples: over-relaxed projection (the plain one, acc/count, converges
        # slowly across long gaps)
        Znew = np.where(alpha, Znew, Z + relax * (Znew - Z))
        change = float(np.max(np.abs(Znew - Z)))
        Z = Znew
        if change < tol * p:
            break
    return Z, w, it


def channel_noise(X: np.ndarray, *, shape: np.ndarray | None = None) -> np.ndarray:
    """σ̂ of white noise per channel of X (T, L) from its second differences (a second
    difference of white noise has variance 6σ²): :func:`mocapfix.solvers.noise.difference_noise`
    at order 2, ``shape`` as there."""
    return difference_noise(X, 2, shape=shape)


def noise_level(X: np.ndarray, *, shape: np.ndarray | None = None) -> float:
    """σ̂ of white noise on the channels of X (T, L): the median over channels of
    :func:`channel_noise` (``shape`` as there). Channels that never move are left out."""
    per = channel_noise(X, shape=shape)
    per = per[np.isfinite(per) & (per > 0)]
    return float(np.median(per)) if per.size else 0.0


def robust_bases(X: np.ndarray, m: int, *, energy: float = 0.99, k: int | None = None,
                 trim: float = 0.05, step: int = 1, spike_floor: float = 0.0):
    """Filter bases learned from the (centred) sequence X (T, L) itself, robustly.

    1. Samples flagged by :func:`despike` are replaced by their running median and gaps
       are bridged, so that an isolated glitch never becomes a basis.
    2. Bases from every ``step``-th window; the ``trim`` fraction of windows with the
       largest residual outside those bases is dropped and the bases are learned again.

    Returns (E, eigenvalues, windows used)."""
    Xc, _ = despike(X, floor=spike_floor)
    W = windows(Xc, m, step=step)
    if len(W) == 0:
        raise ValueError("no complete window to learn filter bases from")
    E, vals = pca_bases(W, energy=energy, k=k)
    if trim > 0 and len(W) > 20:
        res = W - (W @ E) @ E.T
        err = np.einsum("ij,ij->i", res, res)
        W = W[err <= np.quantile(err, 1.0 - trim)]
        E, vals = pca_bases(W, energy=energy, k=k)
    return E, vals, int(len(W))


def pca_bases(W: np.ndarray, *, energy: float = 0.99, k: int | None = None):
    """Bases of the rows of W (S, d) as :meth:`LagCovariance.bases` would give them,
    through the smaller of the two Gram matrices (S × S when there are fewer windows than
    dimensions)."""
    S, d = W.shape
    if S >= d:
        acc = LagCovariance(1, d)
        acc.sum, acc.count = W.T @ W, S
        return acc.bases(energy=energy, k=k)
    vals, U = np.linalg.eigh(W @ W.T)
    vals, U = np.clip(vals[::-1], 0.0, None), U[:, ::-1]
    total = vals.sum()
    if k is None:
        k = 1 if total <= 0 else int(np.searchsorted(np.cumsum(vals) / total, energy) + 1)
    k = int(min(max(k, 1), int((vals > 1e-12 * max(total, 1e-300)).sum()) or 1))
    E = (W.T @ U[:, :k]) / np.sqrt(np.maximum(vals[:k], 1e-300))
    full = np.zeros(d)
    full[:S] = vals / S
    return np.ascontiguousarray(E), full
