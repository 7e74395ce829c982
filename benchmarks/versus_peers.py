#!/usr/bin/env python3
"""Gap filling against the published peers (issue 16), on the shared gap-free captures and
on the complete blocks (every frame, every marker observed) of the shared vendor files.

Each capture gets occlusion gaps (:func:`mocapfix.bench.corrupt.occlusion_gaps`: a quarter of its
markers lose 1–3 interior gaps) of 0.1–1.5 s and, second regime, of 0.1–3 s. Every method
gets the same corrupted capture; the score is the RMSE (mm) over the gap samples (a sample
left unfilled is counted in ``unfilled``, not as an error). Methods:

* ``linear``, ``spline`` — per-channel interpolation of every gap (mocapfix ``fill``);
* ``pca`` — Gløersen & Federolf 2016 weighted PCA (``fill_pca``, ends filled);
* ``pma`` — our implementation of Tits et al. 2018 (PLoS ONE; model averaging with soft
  distance constraints; ``mocapfix.cleaners.pma``);
* ``fill_ensemble`` — the new filler;
* ``default`` — ``configs/default.yaml`` (the whole C3D pipeline).

    python benchmarks/versus_peers.py [--seeds 2] [--max-frames 1500] [--only NAME ...]
        [--min-seconds 2]     (c3d.org s02, 9 markers × 1.8 s, needs --min-seconds 1.5)

Prints Markdown tables: gap RMSE per capture, and each method's ratio to ``pma``. The
peers (linear, spline, pca, pma) run with ``max_fill_error: null`` (every fill written, as
published); ``fill_ensemble`` and ``default`` with the default gate, so their RMSE is over
what they write, and the share of the gap samples they leave unfilled as too uncertain is
in the ``unfilled %`` columns.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from mocapfix import read
from mocapfix.bench.corrupt import occlusion_gaps
from mocapfix.config import load_config, parse_config

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data" / "c3d"

#: capture → short label; gap-free captures are used whole, the others by their block
CAPTURES = {
    "cmu_85_02.c3d": "CMU 85_02 (breakdance, 41 m, 120 Hz)",
    "hdm05_HDM_mm_01-02_03_120.c3d": "HDM05 (44 m, 120 Hz)",
    "ezc3d_Qualisys.c3d": "Qualisys (55 m, 200 Hz)",
    "ezc3d_BTS.c3d": "BTS block",
    "btk_PiG_Motion-FlatFoot-Hole.c3d": "Vicon Nexus PiG block",
    "btk_mocap36_optitrack.c3d": "OptiTrack block",
    "c3dorg_s01_Eb015pi.c3d": "c3d.org s01 block (50 Hz)",
    "c3dorg_s02_pc_real.c3d": "c3d.org s02 block (9 m, 50 Hz)",
    "ktk_tennis_serve_nan.c3d": "tennis serve block (50 Hz)",
    "ktk_racing_full.c3d": "wheelchair racing block (70 Hz)",
    "c3dorg_s13_Dance.c3d": "PhoeniX dance (40 m, 65 Hz)",
}

#: our methods: run under the default fill gate (``max_fill_error``); the peers run without
OURS = ("fill_ensemble", "default")

METHODS = {
    "linear": [{"cleaner": "fill", "method": "linear", "max_gap": None}],
    "spline": [{"cleaner": "fill", "method": "spline", "max_gap": None}],
    "pca": [{"cleaner": "fill_pca", "fill_ends": True}],
    "pma": [{"cleaner": "pma"}],
    "fill_ensemble": [{"cleaner": "fill_ensemble"}],
}


def complete_block(motion, min_seconds: float = 2.0, min_markers: int = 9):
    """The largest (frames × markers) block where every sample is observed: markers taken
    in order of how often they are seen, the longest run of frames where all are seen,
    kept when it lasts at least ``min_seconds``. Returns a Motion or None."""
    obs = ~motion.missing
    if motion.kinds is not None:
        obs &= np.array([k == "marker" for k in motion.kinds])[None, :]
    order = np.argsort(-obs.sum(axis=0), kind="stable")
    need = int(min_seconds * motion.fps)
    best = None
    for k in range(min_markers, len(order) + 1):
        cols = np.sort(order[:k])
        ok = np.concatenate([[False], obs[:, cols].all(axis=1), [False]])
        edges = np.flatnonzero(np.diff(ok.astype(int)))
        if not len(edges):
            continue
        starts, stops = edges[0::2], edges[1::2]
        i = int(np.argmax(stops - starts))
        n = int(stops[i] - starts[i])
        if n >= need and (best is None or n * k >= best[0]):
            best = (n * k, cols, int(starts[i]), int(stops[i]))
    if best is None:
        return None
    _, cols, a, b = best
    pos = motion.positions[a:b][:, cols].copy()
    return motion.replace(positions=pos, names=[motion.names[c] for c in cols], source=None,
                          confidence=None, kinds=None, times=None, skeleton=None)


def captures(max_frames: int, min_seconds: float = 2.0, only=None):
    """``(file name, label, clean motion)`` of every capture of :data:`CAPTURES` there is:
    the gap-free captures whole, the others' largest complete block, cut to their first
    ``max_frames`` frames (a note is printed for a file that is missing or has no block)."""
    for name, label in CAPTURES.items():
        if only and name not in only:
            continue
        path = DATA / name
        if not path.exists():
            print(f"(missing: {path})")
            continue
        motion = read(path)
        clean = (motion if not motion.missing.any() and motion.kinds is None
                 else complete_block(motion, min_seconds))
        if clean is None:
            print(f"(no complete block in {name})")
            continue
        if clean.n_frames > max_frames:
            clean = clean.slice_frames(0, max_frames)
        yield name, label, clean.replace(source=None, confidence=None)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--max-frames", type=int, default=1500,
                    help="longer captures are cut to their first N frames")
    ap.add_argument("--only", nargs="*", help="capture file names to run")
    ap.add_argument("--methods", nargs="*", help="methods to run (default: all)")
    ap.add_argument("--min-seconds", type=float, default=2.0,
                    help="shortest complete block taken from a file with gaps")
    args = ap.parse_args()
    methods = {k: parse_config({"version": 1, "pipeline": v, **({} if k in OURS else
                                                                {"max_fill_error": None})}, k)
               for k, v in METHODS.items()}
    methods["default"] = load_config(REPO / "configs" / "default.yaml")
    if args.methods:
        methods = {k: v for k, v in methods.items() if k in args.methods}
    regimes = {"gaps 0.1–1.5 s": 1.5, "gaps 0.1–3 s": 3.0}
    rows = []
    for name, label, clean in captures(args.max_frames, args.min_seconds, args.only):
        mm = clean.metres_per_unit * 1e3
        for regime, max_s in regimes.items():
            scores = {k: [] for k in methods}
            unfilled = {k: 0 for k in methods}
            samples = 0
            seconds = {k: 0.0 for k in methods}
            for seed in range(args.seeds):
                corrupted, mask = occlusion_gaps(clean, np.random.default_rng(seed), max_s=max_s)
                samples += int(mask.sum())
                for k, pipe in methods.items():
                    t0 = time.perf_counter()
                    out, _ = pipe.run(corrupted)
                    seconds[k] += time.perf_counter() - t0
                    err = np.linalg.norm(out.positions[mask] - clean.positions[mask], axis=1) * mm
                    unfilled[k] += int(np.isnan(err).sum())
                    scores[k].append(float(np.sqrt(np.nanmean(err ** 2))) if (~np.isnan(err)).any()
                                     else float("nan"))
            row = {"capture": f"{label}, {clean.n_frames}×{clean.n_joints}", "regime": regime}
            for k in methods:
                # a seed where a method writes no gap sample has no RMSE: left out
                row[k] = float(np.nanmean(scores[k])) if np.isfinite(scores[k]).any() else np.nan
                row[k + ":unfilled"] = unfilled[k]
                row[k + ":unfilled %"] = 100.0 * unfilled[k] / max(samples, 1)
                row[k + ":s"] = seconds[k] / args.seeds
            rows.append(row)
            print(regime, row["capture"], {k: round(row[k], 2) for k in methods}, flush=True)
    names = list(methods)
    for regime in regimes:
        sel = [r for r in rows if r["regime"] == regime]
        if not sel:
            continue
        print(f"\n### Gap RMSE, mm — {regime} (mean of {args.seeds} seeds; "
              "[n] = samples left unfilled)\n")
        ours = [k for k in OURS if k in names]
        print("| capture | " + " | ".join(names) + " | ensemble / pma | default / pma | "
              + " | ".join(f"{k} unfilled %" for k in ours) + " |")
        print("|---|" + "---:|" * (len(names) + 2 + len(ours)))
        for r in sel:
            cells = [f"{r[k]:.2f}" + (f" [{r[k + ':unfilled']}]" if r[k + ":unfilled"] else "")
                     for k in names]
            ratio = lambda k: (f"{r[k] / r['pma']:.2f}" if k in r and "pma" in r else "–")  # noqa: E731
            print(f"| {r['capture']} | " + " | ".join(cells)
                  + f" | {ratio('fill_ensemble')} | {ratio('default')} | "
                  + " | ".join(f"{r[k + ':unfilled %']:.1f}" for k in ours) + " |")
        if "pma" in names:
            for k in ("fill_ensemble", "default"):
                if k in names:
                    g = np.exp(np.mean([np.log(r[k] / r["pma"]) for r in sel]))
                    u = np.mean([r[k + ":unfilled %"] for r in sel])
                    print(f"\n{k} / pma, geometric mean over captures: {g:.2f} "
                          f"(unfilled: {u:.1f} % of the gap samples, mean over captures)")
        print("\nseconds per run: " + ", ".join(
            f"{k} {np.mean([r[k + ':s'] for r in sel]):.2f}" for k in names))


if __name__ == "__main__":
    main()
