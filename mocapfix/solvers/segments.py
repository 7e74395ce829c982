"""Per-segment kernels for channels with missing samples.

Layout: ``x`` is a (T, C) float array, time along axis 0, one column per channel
(a coordinate of a marker), NaN where a sample is missing. A *segment* is a maximal run of
observed samples in one column. Filters that cannot see NaN (IIR filters,
wavelets) are applied to each segment separately, so that a gap neither spreads NaN nor
pulls values across it. Segments that start and end on the same frames in several columns
(the three coordinates of a marker, or every column of a gap-free capture) are processed
together in one vectorised call: the Python loop is over distinct segments, never over
frames.

Two ways to treat the ends of a segment are offered:

* ``"segments"``: the segment is extended beyond its ends by point (odd) reflection
  (:func:`extend`) and filtered on its own — what
  :func:`scipy.signal.filtfilt` does at the ends of a signal (Gustafsson 1996; the
  ``padtype='odd'`` of SciPy);
* ``"bridge"``: interior gaps are first bridged with a smooth interpolant
  (:func:`interpolate_gaps`), the bridged channel is filtered, and the gaps are restored to
  NaN. Information flows across the gap.

Measured on the gap-free C3D captures (CMU 85_02, HDM05) with the ``gaps`` occlusion
scenario plus 2 mm jitter, 6 Hz Butterworth: within 12 frames of a gap edge the result of
``"segments"`` (odd extension of ≥ 20 samples) is 1.7 mm RMS from the same filter run on
the gap-free signal, ``"bridge"`` (PCHIP) 3.2 mm — a long bridge is a poor guess of the
motion and the filter pulls the edge samples towards it. ``"segments"`` is the default.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

from mocapfix.core.gaps import runs

GAP_MODES = ("segments", "bridge")
INTERPOLATORS = ("linear", "pchip", "spline")


# -- segments -----------------------------------------------------------------------------

def segment_groups(observed: np.ndarray) -> list[tuple[int, int, np.ndarray]]:
    """Observed runs of a (T, C) mask grouped by identical (start, length).

    Returns a list of ``(start, length, columns)``; ``columns`` is an integer array of the
    columns that hold a run of True from ``start`` to ``start + length``.
    """
    observed = np.asarray(observed, dtype=bool)
    col, start, length = runs(observed)
    if col.size == 0:
        return []
    key = start.astype(np.int64) * (observed.shape[0] + 1) + length
    order = np.lexsort((col, key))
    cuts = np.flatnonzero(np.diff(key[order])) + 1
    return [(int(start[idx[0]]), int(length[idx[0]]), col[idx]) for idx in np.split(order, cuts)]


def apply_segments(x: np.ndarray, func: Callable[[np.ndarray], np.ndarray],
                   min_length: int = 1, observed: np.ndarray | None = None) -> np.ndarray:
    """Apply ``func`` to every observed segment of every column of ``x`` (T, C).

    ``func`` receives an (n, k) array (one segment of n samples, shared by k columns) and
    returns an array of the same shape. Segments shorter than ``min_length`` are copied
    unchanged; missing samples stay NaN. Returns a new array.
    """
    x = np.asarray(x, dtype=np.float64)
    if observed is None:
        observed = ~np.isnan(x)
    out = x.copy()
    for s, n, cols in segment_groups(observed):
        if n < min_length:
            continue
        out[s:s + n, cols] = func(x[s:s + n][:, cols])
    return out


def extend(seg: np.ndarray, n_pad: int) -> tuple[np.ndarray, int]:
    """Extend an (n, k) segment at both ends along axis 0 by point (odd) reflection about
    the end sample, ``2 x[0] − x[i]``: value and slope stay continuous, so a straight-line
    movement is extended exactly (SciPy's ``padtype='odd'``). At most ``n − 1`` samples.

    Returns ``(padded, p)`` with ``p`` samples added at each end.
    """
    n = seg.shape[0]
    p = max(0, min(int(n_pad), n - 1))
    if p == 0:
        return seg.copy(), 0
    left = 2.0 * seg[0] - seg[p:0:-1]
    right = 2.0 * seg[-1] - seg[-2:-p - 2:-1]
    return np.concatenate([left, seg, right], axis=0), p


def end_line(seg: np.ndarray) -> np.ndarray:
    """The straight line through the first and last samples of an (n, k) segment, sampled
    on its n frames. :func:`filtfilt` filters ``seg − end_line(seg)`` (zero at both ends)
    and adds the line back: a low-pass passes a line unchanged, but SciPy's steady-state
    start assumes a signal constant before the segment, and on a segment shorter than the
    filter's transient a straight movement came out far off (a 2-sample segment, 26 mm
    apart at 120 Hz, 6 Hz Butterworth: both samples moved 44 mm, past each other)."""
    n = seg.shape[0]
    if n < 2:
        return seg.copy()
    return seg[0] + (seg[-1] - seg[0]) * (np.arange(n) / (n - 1))[:, None]


# -- interpolation across gaps --------------------------------------------------------------

def run_rows(start: np.ndarray, length: np.ndarray) -> np.ndarray:
    """Frame indices covered by runs, concatenated (vectorised ``arange`` per run)."""
    total = int(length.sum())
    offsets = np.repeat(np.cumsum(length) - length, length)
    return np.repeat(start, length) + (np.arange(total) - offsets)


def neighbours(missing: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For a (T, C) mask: the index of the last non-missing sample at or before each
    sample (−1 if none) and of the next one at or after it (T if none), per column."""
    T = missing.shape[0]
    t = np.arange(T)[:, None]
    prev = np.where(missing, -1, t)
    np.maximum.accumulate(prev, axis=0, out=prev)
    nxt = np.where(missing, T, t)[::-1]
    nxt = np.minimum.accumulate(nxt, axis=0)[::-1]
    return prev, nxt


