"""How far a gap's fill may be from the truth: an estimate from synthetic gaps, and a
calibrated 90 % bound.

**Error of a fill.** The RMS, over the samples of one filled run, of the 3-D distance
between the fill and the true position (in the motion's length unit; the report gives
mm). It is what a solver fed the fill would see on average over the run.

**Estimate.** A gap of marker ``j`` and length ``n`` is validated on *windows*: runs of
``n`` frames cut where ``j`` and the frames bounding the run were seen
(:func:`validation_windows`, one window per gap per copy, seeded). The filler fills each
window as it fills gaps, from the copy of the capture with that copy's windows cut, and
the window's error is measured against the samples cut out. The estimate of the gap is
the geometric mean of its windows' errors (:func:`estimates`).

**Bound (split conformal, per capture).** Each window is a test case whose truth is
known: its error ``e_c``, divided by the estimate its gap gets from its *other* windows,
is a normalised nonconformity score (Vovk, Gammerman & Shafer 2005, *Algorithmic
Learning in a Random World*; the normalised residuals of Lei, G'Sell, Rinaldo, Tibshirani
& Wasserman 2018, JASA 113:1094). The 90 % bound of a gap is the estimate times the
finite-sample conformal quantile of the capture's own scores, ``⌈(m + 1) 0.9⌉``-th
smallest of ``m`` (:func:`conformal_factor`): the real gap is one more case of the same
kind, so its error lies below the bound 90 % of the time if the real gaps are
exchangeable with the windows (gaps cut at random places are; occlusions that happen in
the poses where a marker is hard to see are not, which no capture can tell us). Per
capture rather than one factor for all: how far a fill's error strays from its windows'
depends on the capture (a breakdance strays more than a walk: benchmarks/fill_calibration.py).
A capture with fewer than :data:`MIN_SCORES` scores uses :data:`PRIOR_FACTOR`, measured
across the shared captures. The bound is of the fill's RMS error, not of each sample.

The estimate of the gap uses every window, a score only the others: with two windows
per gap, the gap's estimate averages two where a score's rests on one, so the quantile
is scaled down to what one more draw against an average of two needs
(:func:`averaging_exponent`; measured coverage: benchmarks/RESULTS.md, "Fill error
bounds").

**Gaps longer than any window (extrapolated estimates).** A gap whose marker was never
seen as long as the gap has no window of its length: in a short trial (a 3–5 s gait
trial, a 1.7 s clip) that is most long gaps. Such a gap of ``n`` frames is validated on
windows of ``m`` frames, the longest its marker allows, and its error extrapolated by a
growth law measured on this capture, ``error ∝ length^p`` (:func:`growth_exponent`):
estimate = the windows' geometric mean × ``(n/m)^p``. ``p`` comes from *probes*, windows
of ``m/r`` frames on the same marker (``r = n/m``): a probe is to its window what the
window is to the gap. So each window is a test case of the extrapolation whose truth is
known — its error over its probes' estimate × ``r^p`` is a score — and the extrapolated
bound is the estimate times the conformal quantile of those scores, calibrated apart from
the ordinary ones (:func:`extrapolated_bounds`): a capture on which extrapolation strays
more gets wider extrapolated bounds, and a misfit of the law at these ratios is in the
scores. Measured on the captures of benchmarks/fill_calibration.py, error does grow as a
power of the length over these ratios with exponents 0.05–1.5 per capture (pooled 0.63),
and more slowly at the gap's scale than at the probes' (the law fitted on the shorter
lengths over-predicts the gap's error: the median true error / estimate of the
extrapolated fills is 0.43–0.71 by band of ratio), so the bounds err on the safe side. A gap more than
:data:`MAX_RATIO` times as long as its marker's longest window gets no estimate.

**A physical floor.** No bound is below :data:`BOUND_FLOOR_M`: optical marker positions
are not known to better than about a millimetre (the white noise measured on the raw,
unfiltered shared captures is 0.7–1.2 mm in 3-D; smoothed exports show less, smoothed
rather than more accurate), so a bound under it claims what no capture can check.
"""
from __future__ import annotations

