#!/usr/bin/env python3
"""mocapfix's shipped configs against the fill-and-filter pipelines people use today, on
real gap-free optical captures corrupted with the ``occlusion`` protocol
(:mod:`mocapfix.bench.corrupt`): gaps, noise (2 mm jitter + 2 % spikes of 20–100 mm), mixed,
and a marker swap.

Compared, all fed the same corrupted motion:

* ``linear+gaussian`` — linear fill of every gap, Gaussian smoothing (sigma 2 frames);
* ``kineticstoolkit`` — kineticstoolkit 0.17: ``TimeSeries.fill_missing_samples(0,
  method='cubic')`` then ``ktk.filters.butter(fc=6)`` (its documented gap-fill and
  filter, the standard biomechanics recipe), when kineticstoolkit is installed
  (``pip install kineticstoolkit`` — a dev-only comparison, not a dependency);
* ``pchip+butterworth`` — PCHIP fill + 6 Hz Butterworth through mocapfix's own kernels;
* the shipped ``configs/*.yaml`` with a step that runs on C3D.

RMSE in mm over every sample with a truth (a sample left missing counts separately, as
``unfilled %``). Prints a Markdown table.

    python benchmarks/versus_tools.py [--seeds 3] [--frames 1500]
"""
from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np

from mocapfix import read
from mocapfix.bench.corrupt import OCCLUSION_SCENARIOS, occlusion
from mocapfix.core.metrics import rmse, unfilled_fraction
from mocapfix.config import load_config, loads_config

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data" / "c3d"
CAPTURES = ("cmu_85_02.c3d", "hdm05_HDM_mm_01-02_03_120.c3d")

BASELINES = {
    "linear+gaussian": "pipeline:\n  - {cleaner: fill, method: linear, max_gap: 1000 s}\n"
                       "  - {cleaner: gaussian, sigma: 2 frames}\n",
    "pchip+butterworth": "pipeline:\n  - {cleaner: fill, method: pchip, max_gap: 1000 s}\n"
                         "  - {cleaner: butterworth, cutoff: 6 Hz}\n",
}


def kineticstoolkit_pipeline(motion):
    """Cubic fill + 6 Hz Butterworth with kineticstoolkit, on the motion's positions."""
    import kineticstoolkit as ktk

    T, J, _ = motion.positions.shape
    ts = ktk.TimeSeries(time=np.arange(T) / motion.fps)
    for j, name in enumerate(motion.names):
        ts.data[name] = np.concatenate([motion.positions[:, j], np.ones((T, 1))], axis=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ts = ts.fill_missing_samples(0, method="cubic")
        ts = ktk.filters.butter(ts, fc=6.0)
    out = np.stack([ts.data[name][:, :3] for name in motion.names], axis=1)
    return motion.replace(positions=out)


def methods():
    out = {name: loads_config(text, name).run for name, text in BASELINES.items()}
    try:
        import kineticstoolkit  # noqa: F401

        out["kineticstoolkit"] = lambda m: (kineticstoolkit_pipeline(m), [])
    except ImportError:
        print("(kineticstoolkit not installed: its row is skipped)")
    for cfg in sorted((REPO / "configs").glob("*.yaml")):
        pipe = load_config(cfg)
        if any(s.formats is None or "c3d" in s.formats for s in pipe.steps):
            out[f"configs/{cfg.name}"] = pipe.run
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--frames", type=int, default=0, help="use only the first N frames")
    args = ap.parse_args()
    runs = methods()
    table: dict[tuple[str, str], list[tuple[float, float, float]]] = {}
    for capture in CAPTURES:
        truth = read(DATA / capture)
        if args.frames:
            truth = truth.replace(positions=truth.positions[:args.frames])
        for scenario in OCCLUSION_SCENARIOS:
            for seed in range(args.seeds):
                corrupted, mask = occlusion(truth, scenario, seed)
                for name, run in runs.items():
                    t0 = time.perf_counter()
                    cleaned, _ = run(corrupted)
                    dt = time.perf_counter() - t0
                    mm = truth.metres_per_unit * 1000
                    table.setdefault((scenario, name), []).append(
                        (rmse(cleaned.positions, truth.positions) * mm,
                         100 * unfilled_fraction(cleaned.positions, truth.positions), dt))
    names = list(runs)
    print(f"RMSE mm (mean over {len(CAPTURES)} captures × {args.seeds} seeds; unfilled % in brackets)\n")
    print("| scenario | " + " | ".join(names) + " |")
    print("|---|" + "---:|" * len(names))
    for scenario in OCCLUSION_SCENARIOS:
        cells = []
        for name in names:
            vals = np.array(table[(scenario, name)])
            cell = f"{vals[:, 0].mean():.2f}"
            if vals[:, 1].mean() > 0.005:
                cell += f" ({vals[:, 1].mean():.2f} %)"
            cells.append(cell)
        print(f"| {scenario} | " + " | ".join(cells) + " |")
    print("\n| seconds per capture | " + " | ".join(
        f"{np.mean([v[2] for k, vals in table.items() if k[1] == n for v in vals]):.2f}" for n in names) + " |")


if __name__ == "__main__":
    main()
