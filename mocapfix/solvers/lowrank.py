"""Low-rank kernels shared by the matrix-based cleaners.

Plain functions on arrays in the (T, C) layout (rows = frames, columns = channels), with
T >> C in motion capture, so every decomposition is of a C x C matrix or a thin SVD --
never a T x T matrix.

- :func:`shrink` -- entrywise soft threshold, the proximal operator of ``tau * ||X||_1``.
- :func:`svt` -- singular value thresholding, the proximal operator of ``tau * ||X||_*``
  (Cai, Candes & Shen 2010, "A singular value thresholding algorithm for matrix
  completion", eq. 2.2). Used by TSMC (Feng et al. 2014, Alg. 2) and Yang et al. 2019.
- :func:`rank_for_variance` / :func:`lowrank_approx` -- truncated SVD (Eckart-Young).
- :func:`ppca_fit` / :func:`conditional_mean` -- the maximum-likelihood probabilistic PCA
  of Tipping & Bishop (1999, "Probabilistic principal component analysis", eq. 7-8) and
  the Gaussian conditional mean of missing columns given the observed ones.
- :func:`leave_block_out_residual` -- every marker against its PPCA prediction from the
  other markers of its frame (the prior of ``tsmc``'s ``prior: pca``).
- :func:`impute_lowrank` -- iterative low-rank imputation ("SVDimpute", Troyanskaya et al.
  2001; the iterative PCA gap filling of Gloersen & Federolf 2016): fill, fit, re-predict
  the missing entries from the observed ones, repeat until the fill stops moving.
"""
from __future__ import annotations


import numpy as np


def blas_single_thread():
    """Context manager holding BLAS/LAPACK to one thread (``threadpoolctl``). The matrices
    of these kernels are small (C x C with C = 3 x markers, 3T x S SVDs, 3 x 3 blocks),
    where threads only add overhead: measured 4-30x slower on a loaded 2-core machine
    (fill_pca, lowrank_isometry), and a process pool already uses every core."""
    from threadpoolctl import threadpool_limits

    return threadpool_limits(1)


def shrink(X, tau):
    """Soft threshold ``sign(X) * max(|X| - tau, 0)``, entrywise.

    Parameters
    ----------
    X : array_like
        Any shape.
    tau : float or array_like
        Threshold (>= 0), broadcast against ``X``.

    Returns
    -------
    ndarray of the shape of ``X`` (float64).
    """
    X = np.asarray(X, dtype=np.float64)
    return np.sign(X) * np.maximum(np.abs(X) - tau, 0.0)


def svt(X, tau, return_rank: bool = False):
    """Singular value thresholding ``U diag(max(s - tau, 0)) V^T``.

    The minimiser of ``tau ||Y||_* + 1/2 ||Y - X||_F^2`` (Cai, Candes & Shen 2010).
    A matrix at least twice as long as it is wide (motion matrices: 3J channels × T
    frames) goes through the Gram matrix of its short side: with ``A = U S Vᵀ``,
    ``AᵀA = V S² Vᵀ`` and ``svt(A) = A V diag((s − tau)/s) Vᵀ`` — two products with the
    small side instead of a thin SVD (≈ 20× faster for 4,500 × 123); a wide matrix uses
    ``AAᵀ`` the same way, from the left, so a C-contiguous (channels, frames) matrix comes
    back C-contiguous. Directions with
    ``s <= 1e-8 s_max`` are below the Gram matrix's precision and treated as zero. Other
    shapes use the thin SVD, O(m n min(m, n)).

    Parameters
    ----------
    X : array_like, shape (m, n)
    tau : float
        Threshold on the singular values (>= 0).
    return_rank : bool
        Also return the number of singular values left above zero.

    Returns
    -------
    Y : ndarray, shape (m, n)
    rank : int, only when ``return_rank``.
    """
    X = np.asarray(X, dtype=np.float64)
    if tau < 0:
        raise ValueError("svt: tau must be >= 0")
    m, n = X.shape
    if max(m, n) >= 2 * min(m, n) and min(m, n) > 0:
        wide = m < n
        w, V = np.linalg.eigh(X @ X.T if wide else X.T @ X)   # Gram of the short side
        s = np.sqrt(np.clip(w, 0.0, None))
        keep = s > max(tau, 1e-8 * (s[-1] if s.size else 0.0))
        rank = int(np.count_nonzero(keep))
        Vk = V[:, keep]
        f = (s[keep] - tau) / s[keep]
        # products in the order that keeps the long side contiguous (no transposes)
        Y = (Vk * f) @ (Vk.T @ X) if wide else (X @ (Vk * f)) @ Vk.T
        return (Y, rank) if return_rank else Y
    U, s, Vt = np.linalg.svd(X, full_matrices=False)
    s = np.maximum(s - tau, 0.0)
    rank = int(np.count_nonzero(s))
    Y = (U[:, :rank] * s[:rank]) @ Vt[:rank]
    return (Y, rank) if return_rank else Y


