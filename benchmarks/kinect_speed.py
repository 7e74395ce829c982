#!/usr/bin/env python3
"""Speed of configs/kinect.yaml on a 10-minute 30 fps Kinect v2 recording (18,000 frames x
25 joints): CMU 05_02 mapped to Kinect joints (as the ``kinect`` bench protocol does),
played forwards and backwards to length, ``mixed`` sensor corruption, written as a Kinect
v2 CSV. Times the cleaning (the config's pipeline on the read Motion, best of
``--repeat``) and the whole ``mocapfix clean`` run (read, clean, write, JSON report).

    python benchmarks/kinect_speed.py [--frames 18000] [--repeat 3]
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data"


def recording(frames: int, path: Path) -> None:
    from mocapfix.bench import kinect as bk
    from mocapfix import formats

    src = formats.read(DATA / "asfamc" / "05_02.amc")
    truth = bk.kinect_truth(src, np.random.default_rng(0), max_frames=10_000)
    loop = np.concatenate([truth, truth[::-1]])
    n = int(frames / 0.98) + 10                 # ~1.5 % of the frames are dropped
    truth = np.concatenate([loop] * (n // len(loop) + 1))[:n]
    coords, states, keep = bk.sensor_corruption(truth, "mixed", seed=0)
    rows = np.flatnonzero(keep)[:frames]
    times = np.arange(n) / bk.KINECT_FPS
    path.write_text(bk.kinect_v2_csv(coords[rows], states[rows], times[rows]))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=18_000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    from mocapfix import formats
    from mocapfix.config import load_config

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "long_kinect_v2.csv"
        recording(args.frames, path)
        motion = formats.read(path)
        pipe = load_config(REPO / "configs" / "kinect.yaml")
        best = cpu = np.inf
        for _ in range(args.repeat):
            t0, c0 = time.perf_counter(), time.process_time()
            _, records = pipe.run(motion)
            best = min(best, time.perf_counter() - t0)
            cpu = min(cpu, time.process_time() - c0)
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "mocapfix.cli", "clean", str(path), "-o",
                        str(Path(tmp) / "out"), "-c", str(REPO / "configs" / "kinect.yaml")],
                       check=True, capture_output=True)
        wall = time.perf_counter() - t0
    print(f"| frames x joints | kinect.yaml cleaning wall s (best of {args.repeat}) | CPU s | "
          "`mocapfix clean` wall s |")
    print("|---:|---:|---:|---:|")
    print(f"| {motion.n_frames:,} x {motion.n_joints} | {best:.2f} | {cpu:.2f} | {wall:.2f} |")
    print(f"(OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', 'unset')})", file=sys.stderr)


if __name__ == "__main__":
    main()