def linear_bridge(x: np.ndarray) -> np.ndarray:
    """Complete copy of ``x`` (T, …; each trailing index a channel): interior gaps by
    linear interpolation, leading and trailing gaps hold the nearest observed value;
    all-missing channels become 0.

    The starting point every iterative solver here uses (DCT smoothing, PCA imputation,
    the low-rank + isometry ADMM, glitch search). Vectorised over every channel (no per-gap
    loop)."""
    x = np.asarray(x, dtype=np.float64)
    missing = np.isnan(x)
    if not missing.any():
        return x.copy()
    if x.ndim != 2:
        return linear_bridge(x.reshape(x.shape[0], -1)).reshape(x.shape)
    T = x.shape[0]
    prev, nxt = neighbours(missing)
    # the interpolation at the missing samples only (the same operations per sample)
    t, c = np.nonzero(missing)
    p, q = prev[t, c], nxt[t, c]
    before = x[np.maximum(p, 0), c]
    after = x[np.minimum(q, T - 1), c]
    frac = (t - p) / np.maximum(q - p, 1)
    out = x.copy()
    out[t, c] = np.where((p >= 0) & (q < T), before + frac * (after - before),
                         np.where(p >= 0, before, after))
    return np.nan_to_num(out, nan=0.0, copy=False)


def fillable(missing: np.ndarray, max_gap: float | None = None) -> np.ndarray:
    """(T, C) mask of the samples in interior gaps (runs of True in ``missing`` that touch
    neither end) of at most ``max_gap`` samples (None: any length)."""
    missing = np.asarray(missing, dtype=bool)
    T = missing.shape[0]
    target = np.zeros(missing.shape, dtype=bool)
    if missing.size == 0:
        return target
    col, start, length = runs(missing)
    ok = (start > 0) & (start + length < T)
    if max_gap is not None:
        ok &= length <= max_gap
    target.reshape(T, -1)[run_rows(start[ok], length[ok]), np.repeat(col[ok], length[ok])] = True
    return target


