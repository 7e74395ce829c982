"""Glitch (spike) detection on continuous channels: a Hampel identifier on a running
median, confirmed by a local cubic fit across the suspected samples so that fast, smooth
real motion is not taken for a glitch, and cleared when the same deviation recurs
elsewhere in the channel (a gait cycle's toe-off, which a 30 Hz clip samples in two
frames, looks like a glitch once but not in every cycle).

Layout: (T, C) arrays, time along axis 0, NaN = missing.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from mocapfix.core.gaps import runs
from mocapfix.solvers.segments import linear_bridge
from mocapfix.solvers.sure import column_groups


def despike(X: np.ndarray, *, width: int = 7, k: float = 6.0, floor: float = 0.0):
    """(X with spikes replaced, mask of the spikes): a sample farther than
    max(k · 1.4826 · MAD of its channel's residuals, floor) from a running median of
    ``width`` frames is replaced by that median. Gaps are bridged linearly first."""
    X = np.asarray(X, dtype=np.float64)
    filled = linear_bridge(X)
    from scipy import ndimage  # imported here: not loaded unless needed
    med = ndimage.median_filter(filled, size=(width, 1), mode="nearest")
    r = np.abs(filled - med)
    scale = 1.4826 * np.median(r, axis=0)
    mask = r > np.maximum(k * scale, floor)[None, :]
    return np.where(mask, med, filled), mask & ~np.isnan(X)


def glitches(X: np.ndarray, *, width: int = 7, k: float = 6.0, floor: float = 0.0,
             side: int = 4) -> np.ndarray:
    """(T, C) mask of glitches: :func:`despike` candidates that :func:`confirm` keeps (at
    most (width − 1) / 2 samples long, off the cubic through their neighbours by more than
    the same threshold) and :func:`recurring` does not clear."""
    X = np.asarray(X, dtype=np.float64)
    filled = linear_bridge(X)
    from scipy import ndimage  # imported here: not loaded unless needed
    med = ndimage.median_filter(filled, size=(width, 1), mode="nearest")
    r = np.abs(filled - med)
    limit = np.maximum(k * 1.4826 * np.median(r, axis=0), floor)
    cand = (r > limit[None, :]) & ~np.isnan(X)
    # the confirming fit's own spread on this channel: fast or jerky real motion (low
    # frame rates, acrobatics) fits a cubic less well, so it needs a larger deviation
    w = _cubic_weights(1, side)[0]
    kernel = np.r_[w[:side], 0.0, w[side:]][::-1]
    pred = ndimage.correlate1d(filled, kernel[::-1], axis=0, mode="nearest")
    inner = np.abs(filled - pred)[side:-side]
    # a take of at most 2·side frames has no sample to measure the fit's spread on: it is
    # taken as unbounded, which gives the same masks as the NaN of the empty median did
    # (checked on 900 random short takes), without NumPy's "Mean of empty slice" warning
    spread = (1.4826 * np.median(inner, axis=0) if len(inner)
              else np.full(filled.shape[1:], np.inf))
    found = confirm(X, cand, threshold=np.maximum(limit, k * spread), side=side,
                    max_run=(width - 1) // 2)
    return recurring(X, found, side=side)


@lru_cache(maxsize=256)
def _cubic_weights(run: int, side: int) -> np.ndarray:
    """(run, 2·side) weights predicting the ``run`` samples of a gap from a cubic
    least-squares fit to ``side`` samples on each side of it (read-only, computed once per
    ``run`` and ``side``: :func:`contradicted_by_path` asks for them once per run)."""
    t_fit = np.r_[np.arange(-side, 0), np.arange(run, run + side)].astype(float)
    t_gap = np.arange(run, dtype=float)
    V = np.vander(t_fit, 4)
    weights = np.vander(t_gap, 4) @ np.linalg.pinv(V)
    weights.flags.writeable = False
    return weights


def confirm(X: np.ndarray, mask: np.ndarray, *, threshold: np.ndarray, side: int = 4,
            max_run: int = 3) -> np.ndarray:
    """Keep the runs of ``mask`` (per column, at most ``max_run`` long) whose samples lie
    farther than ``threshold`` (per column) from a cubic fitted to ``side`` samples on each
    side of the run: a glitch stands off the curve through its neighbours, a fast turning
    point of real motion does not. A run within ``side`` samples of an end is checked
    against the cubic fitted to the ``2 · side`` samples after (or before) it, extrapolated
    (it used to be kept unchecked: on the 68-frame 30 Hz Bandai run, real leg and toe
    frames at the start were re-made); runs with too few samples there either are kept.
    Longer runs are dropped (not a glitch of this kind)."""
    X = linear_bridge(X)
    T = X.shape[0]
    out = np.zeros_like(mask)
    col, start, length = runs(mask)
    for L in np.unique(length):
        sel = length == L
        if L > max_run:
            continue
        c, s = col[sel], start[sel]
        inside = (s - side >= 0) & (s + L + side <= T)
        for cc, ss in zip(c[~inside], s[~inside]):
            out[ss:ss + L, cc] = _off_one_sided_cubic(X[:, cc], ss, int(L), 2 * side, threshold[cc])
        c, s = c[inside], s[inside]
        if not len(c):
            continue
        idx = np.r_[np.arange(-side, 0), np.arange(L, L + side)]
        fit_vals = X[s[:, None] + idx[None, :], c[:, None]]              # (R, 2·side)
        pred = fit_vals @ _cubic_weights(int(L), side).T                  # (R, L)
        rows = s[:, None] + np.arange(L)[None, :]
        dev = np.abs(X[rows, c[:, None]] - pred).max(axis=1)
        keep = dev > threshold[c]
        for cc, ss in zip(c[keep], s[keep]):
            out[ss:ss + L, cc] = True
    return out


def _off_one_sided_cubic(x: np.ndarray, start: int, run: int, n: int, threshold: float) -> bool:
    """Whether samples ``start .. start + run`` of ``x`` stand farther than ``threshold``
    off the cubic fitted to the ``n`` samples after them (before them, at the end of the
    channel), extrapolated; True when neither side has ``n`` samples."""
    T = len(x)
    if start + run + n <= T and start < T - start - run:
        fit = np.arange(start + run, start + run + n)
    elif start - n >= 0:
        fit = np.arange(start - n, start)
    else:
        return True
    t0 = float(start)
    coef = np.polyfit(fit - t0, x[fit], 3)
    pred = np.polyval(coef, np.arange(run, dtype=float))
    return bool(np.abs(x[start:start + run] - pred).max() > threshold)


#: frames on each side of a run within which :func:`recurring` looks for its recurrences
REACH = 6000


@lru_cache(maxsize=32)
def _beside(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The offsets of the ``n`` samples before and after a window of ``n`` (from its
    start), and the projection that removes a straight line through them."""
    beside = np.r_[np.arange(-n, 0), np.arange(n, 2 * n)]
    trend = np.stack([np.ones(len(beside)), beside / n], axis=1)
    return beside, np.eye(len(beside)) - trend @ np.linalg.pinv(trend)


def recurring(X: np.ndarray, mask: np.ndarray, *, side: int = 4, ratio: float = 0.5,
              window: float = 1.0, context: float = 1.0, count: int = 2,
              reach: int = REACH) -> np.ndarray:
    """``mask`` without the runs whose deviation recurs in their channel with the motion
    around it: a run of ``L`` samples deviates from the cubic through the ``side`` samples
    on each side of it by ``e`` (L values); it is the motion doing what it does elsewhere
    — a toe-off in every gait cycle — and not a glitch when at least ``count`` other
    windows of the channel (each at least one window apart)

    - deviate from their own cubic by within ``ratio · |e|`` of ``e``,
    - hold ``L + 2·side`` samples that, mean removed, lie within ``window · |e|`` of the
      run's, and
    - have beside them (``L + 2·side`` samples before and after) motion whose shape —
      a straight line through those samples removed — lies within ``context`` times its
      own size of the shape around the run.

    The last test keeps glitches alike in amplitude from clearing each other. Only
    windows within ``reach`` frames of the run are compared (:data:`REACH`), so the cost
    grows linearly with the take. Measurements and the known limit (dense glitches on
    strictly periodic motion): docs/methods/rotations.md."""
    X = linear_bridge(np.asarray(X, dtype=np.float64))
    T = X.shape[0]
    out = mask.copy()
    col, start, length = runs(mask)
    cache: dict = {}
    for c, s, L in zip(col, start, length):
        n = int(L) + 2 * side
        lo, hi = s - side - n, s + L + side + n            # the run, its window, beside
        if lo < 0 or hi > T or T < 5 * n:
            continue
        if (c, L) not in cache:          # every window's deviation from its own cubic
            if cache and next(iter(cache))[0] != c:
                cache.clear()            # runs come column by column: one column's kept
            V_all = sliding_window_view(X[:, c], n)                       # (T − n + 1, n)
            sides = np.concatenate([V_all[:, :side], V_all[:, side + L:]], axis=1)
            cache[(c, L)] = V_all, V_all[:, side:side + L] - sides @ _cubic_weights(int(L), side).T
        a = s - side
        # candidate window starts t: n ≤ t ≤ T − 2n (room beside), within reach of a
        first, last = max(n, a - reach), min(T - 2 * n, a + reach)
        V, E = (w[first:last + 1] for w in cache[(c, L)])
        own = a - first
        size = np.sqrt(np.sum(E[own] ** 2))
        t = np.arange(first, last + 1)
        near = (np.sqrt(np.sum((E - E[own]) ** 2, axis=1)) < ratio * size) & (np.abs(t - a) >= n)
        hits = np.flatnonzero(near)
        if len(hits) < count:
            continue
        W = V[hits] - V[hits].mean(axis=1, keepdims=True)
        hits = hits[np.sqrt(np.sum((W - (V[own] - V[own].mean())) ** 2, axis=1)) < window * size]
        hits = hits + first
        beside, shape_of = _beside(n)
        B = X[hits[:, None] + beside, c] @ shape_of
        b0 = X[a + beside, c] @ shape_of
        hits = hits[np.sqrt(np.sum((B - b0) ** 2, axis=1)) < context * np.sqrt(np.sum(b0 ** 2))]
        found, last_hit = 0, None
        for h in hits:                       # distinct recurrences, a window apart
            if last_hit is None or h - last_hit >= n:
                found, last_hit = found + 1, h
                if found >= count:
                    break
        if found >= count:
            out[s:s + L, c] = False
    return out


#: a repair is evidence-based when it leaves at most this share of the summed squared
#: acceleration around it (:func:`limb_contradicts`)
EVIDENCE_RATIO = 0.25
#: frames on each side of a repaired run in which its acceleration is measured
EVIDENCE_CONTEXT = 2


def acceleration_share(before: np.ndarray, after: np.ndarray) -> float:
    """The summed squared second difference (acceleration) of the positions ``after``
    (W, D, 3) over that of ``before``: how much of a window's roughness a repair leaves
    (NaN samples left out; inf when ``before`` has none to lose, or fewer than three
    frames)."""
    if len(before) < 3:
        return np.inf
    rough_before = np.nansum(np.diff(before, n=2, axis=0) ** 2)
    rough_after = np.nansum(np.diff(after, n=2, axis=0) ** 2)
    return float(rough_after / rough_before) if rough_before > 0 else np.inf


def limb_contradicts(before: np.ndarray, after: np.ndarray, *, ratio: float = EVIDENCE_RATIO) -> bool:
    """Whether a repair is evidence-based in world space: the positions of the points it
    moves (the joints below a re-made joint, or a marker) over a window around it,
    ``before`` and ``after`` (W, D, 3), and the repair leaves at most ``ratio`` of their
    summed squared acceleration (:func:`acceleration_share`). A glitch throws the points
    out and back (large accelerations that the repair removes); real fast motion moves
    them along a smooth path, which a wrong repair breaks (the repair then adds
    acceleration). Fewer than three frames: no evidence (False)."""
    return acceleration_share(before, after) <= ratio


def contradicted_by_path(P: np.ndarray, mask: np.ndarray, *, ratio: float = EVIDENCE_RATIO,
                         context: int = EVIDENCE_CONTEXT) -> np.ndarray:
    """``mask`` (T, J) of samples judged wrong on point paths ``P`` (T, J, 3), without the
    runs the path itself does not contradict. Each run is repaired for the test by the
    cubic through the point's two samples on each side of it (every run of ``mask``
    bridged by straight lines first) and kept only when that repair leaves at most
    ``ratio`` of the path's summed squared acceleration over the run and ``context``
    frames on each side, the other runs there repaired alike (:func:`limb_contradicts`):
    a spike thrown out and back goes, a fast turn of real motion — whose peak a curve
    through its neighbours cuts — stays. A run at an end of the
    point's samples is repaired by the straight line through the two samples beyond it;
    with fewer there is no evidence and the run is dropped from the mask. Numpy only (the
    default C3D chain loads no SciPy)."""
    T, J = mask.shape
    keep = np.asarray(mask, dtype=bool).copy()
    if not keep.any():
        return keep
    P = np.asarray(P, dtype=np.float64)
    X = np.where(np.repeat(keep, 3, axis=1), np.nan, P.reshape(T, 3 * J))
    seen = ~np.isnan(X[:, 0::3])
    repaired = linear_bridge(X).reshape(T, J, 3)
    # each run is judged with the other runs near it repaired: a spike two frames away
    # would otherwise stay in both paths and hide what this run's repair does
    context_path = np.where(keep[..., None], repaired, P)
    col, start, length = runs(keep)
    cubic = _cubic_runs(context_path, seen, col, start, length, context)
    for L in np.unique(length[cubic]):
        sel = cubic & (length == L)
        contradicted = _cubic_runs_contradicted(P, context_path, col[sel], start[sel], int(L),
                                                ratio)
        for j, s in zip(col[sel][~contradicted], start[sel][~contradicted]):
            keep[s:s + L, j] = False
    for j, s, n in zip(col[~cubic], start[~cubic], length[~cubic]):
        a, b = max(s - context, 0), min(s + n + context, T)
        before = context_path[a:b, j].copy()
        before[s - a:s - a + n] = P[s:s + n, j]
        if seen[:s, j].any() and seen[s + n:, j].any():
            run = _cubic_across(context_path[:, j], s, n)
        else:
            run = _extrapolated(X[:, 3 * j:3 * j + 3], s, n)
        if run is None:
            keep[s:s + n, j] = False
            continue
        after = before.copy()
        after[s - a:s - a + n] = run
        if not limb_contradicts(before[:, None], after[:, None], ratio=ratio):
            keep[s:s + n, j] = False
    return keep


def _cubic_runs(path: np.ndarray, seen: np.ndarray, col: np.ndarray, start: np.ndarray,
                length: np.ndarray, context: int) -> np.ndarray:
    """Which runs :func:`contradicted_by_path` repairs by the cubic through two samples on
    each side (all four inside the take and present in ``path`` (T, J, 3)) with a window
    of ``context`` = 2 frames on each side inside the take: the runs
    :func:`_cubic_runs_contradicted` judges together."""
    T = len(path)
    ok = (start - 2 >= 0) & (start + length + 1 < T) & (context == 2)
    seen_before = np.cumsum(seen, axis=0)                        # samples seen in [0, t]
    interior = np.zeros_like(ok)
    interior[ok] = (seen_before[start[ok] - 1, col[ok]] > 0) & \
        (seen_before[-1, col[ok]] > seen_before[start[ok] + length[ok] - 1, col[ok]])
    ok &= interior
    for offset in (-2, -1):
        ok[ok] &= ~np.isnan(path[start[ok] + offset, col[ok]]).any(axis=1)
    for offset in (0, 1):
        ok[ok] &= ~np.isnan(path[start[ok] + length[ok] + offset, col[ok]]).any(axis=1)
    return ok


def _cubic_runs_contradicted(P: np.ndarray, path: np.ndarray, col: np.ndarray,
                             start: np.ndarray, length: int, ratio: float) -> np.ndarray:
    """For runs of one ``length`` (points ``col``, first frames ``start``) that
    :func:`_cubic_runs` selects: whether each one's repair by the cubic through the two
    samples of ``path`` on each side leaves at most ``ratio`` of the summed squared
    acceleration of ``P`` over the run and two frames on each side (:func:`limb_contradicts`,
    the arithmetic of the one-run test done for all runs at once: the same products,
    differences and row sums, so the same answers bit for bit)."""
    window = start[:, None] + np.arange(-2, length + 2)
    before = path[window, col[:, None]]                                  # (R, L + 4, 3)
    inside = start[:, None] + np.arange(length)
    before[:, 2:2 + length] = P[inside, col[:, None]]
    ends = start[:, None] + np.array([-2, -1, length, length + 1])
    after = before.copy()
    after[:, 2:2 + length] = np.matmul(_cubic_weights(length, 2), path[ends, col[:, None]])
    R = len(start)
    rough_before = np.nansum((np.diff(before, n=2, axis=1) ** 2).reshape(R, -1), axis=1)
    rough_after = np.nansum((np.diff(after, n=2, axis=1) ** 2).reshape(R, -1), axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        share = np.where(rough_before > 0, rough_after / rough_before, np.inf)
    return share <= ratio


def _cubic_across(x: np.ndarray, start: int, length: int) -> np.ndarray:
    """Samples ``start .. start + length`` of a (T, 3) path on the cubic through the two
    samples on each side of them (the straight line between the nearest where those are
    not all there): a fast curve at a low frame rate bends between its samples, which a
    line would cut."""
    idx = np.r_[start - 2, start - 1, start + length, start + length + 1]
    if idx[0] >= 0 and idx[-1] < len(x) and not np.isnan(x[idx]).any():
        return _cubic_weights(length, 2) @ x[idx]
    gap = x.copy()
    gap[start:start + length] = np.nan
    return linear_bridge(gap)[start:start + length]


def _extrapolated(x: np.ndarray, start: int, length: int) -> np.ndarray | None:
    """Samples ``start .. start + length`` of a (T, 3) path on the straight line through
    the two samples of ``x`` next to them (after them when there are two, else before);
    None when neither side has two."""
    seen = np.flatnonzero(~np.isnan(x).any(axis=1))
    after = seen[seen >= start + length][:2]
    before = seen[seen < start][-2:]
    pair = after if len(after) == 2 else before if len(before) == 2 else None
    if pair is None:
        return None
    t = np.arange(start, start + length)[:, None]
    slope = (x[pair[1]] - x[pair[0]]) / (pair[1] - pair[0])
    return x[pair[0]] + (t - pair[0]) * slope


def overlapping_runs(found: list[tuple[int, int, int]], moves: list[set], context: int) -> list[list]:
    """``found`` runs ``(point, start, length)`` in groups judged together: two runs
    belong together when their frames, ``context`` frames wider, overlap and their points
    move a point in common (``moves[point]``: the points a change at it moves; a rig
    joint moves the joints below it). Runs are taken in time order, and a group no later
    run can reach is closed, so the cost grows with the runs, not their square."""
    done: list[list] = []
    open_: list[tuple[int, list]] = []              # (last frame reached + context, group)
    for run in sorted(found, key=lambda r: r[1]):
        n, s, L = run
        done += [g for end, g in open_ if end <= s - context]
        open_ = [(end, g) for end, g in open_ if end > s - context]
        hits = [k for k, (_, g) in enumerate(open_)
                if any(t + M + context > s - context and moves[n] & moves[m] for m, t, M in g)]
        merged = [run] + [r for k in hits for r in open_[k][1]]
        end = max([s + L + context] + [open_[k][0] for k in hits])
        open_ = [item for k, item in enumerate(open_) if k not in hits] + [(end, merged)]
    return done + [g for _, g in open_]


def steps(X: np.ndarray, noise, *, groups: np.ndarray | None = None,
          threshold: float = 6.0) -> np.ndarray:
    """(T − 1, G) mask of steps: a frame-to-frame change t → t + 1 of a group of columns
    (a joint's features) that stands off the cubic through the two changes on each side
    of it (weights −1/6, 2/3, 2/3, −1/6) and off the median of those four changes, both
    by more than ``threshold`` times the noise of a change (RMS over the group's columns,
    in noise units). A discontinuity — a cut, a
    flip, a glitch that stays — is such a step; in fast smooth motion each change follows
    from its neighbours and is not. A smoother should not average across a step (see
    :func:`mocapfix.solvers.sure.sure_piecewise`).

    ``X``: (T, C), no NaN; ``noise``: standard deviation per sample, scalar or (T, C);
    ``groups``: (C,) labels (default: each column its own group), G groups in label order."""
    X = np.asarray(X, dtype=np.float64)
    T, C = X.shape
    sd = np.broadcast_to(np.asarray(noise, dtype=np.float64), X.shape)
    _, M = column_groups(groups, C)
    if T < 6 or not C:
        return np.zeros((max(T - 1, 0), M.shape[1]), dtype=bool)
    with np.errstate(divide="ignore", invalid="ignore"):
        D = np.diff(X, axis=0) / np.sqrt(sd[1:] ** 2 + sd[:-1] ** 2)
    D = np.nan_to_num(D, nan=0.0, posinf=0.0, neginf=0.0)
    P = np.pad(D, ((2, 2), (0, 0)), mode="reflect")
    n = T - 1
    around = np.stack([P[:n], P[1:n + 1], P[3:n + 3], P[4:n + 4]])

    def off(predicted):
        return np.sqrt(((D - predicted) ** 2 @ M) / M.sum(axis=0))

    # the cubic follows fast smooth motion; the median ignores a step next door
    cubic = (4 * (around[1] + around[2]) - (around[0] + around[3])) / 6.0
    return np.minimum(off(cubic), off(np.median(around, axis=0))) > threshold
