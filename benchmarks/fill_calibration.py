#!/usr/bin/env python3
"""Are the fill error bounds calibrated? (issue "Do no harm")

Every fill mocapfix writes carries an estimated error and a 90 % bound
(:mod:`mocapfix.solvers.fill_error`). Here the truth is known: the gap-free captures and
complete blocks of :mod:`benchmarks.versus_peers` (``captures``: CMU 85_02, HDM05,
Qualisys, Vicon PiG, OptiTrack, c3d.org s01, tennis, wheelchair, PhoeniX dance; 1,200
frames at most) get the ``occlusion`` gaps (:func:`mocapfix.bench.corrupt.occlusion_gaps`, a
quarter of the markers lose 1–3 gaps of 0.1–1.5 s, and of 0.1–3 s), seeds 0..N−1, and
``configs/default.yaml`` cleans them

* with ``max_fill_error: null`` (every fill written with its estimate: the bound's
  calibration over all fills), and
* as shipped (``max_fill_error: 20 mm``: the fills it writes).

The **error of a fill** is the RMS, over the samples of the filled run, of the 3-D
distance between the written fill and the true position (mm). A fill is *covered* when
that error is at most its bound. Per capture: fills, the share covered (target 85–95 %),
the median estimate and true error, the bound factors the capture's own windows gave,
with the gate: the fills written, covered, and the gap samples left unfilled; and the
window scores each run calibrated on, with the chance that the cell would lie in 85–95 %
if every bound were exactly calibrated (:func:`chance_in_range`: the ceiling of that
target with this many windows and fills). A
second table shows what other thresholds would write (from the ungated run's bounds):
the share of the gap samples and the RMS error of those fills.

    python benchmarks/fill_calibration.py [--seeds 5] [--max-frames 1200] [--only FILE ...]

Run time: about 100 s with 5 seeds on the shared 2-core machine (one process).
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from versus_peers import REPO, captures  # noqa: E402

from mocapfix.bench.corrupt import occlusion_gaps  # noqa: E402
from mocapfix.config import load_config  # noqa: E402
from mocapfix.solvers import fill_error  # noqa: E402

REGIMES = {"0.1–1.5 s": 1.5, "0.1–3 s": 3.0}


def fill_outcomes(cleaned, truth, gaps) -> list[tuple[float, float, float, int, bool]]:
    """``(estimate, bound, true error, length, extrapolated)`` (mm) of every fill
    ``cleaned`` carries an estimate for (``Motion.fill_errors``) of samples missing in the
    input (``gaps``, the occlusion mask; not the samples ``trust`` judged wrong in the
    capture itself, whose truth is the glitch)."""
    mm = truth.metres_per_unit * 1e3
    out = []
    for name, entries in (cleaned.fill_errors or {}).items():
        j = cleaned.names.index(name)
        for s, n, err, bound, _, written, far in entries:
            if not written or not gaps[s:s + n, j].all():
                continue
            d = np.linalg.norm(cleaned.positions[s:s + n, j] - truth.positions[s:s + n, j], axis=1)
            out.append((err, bound, float(np.sqrt(np.mean(d ** 2))) * mm, n, far))
    return out


def factors(records, extrapolated: bool = False) -> list[float]:
    """The bound factors the steps calibrated on the capture's own windows (of the
    extrapolated estimates, or of the others)."""
    return [f for r in records
            for what, (f, whence) in ((r.info or {}).get("fill_error_factors") or {}).items()
            if whence == "this capture" and what.endswith(", extrapolated") == extrapolated]


def slopes(records) -> list[float]:
    """The growth exponents the steps fitted on the capture's own probes."""
    return [p for r in records for p, whence in ((r.info or {}).get("fill_error_slopes") or {}).values()
            if whence == "this capture"]


