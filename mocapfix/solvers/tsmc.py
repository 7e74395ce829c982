"""Kernels of trust-data detection and temporal-stable robust matrix completion (Feng,
Ji, Xiao & Sun 2014, "Mining spatial-temporal patterns and structural sparsity for human
motion data denoising", Algorithms 1 and 2), on arrays: the ``trust`` and ``tsmc``
cleaners (:mod:`mocapfix.cleaners.tsmc`, whose docstring gives the method and the
measurements) run them.

- :func:`gross_errors` — samples that are no measurement at all (a corrupt field);
- :func:`trust_mask` — Algorithm 1: robust GCV smoothing per channel, samples far from it
  untrusted;
- :func:`tsmc_solve` — Algorithm 2: low-rank + temporally smooth completion by inexact ALM;
- :func:`moving_reference`, :func:`bridge_residual`, :func:`gcv_denoise` — the body frame,
  the gap-edge correction and the GCV denoiser the cleaner wraps around it.
"""
from __future__ import annotations

import warnings

import numpy as np

from mocapfix.solvers import dct, segments
from mocapfix.solvers.localfit import moving_median
from mocapfix.solvers.nanstats import nanmedian_columns, nanquantile_columns
from mocapfix.solvers.lowrank import svt
from mocapfix.solvers.rigid import body_frame, norms, to_global, to_local
from mocapfix.core.motion import missing_samples
from mocapfix.solvers.segments import NO_CAPTURE_VOLUME_M, linear_bridge


#: a sample further from its marker's median position than this many times the larger of
#: its marker's and the capture's extent (90th percentile of the distances to the marker's
#: median: its own samples', every sample's), and than NO_CAPTURE_VOLUME_M, is no measurement (a
#: corrupt field, a flipped exponent bit). Relative, so a file whose units are mislabelled
#: is not taken for one big gross error, and per marker, so a wand moving over a static rig
#: is not either (a capture-wide extent alone took the whole wand); the shared captures
#: reach 2.2x (C3D) and 11x (Kinect) their extent
GROSS_EXTENT = 20.0


