"""Weighted Whittaker smoothing on an uneven time axis, with the smoothing strength chosen
from the data by generalised cross-validation.

The smoother (Whittaker 1923; Eilers 2003, "A perfect smoother", Anal. Chem. 75, eq. 3
with weights, eq. 6) minimises over z

    Σ_i w_i (y_i − z_i)²  +  λ Σ_i Δ_i (d! · z[t_i, …, t_{i+d}])²

where ``z[t_i, …, t_{i+d}]`` is the d-th divided difference (so ``d! ·`` it approximates
the d-th derivative on any time axis, dropped frames included) and ``Δ_i = (t_{i+d} −
t_i) / d`` its share of the time axis (the penalty approximates ``λ ∫ (z^{(d)})² dt``):
λ is in physical units and means the same at 15 or 30 fps. Weights 0 mark missing
samples, which the solution interpolates (a natural spline of degree 2d − 1 through the
gap). The normal equations ``(W + λ DᵀΔD) z = W y`` are banded (bandwidth d) and solved
with a banded Cholesky factorisation, O(T d²) per channel group.

Choice of λ: GCV (Craven & Wahba 1979) ``V(λ) = n · RSS_w / (n − edf)²`` over a grid,
with ``edf = tr(H)`` taken from the smoother's spectrum on an even grid with even
weights, ``Σ_k 1 / (1 + λ h / w̄ · (2 sin(π k / 2n))^{2d} / h^{2d})`` (Eilers 2003 §"Cross-
validation" uses the exact diagonal; this closed form avoids the O(T) inverse and is
exact away from the ends for an even grid).
"""
from __future__ import annotations

import math

import numpy as np


def penalty_bands(t: np.ndarray, order: int) -> np.ndarray:
    """``DᵀΔD`` of the module docstring in LAPACK lower banded storage, (order + 1, T)."""
    t = np.asarray(t, dtype=np.float64)
    return _bands(t, np.arange(max(len(t) - order, 0)), order)


def stretch_bands(t: np.ndarray, starts: np.ndarray, stops: np.ndarray, order: int):
    """``DᵀΔD`` of the stretches ``t[starts[k]:stops[k]]`` laid end to end, each penalised
    on its own (no difference spans two stretches): one banded system whose solve smooths
    every stretch at once. Returns (bands (order + 1, N), the index into ``t`` of each of
    the N rows)."""
    t = np.asarray(t, dtype=np.float64)
    starts, stops = np.asarray(starts, dtype=np.intp), np.asarray(stops, dtype=np.intp)
    lengths = stops - starts
    first = np.cumsum(lengths) - lengths                     # each stretch's first row
    rows = np.arange(int(lengths.sum()))
    index = rows + np.repeat(starts - first, lengths)
    inner = rows - np.repeat(first, lengths)                 # position within the stretch
    heads = rows[inner < np.repeat(lengths, lengths) - order]
    return _bands(t[index], heads, order), index


def difference_coefficients(t: np.ndarray, order: int) -> tuple[np.ndarray, np.ndarray]:
    """The coefficients (n, d+1) of d! x each d-th divided difference on ``t[i..i+d]``
    and its share of the time axis Δ_i (n,), for the n = T - d differences of ``t``: what
    :func:`smooth_varying` needs, to compute once per time axis."""
    t = np.asarray(t, dtype=np.float64)
    return _coefficients(t, np.arange(max(len(t) - order, 0)), order)


def _coefficients(t: np.ndarray, heads: np.ndarray, d: int):
    tt = t[heads[:, None] + np.arange(d + 1)[None, :]]      # (n, d+1)
    diff = tt[:, :, None] - tt[:, None, :]                   # (n, d+1, d+1)
    eye = np.eye(d + 1, dtype=bool)
    prod = np.prod(np.where(eye, 1.0, diff), axis=2)
    return math.factorial(d) / prod, (tt[:, -1] - tt[:, 0]) / d


def _bands(t: np.ndarray, heads: np.ndarray, order: int, scale: np.ndarray | None = None,
           coefficients: tuple | None = None) -> np.ndarray:
    """The banded ``DᵀΔD`` over ``t`` with one d-th difference on ``t[i..i+d]`` for each
    ``i`` of ``heads`` (weighted by ``scale``, one per head, if given; ``coefficients``:
    those of :func:`_coefficients`, if already computed)."""
    d = order
    ab = np.zeros((d + 1, len(t)))
    if not len(heads):
        return ab
    c, delta = _coefficients(t, heads, d) if coefficients is None else coefficients
    if scale is not None:
        delta = delta * scale
    for p in range(d + 1):
        for q in range(p, d + 1):
            ab[q - p, heads + p] += c[:, p] * c[:, q] * delta
    return ab