def rank_for_variance(eigenvalues, variance: float) -> int:
    """Smallest k whose k leading eigenvalues (variances, decreasing) hold ``variance``
    (a fraction in (0, 1]) of the total; at least 1."""
    ev = np.clip(np.asarray(eigenvalues, dtype=np.float64), 0.0, None)
    total = ev.sum()
    if total <= 0:
        return 1
    k = int(np.searchsorted(np.cumsum(ev) / total, variance * (1 - 1e-12)) + 1)
    return min(max(k, 1), len(ev))


def lowrank_approx(X, rank: int | None = None, variance: float | None = None):
    """Best rank-k approximation of ``X`` in the Frobenius norm (truncated SVD).

    Give ``rank``, or ``variance`` (fraction of the squared singular values to keep).
    Returns ``(approximation, k)``.
    """
    X = np.asarray(X, dtype=np.float64)
    U, s, Vt = np.linalg.svd(X, full_matrices=False)
    if rank is None:
        rank = rank_for_variance(s ** 2, 1.0 if variance is None else variance)
    rank = int(min(max(rank, 0), len(s)))
    return (U[:, :rank] * s[:rank]) @ Vt[:rank], rank


def ppca_fit(X, variance: float = 0.99, rank: int | None = None):
    """Maximum-likelihood probabilistic PCA of the rows of ``X`` (T, C).

    Tipping & Bishop (1999), eq. 7-8: ``W = V_k (L_k - sigma2 I)^{1/2}``, with
    ``sigma2`` the mean of the discarded eigenvalues of the sample covariance. The
    covariance is C x C (eigen-decomposition, never T x T).

    Parameters
    ----------
    X : ndarray (T, C), no NaN.
    variance : float
        Keep the fewest components holding this fraction of the variance...
    rank : int, optional
        ...unless a fixed number of components is given.

    Returns
    -------
    mean (C,), W (C, k), sigma2 (float), k (int)
    """
    X = np.asarray(X, dtype=np.float64)
    mean = X.mean(axis=0)
    Z = X - mean
    return ppca_from_moments(mean, Z.T @ Z / max(len(X), 1), variance, rank)


def ppca_from_moments(mean, cov, variance: float = 0.99, rank: int | None = None):
    """:func:`ppca_fit` from the sample mean (C,) and covariance (C, C). The PPCA of
    column-weighted data ``X diag(w)`` is this with ``mean * w`` and ``cov * w wᵀ`` — one
    C×C product per weighting instead of a pass over the T rows."""
    ev, V = np.linalg.eigh(cov)
    ev, V = np.clip(ev[::-1], 0.0, None), V[:, ::-1]
    k = rank_for_variance(ev, variance) if rank is None else int(min(max(rank, 1), len(ev)))
    sigma2 = float(ev[k:].mean()) if k < len(ev) else 0.0
    W = V[:, :k] * np.sqrt(np.clip(ev[:k] - sigma2, 0.0, None))
    return mean, W, sigma2, k


