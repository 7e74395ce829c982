"""Partlet dictionary denoising (Feng 2015) and its K-SVD variant (Xiao 2015) against our
other cleaners and the paper's rows, on the ``feng2015`` protocol.

- Held out: the shared CMU dance trials (05_02, 05_10) — the shipped model was trained on
  ``../shared/training`` (16 other subject-05 dance trials, salsa, acrobatics…), which
  holds neither of them.
- Baselines: Gaussian, wavelet and Kalman, each oracle-tuned per run (best grid value by
  the error against the truth, as the paper tuned its baselines; mocapfix.bench.oracle).
- Out of sample: the CMU BVH walks (cgspeed 131_01, 131_03): a motion the training set
  does not contain, on another file format (names mapped to the ASF bones).

    python benchmarks/partlet_tables.py [--seeds 2] [--frames 1200]

Prints Markdown tables (RMSE cm per marker, Feng 2015 eq. 19; mean over seeds and files)
and the unexplained-energy figure of the out-of-sample files.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from mocapfix import formats
from mocapfix.bench import corrupt
from mocapfix.core import metrics, models
from mocapfix.bench import cleaner_input
from mocapfix.bench.oracle import TUNED, tuned_method
from mocapfix.config import parse_config

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data"
TRAINING = REPO.parent / "shared" / "training" / "cmu-asfamc"
CACHE = REPO / "benchmarks" / ".cache"
SETTINGS = ["snr30", "snr20", "snr10", "out20", "snr20+out10"]
PAPER_DANCE = {"snr30": 0.86, "snr20": 2.55, "snr10": 3.73, "out20": 1.93, "snr20+out10": 2.42}


def ksvd_model() -> Path:
    """A K-SVD model (Xiao 2015) on the same corpus, trained once and cached."""
    path = CACHE / "partlet-cmu-ksvd.npz"
    if not path.exists():
        from mocapfix.train import train

        train([TRAINING], path, "ksvd", {"train_iterations": 8}, jobs=2)
    return path


def methods() -> dict:
    k = str(ksvd_model())
    step = lambda **kw: {"version": 1, "pipeline": [kw]}  # noqa: E731
    return {
        "tsmc": step(cleaner="tsmc"),
        "lowrank_isometry (tuned)": step(cleaner="lowrank_isometry", gamma=1000, eta=1.1, mu=0.03,
                                         approx_penalty=False, keep_inliers="50 mm"),
        "ksvd, l2 loss (Xiao)": step(cleaner="partlet_dictionary", model=k, coding="ksvd", loss="l2"),
        "ksvd, l1 loss (Xiao)": step(cleaner="partlet_dictionary", model=k, coding="ksvd", loss="l1"),
        "partlet_dictionary": step(cleaner="partlet_dictionary"),
    }


def run(files, settings, seeds, frames):
    pipes = {name: tuned_method(name) for name in TUNED}
    pipes.update({name: parse_config(cfg, name) for name, cfg in methods().items()})
    rows = {name: {s: [] for s in settings} for name in ["none", *pipes]}
    seconds = {name: [] for name in pipes}
    extra = {}
    for path in files:
        clean = formats.read(path).replace(rig=None, channels=None)
        if frames:
            clean = clean.slice_frames(0, frames)
        for s in settings:
            for seed in range(seeds):
                noisy, mask = corrupt.apply_protocol(clean, "feng2015", s, seed)
                rows["none"][s].append(100 * clean.metres_per_unit * metrics.rmse(noisy.positions, clean.positions))
                for name, pipe in pipes.items():
                    t = time.process_time()
                    if name in TUNED:
                        out, _ = pipe.run(cleaner_input(clean, noisy), truth=clean)
                        records = []
                    else:
                        out, records = pipe.run(cleaner_input(clean, noisy))
                    seconds[name].append(time.process_time() - t)
                    rows[name][s].append(100 * clean.metres_per_unit * metrics.rmse(out.positions, clean.positions))
                    if name == "partlet_dictionary":
                        extra.setdefault(path.name, records[-1].info.get("unexplained"))
    return rows, seconds, extra


def table(rows, settings, paper=None):
    out = ["| method | " + " | ".join(settings) + " |", "|---" * (len(settings) + 1) + "|"]
    if paper:
        out.append("| paper: Our (dance, Table I–III) | " + " | ".join(f"{paper[s]:.2f}" for s in settings) + " |")
    for name, r in rows.items():
        out.append(f"| {name} | " + " | ".join(f"{np.mean(r[s]):.2f}" for s in settings) + " |")
    return "\n".join(out)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--frames", type=int, default=0, help="first frames only (0: whole trials)")
    ap.add_argument("--walk-seeds", type=int, default=1)
    args = ap.parse_args()
    CACHE.mkdir(exist_ok=True)
    dance = [DATA / "asfamc" / "05_02.amc", DATA / "asfamc" / "05_10.amc"]
    walks = [DATA / "bvh" / "cmu_cgspeed_131_01.bvh", DATA / "bvh" / "cmu_cgspeed_131_03.bvh"]
    rows, secs, _ = run(dance, SETTINGS, args.seeds, args.frames)
    span = f"first {args.frames} frames" if args.frames else "whole trials"
    print(f"### Held-out CMU dance (05_02, 05_10; {span}; {args.seeds} seeds), RMSE cm\n")
    print(table(rows, SETTINGS, PAPER_DANCE))
    print("\nCPU s per file: " + ", ".join(f"{k} {np.mean(v):.2f}" for k, v in secs.items()))
    rows, secs, _ = run(walks, SETTINGS, args.walk_seeds, args.frames)
    print(f"\n### Out of sample: CMU BVH walks (131_01, 131_03; {span}; {args.walk_seeds} seed), RMSE cm\n")
    print(table(rows, SETTINGS))
    from mocapfix.cleaners import build

    trained = models.load(models.shipped()["partlet-cmu"])[0]["state"]["unexplained"]
    print("\nUnexplained energy of the clean motion (partlet_dictionary): training "
          + ", ".join(f"{p} {100 * f:.2f} %" for p, f in trained.items()))
    for path in dance + walks:
        clean = formats.read(path).replace(rig=None, channels=None)
        _, info = build("partlet_dictionary").apply(clean)
        print(f"- {path.name}: " + ", ".join(f"{p} {100 * f:.2f} %" for p, f in info["unexplained"].items())
              + (f" (warning: {info['warning']})" if "warning" in info else ""))


if __name__ == "__main__":
    main()
