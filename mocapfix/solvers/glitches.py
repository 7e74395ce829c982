"""Glitch (spike) detection on continuous channels: a Hampel identifier on a running
median, confirmed by a local cubic fit across the suspected samples so that fast, smooth
real motion is not taken for a glitch.

Layout: (T, C) arrays, time along axis 0, NaN = missing.
"""
from __future__ import annotations

import numpy as np

from mocapfix.gaps import runs
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
    the same threshold)."""
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
    spread = 1.4826 * np.median(np.abs(filled - pred)[side:-side], axis=0)
    return confirm(X, cand, threshold=np.maximum(limit, k * spread), side=side,
                   max_run=(width - 1) // 2)


def _cubic_weights(run: int, side: int) -> np.ndarray:
    """(run, 2·side) weights predicting the ``run`` samples of a gap from a cubic
    least-squares fit to ``side`` samples on each side of it."""
    t_fit = np.r_[np.arange(-side, 0), np.arange(run, run + side)].astype(float)
    t_gap = np.arange(run, dtype=float)
    V = np.vander(t_fit, 4)
    return np.vander(t_gap, 4) @ np.linalg.pinv(V)


def confirm(X: np.ndarray, mask: np.ndarray, *, threshold: np.ndarray, side: int = 4,
            max_run: int = 3) -> np.ndarray:
    """Keep the runs of ``mask`` (per column, at most ``max_run`` long) whose samples lie
    farther than ``threshold`` (per column) from a cubic fitted to ``side`` samples on each
    side of the run: a glitch stands off the curve through its neighbours, a fast turning
    point of real motion does not. Runs too near the ends to be checked are kept; longer
    runs are dropped (not a glitch of this kind)."""
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
            out[ss:ss + L, cc] = True
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
