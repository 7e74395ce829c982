#!/usr/bin/env python3
"""Why the default's gap filling wins or loses against the PMA-style baseline, per capture
(issue 16): the captures and gaps of ``benchmarks/versus_peers.py``, and for each

* the gap RMSE (mm) after each step of ``configs/default.yaml`` (does a later step —
  ``tsmc`` — move the fills?; "–" while gaps are still unfilled), and of ``pma``;
* the gap RMSE of each ``fill_ensemble`` member run alone (the cleaner with that one
  member and one neighbour count: ``interp``/``poly``/``grnn`` with 3 or 5 rigid
  neighbours, ``linear``; ``pose``: its two members together), and of the per-gap oracle that picks, for every gap, the member
  alone with the lowest error on it (a bound on what choosing members per gap can give);
* the RMSE over gaps of up to 0.3 s, 0.3–0.8 s and longer, and the share of the default's
  squared gap error that comes from its single worst gap.

A gap is a run of occluded samples of one marker. Only the cleaners' parameters are used
(no internals), so the script follows the cleaners as they change.

    python benchmarks/studies/gap_diagnosis.py [--seeds 2] [--max-frames 1200] [--max-s 1.5]
        [--only NAME ...]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from mocapfix import read
from mocapfix.cleaners import build
from mocapfix.bench.corrupt import occlusion_gaps
from mocapfix.core.gaps import runs
from mocapfix.config import load_config

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))   # benchmarks/: versus_peers
from versus_peers import CAPTURES, DATA, REPO, complete_block  # noqa: E402

#: members of fill_ensemble run alone: name → cleaner parameters
MEMBERS = {f"{m}{k}": {"members": [m], "neighbours": [k]}
           for m in ("interp", "poly", "grnn") for k in (3, 5)}
MEMBERS["linear"] = {"members": ["linear"]}
MEMBERS["pose"] = {"members": ["pose"]}           # its two members (6 and 12 neighbours)


def gap_errors(out, truth, gaps, mm):
    """Squared error (mm²) of ``out`` summed over each gap ``(j, s, e)`` (inf if unfilled)."""
    se = np.array([np.sum((out[s:e, j] - truth[s:e, j]) ** 2) for j, s, e in gaps]) * mm ** 2
    return np.where(np.isnan(se), np.inf, se)          # a gap left unfilled: never the best


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--max-frames", type=int, default=1200)
    ap.add_argument("--max-s", type=float, default=1.5, help="longest gap, s")
    ap.add_argument("--only", nargs="*", help="capture file names to run")
    args = ap.parse_args()
    default = load_config(REPO / "configs" / "default.yaml")
    cols = ["pma", "default"] + [f"after {s.cleaner.name}" for s in default.steps
                                 if "c3d" in (s.formats or ["c3d"])] + list(MEMBERS)
    cols += ["oracle member", "≤0.3 s", "0.3–0.8 s", ">0.8 s", "worst gap share"]
    print("| capture | " + " | ".join(cols) + " |")
    print("|---|" + "---:|" * len(cols))
    for name, label in CAPTURES.items():
        if args.only and name not in args.only:
            continue
        if not (DATA / name).exists():
            continue
        motion = read(DATA / name)
        clean = (motion if not motion.missing.any() and motion.kinds is None
                 else complete_block(motion))
        if clean is None:
            continue
        if clean.n_frames > args.max_frames:
            clean = clean.slice_frames(0, args.max_frames)
        clean = clean.replace(source=None, confidence=None)
        mm = clean.metres_per_unit * 1e3
        truth = clean.positions
        acc: dict[str, list] = {}
        for seed in range(args.seeds):
            corrupted, mask = occlusion_gaps(clean, np.random.default_rng(seed), max_s=args.max_s)
            j, s, n = runs(mask)
            gaps = list(zip(j.tolist(), s.tolist(), (s + n).tolist()))
            count = n.astype(float)
            rmse = {}

            def record(key, out):
                se = gap_errors(out, truth, gaps, mm)
                rmse[key] = se
                unfilled = np.isnan(out[mask]).any()       # a step before the fillers
                acc.setdefault(key, []).append(np.nan if unfilled else np.sqrt(se.sum() / count.sum()))

            record("pma", build("pma").apply(corrupted)[0].positions)
            m = corrupted
            cleaned = np.array([why is None for why in default.not_cleaned(m)], bool)
            for step in default.steps:
                if step.applies(m):
                    m = default._apply_step(step, m, cleaned)[0]
                    record(f"after {step.cleaner.name}", m.positions)
            record("default", m.positions)
            for key, params in MEMBERS.items():
                record(key, build("fill_ensemble", **params).apply(corrupted)[0].positions)
            best = np.min(np.stack([rmse[k] for k in MEMBERS]), axis=0)
            acc.setdefault("oracle member", []).append(np.sqrt(best.sum() / count.sum()))
            se = rmse["default"]
            for key, lo, hi in (("≤0.3 s", 0, 0.3), ("0.3–0.8 s", 0.3, 0.8), (">0.8 s", 0.8, 1e9)):
                sel = (count > lo * clean.fps) & (count <= hi * clean.fps)
                acc.setdefault(key, []).append(np.sqrt(se[sel].sum() / max(count[sel].sum(), 1)))
            acc.setdefault("worst gap share", []).append(se.max() / max(se.sum(), 1e-12))
        cells = [f"{np.mean(acc[k]):.2f}" if k in acc and np.isfinite(acc[k]).all() else "–"
                 for k in cols]
        print(f"| {label}, {clean.n_frames}×{clean.n_joints} | " + " | ".join(cells) + " |",
              flush=True)


if __name__ == "__main__":
    main()
