"""Run time of ``trust`` + ``tsmc`` against the number of frames (issue 6).

A 41-marker capture of T frames (500 … 10,000) is built from the shared CMU 85_02 C3D
(810 frames @ 120 Hz) played forwards and backwards (no jump at the joins), corrupted by
the ``mixed`` occlusion scenario (seed 0), and cleaned with the default parameters.
Prints a table of seconds per step, ALM iterations, the share of the ``fill_pca`` prior
and time(4T)/time(T); then the same for the real HDM05 capture (3,990 frames).

    python benchmarks/tsmc_speed.py [--frames 500,1000,...] [--repeat 1]

Without the shared data a smooth synthetic 41-marker motion is used instead.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mocapfix.cleaners import build  # noqa: E402
from mocapfix.bench.corrupt import occlusion  # noqa: E402
from mocapfix.core.motion import Motion  # noqa: E402

DATA = Path(os.environ.get("MOCAPFIX_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))


def base_motion() -> Motion:
    path = DATA / "c3d" / "cmu_85_02.c3d"
    if path.exists():
        import mocapfix
        return mocapfix.read(path)
    rng = np.random.default_rng(0)
    t = np.arange(810) / 120.0
    basis = np.stack([np.sin(2 * np.pi * f * t + ph) for f, ph in
                      zip((0.5, 0.9, 1.3, 2.1), rng.uniform(0, 6, 4))], axis=1)
    pos = (basis @ rng.normal(0, 200, (4, 123))).reshape(-1, 41, 3)
    return Motion(pos, [f"M{j}" for j in range(41)], 120.0, format="c3d")


def of_length(motion: Motion, T: int) -> Motion:
    p = motion.positions
    reps = int(np.ceil(T / p.shape[0])) + 1
    tiled = np.concatenate([p if k % 2 == 0 else p[::-1] for k in range(reps)], axis=0)[:T]
    return motion.replace(positions=tiled, confidence=None, times=None)


def timed(trust, tsmc, bad, repeat: int):
    """Best of ``repeat`` runs: (trust s, tsmc s, total s, iterations, fill_pca s) — the
    last is ``fill_pca`` alone on the trust-flagged motion, the prior's share of tsmc."""
    best = None
    for _ in range(max(1, repeat)):
        t0 = time.perf_counter()
        flagged, _ = trust.apply(bad)
        t1 = time.perf_counter()
        _, info = tsmc.apply(flagged)
        t2 = time.perf_counter()
        if best is None or t2 - t0 < best[2]:
            t3 = time.perf_counter()
            build("fill_pca", fill_ends=True).apply(flagged)
            best = (t1 - t0, t2 - t1, t2 - t0, info["iterations"], time.perf_counter() - t3)
    return best


def row(frames, markers, t) -> str:
    return (f"{frames:>7} {markers:>7} {t[0]:>8.3f} {t[1]:>8.3f} {t[2]:>8.3f} {t[3]:>6}"
            f" {t[4]:>10.3f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", default="500,1000,2000,4000,4500,8000,10000")
    ap.add_argument("--repeat", type=int, default=1, help="best of N runs")
    args = ap.parse_args(argv)
    frames = [int(f) for f in args.frames.split(",")]
    base = base_motion()
    trust, tsmc = build("trust"), build("tsmc")
    rows = {}
    print(f"{'frames':>7} {'markers':>7} {'trust s':>8} {'tsmc s':>8} {'total s':>8} {'iters':>6}"
          f" {'fill_pca s':>10}")
    for T in frames:
        bad, _ = occlusion(of_length(base, T), "mixed", seed=0)
        rows[T] = timed(trust, tsmc, bad, args.repeat)
        print(row(T, bad.n_joints, rows[T]), flush=True)
    real = DATA / "c3d" / "hdm05_HDM_mm_01-02_03_120.c3d"
    if real.exists():
        import mocapfix
        hdm = mocapfix.read(real)
        bad, _ = occlusion(hdm.replace(confidence=None), "mixed", seed=0)
        print(row(f"{hdm.n_frames}*", bad.n_joints, timed(trust, tsmc, bad, args.repeat)))
        print("* the real HDM05 01-02_03 capture (not tiled), same corruption")
    print("\ntime(4T)/time(T):")
    for T in frames:
        if 4 * T in rows:
            print(f"  T={T:>5}: {rows[4 * T][2] / rows[T][2]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
