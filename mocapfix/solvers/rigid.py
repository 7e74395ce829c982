"""Rigid alignment kernels: batched Kabsch fits (shared by the body-frame alignments of
``fill_pca``, ``tsmc``, the model-averaging gap filler and ``partlet_dictionary``) and a
robust, temporally smooth body frame.

:func:`kabsch` is the weighted orthogonal Procrustes fit of Kabsch (1976), batched over
frames (3 × 3 SVDs, no frame loop). :func:`torso_frames` is the pose normalisation of
Feng et al. 2015 §III-B-1 (translate and rotate every pose so that its torso sits in a
fixed frame; the paper uses ICP for robustness to noise): a Kabsch fit of the torso
joints to a template, reweighted (Welsch) against outlying joints, then smoothed in time
so that noise on the torso does not turn into jitter of the whole body when the frame is
undone.
"""
from __future__ import annotations

import numpy as np


def kabsch(source, target, weights):
    """Per-frame rigid fit ``R_t (source_t - cs_t) + ct_t ~ target_t`` (Kabsch 1976).

    source, target: (T, J, 3) without NaN; weights: (T, J) >= 0 with a positive sum per
    frame. Returns R (T, 3, 3), cs (T, 3), ct (T, 3).
    """
    wsum = weights.sum(axis=1, keepdims=True)
    cs = (weights[:, None, :] @ source)[:, 0] / wsum
    ct = (weights[:, None, :] @ target)[:, 0] / wsum
    H = np.swapaxes((source - cs[:, None]) * weights[..., None], 1, 2) @ (target - ct[:, None])
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(U @ Vt))
    d[d == 0] = 1.0
    Vt = Vt.copy()
    Vt[:, 2] *= d[:, None]
    R = np.swapaxes(U @ Vt, 1, 2)                 # V diag(1, 1, d) U^T
    return R, cs, ct


def nearest_rotation(M: np.ndarray) -> np.ndarray:
    """The rotation closest to each 3 × 3 matrix of ``M`` (T, 3, 3) in Frobenius norm."""
    U, _, Vt = np.linalg.svd(M)
    d = np.sign(np.linalg.det(U @ Vt))
    d[d == 0] = 1.0
    U = U.copy()
    U[:, :, 2] *= d[:, None]
    return U @ Vt


def torso_frames(points: np.ndarray, template: np.ndarray, *, smoothing: float = 0.0,
                 rounds: int = 3, min_points: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rotation ``R`` (T, 3, 3) and translation ``c`` (T, 3) with ``R (p − c) ≈ template``
    for the torso points ``points`` (T, n, 3, NaN = missing) of every frame.

    Robust: ``rounds`` of Welsch reweighting against the points' fit residuals (scale: the
    median residual). Smooth: rotations and translations are low-passed with a Gaussian of
    ``smoothing`` frames (rotations re-orthonormalised). Frames with fewer than
    ``min_points`` torso points take the frame interpolated from their neighbours.
    Returns (R, c, valid) with ``valid`` the frames fitted from their own points.
    """
    T, n, _ = points.shape
    observed = ~np.isnan(points).any(axis=2)
    valid = observed.sum(axis=1) >= min_points
    if not valid.any():
        raise ValueError("no frame has enough torso points to fix the body frame")
    src = np.where(observed[..., None], points, 0.0)[valid]
    w = observed[valid].astype(float)
    tgt = np.broadcast_to(template, src.shape)
    for _ in range(rounds):
        R, cs, ct = kabsch(src, tgt, w)
        fitted = (src - cs[:, None]) @ np.swapaxes(R, 1, 2) + ct[:, None]
        r = np.linalg.norm(fitted - tgt, axis=2)
        scale = max(float(np.median(r[w > 0])) * 3.0, 1e-9)
        w = observed[valid] * np.exp(-(r / scale) ** 2)
        w[w.sum(axis=1) <= 1e-12] = observed[valid][w.sum(axis=1) <= 1e-12]
    # R (p − c) = template: c = cs − Rᵀ ct
    c_valid = cs - (np.swapaxes(R, 1, 2) @ ct[..., None])[..., 0]
    R_all = np.empty((T, 3, 3))
    c_all = np.empty((T, 3))
    idx = np.flatnonzero(valid)
    t = np.arange(T)
    for a in range(3):
        c_all[:, a] = np.interp(t, idx, c_valid[:, a])
        for b in range(3):
            R_all[:, a, b] = np.interp(t, idx, R[:, a, b])
    if smoothing > 0:
        from scipy.ndimage import gaussian_filter1d  # imported here: not loaded unless needed
        c_all = gaussian_filter1d(c_all, smoothing, axis=0, mode="nearest")
        R_all = gaussian_filter1d(R_all, smoothing, axis=0, mode="nearest")
    if smoothing > 0 or not valid.all():
        R_all = nearest_rotation(R_all)
    return R_all, c_all, valid


def to_frame(positions: np.ndarray, R: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Global (T, J, 3) positions into the frames of :func:`torso_frames`."""
    return (positions - c[:, None]) @ np.swapaxes(R, 1, 2)


def from_frame(local: np.ndarray, R: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Inverse of :func:`to_frame`."""
    return local @ R + c[:, None]


def body_frame(positions, observed, rounds: int = 50, rtol: float = 1e-10):
    """Align every frame's observed markers to a common mean shape (generalised Procrustes:
    align to the reference, re-average, repeat until the reference moves less than
    ``rtol`` of its size). The default keeps a rigid body's fill exact to 1e-6; ``tsmc``'s
    moving reference uses 1e-6 (fills change by < 1e-4 mm on CMU 85_02 and HDM05, a third
    fewer rounds).

    Returns (local positions with NaN where missing, transform) where ``transform`` maps
    local back to global with :func:`to_global`.
    """
    src = np.where(observed[..., None], positions, 0.0)
    w = observed.astype(np.float64)
    with np.errstate(invalid="ignore"):
        ref = np.nanmean(positions - np.nanmean(positions, axis=1, keepdims=True), axis=0)
    ref = np.nan_to_num(ref)
    size = max(float(np.sqrt(np.mean(ref ** 2))), 1e-300)
    for _ in range(rounds):
        R, cs, ct = kabsch(src, np.broadcast_to(ref, src.shape), w)
        local = to_local(src, (R, cs, ct))
        local[~observed] = np.nan
        new = np.nan_to_num(np.nanmean(local, axis=0))
        moved = float(np.max(np.abs(new - ref)))
        ref = new
        if moved <= rtol * size:
            break
    return local, (R, cs, ct)


def to_local(positions, transform):
    """Global (T, J, 3) positions into the body frame of :func:`body_frame`."""
    R, cs, ct = transform
    return (positions - cs[:, None]) @ np.swapaxes(R, 1, 2) + ct[:, None]


def to_global(local, transform):
    R, cs, ct = transform
    return (local - ct[:, None]) @ R + cs[:, None]