def leave_block_out_residual(X, mean, W, sigma2, block: int = 3):
    """Residual of every column block of ``X`` (T, C) against its prediction from the other
    columns of the same row, under the PPCA model ``x ~ N(mean, Σ)``, ``Σ = W Wᵀ + σ² I``.

    With the precision ``Λ = Σ⁻¹``, the Gaussian conditional mean of block b given the rest
    is ``μ_b − Λ_bb⁻¹ Λ_b,rest (x_rest − μ_rest)``, so the residual is
    ``x_b − E[x_b | x_rest] = Λ_bb⁻¹ (Λ (x − μ))_b`` (e.g. Rue & Held 2005, "Gaussian
    Markov random fields", Thm 2.5): one C×C inverse, one (T, C) product and C/block
    small solves, for every row and every block at once. ``block = 3``: one marker.
    σ² = 0 (all components kept) gets a ridge of 1e-9 of the mean variance.

    Returns the residual (T, C); ``X − residual`` is the leave-one-marker-out prediction.
    """
    X = np.asarray(X, dtype=np.float64)
    C = X.shape[1]
    if C % block:
        raise ValueError("leave_block_out_residual: columns must be whole blocks")
    cov = W @ W.T
    ridge = max(float(sigma2), 1e-9 * float(np.trace(cov)) / C, 1e-300)
    precision = np.linalg.inv(cov + ridge * np.eye(C))
    G = (X - mean) @ precision                                   # Λ symmetric
    nb = C // block
    diag = np.stack([precision[b * block:(b + 1) * block, b * block:(b + 1) * block]
                     for b in range(nb)])                        # (nb, block, block)
    G = G.reshape(len(X), nb, block)
    R = np.linalg.solve(diag[None], G[..., None])[..., 0]        # Λ_bb⁻¹ (Λ(x − μ))_b
    return R.reshape(len(X), C)


def conditional_mean(rows, missing, mean, W, sigma2):
    """Predict the ``missing`` columns of ``rows`` from their other columns under the PPCA
    model ``x ~ N(mean, W W^T + sigma2 I)``.

    ``z = (W_o^T W_o + sigma2 I)^{-1} W_o^T (x_o - mean_o)`` (posterior mean of the
    latent, Tipping & Bishop eq. 34 restricted to the observed columns), ``x_m = mean_m +
    W_m z``. With ``sigma2 = 0`` this is the least-squares fit of the observed columns,
    i.e. the fixed point of EM imputation with a rank-k basis.

    Parameters
    ----------
    rows : ndarray (n, C); values in ``missing`` columns are ignored.
    missing : bool ndarray (C,), the same for every row.
    mean, W, sigma2 : from :func:`ppca_fit`.

    Returns
    -------
    ndarray (n, missing.sum()).
    """
    missing = np.asarray(missing, dtype=bool)
    observed = ~missing
    Wo = W[observed]
    gram = Wo.T @ Wo
    ridge = sigma2 if sigma2 > 0 else 1e-10 * (np.trace(gram) / max(len(gram), 1) + 1e-300)
    gram[np.diag_indices_from(gram)] += ridge
    z = np.linalg.solve(gram, Wo.T @ (rows[:, observed] - mean[observed]).T)
    return (W[missing] @ z).T + mean[missing]


def missing_patterns(missing):
    """Group the rows of a (T, C) boolean mask by their pattern.

    Returns ``(rows, patterns, inverse)``: the indices of the rows with something missing,
    the distinct patterns (P, C) among them, and the pattern index of each such row."""
    missing = np.asarray(missing, dtype=bool)
    rows = np.flatnonzero(missing.any(axis=1))
    if not len(rows):
        return rows, np.zeros((0, missing.shape[1]), bool), np.zeros(0, np.intp)
    # rows packed to bytes and compared as one opaque key: ~10x faster than
    # np.unique(axis=0), which sorts boolean rows column by column
    packed = np.ascontiguousarray(np.packbits(missing[rows], axis=1))
    keys = packed.view(np.dtype((np.void, packed.shape[1]))).ravel()
    _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    return rows, missing[rows[first]], inverse.ravel()


