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
    return _best_rotation(H), cs, ct


#: most 3 × 3 matrices per call of :func:`_best_rotation` in :func:`kabsch_to_shapes`
#: (its temporaries stay in the cache: 363,000 matrices in one call took 2–3× as long as
#: in chunks of this many)
CHUNK = 8192


def kabsch_to_shapes(requests) -> list:
    """:func:`kabsch` of every frame of ``points`` (T, K, 3) onto one fixed ``shape`` (K,
    3) with unit weights, for each ``(points, shape)`` of ``requests``. Per request, ``H_t
    = Σ_k (p_tk − c_t)(s_k − c)ᵀ`` for all its frames as one (3T, K) × (K, 3) matrix
    product (the general kernel forms T small products: 2x faster for 35 points); the
    rotations of all requests are found together, one :func:`_best_rotation` call per
    :data:`CHUNK` matrices (chunks of equal size): a call costs ~150 array operations
    whatever its size, so a few hundred fits of a few dozen frames each (the fill
    ensemble's, :func:`mocapfix.solvers.pma.member_fills`) cost as much as one large one.
    A request's values do not depend on the others' but for rounding (~1e-13: under 100
    matrices in all, the SVD finds the rotations, else the closed form). Returns one ``(R
    (T, 3, 3), cs (T, 3), ct (T, 3))`` per request, as :func:`kabsch`."""
    parts = []
    for points, shape in requests:
        T, K, _ = points.shape
        cs = points.mean(axis=1)
        c = shape.mean(axis=0)
        centred = np.swapaxes(points - cs[:, None], 1, 2).reshape(T * 3, K)
        parts.append(((centred @ (shape - c)).reshape(T, 3, 3), cs, c))
    if not parts:
        return []
    H = np.concatenate([h for h, _, _ in parts])
    chunks = max(1, -(-len(H) // CHUNK))
    R = np.concatenate([_best_rotation(h) for h in np.array_split(H, chunks)])
    out, start = [], 0
    for h, cs, c in parts:
        out.append((R[start:start + len(h)], cs, np.broadcast_to(c, (len(h), 3))))
        start += len(h)
    return out


def _best_rotation_svd(H):
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(U @ Vt))
    d[d == 0] = 1.0
    Vt = Vt.copy()
    Vt[:, 2] *= d[:, None]
    return np.swapaxes(U @ Vt, 1, 2)                 # V diag(1, 1, d) U^T


def _cross(x, y):
    return (x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0])


def _dot(x, y):
    return x[0] * y[0] + x[1] * y[1] + x[2] * y[2]


def norms(v: np.ndarray) -> np.ndarray:
    """Euclidean norm over the last axis (length 3) of ``v``, written out: several times
    faster than ``np.linalg.norm(v, axis=-1)`` on (T, J, 3) arrays, with the same values."""
    return np.sqrt(v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1] + v[..., 2] * v[..., 2])


