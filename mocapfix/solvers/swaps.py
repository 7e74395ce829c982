"""Marker-swap detection and repair on arrays (positions (T, J, 3), NaN = missing): the
kernels of the ``swaps`` cleaner, whose docstring (:mod:`mocapfix.cleaners.swaps`) gives
the method — continuity events (:func:`swap_gain`, :func:`candidate_pairs`) and rigid
distance templates (:func:`rigid_templates`, :func:`exchanged_segments`), run pair by pair
by :func:`find_swaps`.
"""
from __future__ import annotations

import numpy as np

from mocapfix.solvers.nanstats import nanmedian_columns
from mocapfix.solvers.rigid import norms

_CHUNK_ENTRIES = 200_000   # frames x pairs handled at once in the all-pairs scan (two threads
#                            measured 0.11 s against 0.18 s with 400,000: each chunk stays in cache)
#: ... but at least this many frames a chunk while they stay under _MAX_CHUNK_ENTRIES: with
#: hundreds of markers a chunk of one frame spent half the scan's time on the per-chunk work
#: (328 markers, 2,000 frames: 7.0 s, 3.4 s with chunks of 9 frames)
_MIN_CHUNK_FRAMES = 8
_MAX_CHUNK_ENTRIES = 2_000_000
#: jobs the all-pairs scan's chunks are shared out in (each keeps one running maximum, so
#: what is held does not grow with the take)
_SCAN_JOBS = 16


def _cross_distance(X, Y):
    """(n, J, J) distances ``|Y[:, j] - X[:, i]|`` at [:, i, j] for (n, J, 3) arrays, by
    ``|x|^2 + |y|^2 - 2 x.y`` (a batched matrix product, ``matmul``: ~20x faster than the
    equivalent ``einsum`` here; inputs centred per frame)."""
    sq = X @ np.swapaxes(Y, 1, 2)
    sq *= -2.0                              # in place: 4-5x faster than the temporaries
    sq += np.sum(X * X, axis=-1)[:, :, None]
    sq += np.sum(Y * Y, axis=-1)[:, None, :]
    np.maximum(sq, 0.0, out=sq)
    return np.sqrt(sq, out=sq)


def swap_gain(A, B):
    """Evidence of a label exchange between frames t-1 and t for trajectories A, B.

    A, B: (T, ..., 3). Returns ``keep`` and ``swap`` (T, ...) prediction-error sums
    (NaN at t < 2, t = T-1 and where a sample is missing; see the module docstring) and
    ``apart``, the smaller a-b distance of frames t-1 and t.
    """
    T = A.shape[0]
    keep = np.full(A.shape[:-1], np.nan)
    swap = keep.copy()
    apart = keep.copy()
    if T < 4:
        return keep, swap, apart
    t = np.arange(2, T - 1)
    fa, fb = 2 * A[t - 1] - A[t - 2], 2 * B[t - 1] - B[t - 2]      # forward to t
    ba, bb = 2 * A[t] - A[t + 1], 2 * B[t] - B[t + 1]              # backward to t-1
    keep[t] = norms(A[t] - fa) + norms(B[t] - fb) + norms(A[t - 1] - ba) + norms(B[t - 1] - bb)
    swap[t] = norms(B[t] - fa) + norms(A[t] - fb) + norms(A[t - 1] - bb) + norms(B[t - 1] - ba)
    gap = norms(A - B)
    apart[t] = np.minimum(gap[t], gap[t - 1])
    return keep, swap, apart


def is_event(keep, swap, apart, threshold):
    """Where the exchange gain exceeds ``threshold``, the exchanged labelling explains the
    motion at least twice as well, and the markers are at least ``threshold / 2`` apart
    (closer markers, e.g. a duplicated label, make no error worth repairing)."""
    with np.errstate(invalid="ignore"):
        return (keep - swap > threshold) & (swap < 0.5 * keep) & (apart >= 0.5 * threshold)


def event_frames(keep, swap, apart, threshold):
    """Frames t (1-D arrays for one pair) where a label exchange between t-1 and t is
    likely (:func:`is_event`) and the gain is the largest within +-2 frames."""
    gain = np.nan_to_num(keep - swap, nan=-np.inf)
    ok = is_event(keep, swap, apart, threshold)
    if not ok.any():
        return np.zeros(0, dtype=np.intp)
    padded = np.pad(gain, 2, constant_values=-np.inf)
    window = np.lib.stride_tricks.sliding_window_view(padded, 5)
    return np.flatnonzero(ok & (gain >= window.max(axis=1)))