def interpolate_gaps(x: np.ndarray, method: str = "pchip", max_gap: float | None = None,
                     times: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Fill interior gaps of each column of ``x`` (T, C) by interpolation.

    Parameters
    ----------
    x : (T, C) array, NaN = missing.
    method : "linear" (piecewise linear), "pchip" (shape-preserving piecewise cubic
        Hermite, Fritsch & Carlson 1980; never overshoots the neighbouring samples) or
        "spline" (C² cubic spline through all observed samples, not-a-knot ends;
        de Boor 1978).
    max_gap : gaps of more than ``max_gap`` samples are left NaN (None: no limit).
    times : (T,) sample times; default ``arange(T)``.

    Returns
    -------
    filled : (T, C) copy of ``x`` with the fillable gaps filled. Leading and trailing gaps
        are never filled (no extrapolation).
    target : (T, C) boolean mask of the samples that were filled.

    Columns with identical missing patterns are interpolated together; the loop is over
    distinct patterns (at most the number of columns), never over frames.
    """
    if method not in INTERPOLATORS:
        raise ValueError(f"unknown interpolation {method!r} (known: {', '.join(INTERPOLATORS)})")
    x = np.asarray(x, dtype=np.float64)
    T = x.shape[0]
    out = x.copy()
    missing = np.isnan(x)
    target = fillable(missing, max_gap)
    if not target.any():
        return out, target
    col = np.flatnonzero(target.any(axis=0))
    t = np.arange(T, dtype=np.float64) if times is None else np.asarray(times, dtype=np.float64)
    groups: dict[bytes, list[int]] = {}
    for c in col:
        key = np.packbits(missing[:, c]).tobytes() + np.packbits(target[:, c]).tobytes()
        groups.setdefault(key, []).append(int(c))
    from scipy import interpolate      # imported here: loading it costs ~0.5 s

    for cols in groups.values():
        cols = np.asarray(cols)
        obs = ~missing[:, cols[0]]
        rows = target[:, cols[0]]
        tt, yy = t[obs], x[obs][:, cols]
        if method == "linear":
            f = interpolate.make_interp_spline(tt, yy, k=1, axis=0)
        elif method == "pchip":
            f = interpolate.PchipInterpolator(tt, yy, axis=0, extrapolate=False)
        else:
            f = interpolate.CubicSpline(tt, yy, axis=0, bc_type="not-a-knot", extrapolate=False)
        out[np.ix_(rows, cols)] = f(t[rows])
    return out, target


def apply_bridged(x: np.ndarray, func: Callable[[np.ndarray], np.ndarray], bridge: str = "pchip",
                  min_length: int = 1) -> np.ndarray:
    """Bridge every interior gap with ``interpolate_gaps(method=bridge)``, apply ``func`` to
    each channel's span from its first to its last observed sample (see
    :func:`apply_segments`), and restore NaN where ``x`` was missing."""
    filled, _ = interpolate_gaps(x, bridge)
    out = apply_segments(filled, func, min_length=min_length)
    out[np.isnan(x)] = np.nan
    return out


def _by_gaps(x, func, gaps: str, min_length: int = 1):
    if gaps == "segments":
        return apply_segments(x, func, min_length=min_length)
    if gaps == "bridge":
        return apply_bridged(x, func, min_length=min_length)
    raise ValueError(f"unknown gap mode {gaps!r} (known: {', '.join(GAP_MODES)})")


# -- filters ------------------------------------------------------------------------------

def default_padlen(sos: np.ndarray) -> int:
    """SciPy's default pad length of :func:`scipy.signal.sosfiltfilt`."""
    sos = np.atleast_2d(sos)
    return 3 * (2 * len(sos) + 1 - min(int((sos[:, 2] == 0).sum()), int((sos[:, 5] == 0).sum())))


def filtfilt(x: np.ndarray, sos: np.ndarray, gaps: str = "segments",
             padlen: int | None = None) -> np.ndarray:
    """Zero-phase IIR filtering (forward–backward, :func:`scipy.signal.sosfiltfilt`;
    Gustafsson 1996 initial conditions) of every column of ``x`` (T, C), NaN-safe.

    Parameters
    ----------
    sos : second-order sections of the filter (``scipy.signal.butter(..., output='sos')``).
    gaps : "segments" (filter each observed segment alone) or "bridge" (bridge gaps with
        PCHIP, filter, restore NaN) — see the module docstring.
    padlen : samples of odd extension (:func:`extend`); default SciPy's
        ``3 (2 n_sections + 1)``; at most ``n − 1`` for a short segment.

    Returns
    -------
    (T, C) filtered array, NaN where ``x`` is NaN.
    """
    sos = np.atleast_2d(np.asarray(sos, dtype=np.float64))
    pad = default_padlen(sos) if padlen is None else int(padlen)

    from scipy import signal

    def func(seg):
        line = end_line(seg)
        padded, p = extend(seg - line, pad)
        y = signal.sosfiltfilt(sos, padded, axis=0, padtype=None)
        return y[p:p + seg.shape[0]] + line

    return _by_gaps(x, func, gaps, min_length=2)