def _best_rotation(H):
    """The rotation ``R = V diag(1, 1, d) Uᵀ`` of Kabsch (1976) for each 3 × 3 matrix of
    ``H = U S Vᵀ`` (n, 3, 3), in closed form on (n,) component arrays (numpy's batched SVD,
    determinant and matrix product cost microseconds per 3 × 3 matrix): ``v3``, the right
    singular vector of the smallest singular value, is the eigenvector of ``HᵀH`` for its
    smallest eigenvalue (trigonometric eigenvalues of a symmetric 3 × 3 matrix, Smith 1961;
    the vector as the largest cross product of two rows of ``HᵀH − λ₃ I``); on the plane
    ``(a, b)`` orthogonal to it the polar factor of ``H [a b]`` is a plane rotation in
    the Gram–Schmidt basis of its columns; the third axis is the cross product, so
    ``det R = 1``. Each result is checked against Kabsch's optimum ``tr(R H) = s₁ + s₂ +
    sign(det H) s₃``; matrices that fail (degenerate point sets, near-equal small singular
    values) go through the SVD, as do batches of fewer than 100 matrices (where the SVD is
    faster: 0.16 against 0.67 ms for 10, equal near 100)."""
    H = np.asarray(H, dtype=np.float64)
    n = H.shape[0]
    if n == 0:
        return np.zeros((0, 3, 3))
    if n < 100:                 # the closed form's ~150 array operations cost more here
        return _best_rotation_svd(H)
    h = [[H[:, i, j] for j in range(3)] for i in range(3)]
    col = [(h[0][j], h[1][j], h[2][j]) for j in range(3)]          # columns of H
    A = [[_dot(col[i], col[j]) for j in range(3)] for i in range(3)]    # HᵀH = V S² Vᵀ
    q = (A[0][0] + A[1][1] + A[2][2]) / 3.0
    off = A[0][1] ** 2 + A[0][2] ** 2 + A[1][2] ** 2
    p = np.sqrt(((A[0][0] - q) ** 2 + (A[1][1] - q) ** 2 + (A[2][2] - q) ** 2 + 2.0 * off) / 6.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        b00, b11, b22 = (A[0][0] - q) / p, (A[1][1] - q) / p, (A[2][2] - q) / p
        b01, b02, b12 = A[0][1] / p, A[0][2] / p, A[1][2] / p
        detb = (b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02)
                + b02 * (b01 * b12 - b11 * b02))
        phi = np.arccos(np.clip(detb / 2.0, -1.0, 1.0)) / 3.0
        lam1 = q + 2.0 * p * np.cos(phi)
        lam3 = q + 2.0 * p * np.cos(phi + 2.0 * np.pi / 3.0)
        lam2 = 3.0 * q - lam1 - lam3
        # a small λ₃ from the invariants (λ₁λ₂λ₃ = det(H)², λ₁λ₂ + λ₃(λ₁ + λ₂) = c₂):
        # the trigonometric value carries an absolute error ~ 1e-8 λ₁ when λ₁ ≈ λ₂
        deth = _dot(col[0], _cross(col[1], col[2]))
        c2 = (A[0][0] * A[1][1] - A[0][1] ** 2 + A[0][0] * A[2][2] - A[0][2] ** 2
              + A[1][1] * A[2][2] - A[1][2] ** 2)
        small = deth ** 2 / c2
        small = deth ** 2 / (c2 - small * (3.0 * q - small))
        lam3 = np.where(lam3 < 1e-4 * lam2, small, lam3)
        rows = [(A[0][0] - lam3, A[0][1], A[0][2]), (A[0][1], A[1][1] - lam3, A[1][2]),
                (A[0][2], A[1][2], A[2][2] - lam3)]
        cands = [_cross(rows[0], rows[1]), _cross(rows[0], rows[2]), _cross(rows[1], rows[2])]
        size = np.stack([_dot(c, c) for c in cands])
        pick = np.argmax(size, axis=0)
        v = [np.choose(pick, [c[i] for c in cands]) for i in range(3)]
        norm = np.sqrt(_dot(v, v))
        v = [x / norm for x in v]
        # a unit vector orthogonal to v3: cross with the axis of v3's smallest component
        k = np.argmin(np.abs(np.stack(v)), axis=0)
        e = [(k == i).astype(np.float64) for i in range(3)]
        a = _cross(v, e)
        na = np.sqrt(_dot(a, a))
        a = [x / na for x in a]
        b = _cross(v, a)
        Ha = [_dot(h[i], a) for i in range(3)]
        Hb = [_dot(h[i], b) for i in range(3)]
        # polar factor of the 3 × 2 matrix [Ha Hb]: an orthonormal basis (e1, e2) of its
        # columns (Gram–Schmidt), in which it is the upper-triangular 2 × 2 B = [[|Ha|,
        # Hb·e1], [0, |Hb⊥|]] (det > 0) whose nearest rotation is the angle
        # atan2(−Hb·e1, |Ha| + |Hb⊥|)
        la = np.sqrt(_dot(Ha, Ha))
        e1 = [x / la for x in Ha]
        b01 = _dot(Hb, e1)
        perp = [Hb[i] - b01 * e1[i] for i in range(3)]
        lp = np.sqrt(_dot(perp, perp))
        e2 = [x / lp for x in perp]
        cos_, sin_ = la + lp, -b01
        rr = np.sqrt(cos_ * cos_ + sin_ * sin_)
        cos_, sin_ = cos_ / rr, sin_ / rr
        qa = [cos_ * e1[i] + sin_ * e2[i] for i in range(3)]
        qb = [-sin_ * e1[i] + cos_ * e2[i] for i in range(3)]
        qc = _cross(qa, qb)
        R = np.empty((n, 3, 3))
        for i in range(3):                     # R = Pᵀ, P = qa aᵀ + qb bᵀ + qc v3ᵀ
            for j in range(3):
                R[:, j, i] = qa[i] * a[j] + qb[i] * b[j] + qc[i] * v[j]
        # certificate: R H symmetric (a critical point of tr(R H)) with the largest trace
        # s₁ + s₂ ± s₃ (the others are smaller by 2 s₂ at least)
        s = [np.sqrt(np.maximum(x, 0.0)) for x in (lam1, lam2, lam3)]
        best = s[0] + s[1] + np.where(deth < 0, -1.0, 1.0) * s[2]
        RH = [[sum(R[:, i, k] * h[k][j] for k in range(3)) for j in range(3)] for i in range(3)]
        asym = np.abs(RH[0][1] - RH[1][0]) + np.abs(RH[0][2] - RH[2][0]) + np.abs(RH[1][2] - RH[2][1])
        scale = s[0] + s[1] + s[2]
        ok = (np.isfinite(R).all(axis=(1, 2)) & (p > 1e-12 * np.abs(q))
              & (lp > 1e-6 * la) & (asym <= 1e-11 * scale)
              & (RH[0][0] + RH[1][1] + RH[2][2] >= best - 1e-6 * scale))
    if not ok.all():
        bad = ~ok
        R[bad] = _best_rotation_svd(H[bad])
    return R


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
