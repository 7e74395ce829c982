"""Per-channel smoothing chosen by Stein's unbiased risk estimate (SURE; Stein 1981).

For a linear smoother z = S y of a channel y = x + e with independent noise
e_t ~ N(0, v_t), ``SURE = ||y − S y||² − Σ v_t + 2 Σ v_t S_tt`` is an unbiased estimate
of ||z − x||² (Stein 1981, eq. for the divergence of a linear estimator). For a
shift-invariant kernel, S_tt is its centre tap, so the risk of every smoother in a
family costs one filtering pass; each channel (or, with ``span``, each sample) takes
the smoother of least risk. The family holds Gaussian kernels (local constant fits)
and Gaussian-weighted local quadratic fits (the equivalent kernel of local polynomial
regression, Fan & Gijbels 1996, eq. 3.5 — a Savitzky–Golay filter with Gaussian
weights): less bias in turns and accelerations, so in fast motion it can average more
samples. The noise may differ per sample (``noise`` as a (T, C) array of standard
deviations), e.g. for unit quaternions, whose components carry rotation noise in
proportion to √(1 − q_i²) (:func:`mocapfix.solvers.rotchannels.noise_shape`).
:func:`sure_piecewise` does the same between the steps (discontinuities) of each group of
columns, so no smoother averages across a cut and a step's large risk does not make the
frames around it go unsmoothed.
"""
from __future__ import annotations

import functools

import numpy as np

#: Gaussian widths tried, in samples (0.7 … 48)
WIDTHS = (0.7, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0, 16.0, 24.0, 32.0, 48.0)
#: widths (samples) of the Gaussian-weighted local quadratic fits tried
QUADRATIC_WIDTHS = (1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0, 16.0, 24.0)


def group_labels(groups, C: int) -> tuple[np.ndarray, int]:
    """(labels (C,) as 0 … G − 1 in label order, G) of ``groups`` (C,) labels; None: every
    column its own group."""
    labels = np.arange(C) if groups is None else np.unique(np.asarray(groups), return_inverse=True)[1]
    return labels, int(labels.max()) + 1 if C else 0


def column_groups(groups, C: int) -> tuple[np.ndarray, np.ndarray]:
    """(labels as :func:`group_labels`, M (C, G) with M[c, labels[c]] = 1: a (…, C) array
    times M sums each group's columns)."""
    labels, G = group_labels(groups, C)
    M = np.zeros((C, G))
    M[np.arange(C), labels] = 1.0
    return labels, M