def rigid_templates(P):
    """For every marker, the other markers ordered by how little their distance to it
    varies (median absolute deviation over frames), and the median distances.

    Returns partners (J, J) -- row j sorted by spread, j itself last -- and the median
    distance matrix (J, J). The distances of up to 600 frames are measured a block of
    markers at a time, each block against the markers from its first on (a distance and
    its statistics are the same both ways, bit for bit), so the temporaries stay near
    :data:`_TEMPLATE_ENTRIES` values: all pairs at once were 600 × J² (2.3 GB with 328
    markers)."""
    T = P.shape[0]
    step = max(1, T // 600)                      # a subsample is enough for medians
    S = P[::step]
    n, J = S.shape[:2]
    med, spread = np.empty((J, J)), np.empty((J, J))
    rows = max(1, _TEMPLATE_ENTRIES // max(n * J, 1))
    for a in range(0, J, rows):
        b = min(a + rows, J)
        D = _pair_distances(S, a, b)             # (T', b - a, J - a)
        m = nanmedian_columns(D)
        D -= m
        s = nanmedian_columns(np.abs(D, out=D))
        med[a:b, a:], spread[a:b, a:] = m, s
        med[b:, a:b], spread[b:, a:b] = m[:, b - a:].T, s[:, b - a:].T
    spread = np.where(np.isnan(spread), np.inf, spread)
    np.fill_diagonal(spread, np.inf)
    return np.argsort(spread, axis=1, kind="stable"), med


#: distances held at once by :func:`rigid_templates` (frames × markers × markers)
_TEMPLATE_ENTRIES = 2_000_000


def _pair_distances(S, first: int = 0, stop: int | None = None):
    """(T, stop − first, J − first) distances from the markers ``first .. stop − 1`` of (T,
    J, 3) ``S`` to the markers from ``first`` on (all of them to all by default): the same
    sums as ``norms(S[:, :, None] - S[:, None])``, one coordinate at a time (6x faster than
    the (T, J, J, 3) difference array)."""
    stop = S.shape[1] if stop is None else stop
    d = None
    for k in range(3):
        x = np.ascontiguousarray(S[:, first:, k])
        diff = x[:, :stop - first, None] - x[:, None, :]
        diff *= diff
        if d is None:
            d = diff
        else:
            d += diff
    return np.sqrt(d, out=d)


def template_cost(X, partners_pos, template):
    """Mean |distance - template| of trajectory X (n, 3) to partner trajectories
    (n, K, 3), per frame (n,); NaN where nothing is observed."""
    d = np.abs(norms(X[:, None] - partners_pos) - template)
    count = np.sum(np.isfinite(d), axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, np.nansum(d, axis=1) / count, np.nan)


def candidate_pairs(P: np.ndarray, threshold: float) -> list[tuple[float, int, int]]:
    """(strength, a, b) of every pair with at least one event, strongest first.

    The same quantities as :func:`swap_gain` for all pairs at once: the ``keep`` error
    is a sum of per-marker terms, the ``swap`` error ``M + M^T`` with ``M[a, b] =
    |x_b(t) - f_a(t)| + |x_b(t-1) - g_a(t)|`` (f, g the forward and backward
    predictions). Chunks of frames keep memory at O(chunk * J^2)."""
    T, J, _ = P.shape
    if T < 4:
        return []
    from mocapfix.core.threads import parallel_map

    t_all = np.arange(2, T - 1)
    iu = np.triu_indices(J, k=1)
    chunk = max(1, _CHUNK_ENTRIES // (J * J), min(_MIN_CHUNK_FRAMES, _MAX_CHUNK_ENTRIES // (J * J)))

    def strongest(t):
        """The largest event strength of every pair on frames ``t`` (-inf: none)."""
        best = np.full(len(iu[0]), -np.inf)
        seen = np.isfinite(P[t - 1]).all(axis=2, keepdims=True)
        centre = (np.where(seen, P[t - 1], 0.0).sum(axis=1, keepdims=True)
                  / np.maximum(seen.sum(axis=1, keepdims=True), 1))
        now, before = P[t] - centre, P[t - 1] - centre
        fwd, bwd = 2 * before - (P[t - 2] - centre), 2 * now - (P[t + 1] - centre)
        own = norms(now - fwd) + norms(before - bwd)                       # (n, J)
        M = _cross_distance(fwd, now)
        M += _cross_distance(bwd, before)                                   # (n, J, J)
        keep = own[:, iu[0]] + own[:, iu[1]]
        swap = M[:, iu[0], iu[1]]
        swap += M[:, iu[1], iu[0]]
        # the a-b distances only where the two other conditions of an event hold
        with np.errstate(invalid="ignore"):
            r, q = np.nonzero((keep - swap > threshold) & (swap < 0.5 * keep))
        if len(r):
            a, b = iu[0][q], iu[1][q]
            apart = np.minimum(norms(now[r, a] - now[r, b]), norms(before[r, a] - before[r, b]))
            hit = np.zeros(keep.shape, bool)
            hit[r, q] = is_event(keep[r, q], swap[r, q], apart, threshold)
            best = np.where(hit, keep - swap, -np.inf).max(axis=0)
        return best

    def strongest_of(chunks):
        """The largest event strength of every pair over ``chunks`` (a running maximum:
        the chunks' own arrays are not held, with hundreds of markers a chunk's is MBs)."""
        best = np.full(len(iu[0]), -np.inf)
        for t in chunks:
            np.maximum(best, strongest(t), out=best)
        return best

    # the chunks are independent (a maximum over them): on the task's threads, in
    # _SCAN_JOBS runs of consecutive chunks
    chunks = [t_all[lo:lo + chunk] for lo in range(0, len(t_all), chunk)]
    per_job = -(-len(chunks) // _SCAN_JOBS)
    jobs = [chunks[k:k + per_job] for k in range(0, len(chunks), per_job)]
    best = np.max(parallel_map(strongest_of, jobs), axis=0, initial=-np.inf)
    found = np.flatnonzero(np.isfinite(best))
    order = found[np.lexsort((iu[1][found], iu[0][found], -best[found]))]
    return [(float(best[p]), int(iu[0][p]), int(iu[1][p])) for p in order]


def exchanged_segments(P, a, b, events, partners, template, threshold, n_partners):
    """Segments between events (and the capture ends) that match the rigid-distance
    templates (of the ``n_partners`` most rigid partners) clearly better with a and b
    exchanged."""
    T = P.shape[0]
    K = n_partners
    pa = [k for k in partners[a] if k not in (a, b)][:K]
    pb = [k for k in partners[b] if k not in (a, b)][:K]
    ta, tb = template[a, pa], template[b, pb]
    A, B = P[:, a], P[:, b]
    keep = template_cost(A, P[:, pa], ta) + template_cost(B, P[:, pb], tb)
    swap = template_cost(B, P[:, pa], ta) + template_cost(A, P[:, pb], tb)
    bounds = np.concatenate([[0], events, [T]])
    segments = list(zip(bounds[:-1].tolist(), bounds[1:].tolist()))
    clear, odd_ok = [], True
    for i, (start, end) in enumerate(segments):
        k, s = keep[start:end], swap[start:end]
        ok = np.isfinite(k) & np.isfinite(s)
        if ok.sum() < max(1, (end - start) // 2):
            odd_ok &= i % 2 == 0
            continue
        mk, ms = k[ok].mean(), s[ok].mean()
        if mk - ms > 0.5 * threshold and ms < 0.5 * mk:
            clear.append((start, end))
        if i % 2 == 1 and ms - mk > 0.5 * threshold:
            odd_ok = False
    if clear:
        return clear
    # symmetric markers (e.g. two on one rigid segment at the same distance from its
    # other markers): the distances cannot tell, so trust paired events -- an even
    # number of them, each exchanged stretch closed by an event inside the capture.
    if len(events) % 2 == 0 and odd_ok:
        return segments[1::2]
    return []


def find_swaps(P: np.ndarray, threshold: float, n_partners: int, max_swaps: int):
    """Marker positions ``P`` (T, J, 3) with the label swaps undone, and the swaps as
    ``(a, b, start, end)``: pairs by decreasing event strength (:func:`candidate_pairs`),
    each on the data as already repaired (module docstring of
    :mod:`mocapfix.cleaners.swaps`)."""
    P = P.copy()
    T, J, _ = P.shape
    swaps: list[tuple[int, int, int, int]] = []
    if J < 3 or T < 6:
        return P, swaps
    candidates = candidate_pairs(P, threshold)
    if not candidates:
        return P, swaps
    partners, template = rigid_templates(P)
    for _, a, b in candidates:
        if len(swaps) >= max_swaps:
            break
        events = event_frames(*swap_gain(P[:, a], P[:, b]), threshold)
        if not len(events):
            continue
        for start, end in exchanged_segments(P, a, b, events, partners, template, threshold,
                                             n_partners):
            if len(swaps) >= max_swaps:
                break
            P[start:end, [a, b]] = P[start:end, [b, a]]
            swaps.append((a, b, int(start), int(end)))
    return P, swaps
