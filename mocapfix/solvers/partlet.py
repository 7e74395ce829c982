"""Partlet dictionary denoising (Feng, Ji, Xiao & Sun 2015, IEEE T-Cybernetics 45(11);
the K-SVD poselet variant of Xiao et al. 2015, Neurocomputing) on arrays: lagged windows
(:func:`windows`, :func:`overlap_average`, :func:`starts`), the suspect samples and the
noise level, robust structured sparse coding of one partlet (:func:`code_partlet`), the
residual detail, the bone projection, and the dictionary training (:func:`train_robust`,
:func:`train_ksvd`). The ``partlet_dictionary`` cleaner (:mod:`mocapfix.cleaners.partlet`,
whose docstring gives the method and the measurements) runs them.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from mocapfix.solvers import sparse
from mocapfix.solvers.bone_projection import project_lengths
from mocapfix.solvers.dct import gcv_smooth
from mocapfix.solvers.local_sure import local_sure_smooth
from mocapfix.solvers.segments import linear_bridge
from mocapfix.solvers.ssa import channel_noise


def windows(X: np.ndarray, m: int, dilation: int, starts: np.ndarray) -> np.ndarray:
    """(d, n) matrix of windows: column j = vec of X[starts[j] + dilation·k], k < m,
    X (T, c) → d = m·c (frame-major)."""
    span = dilation * (m - 1) + 1
    view = sliding_window_view(X, span, axis=0)[:, :, ::dilation]   # (T-span+1, c, m)
    return np.ascontiguousarray(np.swapaxes(view[starts], 1, 2)).reshape(len(starts), -1).T


def overlap_average(W: np.ndarray, T: int, c: int, m: int, dilation: int, starts: np.ndarray):
    """Inverse of :func:`windows`: average of every window's copy of each frame."""
    rec = W.T.reshape(len(starts), m, c)
    out = np.zeros((T, c))
    count = np.zeros(T)
    for k in range(m):
        out[starts + dilation * k] += rec[:, k]
        count[starts + dilation * k] += 1
    return out / np.maximum(count, 1)[:, None], count


def starts(T: int, m: int, dilation: int, stride: int) -> np.ndarray:
    """Window starts: for each phase r < dilation, every ``stride`` window samples
    (``stride · dilation`` frames) and the last possible one, so that every frame lies in
    about ``m / stride`` windows."""
    last = T - (dilation * (m - 1) + 1)
    if last < 0:
        return np.zeros(0, dtype=np.intp)
    parts = []
    for r in range(min(dilation, last + 1)):
        s = np.arange(r, last + 1, stride * dilation)
        tail = last - ((last - r) % dilation)
        parts.append(np.append(s, tail))
    return np.unique(np.concatenate(parts))


def suspect_samples(P: np.ndarray, k: float, floor: float = 0.0, width: int = 7) -> np.ndarray:
    """(T, J) mask of joint samples of P (T, J, 3) that stand off a running median of
    ``width`` frames by more than ``k`` noise σ (the 3-D distance; σ the MAD of the
    per-coordinate residuals, robust to a minority of outliers): the samples the
    presmoothing and the frame fit must not see, before the ℓ2,p term decides on them."""
    T = P.shape[0]
    flat = P.reshape(T, -1)
    ok = ~np.isnan(flat).all(axis=0)
    if T < width or not ok.any():
        return np.zeros(P.shape[:2], dtype=bool)
    filled = np.ascontiguousarray(linear_bridge(flat[:, ok]).T)      # channels contiguous: faster
    if width % 2:   # the same as ndimage.median_filter(mode="nearest"), in half the time
        h = width // 2
        view = sliding_window_view(np.pad(filled, ((0, 0), (h, h)), mode="edge"), width, axis=1)
        med = np.partition(view, h, axis=-1)[..., h]
    else:
        from scipy import ndimage   # imported here: listing the cleaners need not load it

        med = ndimage.median_filter(filled, size=(1, width), mode="nearest")
    r = np.full(flat.shape, np.nan)
    r[:, ok] = (filled - med).T
    r[np.isnan(flat)] = np.nan
    seen = np.abs(r[~np.isnan(r)])
    scale = 1.4826 * float(np.median(seen)) if seen.size else 0.0
    dist = np.sqrt(np.nansum(r.reshape(P.shape) ** 2, axis=2))
    return (dist > max(k * scale, floor)) & ~np.isnan(P).any(axis=2)