def smooth(y: np.ndarray, w: np.ndarray, t: np.ndarray, lam: float, *, order: int = 2,
           bands: np.ndarray | None = None) -> np.ndarray:
    """The weighted Whittaker smooth of ``y`` (T, C) with weights ``w`` (T,), common to
    the C channels (NaN in ``y`` where ``w`` is 0)."""
    y = np.asarray(y, dtype=np.float64)
    ab = (penalty_bands(t, order) if bands is None else bands) * lam
    ab[0] = ab[0] + w + 1e-12
    rhs = np.where(w[:, None] > 0, y, 0.0) * w[:, None]
    from scipy.linalg import solveh_banded  # imported here: not loaded unless needed
    return solveh_banded(ab, rhs, lower=True, check_finite=False)


def effective_dof(n: int, h: float, lam_over_w: np.ndarray, order: int) -> np.ndarray:
    """Trace of the hat matrix of the even-grid (step h), even-weight smoother (module
    docstring) for every value of ``λ / w̄`` given (the penalty's Δ = h included)."""
    k = np.arange(n)
    mu = h * (2.0 * np.sin(np.pi * k / (2.0 * n))) ** (2 * order) / h ** (2 * order)
    lam_over_w = np.atleast_1d(lam_over_w)
    return np.sum(1.0 / (1.0 + lam_over_w[:, None] * mu[None, :]), axis=1)


def smooth_gcv(y: np.ndarray, w: np.ndarray, t: np.ndarray, grid: np.ndarray, *,
               order: int = 2, bands: np.ndarray | None = None, refine: bool = False):
    """The smooth of ``y`` (T, C) at the λ of ``grid`` (increasing) with the lowest GCV
    score; with ``refine`` the geometric midpoints on both sides of the best grid value
    are tried too.

    Returns (z, lam, edf). Weights are relative (only their ratios matter to the fit;
    GCV uses the mean weight of the observed samples)."""
    t = np.asarray(t, dtype=np.float64)
    bands = penalty_bands(t, order) if bands is None else bands
    seen = w > 0
    n = int(seen.sum())
    if n <= order + 1:
        return np.where(seen[:, None], y, np.nan), float("nan"), float(n)
    h = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    wbar = float(w[seen].mean())

    def evaluate(lams):
        out = []
        for lam, e in zip(lams, effective_dof(n, h, np.asarray(lams) / wbar, order)):
            z = smooth(y, w, t, lam, order=order, bands=bands)
            r = np.where(seen[:, None], y - z, 0.0)
            rss = float(np.sum(w[:, None] * r * r))
            out.append((n * rss / max(n - e, 1e-9) ** 2, z, float(lam), float(e)))
        return out

    grid = np.asarray(grid, dtype=np.float64)
    results = evaluate(grid)
    k = int(np.argmin([r[0] for r in results]))
    best = results[k]
    if refine and len(grid) > 1:
        mids = [np.sqrt(grid[k] * grid[i]) for i in (k - 1, k + 1) if 0 <= i < len(grid)]
        best = min([best] + evaluate(mids), key=lambda r: r[0])
    return best[1], best[2], best[3]


def lambda_for_cutoff(cutoff_hz, mean_weight: float, h: float, order: int) -> np.ndarray:
    """λ whose even-grid (step h) smoother has gain 1/2 at ``cutoff_hz``:
    λ h (2π f)^{2d} = w̄ (low-frequency approximation of the spectrum above)."""
    f = np.asarray(cutoff_hz, dtype=np.float64)
    return mean_weight / (h * (2.0 * np.pi * f) ** (2 * order))


