"""Speed of the M-SSA cleaner (Lou 2012; issue 11 targets: cleaning 4,500 frames × 62
channels in under 0.5 s — the thesis reports under 5 s —, and training on the CMU corpus
in under a minute).

    python benchmarks/mssa_speed.py [--training ../shared/training/cmu-asfamc]

Cleaning: a CMU ASF/AMC take (62 channels; 70 rotation features) tiled to 4,500 frames
with 0.7° jitter, cleaned by ``mssa`` with the shipped model (best of 3, one BLAS thread).
Training: ``mocapfix train-dictionary --method mssa`` on the corpus (reading included,
2 reader processes), and the fit alone.
"""
from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from mocapfix import formats  # noqa: E402
from mocapfix.bench import rotations as bench_rotations
from mocapfix.cleaners import build  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"


def clean_speed(path: Path, frames: int = 4500) -> dict:
    m = formats.read(path)
    reps = int(np.ceil(frames / m.n_frames))
    ch = np.concatenate([m.channels] * reps)[:frames]
    tiled = m.replace(channels=ch, positions=m.rig.positions(ch))
    motion, _ = bench_rotations.corrupt(tiled, "jitter", 0)
    cleaner = build("mssa")
    times = []
    for _ in range(3):
        started = time.perf_counter()
        _, info = cleaner.apply(motion)
        times.append(time.perf_counter() - started)
    return {"frames": frames, "channels": int(ch.shape[1]), "seconds": min(times),
            "bases": info["bases"], "n_bases": info["n_bases"], "iterations": info["iterations"]}


def train_speed(training: Path, out: Path) -> dict:
    from mocapfix.train import discover_training, read_all, train

    started = time.perf_counter()
    summary = train([training], out, method="mssa", jobs=2)
    total = time.perf_counter() - started
    paths = discover_training([training])
    motions = read_all(paths, jobs=2)
    fit_started = time.perf_counter()
    build("mssa").fit(motions)
    return {"files": len(paths), "frames": summary["training"]["frames"], "seconds_total": total,
            "seconds_fit": time.perf_counter() - fit_started}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--file", default=str(SHARED / "data" / "asfamc" / "13_39.amc"))
    ap.add_argument("--training", default=str(SHARED / "training" / "cmu-asfamc"))
    ap.add_argument("--out", default="/tmp/mssa-speed-model.npz")
    args = ap.parse_args()
    c = clean_speed(Path(args.file))
    print(f"clean: {c['frames']} frames x {c['channels']} channels in {c['seconds']:.3f} s "
          f"({c['n_bases']} bases from {c['bases']}, {c['iterations']} iterations; target < 0.5 s)")
    t = train_speed(Path(args.training), Path(args.out))
    print(f"train: {t['files']} files, {t['frames']} frames in {t['seconds_total']:.1f} s including "
          f"reading (fit alone {t['seconds_fit']:.1f} s; target < 60 s)")


if __name__ == "__main__":
    main()
