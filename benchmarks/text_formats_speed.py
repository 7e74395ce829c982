#!/usr/bin/env python3
"""Read and write speed of the text formats, per sample, against the Kinect text reader
(issue "formats": TRC and the vendors' CSV/TSV at least as fast per sample as our Kinect
reader).

One motion — CMU 85_02's 41 markers (C3D, mm) looped to ``--frames`` frames, with 2 % of
the samples missing — is written fresh by every text format's writer; then each file is
read ``--repeat`` times and written back ``--repeat`` times, as read (nothing changed) and
with every sample moved by 0.1 mm (what a smoother's output costs): the path ``clean``
takes. Times are medians, in microseconds per
sample (one marker on one frame), and the ratio to the Kinect format's; a ratio ≤ 1 is
as fast as the Kinect reader or faster. The formats are timed in turn, round by round, so
that a busy spell of the machine slows them alike.

    python benchmarks/text_formats_speed.py [--frames 20000] [--repeat 3]
"""
from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from mocapfix import formats
from mocapfix.core.motion import Motion

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data"
#: the formats stored as text, Kinect first (the reference)
TEXT = [name for name in formats.NAMES if name != "kinect" and
        set(formats.suffixes(name)) & {".csv", ".tsv", ".txt", ".trc"}]


def take(frames: int) -> Motion:
    src = formats.read(DATA / "c3d" / "cmu_85_02.c3d")
    P = src.positions
    loop = np.concatenate([P, P[::-1]])
    P = np.concatenate([loop] * (frames // len(loop) + 1))[:frames].copy()
    rng = np.random.default_rng(0)
    P[rng.random(P.shape[:2]) < 0.02] = np.nan
    return Motion(P, list(src.names), src.fps, units=src.units, metres_per_unit=src.metres_per_unit)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=20_000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    motion = take(args.frames)
    samples = motion.n_frames * motion.n_joints
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        files, backs, moved = {}, {}, {}
        for name in ["kinect", *TEXT]:
            path = Path(tmp) / f"take_{name}{formats.suffixes(name)[0]}"
            formats.write(motion, path, format=name)
            files[name], backs[name] = path, formats.read(path, name)
            moved[name] = backs[name].replace(positions=backs[name].positions + 0.1)
        # the formats in turn, ``repeat`` rounds: a machine busy for a while slows every
        # format alike instead of the one timed then
        reads = {name: [] for name in files}
        writes = {name: [] for name in files}
        rewrites = {name: [] for name in files}
        for _ in range(args.repeat):
            for name, path in files.items():
                started = time.perf_counter()
                formats.read(path, name)
                reads[name].append(time.perf_counter() - started)
                out = Path(tmp) / f"back_{name}{formats.suffixes(name)[0]}"
                started = time.perf_counter()
                formats.write(backs[name], out, format=name)
                writes[name].append(time.perf_counter() - started)
                started = time.perf_counter()
                formats.write(moved[name], out, format=name)
                rewrites[name].append(time.perf_counter() - started)
        for name, path in files.items():
            rows[name] = (statistics.median(reads[name]), statistics.median(writes[name]),
                          statistics.median(rewrites[name]), path.stat().st_size)
    ref_read, ref_write, ref_moved, _ = rows["kinect"]
    print(f"{motion.n_frames} frames x {motion.n_joints} markers ({samples:,} samples), "
          f"median of {args.repeat}\n")
    print("| format | read µs/sample | ÷ Kinect | write-back unchanged | ÷ Kinect | "
          "write-back, every sample moved | ÷ Kinect | file MB |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for name, (read, write, rewrite, size) in rows.items():
        print(f"| {name} | {1e6 * read / samples:.2f} | {read / ref_read:.2f} | "
              f"{1e6 * write / samples:.2f} | {write / ref_write:.2f} | "
              f"{1e6 * rewrite / samples:.2f} | {rewrite / ref_moved:.2f} | {size / 1e6:.1f} |")


if __name__ == "__main__":
    main()