def local_sure_candidates(y: np.ndarray, w: np.ndarray, t: np.ndarray, lams, *, order: int = 2,
                          bands: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The smooths of ``y`` (T, C) at every λ of ``lams`` and the estimated risk of each
    sample under each: Stein's unbiased risk (Stein 1981, "Estimation of the mean of a
    multivariate normal distribution", Ann. Stat. 9(6), eq. 8, with the linear smoother's
    divergence = the trace of its hat matrix) in units of the noise,
    ``w_i |y_i − z_i|² / s² − C + 2 C h_i``, the hat diagonal ``h_i`` taken as
    ``(w_i / w̄) edf(λ) / n`` from the even-grid spectrum (:func:`effective_dof`) and the
    noise scale ``s²`` of the weights estimated at the middle λ (``RSS / (C (n − edf))``),
    so only relative weights matter. Returns (Zs (K, T, C), risk (K, T); risk 0 where
    the weight is 0)."""
    y = np.asarray(y, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    bands = penalty_bands(t, order) if bands is None else bands
    lams = np.atleast_1d(np.asarray(lams, dtype=np.float64))
    seen = w > 0
    n = int(seen.sum())
    T, C = y.shape
    Zs = np.empty((len(lams), T, C))
    Q = np.empty((len(lams), T))
    yz = np.where(seen[:, None], y, 0.0)
    rhs = yz * w[:, None]
    diag = w + 1e-12
    from scipy.linalg import solveh_banded

    for k, lam in enumerate(lams):
        ab = bands * lam                     # as smooth(), with the right-hand side shared
        ab[0] += diag
        Zs[k] = solveh_banded(ab, rhs, lower=True, check_finite=False, overwrite_ab=True)
        r = yz - Zs[k]
        Q[k] = w * np.einsum("tc,tc->t", r, r)
    if n <= order + 1:
        return Zs, np.zeros((len(lams), T))
    h = float(np.median(np.diff(t))) if T > 1 else 1.0
    wbar = float(w[seen].mean())
    edf = effective_dof(n, h, lams / wbar, order)
    mid = len(lams) // 2
    s2 = max(float(Q[mid][seen].sum()) / (C * max(n - edf[mid], 1.0)), 1e-300)
    hat = np.minimum((w / wbar)[None, :] * (edf / n)[:, None], 1.0)
    risk = np.where(seen[None, :], Q / s2 - C + 2.0 * C * hat, 0.0)
    return Zs, risk


def local_lambdas(lams, risk: np.ndarray, half: int) -> tuple[np.ndarray, np.ndarray]:
    """A smoothing strength per sample from local risk: the λ of ``lams`` whose ``risk``
    (K, T) summed over the samples within ±``half`` is least (varying-bandwidth selection,
    e.g. Katkovnik 1999, "A new method for varying adaptive bandwidth selection", IEEE
    Trans. Signal Process. 47(9)), its log then averaged over ±``half`` so the strength
    changes gradually. Returns (λ (T,), index of the least-risk λ (T,))."""
    from scipy.ndimage import uniform_filter1d

    local = uniform_filter1d(risk, 2 * half + 1, axis=1, mode="nearest")
    pick = np.argmin(local, axis=0)
    log_lam = uniform_filter1d(np.log(np.asarray(lams, dtype=np.float64))[pick], 2 * half + 1,
                               mode="nearest")
    return np.exp(log_lam), pick


def smooth_varying(y: np.ndarray, w: np.ndarray, t: np.ndarray, lam: np.ndarray, *,
                   order: int = 2, coefficients: tuple | None = None) -> np.ndarray:
    """The weighted Whittaker smooth of ``y`` (T, C) with a strength ``lam`` (T,) that
    changes along time: the d-th difference on ``t[i..i+d]`` is penalised by the geometric
    mean of ``lam`` over those d + 1 samples -- a penalty weight varying along the axis, as
    in spatially adaptive smoothing splines (Pintore, Speckman & Holmes 2006, J. Multivar.
    Anal. 97(5), eq. 2.1). One banded solve; ``coefficients``: the time axis's
    :func:`difference_coefficients`, if already computed."""
    t = np.asarray(t, dtype=np.float64)
    T, d = len(t), order
    n = max(T - d, 0)
    csum = np.concatenate([[0.0], np.cumsum(np.log(lam))])
    scale = np.exp((csum[d + 1:] - csum[:n]) / (d + 1)) if n else np.zeros(0)
    bands = _bands(t, np.arange(n), d, scale, coefficients)
    return smooth(y, w, t, 1.0, order=order, bands=bands)


def smooth_local_sure(y: np.ndarray, w: np.ndarray, t: np.ndarray, lams, *, order: int = 2,
                      bands: np.ndarray | None = None, half: int = 15,
                      coefficients: tuple | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The smooth of ``y`` (T, C) with a strength that changes along time: each sample's
    λ is the one of least estimated risk (:func:`local_sure_candidates`) over the samples
    within ±``half`` frames, gradually (:func:`local_lambdas`), in one solve
    (:func:`smooth_varying`; ``bands`` and ``coefficients``: the time axis's
    :func:`penalty_bands` and :func:`difference_coefficients`, if already computed). Slow
    parts keep the strong smoothing, fast ones (a foot's swing) the weak one. Returns (z,
    index of the least-risk λ per sample)."""
    _, risk = local_sure_candidates(y, w, t, lams, order=order, bands=bands)
    lam, pick = local_lambdas(lams, risk, half)
    return smooth_varying(y, w, t, lam, order=order, coefficients=coefficients), pick