import dataclasses
import math
from bisect import bisect_left

import numpy as np

from mocapfix.core.gaps import runs
from mocapfix.solvers.nanstats import mean_of

#: the coverage of the bound
LEVEL = 0.9
#: fewest scores (windows whose gap has another window) for a capture's own calibration;
#: with fewer the bound uses :data:`PRIOR_FACTOR`
MIN_SCORES = 9
#: the score quantile used when a capture has too few scores of its own: the 90 %
#: conformal quantile of the scores of the default config's windows pooled over the nine
#: captures of benchmarks/fill_calibration.py (four seeds, both gap ranges: 2.93)
PRIOR_FACTOR = 2.9
#: errors below this (metres) are taken as this in the scores and bounds: window errors of
#: a fraction of a millimetre (a 2-frame hole in a slow marker) would otherwise make
#: ratios of noise
ERROR_FLOOR_M = 0.0005
#: bounds below this (metres) are raised to it: the accuracy of an optical marker position
#: (module docstring). On the Vicon PiG block of benchmarks/fill_calibration.py, whose
#: estimates sit at :data:`ERROR_FLOOR_M`, it lifts the coverage of the 1.5 s gaps' fills
#: from 78.9 % to 85.4 %; the misses left are of 1–10 mm
BOUND_FLOOR_M = 0.001
#: the farthest an estimate is extrapolated: a gap at most this many times as long as the
#: longest window its marker allows gets an extrapolated estimate, a longer one none. On
#: benchmarks/fill_calibration.py with the cap at 8 (five seeds), the extrapolated bounds
#: covered 93–96 % of the fills in each ratio band up to 4 and 30 of 30 at 4–6, 87.5 % of
#: the 24 at 6–8 at a median bound 5.7× their true error: past 6 the evidence thins and
#: the bounds say little
MAX_RATIO = 6.0
#: fewest gaps with probes for a capture's own growth exponent; with fewer the estimates
#: use :data:`PRIOR_SLOPE`
MIN_SLOPES = 3
#: the growth exponent used when a capture has too few probed gaps: the least-squares
#: exponent of the probes pooled over the captures of benchmarks/fill_calibration.py (five
#: seeds, both gap ranges, 546 probed gaps: 0.63)
PRIOR_SLOPE = 0.6


def validation_windows(observed: np.ndarray, gaps, copies: int, seed: int = 0,
                       lengths=None):
    """The synthetic gaps that validate fills: ``copies`` times, per gap ``(j, s, e)`` a
    window of the gap's length (``lengths``: of that many frames per gap instead, 0 for
    none) cut at a random (seeded) place where marker ``j`` and the frames bounding the
    window were seen (windows of one marker in one copy do not overlap). Returns per copy
    ``(cut, windows)``: the observed mask with the copy's windows cut, and the windows as
    ``(gap index, start, stop)``. A gap whose marker has no such stretch gets no window;
    copies stop when no gap gets one. The places a window of one marker and length may
    start are found once, kept as a sorted list, and struck out as windows are cut
    (thousands of spike holes cost one pass over their marker, not one each; the list's
    slices are deleted in place, where a mask of the places was searched whole for every
    window: 53 → 38 ms for the 3,593 short gaps of the 4,500-frame case of
    benchmarks/clean_speed.py, the same windows; 36 ms on a quieter run)."""
    T = observed.shape[0]
    rng = np.random.default_rng(seed)
    seen_rows = np.ascontiguousarray(observed.T)
    sizes = [e - s for _, s, e in gaps] if lengths is None else [int(n) for n in lengths]
    out = []
    for _ in range(copies):
        cut_rows = seen_rows.copy()
        synth = []
        starts: dict = {}          # marker → length → where a window may start, less 1
        for gi, ((j, _, _), n) in enumerate(zip(gaps, sizes)):
            if n < 1 or T - n - 1 < 1:
                continue
            mine = starts.setdefault(j, {})
            good = mine.get(n)
            if good is None:
                c = np.concatenate([[0], np.cumsum(cut_rows[j])])
                u = np.arange(1, T - n)
                good = mine[n] = np.flatnonzero((c[u + n + 1] - c[u - 1]) == n + 2).tolist()
            if not good:
                continue
            u = good[int(rng.integers(len(good)))] + 1      # the draw of rng.choice(good + 1)
            cut_rows[j, u:u + n] = False
            # a window starting at w covers frames w − 1 .. w + m: those that meet the cut
            # frames u .. u + n − 1 can no longer start there (places are w − 1)
            for m, places in mine.items():
                lo = bisect_left(places, u - m - 1)
                hi = bisect_left(places, u + n, lo)
                del places[lo:hi]
            synth.append((gi, u, u + n))
        if not synth:
            break
        out.append((np.ascontiguousarray(cut_rows.T), synth))
    return out


