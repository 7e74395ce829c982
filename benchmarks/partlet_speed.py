"""Speed of partlet_dictionary (issue targets: denoising 4,500 frames × 31 joints in under
1.5 s — the paper: 13.7 s for one walk; training on the whole corpus in under 3 minutes on
2 cores). CPU and wall seconds; run on an otherwise idle machine. The process keeps freed
memory as the CLI does (:mod:`mocapfix.core.memory`; ``--library-memory``: as an importing
program gets it).

    python benchmarks/partlet_speed.py [--repeat 3] [--train] [--library-memory]
"""
from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from mocapfix import formats
from mocapfix.bench import corrupt
from mocapfix.cleaners import build

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data"
TRAINING = REPO.parent / "shared" / "training" / "cmu-asfamc"


def tiled(path, frames):
    m = formats.read(path).replace(rig=None, channels=None)
    reps = -(-frames // m.n_frames)
    pos = np.concatenate([m.positions if k % 2 == 0 else m.positions[::-1] for k in range(reps)])[:frames]
    return m.replace(positions=pos)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--frames", default="1125,2250,4500,9000")
    ap.add_argument("--train", action="store_true", help="also time training on the corpus")
    ap.add_argument("--library-memory", action="store_true",
                    help="leave the C library's memory policy as a library user gets it "
                         "(default: the CLI's, mocapfix.core.memory.retain_freed_memory)")
    args = ap.parse_args()
    if not args.library_memory:
        from mocapfix.core.memory import retain_freed_memory

        retain_freed_memory()
    print(f"# {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}, memory policy "
          f"{'library' if args.library_memory else 'CLI'}")
    print("| frames × joints | setting | wall s (best of %d) | CPU s |" % args.repeat)
    print("|---:|---|---:|---:|")
    cleaner = build("partlet_dictionary")
    for T in map(int, args.frames.split(",")):
        clean = tiled(DATA / "asfamc" / "05_02.amc", T)
        noisy, _ = corrupt.apply_protocol(clean, "feng2015", "snr20+out10", 0)
        cleaner.apply(noisy)   # model load and warm-up
        walls, cpus = [], []
        for _ in range(args.repeat):
            w, c = time.perf_counter(), time.process_time()
            cleaner.apply(noisy)
            walls.append(time.perf_counter() - w)
            cpus.append(time.process_time() - c)
        print(f"| {T} × {clean.n_joints} | snr20+out10 | {min(walls):.2f} | {min(cpus):.2f} |")
    if args.train:
        from mocapfix.train import train

        out = REPO / "benchmarks" / ".cache" / "speed-model.npz"
        out.parent.mkdir(exist_ok=True)
        w = time.perf_counter()
        summary = train([TRAINING], out, "partlet", jobs=2)
        print(f"\ntraining on {len(summary['training']['files'])} files, "
              f"{summary['training']['frames']} frames: {time.perf_counter() - w:.1f} s wall")


if __name__ == "__main__":
    main()