def gaussian(x: np.ndarray, sigma: float, gaps: str = "segments",
             truncate: float = 4.0) -> np.ndarray:
    """Gaussian low-pass (sigma in samples) of every column of ``x`` (T, C), NaN-safe.

    Each segment is extended by point reflection (:func:`extend`) by up to
    ``truncate·sigma`` samples and smoothed by normalised convolution (Knutsson & Westin
    1993):
    ``g * (x w) / g * w`` with ``w`` = 1 on the (extended) segment and 0 beyond, so a short
    segment is averaged over the samples it has and no value is pulled across a gap.
    Odd extension keeps straight-line motion unbiased at the segment ends.
    """
    if sigma <= 0:
        return np.asarray(x, dtype=np.float64).copy()
    radius = int(math.ceil(truncate * sigma))
    from scipy import ndimage

    def func(seg):
        padded, p = extend(seg, radius)
        # taps farther than the padded segment only meet the zeros beyond it, in ``num``
        # and ``den`` alike: the kernel is cut there, so a huge sigma costs O(T), not O(sigma)
        cut = {"truncate": truncate} if radius <= padded.shape[0] else {"radius": padded.shape[0]}
        num = ndimage.gaussian_filter1d(padded, sigma, axis=0, mode="constant", cval=0.0, **cut)
        den = ndimage.gaussian_filter1d(np.ones(padded.shape[0]), sigma, mode="constant",
                                        cval=0.0, **cut)
        return (num / den[:, None])[p:p + seg.shape[0]]

    return _by_gaps(x, func, gaps)


