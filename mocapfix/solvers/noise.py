"""White-noise level of sampled channels from their differences, and whether a take holds
any noise to measure at all.

The k-th difference of white noise of standard deviation σ has standard deviation
σ·√C(2k, k) (its weights are the binomial coefficients with alternating signs, whose
squares sum to C(2k, k)); the median absolute k-th difference / 0.6745 / √C(2k, k) is a
robust σ̂ (Rice 1984 for k = 1; Gasser, Sroka & Jennen-Steinmetz 1986 for the
difference-based family). A smooth signal's k-th difference at frequency ω is scaled by
(2 sin(ω/2))^k, which falls with k below a sixth of the sampling rate, while the noise's
normalised estimate stays the same: **on noise the estimate is flat across orders, on
motion it falls** (von Neumann's variate-difference method, 1941, reads the same thing off
successive differences). So the estimate at a high order is the less biased one, and the
ratio of a high to a low order tells whether the take has a white floor to measure: on
the 16 shared BVH/AMC takes as read the median over channels of σ̂₈ / σ̂₄ is 0.62–0.84
(the 30 Hz Bandai run 0.77: its second differences are motion, σ̂₂ = 0.65° against
σ̂₈ = 0.27°), one CMU-derived BVH with a 0.02° floor 0.95; with 0.15–0.7° of jitter added
it is 0.91–1.03 on every file but the Bandai run at 0.15° (0.78: that little noise is
below what its motion lets one measure at 30 Hz).
"""
from __future__ import annotations

from math import comb

import numpy as np

#: σ̂ at the high order over σ̂ at the low order at and above which a take is taken to
#: hold measurable white noise (see the module docstring for the values on shared takes)
FLAT = 0.9


def difference_noise(X: np.ndarray, order: int = 2, *, shape: np.ndarray | None = None) -> np.ndarray:
    """σ̂ of white noise per channel of X (T, L) from its ``order``-th differences: the
    channel's median absolute difference / 0.6745 / √C(2·order, order); 0 for a channel
    with no difference. NaN-aware (a difference touching a NaN is left out).

    ``shape`` (T, L): noise whose standard deviation is σ · shape (e.g. quaternion
    components, :func:`mocapfix.solvers.rotchannels.noise_shape`); each difference is
    divided by the shape at its centre, and differences where it is below 0.3 are left
    out. The medians come from one sort of all channels (NaN sorts last), not a NaN-median
    per channel."""
    X = np.asarray(X, dtype=np.float64)
    d = np.abs(np.diff(X, n=order, axis=0)) if len(X) > order else np.zeros((0, X.shape[1]))
    if shape is not None:
        mid = np.asarray(shape, dtype=np.float64)[order // 2:order // 2 + len(d)]
        d = np.where(mid >= 0.3, d / np.maximum(mid, 1e-12), np.nan)
    d = np.sort(d, axis=0)
    k = np.isfinite(d).sum(axis=0)
    cols = np.arange(d.shape[1])
    lo, hi = np.maximum(k - 1, 0) // 2, np.minimum(k // 2, max(len(d) - 1, 0))
    med = 0.5 * (d[lo, cols] + d[hi, cols]) if len(d) else np.zeros(X.shape[1])
    return np.where(k > 0, np.nan_to_num(med), 0.0) / 0.6745 / np.sqrt(comb(2 * order, order))


def _median_level(per: np.ndarray) -> float:
    per = per[np.isfinite(per) & (per > 0)]
    return float(np.median(per)) if per.size else 0.0


def white_noise(X: np.ndarray, *, shape: np.ndarray | None = None, low: int = 4, high: int = 8,
                flat: float = FLAT) -> tuple[float, bool]:
    """(σ̂, measurable) of white noise on the channels of X (T, L), one level for all
    of them: σ̂ is the median over channels of :func:`difference_noise` at order
    ``high``; the noise is *measurable* when that estimate is flat across orders — the
    median at ``high`` is at least ``flat`` times the median at ``low`` (module
    docstring). Channels that never move are left out. A take too short for the
    differences has nothing measurable."""
    X = np.asarray(X, dtype=np.float64)
    if len(X) <= 2 * high:
        return 0.0, False
    top = _median_level(difference_noise(X, high, shape=shape))
    base = _median_level(difference_noise(X, low, shape=shape))
    return top, bool(base > 0 and top >= flat * base)
