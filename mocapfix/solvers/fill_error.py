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
"""
from __future__ import annotations

import math

import numpy as np

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


def validation_windows(observed: np.ndarray, gaps, copies: int, seed: int = 0):
    """The synthetic gaps that validate fills: ``copies`` times, per gap ``(j, s, e)`` a
    window of the gap's length cut at a random (seeded) place where marker ``j`` and the
    frames bounding the window were seen (windows of one marker in one copy do not
    overlap). Returns per copy ``(cut, windows)``: the observed mask with the copy's
    windows cut, and the windows as ``(gap index, start, stop)``. A gap whose marker has
    no such stretch gets no window; copies stop when no gap gets one. The places a window
    of one marker and length may start are found once and struck out as windows are cut
    (thousands of spike holes cost one pass over their marker, not one each)."""
    T = observed.shape[0]
    rng = np.random.default_rng(seed)
    seen_rows = np.ascontiguousarray(observed.T)
    out = []
    for _ in range(copies):
        cut_rows = seen_rows.copy()
        synth = []
        starts: dict = {}          # marker → length → where a window may start (1..T−n−1)
        for gi, (j, s, e) in enumerate(gaps):
            n = e - s
            if T - n - 1 < 1:
                continue
            mine = starts.setdefault(j, {})
            if n not in mine:
                c = np.concatenate([[0], np.cumsum(cut_rows[j])])
                u = np.arange(1, T - n)
                mine[n] = (c[u + n + 1] - c[u - 1]) == n + 2
            good = np.flatnonzero(mine[n])
            if not len(good):
                continue
            u = int(good[rng.integers(len(good))]) + 1     # the draw of rng.choice(good + 1)
            cut_rows[j, u:u + n] = False
            # a window starting at w covers frames w − 1 .. w + m: those that meet the cut
            # frames u .. u + n − 1 can no longer start there
            for m, ok in mine.items():
                ok[max(u - m - 1, 0):max(u + n, 0)] = False
            synth.append((gi, u, u + n))
        if not synth:
            break
        out.append((np.ascontiguousarray(cut_rows.T), synth))
    return out


def rms_error(fill: np.ndarray, truth: np.ndarray) -> float:
    """The error of a fill (n, 3) against the truth (n, 3): RMS of the 3-D distances."""
    return float(np.sqrt(np.mean(np.sum((fill - truth) ** 2, axis=-1))))


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
    """``Motion.fill_errors`` (``{name: [[start, length, error, bound, ..., written],
    ...]}``) indexed by start per name, for many :meth:`error` look-ups (a report asks
    once per gap: thousands of spike holes)."""

    def __init__(self, fill_errors: dict | None):
        self._by_name = {}
        for name, entries in (fill_errors or {}).items():
            fills = sorted((e for e in entries if len(e) < 6 or e[5]), key=lambda e: e[0])
            self._by_name[name] = (np.array([e[0] for e in fills], dtype=np.int64), fills)

    def error(self, name: str, start: int, length: int):
        """``(error, bound)`` of the samples ``start .. start + length − 1`` of ``name``:
        the length-weighted RMS of the estimates of the fills there and the largest bound;
        None when part of the span has no estimate (gaps left unfilled are no fills)."""
        starts, fills = self._by_name.get(name, (np.zeros(0, np.int64), []))
        lo, hi = np.searchsorted(starts, [start, start + length])
        inside = [e for e in fills[lo:hi] if e[0] + e[1] <= start + length]
        n = sum(e[1] for e in inside)
        if not inside or n < length:
            return None
        return (float(np.sqrt(sum(e[1] * e[2] ** 2 for e in inside) / n)),
                float(max(e[3] for e in inside)))


#: why a fill has no estimate: no window of its length could be cut
NO_ESTIMATE = "no stretch of the marker as long as the gap was seen to test a fill on"


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
        self.bounds: dict = {}
        self.factors: dict = {}
        self.rejected: dict = {}
        self.written: dict = {}
        self._refused: set = set()

    def estimate(self, gaps, window_errors, what: str, fitted=None) -> None:
        """The estimates and bounds of ``gaps`` from their windows' errors (G, copies),
        calibrated on those windows (one group of fills, ``what``; ``fitted``: see
        :func:`scores`)."""
        if not len(gaps):
            return
        est, bound, factor, own = bounds(window_errors, self.floor, fitted=fitted)
        self.factors[what] = [round(factor, 3), "this capture" if own else "prior"]
        for g, x, b in zip(gaps, est, bound):
            if np.isfinite(x):
                self.bounds[tuple(g)] = (float(x), float(b))

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
                [int(s), int(e - s), round(eb[0] * self.mm, 3), round(eb[1] * self.mm, 3)])
        return True

    def refuse(self, gap, why: str = "") -> None:
        """Leave the gap as too uncertain to fill, with its estimate when it has one."""
        j, s, e = gap
        eb = self.bounds.get(tuple(gap))
        err, bound = (None, None) if eb is None else (round(eb[0] * self.mm, 3),
                                                      round(eb[1] * self.mm, 3))
        self.rejected.setdefault(self.names[j], []).append(
            [int(s), int(e - s), uncertain_reason(err, bound, why), err, bound])
        self._refused.add(tuple(gap))

    def refused(self, gap) -> bool:
        return tuple(gap) in self._refused

    @property
    def count(self) -> int:
        """Gaps refused."""
        return len(self._refused)
