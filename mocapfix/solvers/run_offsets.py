"""The offset of a run of biased samples, read as the jump at each end of the run.

A run of samples ``y_i = x(t_i) + b_i`` (the Kinect's Inferred joints: the joint plus an
offset) between samples without the offset. At each end of the run the jump of the data
is the offset there: both sides are fitted by least squares with a polynomial of degree
``d`` in time, each on its ``k`` samples next to the boundary, and both fits are
evaluated at the run's first (last) sample; the difference is the offset. This is the
two-sided local-polynomial jump estimator of change-point regression (McDonald & Owen
1986, "Smoothing with split linear fits", Technometrics 28(3); Qiu & Yandell 1998, "A
local polynomial jump-detection algorithm in nonparametric regression", Technometrics
40(2), eq. 2.2): unbiased for motion of degree ≤ d, where a smooth taken across the run
is not — a smoothing spline through a gap bends toward its ends' neighbours, which for a
fast foot is off by centimetres at the gap's edge.

All runs are solved at once: one batched (d+1)×(d+1) solve per side.
"""
from __future__ import annotations

import numpy as np


def side_fit(t: np.ndarray, Y: np.ndarray, idx: np.ndarray, w: np.ndarray, at: np.ndarray, *,
             degree: int = 1) -> np.ndarray:
    """Weighted least-squares polynomial fits evaluated at ``at``.

    ``t`` (T,) times; ``Y`` (R, k, D) the samples of R fits; ``idx`` (R, k) their frame
    indices (any value where ``w`` is 0); ``w`` (R, k) weights; ``at`` (R,) where to
    evaluate. Times are centred on ``at`` (the fit's value there is its constant term).
    Fits with fewer than ``degree + 1`` weighted samples drop to the degree they support
    (a tiny ridge on the higher terms). Returns (R, D)."""
    idx = np.clip(idx, 0, len(t) - 1)
    u = t[idx] - at[:, None]                                    # (R, k)
    scale = np.maximum(np.max(np.abs(u) * (w > 0), axis=1, keepdims=True), 1e-9)
    u = u / scale
    V = u[..., None] ** np.arange(degree + 1)                  # (R, k, d+1)
    Vw = V * w[..., None]
    A = np.swapaxes(Vw, 1, 2) @ V                               # (R, d+1, d+1)
    ridge = 1e-6 * np.maximum(A[:, 0, 0], 1e-12)
    A[:, np.arange(1, degree + 1), np.arange(1, degree + 1)] += ridge[:, None]
    A[:, 0, 0] += 1e-12
    rhs = np.swapaxes(Vw, 1, 2) @ Y                             # (R, d+1, D)
    coef = np.linalg.solve(A, rhs)
    return coef[:, 0, :]


def run_end_offsets(t: np.ndarray, y: np.ndarray, inside: np.ndarray, outside: np.ndarray,
                    col: np.ndarray, start: np.ndarray, length: np.ndarray, *, k: int = 4,
                    degree: int = 1, min_outside: int = 2):
    """Offsets at the first and the last sample of each run (module docstring).

    ``y`` (T, J, D); ``inside`` / ``outside`` (T, J) bool: the samples of the runs and the
    unbiased samples; runs given as (col, start, length) arrays. Each side uses its ``k``
    nearest usable samples in the ``k`` frames next to the boundary. Returns (first, last,
    ok_first, ok_last): offsets (R, D) and whether the outside had ``min_outside`` samples
    there (otherwise the offset is NaN)."""
    T = len(t)
    col, start, length = (np.asarray(a, dtype=np.intp) for a in (col, start, length))
    R = len(col)
    D = y.shape[2]
    if R == 0:
        empty = np.zeros((0, D))
        return empty, empty, np.zeros(0, bool), np.zeros(0, bool)
    steps = np.arange(k)
    out = []
    for first in (True, False):
        if first:
            edge = start                                        # run's first sample
            in_idx = start[:, None] + steps                     # forward into the run
            out_idx = start[:, None] - 1 - steps                # backward before it
        else:
            edge = start + length - 1
            in_idx = edge[:, None] - steps
            out_idx = edge[:, None] + 1 + steps
        in_ok = (np.abs(in_idx - edge[:, None]) < length[:, None]) & (in_idx >= 0) & (in_idx < T)
        out_ok = (out_idx >= 0) & (out_idx < T)
        ci, co = np.clip(in_idx, 0, T - 1), np.clip(out_idx, 0, T - 1)
        in_ok &= inside[ci, col[:, None]]
        out_ok &= outside[co, col[:, None]]
        Yin = np.nan_to_num(y[ci, col[:, None]])
        Yout = np.nan_to_num(y[co, col[:, None]])
        at = t[edge]
        a = side_fit(t, Yin, ci, in_ok.astype(float), at, degree=degree)
        b = side_fit(t, Yout, co, out_ok.astype(float), at, degree=degree)
        ok = (out_ok.sum(axis=1) >= min_outside) & (in_ok.sum(axis=1) >= 1)
        out.append((np.where(ok[:, None], a - b, np.nan), ok))
    return out[0][0], out[1][0], out[0][1], out[1][1]
