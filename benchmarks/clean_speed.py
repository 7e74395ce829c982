#!/usr/bin/env python3
"""End-to-end speed of ``mocapfix clean`` with the default config.

1. One 4,500-frame, 41-marker C3D (CMU 85_02 played forwards and backwards to length,
   with the ``mixed`` occlusion corruption so every step has work), timed through the CLI
   including reading, writing and the JSON report.
2. A batch of 20 corrupted captures (85_02 and a 1,500-frame slice of HDM05, 10 seeds
   each): wall time with ``-j 1`` and ``-j 2``.

    python benchmarks/clean_speed.py
"""
from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from mocapfix import read, write
from mocapfix.corrupt import occlusion

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "c3d"


def _fresh(motion, positions):
    """A Motion the C3D writer writes as a new file (no source to splice into)."""
    return motion.replace(positions=positions, source=None, confidence=None)


def clean(inputs, out, jobs):
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "mocapfix.cli", "clean", *map(str, inputs), "-o", str(out),
                    "-j", str(jobs)], check=True, capture_output=True)
    return time.perf_counter() - t0


def main():
    base = read(DATA / "cmu_85_02.c3d")
    hdm = read(DATA / "hdm05_HDM_mm_01-02_03_120.c3d").slice_frames(0, 1500)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        long = np.concatenate([base.positions, base.positions[::-1]] * 3)[:4500]
        motion = _fresh(base, long)
        corrupted, _ = occlusion(motion.replace(positions=long), "mixed", 0)
        write(_fresh(base, corrupted.positions), tmp / "long.c3d")
        t = min(clean([tmp / "long.c3d"], tmp / f"out{k}", 1) for k in range(3))
        print("| capture | frames × markers | `mocapfix clean` wall time (s) |")
        print("|---|---:|---:|")
        print(f"| 85_02 ×6, mixed corruption | 4500 × {base.n_joints} | {t:.2f} |")

        batch = tmp / "batch"
        batch.mkdir()
        for seed in range(10):
            for name, m in (("cmu", base), ("hdm", hdm)):
                c, _ = occlusion(m, "mixed", seed)
                write(_fresh(m, c.positions), batch / f"{name}_{seed}.c3d")
        t1 = clean([batch], tmp / "j1", 1)
        t2 = clean([batch], tmp / "j2", 2)
        print("\n| batch | -j 1 (s) | -j 2 (s) | speed-up |")
        print("|---|---:|---:|---:|")
        print(f"| 20 corrupted captures | {t1:.1f} | {t2:.1f} | {t1 / t2:.2f}× |")


if __name__ == "__main__":
    main()