def conditional_mean_rows(X, grouping, mean, W, sigma2, at=None):
    """:func:`conditional_mean` for rows with different missing patterns at once.

    ``grouping`` is :func:`missing_patterns` of the missing mask. One k x k system per
    distinct pattern (``W_o^T W_o = W^T W - W_m^T W_m``, inverted as a batch), then one
    (rows of the pattern) x k product per pattern and one product for all rows -- a
    handful of array operations however many rows there are.

    Returns the predictions (len(rows), C) of every column of those rows (callers keep the
    missing ones), or with ``at = (i, c)`` (indices into those rows and the columns) only
    the predictions of those entries, (len(i),).
    """
    rows, patterns, inverse = grouping
    k = W.shape[1]
    if not len(rows):
        return np.zeros((0, W.shape[0]))
    gram = W.T @ W
    missing_W = patterns[:, :, None] * W[None]                      # (P, C, k)
    grams = gram[None] - np.swapaxes(missing_W, 1, 2) @ W
    scale = np.trace(gram) / max(k, 1)
    ridge = sigma2 if sigma2 > 0 else 1e-10 * scale + 1e-300
    grams[:, np.arange(k), np.arange(k)] += ridge
    inverses = np.linalg.inv(grams)
    centred = X[rows] - mean
    centred[patterns[inverse]] = 0.0
    proj = centred @ W                                              # (n, k)
    z = np.empty_like(proj)
    order = np.argsort(inverse, kind="stable")
    bounds = np.searchsorted(inverse[order], np.arange(len(patterns) + 1))
    for p in range(len(patterns)):                # the rows of one pattern share its inverse
        sel = order[bounds[p]:bounds[p + 1]]
        z[sel] = proj[sel] @ inverses[p].T
    if at is not None:
        i, c = at
        return np.einsum("nk,nk->n", z[i], W[c]) + mean[c]
    out = z @ W.T
    out += mean
    return out


class _Moments:
    """Mean and covariance (as :func:`ppca_fit` computes them) of a (T, C) matrix whose
    ``changing`` columns are rewritten between calls while the others stay fixed: the
    fixed block is computed once and each call recomputes only the changing columns'
    rows and columns of the covariance (C × |changing| products instead of C × C)."""

    def __init__(self, X, changing):
        self.changing = np.asarray(changing, dtype=np.intp)
        self.mean = X.mean(axis=0)
        self.Z = X - self.mean
        self.cov = self.Z.T @ self.Z / max(len(X), 1)

    def update(self, X):
        c = self.changing
        if len(c):
            self.mean[c] = X[:, c].mean(axis=0)
            self.Z[:, c] = X[:, c] - self.mean[c]
            block = self.Z.T @ self.Z[:, c] / max(len(X), 1)           # (C, |c|)
            self.cov[:, c] = block
            self.cov[c, :] = block.T
        return self.mean.copy(), self.cov.copy()


#: a SQUAREM step is kept unless its residual grows beyond this many times the last one
_SQUAREM_LEASH = 100.0