def bayes_shrink(coeffs: list[np.ndarray], sigma: np.ndarray) -> list[np.ndarray]:
    """Soft-threshold every detail band with the BayesShrink threshold
    ``σ² / σ_x``, ``σ_x = sqrt(max(mean(d²) − σ², 0))`` (Chang, Yu & Vetterli 2000;
    as in ``skimage.restoration.denoise_wavelet``); a band with ``σ_x = 0`` is zeroed.
    ``coeffs`` is a ``pywt.wavedec`` list along axis 0, ``sigma`` the noise std per column.
    """
    out = [coeffs[0]]
    var = np.asarray(sigma, dtype=np.float64) ** 2
    for d in coeffs[1:]:
        sig_x = np.sqrt(np.maximum(np.mean(d * d, axis=0) - var, 0.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            thr = np.where(sig_x > 0, var / np.where(sig_x > 0, sig_x, 1.0), np.abs(d).max(axis=0))
        out.append(np.sign(d) * np.maximum(np.abs(d) - thr, 0.0))
    return out


WAVELET_THRESHOLDS = ("bayes", "linear")


def wavelet_denoise(x: np.ndarray, wavelet: str = "sym8", level: int | None = None,
                    gaps: str = "segments", mode: str = "antireflect", *,
                    threshold: str = "bayes") -> np.ndarray:
    """Wavelet shrinkage denoising of every column of ``x`` (T, C), NaN-safe.

    Discrete wavelet transform (``pywt.wavedec``, boundary ``mode``), robust noise estimate
    ``σ = median(|d_1|) / 0.6745`` from the finest detail band (Donoho & Johnstone 1994),
    BayesShrink soft thresholds per band (:func:`bayes_shrink`), inverse transform.
    ``level`` None: ``max(dwt_max_level − 1, 1)`` — deeper than scikit-image's
    ``dwt_max_level − 3``: motion-capture channels are oversampled (the movement lives below
    ~10 Hz of a 100–200 Hz capture), so noise sits in the coarse bands too; BayesShrink
    leaves bands dominated by the movement alone. Measured after ``spikes`` + ``fill`` on
    CMU 85_02 / HDM05 with 2 mm jitter: 1.66 / 1.39 mm RMSE against 1.83 / 1.39 for −3.

    Segments too short for one level (``pywt.dwt_max_level`` = 0, e.g. fewer than
    15 samples for sym8) are left as they are.

    ``threshold``: ``"bayes"`` (above) or ``"linear"``: every detail band of the ``level``
    finest levels is set to zero, i.e. the projection on the approximation space at
    ``level`` (linear wavelet smoothing, a low-pass of cut-off ≈ fs / 2^(level+1); it also
    spreads sparse outliers instead of keeping them, as thresholds tuned on a robust noise
    estimate do).

    Returns the denoised (T, C) array, NaN where ``x`` is NaN.
    """
    import pywt

    if threshold not in WAVELET_THRESHOLDS:
        raise ValueError(f"unknown wavelet threshold {threshold!r} "
                         f"(known: {', '.join(WAVELET_THRESHOLDS)})")

    w = pywt.Wavelet(wavelet)

    def func(seg):
        n = seg.shape[0]
        maxlev = pywt.dwt_max_level(n, w.dec_len)
        if maxlev < 1:
            return seg
        lev = max(maxlev - 1, 1) if level is None else min(level, maxlev)
        coeffs = pywt.wavedec(seg, w, mode=mode, level=lev, axis=0)
        if threshold == "linear":
            shrunk = [coeffs[0]] + [np.zeros_like(d) for d in coeffs[1:]]
        else:
            sigma = np.median(np.abs(coeffs[-1]), axis=0) / 0.6745
            shrunk = bayes_shrink(coeffs, sigma)
        rec = pywt.waverec(shrunk, w, mode=mode, axis=0)
        return rec[:n]

    return _by_gaps(x, func, gaps, min_length=2)


#: a sample this far (m) from where its point usually is can be no measurement: no capture
#: volume is that large, and depth sensors reach ~10 m (a corrupt field, a flipped exponent
#: bit); the gross-error screens of ``tsmc`` and ``kinect_skeleton`` never keep one
NO_CAPTURE_VOLUME_M = 100.0


def implausible_runs(filled, write, observed_points, margin: float = 0.1) -> np.ndarray:
    """(T, J) mask of filled gap runs to reject: runs with a sample outside the capture
    volume (the bounding box of every observed sample, grown by ``margin`` of its size on
    each side). A PCA fill fails this way when the markers do not move as one body (two
    subjects in one file, a marker seen too briefly to be learned): such a gap is better
    left missing and reported than filled metres away."""
    lo, hi = observed_points.min(axis=0), observed_points.max(axis=0)
    pad = margin * (hi - lo)
    outside = write & ((filled < lo - pad) | (filled > hi + pad)).any(axis=-1)
    rejected = np.zeros_like(write)
    if not outside.any():
        return rejected
    col, start, length = runs(write)
    for c, s, n in zip(col, start, length):
        if outside[s:s + n, c].any():
            rejected[s:s + n, c] = True
    return rejected


def largest_steps(positions: np.ndarray, seen: np.ndarray) -> np.ndarray:
    """(J,) the largest distance each point of ``positions`` (T, J, 3) moves from one
    frame to the next between two frames where ``seen`` (T, J) holds (0 where it never
    does): how fast the data says the point can move."""
    both = seen[1:] & seen[:-1]
    d = np.diff(positions, axis=0)
    step = np.sqrt(np.einsum("tjk,tjk->tj", d, d, optimize=False))
    return np.where(both, np.nan_to_num(step), 0.0).max(axis=0, initial=0.0)


def steepest_step(fill: np.ndarray, before: np.ndarray | None, after: np.ndarray | None) -> float:
    """The largest frame-to-frame step of ``fill`` (n, 3), joined to the data sample
    ``before`` its first frame and ``after`` its last (None at the capture's ends); steps
    to or from a NaN sample do not count (0 when none is left)."""
    parts = ([before[None]] if before is not None else []) + [fill] + \
        ([after[None]] if after is not None else [])
    seg = np.concatenate(parts) if len(parts) > 1 else fill
    d = np.diff(seg, axis=0)
    return float(np.nanmax(np.sqrt((d * d).sum(axis=1)), initial=0.0))


def discontinuous_runs(filled: np.ndarray, write: np.ndarray, top: np.ndarray,
                       factor: float) -> np.ndarray:
    """(T, J) mask of the runs of ``write`` (samples a filler wrote into ``filled`` (T, J,
    3)) to reject because the fill, joined to the samples around the run, steps further
    from one frame to the next than ``factor`` × the point's largest observed step
    ``top`` (J,; :func:`largest_steps`): a fill that jumps where the data never does
    (a model that changes its mind when the markers it leans on drop out) is worse than a
    gap left for the report. Points with ``top`` 0 (never seen on two frames in a row) are
    not judged."""
    rejected = np.zeros_like(write)
    if factor <= 0:
        return rejected
    T = filled.shape[0]
    for c, s, n in zip(*runs(write)):
        before = filled[s - 1, c] if s > 0 else None
        after = filled[s + n, c] if s + n < T else None
        if top[c] > 0 and steepest_step(filled[s:s + n, c], before, after) > factor * top[c]:
            rejected[s:s + n, c] = True
    return rejected


def rejected_fills(names, masks: dict) -> dict:
    """``{name: [[start, length, why], ...]}`` of the runs of each (T, J) mask of ``masks``
    (``{why: mask}``), for a step's ``info``
    (:data:`mocapfix.cleaners.base.REJECTED_FILLS`)."""
    out: dict = {}
    for why, mask in masks.items():
        for c, s, n in zip(*runs(mask)):
            out.setdefault(names[c], []).append([int(s), int(n), why])
    return out