def rigid_bones(a: np.ndarray, b: np.ndarray, sigma: float, *, factor: float = 2.0) -> np.ndarray:
    """Per bone, whether the input is consistent with a bone of constant length between
    joint tracks ``a`` and ``b`` (T, B, 3) carrying white noise of σ per coordinate: the
    robust spread (1.4826 MAD) of the squared length ℓ² is at most ``factor`` × what the
    noise alone gives (Var ℓ² = 8L²σ² + 24σ⁴ for ℓ² = |d + n|², n ~ N(0, 2σ²I)), plus 1 %
    of L² for rounding. Clean data from a rigid skeleton: ℓ² constant; a marker pair or a
    sensor's joints that move apart: spread far above the noise's. NaN samples are
    ignored; a bone with fewer than 3 samples is not taken as rigid."""
    l2 = np.sum((a - b) ** 2, axis=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        med = np.nanmedian(l2, axis=0)
        spread = 1.4826 * np.nanmedian(np.abs(l2 - med), axis=0)
    L2 = np.maximum(med - 6.0 * sigma ** 2, 0.0)
    expected = np.sqrt(8.0 * L2 * sigma ** 2 + 24.0 * sigma ** 4)
    enough = np.isfinite(l2).sum(axis=0) >= 3
    return enough & (spread <= factor * expected + 0.01 * L2)


def noise_level(X: np.ndarray) -> float:
    """σ̂ of white noise on the channels of X (T, c), NaN-aware: the median absolute second
    difference / 0.6745 / √6 (Var of a second difference of white noise is 6σ²)."""
    d2 = X[2:] - 2 * X[1:-1] + X[:-2]
    d2 = np.abs(d2[np.isfinite(d2)])
    return float(np.median(d2) / 0.6745 / np.sqrt(6.0)) if d2.size else 0.0


@dataclass(frozen=True)
class Coding:
    """The weights and iteration counts of :func:`code_partlet` (the cleaner's parameters
    of the same names; ``min_outlier`` in metres, ``local_smoothing`` in seconds)."""

    presmooth: bool = True
    local_smoothing: float = 0.0
    lambda1: float = 4.0
    lambda2: float = 0.0
    lambda3: float = 1.0
    p: float = 1.0
    min_outlier: float = 0.04
    ridge: float = 1e-2
    iterations: int = 3
    fill_iterations: int = 10
    fista_iterations: int = 20
    neighbours: int = 5
    loss: str = "l2"
    sparsity: int = 6
    detail: bool = True


def code_partlet(Xp, D, starts, m, dil, sigma, coding, fps, suspect, c: "Coding"):
    """Robust structured sparse coding of one partlet (Feng 2015 eq. 11), or OMP (Xiao
    2015), with windows of ``m`` samples ``dil`` frames apart (``starts``: :func:`starts`),
    on the partlet's joints ``Xp`` (T, n, 3) in its torso frame, metres; ``sigma`` the noise
    level, ``suspect`` (T, n) samples the presmoothing must not see, ``c`` the weights and
    iteration counts (:class:`Coding`).
    Returns (reconstruction (T, n, 3), unexplained energy fraction, iterations)."""
    T, n, _ = Xp.shape
    flat = Xp.reshape(T, -1)
    missing = np.isnan(Xp).any(axis=2)
    if suspect is not None and suspect.any():
        flat = np.where(np.repeat(suspect, 3, axis=1), np.nan, flat)
    Z = linear_bridge(flat)
    Z[np.isnan(Z)] = 0.0
    pad = min(T // 2, int(round(0.1 * fps)))
    presmooth = c.presmooth
    width = c.local_smoothing * fps

    def presmoothed(Z, noisy):
        """Z smoothed per sample by SURE with the channel noise of ``noisy`` (or by one
        GCV strength per channel when ``local_smoothing`` is 0)."""
        if width > 0:
            return local_sure_smooth(Z, channel_noise(noisy) ** 2, width=width, n_pad=pad,
                                     group=3)[0]
        return gcv_smooth(Z, n_pad=pad)[0]

    if presmooth:
        Z = presmoothed(Z, flat)
        sigma = noise_level(Z)
    Y = windows(Z, m, dil, starts)
    G = D.T @ D
    Lnorm = float(np.linalg.eigvalsh(G)[-1])
    lam3 = c.lambda3 * sigma * np.sqrt(2.0 * np.log(D.shape[1])) * np.sqrt(m)
    thr = max(c.lambda1 * sigma * np.sqrt(3.0), c.min_outlier)
    lap = None
    lam2 = 0.0
    if coding == "robust" and c.neighbours > 0 and c.lambda2 > 0:
        lap = sparse.knn_laplacian(Y.T, k=c.neighbours)
        lam2 = c.lambda2 * Lnorm
    step = 1.0 / sparse.lipschitz(G, lap, lam2)
    ridge = np.linalg.inv(G + (c.ridge * Lnorm + lam2) * np.eye(len(G)))
    E = np.zeros((T, n, 3))
    Psi = None
    it = 0
    rec = None
    p = c.p if coding == "robust" else 1.0
    robust = coding == "robust" or c.loss == "l1"
    n_outer = c.iterations if robust else 1
    if missing.any():
        n_outer = max(n_outer, c.fill_iterations)
    # the Ψ-step in single precision (as training): half the time, codes alike
    # (held-out dance, 2 seeds: every cell within 0.01 cm)
    D1, G1, ridge1 = (D.astype(np.float32), G.astype(np.float32), ridge.astype(np.float32)) \
        if coding == "robust" else (D, G, ridge)
    for it in range(1, n_outer + 1):
        C = D1.T @ Y.astype(D1.dtype)
        if coding == "robust":
            if Psi is None:   # start from the ridge solution: FISTA from zero is slow
                Psi = ridge1 @ C
            Psi, _ = sparse.fista(G1, C, lam3, laplacian=lap, lam_graph=lam2, x0=Psi,
                                  n_iter=c.fista_iterations, tol=1e-4, step=step)
        else:
            Psi = sparse.omp(G, C, c.sparsity)
        rec, _ = overlap_average((D1 @ Psi).astype(np.float64), T, flat.shape[1], m, dil, starts)
        rec3 = rec.reshape(T, n, 3)
        Q = np.where(missing[..., None], 0.0, Xp - rec3)
        if robust:
            E = E if it > 1 else Q
            for _ in range(1 if p == 1.0 else 3):   # p = 1: closed form, one step
                E = sparse.group_shrink_lp(Q, E, 2.0 * thr, p)
        if it == n_outer:   # nothing codes it: the next signal is not needed
            break
        Z = np.where(missing[..., None], rec3, Xp - E).reshape(T, -1)
        if presmooth:
            # the noise level of this signal, not the input's: E takes part of the noise
            Z = presmoothed(Z, Z)
        Y = windows(Z, m, dil, starts)
    obs = ~missing
    resid = np.where(obs[..., None], Xp - E - rec.reshape(T, n, 3), 0.0)
    # out of sample: the energy of the coded (smoothed, outlier-free) signal the
    # dictionary leaves, as a fraction of that signal's energy
    coded = np.where(obs[..., None], Z.reshape(T, n, 3), 0.0)
    left = np.where(obs[..., None], Z.reshape(T, n, 3) - rec.reshape(T, n, 3), 0.0)
    frac = float(np.vdot(left, left) / max(np.vdot(coded, coded), 1e-300))
    rec3 = rec.reshape(T, n, 3)
    if c.detail:
        # samples the noise term took as outliers get no detail back
        clean = obs & (np.linalg.norm(E, axis=2) == 0.0)
        rec3 = rec3 + residual_detail(resid, clean, fps)
    return rec3, frac, it


def project_bones(pos: np.ndarray, bones: np.ndarray):
    """``bones`` projected to their median length over the cleaned frames
    (:func:`mocapfix.solvers.bone_projection.project_lengths`, equal weights, 4 sweeps: 8
    gain ≤ 0.05 cm at 10 dB for twice the time): the
    skeleton is rigid, the dictionary's reconstruction only nearly so. Bones of zero
    length (joints a conversion put at one place) are left alone."""
    bones = np.asarray(bones, dtype=np.intp).reshape(-1, 2)
    if not len(bones):
        return pos, 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        lengths = np.nanmedian(np.linalg.norm(pos[:, bones[:, 0]] - pos[:, bones[:, 1]], axis=2), axis=0)
    scale = np.nanmedian(lengths) if np.isfinite(lengths).any() else 0.0
    ok = np.isfinite(lengths) & (lengths > 1e-3 * max(scale, 1e-300))
    if not ok.any():
        return pos, 0
    w = np.ones(pos.shape[:2])
    return project_lengths(pos, bones[ok], lengths[ok], w, sweeps=4), int(ok.sum())

def residual_detail(resid: np.ndarray, keep: np.ndarray, fps: float) -> np.ndarray:
    """The part of the residual the dictionary leaves that is motion, not noise: the
    residual of every channel smoothed with its own GCV-chosen strength (the DCT
    smoother of :mod:`mocapfix.solvers.dct`). Clean input (GCV: no smoothing) keeps all
    its detail; white noise is smoothed away. Samples not in ``keep`` (missing, or taken
    as outliers) contribute no detail."""
    T = resid.shape[0]
    r = np.where(keep[..., None], resid, 0.0).reshape(T, -1)
    smooth, _ = gcv_smooth(r, n_pad=min(T // 2, int(round(0.1 * fps))))
    return smooth.reshape(resid.shape)


def init_dictionary(B: np.ndarray, K: int, rng) -> np.ndarray:
    """K atoms drawn from the columns of B (random normal ones when B has fewer), unit norm."""
    D = B[:, rng.choice(B.shape[1], size=min(K, B.shape[1]), replace=False)].copy()
    if D.shape[1] < K:
        D = np.concatenate([D, rng.normal(size=(B.shape[0], K - D.shape[1])).astype(B.dtype)], axis=1)
    return D / np.maximum(np.linalg.norm(D, axis=0), 1e-12)

def train_robust(B: np.ndarray, K: int, rng, *, beta: float, lam: float, iterations: int):
    """Robust dictionary learning, Feng 2015 eq. 5, by coordinate descent (§III-C-2):
    (W, E)-step = lasso on D (FISTA) and soft-threshold of the residual; D-step = eq. 6.
    ``beta``: the sparsity weight relative to the median window norm; ``lam``: the outlier
    weight (the data's unit)."""
    D = init_dictionary(B, K, rng)
    beta = beta * float(np.median(np.linalg.norm(B, axis=0)))
    W = np.zeros((K, B.shape[1]), dtype=B.dtype)
    E = np.zeros_like(B)
    it = 0
    for it in range(1, iterations + 1):
        G = D.T @ D
        W, _ = sparse.fista(G, D.T @ (B - E), beta, x0=W, n_iter=10, tol=1e-3)
        E = sparse.soft(B - D @ W, lam / 2.0) if lam > 0 else np.zeros_like(B)
        D = sparse.dictionary_step(D, W @ W.T, (B - E) @ W.T, rng=rng, data=B)
    return D, W, E, it

def train_ksvd(B: np.ndarray, K: int, rng, *, sparsity: int, iterations: int):
    """K-SVD (Xiao 2015 §3, after Aharon et al. 2006): OMP codes with ``sparsity`` atoms,
    then the atom-by-atom rank-1 update."""
    D = init_dictionary(B, K, rng)
    it = 0
    W = None
    for it in range(1, iterations + 1):
        W = sparse.omp(D.T @ D, D.T @ B, sparsity)
        D, W = sparse.ksvd_step(B, D, W, rng=rng)
    return D, W, it