def longest_windows(observed: np.ndarray) -> np.ndarray:
    """(J,) the longest validation window each marker of ``observed`` (T, J) allows: its
    longest run of seen frames less the two frames that bound a window (0 for none)."""
    col, _, length = runs(observed)
    out = np.zeros(observed.shape[1], dtype=np.int64)
    np.maximum.at(out, col, length - 2)
    return np.maximum(out, 0)


@dataclasses.dataclass
class WindowPlan:
    """The validation windows of a list of gaps (:func:`window_plan`): ``windows`` as
    :func:`validation_windows` gives them, copies of three kinds in this order —
    ``ordinary`` (the gaps' own length), ``extrapolated`` (the gaps longer than any
    window: the longest their marker allows) and ``probes`` (shorter windows of the
    extrapolated gaps' markers); each a slice of the copies. Per gap: ``ratio``, its length
    over its windows' (1 for an ordinary gap, NaN for a gap with none), and
    ``probe_ratio``, its windows' length over its probes' (NaN without probes)."""
    windows: list
    ordinary: slice
    extrapolated: slice
    probes: slice
    ratio: np.ndarray
    probe_ratio: np.ndarray


def window_plan(observed: np.ndarray, gaps, copies: int, seed: int = 0,
                cap: float = MAX_RATIO, probes: bool = True) -> WindowPlan:
    """The validation windows of ``gaps`` (:func:`validation_windows`, ``copies`` per gap):
    a gap whose marker was seen as long as the gap gets windows of its length; one longer
    than the longest window ``m`` its marker allows (:func:`longest_windows`) but at most
    ``cap`` times as long gets windows of ``m`` frames, in copies of their own, and with
    ``probes`` also probe windows of ``m / r`` frames (``r``: the gap's length over ``m``;
    at least 1 frame and less than ``m``), in copies of their own: a probe is to its
    window what the window is to the gap, so the error of a window predicted from its
    probes is a test case of the extrapolation with a known truth
    (:func:`extrapolated_bounds`). A gap longer than ``cap`` × ``m`` gets none, and so
    does one whose marker allows windows of one frame only (no probe, no test case of
    its own: ktk_racing_full's Sternum, seen in bursts of 1–3 frames, would have had its
    first 5 frames filled from 1-frame windows). The
    ordinary copies are what :func:`validation_windows` gives without the extrapolated
    gaps (the same seed: their windows are the same)."""
    gaps = list(gaps)
    n = np.array([e - s for _, s, e in gaps], dtype=np.int64).reshape(-1)
    longest = longest_windows(observed)[np.array([j for j, _, _ in gaps], dtype=np.intp)]
    own = n <= longest
    far = ~own & (n <= cap * longest) & (longest >= 2)
    m = np.where(far, longest, 0)
    probe = np.where(far, np.clip(np.rint(m * m / np.maximum(n, 1)), 1, m - 1), 0)
    windows = validation_windows(observed, gaps, copies, seed, lengths=np.where(own, n, 0))
    a = len(windows)
    if far.any():
        windows += validation_windows(observed, gaps, copies, seed + 1, lengths=m)
    b = len(windows)
    if probes and (probe > 0).any():
        windows += validation_windows(observed, gaps, copies, seed + 2, lengths=probe)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(own, 1.0, np.where(far, n / np.maximum(m, 1), np.nan))
        probe_ratio = np.where(probe > 0, m / np.maximum(probe, 1), np.nan)
    return WindowPlan(windows, slice(0, a), slice(a, b), slice(b, len(windows)), ratio,
                      probe_ratio)