class Pooled:
    """The scores and growth pairs every step calibrates on (gathered by wrapping the
    kernels of :mod:`mocapfix.solvers.fill_error`), for the pooled priors."""

    def __init__(self):
        self.scores, self.extrapolation, self.rise, self.span = [], [], [], []
        originals = {k: getattr(fill_error, k) for k in ("scores", "extrapolation_scores",
                                                         "growth_exponent")}

        def scores(*a, **k):
            out = originals["scores"](*a, **k)
            self.scores.append(out)
            return out

        def extrapolation_scores(*a, **k):
            out = originals["extrapolation_scores"](*a, **k)
            self.extrapolation.append(out)
            return out

        def growth_exponent(rise, span, *a, **k):
            self.rise.append(np.asarray(rise, float))
            self.span.append(np.asarray(span, float))
            return originals["growth_exponent"](rise, span, *a, **k)

        fill_error.scores = scores
        fill_error.extrapolation_scores = extrapolation_scores
        fill_error.growth_exponent = growth_exponent

    def report(self) -> str:
        quantile = lambda s: fill_error.conformal_factor(np.concatenate(s or [np.zeros(0)]),  # noqa: E731
                                                         minimum=1, prior=np.nan)[0]
        rise, span = np.concatenate(self.rise or [np.zeros(0)]), np.concatenate(self.span or [np.zeros(0)])
        slope = float(np.sum(rise * span) / np.sum(span ** 2)) if len(span) else float("nan")
        return (f"pooled 90 % conformal quantiles: windows {quantile(self.scores):.2f} "
                f"({sum(map(len, self.scores))} scores), extrapolation "
                f"{quantile(self.extrapolation):.2f} ({sum(map(len, self.extrapolation))} scores); "
                f"pooled growth exponent {slope:.2f} ({len(span)} probed gaps)")


class ScoreCounts:
    """How many window scores each run's calibration rests on (the ordinary scores of
    every step of the run, summed), by wrapping :func:`mocapfix.solvers.fill_error.scores`."""

    def __init__(self):
        self.count = 0
        original = fill_error.scores

        def scores(*a, **k):
            out = original(*a, **k)
            self.count += len(out)
            return out

        fill_error.scores = scores

    def take(self) -> int:
        count, self.count = self.count, 0
        return count


