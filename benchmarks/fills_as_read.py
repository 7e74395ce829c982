#!/usr/bin/env python3
"""What the default config writes into the shared C3D files as they are read (no
corruption): per file, the samples missing in the input that the cleaned file holds
(fills), by the length of the filled run — at most 0.1 s, 0.5 s, 1.5 s, and longer — and
the longest fill written; beside them the samples still missing after cleaning. Only the
markers are counted (model outputs a file lists in POINT:ANGLES etc. are never cleaned).

    python benchmarks/fills_as_read.py [--config configs/default.yaml]

Run time: about a minute (numediart_03_rolling takes most of it). Run it on another
checkout with ``PYTHONPATH=<checkout>`` to compare versions.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from mocapfix import read
from mocapfix.cleaning import clean_motion
from mocapfix.core.gaps import runs
from mocapfix.config import load_config
from mocapfix.pipeline.selection import not_cleaned

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "c3d"
#: upper ends (s) of the run-length classes
CLASSES = (0.1, 0.5, 1.5, np.inf)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--config", default=str(Path(__file__).resolve().parents[1] / "configs" / "default.yaml"))
    args = ap.parse_args()
    config = load_config(args.config)
    print("| file | missing samples | written ≤ 0.1 s | ≤ 0.5 s | ≤ 1.5 s | longer | "
          "longest fill (s) | still missing | s |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    totals = np.zeros(6, dtype=np.int64)
    for path in sorted(DATA.iterdir(), key=lambda p: p.name.lower()):
        motion = read(path)
        markers = np.array([w is None for w in not_cleaned(motion)], bool)
        started = time.perf_counter()
        cleaned = clean_motion(motion, config).cleaned
        seconds = time.perf_counter() - started
        before = motion.missing[:, markers]
        written = before & ~cleaned.missing[:, markers]
        _, _, length = runs(written)
        secs = length / motion.fps
        counts = [int(length[(secs <= hi) & (secs > lo)].sum())
                  for lo, hi in zip((-1.0, *CLASSES[:-1]), CLASSES)]
        left = int((before & cleaned.missing[:, markers]).sum())
        longest = float(secs.max()) if len(secs) else 0.0
        totals += [int(before.sum()), *counts, left]
        print(f"| {path.name} | {int(before.sum())} | " + " | ".join(map(str, counts))
              + f" | {longest:.2f} | {left} | {seconds:.1f} |", flush=True)
    print(f"| all | {totals[0]} | " + " | ".join(map(str, totals[1:5])) + f" | | {totals[5]} | |")


if __name__ == "__main__":
    main()