def growth_exponent(rise: np.ndarray, span: np.ndarray, minimum: int = MIN_SLOPES,
                    prior: float = PRIOR_SLOPE) -> tuple[float, bool, np.ndarray]:
    """The exponent ``p`` of the growth law ``error ∝ length^p`` from pairs of window
    lengths: ``rise`` the log of a window's error over its probes', ``span`` the log of
    their lengths' ratio (both (K,)). The least-squares slope through the origin
    (Σ rise·span / Σ span²: pairs of close lengths weigh little), clipped to 0..3 (a
    longer gap is not easier); ``prior`` (and ``False``) with fewer than ``minimum``
    pairs. Also per pair the slope fitted without it (what a pair's score is judged
    with: :func:`extrapolated_bounds`)."""
    rise, span = np.asarray(rise, float), np.asarray(span, float)
    if len(rise) < minimum:
        return prior, False, np.full(len(rise), prior)
    sxy, sxx = float(np.sum(rise * span)), float(np.sum(span ** 2))
    with np.errstate(divide="ignore", invalid="ignore"):
        loo = np.where(sxx - span ** 2 > 0, (sxy - rise * span) / (sxx - span ** 2), prior)
    return float(np.clip(sxy / sxx, 0.0, 3.0)), True, np.clip(loo, 0.0, 3.0)


