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
and with the gate: the fills written, covered, and the gap samples left unfilled. A
second table shows what other thresholds would write (from the ungated run's bounds):
the share of the gap samples and the RMS error of those fills.

    python benchmarks/fill_calibration.py [--seeds 5] [--max-frames 1200] [--only FILE ...]

Run time: about 100 s with 5 seeds on the shared 2-core machine (one process).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from versus_peers import REPO, captures  # noqa: E402

from mocapfix.bench.corrupt import occlusion_gaps  # noqa: E402
from mocapfix.config import load_config  # noqa: E402

REGIMES = {"0.1–1.5 s": 1.5, "0.1–3 s": 3.0}


def fill_outcomes(cleaned, truth, gaps) -> list[tuple[float, float, float, int]]:
    """``(estimate, bound, true error, length)`` in mm of every fill ``cleaned`` carries an
    estimate for (``Motion.fill_errors``) of samples missing in the input (``gaps``, the
    occlusion mask; not the samples ``trust`` judged wrong in the capture itself, whose
    truth is the glitch)."""
    mm = truth.metres_per_unit * 1e3
    out = []
    for name, entries in (cleaned.fill_errors or {}).items():
        j = cleaned.names.index(name)
        for s, n, err, bound, _, written in entries:
            if not written or not gaps[s:s + n, j].all():
                continue
            d = np.linalg.norm(cleaned.positions[s:s + n, j] - truth.positions[s:s + n, j], axis=1)
            out.append((err, bound, float(np.sqrt(np.mean(d ** 2))) * mm, n))
    return out


def factors(records) -> list[float]:
    """The bound factors the steps calibrated on the capture's own windows."""
    return [f for r in records for f, whence in ((r.info or {}).get("fill_error_factors") or {}).values()
            if whence == "this capture"]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--max-frames", type=int, default=1200)
    ap.add_argument("--only", nargs="*")
    args = ap.parse_args()
    gated = load_config(REPO / "configs" / "default.yaml")
    ungated = load_config(REPO / "configs" / "default.yaml")
    ungated.max_fill_error = None
    started = time.perf_counter()
    rows = []
    for name, label, clean in captures(args.max_frames, only=args.only):
        for regime, max_s in REGIMES.items():
            every, written, facs = [], [], []
            left = samples = 0
            for seed in range(args.seeds):
                corrupted, mask = occlusion_gaps(clean, np.random.default_rng(seed), max_s=max_s)
                out, records = ungated.run(corrupted)
                every += fill_outcomes(out, clean, mask)
                facs += factors(records)
                out, _ = gated.run(corrupted)
                written += fill_outcomes(out, clean, mask)
                left += int(out.missing[mask].sum())
                samples += int(mask.sum())
            rows.append((label, regime, every, written, facs, 100.0 * left / max(samples, 1),
                         samples))
            print(f"{label} {regime}: {coverage(every)} all, {coverage(written)} written",
                  flush=True)
    print(f"\n### Fill error bounds — coverage of the 90 % bound ({args.seeds} seeds, "
          f"occlusion gaps, configs/default.yaml)\n")
    print("| capture | gaps | fills | covered | median estimate mm | median true mm | "
          "bound factors | written (20 mm gate) | covered | samples left unfilled |")
    print("|---|---|---:|---:|---:|---:|---|---:|---:|---:|")
    for label, regime, every, written, facs, left, _ in rows:
        est = np.median([e for e, *_ in every]) if every else float("nan")
        true = np.median([t for _, _, t, _ in every]) if every else float("nan")
        fr = f"{min(facs):.1f}–{max(facs):.1f}" if facs else "prior"
        print(f"| {label} | {regime} | {len(every)} | {coverage(every)} | {est:.2f} | "
              f"{true:.2f} | {fr} | {len(written)} | {coverage(written)} | {left:.1f} % |")
    print(f"\n### What a threshold would write (every fill's bound, {args.seeds} seeds): share of "
          "the gap samples written / RMSE of the fills written, mm\n")
    print("| capture | gaps | " + " | ".join(f"≤ {t:g} mm" for t in THRESHOLDS) + " | every fill |")
    print("|---|---|" + "---:|" * (len(THRESHOLDS) + 1))
    for label, regime, every, _, _, _, samples in rows:
        cells = [written_at(every, t, samples) for t in (*THRESHOLDS, np.inf)]
        print(f"| {label} | {regime} | " + " | ".join(cells) + " |")
    allf = [f for r in rows for f in r[2]]
    allw = [f for r in rows for f in r[3]]
    print(f"\nall captures: {coverage(allf)} of {len(allf)} fills covered; written "
          f"{coverage(allw)} of {len(allw)}; {time.perf_counter() - started:.0f} s")


#: thresholds whose effect the second table shows
THRESHOLDS = (10.0, 20.0, 30.0, 50.0)


def written_at(outcomes, threshold: float, samples: int) -> str:
    """The share of ``samples`` gap samples the fills with a bound ≤ ``threshold`` hold,
    and their RMS error (from the true errors), as ``"61 % / 3.2"``."""
    kept = [(t, n) for _, b, t, n in outcomes if b <= threshold]
    n = sum(k for _, k in kept)
    if not n:
        return "0 % / –"
    rms = np.sqrt(sum(k * t ** 2 for t, k in kept) / n)
    return f"{100.0 * n / max(samples, 1):.0f} % / {rms:.1f}"


def coverage(outcomes) -> str:
    """The share of fills whose true error is at most their bound, as a percentage."""
    if not outcomes:
        return "–"
    return f"{100.0 * np.mean([t <= b for _, b, t, _ in outcomes]):.1f} %"


if __name__ == "__main__":
    main()