def group_plan(labels: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """For :func:`group_sums`: per rank q, the columns that are the q-th of their group
    (in column order) and their groups."""
    if not len(labels):
        return []
    order = np.argsort(labels, kind="stable")
    sizes = np.bincount(labels)
    rank = np.empty(len(labels), dtype=np.intp)
    rank[order] = np.arange(len(labels)) - np.repeat(np.cumsum(sizes) - sizes, sizes)
    return [(cols, labels[cols]) for cols in (np.flatnonzero(rank == q) for q in range(int(sizes.max())))]


def group_sums(R: np.ndarray, plan, G: int) -> np.ndarray:
    """(…, G): the columns of R (…, C) summed by group (``plan`` from :func:`group_plan`),
    each group's columns added one after another in column order — so a group's sum does
    not depend on which other columns stand beside it (a matrix product with an indicator
    matrix may add them in another order, and in another again when more groups are
    present), and no (C, G) matrix is built."""
    cols, groups = plan[0] if plan else (np.zeros(0, np.intp), np.zeros(0, np.intp))
    out = np.zeros(R.shape[:-1] + (G,))
    out[..., groups] = R[..., cols]               # each group's first column: 0 + x = x
    for cols, groups in plan[1:]:
        out[..., groups] += R[..., cols]
    return out


def centre_weight(sigma: float) -> float:
    """g_σ(0) of the discrete Gaussian filter ``ndimage.gaussian_filter1d`` applies: the
    middle tap of :func:`gaussian_taps` (cached there)."""
    taps = gaussian_taps(sigma)
    return float(taps[len(taps) // 2])


@functools.lru_cache(maxsize=256)
def local_quadratic_kernel(sigma: float) -> np.ndarray:
    """Taps (2n + 1) of the Gaussian-weighted local quadratic fit evaluated at the centre:
    ``e₀ᵀ (Uᵀ K U)⁻¹ Uᵀ K`` with U = [1, u, u²] and K = exp(−u²/2σ²) (Fan & Gijbels
    1996, eq. 3.5). It reproduces quadratics exactly; its taps sum to 1. Cached and
    read-only (the same few widths serve every channel and piece)."""
    taps = _local_quadratic_taps(sigma)
    taps.setflags(write=False)
    return taps


def _local_quadratic_taps(sigma: float) -> np.ndarray:
    n = int(np.ceil(4 * sigma)) + 1
    u = np.arange(-n, n + 1, dtype=np.float64)
    k = np.exp(-0.5 * (u / sigma) ** 2)
    U = np.stack([np.ones_like(u), u / sigma, (u / sigma) ** 2], axis=1)
    M = U.T @ (k[:, None] * U)
    return np.linalg.solve(M, np.eye(3)[0]) @ (U * k[:, None]).T


def _filter_trend_padded(X: np.ndarray, taps: np.ndarray) -> np.ndarray:
    """Correlate the columns of X with ``taps``, the ends padded by odd reflection about
    the end sample (2 x₀ − x_k), which keeps a linear trend, so a polynomial kernel is
    not bent at the ends."""
    from scipy import ndimage  # imported here: not loaded unless needed

    T, n = len(X), len(taps) // 2
    m = min(n, T - 1)
    head, tail = 2 * X[:1] - X[1:m + 1][::-1], 2 * X[-1:] - X[-m - 1:-1][::-1]
    if n > m:                       # a piece shorter than the kernel: the ends held
        first, last = (head[:1], tail[-1:]) if m else (X[:1], X[-1:])
        head = np.concatenate([np.repeat(first, n - m, axis=0), head])
        tail = np.concatenate([tail, np.repeat(last, n - m, axis=0)])
    P = np.concatenate([head, X, tail])
    return ndimage.correlate1d(P, taps, axis=0, mode="nearest")[n:n + T]


@functools.lru_cache(maxsize=256)
def gaussian_taps(sigma: float) -> np.ndarray:
    """The taps ``ndimage.gaussian_filter1d`` correlates with for ``sigma`` (its impulse
    response, read-only): filtering with them is that function without recomputing the
    kernel on every call."""
    from scipy import ndimage  # imported here: not loaded unless needed

    n = int(4.0 * float(sigma) + 0.5)
    impulse = np.zeros(2 * n + 1)
    impulse[n] = 1.0
    taps = ndimage.gaussian_filter1d(impulse, sigma, mode="constant")
    taps.setflags(write=False)
    return taps


def _family(X, widths, quadratic_widths, max_width):
    from scipy import ndimage  # imported here: not loaded unless needed

    for w in widths:
        if max_width is None or w <= max_width:
            yield ndimage.correlate1d(X, gaussian_taps(w), axis=0, mode="nearest"), centre_weight(w), w
    for w in quadratic_widths:
        if max_width is None or w <= max_width:
            taps = local_quadratic_kernel(w)
            yield _filter_trend_padded(X, taps), float(taps[len(taps) // 2]), w


def sure_gaussian(X: np.ndarray, noise, *, widths=WIDTHS, quadratic_widths=(),
                  max_width: float | None = None, span: float | None = None,
                  groups: np.ndarray | None = None):
    """Each column of X (T, C, no NaN) smoothed by the member of least SURE of a family of
    Gaussian kernels (``widths``, samples) and Gaussian-weighted local quadratic fits
    (``quadratic_widths``). ``noise``: the noise standard deviation, a scalar or a (T, C)
    array. ``max_width`` caps the widths (samples). ``span`` (samples): choose per sample
    instead, by the risk summed over a Gaussian neighbourhood of that width (the smoother
    then varies along the motion: short in a fast turn, long in a hold). ``groups`` (C,
    integer labels): columns with one label take one smoother, chosen by their summed risk
    (the four components of a joint's quaternion: one estimate of one rotation, and a
    choice made from four times the data).
    Returns (Z, widths (C,) — with ``span``, the median width per column)."""
    from scipy import ndimage  # imported here: not loaded unless needed

    X = np.asarray(X, dtype=np.float64)
    V = np.broadcast_to(np.asarray(noise, dtype=np.float64) ** 2, X.shape)
    C = X.shape[1]
    labels, G = group_labels(groups, C)
    plan = group_plan(labels)
    best = X.copy()
    chosen = np.zeros(X.shape if span else C)
    # the identity: SURE = −v + 2v per sample
    risk = group_sums(ndimage.gaussian_filter1d(V, span, axis=0, mode="nearest") if span
                      else V.sum(axis=0), plan, G)
    for Z, centre, w in _family(X, widths, quadratic_widths, max_width):
        per_sample = (X - Z) ** 2 - V + 2 * V * centre
        r = group_sums(ndimage.gaussian_filter1d(per_sample, span, axis=0, mode="nearest") if span
                       else per_sample.sum(axis=0), plan, G)
        better = r < risk
        risk[better] = r[better]
        cols = better[..., labels]
        if span:
            best[cols] = Z[cols]
        else:
            best[:, cols] = Z[:, cols]
        chosen[cols] = w
    return best, (np.median(chosen, axis=0) if span else chosen)


#: pieces smoothed side by side in one call of :func:`sure_gaussian` at most (bounds the
#: arrays of one call however dense a take's steps are)
_PIECES_PER_CALL = 256


def sure_piecewise(X: np.ndarray, noise, *, breaks: np.ndarray | None, groups: np.ndarray | None = None,
                   **options):
    """:func:`sure_gaussian` run separately on the pieces of each group of columns between
    its ``breaks`` ((T − 1, G) mask: no smoothing across t → t + 1 for group g; e.g.
    :func:`mocapfix.solvers.glitches.steps`; None: no break). Groups with no break go
    through one call, and so do the pieces of one length (side by side, up to
    ``_PIECES_PER_CALL`` at a time, each piece a column group of its own: the same values
    as one call per piece — :func:`group_sums` adds a group's risks alike wherever it
    stands — without the per-call cost; a CMU take has hundreds of short pieces between
    steps); pieces shorter than 3
    samples are left as they are. ``options``: those of :func:`sure_gaussian`. Returns
    (Z, widths (C,): the median width per column)."""
    X = np.asarray(X, dtype=np.float64)
    T, C = X.shape
    sd = np.broadcast_to(np.asarray(noise, dtype=np.float64), X.shape)
    labels, G = group_labels(groups, C)
    broken = np.zeros(G, dtype=bool) if breaks is None else np.asarray(breaks, dtype=bool).any(axis=0)
    Z = X.copy()
    widths = np.zeros(C)
    whole = ~broken[labels]
    if whole.any():
        Z[:, whole], widths[whole] = sure_gaussian(X[:, whole], sd[:, whole], groups=labels[whole],
                                                   **options)
    # the pieces, by length: pieces of one length go through one call, side by side as
    # column groups of their own (each still takes its own smoother by its own risk)
    by_length: dict = {}
    for g in np.flatnonzero(broken):
        cuts = np.r_[0, np.flatnonzero(breaks[:, g]) + 1, T]
        for a, b in zip(cuts[:-1], cuts[1:]):
            if b - a >= 3:
                by_length.setdefault(int(b - a), []).append((g, int(a)))
    chosen: dict = {}
    batches = [(L, pieces[i:i + _PIECES_PER_CALL]) for L, pieces in by_length.items()
               for i in range(0, len(pieces), _PIECES_PER_CALL)]
    for L, pieces in batches:
        cols = [np.flatnonzero(labels == g) for g, _ in pieces]
        rows = np.concatenate([np.add.outer(np.arange(a, a + L), np.zeros(len(c), int))
                               for (_, a), c in zip(pieces, cols)], axis=1)
        take = np.concatenate([np.broadcast_to(c, (L, len(c))) for c in cols], axis=1)
        piece_of = np.concatenate([np.full(len(c), n) for n, c in enumerate(cols)])
        Zp, w = sure_gaussian(X[rows, take], sd[rows, take], groups=piece_of, **options)
        Z[rows, take] = Zp
        first = np.r_[0, np.cumsum([len(c) for c in cols])[:-1]]
        for (g, _), k in zip(pieces, first):
            chosen.setdefault(g, []).append(np.repeat(w[k:k + 1], L))
    for g in np.flatnonzero(broken):
        widths[labels == g] = np.median(np.concatenate(chosen[g])) if g in chosen else 0.0
    return Z, widths