def extrapolated_bounds(window_errors: np.ndarray, probe_errors: np.ndarray,
                        ratio: np.ndarray, probe_ratio: np.ndarray, floor: float,
                        level: float = LEVEL, fitted: np.ndarray | None = None,
                        fitted_probes: np.ndarray | None = None, prior: float = PRIOR_FACTOR):
    """Per gap ``(estimate, bound)`` of gaps longer than their windows, and the factor,
    whether it came from these gaps, the growth exponent and whether it did.

    ``window_errors`` (G, C): the errors on each gap's windows, ``ratio`` times shorter
    than the gap; ``probe_errors`` (G, C'): on its probes, ``probe_ratio`` times shorter
    than the windows (:func:`window_plan`); ``fitted``/``fitted_probes``: see
    :func:`scores`. **Law**: error ∝ length^p, ``p`` fitted on this capture from each
    gap's windows and probes (:func:`growth_exponent`); the estimate is the windows'
    geometric mean × ``ratio^p``. **Bound** (split conformal, as :func:`bounds`): each
    window is a test case of the extrapolation whose truth is known — its (cross-fitted)
    error over its probes' geometric mean × ``probe_ratio^p`` (``p`` fitted without that
    gap) is a score, made as the real gap's estimate is made (one draw against an average
    of as many shorter windows, scaled up by the same ratio), so its quantile holds how
    far an extrapolation by such ratios strays on this capture, growth-law misfit
    included. With fewer than :data:`MIN_SCORES` scores, ``prior``: the capture's factor
    for its ordinary windows (:class:`FillTrust`) — an extrapolated estimate is no more
    certain than one from windows of the gap's length; the pooled quantile of the
    extrapolation scores (1.94) is set by the many tight scores of the Vicon and Qualisys
    clips, and with it the extrapolated fills of CMU 85_02 (3 s gaps) were covered 78.9 %
    of the time, against 89.5 % with the capture's own window factor. NaN for gaps with
    no window."""
    e = np.asarray(window_errors, dtype=float).reshape(len(window_errors), -1)
    f = e if fitted is None else np.asarray(fitted, dtype=float).reshape(e.shape)
    pe = np.asarray(probe_errors, dtype=float)
    fp = pe if fitted_probes is None else np.asarray(fitted_probes, dtype=float)
    est = estimates(f, floor)
    probe = estimates(fp, floor) if pe.size else np.full(len(e), np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        rise = np.log(est / probe)
        span = np.log(np.asarray(probe_ratio, dtype=float))
    paired = np.isfinite(rise) & np.isfinite(span) & (span > 0)
    slope, own_slope, loo = growth_exponent(rise[paired], span[paired])
    factor, own = conformal_factor(
        extrapolation_scores(e[paired], probe[paired], span[paired], loo, floor), level,
        prior=prior)
    est = est * np.asarray(ratio, dtype=float) ** slope
    return est, factor * np.maximum(est, floor), factor, own, slope, own_slope


def extrapolation_scores(window_errors: np.ndarray, probe_estimates: np.ndarray,
                         span: np.ndarray, slopes: np.ndarray, floor: float) -> np.ndarray:
    """The nonconformity scores of extrapolation: each window's error (G, C; floored at
    ``floor``) over the estimate its gap's probes extrapolate to its length,
    ``probe_estimates × exp(span × slopes)`` (``span``: log of the windows' length over
    the probes'; ``slopes``: the growth exponent each gap is judged with), for every
    window there is."""
    e = np.asarray(window_errors, dtype=float)
    predicted = np.asarray(probe_estimates, float) * np.exp(np.asarray(span, float)
                                                           * np.asarray(slopes, float))
    with np.errstate(invalid="ignore", divide="ignore"):
        test = np.maximum(e, floor) / predicted[:, None]
    return test[np.isfinite(test)]


def rms_error(fill: np.ndarray, truth: np.ndarray) -> float:
    """The error of a fill (n, 3) against the truth (n, 3): RMS of the 3-D distances."""
    return math.sqrt(mean_of(np.sum((fill - truth) ** 2, axis=-1)))


def estimates(window_errors: np.ndarray, floor: float = 0.0) -> np.ndarray:
    """Per gap the geometric mean of its windows' errors (G, C; NaN where a copy has no
    window for the gap; each floored at ``floor``); NaN for a gap with no window. The
    errors of one gap's windows spread log-normally (a window in an easy stretch of the
    motion, one in a hard one: the two windows of a gap differ by about 3× or more in one
    gap in five on the shared captures); their geometric mean is the median under that
    model, where their RMS is pulled up by the worse window (with it, the bounds covered
    93.0 % of the fills of benchmarks/fill_calibration.py at a median bound 3.0× the true
    error, against 91.2 % at 2.8×: :func:`averaging_exponent`)."""
    e = np.asarray(window_errors, dtype=float).reshape(len(window_errors), -1)
    ok = np.isfinite(e)
    count = ok.sum(axis=1)
    logs = np.where(ok, np.log(np.maximum(np.where(ok, e, 1.0), max(floor, 1e-300))), 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, np.exp(logs.sum(axis=1) / np.maximum(count, 1)), np.nan)


def scores(window_errors: np.ndarray, floor: float, fitted: np.ndarray | None = None
           ) -> np.ndarray:
    """The normalised nonconformity scores of the windows: a window's error over the
    geometric mean of the errors of its gap's other windows (each floored at ``floor``),
    for every window whose gap has another. ``fitted``: the errors the estimate is made
    of, when they differ from the test errors (a filler whose weights were chosen on the
    windows: the test error of a window with weights chosen on the others, the estimate's
    errors with the weights chosen on all, as for the real gap); default
    ``window_errors``."""
    e = np.asarray(window_errors, dtype=float).reshape(len(window_errors), -1)
    f = e if fitted is None else np.asarray(fitted, dtype=float).reshape(e.shape)
    ok = np.isfinite(e) & np.isfinite(f)
    count = ok.sum(axis=1, keepdims=True) - 1
    logs = np.where(ok, np.log(np.maximum(np.where(ok, f, 1.0), floor)), 0.0)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        others = np.exp((logs.sum(axis=1, keepdims=True) - logs) / np.maximum(count, 1))
        s = np.maximum(e, floor) / others
    return s[ok & (count > 0)]


def conformal_factor(score: np.ndarray, level: float = LEVEL, minimum: int = MIN_SCORES,
                     prior: float = PRIOR_FACTOR) -> tuple[float, bool]:
    """The split-conformal quantile of ``score``: its ``⌈(m + 1) level⌉``-th smallest of
    ``m``; ``(prior, False)`` with fewer than ``minimum`` scores, else ``(factor, True)``."""
    score = np.sort(np.asarray(score, dtype=float))
    m = len(score)
    k = math.ceil((m + 1) * level)
    if m < minimum or k > m:
        return prior, False
    return float(score[k - 1]), True


def bounds(window_errors: np.ndarray, floor: float, level: float = LEVEL,
           factor: float | None = None, fitted: np.ndarray | None = None):
    """Per gap ``(estimate, bound)`` from its windows' errors (G, C), and the factor and
    whether it came from these windows. The estimate is the RMS of the ``fitted`` errors
    (default ``window_errors``; see :func:`scores`). The factor is the conformal quantile
    of the windows' scores (:func:`conformal_factor`) unless ``factor`` is given; the
    bound of a gap with ``n`` windows is ``factor ** a(n) × max(estimate, floor)`` with
    ``a(n) = √((1 + 1/n) / (1 + 1/(C − 1)))`` (:func:`averaging_exponent`). NaN for gaps
    with no window."""
    e = np.asarray(window_errors, dtype=float).reshape(len(window_errors), -1)
    f = e if fitted is None else np.asarray(fitted, dtype=float).reshape(e.shape)
    est = estimates(f, floor)
    own = factor is None
    if own:
        factor, own = conformal_factor(scores(e, floor, f), level)
    exponent = averaging_exponent(np.isfinite(f).sum(axis=1), f.shape[1])
    return est, factor ** exponent * np.maximum(est, floor), factor, own


def averaging_exponent(windows: np.ndarray, copies: int) -> np.ndarray:
    """The power of the score quantile that bounds a gap estimated from ``windows``
    windows, when the scores compare one window with the mean of ``copies − 1`` others.
    If a window's log error is the gap's log scale plus independent noise of spread σ, a
    score's log has spread σ √(1 + 1/(copies − 1)) and the real gap's error over its
    estimate σ √(1 + 1/windows) (the real gap is one more draw, its estimate an average
    of ``windows``): the quantile's log scales by their ratio. With two copies and two
    windows, 0.87. Measured offline on the windows and fills of the nine captures of
    benchmarks/fill_calibration.py (four seeds, both gap ranges, 1,234 fills): the
    unscaled quantile covered 93.9 % of the fills at a median bound 3.3× their true
    error, the scaled one 91.2 % at 2.8× (with the RMS instead of the geometric mean as
    the estimate: 94.6 % at 3.6×, 93.0 % at 3.0×)."""
    k = max(copies - 1, 1)
    return np.sqrt((1.0 + 1.0 / np.maximum(windows, 1)) / (1.0 + 1.0 / k))


class FillIndex:
    """``Motion.fill_errors`` (``{name: [[start, length, error, bound, step, written,
    extrapolated], ...]}``) indexed by start per name, for many :meth:`error` look-ups (a
    report asks once per gap: thousands of spike holes)."""

    def __init__(self, fill_errors: dict | None):
        self._by_name = {}
        for name, entries in (fill_errors or {}).items():
            fills = sorted((e for e in entries if len(e) < 6 or e[5]), key=lambda e: e[0])
            self._by_name[name] = (np.array([e[0] for e in fills], dtype=np.int64), fills)

    def error(self, name: str, start: int, length: int):
        """``(error, bound, extrapolated)`` of the samples ``start .. start + length − 1``
        of ``name``: the length-weighted RMS of the estimates of the fills there, the
        largest bound, and whether one of them was extrapolated (:func:`extrapolated_bounds`);
        None when part of the span has no estimate (gaps left unfilled are no fills)."""
        starts, fills = self._by_name.get(name, (np.zeros(0, np.int64), []))
        lo, hi = np.searchsorted(starts, [start, start + length])
        inside = [e for e in fills[lo:hi] if e[0] + e[1] <= start + length]
        n = sum(e[1] for e in inside)
        if not inside or n < length:
            return None
        return (float(np.sqrt(sum(e[1] * e[2] ** 2 for e in inside) / n)),
                float(max(e[3] for e in inside)), any(len(e) > 6 and e[6] for e in inside))


#: why a fill has no estimate: no window of its length, nor of a sixth of it (and of 2
#: frames at least), could be cut
NO_ESTIMATE = (f"no stretch of the marker as long as 1/{MAX_RATIO:g} of the gap was seen to "
               "test a fill on")


def uncertain_reason(error_mm: float | None, bound_mm: float | None, why: str = "") -> str:
    """The report's words for a gap left because its fill could not be trusted."""
    if error_mm is None or not np.isfinite(error_mm):
        return "too uncertain to fill: " + (why or NO_ESTIMATE)
    return (f"too uncertain to fill, estimated error {error_mm:.0f} mm "
            f"(90 % bound {bound_mm:.0f} mm)")


def window_fill_errors(pos: np.ndarray, gaps, windows, fill_copy) -> np.ndarray:
    """(G, C) errors of a filler on the validation windows of ``gaps``
    (:func:`validation_windows`): ``fill_copy(cut_positions, synth)`` fills one copy
    (positions with the copy's windows NaN; ``synth`` its windows as ``(j, start,
    stop)``) and returns the filled positions (T, J, 3); each window's error is measured
    against ``pos`` (all windows of a copy at once). NaN where a gap has no window in a
    copy."""
    err = np.full((len(gaps), max(len(windows), 1)), np.nan)
    for c, (cut, synth) in enumerate(windows):
        spans = [(gaps[g][0], u, v) for g, u, v in synth]
        filled = fill_copy(np.where(cut[..., None], pos, np.nan), spans)
        j, u, v = (np.array(x, dtype=np.intp) for x in zip(*spans))
        n = v - u
        rows = np.repeat(u - np.cumsum(n) + n, n) + np.arange(n.sum())
        cols = np.repeat(j, n)
        sq = np.sum((filled[rows, cols] - pos[rows, cols]) ** 2, axis=1)
        starts = np.cumsum(n) - n
        err[[g for g, _, _ in synth], c] = np.sqrt(np.add.reduceat(sq, starts) / n)
    return err


class FillTrust:
    """The error estimates and calibrated bounds of one step's fills and, under the
    pipeline's gate (:class:`mocapfix.cleaners.base.FillGate`), the decision to write each:
    a fill is written when its bound is at most the gate's threshold. Records the written
    fills' estimates (``written``: the steps' ``fill_errors`` info) and the refused ones
    (``rejected``: ``rejected_fills`` entries with their estimate and bound). Gaps are
    ``(j, s, e)``; lengths in the motion's unit, mm in the records."""

    def __init__(self, motion, gate=None):
        self.names = motion.names
        self.gate = gate
        self.limit = None if gate is None else gate.max_error(motion)
        self.mm = motion.metres_per_unit * 1e3
        self.floor = ERROR_FLOOR_M / motion.metres_per_unit
        self.bound_floor = BOUND_FLOOR_M / motion.metres_per_unit
        self.bounds: dict = {}
        self.factors: dict = {}
        self.slopes: dict = {}
        self.rejected: dict = {}
        self.written: dict = {}
        self._refused: set = set()

    def estimate(self, gaps, plan: WindowPlan, window_errors, what: str, fitted=None) -> None:
        """The estimates and bounds of ``gaps`` from their windows' errors (G, copies of
        ``plan``, :func:`window_plan`), calibrated on those windows (one group of fills,
        ``what``; ``fitted``: see :func:`scores`): the gaps with windows of their length by
        :func:`bounds`, the longer ones by :func:`extrapolated_bounds`; every bound at
        least :data:`BOUND_FLOOR_M`."""
        if not len(gaps):
            return
        e = np.asarray(window_errors, dtype=float).reshape(len(gaps), -1)
        f = e if fitted is None else np.asarray(fitted, dtype=float).reshape(e.shape)
        ordinary = plan.ratio == 1.0
        far = np.isfinite(plan.ratio) & ~ordinary
        est = np.full(len(gaps), np.nan)
        bound = est.copy()
        factor = PRIOR_FACTOR
        if ordinary.any():
            cols = plan.ordinary
            est[ordinary], bound[ordinary], factor, own = bounds(
                e[ordinary, cols], self.floor, fitted=f[ordinary, cols])
            self.factors[what] = [round(factor, 3), "this capture" if own else "prior"]
        if far.any():
            cols, probes = plan.extrapolated, plan.probes
            est[far], bound[far], factor, own, slope, own_slope = extrapolated_bounds(
                e[far, cols], e[far, probes], plan.ratio[far], plan.probe_ratio[far],
                self.floor, fitted=f[far, cols], fitted_probes=f[far, probes], prior=factor)
            self.factors[what + ", extrapolated"] = [round(factor, 3),
                                                    "this capture" if own else "prior"]
            self.slopes[what] = [round(slope, 3), "this capture" if own_slope else "prior"]
        bound = np.maximum(bound, self.bound_floor)
        for g, x, b, r in zip(gaps, est, bound, plan.ratio):
            if np.isfinite(x):
                self.bounds[tuple(g)] = (float(x), float(b), bool(r > 1.0))

    def trusted(self, gap) -> bool:
        """The gap's fill may be written: no gate, or a bound within its threshold."""
        if self.gate is None:
            return True
        eb = self.bounds.get(tuple(gap))
        return eb is not None and eb[1] <= self.limit

    def allows(self, gap) -> bool:
        """:meth:`trusted`, recording the gap as written (with its estimate) or refused."""
        if not self.trusted(gap):
            self.refuse(gap)
            return False
        eb = self.bounds.get(tuple(gap))
        if eb is not None:
            j, s, e = gap
            self.written.setdefault(self.names[j], []).append(
                [int(s), int(e - s), round(eb[0] * self.mm, 3), round(eb[1] * self.mm, 3),
                 eb[2]])
        return True

    def refuse(self, gap, why: str = "") -> None:
        """Leave the gap as too uncertain to fill, with its estimate when it has one."""
        j, s, e = gap
        eb = self.bounds.get(tuple(gap))
        err, bound = (None, None) if eb is None else (round(eb[0] * self.mm, 3),
                                                      round(eb[1] * self.mm, 3))
        self.rejected.setdefault(self.names[j], []).append(
            [int(s), int(e - s), uncertain_reason(err, bound, why), err, bound,
             eb is not None and eb[2]])
        self._refused.add(tuple(gap))

    def refused(self, gap) -> bool:
        return tuple(gap) in self._refused

    @property
    def count(self) -> int:
        """Gaps refused."""
        return len(self._refused)