def chance_in_range(runs, draws: int = 20000, seed: int = 0) -> float:
    """The probability that a cell of these runs lands in 85–95 % coverage if every bound
    were exactly what split conformal promises: the real gaps exchangeable with the
    windows. ``runs``: (scores m, fills n) per run. A run's coverage is then
    Beta(k, m + 1 − k), k = ⌈(m + 1) 0.9⌉ (the coverage of split conformal given its
    calibration set; Vovk 2012, "Conditional validity of inductive conformal predictors"), 0.9 where the run used
    the prior (m < 9), and its fills are covered independently at that rate. The ceiling
    of what any per-capture calibration resting on these windows can show per cell."""
    rng = np.random.default_rng(seed)
    covered = np.zeros(draws)
    total = 0
    for m, n in runs:
        if n == 0:
            continue
        if m >= fill_error.MIN_SCORES:
            k = math.ceil((m + 1) * fill_error.LEVEL)
            rate = rng.beta(k, m + 1 - k, draws) if k <= m else np.ones(draws)
        else:
            rate = np.full(draws, fill_error.LEVEL)
        covered += rng.binomial(n, rate)
        total += n
    share = covered / max(total, 1)
    return float(np.mean((share >= 0.85) & (share <= 0.95)))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--max-frames", type=int, default=1200)
    ap.add_argument("--only", nargs="*")
    ap.add_argument("--priors", action="store_true", help="also print the pooled priors "
                    "(score quantiles and growth exponent over every capture's calibration)")
    args = ap.parse_args()
    pooled = Pooled() if args.priors else None
    counts = ScoreCounts()
    gated = load_config(REPO / "configs" / "default.yaml")
    ungated = load_config(REPO / "configs" / "default.yaml")
    ungated.max_fill_error = None
    started = time.perf_counter()
    rows = []
    for name, label, clean in captures(args.max_frames, only=args.only):
        for regime, max_s in REGIMES.items():
            every, written, facs, far, grow, runs = [], [], [], [], [], []
            left = samples = 0
            for seed in range(args.seeds):
                corrupted, mask = occlusion_gaps(clean, np.random.default_rng(seed), max_s=max_s)
                counts.take()
                out, records = ungated.run(corrupted)
                outcomes = fill_outcomes(out, clean, mask)
                runs.append((counts.take(), len(outcomes)))
                every += outcomes
                facs += factors(records)
                far += factors(records, extrapolated=True)
                grow += slopes(records)
                out, _ = gated.run(corrupted)
                written += fill_outcomes(out, clean, mask)
                left += int(out.missing[mask].sum())
                samples += int(mask.sum())
            rows.append((label, regime, every, written, (facs, far, grow),
                         100.0 * left / max(samples, 1), samples, runs))
            print(f"{label} {regime}: {coverage(every)} all, {coverage(written)} written",
                  flush=True)
    print(f"\n### Fill error bounds — coverage of the 90 % bound ({args.seeds} seeds, "
          f"occlusion gaps, configs/default.yaml)\n")
    print("| capture | gaps | fills | covered | median estimate mm | median true mm | "
          "bound factors | extrapolated fills | covered | factors | exponents | "
          "written (20 mm gate) | covered | samples left unfilled | scores per run | "
          "chance in 85–95 % if exchangeable |")
    print("|---|---|---:|---:|---:|---:|---|---:|---:|---|---|---:|---:|---:|---|---:|")
    for label, regime, every, written, (facs, far, grow), left, _, runs in rows:
        est = np.median([o[0] for o in every]) if every else float("nan")
        true = np.median([o[2] for o in every]) if every else float("nan")
        extra = [o for o in every if o[4]]
        print(f"| {label} | {regime} | {len(every)} | {coverage(every)} | {est:.2f} | "
              f"{true:.2f} | {spread(facs)} | {len(extra)} | {coverage(extra)} | {spread(far)} | "
              f"{spread(grow, 2)} | {len(written)} | {coverage(written)} | {left:.1f} % | "
              f"{spread([m for m, _ in runs], 0)} | {100 * chance_in_range(runs):.0f} % |")
    print(f"\n### What a threshold would write (every fill's bound, {args.seeds} seeds): share of "
          "the gap samples written / RMSE of the fills written, mm\n")
    print("| capture | gaps | " + " | ".join(f"≤ {t:g} mm" for t in THRESHOLDS) + " | every fill |")
    print("|---|---|" + "---:|" * (len(THRESHOLDS) + 1))
    for label, regime, every, _, _, _, samples, _ in rows:
        cells = [written_at(every, t, samples) for t in (*THRESHOLDS, np.inf)]
        print(f"| {label} | {regime} | " + " | ".join(cells) + " |")
    allf = [f for r in rows for f in r[2]]
    allw = [f for r in rows for f in r[3]]
    alle = [f for f in allf if f[4]]
    print(f"\nall captures: {coverage(allf)} of {len(allf)} fills covered ({coverage(alle)} of "
          f"the {len(alle)} extrapolated); written {coverage(allw)} of {len(allw)}; "
          f"{time.perf_counter() - started:.0f} s")
    chances = [chance_in_range(r[7]) for r in rows]
    print(f"cells in 85–95 %: {sum(85 <= 100 * np.mean([t <= b for _, b, t, *_ in r[2]]) <= 95 for r in rows if r[2])} "
          f"of {len(rows)}; expected if every bound were exactly calibrated (exchangeable gaps): "
          f"{sum(chances):.1f} of {len(rows)}")
    if pooled:
        print(pooled.report())


def spread(values, digits: int = 1) -> str:
    """``"lo–hi"`` of ``values``, "prior" when there are none."""
    return f"{min(values):.{digits}f}–{max(values):.{digits}f}" if values else "prior"


#: thresholds whose effect the second table shows
THRESHOLDS = (10.0, 20.0, 30.0, 50.0)


def written_at(outcomes, threshold: float, samples: int) -> str:
    """The share of ``samples`` gap samples the fills with a bound ≤ ``threshold`` hold,
    and their RMS error (from the true errors), as ``"61 % / 3.2"``."""
    kept = [(t, n) for _, b, t, n, _ in outcomes if b <= threshold]
    n = sum(k for _, k in kept)
    if not n:
        return "0 % / –"
    rms = np.sqrt(sum(k * t ** 2 for t, k in kept) / n)
    return f"{100.0 * n / max(samples, 1):.0f} % / {rms:.1f}"


def coverage(outcomes) -> str:
    """The share of fills whose true error is at most their bound, as a percentage."""
    if not outcomes:
        return "–"
    return f"{100.0 * np.mean([t <= b for _, b, t, *_ in outcomes]):.1f} %"


if __name__ == "__main__":
    main()