def impute_lowrank(X, missing, variance: float = 0.99, rank: int | None = None,
                   max_iter: int = 100, tol: float = 0.0, accelerate: bool = True):
    """Iterative low-rank imputation of the ``missing`` entries of ``X`` (T, C).

    The map ``F``: fit :func:`ppca_fit` on the matrix completed with the current fill;
    predict every missing entry by its conditional mean given the observed entries of its
    row (:func:`conditional_mean_rows`). The fill is iterated to a fixed point of ``F``:
    stop when ``F`` moves no missing entry by more than ``tol``, or after ``max_iter``
    evaluations of ``F`` (fits). Observed entries never change. One evaluation costs one
    C x C eigen-decomposition, one k x k inverse per missing pattern, a few (T, C) x (C, k)
    products and the covariance of the columns with missing entries against all
    (:class:`_Moments`: the rest of the covariance does not change).

    ``accelerate`` (default): SQUAREM (Varadhan & Roland 2008, "Simple and globally
    convergent methods for accelerating the convergence of any EM algorithm", Scand. J.
    Stat. 35:335-353; scheme S3, step ``alpha = -|r| / |v|`` with ``r = F(x) - x``,
    ``v = F(F(x)) - 2 F(x) + x``, new point ``x - 2 alpha r + alpha^2 v`` followed by one
    ``F``). Plain iteration creeps where markers with gaps are strongly correlated: on
    CMU 85_02 (1,200 frames, a quarter of the markers with 1-3 gaps of 0.1-1.5 s) it
    needed 300-1,300 fits, and the 300-fit cap stopped it up to 45 mm from its fixed
    point; SQUAREM reaches the same fixed point in 55-160 fits. Safeguards: a step whose
    residual ``|F(x') - x'|`` is more than ``_SQUAREM_LEASH`` times the residual it started
    from (or not finite) is dropped for the two plain steps already taken; stopped by
    ``max_iter``, the fill returned is the one with the smallest residual seen. EM
    residuals can jump and then fall: a leash of 10 threw away useful steps (tsmc's prior
    on 500 frames of 85_02: 1,043 fits against 195 with 100; plain iteration 1,636).

    Parameters
    ----------
    X : ndarray (T, C); missing entries hold an initial guess (e.g. interpolation).
    missing : bool ndarray (T, C).
    variance, rank : see :func:`ppca_fit`.
    max_iter : int >= 1, evaluations of ``F``.
    tol : float, in the unit of ``X``.
    accelerate : bool, SQUAREM (True) or plain iteration.

    Returns
    -------
    completed (T, C), info dict (iterations = fits, rank, last_change, converged,
    model=(mean, W, sigma2) of the fit on the completed matrix).
    """
    X = np.array(X, dtype=np.float64)
    missing = np.asarray(missing, dtype=bool)
    grouping = missing_patterns(missing)
    rows = grouping[0]
    hole_row, hole_col = np.nonzero(missing[rows])          # the holes, by row of ``rows``
    hole_x = rows[hole_row]                                 # ... and by row of X
    moments = _Moments(X, np.unique(hole_col))
    model = ppca_from_moments(*moments.update(X), variance, rank)
    fits = 0

    def step(x):
        """F(x): the model fitted with the holes at ``x``, and its prediction of them."""
        nonlocal model, fits
        if x is not None:
            X[hole_x, hole_col] = x
            model = ppca_from_moments(*moments.update(X), variance, rank)
        fits += 1
        return conditional_mean_rows(X, grouping, *model[:3], at=(hole_row, hole_col))

    change = 0.0
    if len(rows):
        x = X[hole_x, hole_col].copy()
        fx = step(None)                                     # the model of X is fitted already
        change = float(np.max(np.abs(fx - x)))
        best = (float(np.linalg.norm(fx - x)), fx, change)
        while change > tol and fits < max_iter:
            if not accelerate or fits + 2 > max_iter:
                x, fx = fx, step(fx)
            else:
                ffx = step(fx)
                r, v = fx - x, ffx - 2 * fx + x
                vv = float(v @ v)
                alpha = min(-np.sqrt(float(r @ r) / vv), -1.0) if vv > 0 else -1.0
                trial = x - 2 * alpha * r + alpha * alpha * v
                f_trial = step(trial)
                if (np.isfinite(f_trial).all()
                        and np.linalg.norm(f_trial - trial) <= _SQUAREM_LEASH * np.linalg.norm(r)):
                    x, fx = trial, f_trial
                else:                                       # thrown far: keep the plain steps
                    x, fx = fx, ffx
            change = float(np.max(np.abs(fx - x)))
            residual = float(np.linalg.norm(fx - x))
            if residual < best[0]:
                best = (residual, fx, change)
        if change > tol:                                    # stopped by max_iter
            _, fx, change = best
        X[hole_x, hole_col] = fx
        model = ppca_from_moments(*moments.update(X), variance, rank)
    info = dict(iterations=fits, rank=int(model[3]), last_change=change,
                converged=bool(change <= tol), model=model[:3])
    return X, info