def gross_errors(pos: np.ndarray, fps: float, metres_per_unit: float) -> np.ndarray:
    """(T, J) True for observed samples that are gross errors (:data:`GROSS_EXTENT`,
    :data:`LOCAL_GROSS_M`). The medians and extents come from at most 2,000 evenly spaced
    frames of a marker (all its frames when it is seen on none of those): they only place
    limits 20 times the extent away."""
    seen = ~missing_samples(pos)
    if not seen.any():
        return seen
    T, J, _ = pos.shape
    rows = np.arange(0, T, max(1, T // 2000))
    sampled = seen[rows].any(axis=0)
    centre, own = np.zeros((J, 3)), np.zeros(J)
    with np.errstate(invalid="ignore", over="ignore"):
        for part, todo in ((rows, sampled), (slice(None), seen.any(axis=0) & ~sampled)):
            if todo.any():
                sub = pos[part][:, todo]
                centre[todo] = nanmedian_columns(sub.reshape(len(sub), -1)).reshape(-1, 3)
                own[todo] = nanquantile_columns(norms(sub - centre[todo]), 0.9)
        dist = norms(pos - centre)
        every = dist[rows][seen[rows]]
        extent = np.maximum(own, float(np.quantile(every if len(every) else dist[seen], 0.9)))
        limit = np.maximum(GROSS_EXTENT * extent, NO_CAPTURE_VOLUME_M / metres_per_unit)
        far = seen & ~(dist <= limit[None, :])
    if far.any():
        pos, seen = np.where(far[..., None], np.nan, pos), seen & ~far
    return far | _local_gross(pos, seen, fps, metres_per_unit)


#: a sample further than LOCAL_GROSS_M, and than LOCAL_FACTOR times its marker's median
#: frame-to-frame step, from the median of its marker's samples within ±LOCAL_HALF_S is no
#: measurement either: left in, a single sample 5-99 m off made trust untrust 28-673 of
#: its neighbours on CMU 85_02 (the screen above starts at 100 m). A human marker moves far
#: less than a metre from its local median in 0.1 s; the step factor keeps a file whose
#: units are mislabelled (millimetres read as metres) from looking all gross
LOCAL_GROSS_M = 1.0
LOCAL_FACTOR = 20.0
LOCAL_HALF_S = 0.1


def _local_gross(pos: np.ndarray, seen: np.ndarray, fps: float, metres_per_unit: float) -> np.ndarray:
    """(T, J) True for observed samples far from the median of their marker's samples
    around them (:data:`LOCAL_GROSS_M`). Only markers with a step of at least half that far
    between two observed frames are looked at (none in the shared captures): the running
    medians cost O(T·window) for them alone."""
    T, J, _ = pos.shape
    out = np.zeros((T, J), bool)
    if T < 3:
        return out
    with np.errstate(invalid="ignore", over="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)     # a marker never seen twice in a row
        step = norms(pos[1:] - pos[:-1])                                # NaN beside a gap
        # the median step from at most 2,000 evenly spaced steps (the factor is 20)
        typical = np.nan_to_num(np.nanmedian(step[::max(1, len(step) // 2000)], axis=0))
        limit = np.maximum(LOCAL_GROSS_M / metres_per_unit, LOCAL_FACTOR * typical)
        suspects = np.flatnonzero((step > 0.5 * limit[None, :]).any(axis=0))
    if len(suspects):
        x = np.where(seen[:, suspects, None], pos[:, suspects], np.nan)
        local = moving_median(x, max(2, int(round(LOCAL_HALF_S * fps))))
        with np.errstate(invalid="ignore", over="ignore"):
            out[:, suspects] = seen[:, suspects] & (norms(x - local) > limit[suspects])
    return out


#: most markers per block of :func:`trust_mask` (the blocks run on the task's threads)
TRUST_BLOCK = 10
#: fewest samples (frames × markers) per block of :func:`trust_mask`: a block's robust
#: smooth is ~100 array operations whatever its size, so a short take is one block
#: (c3d.org s02, 89 frames × 36 markers: 28 → 12 ms on two threads) and c3d.org s20
#: (701 × 40) two (47 → 38 ms)
TRUST_BLOCK_SAMPLES = 14_000


def trust_mask(pos: np.ndarray, weights: np.ndarray, k: float, lo: float, hi: float,
               iterations: int, pad: int, welsch: float | None = None):
    """:func:`trust_mask_block` of blocks of markers of equal size (at most
    :data:`TRUST_BLOCK` markers, at least :data:`TRUST_BLOCK_SAMPLES` samples but for
    one block, an even number of them but for one; every marker's detection is its own,
    and the blocks depend on the take's size only, not on the thread count) on the
    task's threads
    (:func:`mocapfix.core.threads.parallel_map`), put back together."""
    from mocapfix.core.threads import parallel_map

    T, J = pos.shape[:2]
    count = max(1, min(-(-J // TRUST_BLOCK), T * J // TRUST_BLOCK_SAMPLES))
    count += count % 2 if count > 1 else 0      # two threads end together (41 markers: 6 blocks)
    if count == 1:
        return trust_mask_block(pos, weights, k, lo, hi, iterations, pad, welsch)
    blocks = [slice(b[0], b[-1] + 1) for b in np.array_split(np.arange(J), count)]
    parts = parallel_map(lambda b: trust_mask_block(pos[:, b], weights[:, b], k, lo, hi,
                                                    iterations, pad, welsch), blocks)
    trusted, smooth, theta, mu = zip(*parts)
    return (np.concatenate(trusted, axis=1), np.concatenate(smooth, axis=1),
            np.concatenate(theta), np.concatenate(mu))


def trust_mask_block(pos: np.ndarray, weights: np.ndarray, k: float, lo: float, hi: float,
                     iterations: int, pad: int, welsch: float | None = None):
    """Trust-data detection (Feng 2014 Algorithm 1) on marker positions (T, J, 3).

    ``weights`` (T, J) in [0, 1] (0 = missing or not confident). Thresholds ``lo``/``hi`` and
    ``welsch`` in the units of ``pos``. Two stages: a robust smooth with Welsch scale ``hi``
    (the paper's p ≈ θ) gives the robust noise σ per marker (1.4826 · median |residual|
    over its coordinates) and θ = clip(k σ, lo, hi); a second robust smooth with Welsch
    scale θ (or ``welsch``) gives the residuals that are compared with θ.

    Returns ``(trusted (T, J), smooth (T, J, 3), theta (J,), mu (3J,))``.
    """
    T, J, _ = pos.shape
    x = pos.reshape(T, 3 * J)
    w = np.repeat(np.where(missing_samples(pos), 0.0, weights), 3, axis=1)
    if pad > 0 and dct.fast_pad(T, pad) < T:        # reflection needs fewer than T samples
        pad = dct.fast_pad(T, pad)
    xp, p = dct.pad_missing(np.where(w > 0, x, np.nan), pad)
    wp = np.pad(w, ((p, p), (0, 0)))
    init, _ = dct.pad_reflect(linear_bridge(np.where(w > 0, x, np.nan)), pad)
    scale = np.full(3 * J, hi if welsch is None else welsch)
    theta = np.full(J, hi)
    xhat, mu = init, None
    for stage in range(2):
        xhat, mu, _ = dct.robust_smooth(xp, wp, scale, iterations, init=xhat)
        res = (xp - xhat)[p:p + T].reshape(T, J, 3)
        used = (wp[p:p + T].reshape(T, J, 3) > 0).all(axis=2)
        absres = np.where(used[..., None], np.abs(res), np.nan)
        has = used.any(axis=0)
        sigma = np.zeros(J)
        if has.any():
            sigma[has] = 1.4826 * np.nanmedian(absres[:, has], axis=(0, 2))
        theta = np.clip(k * sigma, lo, hi)
        if welsch is None:
            scale = np.repeat(theta, 3)
    r = np.linalg.norm((xp - xhat)[p:p + T].reshape(T, J, 3), axis=2)
    observed = ~missing_samples(pos)
    trusted = observed & (weights > 0) & (r <= theta[None, :])
    return trusted, dct.unpad(xhat, p).reshape(T, J, 3), theta, mu


# -- Algorithm 2 ---------------------------------------------------------------------------

def tsmc_solve(x: np.ndarray, omega: np.ndarray, alpha: float = 1.0, beta: float = 100.0,
               gamma: float = 1.1, tol: float = 1e-7, max_iter: int = 500,
               penalty0: float = 1.25) -> tuple[np.ndarray, np.ndarray, dict]:
    """Temporal-stable robust matrix completion by inexact ALM (Feng 2014 Algorithm 2,
    eqs. A.5–A.16).

    Parameters
    ----------
    x : (T, C) data, one column per channel; entries outside ``omega`` are ignored.
    omega : (T, C) boolean, True = trusted observed entry.
    alpha, beta : weights of ||Ω∘E||_1 and β/2 ||M O||² (in the data's units; the paper's
        values 1 and 100 are for cm).
    gamma : growth factor of the penalties λ1, λ2 (> 1).
    tol : stop when ||X − Y − E||_F and ||M − Y||_F are both below tol · ||X||_F.
    max_iter : iteration cap.
    penalty0 : initial λ1 = λ2 = penalty0 / ||X||_2 (1.25: Lin, Chen & Ma 2010).

    Returns
    -------
    (Y, E, info), Y and E (T, C), info = {"iterations", "residual", "converged", "rank"}.

    The iteration runs on the paper's own layout, channels as rows (C, T), so that the
    DCT of the M-step (eq. A.13) reads contiguous rows; λ1 = λ2 throughout (same start,
    same growth), which folds the Y-step's weighted mean (eq. A.9) into
    ``Z = (Y1/λ + Y2/λ + X − E + M) / 2``. Every update writes into preallocated
    buffers: per iteration one Gram-matrix SVT, one DCT pair and about fifteen passes over
    the C × T matrix. The multipliers are kept scaled (U = Y/λ, the scaled form of
    Boyd et al. 2011 §3.1.1), which turns the E-step and the Y1 update into one clip.
    """
    X = np.ascontiguousarray(np.where(omega, x, 0.0).T)           # (C, T)
    inside = np.ascontiguousarray(omega.T).astype(np.float64)
    norm_f = float(np.linalg.norm(X))
    if norm_f == 0.0:
        return np.zeros_like(x, dtype=np.float64), np.zeros_like(x, dtype=np.float64), \
            {"iterations": 0, "residual": 0.0, "converged": True, "rank": 0}
    C, T = X.shape
    norm_2 = float(np.sqrt(np.linalg.eigvalsh(X @ X.T)[-1])) if C <= T \
        else float(np.linalg.norm(X, 2))
    norm_inf = float(np.abs(X).sum(axis=1).max())   # paper's ∞-norm: max row sum
    lam = penalty0 / norm_2                                       # λ1 = λ2
    # scaled multipliers U1 = Y1/λ, U2 = Y2/λ; S = X − E
    U1 = X / (max(norm_2, norm_inf) * lam)
    U2 = U1.copy()
    S = X.copy()
    M = np.zeros_like(X)
    Z, D, B = np.empty_like(X), np.empty_like(X), np.empty_like(X)
    residual, it, converged = np.inf, 0, False
    for it in range(1, max_iter + 1):
        # Y-step (A.9–A.10): SVT of the mean of X − E + Y1/λ1 and M + Y2/λ2
        np.add(U1, U2, out=Z)
        Z += S
        Z += M
        Z *= 0.5
        Y = svt(Z, 0.5 / lam)
        # E-step (A.11–A.12): E = Ze − Ω∘clip(Ze, ±α/λ) with Ze = Y1/λ + X − Y
        # (E = Ze outside Ω); then R1 = X − Y − E = Ω∘clip(Ze) − U1 and
        # Y1 + λR1 = λ Ω∘clip(Ze)
        np.subtract(X, Y, out=D)
        D += U1
        np.clip(D, -alpha / lam, alpha / lam, out=D)
        D *= inside
        np.subtract(D, U1, out=B)
        r1 = float(np.linalg.norm(B))
        np.subtract(Y, U1, out=S)
        S += D                                                    # X − E = Y − U1 + Ω∘clip
        np.multiply(D, 1.0 / gamma, out=U1)
        # M-step (A.13): (λY − Y2)(β OOᵀ + λI)⁻¹ = idct(dct(Y − U2) λ / (β λ_k² + λ))
        np.subtract(Y, U2, out=B)
        M = dct.penalty_solve(B, beta, lam, axis=1)
        M *= lam
        # R2 = M − Y; Y2 + λR2, rescaled for the next λ
        np.subtract(M, Y, out=B)
        r2 = float(np.linalg.norm(B))
        U2 += B
        U2 *= 1.0 / gamma
        lam *= gamma
        residual = max(r1, r2) / norm_f
        if residual < tol:
            converged = True
            break
    E = X - S
    s = np.sqrt(np.clip(np.linalg.eigvalsh(Y @ Y.T), 0.0, None))[::-1] if C <= T \
        else np.linalg.svd(Y, compute_uv=False)
    rank = int(np.sum(s > 1e-3 * s[0])) if s.size and s[0] > 0 else 0
    return Y.T.copy(), E.T.copy(), {"iterations": it, "residual": residual,
                                    "converged": converged, "rank": rank}


def moving_reference(pos: np.ndarray, observed: np.ndarray, hold: float = 0.0):
    """Body-frame coordinates of (T, J, 3) ``pos`` and a function mapping local positions
    back to global. The per-frame rigid transform is the generalised Procrustes fit
    (:func:`mocapfix.solvers.rigid.body_frame`) of the *gap-bridged* marker set
    (linear interpolation; a marker's leading/trailing gap is held for ``hold`` frames and
    left out beyond), so every frame is fitted on nearly the same markers: fitting
    each frame on its own observed subset made the frame jitter (CMU 05_01 with 40 %
    random missing: 1.70 cm instead of 0.31 cm in the global frame). Markers never
    observed are left out. Returns ``(local, back)``, or ``(pos, None)`` (global frame) when
    some frame has fewer than 3 such markers."""
    T, J, _ = pos.shape
    seen = observed.any(axis=0)
    if seen.sum() < 3:
        return pos, None
    flat = np.where(observed[..., None], pos, np.nan).reshape(T, 3 * J)
    missing = np.isnan(flat)
    prev, nxt = segments.neighbours(missing)
    bracketed = (prev >= 0) & (nxt < T)                       # observed or an interior gap
    near_end = _distance_to_observed(missing, (prev, nxt)) <= hold
    use = (bracketed | near_end).reshape(T, J, 3).all(axis=2)[:, seen]
    bridged = linear_bridge(flat).reshape(T, J, 3)[:, seen]
    if (use.sum(axis=1) < 3).any():
        return pos, None
    _, transform = body_frame(bridged, use, rtol=1e-6)
    local = to_local(np.where(observed[..., None], pos, 0.0), transform)
    local[~observed] = np.nan
    return local, (lambda loc: to_global(loc, transform))


def _distance_to_observed(missing: np.ndarray, neighbours=None) -> np.ndarray:
    """Frames from each sample of a (T, C) mask to the nearest non-missing one in its
    column (0 where observed, inf in an all-missing column); ``neighbours`` is
    :func:`mocapfix.solvers.segments.neighbours` of the mask when the caller has it already."""
    T = missing.shape[0]
    prev, nxt = segments.neighbours(missing) if neighbours is None else neighbours
    t = np.arange(T)[:, None]
    dist = np.minimum(np.where(prev >= 0, t - prev, T), np.where(nxt < T, nxt - t, T))
    return np.where(dist >= T, np.inf, dist.astype(np.float64))


def bridge_residual(d: np.ndarray, tau: float) -> np.ndarray:
    """Correction of a model fill inside the gaps of ``d`` (T, C) = data − model (NaN in
    gaps): the edge residuals interpolated linearly across each gap (held at the ends),
    times ``exp(−distance to the nearest observed sample / tau)``. Short gaps are then
    filled continuously with the data (like an interpolant riding on the model), long gaps
    follow the model. 0 where ``d`` is observed."""
    missing = np.isnan(d)
    lin = linear_bridge(d)
    dist = _distance_to_observed(missing)
    with np.errstate(invalid="ignore"):
        taper = np.exp(-dist / tau) if np.isfinite(tau) else np.ones_like(dist)
    return np.where(missing, np.nan_to_num(lin * taper), 0.0)


def gcv_denoise(x: np.ndarray, pad: int, measured: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """GCV smoothing of every complete channel (T, C) with reflection padding, and the
    noise estimate per channel: RMS residual / sqrt(1 − tr H / n) (Wahba 1990 §4.7),
    the RMS taken over the ``measured`` samples only (T, C; default all)."""
    smooth, mu = dct.gcv_smooth(x, pad)
    n = x.shape[0] + 2 * min(pad, max(x.shape[0] - 1, 0))
    lam2 = dct.eigenvalues(n) ** 2
    tr = (1.0 / (1.0 + np.outer(mu, lam2))).sum(axis=1)
    sq = (x - smooth) ** 2
    if measured is None:
        rms = np.sqrt(np.mean(sq, axis=0))
    else:
        count = measured.sum(axis=0)
        rms = np.sqrt(np.where(measured, sq, 0.0).sum(axis=0) / np.maximum(count, 1))
    noise = rms / np.sqrt(np.clip(1.0 - tr / n, 1e-6, None))
    return smooth, noise
