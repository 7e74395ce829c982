#!/usr/bin/env python3
"""Read, write and forward-kinematics time for every file in ../shared/data (and
sample_data), with frames × joints per second. Prints a Markdown table.

Targets (issue 2): any shared file read in under 1 s; FK of 5,000 frames × 31 joints under
0.1 s (measured on the CMU BVH and ASF rigs, frames tiled to 5,000).

    python benchmarks/formats_io.py [DATA_DIR]
"""
from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from mocapfix.formats import read, write
from mocapfix.formats import MOTION_SUFFIXES

REPO = Path(__file__).resolve().parents[1]


def best_of(fn, repeat=3):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out


def main(data: Path) -> None:
    files = sorted(p for p in data.rglob("*") if p.suffix.lower() in MOTION_SUFFIXES)
    files += sorted(p for p in (REPO / "sample_data").iterdir() if p.suffix.lower() in MOTION_SUFFIXES)
    print("| file | frames × joints | read (s) | write (s) | FK (s) | read Mfj/s |")
    print("|---|---:|---:|---:|---:|---:|")
    worst = 0.0
    with tempfile.TemporaryDirectory() as tmp:
        for path in files:
            try:
                t_read, motion = best_of(lambda: read(path))
            except Exception as exc:  # noqa: BLE001
                print(f"| {path.name} | refused: {exc} | | | | |")
                continue
            worst = max(worst, t_read)
            out = Path(tmp) / path.name
            t_write, _ = best_of(lambda: write(motion, out))
            fk = "–"
            if motion.rig is not None:
                t_fk, _ = best_of(lambda: motion.rig.positions(motion.channels))
                fk = f"{t_fk:.4f}"
            fj = motion.n_frames * motion.n_joints
            print(f"| {path.parent.name}/{path.name} | {motion.n_frames} × {motion.n_joints} | "
                  f"{t_read:.3f} | {t_write:.3f} | {fk} | {fj / t_read / 1e6:.2f} |")
    print(f"\nslowest read: {worst:.3f} s (target < 1 s)\n")
    print("| rig | frames × joints | FK (s) | target |")
    print("|---|---:|---:|---|")
    for rel in ("bvh/cmu_cgspeed_131_01.bvh", "asfamc/05_01.amc"):
        path = data / rel
        if not path.exists():
            continue
        motion = read(path)
        reps = int(np.ceil(5000 / motion.n_frames))
        channels = np.tile(motion.channels, (reps, 1))[:5000]
        t_fk, pos = best_of(lambda: motion.rig.positions(channels), repeat=5)
        print(f"| {rel} | {pos.shape[0]} × {pos.shape[1]} | {t_fk:.4f} | < 0.1 s |")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else REPO.parent / "shared" / "data")
