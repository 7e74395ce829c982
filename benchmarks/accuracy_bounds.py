#!/usr/bin/env python3
"""Measured RMSE (mm) of the shipped default per accuracy case, over the seeds of
tests/accuracy_cases.py (mean and worst seed), and its ratio to each baseline — the
numbers the bounds of tests/config/test_default_accuracy.py and tests/cleaners/test_tsmc.py
are set from. Re-run after any change to the default config or its cleaners and re-set the
bounds.

    MOCAPFIX_REQUIRE_DATA=1 python benchmarks/accuracy_bounds.py [--seeds 0,1,2]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default=None, help="comma-separated seeds (default: the tests')")
    parser.add_argument("--baselines", default="pca,classical,scipy_linear_gaussian,scipy_spline")
    args = parser.parse_args()
    if args.seeds:
        os.environ["MOCAPFIX_ACCURACY_SEEDS"] = args.seeds
    import accuracy_cases as A

    baselines = [b for b in args.baselines.split(",") if b]
    print(f"seeds {A.SEEDS}")
    print("| capture | scenario | default mean | worst | per seed | "
          + " | ".join(f"/{b} mean | worst" for b in baselines) + " | s |")
    print("|---|---|---:|---:|---|" + "---:|---:|" * len(baselines) + "---:|")
    for capture in A.CAPTURES:
        for scenario in A.SCENARIOS:
            t0 = time.perf_counter()
            ours = A.over_seeds("default", capture, scenario)
            cells = []
            for b in baselines:
                r = A.ratios("default", b, capture, scenario)
                cells.append(f"{r.mean():.3f} | {r.max():.3f}")
            seeds = " ".join(f"{v:.3f}" for v in ours)
            print(f"| {capture} | {scenario} | {ours.mean():.3f} | {ours.max():.3f} | {seeds} | "
                  + " | ".join(cells) + f" | {time.perf_counter() - t0:.0f} |", flush=True)


if __name__ == "__main__":
    main()
